"""What a glTF material does to an obscurance ray: the paper's §3–5 cases, from glTF.

``classify`` maps one ``scene.Material`` to the ``materials.Classification`` the estimators
read: the weights of four branches that sum to 1 —
diffuse, perfect specular (§3.1), transparent (§3.2) and translucent (§3.3) — plus its alpha
test, sidedness and unlit flag (docs/design.md §2, materials table):

- metal part ``metallic``: a mirror (specular, colour = base colour) when roughness is under
  ``mirror_roughness`` (a setting); rougher metal scatters its light widely and counts as
  diffuse (the paper has no glossy case). So the glTF default material (metallic 1, roughness 1)
  and exporters' defaults stay diffuse, as before.
- dielectric part ``1 − metallic``, split by ``KHR_materials_transmission``: the transmitted
  part ``transmission`` refracts (transparent, IOR from ``KHR_materials_ior``, tinted by the base
  colour) when smooth, or counts as translucent when rough (frosted glass); the rest splits by
  ``KHR_materials_diffuse_transmission`` into translucent and diffuse.

So diffuse albedo = base × [(1 − m)(1 − t)(1 − dt) + m·rough] (texture and vertex colours
multiply at the hit, ``surface.albedo``). ``KHR_materials_volume`` (thickness, attenuation) is
kept for the inner obscurances of translucent objects. A ``metallicRoughnessTexture`` counts by
its mean (B metallic, G roughness, linear) times the factors: one classification per material.

Alpha (``alphaMode``): MASK lets rays through where base alpha × texture alpha × vertex alpha is
below ``alphaCutoff``; BLEND lets them through with probability 1 − alpha. ``AlphaTest`` holds
what the tracer needs for that (trace.py), per world triangle, built only when some triangle can
let a ray through: a scene without alpha-tested materials pays nothing.
"""

from __future__ import annotations

import numpy as np

from baker.materials import (
    BRANCHES,
    DIFFUSE,
    SPECULAR,
    TRANSLUCENT,
    TRANSPARENT,
    Classification,
    MaterialTable,
    table_of,
)

MIRROR_ROUGHNESS = 0.1
"""Default threshold: metals with (mean) roughness below it are perfect mirrors."""

UNLIT_REASON = "unlit material"


def _texture_mean(images, ref, channel: int) -> float:
    """Mean of one 8-bit channel of a (linear) texture, in [0, 1]; 1 without a texture."""
    if ref is None or ref.image >= len(images):
        return 1.0
    pixels = images[ref.image].pixels
    return float(pixels[..., channel].mean()) / 255.0


def classify(material, images=(), mirror_roughness: float = MIRROR_ROUGHNESS) -> Classification:
    """The obscurance model's view of ``material`` (a ``scene.Material``); ``images``: the
    scene's decoded images (for the metallic-roughness and alpha textures' values)."""
    base = np.clip(np.asarray(material.base_color, np.float64)[:3], 0.0, None)
    mr = material.metallic_roughness_texture
    metallic = float(np.clip(material.metallic * _texture_mean(images, mr, 2), 0.0, 1.0))
    roughness = float(np.clip(material.roughness * _texture_mean(images, mr, 1), 0.0, 1.0))
    smooth = roughness < mirror_roughness
    transmission = float(np.clip(material.transmission, 0.0, 1.0))
    diffuse_transmission = float(np.clip(material.diffuse_transmission, 0.0, 1.0))
    dielectric = 1.0 - metallic
    weights = np.zeros(4)
    weights[SPECULAR] = metallic if smooth else 0.0
    weights[TRANSPARENT] = dielectric * transmission if smooth else 0.0
    weights[TRANSLUCENT] = (dielectric * (1.0 - transmission) * diffuse_transmission
                            + (0.0 if smooth else dielectric * transmission))
    weights[DIFFUSE] = max(1.0 - weights[1:].sum(), 0.0)
    texture = material.base_color_texture
    alpha_textured = bool(texture is not None and texture.image < len(images)
                          and images[texture.image].pixels[..., 3].min() < 255)
    return Classification(
        weights=weights,
        diffuse=base * weights[DIFFUSE],
        specular_color=base.copy(),
        transmission_color=base.copy(),
        translucent_color=base * np.clip(np.asarray(material.diffuse_transmission_color,
                                                    np.float64), 0.0, None),
        ior=float(material.ior) if material.ior >= 1.0 else 1.5,
        thickness=max(float(material.thickness), 0.0),
        attenuation_distance=float(material.attenuation_distance),
        attenuation_color=np.asarray(material.attenuation_color, np.float64),
        metallic=metallic,
        roughness=roughness,
        alpha_mode=material.alpha_mode,
        alpha_cutoff=float(material.alpha_cutoff),
        alpha=float(material.base_color[3]),
        alpha_textured=alpha_textured,
        double_sided=bool(material.double_sided),
        unlit=bool(material.unlit),
    )


def no_lightmap_reason(c: Classification) -> str:
    """Why surfaces of a material with classification ``c`` get no lightmap texels ("" when
    they get them): the lightmap is multiplied by the diffuse albedo, so where that is zero (or
    the surface is never drawn, or drawn unlit) its texels would never be seen."""
    if c.unlit:
        return UNLIT_REASON
    if c.invisible:
        return "alpha below the cutoff everywhere: never drawn"
    if c.weights[DIFFUSE] > 0 and c.diffuse.max() > 0:
        return ""
    if c.weights[DIFFUSE] == 0:
        branch = BRANCHES[int(np.argmax(c.weights))]
        what = {"specular": "perfect mirror (smooth metal)",
                "transparent": "clear glass (full transmission)",
                "translucent": "fully translucent (diffuse transmission)"}[branch]
        return f"{what}: zero diffuse albedo, occluder and {branch} neighbour only"
    return "black base colour: zero diffuse albedo"


def material_table(scene) -> MaterialTable:
    """``classify`` every material of ``scene`` with the scene's mirror threshold: built once
    per bake, with its world (``geometry.world.build_world``: the texture means cost a pass
    over each image)."""
    return table_of(tuple(classify(m, scene.images, scene.mirror_roughness)
                          for m in scene.materials))


def normal_mapped(scene, material: int) -> bool:
    """Whether the scene's material ``material`` (index into ``Scene.materials``) has a glTF
    ``normalTexture``: what directional lightmaps are for (``Settings.directional``)."""
    index = scene.materials[material].index
    if index is None or not scene.document.materials:
        return False
    return getattr(scene.document.materials[index], "normalTexture", None) is not None


def has_normal_maps(scene) -> bool:
    """Whether a baked instance's material has a normal map (``normal_mapped``)."""
    return any(normal_mapped(scene, scene.primitives[inst.primitive].material)
               for inst in scene.instances if inst.baked)
