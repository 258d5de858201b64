"""The glTF extensions baker knows: those a file may require and still be baked, and the
material extensions the bake reads or has no need of."""

from __future__ import annotations

from baker.gltf.decompress import COMPRESSION_EXTENSIONS


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


def unsupported_kind(name: str) -> str:
    """What an extension baker does not support is, from its name, for the refusal's message."""
    if "compression" in name:
        return "compressed geometry"
    if name.startswith(("KHR_texture_", "EXT_texture_")):
        return "a texture format or sampling extension"
    if "_materials_" in name:
        return "a material extension"
    return "an extension baker does not know"
