"""Write the baked scene back as glTF: the same asset, plus lightmap UVs, images and materials.

Everything the bake does not add is carried over from ``Scene.document`` untouched (extensions,
extras, animations, skins, cameras, names, samplers, GPU-instanced nodes). What is added:

- every baked node gets its own mesh (a copy, unless no other node uses the mesh), because the
  lightmap is bound through the material and each instance has its own area in the atlas;
- every baked primitive is rewritten as one TRIANGLES primitive per lightmap page it lies on,
  every vertex attribute (morph targets included) gathered through ``InstanceUV.vertices``, and
  the lightmap UVs as ``TEXCOORD_1``, where Hubs' loader and most engines look for them: sets
  the input had from ``TEXCOORD_1`` on move up one, and the material copy's ``texCoord``s with
  them (the set also goes to ``TEXCOORD_0`` when the primitive has none, since glTF forbids
  TEXCOORD_1 without TEXCOORD_0). Only a primitive with ``KHR_materials_variants``, whose other
  materials would keep pointing at the old sets, keeps them and gets the first free set, with a
  note;
- per (material, page, UV set) a copy of the material, named "<name> (lightmap page p)", that
  carries the bake (``WriteOptions.carrier``): ``extensions.MOZ_lightmap = {index, texCoord,
  intensity}`` (moz), the radiance as its emission on a black base (emissive) or the visibility
  as its core ``occlusionTexture`` (occlusion, or moz with occlusion "also"); one PNG image (in
  a bufferView) per page;
- the ``KHR_lights_punctual`` lights removed when their light is in the lightmap
  (``baked_lights`` "remove"), so that viewers do not light the baked surfaces a second time;
- ``asset.extras["baker"]`` records the carrier, the lights and how the texels encode light.

All buffers are merged into one (GLB BIN chunk, or ``<stem>.bin`` beside a ``.gltf``). Files are
staged beside their places and moved into place together (``staging.Outputs``).
"""

from __future__ import annotations

import json
import re
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from urllib.parse import quote, unquote

import numpy as np

from baker.atlas.layout import Atlas, InstanceUV
from baker.errors import InputError, OutputError, SettingsError
from baker.gltf import document as gltf_document
from baker.gltf import images, objects
from baker.gltf.document import COMPONENT_DTYPES
from baker.gltf.accessors import read_accessor
from baker.gltf.scene import Material, Scene
from baker.image.encode import PNG_SIGNATURE, EncodedPage
from baker.jit import jit
from baker.output.specular import mixed_pair, without_diffuse
from baker.run.atomic import Outputs
from baker.run.progress import Steps
from baker.settings import BAKED_LIGHTS, CARRIERS, ENCODINGS, OCCLUSION_MODES

LIGHTMAP_EXTENSION = "MOZ_lightmap"
DIRECTIONAL_EXTENSION = "BAKER_lightmap_directional"
"""Directional pages beside a MOZ_lightmap, on normal-mapped materials (docs/directional.md):
``{"index": T, "texCoord": n}``, texture T holding h = g/(1 + |g|) as 0.5 + 0.5·h, linear, on
the lightmap's UV set (``light.directional``)."""
LIGHTS_EXTENSION = "KHR_lights_punctual"
VARIANTS_EXTENSION = "KHR_materials_variants"
TEXTURE_TRANSFORM = "KHR_texture_transform"
EMISSIVE_STRENGTH = "KHR_materials_emissive_strength"
ENCODING_TARGETS = {
    "linear": "texel/255 x intensity: the three.js MOZ_lightmap plugin, Hubs, baker view",
    "srgb": "sRGB-decoded texel x intensity: the MOZ_lightmap extension text; glTF's "
            "emissiveTexture",
}
"""What reads each encoding as it is meant (recorded in ``asset.extras.baker``)."""

_FLOAT = 5126
_UNSIGNED_SHORT = 5123
_UNSIGNED_INT = 5125
_ARRAY_BUFFER = 34962
_ELEMENT_ARRAY_BUFFER = 34963
_TRIANGLES = 4
_LINEAR = 9729
_CLAMP_TO_EDGE = 33071

_MIME_TYPES = {"PNG": "image/png", "JPEG": "image/jpeg", "WEBP": "image/webp",
               "KTX2": "image/ktx2"}
_GLB_MAGIC, _GLB_JSON, _GLB_BIN = 0x46546C67, 0x4E4F534A, 0x004E4942


@dataclass(frozen=True)
class WriteOptions:
    """How the lightmaps are stored in the output.

    ``carrier``: ``moz`` (``EncodedPage.png`` as ``MOZ_lightmap``), ``emissive`` (the pages hold
    outgoing radiance, ``image/carriers.py``: bound as the copy's ``emissiveTexture``, its base colour
    black) or ``occlusion`` (``EncodedPage.occlusion_png`` as the core ``occlusionTexture``
    alone).
    ``baked_lights``: ``remove`` drops the KHR_lights_punctual lights from the output once
    something carries the bake; ``keep`` and ``indirect`` (the bake left their direct light
    out) keep them.
    ``encoding``: how a PNG texel maps to linear light — ``linear`` (texel / 255 × intensity) or
    ``srgb`` (sRGB-decoded texel × intensity); recorded in ``asset.extras["baker"]``.
    ``occlusion``: ``none``, or ``also``: the visibility as the core ``occlusionTexture`` on the
    lightmap UV set next to ``MOZ_lightmap``.
    ``clip_percentile``: the percentile of each page's texels that its ``intensity`` is
    (encode.py; 100: the page's peak), recorded in ``asset.extras["baker"]``.
    ``authored_uv``: the atlas is the primitives' own TEXCOORD_<n> (``--uv``); when n is 1,
    the lightmap set is already where viewers read it, so no set moves. None: xatlas's UVs.
    """

    encoding: str = "linear"
    occlusion: str = "none"
    clip_percentile: float = 100.0
    carrier: str = "moz"
    baked_lights: str = "remove"
    authored_uv: int | None = None

    def __post_init__(self) -> None:
        for name, allowed in (("carrier", CARRIERS), ("baked_lights", BAKED_LIGHTS)):
            if getattr(self, name) not in allowed:
                raise SettingsError(f"unknown {name} {getattr(self, name)!r}",
                                    fix=f"use one of: {', '.join(allowed)}")
        if self.carrier == "emissive" and self.encoding != "srgb":
            raise SettingsError("the emissive carrier's pages are emissiveTextures, sRGB by glTF",
                                fix="encode them with encoding 'srgb'")
        if self.encoding not in ENCODINGS:
            raise SettingsError(f"unknown lightmap encoding {self.encoding!r}",
                                fix=f"use one of: {', '.join(ENCODINGS)}")
        if self.occlusion not in OCCLUSION_MODES:
            raise SettingsError(f"unknown occlusion mode {self.occlusion!r}",
                                fix=f"use one of: {', '.join(OCCLUSION_MODES)}")


