"""Reading a glTF 2.0 file into a ``Scene``: the first stage of the pipeline.

Why a stage of its own: every later stage wants plain arrays — triangles in a mesh's local space,
float64 world matrices per placement, materials reduced to what light transport needs — and none
of them should know about buffers, strides, sparse accessors or node hierarchies. This is the only
module that decodes glTF binary data. It keeps the pygltflib document so that the writer adds the
bake to it and leaves everything else as it was.

In order, ``load`` does:
1. read the file (``.gltf`` JSON or ``.glb``, told apart by the magic bytes, not the suffix) and
   check ``asset.version`` and ``extensionsRequired``;
2. resolve every buffer to bytes (GLB binary chunk, data URI, or a file beside the ``.gltf``),
   and decode Draco and meshopt compressed geometry into plain accessors (``decompress``);
3. read the materials, then the default material glTF prescribes (appended last), and decode the
   images their base colour and emissive textures use; check that every other image file is
   there, so that nothing the output carries is found missing after the bake;
4. walk the scene's node tree into float64 world matrices, read the meshes the nodes use and make
   one ``Instance`` per (node, primitive), or per GPU instance of it.

Choices worth knowing:
- ``Scene.images`` has one entry per glTF image, so indices match the file. Only images that a
  material's base colour or emissive texture uses are decoded; every other entry (normal maps,
  metallic-roughness, occlusion, unused) is a 1×1 white placeholder, since the bake never samples
  them.
- TEXCOORD sets are kept from TEXCOORD_0 up to the first missing one: ``TextureRef.texcoord``
  indexes ``Primitive.texcoords`` directly, so sets after a gap (TEXCOORD_1 without TEXCOORD_0)
  cannot be stored; they are listed in ``Scene.skipped``.
- Primitives are read only for meshes that the scene's nodes use, in mesh order, one
  ``Primitive`` per mesh primitive however many nodes place it. Instances follow the node tree
  depth first, children in file order.
- Strips and fans are expanded with the glTF spec's vertex order (glTF 2.0 §3.7.2.1), so the
  winding is preserved; degenerate triangles are kept. Trailing indices of a TRIANGLES primitive
  that do not make a whole triangle are dropped.
- Node rotations are normalised quaternions; scale, negative or non-uniform, is kept exactly.
- Every problem with the file is an ``InputError`` naming the file, the glTF JSON path and a fix.
"""

from __future__ import annotations

import base64
import binascii
import dataclasses
import json
import math
import os
import struct
import urllib.parse
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np
import pygltflib

from baker.errors import InputError
from baker.gltf import budget
from baker.gltf import document as gltf_document
from baker.gltf import images
from baker.gltf.decompress import (
    COMPRESSION_EXTENSIONS,
    compressed,
    decompressed,
    draco_declared_bytes,
    is_meshopt_fallback,
)
from baker.gltf.document import COMPONENT_DTYPES
from baker.gltf.files import SceneFolder, read_descriptor
from baker.gltf.materials import (
    MIRROR_ROUGHNESS,
    UNLIT_REASON,
    classify,
    no_lightmap_reason,
)
from baker.gltf.references import check_references, texture_slots
from baker.gltf.scene import (
    REPEAT,
    Image,
    Instance,
    Light,
    Material,
    Primitive,
    Scene,
    Skipped,
    TextureRef,
)

VIEW_ONLY_EXTENSIONS = frozenset(
    {
        "KHR_materials_anisotropy",
        "KHR_materials_clearcoat",
        "KHR_materials_dispersion",
        "KHR_materials_emissive_strength",
        "KHR_materials_iridescence",
        "KHR_materials_sheen",
        "KHR_materials_specular",
        "KHR_materials_variants",
    }
)
"""Material extensions that change only what a viewer draws over the lightmap (specular layers,
the default of several material variants, emission's scale, which is read): the diffuse light a
lightmap stores is baked the same with or without them, so they need nothing from baker."""

SUPPORTED_EXTENSIONS = VIEW_ONLY_EXTENSIONS | COMPRESSION_EXTENSIONS | frozenset(
    {
        "KHR_materials_unlit",
        "KHR_texture_transform",
        "KHR_materials_transmission",
        "KHR_materials_volume",
        "KHR_materials_ior",
        "KHR_materials_pbrSpecularGlossiness",
        "KHR_lights_punctual",
        "EXT_mesh_gpu_instancing",
        "KHR_mesh_quantization",
        "KHR_materials_diffuse_transmission",
        "EXT_texture_webp",  # decoded (images.py); a texture's image only in them is required
        "KHR_texture_basisu",  # there, and without its decoder the texture's factor is used
    }
)
"""Extensions a file may list in ``extensionsRequired`` and still be baked."""

MATERIAL_EXTENSIONS = VIEW_ONLY_EXTENSIONS | frozenset(
    {
        "KHR_materials_unlit",
        "KHR_materials_transmission",
        "KHR_materials_volume",
        "KHR_materials_ior",
        "KHR_materials_diffuse_transmission",
        "KHR_materials_pbrSpecularGlossiness",
    }
)
"""Material extensions the bake reads (``materials.classify``) or has no need of
(``VIEW_ONLY_EXTENSIONS``); any other one on a material (a vendor's, a new one) is left out
with a warning."""

_SPEC_GLOSS = "KHR_materials_pbrSpecularGlossiness"

# componentType → the divisor of normalized integers (glTF §3.11).
_NORMALIZED_DIVISORS = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0, 5125: 4294967295.0}
# accessor type → (columns, rows); a matrix is stored column by column.
_TYPE_SHAPES = {
    "SCALAR": (1, 1),
    "VEC2": (1, 2),
    "VEC3": (1, 3),
    "VEC4": (1, 4),
    "MAT2": (2, 2),
    "MAT3": (3, 3),
    "MAT4": (4, 4),
}
_MODE_NAMES = {
    0: "POINTS",
    1: "LINES",
    2: "LINE_LOOP",
    3: "LINE_STRIP",
    4: "TRIANGLES",
    5: "TRIANGLE_STRIP",
    6: "TRIANGLE_FAN",
}
_TRIANGLES, _STRIP, _FAN = 4, 5, 6
_GLB_MAGIC = b"glTF"
_CHUNK_JSON = 0x4E4F534A
_CHUNK_BIN = 0x004E4942

_REEXPORT = "re-export the asset from your DCC tool; the Khronos glTF Validator shows what is wrong"
MAX_JSON_DEPTH = 64
"""Deepest nesting of arrays and objects in the glTF JSON (glTF's own is 5; extras may add)."""
MAX_INTEGER_DIGITS = 400
"""Longest integer in the glTF JSON: glTF's are below 2^53 (16 digits), but a float of the input
(1e300) written back as an integer index has up to 309; Python refuses 4,300, and converting
10^5 digits takes seconds."""
MAX_WORLD_UNITS = 1e12
"""Farthest a mesh may lie from the origin, in scene units (Embree's float32 has a resolution of
1e5 units there already; a scale of 1e300 would overflow every later computation)."""
MAX_SCENE_COMPONENTS = 1 << 28
"""Most numbers the accessors baker reads may declare in all (2 GiB as float64: some 40 million
vertices with normals and UVs); those without a bufferView, ``budget.MAX_UNBACKED_NUMBERS``."""
_GPU_REASON = "GPU-instanced (EXT_mesh_gpu_instancing): occluder only"
_SKIN_REASON = "skinned: occluder only (rest pose)"
_UNLIT_REASON = UNLIT_REASON
_MOVING = "node-animated (an animation moves it or an ancestor)"
_MOVING_REASON = {  # what becomes of a node-animated instance, by ``Settings.animated``
    "bake": f"{_MOVING}: baked in its rest pose, its lightmap does not follow the animation "
            "(--animated occlude or skip leaves it out)",
    "occlude": f"{_MOVING}: occluder only (rest pose), no lightmap (--animated occlude)",
    "skip": f"{_MOVING}: left out, not even as an occluder (--animated skip)",
}
_MORPH_REASON = "morph-animated (animated weights): occluder only (rest pose)"


@dataclass
class _Context:
    """What every reading step needs: the document, its buffers as bytes, where the file lives,
    and the list of things left out so far."""

    document: pygltflib.GLTF2
    buffers: list[bytes]
    file: str
    folder: SceneFolder | None  # None once the load is done (``image_pixels``)
    skipped: list[Skipped] = field(default_factory=list)
    decoded: dict[int, np.ndarray] = field(default_factory=dict)  # image index → (h, w, 4) uint8
    image_files: dict[int, bytes] = field(default_factory=dict)  # image index → its file's bytes
    headers: dict[int, images.Header] = field(default_factory=dict)  # image index → its header

    def skip(self, where: str, reason: str) -> None:
        """Record something left out, once."""
        entry = Skipped(where=where, reason=reason)
        if entry not in self.skipped:
            self.skipped.append(entry)


# --------------------------------------------------------------------------------------------
# Entry point


def load(path: str | Path, mirror_roughness: float = MIRROR_ROUGHNESS,
         animated: str = "bake", hard_links: bool = False, contained: bool = False) -> Scene:
    """Read a ``.gltf`` or ``.glb`` file into a ``Scene`` (see ``baker.gltf.scene``).

    Geometry stays in each mesh's local space (glTF units, metres); ``Instance.world`` is the
    (4, 4) float64 local-to-world matrix. Raises ``InputError`` for anything in the file that
    baker cannot read, naming the file, the glTF JSON path and what to do. ``mirror_roughness``:
    metals smoother than this are mirrors (``materials.classify``), which get no lightmap.
    ``animated``: what becomes of node-animated instances (an animation drives the transform
    of their node or of an ancestor): "bake" them in their rest pose with a warning, keep them
    as "occlude"rs only (rest pose, no texels), or "skip" them (no instance at all: neither
    baked nor casting shadows); each is listed with its reason in ``Scene.skipped``.
    ``hard_links``: read files the URIs name that have other names too (``files.SceneFolder``).
    ``contained``: the scene file itself is opened as the files it names are (inside its
    folder, no link out, one name): for files as untrusted as their contents (``baker hook``).

    Every file is opened once, relative to the scene's folder, and the whole input is checked
    against ``gltf.budget`` before anything is allocated for it: the nodes, the buffers'
    declared bytes, the accessors the meshes use, then every image's header.
    """
    path = Path(path)
    with SceneFolder(path.parent, str(path), hard_links) as folder:
        spent = budget.Budget(str(path))
        document = read_document(path, folder if contained else None, spent)
        ctx = _Context(document, [], str(path), folder)
        placements = _walk_nodes(ctx)
        _check_declared_sizes(ctx, placements)
        check_buffer_budget(document, str(path), spent)
        ctx.buffers = resolve_buffers(document, folder)
        if compressed(document):
            ctx.document, ctx.buffers = decompressed(document, ctx.buffers, str(path))
        _read_images(ctx, spent)
        materials = _read_materials(ctx)
        _check_images(ctx)
        images = _images(ctx)
        unbaked = [no_lightmap_reason(classify(m, images, mirror_roughness)) for m in materials]
        primitives, instances = _instantiate(ctx, placements, materials, unbaked, animated)
        lights = _read_lights(ctx, placements)
    return Scene(
        path=path,
        document=ctx.document,
        primitives=tuple(primitives),
        instances=tuple(instances),
        materials=tuple(materials),
        images=images,
        skipped=tuple(ctx.skipped),
        lights=lights,
        mirror_roughness=float(mirror_roughness),
        buffers=tuple(ctx.buffers),
        inputs=dict(folder.opened),
    )


