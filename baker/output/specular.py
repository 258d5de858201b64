"""The emissive carrier's material copies: no diffuse response, the specular response kept.

The emissive carrier's pages hold the diffuse light the bake computed (``image/carriers.py``), as
the copy's emission. A viewer must then add nothing diffuse — its lights and its environment would
light the surface a second time — but it should keep what the bake leaves out: each material's
specular reflection of the viewer's lights and environment (highlights, Fresnel, metals' colour).

glTF's metallic-roughness BRDF mixes a dielectric (diffuse base colour × (1 − metallic), and a
specular lobe of reflectance F0 = ((ior − 1)/(ior + 1))², 0.04 at ior 1.5) with a metal
(specular only, F0 = base colour), both through the same Schlick Fresnel and GGX lobe. So:

- a dielectric (metallic 0) loses its diffuse with a black base colour, and keeps its specular
  lobe whole (it does not depend on the base colour): roughness, normal map, ``KHR_materials_ior``
  and ``KHR_materials_specular``, clear coat, sheen are kept;
- a metal (metallic 1, no metallic texture) has no diffuse: the copy keeps its material as it is;
- a material whose metallic varies (a metallicRoughnessTexture, or a factor between 0 and 1) is
  made metal everywhere with base colour F0 = mix(F0_dielectric, base colour, metallic) per texel
  of new textures: the same specular reflectance, no diffuse;
- a ``KHR_materials_pbrSpecularGlossiness`` material (read as a dielectric whose diffuse is its
  diffuseFactor × diffuseTexture) gets a black diffuseFactor and loses its diffuseTexture the
  same way, its specular colour and glossiness kept: the viewers that read the extension
  (Babylon.js, Blender, glTFast) read it in place of the core terms;
- a transmissive material keeps its base colour, which tints what it lets through: its
  (1 − transmission) diffuse share is lit by the viewer as well (noted in the report).

``KHR_materials_diffuse_transmission`` is dropped: the light it lets through a thin surface is in
the bake.
"""

from __future__ import annotations

import io
from collections.abc import Callable

import numpy as np
from PIL import Image as PILImage

from baker.geometry.surface import SRGB_TO_LINEAR
from baker.gltf.read_materials import SPEC_GLOSS
from baker.gltf.scene import Material, Scene
from baker.image.encode import linear_to_srgb

DROPPED = ("KHR_materials_diffuse_transmission",)
"""Material extensions a copy loses: their light is in the bake."""

AddImage = Callable[[bytes, str], int]
"""Adds a PNG image (bytes, name) to the output and returns its texture index."""


def dielectric_f0(material: Material) -> np.ndarray:
    """(3,) the specular reflectance at normal incidence of ``material``'s dielectric part:
    ((ior − 1)/(ior + 1))² × KHR_materials_specular's factor and colour (their textures left
    out), in [0, 1]: the values the load read and checked (it read them from the file's JSON
    here, unchecked: an ior that was a string ended the bake in an internal error)."""
    f0 = ((material.ior - 1.0) / (material.ior + 1.0)) ** 2
    return np.clip(f0 * material.specular * material.specular_color, 0.0, 1.0)


def kind(material: Material) -> str:
    """How a copy of ``material`` loses its diffuse response: "transmissive", "dielectric",
    "metal" or "mixed" (the module's docstring)."""
    if material.transmission > 0.0:
        return "transmissive"
    if material.metallic <= 0.0:
        return "dielectric"
    if material.metallic >= 1.0 and material.metallic_roughness_texture is None:
        return "metal"
    return "mixed"


def without_diffuse(copied: dict, material: Material, scene: Scene,
                    mixed_textures: Callable[[np.ndarray], tuple[int, int] | None]) -> str | None:
    """Make ``copied`` (a material's JSON, changed in place) reflect as ``material`` does but with
    no diffuse response; ``mixed_textures(f0)`` gives the (base colour, metallicRoughness)
    textures of a "mixed" material whose dielectric part reflects ``f0`` (``mixed_pair``), made
    once per material. Returns a note for the report, or None."""
    extensions = copied.get("extensions") or {}
    for name in DROPPED:
        extensions.pop(name, None)
    opaque = copied.get("alphaMode", "OPAQUE") == "OPAQUE"
    if isinstance(extensions.get(SPEC_GLOSS), dict):  # replaces the core terms where a viewer
        # reads it (Babylon.js, Blender, glTFast): a dielectric whose diffuse goes black too
        _black_diffuse(extensions[SPEC_GLOSS], "diffuseFactor", "diffuseTexture", opaque)
    pbr = copied.setdefault("pbrMetallicRoughness", {})
    how = kind(material)
    if how == "dielectric":
        _black_diffuse(pbr, "baseColorFactor", "baseColorTexture", opaque)
        return None
    if how == "mixed":
        alpha = float((pbr.get("baseColorFactor") or [1.0, 1.0, 1.0, 1.0])[3])
        pbr["metallicFactor"] = 1.0
        f0 = dielectric_f0(material)
        for name in ("KHR_materials_ior", "KHR_materials_specular"):  # a metal has no use for them
            extensions.pop(name, None)
        textured = pbr.get("metallicRoughnessTexture") or pbr.get("baseColorTexture")
        if textured is None:  # factors only
            colour = (1.0 - material.metallic) * f0 + material.metallic * material.base_color[:3]
            pbr["baseColorFactor"] = [*map(float, colour), alpha]
            return None
        made = mixed_textures(f0)
        if made is None:
            return (f"material {material.name!r}: its base colour and metallic textures use "
                    "other UVs, so its copies are made all metal with its base colour: "
                    "its dielectric parts reflect in colour")
        base, metal_roughness = made
        pbr["baseColorFactor"] = [1.0, 1.0, 1.0, 1.0]
        pbr["baseColorTexture"] = {**textured, "index": base}
        if metal_roughness is not None:
            pbr["metallicRoughnessTexture"]["index"] = metal_roughness
        return None
    if how == "transmissive" and material.transmission < 1.0:
        return (f"material {material.name!r} (transmission {material.transmission:g}) keeps its "
                "base colour, which tints what it lets through: viewers light its "
                f"{1 - material.transmission:.0%} diffuse share themselves as well as the bake")
    return None


