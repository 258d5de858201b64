"""The file's materials as the bake sees them (``read_materials``): base colour, emission,
transmission, volume, IOR, diffuse transmission, unlit and specular-glossiness read into
``Material``s, with their textures (``TextureRef``: UV set, KHR_texture_transform)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from baker.errors import InputError
from baker.gltf import budget, images, objects
from baker.gltf.context import (MAX_ALBEDO, Context, checked_item, finite, invalid,
                                or_default, referred, schema)
from baker.gltf.extensions import MATERIAL_EXTENSIONS
from baker.gltf.read_images import decode_image
from baker.gltf.scene import REPEAT, Material, TextureRef
from baker.settings import MAX_LIGHT


SPEC_GLOSS = "KHR_materials_pbrSpecularGlossiness"


def read_materials(ctx: Context) -> list[Material]:
    """One Material per glTF material, then the default material (index None) last."""
    materials = []
    for i, material in enumerate(ctx.document.materials):
        with schema(ctx.file, f"materials[{i}]"):
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


def _read_material(ctx: Context, i: int, material: objects.Material) -> Material:
    """The baker's view of ``materials[i]``: factors as float64 linear values, texture refs."""
    where = f"materials[{i}]"
    extensions = material.extensions or {}
    strength = (extensions.get("KHR_materials_emissive_strength") or {}).get("emissiveStrength", 1.0)
    base = _base_terms(ctx, material, extensions, where)
    emissive = _factor(ctx, material.emissiveFactor, [0.0, 0.0, 0.0], f"{where}.emissiveFactor",
                       colour=False)  # checked with its strength (``_emission``)
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
    specular = _extension(extensions, "KHR_materials_specular")
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
        transmission_texture=_optional_texture(
            ctx, _texture_info(_extension(extensions, "KHR_materials_transmission")
                               .get("transmissionTexture")),
            f"{ext}.KHR_materials_transmission.transmissionTexture", "the transmission factor"),
        ior=value(_extension(extensions, "KHR_materials_ior"), "ior", 1.5, 1.0, math.inf,
                  f"{ext}.KHR_materials_ior"),
        specular=value(specular, "specularFactor", 1.0, 0.0, 1.0, f"{ext}.KHR_materials_specular"),
        specular_color=_factor(ctx, specular.get("specularColorFactor"), [1.0, 1.0, 1.0],
                               f"{ext}.KHR_materials_specular.specularColorFactor",
                               colour=False),
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


def _base_terms(ctx: Context, material: objects.Material, extensions: dict,
                where: str) -> dict[str, Any]:
    """The Material fields of the base layer: base colour factor and texture, metallic,
    roughness and their texture, from pbrMetallicRoughness, or from
    KHR_materials_pbrSpecularGlossiness when the material has it (the extension replaces the
    core terms): its diffuseFactor/diffuseTexture are the diffuse albedo a lightmap needs, as a
    dielectric (metallic 0) of roughness 1 − glossinessFactor."""
    spec_gloss = extensions.get(SPEC_GLOSS)
    if isinstance(spec_gloss, dict):
        at = f"{where}.extensions.{SPEC_GLOSS}"
        info = _texture_info(spec_gloss.get("diffuseTexture"))
        glossiness = _material_number(ctx, spec_gloss, "glossinessFactor", 1.0, 0.0, 1.0,
                                      f"{at}.glossinessFactor")
        return dict(
            base_color=_factor(ctx, spec_gloss.get("diffuseFactor"), [1.0, 1.0, 1.0, 1.0],
                               f"{at}.diffuseFactor"),
            base_color_texture=_texture_ref(ctx, info, f"{at}.diffuseTexture"),
            metallic=0.0, roughness=1.0 - glossiness, metallic_roughness_texture=None)
    pbr = material.pbrMetallicRoughness or objects.PbrMetallicRoughness()
    at = f"{where}.pbrMetallicRoughness"
    return dict(
        base_color=_factor(ctx, pbr.baseColorFactor, [1.0, 1.0, 1.0, 1.0], f"{at}.baseColorFactor"),
        base_color_texture=_texture_ref(ctx, pbr.baseColorTexture, f"{at}.baseColorTexture"),
        metallic=_material_number(ctx, {"metallicFactor": pbr.metallicFactor}, "metallicFactor",
                                  1.0, 0.0, 1.0, f"{at}.metallicFactor"),
        roughness=_material_number(ctx, {"roughnessFactor": pbr.roughnessFactor}, "roughnessFactor",
                                   1.0, 0.0, 1.0, f"{at}.roughnessFactor"),
        metallic_roughness_texture=_optional_texture(ctx, pbr.metallicRoughnessTexture,
                                                     f"{at}.metallicRoughnessTexture",
                                                     "metallic and roughness factors"))


def _optional_texture(ctx: Context, info: Any, where: str, factors: str) -> TextureRef | None:
    """``_texture_ref`` for a texture the bake can do without (metallic-roughness,
    transmission): one it cannot read is left out and recorded in ``ctx.skipped`` instead of
    stopping the bake, its material's ``factors`` used alone."""
    try:
        return _texture_ref(ctx, info, where)
    except InputError as error:
        ctx.skip(where, f"cannot be read ({error.message}): {factors} used alone")
        return None