# --------------------------------------------------------------------------------------------
# File, JSON, GLB container


def read_document(path: str | Path, folder: SceneFolder | None = None, contained: bool = False,
                  spent: budget.Budget | None = None) -> pygltflib.GLTF2:
    """Parse a ``.gltf`` or ``.glb`` file into a pygltflib document, checking what baker relies on.

    A GLB's binary chunk is kept as ``document.binary_blob()``; ``document._path`` and
    ``document._name`` are set as ``pygltflib.GLTF2.load`` sets them. The file is read through
    ``folder`` (its folder, opened: ``files.SceneFolder.read_scene``; ``contained`` as there) and
    counted in ``spent`` (the input's budget), each made here when not given.
    """
    path = Path(path)
    file = str(path)
    spent = spent or budget.Budget(file)
    if folder is None:
        with SceneFolder(path.parent, file) as own:
            data = own.read_scene(path, contained, budget.MAX_INPUT_BYTES)
    else:
        data = folder.read_scene(path, contained, budget.MAX_INPUT_BYTES)
    spent.spend(len(data), "the scene file", "")
    if data[:4] == _GLB_MAGIC:
        text, blob = _split_glb(data, file)
    else:
        text, blob = _decode_text(data, file), None
    raw = _parse_json(text, file)
    _check_asset(raw, file)
    _check_arrays(raw, file)
    budget.check_nodes(raw, file)
    check_references(raw, file)
    _check_required_extensions(raw, file)
    try:
        document = _document_from_json(text, raw)
    except Exception as exc:  # dataclasses_json raises whatever the mismatch provokes
        raise InputError(
            f"not a glTF 2.0 document pygltflib can read ({type(exc).__name__}: {exc})",
            file=file,
            fix=_REEXPORT,
        ) from exc
    if blob is not None:
        document.set_binary_blob(blob)
    document._path = path.parent
    document._name = path.name
    return document


def used_uris(path: str | Path) -> list[tuple[str, str]]:
    """(JSON path, URI) of every file the scene at ``path`` names (its buffers' and images'),
    none when it cannot be read or parsed. For ``baker watch`` (``file_stamps``)."""
    path = Path(path)
    try:
        with SceneFolder(path.parent, str(path)) as folder:
            data = folder.read_scene(path, False, budget.MAX_INPUT_BYTES)
        text = _split_glb(data, str(path))[0] if data[:4] == _GLB_MAGIC else _decode_text(data, "")
        raw = _parse_json(text, str(path))
    except InputError:
        return []
    out = []
    for kind in ("buffers", "images"):
        items = raw.get(kind)
        for i, item in enumerate(items if isinstance(items, list) else []):
            uri = item.get("uri") if isinstance(item, dict) else None
            if isinstance(uri, str) and not uri.startswith("data:"):
                out.append((f"{kind}[{i}].uri", uri))
    return out


def file_stamps(path: str | Path, uris: list[tuple[str, str]]) -> tuple:
    """(size, modification time) of the scene file at ``path`` and of each file of ``uris``
    (``used_uris``) as opened (``files.SceneFolder``), None for one that cannot be: what
    changes when any of them does, for ``baker watch``."""
    path = Path(path)
    try:
        folder = SceneFolder(path.parent, str(path))
    except InputError:
        return (None,)
    stamps = []
    with folder:
        for at, uri in [("", None)] + uris:
            try:
                descriptor = (folder.open(uri, at)[0] if uri is not None
                              else os.open(path, os.O_RDONLY | os.O_NONBLOCK))
            except (InputError, OSError):
                stamps.append(None)
                continue
            try:
                info = os.fstat(descriptor)
                stamps.append((info.st_size, info.st_mtime_ns))
            finally:
                os.close(descriptor)
    return tuple(stamps)


def _document_from_json(text: str, raw: dict) -> pygltflib.GLTF2:
    """pygltflib's document of the JSON ``text`` (parsed: ``raw``): made directly
    (``gltf_document.document``, 50 ms sooner for 60 nodes, 5 s for 10 000), or by pygltflib
    itself when a value has another type than its field's."""
    try:
        return gltf_document.document(raw)
    except gltf_document.NotPlain:
        return pygltflib.GLTF2.gltf_from_json(text)


def _split_glb(data: bytes, file: str) -> tuple[str, bytes | None]:
    """Split a GLB container into its JSON text and its binary chunk (None when it has none)."""
    fix = "the file was cut short or is damaged: copy or export it again"
    if len(data) < 20:
        raise InputError(
            f"truncated GLB: {len(data)} bytes, too short for a header",
            file=file,
            where="GLB header",
            fix=fix,
        )
    version, length = struct.unpack_from("<II", data, 4)
    if version != 2:
        raise InputError(
            f"GLB container version {version}: baker reads version 2 (glTF 2.0)",
            file=file,
            where="GLB header",
            fix="convert the file to glTF 2.0, e.g. by re-exporting it",
        )
    if length > len(data):
        raise InputError(
            f"truncated GLB: the header says {length} bytes but the file has {len(data)}",
            file=file,
            where="GLB header",
            fix=fix,
        )
    text, blob, offset, chunk = None, None, 12, 0
    while offset < length:
        if offset + 8 > length:
            raise InputError(
                f"truncated GLB: chunk {chunk} has no complete header",
                file=file,
                where=f"GLB chunk {chunk}",
                fix=fix,
            )
        size, kind = struct.unpack_from("<II", data, offset)
        start, end = offset + 8, offset + 8 + size
        if end > length:
            raise InputError(
                f"truncated GLB: chunk {chunk} needs {size} bytes but only {length - start} remain",
                file=file,
                where=f"GLB chunk {chunk}",
                fix=fix,
            )
        if chunk == 0 and kind != _CHUNK_JSON:
            raise InputError("GLB's first chunk is not JSON", file=file, where="GLB chunk 0", fix=fix)
        if chunk == 0:
            text = _decode_text(data[start:end], file)
        elif chunk == 1 and kind == _CHUNK_BIN:
            blob = data[start:end]
        offset, chunk = end, chunk + 1
    if text is None:
        raise InputError("GLB has no JSON chunk", file=file, where="GLB chunk 0", fix=fix)
    return text, blob


def _decode_text(data: bytes, file: str) -> str:
    """The glTF JSON as text (UTF-8, a byte-order mark tolerated)."""
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise InputError(
            "not a glTF file: neither a GLB container nor UTF-8 JSON text",
            file=file,
            fix="give baker a .gltf or .glb file",
        ) from None


class _LongNumber(Exception):
    """An integer in the JSON with more digits than ``MAX_INTEGER_DIGITS``."""


def _bounded_int(text: str) -> int:
    """``int(text)`` for the JSON parser, refusing integers of more than ``MAX_INTEGER_DIGITS``
    digits (converting 10^5 digits takes seconds; Python refuses 4300 with a ValueError)."""
    if len(text) > MAX_INTEGER_DIGITS + 1:
        raise _LongNumber(len(text.lstrip("-")))
    return int(text)


def _parse_json(text: str, file: str) -> dict:
    """The top-level JSON object; a syntax error names its line and column. Integers are at most
    ``MAX_INTEGER_DIGITS`` digits long and arrays and objects nested at most ``MAX_JSON_DEPTH``
    deep (extras nested 10^5 deep overflowed Python's stack, in the parser or after it)."""
    too_deep = InputError(f"the JSON is nested more than {MAX_JSON_DEPTH} arrays or objects deep",
                          file=file, fix="re-export the file; glTF needs a few levels")
    try:
        raw = json.loads(text, parse_int=_bounded_int)
    except _LongNumber as exc:
        raise InputError(f"the JSON holds an integer of {exc.args[0]:,} digits (baker reads at "
                         f"most {MAX_INTEGER_DIGITS})", file=file,
                         fix="re-export the file; if it was edited by hand, fix that number") from None
    except RecursionError:
        raise too_deep from None
    except json.JSONDecodeError as exc:
        raise InputError(
            f"not valid JSON: {exc.msg} at line {exc.lineno}, column {exc.colno}",
            file=file,
            where=f"line {exc.lineno}",
            fix="re-export the file; if it was edited by hand, fix the JSON at that line",
        ) from None
    if not isinstance(raw, dict):
        raise InputError(
            "not a glTF file: the JSON is not an object",
            file=file,
            fix="give baker a .gltf or .glb file",
        )
    if _depth(raw) > MAX_JSON_DEPTH:
        raise too_deep
    return raw


def _depth(value: Any) -> int:
    """How deep arrays and objects nest in the parsed JSON ``value`` (a scalar: 0), walked
    without recursion."""
    deepest, level = 0, [(value, 1)]
    while level:
        item, depth = level.pop()
        children = item.values() if isinstance(item, dict) else item if isinstance(item, list) else None
        if children is None:
            continue
        deepest = max(deepest, depth)
        level.extend((child, depth + 1) for child in children if isinstance(child, (dict, list)))
    return deepest


def _check_asset(raw: dict, file: str) -> None:
    """Require ``asset.version`` 2.x."""
    asset = raw.get("asset")
    if not isinstance(asset, dict):
        raise InputError(
            "no asset object: not a glTF 2.0 file",
            file=file,
            where="asset",
            fix="give baker a glTF 2.0 .gltf or .glb file",
        )
    version = asset.get("version")
    if not isinstance(version, str) or not version.startswith("2."):
        raise InputError(
            f"asset.version is {json.dumps(version)}: baker reads glTF 2.x only",
            file=file,
            where="asset.version",
            fix="convert the file to glTF 2.0: re-export it, or run Khronos gltf-pipeline on glTF 1.0",
        )


