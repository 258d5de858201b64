"""One budget for a whole input: what a scene may declare in all, checked before it costs anything.

A file of a few kB can declare what no memory holds: six meshopt fallback buffers of 1 GiB each,
a sparse 5 GiB ``.bin``, four 130 kB PNGs of 16384×8192, an index accessor of 30 M with no data
behind it, a chain of a million nodes. A limit on each item lets them through one at a time; so
every limit here is a total over the whole input, checked from what the files declare (the JSON,
each file's size, each image's header) before a byte of it is read, allocated or decoded, and
its error names the figures and the largest item:

- ``MAX_INPUT_BYTES``: the scene file, the declared bytes of all its buffers and the sizes of
  all its image files, together;
- ``MAX_DECODED_GEOMETRY``/``DECODE_RATIO``: the bytes compressed geometry decodes to (meshopt
  fallback buffers, which hold nothing until decoded, and the accessors of Draco primitives), at
  most ``DECODE_RATIO`` times the bytes the buffers hold, or ``MAX_DECODED_GEOMETRY``;
- ``MAX_NODES`` nodes, nested at most ``MAX_NODE_DEPTH`` deep;
- the accessors baker reads, against the data backing them (``instances.check_declared_sizes``):
  ``instances.MAX_SCENE_COMPONENTS`` numbers in all, of which ``MAX_UNBACKED_NUMBERS`` at most in
  accessors without a bufferView (zeros: nothing in the file bounds their count);
- ``MAX_PLACED_TRIANGLES``: the triangles the nodes place, each instance counted, at most
  ``PLACED_FLOOR`` + ``PLACED_PER_BYTE`` per byte of the input (``check_placed``, once the
  meshes are read: GPU instancing multiplies a small file's triangles);
- ``MAX_SCENE_PIXELS``: the pixels of all images together (every level of a KTX 2), from their
  headers, all read before the first image is decoded (``images.header``; one image at most
  ``images.MAX_IMAGE_PIXELS``): every image is decoded once, to check it;
- ``MAX_SAMPLED_PIXELS``: the pixels of the colour textures the bake keeps to sample (base
  colour, emission, metallic-roughness), from their headers; a texture past it is left out
  with a warning (``OverBudget``: its factor is used) and only checked.

What these bound is stated in docs/robustness.md: a bake of an input under 1 MB peaks under
1 GB and ends within 60 s on 2 cores, or is refused at once.
"""

from __future__ import annotations

from typing import Any, Iterable

from baker.errors import InputError

MAX_INPUT_BYTES = 1 << 31
"""Most bytes of an input: the scene file, its buffers' declared byteLengths and its image files
together (2 GiB)."""
MAX_DECODED_GEOMETRY = 64 << 20
"""Most bytes compressed geometry may decode to whatever the input's size (64 MiB) …"""
DECODE_RATIO = 32
"""… or this many times the bytes the input's buffers hold, if more (meshopt and Draco pack real
meshes 3 to 20 times; constant data, a thousand times)."""
MAX_NODES = 1 << 18
"""Most nodes of a scene (262,144: a level of 20,000 instances has a tenth of that; GPU
instancing places more)."""
MAX_NODE_DEPTH = 4096
"""Deepest nesting of nodes (viewers walk the hierarchy by recursion)."""
MAX_UNBACKED_NUMBERS = 1 << 20
"""Most numbers of the accessors baker reads that have no bufferView (all zeros but their sparse
values, which the file's bytes bound): 8 MiB as float64."""
MAX_SCENE_PIXELS = 1 << 28
"""Most pixels of all a scene's images together, every KTX 2 level counted (268 M: sixteen
4096² textures, sixty-four 2048²), each decoded once to check it (seconds of decoding)."""
MAX_SAMPLED_PIXELS = 1 << 26
"""Most pixels of the colour textures a bake keeps to sample (64 M: 256 MiB as RGBA, four
4096² textures or sixteen 2048²); the textures past it are left out with a warning."""

MAX_PLACED_TRIANGLES = 1 << 24
"""Most triangles the nodes may place in all, every instance (node or GPU instance) counted
(16.8 M), and of an input of n bytes at most ``PLACED_FLOOR`` + ``PLACED_PER_BYTE`` · n: a
placed triangle takes 550–770 bytes of memory as the bake holds it (6.5 M of 1,714 GPU-instanced
flowers peaked at 3.5 GB, 3.6 M of 300,000 instanced boxes at 2.8 GB), and a 38 kB file's
300,000 GPU instances of a 1,280-triangle ball placed 384 M (killed at 21 GB)."""
PLACED_FLOOR = 1 << 20
"""Triangles any input may place (1 M: under 1 GB)…"""
PLACED_PER_BYTE = 2
"""… and per byte of the input (a mesh's own bytes hold one triangle per 12 or more: this
lets GPU instancing place each about 24 times, a level of 40 MB 16.8 M triangles)."""

_FIX = "split the scene, or bake its parts apart"


class OverBudget(InputError):
    """A colour texture that would take the textures the bake keeps past
    ``MAX_SAMPLED_PIXELS``: left out with a warning, its factor used."""


class Budget:
    """The bytes of one input counted as its files are opened (``spend``), against
    ``MAX_INPUT_BYTES``."""

    def __init__(self, file: str):
        self.file, self.spent = file, 0

    def spend(self, count: int, what: str, where: str) -> None:
        """Count ``count`` more bytes of ``what`` (at ``where``), or refuse them when the input
        would pass ``MAX_INPUT_BYTES``."""
        if self.spent + count > MAX_INPUT_BYTES:
            raise InputError(f"{what}: {count:,} bytes, which take the input past "
                             f"{MAX_INPUT_BYTES:,} bytes (the scene file, its buffers and images "
                             f"together; {self.spent:,} before these)", file=self.file,
                             where=where, fix=_FIX)
        self.spent += count