def _texture_info(texture: Any) -> objects.TextureInfo | None:
    """A textureInfo of an extension's JSON (a dict with ``index``, ``texCoord``,
    ``extensions``) as an ``objects.TextureInfo``, for ``_texture_ref``; None when it is not one."""
    if not isinstance(texture, dict):
        return None
    return objects.TextureInfo(index=texture.get("index"), texCoord=texture.get("texCoord"),
                                 extensions=texture.get("extensions"))


def _extension(extensions: dict, name: str) -> dict:
    """A material extension's object ({} when absent or not an object)."""
    value = extensions.get(name)
    return value if isinstance(value, dict) else {}


def _material_number(ctx: Context, values: dict, key: str, default: float, low: float,
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


def _emission(ctx: Context, factor: np.ndarray, strength: Any, where: str) -> np.ndarray:
    """emissiveFactor × KHR_materials_emissive_strength, finite, ≥ 0 and at most
    ``MAX_LIGHT`` (1e-6 to 1e6 and beyond bake; NaN, infinity, a negative value or one past
    the bound is refused)."""
    strength_where = f"{where}.extensions.KHR_materials_emissive_strength.emissiveStrength"
    if isinstance(strength, bool) or not isinstance(strength, (int, float)):
        raise invalid(f"emissiveStrength {strength!r} is not a number", ctx.file, strength_where)
    with np.errstate(over="ignore"):
        emission = factor * float(strength)
    if not (np.isfinite(emission).all() and (emission >= 0).all() and strength >= 0):
        raise invalid(f"emission {factor.tolist()} × {strength!r} is not a finite number ≥ 0",
                      ctx.file, strength_where if not (factor < 0).any() else f"{where}.emissiveFactor")
    if emission.max() > MAX_LIGHT:
        raise InputError(f"emission {factor.tolist()} × {strength!r} is above {MAX_LIGHT:g}, "
                         "past any real light", file=ctx.file, where=strength_where,
                         fix="check the emissive strength (it multiplies emissiveFactor) "
                             "and export the material again")
    return emission


def _factor(ctx: Context, value: Any, default: list[float], where: str,
            colour: bool = True) -> np.ndarray:
    """A material factor as a finite float64 vector of the default's length; a colour
    (``colour``) clamped to [0, ``MAX_ALBEDO``], with a warning in ``ctx.skipped`` where it is
    not."""
    vector = np.asarray(or_default(value, default), dtype=np.float64)
    if vector.shape != (len(default),) or not np.isfinite(vector).all():
        raise invalid(f"expected {len(default)} finite numbers, found {value!r}", ctx.file, where)
    clamped = np.clip(vector, 0.0, MAX_ALBEDO) if colour else vector
    if not np.array_equal(clamped, vector):
        ctx.skip(where, f"{vector.tolist()} is outside [0, {MAX_ALBEDO:g}]: {clamped.tolist()} "
                        "is used")
    return clamped


MAX_TEXCOORD_SETS = 32
"""A texture may name TEXCOORD_0 to TEXCOORD_31; past that (or below 0) it is left out: the
world holds one UV array per set up to the highest a material reads."""


def _texture_ref(ctx: Context, info: Any, where: str) -> TextureRef | None:
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
    texture = checked_item(ctx.document.textures, info.index, "textures", ctx.file,
                           f"{where}.index")
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
    checked_item(ctx.document.images, source, "images", ctx.file, f"{texture_where}.source")
    try:
        with referred(where):
            decode_image(ctx, source)
    except (images.Undecodable, budget.OverBudget) as exc:
        named = f" ({extension})" if extension else ""
        ctx.skip(texture_where, f"image {source}{named} not decoded ({exc.message}; {exc.fix}): "
                                "texture left out, its material's factor used")
        return None
    texcoord = int(or_default(info.texCoord, 0))
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
        sampler = checked_item(samplers, texture.sampler, "samplers", ctx.file,
                               f"{texture_where}.sampler")
        wrap_s, wrap_t = or_default(sampler.wrapS, REPEAT), or_default(sampler.wrapT, REPEAT)
    return TextureRef(image=source, texcoord=texcoord, wrap_s=wrap_s, wrap_t=wrap_t,
                      transform=affine)


def _uv_transform(ctx: Context, transform: dict, where: str) -> tuple[float, ...] | None:
    """KHR_texture_transform's offset, rotation and scale as ``TextureRef.transform``:
    uv' = offset + R(rotation) · (scale ⊙ uv), with u' = u·cos + v·sin and v' = v·cos − u·sin
    (the extension's matrix T · R · S; the UVs turn counter-clockwise, the image clockwise).
    None when it is the identity; a value that is not finite numbers is left out with a
    warning (the UVs are then used as stored)."""
    try:
        offset = finite(ctx, or_default(transform.get("offset"), [0.0, 0.0]), 2, f"{where}.offset")
        rotation = finite(ctx, [or_default(transform.get("rotation"), 0.0)], 1, f"{where}.rotation")[0]
        scale = finite(ctx, or_default(transform.get("scale"), [1.0, 1.0]), 2, f"{where}.scale")
    except InputError as error:
        ctx.skip(where, f"{error.message}: the texture is sampled with the UVs as stored")
        return None
    cos, sin = math.cos(rotation), math.sin(rotation)
    affine = (scale[0] * cos, scale[1] * sin, offset[0], -scale[0] * sin, scale[1] * cos, offset[1])
    return None if affine == (1.0, 0.0, 0.0, 0.0, 1.0, 0.0) else tuple(float(x) for x in affine)