_TOP_LEVEL_ARRAYS = (
    "accessors",
    "animations",
    "buffers",
    "bufferViews",
    "cameras",
    "images",
    "materials",
    "meshes",
    "nodes",
    "samplers",
    "scenes",
    "skins",
    "textures",
)


def _check_arrays(raw: dict, file: str) -> None:
    """Require the top-level glTF arrays, where present, to be arrays of objects."""
    for key in _TOP_LEVEL_ARRAYS:
        items = raw.get(key, [])
        if not isinstance(items, list):
            raise _invalid(f"{key} is not an array", file, key)
        for i, item in enumerate(items):
            if not isinstance(item, dict):
                raise _invalid("is not a JSON object", file, f"{key}[{i}]")


def _check_required_extensions(raw: dict, file: str) -> None:
    """Refuse a file that requires an extension baker cannot honour, naming what each one is."""
    required = raw.get("extensionsRequired") or []
    if not isinstance(required, list):
        raise _invalid("extensionsRequired is not a list", file, "extensionsRequired")
    missing = [str(name) for name in required if name not in SUPPORTED_EXTENSIONS]
    if missing:
        names = ", ".join(missing)
        kinds = "; ".join(f"{name}: {_unsupported_kind(name)}" for name in missing)
        raise InputError(
            f"the file requires {names}, which baker does not support ({kinds})",
            file=file,
            where="extensionsRequired",
            fix=f"re-export without {names}",
        )


def _unsupported_kind(name: str) -> str:
    """What an extension baker does not support is, from its name, for the refusal's message."""
    if "compression" in name:
        return "compressed geometry"
    if name.startswith(("KHR_texture_", "EXT_texture_")):
        return "a texture format or sampling extension"
    if "_materials_" in name:
        return "a material extension"
    return "an extension baker does not know"


# --------------------------------------------------------------------------------------------
# Buffers and URIs


def check_buffer_budget(document: pygltflib.GLTF2, file: str, spent: budget.Budget) -> None:
    """Check every buffer's declared byteLength, before any is read, against the input's
    budget (``budget.check_buffers``): files, bytes embedded in the scene file, and the
    meshopt fallback buffers and Draco primitives that compressed geometry decodes into."""
    blob = document.binary_blob()
    lengths = []
    for i, buffer in enumerate(document.buffers or []):
        embedded = (buffer.uri is None and i == 0 and blob is not None) or (
            isinstance(buffer.uri, str) and buffer.uri.startswith("data:"))
        kind = ("embedded" if embedded else "file" if buffer.uri is not None
                else "decoded" if is_meshopt_fallback(buffer) else "embedded")
        lengths.append((f"buffers[{i}]", buffer.byteLength, kind))
    budget.check_buffers(lengths, draco_declared_bytes(document), spent)


def resolve_buffers(document: pygltflib.GLTF2, folder: SceneFolder) -> list[bytes]:
    """The bytes of every ``document.buffers[i]``, exactly ``byteLength`` of them.

    A buffer without ``uri`` is the GLB binary chunk; a ``data:`` URI is decoded; any other URI is
    a file inside the scene's ``folder``, percent-decoded (``files.SceneFolder``).
    """
    blob = document.binary_blob()
    out = []
    for i, buffer in enumerate(document.buffers):
        where = f"buffers[{i}]"
        with _schema(folder.file, where):
            out.append(_buffer_bytes(buffer, blob if i == 0 else None, folder, where))
    return out


def _buffer_bytes(buffer: pygltflib.Buffer, blob: bytes | None, folder: SceneFolder,
                  where: str) -> bytes:
    """The ``byteLength`` bytes of one buffer: ``blob`` (GLB binary chunk) when it has no uri; of
    a file, at most ``byteLength`` bytes are read."""
    file = folder.file
    length = buffer.byteLength
    if not isinstance(length, int) or isinstance(length, bool) or length < 0:
        raise _invalid(f"byteLength {length!r} is not a byte count", file, where)
    if buffer.uri is None:
        if blob is None and is_meshopt_fallback(buffer):
            return bytes(length)  # where decompress.decompressed puts the decoded views
        if blob is None:
            raise _invalid("buffer has no uri and the file has no GLB binary chunk for it", file, where)
        data = blob
    elif isinstance(buffer.uri, str) and buffer.uri.startswith("data:"):
        data = _decode_data_uri(buffer.uri, file, where)
    else:
        data = folder.read(buffer.uri, f"{where}.uri", length)
    if len(data) < length:
        raise InputError(
            f"buffer holds {len(data)} bytes but its byteLength is {length}",
            file=file,
            where=where,
            fix="the binary data is incomplete or from another export: export the asset again",
        )
    return data if len(data) == length else bytes(data[:length])


def _decode_data_uri(uri: str, file: str, where: str) -> bytes:
    """Decode ``data:[<mime>][;base64],<payload>``."""
    header, comma, payload = uri[5:].partition(",")
    fix = "the embedded data is damaged: export the asset again"
    if not comma:
        raise InputError("bad data URI: no comma before the data", file=file, where=f"{where}.uri", fix=fix)
    if not header.endswith(";base64"):
        return urllib.parse.unquote_to_bytes(payload)
    try:
        return base64.b64decode(payload, validate=True)
    except (binascii.Error, ValueError) as exc:
        raise InputError(
            f"bad data URI: invalid base64 ({exc})",
            file=file,
            where=f"{where}.uri",
            fix=fix,
        ) from None


# --------------------------------------------------------------------------------------------
# Accessors


def read_accessor(
    document: pygltflib.GLTF2, buffers: Sequence[bytes], index: int, *, file: str = ""
) -> np.ndarray:
    """The elements of ``document.accessors[index]`` as a (count, ncomp) array.

    ncomp is 1, 2, 3, 4, 4, 9 or 16 for SCALAR … MAT4 (matrices column-major, as stored).
    float64 for FLOAT and for ``normalized`` integers (mapped to [0, 1] or [-1, 1] per glTF §3.11),
    int64 for integers that are not normalized (indices; quantized data, which callers cast).
    Honours byteOffset of accessor and bufferView, byteStride, matrix column alignment, accessors
    without bufferView (zeros) and sparse substitution. ``file`` only goes into error messages.
    """
    where = f"accessors[{index}]"
    accessor = _item(document.accessors, index, "accessors", file, where)
    with _schema(file, where):
        dtype = COMPONENT_DTYPES.get(accessor.componentType)
        if dtype is None:
            raise _invalid(
                f"componentType {accessor.componentType} is not a glTF component type", file, where
            )
        shape = _TYPE_SHAPES.get(accessor.type)
        if shape is None:
            raise _invalid(f"type {accessor.type!r} is not a glTF accessor type", file, where)
        count = accessor.count
        if not isinstance(count, int) or count < 0:
            raise _invalid(f"count {count!r} is not an element count", file, where)
        if accessor.bufferView is None:
            if count * shape[0] * shape[1] > budget.MAX_UNBACKED_NUMBERS:
                raise _invalid(f"count {count:,} is too large for an accessor without a bufferView",
                               file, where)
            raw = np.zeros((count, shape[0] * shape[1]), dtype)
        else:
            view, stride = _buffer_view(document, buffers, accessor.bufferView, file, f"{where}.bufferView")
            raw = _elements(view, accessor.byteOffset or 0, count, dtype, shape, stride, file, where)
        if accessor.sparse is not None:
            _substitute_sparse(document, buffers, accessor.sparse, raw, shape, file, f"{where}.sparse")
        return _to_numbers(raw, accessor.componentType, bool(accessor.normalized))


def _buffer_view(
    document: pygltflib.GLTF2, buffers: Sequence[bytes], index: int, file: str, referrer: str
) -> tuple[memoryview, int | None]:
    """The bytes of ``document.bufferViews[index]`` (bounds checked) and its byteStride."""
    view = _item(document.bufferViews, index, "bufferViews", file, referrer)
    where = f"bufferViews[{index}]"
    data = _item(buffers, view.buffer, "buffers", file, f"{where}.buffer")
    start, length = view.byteOffset or 0, view.byteLength
    if not isinstance(length, int) or length < 0 or not isinstance(start, int) or start < 0:
        raise _invalid("byteOffset/byteLength are not byte counts", file, where)
    if start + length > len(data):
        raise InputError(
            f"bufferView spans bytes {start}–{start + length} but buffers[{view.buffer}] has {len(data)}",
            file=file,
            where=where,
            fix="the binary data does not match the JSON: export the asset again",
        )
    stride = view.byteStride
    if stride is not None and (not isinstance(stride, int) or stride <= 0):
        raise _invalid(f"byteStride {stride!r} is not a positive byte count", file, where)
    return memoryview(data)[start : start + length], stride