def check_placed(placed: list[tuple[int, int]], input_bytes: int, file: str) -> None:
    """Refuse nodes that place more triangles in all (``placed``: (node index, the triangles it
    places, each GPU instance counted)) than an input of ``input_bytes`` may
    (``MAX_PLACED_TRIANGLES``), before any instance is made."""
    total = sum(count for _, count in placed)
    limit = min(MAX_PLACED_TRIANGLES, PLACED_FLOOR + PLACED_PER_BYTE * input_bytes)
    if total > limit:
        node, most = max(placed, key=lambda item: item[1])
        raise InputError(f"the nodes place {total:,} triangles in all (each instance counted), "
                         f"more than baker holds for an input of {input_bytes:,} bytes "
                         f"({limit:,}: a placed triangle takes about 750 bytes of memory); "
                         f"nodes[{node}] places the most, {most:,}", file=file,
                         where=f"nodes[{node}]",
                         fix="place fewer instances (EXT_mesh_gpu_instancing), or " + _FIX)


def check_nodes(raw: dict, file: str) -> None:
    """Refuse a file of more than ``MAX_NODES`` nodes (``raw``: the parsed JSON)."""
    nodes = raw.get("nodes", [])
    if len(nodes) > MAX_NODES:
        raise InputError(f"the file has {len(nodes):,} nodes, more than baker reads "
                         f"({MAX_NODES:,})", file=file, where="nodes",
                         fix="merge static nodes, or place repeated meshes with "
                             "EXT_mesh_gpu_instancing")


def check_depth(depth: int, where: str, file: str) -> None:
    """Refuse a node nested more than ``MAX_NODE_DEPTH`` deep (``depth``: 1 for a root)."""
    if depth > MAX_NODE_DEPTH:
        raise InputError(f"the node is nested {depth:,} deep, more than baker reads "
                         f"({MAX_NODE_DEPTH:,})", file=file, where=where,
                         fix="flatten the node hierarchy (apply the parents' transforms)")


def check_buffers(lengths: list[tuple[str, Any, str]], decoded: Iterable[tuple[str, int]],
                  budget: Budget) -> None:
    """Refuse, before any buffer is read, buffers that take the input past ``MAX_INPUT_BYTES``
    or decode to more than compressed geometry may (see the module's docstring).

    ``lengths``: (where, declared byteLength, kind) of every buffer, kind "file" (a file of its
    own), "embedded" (the GLB's binary chunk or a data URI: bytes of the scene file, counted
    with it) or "decoded" (a meshopt fallback buffer: zeros until decoded into); a byteLength
    that is no byte count is left for the reading to report. ``decoded``: (where, bytes) that
    Draco primitives declare."""
    counts = [(where, length, kind) for where, length, kind in lengths
              if isinstance(length, int) and not isinstance(length, bool) and length >= 0]
    files = [(where, length) for where, length, kind in counts if kind == "file"]
    if files:
        where, largest = max(files, key=lambda item: item[1])
        budget.spend(sum(length for _, length in files), f"the buffers' files declare "
                     f"(the largest, {where}, {largest:,} bytes)", where)
    held = sum(length for _, length, kind in counts if kind != "decoded")
    unpacked = [(where, length) for where, length, kind in counts if kind == "decoded"]
    unpacked += list(decoded)
    total = sum(length for _, length in unpacked)
    allowed = max(MAX_DECODED_GEOMETRY, DECODE_RATIO * held)
    if total > allowed:
        where, largest = max(unpacked, key=lambda item: item[1])
        raise InputError(f"the compressed geometry declares {total:,} bytes decoded (the "
                         f"largest, {where}, {largest:,}), more than baker decodes for "
                         f"{held:,} bytes of buffers ({allowed:,}: {DECODE_RATIO} times as many, "
                         f"or {MAX_DECODED_GEOMETRY >> 20} MiB)", file=budget.file, where=where,
                         fix="check the byteLengths and counts the compressed data declares")


def check_sampled(kept: int, pixels: int, size: str, label: str, file: str, where: str) -> None:
    """Raise ``OverBudget`` when keeping a colour texture of ``pixels`` (``size``: its width ×
    height; ``label`` names it) would take the ``kept`` pixels past ``MAX_SAMPLED_PIXELS``."""
    if kept + pixels > MAX_SAMPLED_PIXELS:
        raise OverBudget(f"{label} ({size}) would take the colour textures the bake samples "
                         f"past {MAX_SAMPLED_PIXELS:,} pixels ({4 * MAX_SAMPLED_PIXELS >> 20} "
                         "MiB as RGBA)", file=file, where=where,
                         fix="downscale the scene's largest textures")


def check_pixels(images: list[tuple[str, int]], file: str) -> None:
    """Refuse images whose pixels together (``images``: (where, pixels) of each, from its
    header) pass ``MAX_SCENE_PIXELS``, before any is decoded."""
    total = sum(pixels for _, pixels in images)
    if total > MAX_SCENE_PIXELS:
        where, largest = max(images, key=lambda item: item[1])
        raise InputError(f"the scene's {len(images)} images have {total:,} pixels in all, more "
                         f"than baker decodes ({MAX_SCENE_PIXELS:,}: "
                         f"{4 * MAX_SCENE_PIXELS >> 20} MiB as RGBA); the largest, {where}, "
                         f"{largest:,}", file=file, where=where,
                         fix="downscale the textures (2048×2048 is plenty for a lightmap "
                             "bake) and export again")