@dataclass(frozen=True)
class WriteInfo:
    """What ``write`` did that the user should know.

    ``lightmap_texcoord``: Scene.instances index → the TEXCOORD set holding its lightmap UVs.
    ``notes``: one line each for the report (UV sets moved, textures replaced, …).
    """

    lightmap_texcoord: dict[int, int]
    notes: tuple[str, ...]


def write(scene: Scene, atlas: Atlas, pages: Sequence[EncodedPage], output: Path,
          options: WriteOptions = WriteOptions(), outputs: Outputs | None = None,
          steps: Steps | None = None) -> WriteInfo:
    """Write ``scene`` with the lightmaps of ``atlas``/``pages`` to ``output`` (.glb or .gltf).

    ``pages[p]`` is atlas page p. Nothing is written unless everything succeeds: an existing
    output is replaced atomically. ``outputs``: stage the files there, for the caller to put in
    place with its other files (``staging.Outputs.commit``); None: put them in place now.
    Raises ``OutputError`` when the output cannot be written, ``InputError`` when the input's
    buffers or images cannot be read. ``steps``: the baked triangles, counted as their nodes
    are written.
    """
    output = Path(output)
    kind = _output_kind(output)
    if len(pages) != atlas.page_count:
        raise ValueError(f"{len(pages)} encoded pages for an atlas of {atlas.page_count}")
    builder = _Builder(scene, output, options)
    builder.add_pages(pages)
    steps = steps or Steps()
    steps.expect(sum(len(unwrap.triangles) for unwrap in atlas.instances))
    for node, baked in _baked_by_node(scene, atlas).items():
        builder.bake_node(node, baked)
        steps.advance(sum(len(unwrap.triangles) for unwrap in baked.values()))
    builder.record_asset()
    if options.baked_lights == "remove" and builder.material_copies:
        builder.remove_lights()
    files = builder.finish(kind)
    staged = Outputs() if outputs is None else outputs
    try:
        for destination, content in files:
            staged.stage(destination, content, durable=True)
        if outputs is None:
            staged.commit()
    except BaseException:
        if outputs is None:
            staged.discard()
        raise
    return WriteInfo(lightmap_texcoord=dict(builder.texcoord), notes=tuple(builder.notes))


# ---------------------------------------------------------------------------------------------
# the document as plain JSON data


def _document_data(document: objects.GLTF2) -> dict:
    """The document as glTF JSON data (a deep copy): None and empty properties dropped.

    ``extensions`` and ``extras`` values are kept verbatim (an extension's empty object means
    something); list items are never dropped, so indices stay valid.
    """
    data = gltf_document.data(document)
    # the objects hold the spec's byteOffset 0 and normalized false; on an accessor without
    # bufferView (zeros or sparse only) byteOffset is an error, so drop these defaults everywhere.
    for accessor in data.get("accessors", []):
        if accessor.get("byteOffset") == 0:
            del accessor["byteOffset"]
        if accessor.get("normalized") is False:
            del accessor["normalized"]
        for part in ("indices", "values"):
            sparse_part = accessor.get("sparse", {}).get(part, {})
            if sparse_part.get("byteOffset") == 0:
                del sparse_part["byteOffset"]
    for mesh in data.get("meshes", []):  # required, if empty (a primitive left unbaked)
        for primitive in mesh.get("primitives", []):
            primitive.setdefault("attributes", {})
    return data


def _json_copy(value):
    """A deep copy of glTF JSON data (dicts, lists and immutable values): ``copy.deepcopy``'s
    result without its memo and dispatch, 2.7× sooner on a material or a mesh (the writer
    copies one of each for every instance: 20,000 instances' copies took 2 s)."""
    if isinstance(value, dict):
        return {key: _json_copy(item) for key, item in value.items()}
    if isinstance(value, list):
        return [_json_copy(item) for item in value]
    return value


def _as_stored(values: np.ndarray, component_type: int, normalized: bool) -> np.ndarray:
    """Numbers from ``accessors.read_accessor`` back in the accessor's component type.

    Exact for floats and plain integers; normalized integers are rounded back from their [0, 1]
    or [-1, 1] values (a signed minimum, e.g. -128, comes back as -127: the same -1.0).
    """
    dtype = COMPONENT_DTYPES[component_type]
    if dtype.kind == "f":
        return values.astype(dtype)
    if normalized:
        values = np.rint(values * float(np.iinfo(dtype).max))
    return values.astype(dtype)


# ---------------------------------------------------------------------------------------------
# the bake's additions