def _elements(
    view: memoryview,
    offset: int,
    count: int,
    dtype: np.dtype,
    shape: tuple[int, int],
    stride: int | None,
    file: str,
    where: str,
) -> np.ndarray:
    """Copy ``count`` elements of (columns, rows) components out of ``view`` into (count, ncomp).

    Elements start ``stride`` bytes apart (tightly packed when None); matrix columns start on
    4-byte boundaries (glTF §3.6.2.4). Bounds are checked against the view.
    """
    columns, rows = shape
    size = dtype.itemsize
    column_bytes = rows * size
    column_stride = column_bytes if columns == 1 else -(-column_bytes // 4) * 4
    extent = column_stride * (columns - 1) + column_bytes
    stride = stride or column_stride * columns
    if stride < extent:
        raise _invalid(f"byteStride {stride} is smaller than one element ({extent} bytes)", file, where)
    if not isinstance(offset, int) or offset < 0:
        raise _invalid(f"byteOffset {offset!r} is not a byte count", file, where)
    end = offset + (stride * (count - 1) + extent if count else 0)
    if end > len(view):
        raise InputError(
            f"{count} elements from byte {offset} need {end} bytes but the bufferView has {len(view)}",
            file=file,
            where=where,
            fix="the binary data does not match the JSON: export the asset again",
        )
    if count == 0:
        return np.zeros((0, columns * rows), dtype)
    strides = (stride, column_stride, size)
    strided = np.ndarray((count, columns, rows), dtype, buffer=view, offset=offset, strides=strides)
    return np.array(strided).reshape(count, columns * rows)


def _substitute_sparse(
    document: pygltflib.GLTF2,
    buffers: Sequence[bytes],
    sparse: Any,
    raw: np.ndarray,
    shape: tuple[int, int],
    file: str,
    where: str,
) -> None:
    """Write a sparse accessor's values, laid out as ``shape`` (columns, rows), into ``raw``
    (count, ncomp) at its indices, in place."""
    count = sparse.count
    if not isinstance(count, int) or count < 0:
        raise _invalid(f"count {count!r} is not an element count", file, where)
    index_type = sparse.indices.componentType
    if index_type not in (5121, 5123, 5125):
        raise _invalid(
            f"indices.componentType {index_type} is not an unsigned integer type", file, f"{where}.indices"
        )
    view, _ = _buffer_view(document, buffers, sparse.indices.bufferView, file, f"{where}.indices.bufferView")
    offset, dtype = sparse.indices.byteOffset or 0, COMPONENT_DTYPES[index_type]
    indices = _elements(view, offset, count, dtype, (1, 1), None, file, f"{where}.indices")
    indices = indices[:, 0].astype(np.int64)
    if indices.size and indices.max() >= len(raw):
        raise _invalid(
            f"sparse index {indices.max()} is past the accessor's {len(raw)} elements",
            file,
            f"{where}.indices",
        )
    view, _ = _buffer_view(document, buffers, sparse.values.bufferView, file, f"{where}.values.bufferView")
    offset = sparse.values.byteOffset or 0
    values = _elements(view, offset, count, raw.dtype, shape, None, file, f"{where}.values")
    raw[indices] = values


def _to_numbers(raw: np.ndarray, component_type: int, normalized: bool) -> np.ndarray:
    """float64 for floats and normalized integers (signed ones clamped at -1), else int64."""
    if component_type == 5126:
        return raw.astype(np.float64)
    if normalized:
        values = raw.astype(np.float64) / _NORMALIZED_DIVISORS[component_type]
        return np.maximum(values, -1.0) if raw.dtype.kind == "i" else values
    return raw.astype(np.int64)


# --------------------------------------------------------------------------------------------
# Materials and images


def _read_materials(ctx: _Context) -> list[Material]:
    """One Material per glTF material, then the default material (index None) last."""
    materials = []
    for i, material in enumerate(ctx.document.materials):
        with _schema(ctx.file, f"materials[{i}]"):
            materials.append(_read_material(ctx, i, material))
    default = Material(
        index=None,
        name="default",
        base_color=np.ones(4),
        base_color_texture=None,
        emissive=np.zeros(3),
        emissive_texture=None,
    )
    return materials + [default]


def _read_material(ctx: _Context, i: int, material: pygltflib.Material) -> Material:
    """The baker's view of ``materials[i]``: factors as float64 linear values, texture refs."""
    where = f"materials[{i}]"
    extensions = material.extensions or {}
    strength = (extensions.get("KHR_materials_emissive_strength") or {}).get("emissiveStrength", 1.0)
    base = _base_terms(ctx, material, extensions, where)
    emissive = _factor(ctx, material.emissiveFactor, [0.0, 0.0, 0.0], f"{where}.emissiveFactor")
    alpha_mode = material.alphaMode or "OPAQUE"
    if alpha_mode not in ("OPAQUE", "MASK", "BLEND"):
        ctx.skip(f"{where}.alphaMode", f"alphaMode {alpha_mode!r} is not OPAQUE, MASK or BLEND: "
                                       "baked as OPAQUE")
        alpha_mode = "OPAQUE"
    for name in extensions:
        if name not in MATERIAL_EXTENSIONS:
            ctx.skip(f"{where}.extensions.{name}", f"{name} is not understood by baker: baked "
                                                   "without it (core metallic-roughness material)")
    volume = _extension(extensions, "KHR_materials_volume")
    diffuse_transmission = _extension(extensions, "KHR_materials_diffuse_transmission")
    ext = f"{where}.extensions"

    def value(values: Any, key: str, default: float, low: float, high: float, at: str) -> float:
        return _material_number(ctx, values, key, default, low, high, f"{at}.{key}")
    return Material(
        index=i,
        name=material.name or "",
        **base,
        emissive=_emission(ctx, emissive, strength, where),
        emissive_texture=_texture_ref(ctx, material.emissiveTexture, f"{where}.emissiveTexture"),
        occlusion_texture=_texture_ref(ctx, material.occlusionTexture,
                                       f"{where}.occlusionTexture"),
        alpha_mode=alpha_mode,
        alpha_cutoff=value({"alphaCutoff": material.alphaCutoff}, "alphaCutoff", 0.5, 0.0,
                           math.inf, where),
        double_sided=bool(material.doubleSided),
        unlit="KHR_materials_unlit" in extensions,
        extensions=tuple(extensions),
        transmission=value(_extension(extensions, "KHR_materials_transmission"),
                           "transmissionFactor", 0.0, 0.0, 1.0, f"{ext}.KHR_materials_transmission"),
        ior=value(_extension(extensions, "KHR_materials_ior"), "ior", 1.5, 1.0, math.inf,
                  f"{ext}.KHR_materials_ior"),
        thickness=value(volume, "thicknessFactor", 0.0, 0.0, math.inf,
                        f"{ext}.KHR_materials_volume"),
        attenuation_distance=value(volume, "attenuationDistance", math.inf, 1e-300, math.inf,
                                   f"{ext}.KHR_materials_volume"),
        attenuation_color=_factor(ctx, volume.get("attenuationColor"), [1.0, 1.0, 1.0],
                                  f"{where}.extensions.KHR_materials_volume.attenuationColor"),
        diffuse_transmission=value(diffuse_transmission, "diffuseTransmissionFactor", 0.0, 0.0, 1.0,
                                   f"{ext}.KHR_materials_diffuse_transmission"),
        diffuse_transmission_color=_factor(
            ctx, diffuse_transmission.get("diffuseTransmissionColorFactor"), [1.0, 1.0, 1.0],
            f"{where}.extensions.KHR_materials_diffuse_transmission.diffuseTransmissionColorFactor"),
    )


def _base_terms(ctx: _Context, material: pygltflib.Material, extensions: dict,
                where: str) -> dict[str, Any]:
    """The Material fields of the base layer: base colour factor and texture, metallic,
    roughness and their texture, from pbrMetallicRoughness, or from
    KHR_materials_pbrSpecularGlossiness when the material has it (the extension replaces the
    core terms): its diffuseFactor/diffuseTexture are the diffuse albedo a lightmap needs, as a
    dielectric (metallic 0) of roughness 1 − glossinessFactor."""
    spec_gloss = extensions.get(_SPEC_GLOSS)
    if isinstance(spec_gloss, dict):
        at = f"{where}.extensions.{_SPEC_GLOSS}"
        texture = spec_gloss.get("diffuseTexture")
        info = None
        if isinstance(texture, dict):
            info = pygltflib.TextureInfo(index=texture.get("index"), texCoord=texture.get("texCoord"),
                                         extensions=texture.get("extensions"))
        glossiness = _material_number(ctx, spec_gloss, "glossinessFactor", 1.0, 0.0, 1.0,
                                      f"{at}.glossinessFactor")
        return dict(
            base_color=_factor(ctx, spec_gloss.get("diffuseFactor"), [1.0, 1.0, 1.0, 1.0],
                               f"{at}.diffuseFactor"),
            base_color_texture=_texture_ref(ctx, info, f"{at}.diffuseTexture"),
            metallic=0.0, roughness=1.0 - glossiness, metallic_roughness_texture=None)
    pbr = material.pbrMetallicRoughness or pygltflib.PbrMetallicRoughness()
    at = f"{where}.pbrMetallicRoughness"
    return dict(
        base_color=_factor(ctx, pbr.baseColorFactor, [1.0, 1.0, 1.0, 1.0], f"{at}.baseColorFactor"),
        base_color_texture=_texture_ref(ctx, pbr.baseColorTexture, f"{at}.baseColorTexture"),
        metallic=_material_number(ctx, {"metallicFactor": pbr.metallicFactor}, "metallicFactor",
                                  1.0, 0.0, 1.0, f"{at}.metallicFactor"),
        roughness=_material_number(ctx, {"roughnessFactor": pbr.roughnessFactor}, "roughnessFactor",
                                   1.0, 0.0, 1.0, f"{at}.roughnessFactor"),
        metallic_roughness_texture=_optional_texture(ctx, pbr.metallicRoughnessTexture,
                                                     f"{at}.metallicRoughnessTexture"))


def _optional_texture(ctx: _Context, info: Any, where: str) -> TextureRef | None:
    """``_texture_ref`` for a texture the bake can do without (metallic-roughness): one it
    cannot read is left out and recorded in ``ctx.skipped`` instead of stopping the bake."""
    try:
        return _texture_ref(ctx, info, where)
    except InputError as error:
        ctx.skip(where, f"cannot be read ({error.message}): metallic and roughness factors used alone")
        return None


def _extension(extensions: dict, name: str) -> dict:
    """A material extension's object ({} when absent or not an object)."""
    value = extensions.get(name)
    return value if isinstance(value, dict) else {}


def _material_number(ctx: _Context, values: dict, key: str, default: float, low: float,
                     high: float, where: str) -> float:
    """``values[key]`` as a float in [low, high]: ``default`` when absent (None), and a warning in
    ``ctx.skipped`` when it is not a number or not finite (``default`` used) or out of range
    (clamped). A material value baker cannot use is baked with the default, never a crash."""
    value = values.get(key)
    if value is None:
        return default
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
            math.isfinite(value) or value == default == math.inf):
        ctx.skip(where, f"{value!r} is not a usable number: the default {default} is used")
        return default
    clamped = min(max(float(value), low), high)
    if clamped != value:
        ctx.skip(where, f"{value!r} is outside [{low:g}, {high:g}]: {clamped:g} is used")
    return clamped


def _emission(ctx: _Context, factor: np.ndarray, strength: Any, where: str) -> np.ndarray:
    """emissiveFactor × KHR_materials_emissive_strength, finite and ≥ 0 (1e-6 to 1e6 and beyond
    bake; NaN, infinity or a negative value is refused)."""
    strength_where = f"{where}.extensions.KHR_materials_emissive_strength.emissiveStrength"
    if isinstance(strength, bool) or not isinstance(strength, (int, float)):
        raise _invalid(f"emissiveStrength {strength!r} is not a number", ctx.file, strength_where)
    emission = factor * float(strength)
    if not (np.isfinite(emission).all() and (emission >= 0).all() and strength >= 0):
        raise _invalid(f"emission {factor.tolist()} × {strength!r} is not a finite number ≥ 0",
                       ctx.file, strength_where if not (factor < 0).any() else f"{where}.emissiveFactor")
    return emission


