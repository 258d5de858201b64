"""What a glTF material does to an obscurance ray: the paper's §3–5 cases, from glTF.

``classify`` maps one ``scene.Material`` to the weights of four branches that sum to 1 —
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

from dataclasses import dataclass

import numpy as np

MIRROR_ROUGHNESS = 0.1
"""Default threshold: metals with (mean) roughness below it are perfect mirrors."""

UNLIT_REASON = "unlit material"

# Branches of a hit, in the column order of ``MaterialTable.weights``.
DIFFUSE, SPECULAR, TRANSPARENT, TRANSLUCENT = range(4)
BRANCHES = ("diffuse", "specular", "transparent", "translucent")


@dataclass(frozen=True)
class Classification:
    """One material as the obscurance model sees it. Colours are (3,) float64 linear RGB
    factors (textures and vertex colours multiply the diffuse one at each hit).

    weights: (4,) fractions of the light a hit sends into each branch (DIFFUSE, SPECULAR,
    TRANSPARENT, TRANSLUCENT), summing to 1. diffuse: base colour × weights[DIFFUSE], the
    diffuse albedo factor. specular_color / transmission_color / translucent_color: the tint
    of each branch. ior: index of refraction. thickness (mesh units, 0 thin-walled),
    attenuation_distance (metres, inf none) and attenuation_color: KHR_materials_volume.
    metallic / roughness: the effective values (factors × texture means). alpha: base colour
    alpha; alpha_textured: the base colour texture has alpha below 1 somewhere.
    """

    weights: np.ndarray
    diffuse: np.ndarray
    specular_color: np.ndarray
    transmission_color: np.ndarray
    translucent_color: np.ndarray
    ior: float
    thickness: float
    attenuation_distance: float
    attenuation_color: np.ndarray
    metallic: float
    roughness: float
    alpha_mode: str
    alpha_cutoff: float
    alpha: float
    alpha_textured: bool
    double_sided: bool
    unlit: bool

    @property
    def alpha_tested(self) -> bool:
        """Whether some ray may pass through this material's surfaces (alpha below opaque)."""
        if self.alpha_mode == "MASK":
            return self.alpha < self.alpha_cutoff or self.alpha_textured
        if self.alpha_mode == "BLEND":
            return self.alpha < 1.0 or self.alpha_textured
        return False

    @property
    def invisible(self) -> bool:
        """Every ray passes (MASK with constant alpha below the cutoff, BLEND with alpha 0)."""
        if self.alpha_textured:
            return False
        return (self.alpha_mode == "MASK" and self.alpha < self.alpha_cutoff) or (
            self.alpha_mode == "BLEND" and self.alpha <= 0.0)

    @property
    def translucency(self) -> np.ndarray:
        """(3,) the share of light that crosses the surface (§4): the translucent branch's
        weight × its tint (base colour × diffuseTransmissionColor)."""
        return self.weights[TRANSLUCENT] * self.translucent_color

    @property
    def leaf(self) -> bool:
        """Thin double-sided translucent geometry (no KHR_materials_volume thickness): a leaf
        (§4), whose texels add the back face's obscurance × ``translucency`` to the front's."""
        return self.weights[TRANSLUCENT] > 0 and self.double_sided and self.thickness <= 0.0

    @property
    def inner(self) -> bool:
        """A closed translucent object (KHR_materials_volume thickness > 0): its texels get the
        inner obscurance (§4, equation 5)."""
        return self.weights[TRANSLUCENT] > 0 and self.thickness > 0.0

    def stages(self) -> set[str]:
        """Which of the bake's material stages this material needs."""
        out = set()
        if self.leaf:
            out.add("leaves")
        if self.inner:
            out.add("inner obscurances")
        if self.weights[SPECULAR] > 0:
            out.add("specular chains")
        if self.weights[TRANSPARENT] > 0:
            out.add("refraction")
        if self.weights[TRANSLUCENT] > 0:
            out.add("translucency")
        if self.alpha_tested:
            out.add("alpha testing")
        return out


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


@dataclass(frozen=True)
class MaterialTable:
    """Every material's classification as arrays, for vectorised shading of hits.

    weights: (M, 4) branch weights; specular / transmission / translucent: (M, 3) tints;
    ior: (M,); special: (M,) bool, some branch other than diffuse has weight; thin: (M,) bool,
    no KHR_materials_volume thickness (a thin wall: refraction does not bend). Rows follow
    ``Scene.materials``.
    """

    classes: tuple[Classification, ...]
    weights: np.ndarray
    specular: np.ndarray
    transmission: np.ndarray
    translucent: np.ndarray
    ior: np.ndarray
    special: np.ndarray
    thin: np.ndarray

    def stages(self) -> set[str]:
        """Union of the material stages the materials need."""
        return set().union(*(c.stages() for c in self.classes)) if self.classes else set()


def material_table(scene) -> MaterialTable:
    """``classify`` every material of ``scene`` with the scene's mirror threshold.

    Computed once per scene and kept on it (the scene is immutable; ``surface.albedo`` asks for
    it on every batch of hits, and the texture means cost a pass over each image)."""
    cached = scene.__dict__.get("_material_table")
    if cached is not None:
        return cached
    classes = tuple(classify(m, scene.images, scene.mirror_roughness) for m in scene.materials)

    def rows(get, width):
        return np.array([get(c) for c in classes], np.float64).reshape(-1, width)

    weights = rows(lambda c: c.weights, 4)
    table = MaterialTable(classes=classes, weights=weights,
                          specular=rows(lambda c: c.specular_color, 3),
                          transmission=rows(lambda c: c.transmission_color, 3),
                          translucent=rows(lambda c: c.translucent_color, 3),
                          ior=rows(lambda c: [c.ior], 1)[:, 0],
                          special=weights[:, DIFFUSE] < 1.0,
                          thin=np.array([c.thickness <= 0.0 for c in classes], bool))
    object.__setattr__(scene, "_material_table", table)
    return table


# ------------------------------------------------------------------------------------------
# Alpha testing

MASK, BLEND = 1, 2


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