def _baked_by_node(scene: Scene, atlas: Atlas) -> dict[int, dict[int, InstanceUV]]:
    """Baked instances grouped by node: node → {primitive index within its mesh: unwrap}."""
    nodes: dict[int, dict[int, InstanceUV]] = {}
    for unwrap in atlas.instances:
        instance = scene.instances[unwrap.instance]
        primitive = scene.primitives[instance.primitive]
        if instance.gpu_instance is not None:
            raise ValueError(f"instance {unwrap.instance} is GPU-instanced and cannot be baked")
        per_node = nodes.setdefault(instance.node, {})
        if primitive.index in per_node:
            raise ValueError(f"node {instance.node} primitive {primitive.index} unwrapped twice")
        per_node[primitive.index] = unwrap
    return dict(sorted(nodes.items()))


@jit
def _compacted(triangles: np.ndarray, page_of: np.ndarray, page: int, count: int
               ) -> tuple[np.ndarray, np.ndarray]:
    """The vertices (k,) of ``count`` that the triangles (m, 3) on ``page`` (``page_of``
    (m,)) use, in ascending order, and those triangles (t, 3) as rows into them:
    ``np.unique(..., return_inverse=True)``'s result, by a mark and a running count in one
    compiled pass (numpy's six passes were a tenth of the writer's time a node)."""
    row = np.full(count, -1, np.int64)
    on_page = 0
    for i in range(len(triangles)):
        if page_of[i] == page:
            on_page += 1
            for c in range(3):
                row[triangles[i, c]] = 0
    used = 0
    for v in range(count):
        if row[v] == 0:
            row[v] = used
            used += 1
    vertices = np.empty(used, np.int64)
    for v in range(count):
        if row[v] >= 0:
            vertices[row[v]] = v
    rows = np.empty((on_page, 3), np.int64)
    t = 0
    for i in range(len(triangles)):
        if page_of[i] == page:
            for c in range(3):
                rows[t, c] = row[triangles[i, c]]
            t += 1
    return vertices, rows


def _file_winding(scene: Scene, unwrap: InstanceUV) -> np.ndarray:
    """``unwrap.triangles`` with each triangle's corners in the file's order (winding kept).

    The unwrapper works on world triangles, which have two corners swapped where the instance's
    matrix mirrors; the written indices must wind as the input did.
    """
    primitive = scene.primitives[scene.instances[unwrap.instance].primitive]
    triangles = np.asarray(unwrap.triangles, np.int64)
    vertices = np.asarray(unwrap.vertices, np.int64)
    if triangles.shape != primitive.triangles.shape:
        raise ValueError(f"instance {unwrap.instance}: {len(triangles)} unwrapped triangles for "
                         f"{len(primitive.triangles)} in the primitive")
    mapped = vertices[triangles]
    if np.array_equal(mapped, primitive.triangles):  # corner for corner: nothing mirrored
        return triangles

    def same_cycle(a: np.ndarray) -> np.ndarray:  # (corner orders by index: np.roll is slow)
        return np.any([np.all(a[:, order] == primitive.triangles, axis=1)
                       for order in ([0, 1, 2], [2, 0, 1], [1, 2, 0])], axis=0)

    kept = same_cycle(mapped)
    flipped = ~kept & same_cycle(mapped[:, [0, 2, 1]])
    if not np.all(kept | flipped):
        bad = int(np.flatnonzero(~(kept | flipped))[0])
        raise ValueError(f"instance {unwrap.instance}: unwrapped triangle {bad} is not the "
                         "primitive's triangle")
    triangles = triangles.copy()
    triangles[flipped] = triangles[flipped][:, [0, 2, 1]]
    return triangles