def _factor(ctx: _Context, value: Any, default: list[float], where: str) -> np.ndarray:
    """A material factor as a finite float64 vector of the default's length."""
    vector = np.asarray(_default(value, default), dtype=np.float64)
    if vector.shape != (len(default),) or not np.isfinite(vector).all():
        raise _invalid(f"expected {len(default)} finite numbers, found {value!r}", ctx.file, where)
    return vector


MAX_TEXCOORD_SETS = 32
"""A texture may name TEXCOORD_0 to TEXCOORD_31; past that (or below 0) it is left out: the
world holds one UV array per set up to the highest a material reads."""


def _texture_ref(ctx: _Context, info: Any, where: str) -> TextureRef | None:
    """Resolve a textureInfo to (image, UV set, wrap modes), decoding the image; None if absent.

    The texture's core ``source`` is used, else the image of the first extension whose format
    baker decodes (``EXT_texture_webp``, ``KHR_texture_basisu``, ``EXT_texture_avif``). One
    that this installation cannot decode (KTX 2 without opengl-basisu), or past the pixels the
    bake keeps (``budget.MAX_SAMPLED_PIXELS``), is left out and recorded in ``ctx.skipped``,
    its material's factor used (and only checked); one that does not decode is an InputError.
    ``KHR_texture_transform``: its texCoord override and its UV transform are honoured.
    """
    if info is None:
        return None
    texture = _item(ctx.document.textures, info.index, "textures", ctx.file, f"{where}.index")
    texture_where = f"textures[{info.index}]"
    source, extension = texture.source, None
    if source is None:
        for name, value in (texture.extensions or {}).items():
            if name in images.FORMATS and isinstance(value, dict) and value.get("source") is not None:
                source, extension = value["source"], name
                break
    if source is None:
        ctx.skip(texture_where, "texture has no image source baker reads: left out")
        return None
    _item(ctx.document.images, source, "images", ctx.file, f"{texture_where}.source")
    try:
        with _referred(where):
            _decode_image(ctx, source)
    except (images.Undecodable, budget.OverBudget) as exc:
        named = f" ({extension})" if extension else ""
        ctx.skip(texture_where, f"image {source}{named} not decoded ({exc.message}; {exc.fix}): "
                                "texture left out, its material's factor used")
        return None
    texcoord = int(_default(info.texCoord, 0))
    transform = (info.extensions or {}).get("KHR_texture_transform")
    affine = None
    if isinstance(transform, dict):
        texcoord = int(transform.get("texCoord", texcoord))  # the extension's override (spec)
        affine = _uv_transform(ctx, transform, f"{where}.extensions.KHR_texture_transform")
    if not 0 <= texcoord < MAX_TEXCOORD_SETS:
        ctx.skip(texture_where, f"{where} reads TEXCOORD_{texcoord}, which no primitive may have "
                                f"(0 to {MAX_TEXCOORD_SETS - 1}): texture left out, its "
                                "material's factor used")
        return None
    wrap_s = wrap_t = REPEAT
    if texture.sampler is not None:
        samplers = ctx.document.samplers
        sampler = _item(samplers, texture.sampler, "samplers", ctx.file, f"{texture_where}.sampler")
        wrap_s, wrap_t = _default(sampler.wrapS, REPEAT), _default(sampler.wrapT, REPEAT)
    return TextureRef(image=source, texcoord=texcoord, wrap_s=wrap_s, wrap_t=wrap_t,
                      transform=affine)


def _uv_transform(ctx: _Context, transform: dict, where: str) -> tuple[float, ...] | None:
    """KHR_texture_transform's offset, rotation and scale as ``TextureRef.transform``:
    uv' = offset + R(rotation) · (scale ⊙ uv), with u' = u·cos + v·sin and v' = v·cos − u·sin
    (the extension's matrix T · R · S; the UVs turn counter-clockwise, the image clockwise).
    None when it is the identity; a value that is not finite numbers is left out with a
    warning (the UVs are then used as stored)."""
    try:
        offset = _finite(ctx, _default(transform.get("offset"), [0.0, 0.0]), 2, f"{where}.offset")
        rotation = _finite(ctx, [_default(transform.get("rotation"), 0.0)], 1, f"{where}.rotation")[0]
        scale = _finite(ctx, _default(transform.get("scale"), [1.0, 1.0]), 2, f"{where}.scale")
    except InputError as error:
        ctx.skip(where, f"{error.message}: the texture is sampled with the UVs as stored")
        return None
    cos, sin = math.cos(rotation), math.sin(rotation)
    affine = (scale[0] * cos, scale[1] * sin, offset[0], -scale[0] * sin, scale[1] * cos, offset[1])
    return None if affine == (1.0, 0.0, 0.0, 0.0, 1.0, 0.0) else tuple(float(x) for x in affine)


def _read_images(ctx: _Context, spent: budget.Budget) -> None:
    """Read every image's bytes (a file once: kept in ``ctx.image_files`` for the writer,
    counted in the input's budget ``spent``) and its header (``images.header``: a format its
    textures allow, pixels its bytes can hold), then check the pixels of all of them together
    (``budget.check_pixels``), before any is decoded."""
    allowed, users = _image_formats(ctx.document), _image_users(ctx.document)
    for i in range(len(ctx.document.images)):
        with _referred(users.get(i, f"images[{i}]")):
            _read_image(ctx, i, allowed[i], spent)
    budget.check_pixels([(f"images[{i}]", head.pixels) for i, head in ctx.headers.items()],
                        ctx.file)


def _read_image(ctx: _Context, i: int, allowed: tuple[str, ...], spent: budget.Budget) -> None:
    """Read ``images[i]``'s file (when it is one) and header (``_read_images``)."""
    image, where = ctx.document.images[i], f"images[{i}]"
    if _is_file(image.uri):
        descriptor, size = ctx.folder.open(image.uri, f"{where}.uri")
        try:
            spent.spend(size, f'the image file "{image.uri}"', f"{where}.uri")
            ctx.image_files[i] = read_descriptor(descriptor, size, image.uri, ctx.file,
                                                 f"{where}.uri")
        finally:
            os.close(descriptor)
    data, label = _image_data(ctx, i)
    ctx.headers[i] = images.header(data, allowed, label, ctx.file, where)


def _image_users(document: pygltflib.GLTF2) -> dict[int, str]:
    """The first material texture slot that uses each image (its JSON path, e.g.
    ``materials[0].pbrMetallicRoughness.baseColorTexture``), to name in messages."""
    users: dict[int, str] = {}
    textures = document.textures or []
    for m, material in enumerate(document.materials or []):
        for at, index in texture_slots(dataclasses.asdict(material), f"materials[{m}]"):
            if not isinstance(index, int) or not 0 <= index < len(textures):
                continue
            texture = textures[index]
            sources = [texture.source] + [value.get("source") for value in
                                          (texture.extensions or {}).values()
                                          if isinstance(value, dict)]
            for source in sources:
                if isinstance(source, int):
                    users.setdefault(source, at)
    return users


def _is_file(uri: Any) -> bool:
    """Whether an image's ``uri`` names a file (not a data URI, not absent)."""
    return uri is not None and not (isinstance(uri, str) and uri.startswith("data:"))


def _image_formats(document: pygltflib.GLTF2) -> list[tuple[str, ...]]:
    """The formats each image may have: those every texture naming it allows
    (``images.FORMATS``: PNG or JPEG as a core source, WebP through ``EXT_texture_webp``, …;
    none through an extension baker does not know), any format baker reads when none does."""
    allowed: list[set[str] | None] = [None] * len(document.images or [])

    def name(index: Any, formats: tuple[str, ...]) -> None:
        if isinstance(index, int) and not isinstance(index, bool) and 0 <= index < len(allowed):
            allowed[index] = set(formats) if allowed[index] is None else allowed[index] & set(formats)

    for texture in document.textures or []:
        name(texture.source, images.FORMATS[None])
        for extension, value in (texture.extensions or {}).items():
            if isinstance(value, dict):
                name(value.get("source"), images.FORMATS.get(extension, ()))
    return [images.ANY_FORMAT if formats is None
            else tuple(f for f in images.ANY_FORMAT if f in formats) for formats in allowed]


def _image_data(ctx: _Context, index: int) -> tuple[bytes, str]:
    """The encoded bytes of ``images[index]`` and a label naming it in messages: its file's
    (read by ``_read_images``), its bufferView's or its data URI's."""
    image = ctx.document.images[index]
    where = f"images[{index}]"
    if index in ctx.image_files:
        return ctx.image_files[index], f'"{image.uri}"'
    if image.bufferView is not None:
        view, _ = _buffer_view(ctx.document, ctx.buffers, image.bufferView, ctx.file,
                               f"{where}.bufferView")
        return bytes(view), f"the image in bufferViews[{image.bufferView}]"
    if image.uri is None:
        raise _invalid("image has neither uri nor bufferView", ctx.file, where)
    return _decode_data_uri(image.uri, ctx.file, where), "the embedded image"


def _decode_image(ctx: _Context, index: int, keep: bool = True) -> np.ndarray | None:
    """Decode ``images[index]`` (its header read by ``_read_images``) once: into (h, w, 4) uint8
    RGBA, row 0 at the top (sRGB as stored), kept in ``ctx.decoded`` when ``keep``; else
    decoded only to check it."""
    if index in ctx.decoded:
        return ctx.decoded[index]
    data, label = _image_data(ctx, index)
    head, where = ctx.headers[index], f"images[{index}]"
    if keep:
        budget.check_sampled(sum(p.shape[0] * p.shape[1] for p in ctx.decoded.values()),
                             head.pixels, f"{head.width}×{head.height}", label, ctx.file, where)
    pixels = images.decode(data, head, label, ctx.file, where, keep)
    if keep:
        ctx.decoded[index] = pixels
    return pixels


def image_pixels(scene: Scene, index: int) -> np.ndarray:
    """``scene.images[index]`` as (h, w, 4) uint8 RGBA, decoded again from the bytes the load
    read (its file's, its bufferView's or its data URI's): for an image the bake does not
    sample (``baker preview`` reads the lightmap pages of a baked file)."""
    ctx = _Context(scene.document, list(scene.buffers), str(scene.path), None)
    ctx.image_files = {i: image.data for i, image in enumerate(scene.images)
                       if image.data is not None}
    data, label = _image_data(ctx, index)
    where = f"images[{index}]"
    head = images.header(data, images.ANY_FORMAT, label, ctx.file, where)
    return images.decode(data, head, label, ctx.file, where)


