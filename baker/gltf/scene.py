"""The scene as the loader hands it to the rest of the pipeline.

A glTF file is flattened into *instances*: one per (node, mesh primitive) pair, or per GPU instance
of such a pair, each with its float64 world matrix. Geometry stays in the mesh's local space in
``Primitive`` (shared by every instance of the mesh); ``geometry.py`` puts it in world space.

Colours are linear RGB(A) floats unless a field says otherwise. Lengths are in glTF units (metres).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from baker.errors import InputError
from baker.gltf import objects
from baker.punctual import Light

# glTF sampler wrap modes (OpenGL enums), as glTF stores them.
REPEAT = 10497
CLAMP_TO_EDGE = 33071
MIRRORED_REPEAT = 33648


@dataclass(frozen=True)
class Image:
    """A decoded texture image, its texels exactly as stored in the file.

    ``pixels``: (h, w, 4) uint8 RGBA, row 0 at the top (v = 0 in glTF UV space). The values are
    sRGB-encoded for colour textures (base colour, emissive); whoever samples decodes them.
    """

    pixels: np.ndarray
    name: str = ""
    data: bytes | None = None  # the image file's bytes as read, for the writer to copy; None
    # when the image is in a buffer or a data URI (the writer has those)


@dataclass(frozen=True)
class TextureRef:
    """A material's reference to a texture: which image, which UV set, how UVs wrap.

    ``transform``: KHR_texture_transform as the affine map (a, b, c, d, e, f) of the stored UVs
    to the sampled ones, u' = a·u + b·v + c and v' = d·u + e·v + f; None without one.
    """

    image: int  # index into Scene.images
    texcoord: int = 0  # the primitive's TEXCOORD_<texcoord> set
    wrap_s: int = REPEAT
    wrap_t: int = REPEAT
    transform: tuple[float, float, float, float, float, float] | None = None


@dataclass(frozen=True)
class Material:
    """What the baker needs of a glTF material.

    ``index`` is the glTF material index, or None for the default material that glTF prescribes for
    primitives without one (white, opaque, metallic 1, roughness 1, single-sided).
    """

    index: int | None
    name: str
    base_color: np.ndarray  # (4,) float64 linear RGBA, baseColorFactor
    base_color_texture: TextureRef | None
    emissive: np.ndarray  # (3,) float64 linear, emissiveFactor × KHR_materials_emissive_strength
    emissive_texture: TextureRef | None
    metallic: float = 1.0
    roughness: float = 1.0
    alpha_mode: str = "OPAQUE"  # OPAQUE, MASK or BLEND
    alpha_cutoff: float = 0.5
    double_sided: bool = False
    unlit: bool = False  # KHR_materials_unlit
    extensions: tuple[str, ...] = ()  # names of the material's extensions, for the plan
    # metallicRoughnessTexture (linear: G roughness, B metallic), None when absent.
    metallic_roughness_texture: TextureRef | None = None
    transmission: float = 0.0  # KHR_materials_transmission transmissionFactor
    # KHR_materials_transmission transmissionTexture (linear, R: × the factor), None when absent.
    transmission_texture: TextureRef | None = None
    ior: float = 1.5  # KHR_materials_ior
    specular: float = 1.0  # KHR_materials_specular specularFactor (its texture left out)
    specular_color: np.ndarray = field(default_factory=lambda: np.ones(3))  # (3,) its colour factor
    thickness: float = 0.0  # KHR_materials_volume thicknessFactor, mesh units (0: thin-walled)
    attenuation_distance: float = float("inf")  # KHR_materials_volume, metres
    attenuation_color: np.ndarray = field(default_factory=lambda: np.ones(3))  # (3,) linear
    diffuse_transmission: float = 0.0  # KHR_materials_diffuse_transmission factor
    diffuse_transmission_color: np.ndarray = field(default_factory=lambda: np.ones(3))  # (3,)
    # occlusionTexture (linear, R): read only where it carries a bake (the occlusion carrier,
    # baker preview), its UV set and transform as the other textures'; None when absent.
    occlusion_texture: TextureRef | None = None

    def textures(self) -> tuple[TextureRef, ...]:
        """Every texture the material reads (each ``TextureRef`` field that is set)."""
        return tuple(ref for ref in (self.base_color_texture, self.emissive_texture,
                                     self.metallic_roughness_texture, self.transmission_texture,
                                     self.occlusion_texture) if ref is not None)


@dataclass(frozen=True)
class Primitive:
    """One glTF mesh primitive's triangles, in the mesh's local space.

    ``mesh``/``index`` say where it lives: ``meshes[mesh].primitives[index]``.
    Vertex arrays all have n rows; ``triangles`` is (m, 3) int64 into them (strips and fans are
    already expanded to triangle lists, non-indexed primitives given indices 0..n-1).
    """

    mesh: int
    index: int
    positions: np.ndarray  # (n, 3) float64
    normals: np.ndarray | None  # (n, 3) float64, None when the file has none
    texcoords: tuple[np.ndarray, ...]  # TEXCOORD_0, TEXCOORD_1, …: each (n, 2) float64
    colors: np.ndarray | None  # (n, 4) float64 linear RGBA from COLOR_0, None when absent
    triangles: np.ndarray  # (m, 3) int64
    material: int  # index into Scene.materials
    has_morph_targets: bool = False


@dataclass(frozen=True)
class Instance:
    """One placement of a primitive in the world.

    ``world`` is the (4, 4) float64 matrix from the primitive's local space to world space
    (column vectors: p_world = world @ [p, 1]). ``baked`` says whether the instance gets lightmap
    texels; instances that are not baked still occlude and reflect light, and ``reason`` says why
    they are not baked (GPU-instanced, skinned, unlit, …).
    """

    node: int
    primitive: int  # index into Scene.primitives
    world: np.ndarray
    baked: bool = True
    reason: str = ""
    gpu_instance: int | None = None  # index within EXT_mesh_gpu_instancing, if any


@dataclass(frozen=True)
class Skipped:
    """Something in the file the bake leaves out, with where it is and why."""

    where: str  # glTF JSON path, e.g. "meshes[2].primitives[0]"
    reason: str


@dataclass(frozen=True)
class Scene:
    """A loaded glTF scene: the flattened instances plus the document to write back.

    ``document`` is the file's document as read (``objects``) (buffers resolved); the writer changes only what
    the bake adds to it. ``materials`` has one entry per glTF material, then the default material.
    """

    path: Path
    document: objects.GLTF2
    primitives: tuple[Primitive, ...]
    instances: tuple[Instance, ...]
    materials: tuple[Material, ...]
    images: tuple[Image, ...]
    skipped: tuple[Skipped, ...] = field(default=())
    lights: tuple[Light, ...] = field(default=())  # KHR_lights_punctual lights, in node order
    # Metals smoother than this are mirrors (materials.py); a setting, carried with the scene.
    mirror_roughness: float = 0.1
    # The bytes of every document.buffers[i], as read (a compressed file's as decoded:
    # decompress.py), for the writer: no file is read twice.
    buffers: tuple[bytes, ...] = ()
    # (device, inode) → how the scene reads it, of every file the load opened (the scene file,
    # its buffers and images): no file a bake writes may replace one (run/atomic.py).
    inputs: dict[tuple[int, int], str] = field(default_factory=dict)

    def recorded_bake(self) -> dict | None:
        """What baker recorded in a file it wrote (``asset.extras.baker``: the carrier, the
        lightmap encoding), or None when the file holds no such object."""
        extras = getattr(self.document.asset, "extras", None)
        made = extras.get("baker") if isinstance(extras, dict) else None
        return made if isinstance(made, dict) else None

    def check_not_a_bake(self) -> None:
        """Refuse a file baker wrote (``asset.extras.baker``, as ``output.write`` marks every
        bake): its materials are lightmap copies (under the emissive carrier black, their light
        in their emission, which a second bake would take for emitters), and baking them again
        copies the copies. The first bake's output given again as input, e.g. after
        ``--overwrite`` replaced the scene with its bake, ended in "nothing baked: black base
        colour", which named neither the file's kind nor what to do."""
        made = self.recorded_bake()
        if made is None:
            return
        carrier = made.get("carrier")
        raise InputError(
            f"this file is a bake baker wrote (asset.extras.baker"
            f"{f', carrier {carrier}' if isinstance(carrier, str) else ''}): its materials "
            "are the lightmap copies of the scene it was made from, which a bake would copy "
            "again", file=str(self.path), where="asset.extras.baker",
            fix="bake the scene it was made from; to bake this file as it is, remove "
                "asset.extras.baker from it")

    def lights_needed(self) -> bool:
        """Whether the punctual lights light a surface that no lightmap will hold: an instance
        left without one (skinned, GPU-instanced, animated, a mirror, clear glass) whose
        material is not unlit. Removing the lights would leave it dark in a viewer."""
        return bool(self.lights) and any(
            not inst.baked and not self.materials[self.primitives[inst.primitive].material].unlit
            for inst in self.instances)