class _Builder:
    """The output document under construction: JSON data plus one growing binary buffer."""

    def __init__(self, scene: Scene, output: Path, options: WriteOptions):
        self.scene = scene
        self.output = output
        self.options = options
        self.base = Path(scene.path).parent
        self.data = _document_data(scene.document)
        self.source_buffers = list(scene.buffers)
        self.blob = bytearray()
        self._merge_buffers()
        self.source_cache: dict[int, np.ndarray] = {}
        self.mesh_users: dict[int, int] = {}
        for node in self.data.get("nodes", []):
            if "mesh" in node:
                self.mesh_users[node["mesh"]] = self.mesh_users.get(node["mesh"], 0) + 1
        self.lightmap_textures: list[int] = []
        self.direction_textures: list[int] = []  # a page's directional page, if any
        self.occlusion_textures: list[int] = []
        self.intensities: list[float] = []
        self.material_copies: dict[tuple[int | None, int, int], int] = {}
        self.mixed: dict[int | None, tuple[int, int | None] | None] = {}  # specular.mixed_pair
        self.shared_geometry: dict[tuple, tuple[dict, np.ndarray, int]] = {}  # _page_geometry
        self.texcoord: dict[int, int] = {}
        self.notes: list[str] = []

    # -- buffers ------------------------------------------------------------------------------

    def _merge_buffers(self) -> None:
        """Concatenate the input's buffers (4-byte aligned) and re-point their bufferViews."""
        starts = []
        for raw in self.source_buffers:
            self._align()
            starts.append(len(self.blob))
            self.blob += raw
        for view in self.data.get("bufferViews", []):
            view["byteOffset"] = starts[view["buffer"]] + int(view.get("byteOffset", 0))
            view["buffer"] = 0
            if view["byteOffset"] == 0:
                del view["byteOffset"]

    def _align(self) -> None:
        self.blob += b"\0" * (-len(self.blob) % 4)

    def _add_view(self, payload: bytes, target: int | None = None,
                  stride: int | None = None) -> int:
        self._align()
        view = {"buffer": 0, "byteLength": len(payload)}
        if len(self.blob):
            view["byteOffset"] = len(self.blob)
        if stride is not None:
            view["byteStride"] = stride
        if target is not None:
            view["target"] = target
        self.blob += payload
        views = self.data.setdefault("bufferViews", [])
        views.append(view)
        return len(views) - 1

    def _add_accessor(self, values: np.ndarray, component_type: int, kind: str,
                      normalized: bool = False, bounds: bool = False,
                      target: int = _ARRAY_BUFFER) -> int:
        """Append ``values`` ((count, components), already of ``component_type``) as an accessor.

        Vertex attributes whose elements are not a multiple of 4 bytes are padded, with a
        byteStride, as glTF requires; indices are tightly packed without byteStride.
        """
        dtype = COMPONENT_DTYPES[component_type]
        values = np.ascontiguousarray(values, dtype)
        count, components = values.shape
        element = dtype.itemsize * components
        stride = None
        payload = values.tobytes()
        if target == _ARRAY_BUFFER and element % 4:
            stride = element + (-element % 4)
            padded = np.zeros((count, stride), np.uint8)
            padded[:, :element] = values.view(np.uint8).reshape(count, element)
            payload = padded.tobytes()
        accessor = {"bufferView": self._add_view(payload, target, stride),
                    "componentType": component_type, "count": int(count), "type": kind}
        if normalized:
            accessor["normalized"] = True
        if bounds:
            convert = float if dtype.kind == "f" else int
            accessor["min"] = [convert(v) for v in values.min(axis=0)]
            accessor["max"] = [convert(v) for v in values.max(axis=0)]
        accessors = self.data.setdefault("accessors", [])
        accessors.append(accessor)
        return len(accessors) - 1

    def _gather(self, index: int, rows: np.ndarray, bounds: bool) -> int:
        """A new accessor holding rows ``rows`` of accessor ``index`` (same type, normalized)."""
        accessor = self.data["accessors"][index]
        if index not in self.source_cache:
            values = read_accessor(self.scene.document, self.source_buffers, index,
                                   file=str(self.scene.path))
            self.source_cache[index] = _as_stored(values, accessor["componentType"],
                                                  bool(accessor.get("normalized", False)))
        source = self.source_cache[index]
        if bounds and source.dtype.kind == "f" and not np.isfinite(source[rows]).all():
            raise InputError("a POSITION (of a mesh or a morph target) has NaN or infinite "
                             "values: its min and max cannot be written",
                             file=str(self.scene.path), where=f"accessors[{index}]",
                             fix="clean up the mesh in your DCC tool (e.g. Blender: Mesh > "
                                 "Clean Up) and export again")
        if len(rows) and rows.max() >= len(source):
            raise ValueError(f"unwrap vertex {int(rows.max())} past accessors[{index}] "
                             f"({len(source)} elements)")
        return self._add_accessor(source[rows], accessor["componentType"], accessor["type"],
                                  normalized=bool(accessor.get("normalized", False)),
                                  bounds=bounds)

    # -- images, textures, materials ------------------------------------------------------------

    def add_pages(self, pages: Sequence[EncodedPage]) -> None:
        """One lightmap (and occlusion) texture per page, sharing one clamped linear sampler."""
        if not pages:
            return
        samplers = self.data.setdefault("samplers", [])
        samplers.append({"magFilter": _LINEAR, "minFilter": _LINEAR, "wrapS": _CLAMP_TO_EDGE,
                         "wrapT": _CLAMP_TO_EDGE, "name": "lightmap"})
        sampler = len(samplers) - 1
        for p, page in enumerate(pages):
            intensity = float(page.intensity)
            if not np.isfinite(intensity) or intensity < 0:
                raise ValueError(f"lightmap page {p} has intensity {intensity}")
            self.intensities.append(intensity)
            if self.options.carrier != "occlusion":
                kind = "emission" if self.options.carrier == "emissive" else "lightmap"
                self.lightmap_textures.append(
                    self._add_texture(page.png, sampler, f"{kind} page {p}"))
            if page.direction_png is not None and self.options.carrier == "moz":
                self.direction_textures.append(
                    self._add_texture(page.direction_png, sampler, f"directional page {p}"))
            if self._writes_occlusion():
                if page.occlusion_png is None:
                    raise SettingsError(f"occlusion output was asked but lightmap page {p} has "
                                        "no occlusion image",
                                        fix="encode the pages with occlusion, or set occlusion "
                                            "to 'none'")
                self.occlusion_textures.append(
                    self._add_texture(page.occlusion_png, sampler, f"occlusion page {p}"))

    def _writes_occlusion(self) -> bool:
        return self.options.carrier == "occlusion" or self.options.occlusion == "also"

    def _add_texture(self, png: bytes, sampler: int | None, name: str) -> int:
        if not bytes(png[:8]) == PNG_SIGNATURE:
            raise ValueError(f"{name} is not a PNG image")
        images = self.data.setdefault("images", [])
        images.append({"bufferView": self._add_view(bytes(png)), "mimeType": "image/png",
                       "name": name})
        textures = self.data.setdefault("textures", [])
        texture = {"source": len(images) - 1, "name": name}
        if sampler is not None:
            texture["sampler"] = sampler
        textures.append(texture)
        return len(textures) - 1

    def _lightmap_material(self, material: int | None, page: int, texcoord: int,
                           shifted: bool = False, transform: dict | None = None) -> int:
        """The copy of ``material`` (None: the default material) bound to lightmap ``page`` on
        UV set ``texcoord``; ``shifted``: the primitive's sets from TEXCOORD_1 on moved up one,
        so every texCoord of 1 or more in the copy moves with them; ``transform``: the
        KHR_texture_transform (offset, scale) that maps the UVs an instance shares with others
        to its own place on the page (``_shared_uv``), on every texture read on them."""
        key = (material, page, texcoord, shifted, None if transform is None
               else (tuple(transform["offset"]), tuple(transform["scale"])))
        if key in self.material_copies:
            return self.material_copies[key]
        materials = self.data.setdefault("materials", [])
        if material is None:
            copied = {"pbrMetallicRoughness": {}}
            name = "default"
        else:
            copied = _json_copy(materials[material])
            name = copied.get("name") or f"material {material}"
        copied["name"] = f"{name} (lightmap page {page})"
        if shifted:
            _shift_texcoords(copied)
        if self.options.carrier == "moz":
            copied.setdefault("extensions", {})[LIGHTMAP_EXTENSION] = {
                "index": self.lightmap_textures[page], "texCoord": texcoord,
                "intensity": self.intensities[page]}
            if self.direction_textures and "normalTexture" in copied:
                copied["extensions"][DIRECTIONAL_EXTENSION] = {
                    "index": self.direction_textures[page], "texCoord": texcoord}
        elif self.options.carrier == "emissive":
            self._note_once(without_diffuse(copied, self._material(material), self.scene,
                                            lambda f0: self._mixed_textures(material, copied,
                                                                            f0)))
            _carry_as_emission(copied, self.lightmap_textures[page], texcoord,
                               self.intensities[page])
        if self._writes_occlusion():
            if "occlusionTexture" in copied:
                note = (f"materials[{material}] has an occlusionTexture; its lightmap copies use "
                        "the baked occlusion instead")
                if note not in self.notes:
                    self.notes.append(note)
            copied["occlusionTexture"] = {"index": self.occlusion_textures[page],
                                          "texCoord": texcoord}
        if transform is not None:
            for info in (copied.get("emissiveTexture"), copied.get("occlusionTexture")):
                if info is not None and info.get("texCoord") == texcoord:
                    info.setdefault("extensions", {})[TEXTURE_TRANSFORM] = dict(transform)
        materials.append(copied)
        self.material_copies[key] = len(materials) - 1
        return len(materials) - 1

    def _material(self, material: int | None) -> Material:
        """The scene's Material of glTF material ``material`` (None: glTF's default one)."""
        return next(m for m in self.scene.materials if m.index == material)

    def _mixed_textures(self, material: int | None, copied: dict,
                        f0: np.ndarray) -> tuple[int, int | None] | None:
        """``specular.mixed_pair`` of ``material`` whose dielectric part reflects ``f0`` (3,),
        made once for all its copies, each texture with the sampler of the texture it
        replaces."""
        if material not in self.mixed:
            pbr = copied.get("pbrMetallicRoughness") or {}
            replaced = pbr.get("metallicRoughnessTexture") or pbr.get("baseColorTexture")
            sampler = self.data["textures"][replaced["index"]].get("sampler")

            def add_image(png: bytes, name: str) -> int:
                return self._add_texture(png, sampler, name)

            scene_material = self._material(material)
            self.mixed[material] = mixed_pair(scene_material, self.scene, f0, add_image)
        return self.mixed[material]

    def _note_once(self, note: str | None) -> None:
        if note is not None:
            self._note(note)

    # -- meshes -----------------------------------------------------------------------------

    def bake_node(self, node_index: int, baked: dict[int, InstanceUV]) -> None:
        """Give the node its own mesh with its baked primitives rewritten."""
        node = self.data["nodes"][node_index]
        mesh_index = node.get("mesh")
        for unwrap in baked.values():
            expected = self.scene.primitives[self.scene.instances[unwrap.instance].primitive].mesh
            if mesh_index != expected:
                raise ValueError(f"instance {unwrap.instance}: node {node_index} has mesh "
                                 f"{mesh_index}, the scene says {expected}")
        meshes = self.data["meshes"]
        shared = self.mesh_users.get(mesh_index, 0) != 1
        mesh = meshes[mesh_index]
        primitives = []
        for i, primitive in enumerate(mesh["primitives"]):
            if i in baked:  # made anew, from copies of what it keeps
                primitives.extend(self._bake_primitive(primitive, f"meshes[{mesh_index}]"
                                                       f".primitives[{i}]", baked[i]))
            else:
                primitives.append(_json_copy(primitive) if shared else primitive)
        if shared:  # the node's own copy of the mesh, its keys in their order
            mesh = {key: None if key == "primitives" else _json_copy(value)
                    for key, value in mesh.items()}
            meshes.append(mesh)
            node["mesh"] = len(meshes) - 1
        mesh["primitives"] = primitives

    def _bake_primitive(self, primitive: dict, where: str, unwrap: InstanceUV) -> list[dict]:
        """The primitive split by page, its attributes gathered, the lightmap UVs added."""
        attributes = primitive["attributes"]
        used_sets = {int(name[9:]) for name in attributes
                     if name.startswith("TEXCOORD_") and name[9:].isdigit()}
        texcoord, shifted = 1, 1 in used_sets and self.options.authored_uv != 1
        if shifted and VARIANTS_EXTENSION in primitive.get("extensions", {}):
            shifted = False  # its variants' materials would keep pointing at the old sets
            while texcoord in used_sets:
                texcoord += 1
        vertices = np.asarray(unwrap.vertices, np.int64)
        uv = np.asarray(unwrap.uv, np.float64)
        pages = np.asarray(unwrap.pages, np.int64)
        triangles = _file_winding(self.scene, unwrap)
        if uv.shape != (len(vertices), 2) or not np.all(np.isfinite(uv)):
            raise ValueError(f"instance {unwrap.instance}: lightmap UVs are not (k, 2) finite")
        on_pages = np.flatnonzero(np.bincount(pages[pages >= 0]))
        if on_pages.size == 0:
            self.notes.append(f"{where}: no triangle got lightmap texels; left without lightmap")
            return [primitive]
        if on_pages.max() >= len(self.intensities):
            raise ValueError(f"instance {unwrap.instance} lies on page {int(on_pages.max())}, "
                             f"only {len(self.intensities)} pages were encoded")
        self.texcoord[unwrap.instance] = texcoord
        if 0 not in used_sets:
            self._note(f"{where} has no TEXCOORD_0; the lightmap UVs are written as TEXCOORD_0 "
                       f"too (glTF requires TEXCOORD_0 before TEXCOORD_{texcoord})")
        taken = ", ".join(f"TEXCOORD_{n}" for n in sorted(used_sets) if n >= 1)
        if texcoord != 1:
            self._note(f"{where} uses {taken} and has {VARIANTS_EXTENSION}, whose materials "
                       f"would keep pointing at them, so they stay; the lightmap UVs are "
                       f"TEXCOORD_{texcoord}, which Hubs does not read (it reads TEXCOORD_1); "
                       "remove the variants to have them moved")
        elif shifted:
            self._note(f"{where}: {taken} moved up one set (and the texCoords of its material "
                       "copies with them) so that the lightmap UVs are TEXCOORD_1")
        page_of = np.where(pages < 0, on_pages[0], pages)
        result = []
        for page in on_pages:
            used, indices = _compacted(triangles, page_of, int(page), len(vertices))
            geometry, uv_accessor, transform = self._page_geometry(
                primitive, where, vertices[used], indices, uv[used], texcoord, shifted)
            new = {key: _json_copy(value) for key, value in primitive.items()
                   if key not in ("attributes", "indices", "mode", "targets", "material")}
            new.update(_json_copy(geometry))
            new["attributes"][f"TEXCOORD_{texcoord}"] = uv_accessor
            if 0 not in used_sets:
                new["attributes"]["TEXCOORD_0"] = uv_accessor
            new["mode"] = _TRIANGLES
            new["material"] = self._lightmap_material(primitive.get("material"), int(page),
                                                       texcoord, shifted, transform)
            self._variant_copies(new, where, int(page), texcoord, shifted, transform)
            result.append(new)
        return result

    def _variant_copies(self, primitive: dict, where: str, page: int, texcoord: int,
                        shifted: bool, transform: dict | None) -> None:
        """Point the ``KHR_materials_variants`` mappings of a baked ``primitive`` (its JSON, a
        copy: changed in place) at lightmap copies of their materials, on the primitive's page,
        UV set and texture transform, where the carrier's page is the same for every material
        (moz: irradiance, occlusion: visibility); else, under the emissive carrier, whose page
        holds the default material's colour, each variant keeps its own material (noted)."""
        variants = (primitive.get("extensions") or {}).get(VARIANTS_EXTENSION)
        mappings = variants.get("mappings") if isinstance(variants, dict) else None
        if not isinstance(mappings, list):  # none, or not the extension's object: as none
            return
        if self.options.carrier == "emissive":
            self._note(f"{where} has {VARIANTS_EXTENSION}: under the emissive carrier its "
                       "variants keep their own materials, which show no bake (its page holds "
                       "the default material's colour); --carrier moz carries the bake to "
                       "every variant")
            return
        for mapping in mappings:
            if isinstance(mapping, dict) and isinstance(mapping.get("material"), int):
                mapping["material"] = self._lightmap_material(mapping["material"], page,
                                                              texcoord, shifted, transform)

    def _page_geometry(self, primitive: dict, where: str, rows: np.ndarray, indices: np.ndarray,
                       uv: np.ndarray, texcoord: int, shifted: bool) -> tuple[dict, int, dict | None]:
        """A page's part of an instance of the primitive at ``where`` in the input: its
        attributes but the lightmap UVs, its targets and indices (``rows`` (k,) of the
        primitive's vertices, ``indices`` (m, 3) into them), and the accessor of its lightmap
        UVs ``uv`` (k, 2) with the texture transform to read them through (None: as they are).

        Instances of one mesh charted alike give the same rows and indices: the accessors are
        written once and shared (``shared_geometry``), so a mesh placed 20,000 times is stored
        once. Where an instance's UVs are the first such instance's moved and scaled on the
        page (its charts packed as one block), they are shared too, and the instance's material
        copy reads them through a KHR_texture_transform: with the emissive carrier, whose core
        textureInfo every viewer transforms (MOZ_lightmap readers know no transform)."""
        key = (where, shifted, texcoord, rows.tobytes(), indices.tobytes())
        if key not in self.shared_geometry:
            attributes = primitive["attributes"]
            geometry = {"attributes": {
                _moved(name, shifted): self._gather(accessor, rows, bounds=name == "POSITION")
                for name, accessor in attributes.items()
                if _moved(name, shifted) != f"TEXCOORD_{texcoord}"}}
            if primitive.get("targets"):
                geometry["targets"] = [{_moved(name, shifted):
                                        self._gather(accessor, rows, bounds=name == "POSITION")
                                        for name, accessor in target.items()}
                                       for target in primitive["targets"]]
            wide = len(rows) > 65535  # 65535 itself is reserved (primitive restart)
            geometry["indices"] = self._add_accessor(
                indices.reshape(-1, 1), _UNSIGNED_INT if wide else _UNSIGNED_SHORT, "SCALAR",
                target=_ELEMENT_ARRAY_BUFFER)
            reference = uv.astype(np.float32)
            self.shared_geometry[key] = (geometry, reference,
                                         self._add_accessor(reference, _FLOAT, "VEC2"))
            return geometry, self.shared_geometry[key][2], None
        geometry, reference, shared = self.shared_geometry[key]
        transform = _uv_transform(reference, uv)
        if transform is None or (transform and self.options.carrier != "emissive"):
            return geometry, self._add_accessor(uv.astype(np.float32), _FLOAT, "VEC2"), None
        return geometry, shared, transform or None

    def _note(self, note: str) -> None:
        if note not in self.notes:
            self.notes.append(note)

    # -- asset and output ---------------------------------------------------------------------

    def record_asset(self) -> None:
        """extensionsUsed (never extensionsRequired) and the carrier and encoding in
        asset.extras."""
        used = self.data.setdefault("extensionsUsed", [])
        for index in sorted(set(self.material_copies.values())):
            copied = self.data["materials"][index]
            transformed = any(TEXTURE_TRANSFORM in ((copied.get(slot) or {}).get("extensions") or {})
                              for slot in ("emissiveTexture", "occlusionTexture"))
            for name in [*copied.get("extensions", {}), *([TEXTURE_TRANSFORM] * transformed)]:
                if name not in used:
                    used.append(name)
        if not used:
            del self.data["extensionsUsed"]
        required = self.data.get("extensionsRequired", [])
        if LIGHTMAP_EXTENSION in required:
            required.remove(LIGHTMAP_EXTENSION)
            if not required:
                del self.data["extensionsRequired"]
        asset = self.data.setdefault("asset", {"version": "2.0"})
        extras = asset.get("extras", {})
        if not isinstance(extras, dict):
            self._note("asset.extras was not an object; its value moved to asset.extras.value")
            extras = {"value": extras}
        moz = self.options.carrier == "moz"
        extras["baker"] = {
            "carrier": self.options.carrier,
            "baked_lights": self.options.baked_lights,
            "lightmap_encoding": self.options.encoding,
            "lightmap_encoding_for": ENCODING_TARGETS[self.options.encoding],
            "lightmap_extension": LIGHTMAP_EXTENSION if moz else None,
            "occlusion": "visibility" if self._writes_occlusion() else "none",
            "lightmap_intensity_percentile": self.options.clip_percentile,
            **({"directional_extension": DIRECTIONAL_EXTENSION} if self.direction_textures
               else {}),
        }
        asset["extras"] = extras

    def remove_lights(self) -> None:
        """Drop every KHR_lights_punctual light (nodes' references, the root list, the
        extension's name): the lightmap holds their light, and a viewer that also lit the
        baked surfaces with them would show it twice."""
        lights = (self.data.get("extensions") or {}).pop(LIGHTS_EXTENSION, None)
        if lights is None:
            return
        if not self.data["extensions"]:
            del self.data["extensions"]
        for node in self.data.get("nodes", []):
            extensions = node.get("extensions") or {}
            if extensions.pop(LIGHTS_EXTENSION, None) is not None and not extensions:
                del node["extensions"]
        for key in ("extensionsUsed", "extensionsRequired"):
            names = self.data.get(key, [])
            if LIGHTS_EXTENSION in names:
                names.remove(LIGHTS_EXTENSION)
                if not names:
                    del self.data[key]
        count = len(lights.get("lights", [])) if isinstance(lights, dict) else 0
        self._note(f"{count} KHR_lights_punctual light(s) removed: their light is in the bake, "
                   "and a viewer would light the baked surfaces with them again (surfaces "
                   "without a lightmap lose them too); --baked-lights indirect keeps them and "
                   "bakes only the indirect light, --baked-lights keep keeps both")

    def finish(self, kind: str) -> list[tuple[Path, bytes]]:
        """The files to write, in order: copied images (a .gltf output), then .bin, then the
        .gltf or .glb; a .glb holds every image the input names by URI."""
        files = self._embed_images() if kind == "glb" else self._external_images()
        self._align()
        blob = bytes(self.blob)
        if blob:
            buffer = {"byteLength": len(blob)}
            if kind == "gltf":
                bin_name = self.output.stem + ".bin"
                buffer["uri"] = quote(bin_name)
                files.append((self.output.with_name(bin_name), blob))
            self.data["buffers"] = [buffer]
        else:
            self.data.pop("buffers", None)
        if kind == "gltf":
            text = json.dumps(self.data, indent=2, allow_nan=False) + "\n"
            files.append((self.output, text.encode("utf-8")))
        else:
            files.append((self.output, glb_file(self.data, blob)))
        return files

    def _image_files(self):
        """(index, image JSON, its bytes) of the images the input names by a URI: files
        inside the input's folder, read once at load (``Image.data``)."""
        for i, (image, loaded) in enumerate(zip(self.data.get("images", []), self.scene.images)):
            if loaded.data is not None:
                yield i, image, loaded.data

    def _embed_images(self) -> list[tuple[Path, bytes]]:
        """Put every image the input names by URI into the .glb's binary chunk (a bufferView
        and its mimeType, by the file's own bytes): a .glb is one self-contained file."""
        for i, image, data in self._image_files():
            mime = _MIME_TYPES.get(images.kind(data))
            if mime is None:
                raise InputError(f"images[{i}] ({image['uri']}) is in no format a glTF image "
                                 "may be", file=str(self.scene.path), where=f"images[{i}].uri",
                                 fix="export the image as PNG or JPEG")
            del image["uri"]
            image["bufferView"], image["mimeType"] = self._add_view(data), mime
        return []

    def _external_images(self) -> list[tuple[Path, bytes]]:
        """For a .gltf output: the images the input names by URI, referred to as they are when
        the output goes to the input's folder, else copied beside the output under a name baker
        makes (``image_file_name``), never at a path taken from the input."""
        target = self.output.parent
        if target.resolve() == self.base.resolve():
            return []
        files: list[tuple[Path, bytes]] = []
        for i, image, data in self._image_files():
            name = image_file_name(self.output, i, image["uri"])
            image["uri"] = quote(name)
            files.append((target / name, data))
        return files