def _check_images(ctx: _Context) -> None:
    """Decode every image the bake does not sample (normal, occlusion, metallic-roughness
    maps, unused images), only to check it: every image an output carries was decoded once.
    One this installation cannot decode (KTX 2 without opengl-basisu) is checked from its
    header alone, and recorded in ``ctx.skipped``."""
    users = _image_users(ctx.document)
    for i in range(len(ctx.document.images)):
        if i in ctx.decoded:
            continue
        try:
            with _referred(users.get(i, f"images[{i}]")):
                _decode_image(ctx, i, keep=False)
        except images.Undecodable as exc:
            ctx.skip(f"images[{i}]", f"checked from its header only: {exc.message} ({exc.fix})")


def _images(ctx: _Context) -> tuple[Image, ...]:
    """One Image per glTF image: decoded when a texture the bake samples uses it, else a 1×1
    white placeholder; with its file's bytes when it is a file."""
    out = []
    for i, image in enumerate(ctx.document.images):
        pixels = ctx.decoded.get(i)
        if pixels is None:
            pixels = np.full((1, 1, 4), 255, np.uint8)
        uri = image.uri if image.uri and not image.uri.startswith("data:") else ""
        out.append(Image(pixels=pixels, name=image.name or uri, data=ctx.image_files.get(i)))
    return tuple(out)


# --------------------------------------------------------------------------------------------
# Meshes and primitives


def _read_mesh(ctx: _Context, mesh: int, material_count: int) -> list[Primitive | None]:
    """The Primitives of ``meshes[mesh]``, None where a primitive is left out (see ``ctx.skipped``)."""
    out = []
    for j, primitive in enumerate(ctx.document.meshes[mesh].primitives):
        where = f"meshes[{mesh}].primitives[{j}]"
        with _schema(ctx.file, where):
            out.append(_read_primitive(ctx, mesh, j, primitive, material_count, where))
    return out


def _read_primitive(
    ctx: _Context, mesh: int, j: int, primitive: pygltflib.Primitive, material_count: int, where: str
) -> Primitive | None:
    """One mesh primitive as local-space triangles, or None (recorded) when it has none."""
    mode = _default(primitive.mode, _TRIANGLES)
    if mode not in (_TRIANGLES, _STRIP, _FAN):
        ctx.skip(where, f"mode {_MODE_NAMES.get(mode, mode)}: not triangles")
        return None
    raw = primitive.attributes
    attributes = {k: v for k, v in (raw if isinstance(raw, dict) else vars(raw)).items() if v is not None}
    if "POSITION" not in attributes:
        ctx.skip(where, "no POSITION attribute: nothing to place")
        return None
    positions = _attribute(ctx, attributes, "POSITION", (3,), None, where)
    n = len(positions)
    bad = np.flatnonzero(~np.isfinite(positions).all(axis=1))
    if bad.size:
        raise InputError(
            f"POSITION has NaN or infinite values ({bad.size} vertices, first vertex {bad[0]})",
            file=ctx.file,
            where=f"{where}.attributes.POSITION",
            fix="clean up the mesh in your DCC tool (e.g. Blender: Mesh > Clean Up) and export again",
        )
    normals = _attribute(ctx, attributes, "NORMAL", (3,), n, where) if "NORMAL" in attributes else None
    colors = _attribute(ctx, attributes, "COLOR_0", (3, 4), n, where) if "COLOR_0" in attributes else None
    if colors is not None and colors.shape[1] == 3:
        colors = np.concatenate([colors, np.ones((n, 1))], axis=1)
    triangles = _triangles(ctx, primitive, mode, n, where)
    if not len(triangles):
        ctx.skip(where, "no whole triangle: nothing to bake or to occlude")
        return None
    return Primitive(
        mesh=mesh,
        index=j,
        positions=positions,
        normals=normals,
        texcoords=_texcoords(ctx, attributes, n, where),
        colors=colors,
        triangles=triangles,
        material=_material_index(ctx, primitive.material, material_count, where),
        has_morph_targets=bool(primitive.targets),
    )


def _attribute(
    ctx: _Context, attributes: dict, name: str, widths: tuple[int, ...], n: int | None, where: str
) -> np.ndarray:
    """Vertex attribute ``name`` as (n, width) float64, its width and vertex count checked."""
    attribute_where = f"{where}.attributes.{name}"
    index = attributes[name]
    _item(ctx.document.accessors, index, "accessors", ctx.file, attribute_where)
    with _referred(attribute_where):
        values = read_accessor(ctx.document, ctx.buffers, index, file=ctx.file).astype(np.float64)
    if values.shape[1] not in widths:
        expected = " or ".join(f"{w} components" for w in widths)
        raise _invalid(
            f"{name} has {values.shape[1]} components per vertex, expected {expected}",
            ctx.file,
            attribute_where,
        )
    if n is not None and len(values) != n:
        raise _invalid(f"{name} has {len(values)} vertices but POSITION has {n}", ctx.file, attribute_where)
    bad = ~np.isfinite(values)
    if name.startswith(("NORMAL", "TEXCOORD_", "COLOR_")) and bad.any():
        fallback = 1.0 if name.startswith("COLOR_") else 0.0
        values = np.where(bad, fallback, values)
        used = " (the triangle's own normal is used)" if name == "NORMAL" else ""
        ctx.skip(attribute_where, f"{int(bad.any(axis=1).sum())} vertices had NaN or infinite "
                                  f"values: set to {fallback:g}{used}")
    return values


def _texcoords(ctx: _Context, attributes: dict, n: int, where: str) -> tuple[np.ndarray, ...]:
    """TEXCOORD_0, TEXCOORD_1, … each (n, 2) float64, up to the first missing set."""
    sets = []
    while f"TEXCOORD_{len(sets)}" in attributes:
        sets.append(_attribute(ctx, attributes, f"TEXCOORD_{len(sets)}", (2,), n, where))
    for name in sorted(k for k in attributes if k.startswith("TEXCOORD_")):
        suffix = name[len("TEXCOORD_") :]
        if suffix.isdigit() and int(suffix) > len(sets):
            reason = f"TEXCOORD_{len(sets)} is missing: UV sets after the gap are not used"
            ctx.skip(f"{where}.attributes.{name}", reason)
    return tuple(sets)


def _triangles(ctx: _Context, primitive: pygltflib.Primitive, mode: int, n: int, where: str) -> np.ndarray:
    """(m, 3) int64 vertex indices, strips and fans expanded, every index checked below n."""
    if primitive.indices is None:
        indices = np.arange(n, dtype=np.int64)
    else:
        _item(ctx.document.accessors, primitive.indices, "accessors", ctx.file, f"{where}.indices")
        with _referred(f"{where}.indices"):
            indices = read_accessor(ctx.document, ctx.buffers, primitive.indices, file=ctx.file)
        if indices.dtype != np.int64 or indices.shape[1] != 1:
            raise _invalid(
                "indices must be a SCALAR accessor of unsigned integers", ctx.file, f"{where}.indices"
            )
        indices = indices[:, 0]
        out_of_range = np.flatnonzero((indices < 0) | (indices >= n))
        if out_of_range.size:
            k = out_of_range[0]
            raise InputError(
                f"index {indices[k]} (element {k}) is out of range: the primitive has {n} vertices",
                file=ctx.file,
                where=f"{where}.indices",
                fix="the index and vertex data do not match: export the asset again",
            )
    return expand_triangles(indices, mode)


def expand_triangles(indices: np.ndarray, mode: int) -> np.ndarray:
    """Turn a (k,) index list of glTF mode 4, 5 or 6 into (m, 3) int64 triangles.

    Strip triangle i is (v_i, v_{i+1+i%2}, v_{i+2-i%2}), fan triangle i is (v_{i+1}, v_{i+2}, v_0),
    as glTF 2.0 §3.7.2.1 writes them, so the winding of the source is kept.
    """
    indices = np.asarray(indices, dtype=np.int64)
    if mode == _TRIANGLES:
        m = len(indices) // 3
        return indices[: 3 * m].reshape(m, 3)
    if len(indices) < 3:
        return np.zeros((0, 3), np.int64)
    i = np.arange(len(indices) - 2)
    if mode == _STRIP:
        odd = i & 1
        return np.stack([indices[i], indices[i + 1 + odd], indices[i + 2 - odd]], axis=1)
    if mode == _FAN:
        return np.stack([indices[i + 1], indices[i + 2], np.full_like(i, indices[0])], axis=1)
    raise ValueError(f"mode {mode} is not a triangle mode")


def _material_index(ctx: _Context, material: int | None, material_count: int, where: str) -> int:
    """Index into Scene.materials: the glTF index, or the default material (last) when None."""
    if material is None:
        return material_count - 1
    _item(ctx.document.materials, material, "materials", ctx.file, f"{where}.material")
    return material


# --------------------------------------------------------------------------------------------
# Nodes and instances


def _walk_nodes(ctx: _Context) -> list[tuple[int, np.ndarray]]:
    """Every node of the scene with its (4, 4) float64 world matrix, depth first, children in order.

    The scene is ``document.scene`` (0 when unset); a file without scenes uses every root node.
    A node reached twice (a cycle, or two parents) is an error: glTF node hierarchies are trees;
    so is one nested deeper than ``budget.MAX_NODE_DEPTH``. The nodes' local matrices are made
    all at once (``_local_matrices``), so that a walk costs a matrix product a node.
    """
    document = ctx.document
    if document.scenes:
        s = _default(document.scene, 0)
        scene = _item(document.scenes, s, "scenes", ctx.file, "scene")
        roots = [_checked_node(ctx, r, f"scenes[{s}].nodes") for r in scene.nodes or []]
    else:
        with _schema(ctx.file, "nodes"):
            children = {c for node in document.nodes for c in node.children or []}
        roots = [i for i in range(len(document.nodes)) if i not in children]
    local = _local_matrices(ctx)
    out, visited = [], set()
    stack = [(root, np.eye(4), 1) for root in reversed(roots)]
    while stack:
        index, parent, depth = stack.pop()
        where = f"nodes[{index}]"
        if index in visited:
            raise InputError(
                "node is reached twice: the node hierarchy has a cycle or a node with two parents",
                file=ctx.file,
                where=where,
                fix="give every node at most one parent (glTF node hierarchies are trees) and export again",
            )
        budget.check_depth(depth, where, ctx.file)
        visited.add(index)
        node = document.nodes[index]
        with _schema(ctx.file, where):
            matrix = local.get(index)
            with np.errstate(over="ignore", invalid="ignore"):  # checked in _check_reach
                world = parent if matrix is None else parent @ matrix
            children = [_checked_node(ctx, c, f"{where}.children") for c in node.children or []]
        out.append((index, world))
        stack.extend((child, world, depth + 1) for child in reversed(children))
    return out