def _black_diffuse(terms: dict, factor: str, texture: str, opaque: bool) -> None:
    """Make the colour ``factor`` of ``terms`` (a material's JSON object, changed in place)
    black, its alpha kept, and drop its ``texture`` where the material is ``opaque`` (else the
    texture stays for its alpha)."""
    alpha = float((terms.get(factor) or [1.0, 1.0, 1.0, 1.0])[3])
    terms[factor] = [0.0, 0.0, 0.0, alpha]
    if opaque:
        terms.pop(texture, None)


def mixed_pair(material: Material, scene: Scene, f0: np.ndarray,
               add_image: AddImage) -> tuple[int, int | None] | None:
    """For a "mixed" ``material`` with a texture: a texture of base colour F0 = mix(f0, base,
    metallic) (sRGB, its alpha kept), and one of metallicRoughness with metallic 1 (the other
    channels kept; None without a metallicRoughnessTexture), on the UVs of its textures, at the
    larger of the two images' sizes; None when its base colour and metallic textures use other
    UVs (another set or transform)."""
    metal_ref, base_ref = material.metallic_roughness_texture, material.base_color_texture
    if base_ref is not None and metal_ref is not None and (
            base_ref.texcoord, base_ref.transform) != (metal_ref.texcoord, metal_ref.transform):
        return None
    white = np.full((1, 1, 4), 255, np.uint8)
    metal = scene.images[metal_ref.image].pixels if metal_ref is not None else white
    base = scene.images[base_ref.image].pixels if base_ref is not None else white
    height, width = max(base.shape[0], metal.shape[0]), max(base.shape[1], metal.shape[1])
    base, metal = _resized(base, height, width), _resized(metal, height, width)
    table = _reflectance_levels(material, f0)
    alpha = np.round(np.clip(np.arange(256.0) * material.base_color[3], 0, 255)).astype(np.uint8)
    rgba = np.dstack([table[metal[..., 2, None], np.arange(3), base[..., :3]], alpha[base[..., 3]]])
    name = material.name or f"material {material.index}"
    colour_texture = add_image(_png(rgba), f"{name} specular colour")
    if metal_ref is None:
        return colour_texture, None
    metal_out = metal[..., :3].copy()
    metal_out[..., 2] = 255
    return colour_texture, add_image(_png(metal_out), f"{name} metal roughness")


def _resized(pixels: np.ndarray, height: int, width: int) -> np.ndarray:
    """``pixels`` (h, w, 4) uint8 at (height, width), nearest texel (both sides multiples of
    texel centres: an image of 1×1 is a constant)."""
    rows = (np.arange(height) + 0.5) * pixels.shape[0] // height
    cols = (np.arange(width) + 0.5) * pixels.shape[1] // width
    return pixels[rows.astype(np.int64)][:, cols.astype(np.int64)]


def _reflectance_levels(material: Material, f0: np.ndarray) -> np.ndarray:
    """(256, 3, 256) uint8: the sRGB level of F0 = mix(f0, base colour, metallic) in each
    channel for each metallic texture level (blue channel, first axis) and base colour texture
    level (last axis), the material's factors applied. A texel's level depends on those two
    levels alone, so the 196,608 entries are computed once for the texture's millions of texels
    (a 2048² texture: 1.8 s elementwise, of a 7.8 s bake of LightsPunctualLamp)."""
    metallic = np.clip(material.metallic * np.arange(256.0) / 255.0, 0.0, 1.0)[:, None, None]
    colour = SRGB_TO_LINEAR[None, None, :] * np.asarray(material.base_color[:3])[None, :, None]
    reflectance = (1.0 - metallic) * np.asarray(f0)[None, :, None] + metallic * colour
    return np.round(linear_to_srgb(reflectance) * 255.0).astype(np.uint8)


def _png(pixels: np.ndarray) -> bytes:
    """A PNG of (h, w, 3 or 4) uint8 pixels, the same bytes for the same pixels."""
    out = io.BytesIO()
    PILImage.fromarray(np.ascontiguousarray(pixels)).save(out, format="PNG", optimize=False)
    return out.getvalue()