def image_file_name(output: Path, index: int, uri: str) -> str:
    """The name of the copy of ``images[index]`` (file ``uri``) beside ``output`` when the output
    goes to another folder than the input: ``<stem>_image<index>`` and the URI's suffix when it
    is a short alphanumeric one (``.png``, ``.jpg``)."""
    suffix = PurePosixPath(unquote(uri)).suffix.lower()
    if not re.fullmatch(r"\.[a-z0-9]{1,5}", suffix):
        suffix = ""
    return f"{output.stem}_image{index}{suffix}"


def _uv_transform(reference: np.ndarray, uv: np.ndarray) -> dict | None:
    """The KHR_texture_transform {offset, scale} that maps ``reference`` (k, 2) float32 UVs onto
    ``uv`` (k, 2) to within a millionth of the page, per axis: {} when they are the same
    already, None when no such map does it (the charts not moved as one block)."""
    fit = np.empty(4)
    found = _block_fit(reference, uv.astype(np.float32), fit)
    if found == _SAME:
        return {}
    if found == _NO_FIT:
        return None
    return {"offset": [float(v) for v in fit[2:]], "scale": [float(v) for v in fit[:2]]}


_SAME, _FITS, _NO_FIT = 0, 1, 2  # what ``_block_fit`` found


@jit
def _block_fit(reference: np.ndarray, target: np.ndarray, fit: np.ndarray) -> int:
    """Whether ``target`` (k, 2) float32 is ``reference`` (k, 2) float32 (``_SAME``), or it
    scaled and moved per axis to within 10⁻⁶ (``_FITS``: ``fit`` (4,) = scale x, y and offset
    x, y, from the two sets' extents, in float64), or neither (``_NO_FIT``; so is a reference
    with no extent on an axis). One compiled pass each: numpy's dozen passes over these few
    rows were over a quarter of the writer's time a node."""
    same = True
    for i in range(len(reference)):
        for a in range(2):
            same &= reference[i, a] == target[i, a]
    if same:
        return _SAME
    for a in range(2):
        low, high = np.inf, -np.inf
        near, far = np.inf, -np.inf
        for i in range(len(reference)):
            low, high = min(low, float(reference[i, a])), max(high, float(reference[i, a]))
            near, far = min(near, float(target[i, a])), max(far, float(target[i, a]))
        if not high - low > 0:
            return _NO_FIT
        fit[a] = (far - near) / (high - low)
        fit[2 + a] = near - fit[a] * low
    for i in range(len(reference)):
        for a in range(2):
            if abs(float(reference[i, a]) * fit[a] + fit[2 + a] - float(target[i, a])) > 1e-6:
                return _NO_FIT
    return _FITS