def _checked_node(ctx: _Context, index: Any, referrer: str) -> int:
    """``index`` if it names a node, else an InputError at ``referrer``."""
    _item(ctx.document.nodes, index, "nodes", ctx.file, referrer)
    return index


def _local_matrices(ctx: _Context) -> dict[int, np.ndarray]:
    """Each node's (4, 4) float64 local matrix that is not the identity: its ``matrix``
    (column-major in the file), or T @ R @ S, made for all such nodes at once."""
    matrices: dict[int, np.ndarray] = {}
    trs: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]] = []
    for index, node in enumerate(ctx.document.nodes):
        where = f"nodes[{index}]"
        with _schema(ctx.file, where):
            if node.matrix is not None:
                matrices[index] = _finite(ctx, node.matrix, 16, f"{where}.matrix").reshape(4, 4).T
            elif not (node.translation is None and node.rotation is None and node.scale is None):
                trs.append((index,
                            _finite(ctx, _default(node.translation, [0.0, 0.0, 0.0]), 3,
                                    f"{where}.translation"),
                            _finite(ctx, _default(node.rotation, [0.0, 0.0, 0.0, 1.0]), 4,
                                    f"{where}.rotation"),
                            _finite(ctx, _default(node.scale, [1.0, 1.0, 1.0]), 3,
                                    f"{where}.scale")))
    if trs:
        zero = next((i for i, _, rotation, _ in trs if not np.any(rotation)), None)
        if zero is not None:
            raise _invalid("rotation quaternion has zero length", ctx.file, f"nodes[{zero}]")
        indices, translation, rotation, scale = zip(*trs)
        made = trs_matrices(np.array(translation), np.array(rotation), np.array(scale))
        matrices.update(zip(indices, made))
    return matrices


def trs_matrices(
    translation: np.ndarray, rotation: np.ndarray, scale: np.ndarray, *, file: str = "", where: str = ""
) -> np.ndarray:
    """(k, 4, 4) float64 matrices T @ R @ S from (k, 3) translations, (k, 4) quaternions
    [x, y, z, w] and (k, 3) scales. Quaternions are normalised; scale is used as given."""
    norm = np.linalg.norm(rotation, axis=1)
    if (norm == 0).any():
        raise _invalid("rotation quaternion has zero length", file, where)
    x, y, z, w = (rotation / norm[:, None]).T
    r = np.empty((len(rotation), 3, 3))
    r[:, 0, 0] = 1 - 2 * (y * y + z * z)
    r[:, 0, 1] = 2 * (x * y - z * w)
    r[:, 0, 2] = 2 * (x * z + y * w)
    r[:, 1, 0] = 2 * (x * y + z * w)
    r[:, 1, 1] = 1 - 2 * (x * x + z * z)
    r[:, 1, 2] = 2 * (y * z - x * w)
    r[:, 2, 0] = 2 * (x * z - y * w)
    r[:, 2, 1] = 2 * (y * z + x * w)
    r[:, 2, 2] = 1 - 2 * (x * x + y * y)
    out = np.zeros((len(rotation), 4, 4))
    out[:, :3, :3] = r * scale[:, None, :]
    out[:, :3, 3] = translation
    out[:, 3, 3] = 1.0
    return out


def _animated_nodes(document: pygltflib.GLTF2, paths: tuple[str, ...]) -> set[int]:
    """Nodes that an animation channel drives on one of ``paths`` ("weights": morph targets;
    "translation", "rotation", "scale": the node's transform)."""
    nodes = set()
    for animation in document.animations or []:
        for channel in animation.channels or []:
            target = channel.target
            if target is not None and target.path in paths and isinstance(target.node, int):
                nodes.add(target.node)
    return nodes


def _moving_nodes(document: pygltflib.GLTF2) -> set[int]:
    """Nodes whose world transform an animation changes: its own, or an ancestor's."""
    stack = list(_animated_nodes(document, ("translation", "rotation", "scale")))
    moving: set[int] = set()
    while stack:
        index = stack.pop()
        if index in moving or not 0 <= index < len(document.nodes):
            continue
        moving.add(index)
        stack.extend(c for c in document.nodes[index].children or [] if isinstance(c, int))
    return moving


def _gpu_instances(ctx: _Context, index: int, node: pygltflib.Node) -> np.ndarray | None:
    """(k, 4, 4) local matrices T_k @ R_k @ S_k of EXT_mesh_gpu_instancing, None without it."""
    extension = (node.extensions or {}).get("EXT_mesh_gpu_instancing")
    if not isinstance(extension, dict) or not extension.get("attributes"):
        return None
    where = f"nodes[{index}].extensions.EXT_mesh_gpu_instancing.attributes"
    attributes = extension["attributes"]
    read = {}
    for name, width in (("TRANSLATION", 3), ("ROTATION", 4), ("SCALE", 3)):
        if attributes.get(name) is not None:
            read[name] = _attribute(ctx, attributes, name, (width,), None, where.removesuffix(".attributes"))
    counts = {len(v) for v in read.values()}
    if len(counts) > 1:
        raise _invalid(f"TRANSLATION/ROTATION/SCALE have different counts {sorted(counts)}", ctx.file, where)
    if not read:
        return None
    k = counts.pop()
    translation = read.get("TRANSLATION", np.zeros((k, 3)))
    rotation = read.get("ROTATION", np.tile([0.0, 0.0, 0.0, 1.0], (k, 1)))
    scale = read.get("SCALE", np.ones((k, 3)))
    if not all(np.isfinite(v).all() for v in read.values()):
        raise _invalid("instance transforms hold NaN or infinite values", ctx.file, where)
    return trs_matrices(translation, rotation, scale, file=ctx.file, where=where)


def _instantiate(
    ctx: _Context, placements: list[tuple[int, np.ndarray]], materials: list[Material],
    unbaked: list[str], animated: str = "bake",
) -> tuple[list[Primitive], list[Instance]]:
    """Read the meshes the placed nodes use (in mesh order) and make their instances (in walk order).

    ``unbaked``: per material, why its primitives get no lightmap ("" when they do);
    ``animated``: what becomes of node-animated instances (``load``)."""
    document = ctx.document
    used = _used_meshes(ctx, placements)
    primitives: list[Primitive] = []
    slots: dict[int, list[int | None]] = {}
    for mesh in sorted(used):
        slots[mesh] = []
        for primitive in _read_mesh(ctx, mesh, len(materials)):
            slots[mesh].append(None if primitive is None else len(primitives))
            if primitive is not None:
                primitives.append(primitive)
    instances = []
    morphed = _animated_nodes(document, ("weights",))
    moving = _moving_nodes(document)
    for index, world in placements:
        node = document.nodes[index]
        if node.mesh is None:
            continue
        animated_here = index in moving and node.skin is None
        if animated_here and animated != "occlude":
            ctx.skip(f"nodes[{index}]", _MOVING_REASON[animated])
            if animated == "skip":
                continue
        with _schema(ctx.file, f"nodes[{index}].extensions.EXT_mesh_gpu_instancing"):
            gpu = _gpu_instances(ctx, index, node)
        worlds = [world] if gpu is None else list(world @ gpu)
        _check_reach(ctx, index, worlds, [primitives[slot] for slot in slots[node.mesh]
                                          if slot is not None])
        node_reasons = [_GPU_REASON] if gpu is not None else []
        node_reasons += [_SKIN_REASON] if node.skin is not None else []
        node_reasons += [_MORPH_REASON] if index in morphed and node_reasons[-1:] != [_SKIN_REASON] else []
        node_reasons += [_MOVING_REASON["occlude"]] if animated_here and animated == "occlude" else []
        for slot in slots[node.mesh]:
            if slot is None:
                continue
            material_reason = unbaked[primitives[slot].material]
            reasons = node_reasons + ([material_reason] if material_reason else [])
            for k, matrix in enumerate(worlds):
                instances.append(
                    Instance(
                        node=index,
                        primitive=slot,
                        world=np.array(matrix, dtype=np.float64),
                        baked=not reasons,
                        reason="; ".join(reasons),
                        gpu_instance=None if gpu is None else k,
                    )
                )
    return primitives, instances


def _used_meshes(ctx: _Context, placements: list[tuple[int, np.ndarray]]) -> list[int]:
    """The meshes the placed nodes use, in mesh order (each checked to be one of the file's)."""
    used = set()
    for index, _ in placements:
        mesh = ctx.document.nodes[index].mesh
        if mesh is not None:
            _item(ctx.document.meshes, mesh, "meshes", ctx.file, f"nodes[{index}].mesh")
            used.add(mesh)
    return sorted(used)


def _check_declared_sizes(ctx: _Context, placements: list[tuple[int, np.ndarray]]) -> None:
    """Refuse, before any buffer is read, accessors baker would read (the attributes and
    indices of every primitive of the meshes the nodes use, the GPU instances' transforms; each
    accessor once) that declare more than ``MAX_SCENE_COMPONENTS`` numbers in all, or more
    than ``budget.MAX_UNBACKED_NUMBERS`` in accessors without a bufferView (zeros, whose count
    nothing in the file bounds: a 1 kB file of an index accessor of 30 M took a minute). A
    3 KB file of accessors without a bufferView and large counts took 9 GB and 86 s before it
    failed. The error names the largest accessor and where it is used. Entries that are not
    valid are left for the reading to report; morph targets are not read."""
    accessors = ctx.document.accessors or []
    seen: set[int] = set()
    totals = {"all": [0, -1, 0, ""], "unbacked": [0, -1, 0, ""]}  # total, largest, its count, at
    for at, index in _read_accessors(ctx, placements):
        if not isinstance(index, int) or not 0 <= index < len(accessors) or index in seen:
            continue
        seen.add(index)
        accessor = accessors[index]
        shape = _TYPE_SHAPES.get(accessor.type)
        if shape is None or not isinstance(accessor.count, int) or accessor.count < 0:
            continue
        numbers = accessor.count * shape[0] * shape[1]
        for key in ("all",) + (("unbacked",) if accessor.bufferView is None else ()):
            tally = totals[key]
            tally[0] += numbers
            if numbers > tally[2]:
                tally[1:] = [index, numbers, at]
    for key, limit, what in (("unbacked", budget.MAX_UNBACKED_NUMBERS,
                              "accessors without a bufferView (zeros: no data behind them)"),
                             ("all", MAX_SCENE_COMPONENTS, "accessors")):
        total, largest, largest_count, used_at = totals[key]
        if total > limit:
            raise InputError(
                f"the {what} baker reads declare {total:,} numbers in all, more than baker "
                f"holds ({limit:,}, {8 * limit >> 20:,} MiB as float64); the largest, "
                f"accessors[{largest}], declares {largest_count:,}",
                file=ctx.file,
                where=f"{used_at} → accessors[{largest}]",
                fix="check the accessors' counts; split the scene, or bake its parts apart",
            )