def _moved(attribute: str, shifted: bool) -> str:
    """The attribute's name once the sets from TEXCOORD_1 on moved up one (when ``shifted``)."""
    if shifted and attribute.startswith("TEXCOORD_") and attribute[9:].isdigit():
        n = int(attribute[9:])
        return f"TEXCOORD_{n + 1}" if n >= 1 else attribute
    return attribute


def _shift_texcoords(value) -> None:
    """Every texture reference in a material's JSON (a dict with an integer ``index``: core
    textureInfos and every extension's) that reads TEXCOORD_n, n ≥ 1, reads TEXCOORD_n+1 — its
    ``texCoord``, and the ``texCoord`` of its KHR_texture_transform, which overrides it."""
    items = value if isinstance(value, list) else value.values() if isinstance(value, dict) else ()
    if isinstance(value, dict) and isinstance(value.get("index"), int):
        extensions = value.get("extensions")  # an extension's own textureInfo: unchecked JSON
        transform = (extensions.get("KHR_texture_transform") if isinstance(extensions, dict)
                     else None)
        for holder in (value, transform):
            if isinstance(holder, dict) and isinstance(holder.get("texCoord"), int) \
                    and holder["texCoord"] >= 1:
                holder["texCoord"] += 1
        return
    for item in items:
        _shift_texcoords(item)