def _read_accessors(ctx: _Context, placements: list[tuple[int, np.ndarray]]
                    ) -> Iterator[tuple[str, Any]]:
    """(JSON path, accessor index) of every accessor baker reads for the placed nodes: the
    attributes and indices of the primitives of their meshes, and their GPU instances'
    transforms (``EXT_mesh_gpu_instancing``)."""
    document = ctx.document
    for mesh in _used_meshes(ctx, placements):
        for j, primitive in enumerate(document.meshes[mesh].primitives or []):
            for name, index in _accessors_of(primitive):
                yield f"meshes[{mesh}].primitives[{j}].{name}", index
    for node, _ in placements:
        extension = (document.nodes[node].extensions or {}).get("EXT_mesh_gpu_instancing")
        attributes = extension.get("attributes") if isinstance(extension, dict) else None
        for name, index in (attributes.items() if isinstance(attributes, dict) else ()):
            yield f"nodes[{node}].extensions.EXT_mesh_gpu_instancing.attributes.{name}", index


def _accessors_of(primitive: Any) -> list[tuple[str, Any]]:
    """(JSON path within the primitive, accessor index) of every accessor of a primitive baker
    reads: its attributes and its indices."""
    attributes = primitive.attributes
    items = {} if attributes is None else (
        attributes if isinstance(attributes, dict) else vars(attributes))
    return ([(f"attributes.{k}", v) for k, v in items.items() if v is not None]
            + [("indices", primitive.indices)])


def _check_reach(ctx: _Context, index: int, worlds: list[np.ndarray],
                 primitives: list[Primitive]) -> None:
    """Refuse a node whose world matrices (one, or one per GPU instance) take its mesh farther
    than ``MAX_WORLD_UNITS`` from the origin on some axis, or to no finite place (a scale of
    1e300 overflows): a bound from the matrices' absolute values and the mesh's largest local
    coordinate, computed without overflow warnings."""
    if not primitives or not worlds:
        return
    local = max(float(np.abs(p.positions).max(initial=0.0)) for p in primitives)
    matrices = np.asarray(worlds, np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        reach = (np.abs(matrices[:, :3, :3]).sum(axis=2) * local + np.abs(matrices[:, :3, 3])).max()
    if not (np.isfinite(reach) and reach <= MAX_WORLD_UNITS):
        raise InputError(
            f"its world transform places the mesh up to {reach:.3g} units from the origin, more "
            f"than baker bakes ({MAX_WORLD_UNITS:.0e})",
            file=ctx.file,
            where=f"nodes[{index}]",
            fix="check the scale and translation of this node and of its parents "
                "(a scale of 1e300 is an export error)",
        )


# --------------------------------------------------------------------------------------------
# Lights (KHR_lights_punctual)

_LIGHT_KINDS = ("directional", "point", "spot")


def _read_lights(ctx: _Context, placements: list[tuple[int, np.ndarray]]) -> tuple[Light, ...]:
    """Every node's KHR_lights_punctual light in world space, in node walk order.

    Position is the node's world translation, direction its local −Z through the (float64) world
    matrix, normalised. Range, intensity and cone angles ignore node scale (the extension says so).
    Soft-shadow sizes come from the light's ``extras``: ``radius`` (metres, point/spot) and
    ``angular_diameter`` (degrees, directional). Spot cones outside 0 ≤ inner ≤ outer ≤ π/2 are
    clamped into it and the clamp is recorded in ``ctx.skipped``.
    """
    top = (ctx.document.extensions or {}).get("KHR_lights_punctual") or {}
    definitions = top.get("lights") if isinstance(top, dict) else None
    if definitions is None:
        definitions = []
    if not isinstance(definitions, list):
        raise _invalid("KHR_lights_punctual.lights is not a list", ctx.file, "extensions.KHR_lights_punctual")
    lights = []
    for node_index, world in placements:
        extension = (ctx.document.nodes[node_index].extensions or {}).get("KHR_lights_punctual")
        if extension is None:
            continue
        referrer = f"nodes[{node_index}].extensions.KHR_lights_punctual.light"
        index = extension.get("light") if isinstance(extension, dict) else None
        definition = _item(definitions, index, "KHR_lights_punctual lights", ctx.file, referrer)
        where = f"extensions.KHR_lights_punctual.lights[{index}]"
        with _schema(ctx.file, where):
            light = _read_light(ctx, definition, index, node_index, world, where)
        if light is not None:
            lights.append(light)
    return tuple(lights)


def _read_light(ctx: _Context, definition: dict, index: int, node: int, world: np.ndarray,
                where: str) -> Light | None:
    """One placed light; None (recorded as skipped) when the node's matrix collapses −Z."""
    kind = definition.get("type")
    if kind not in _LIGHT_KINDS:
        raise _invalid(f"light type {kind!r} is not directional, point or spot", ctx.file, f"{where}.type")
    colour = _finite(ctx, _default(definition.get("color"), [1.0, 1.0, 1.0]), 3, f"{where}.color")
    intensity = _finite(ctx, [_default(definition.get("intensity"), 1.0)], 1, f"{where}.intensity")[0]
    if (colour < 0).any() or intensity < 0:
        raise _invalid("light colour and intensity must not be negative", ctx.file, where)
    light_range = float("inf")
    if kind != "directional" and definition.get("range") is not None:
        light_range = float(_finite(ctx, [definition["range"]], 1, f"{where}.range")[0])
        if light_range <= 0:
            raise _invalid(f"range must be above 0, not {light_range}", ctx.file, f"{where}.range")
    inner, outer = 0.0, np.pi / 4
    if kind == "spot":
        spot = definition.get("spot") or {}
        inner = float(_finite(ctx, [_default(spot.get("innerConeAngle"), 0.0)], 1, f"{where}.spot")[0])
        outer = float(_finite(ctx, [_default(spot.get("outerConeAngle"), np.pi / 4)], 1, f"{where}.spot")[0])
        clamped_outer = min(max(outer, 1e-6), np.pi / 2)
        clamped_inner = min(max(inner, 0.0), clamped_outer)
        if (clamped_inner, clamped_outer) != (inner, outer):
            ctx.skip(f"{where}.spot", f"cone angles ({inner:.4g}, {outer:.4g}) rad clamped to "
                                      f"({clamped_inner:.4g}, {clamped_outer:.4g})")
        inner, outer = clamped_inner, clamped_outer
    extras = definition.get("extras") if isinstance(definition.get("extras"), dict) else {}
    radius = _light_size(ctx, extras, "radius", 1.0, where)
    angular = _light_size(ctx, extras, "angular_diameter", np.pi / 180, where)
    direction = world[:3, :3] @ np.array([0.0, 0.0, -1.0])
    length = np.linalg.norm(direction)
    if kind != "point" and not length > 0:
        ctx.skip(f"nodes[{node}]", "light's node scale is zero: the light has no direction, left out")
        return None
    return Light(index=index, node=node, name=str(definition.get("name") or ""), kind=kind,
                 colour=colour, intensity=float(intensity), position=np.array(world[:3, 3], np.float64),
                 direction=direction / length if length > 0 else np.array([0.0, 0.0, -1.0]),
                 range=light_range, inner_cone=inner, outer_cone=outer, radius=radius,
                 angular_diameter=angular)


def _light_size(ctx: _Context, extras: dict, key: str, scale: float, where: str) -> float | None:
    """``extras[key] × scale`` when it is a finite number ≥ 0, else None (a bad value is recorded)."""
    value = extras.get(key)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value < 0:
        ctx.skip(f"{where}.extras.{key}", f"{key} {value!r} is not a number ≥ 0: the bake's setting applies")
        return None
    return float(value) * scale


# --------------------------------------------------------------------------------------------
# Small helpers


def _invalid(message: str, file: str, where: str) -> InputError:
    """An InputError for data that breaks the glTF spec; the fix is always to export again."""
    return InputError(message, file=file, where=where, fix=_REEXPORT)


def _default(value: Any, default: Any) -> Any:
    """``value``, or ``default`` when the file leaves it out (pygltflib gives None)."""
    return default if value is None else value


def _item(items: Sequence, index: Any, kind: str, file: str, referrer: str) -> Any:
    """``items[index]``, or an InputError at ``referrer`` when ``index`` is not a valid index."""
    if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < len(items):
        raise _invalid(f"refers to {kind}[{index}] but the file has {len(items)} {kind}", file, referrer)
    return items[index]


def _finite(ctx: _Context, value: Any, length: int, where: str) -> np.ndarray:
    """``value`` as a (length,) float64 array of finite numbers, or an InputError."""
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        array = None
    if array is None or array.shape != (length,) or not np.isfinite(array).all():
        raise _invalid(f"expected {length} finite numbers, found {value!r}", ctx.file, where)
    return array


@contextmanager
def _referred(referrer: str) -> Iterator[None]:
    """Name the object that refers to the faulty one too: an error at ``accessors[4]`` read for
    POSITION is reported at ``meshes[1].primitives[0].attributes.POSITION → accessors[4]``."""
    try:
        yield
    except InputError as error:
        if not error.where.startswith(referrer):
            error.where = f"{referrer} → {error.where}" if error.where else referrer
        raise


@contextmanager
def _schema(file: str, where: str) -> Iterator[None]:
    """Turn the errors that malformed JSON values provoke (a string where a number belongs, …)
    into an InputError at ``where``."""
    try:
        yield
    except (TypeError, ValueError, AttributeError, KeyError, IndexError) as exc:
        message = f"does not follow the glTF 2.0 schema ({type(exc).__name__}: {exc})"
        raise _invalid(message, file, where) from exc