def _carry_as_emission(material: dict, texture: int, texcoord: int, scale: float) -> None:
    """Make the material copy show the emissive carrier's page (``texture`` on UV set
    ``texcoord``, values ``texel × scale``) as its emission, in place of its own (which the page
    holds): the factor up to 1, KHR_materials_emissive_strength above it. Its diffuse response
    is taken away beforehand (``specular.without_diffuse``)."""
    extensions = material.setdefault("extensions", {})
    extensions.pop(EMISSIVE_STRENGTH, None)
    material["emissiveTexture"] = {"index": texture, "texCoord": texcoord}
    material["emissiveFactor"] = [min(scale, 1.0)] * 3
    if scale > 1.0:
        extensions[EMISSIVE_STRENGTH] = {"emissiveStrength": scale}
    if not extensions:
        del material["extensions"]


def glb_file(data: dict, blob: bytes | None) -> bytes:
    """The .glb file of the JSON ``data`` and the binary chunk ``blob``, joined in one copy
    (the blob is most of the file: megabytes)."""
    text = json.dumps(data, separators=(",", ":"), allow_nan=False).encode("utf-8")
    text += b" " * (-len(text) % 4)
    chunks = [struct.pack("<II", len(text), _GLB_JSON), text]
    if blob:
        padding = b"\0" * (-len(blob) % 4)
        chunks += [struct.pack("<II", len(blob) + len(padding), _GLB_BIN), blob, padding]
    size = 12 + sum(len(chunk) for chunk in chunks)
    return b"".join([struct.pack("<III", _GLB_MAGIC, 2, size), *chunks])


# ---------------------------------------------------------------------------------------------
# atomic output


def _output_kind(output: Path) -> str:
    suffix = output.suffix.lower()
    if suffix not in (".glb", ".gltf"):
        raise OutputError("the output must be a .glb or .gltf file", file=str(output),
                          fix="name the output <name>.glb or <name>.gltf")
    folder = output.parent
    if not folder.is_dir():
        raise OutputError(f"the output folder {folder} does not exist", file=str(output),
                          fix=f"create {folder} first, or write to an existing folder")
    if output.is_dir():
        raise OutputError("the output path is a folder", file=str(output),
                          fix="give a file name ending in .glb or .gltf")
    return suffix[1:]
