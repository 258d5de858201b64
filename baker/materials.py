"""Materials as the estimators see them: the weights of a hit's four branches and their tints.

A material sends the light that reaches it into four branches whose weights sum to 1 —
diffuse, perfect specular (the paper's §3.1), transparent (§3.2) and translucent (§3.3) — and
may let rays through (alpha testing). ``Classification`` is one material so seen,
``MaterialTable`` every material's as arrays for shading hits in bulk. They say nothing of the
file a material came from: the glTF loader makes them (``gltf.materials.classify``,
``material_table``) and the estimators (``light/``) read them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Branches of a hit, in the column order of ``MaterialTable.weights``.
DIFFUSE, SPECULAR, TRANSPARENT, TRANSLUCENT = range(4)
BRANCHES = ("diffuse", "specular", "transparent", "translucent")


# Alpha modes of a triangle, as the tracer tests them (0: opaque, never tested).
MASK, BLEND = 1, 2


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


def table_of(classes: tuple[Classification, ...]) -> MaterialTable:
    """The ``MaterialTable`` of ``classes``, one row each, in their order."""

    def rows(get, width):
        return np.array([get(c) for c in classes], np.float64).reshape(-1, width)

    weights = rows(lambda c: c.weights, 4)
    return MaterialTable(classes=classes, weights=weights,
                         specular=rows(lambda c: c.specular_color, 3),
                         transmission=rows(lambda c: c.transmission_color, 3),
                         translucent=rows(lambda c: c.translucent_color, 3),
                         ior=rows(lambda c: [c.ior], 1)[:, 0],
                         special=weights[:, DIFFUSE] < 1.0,
                         thin=np.array([c.thickness <= 0.0 for c in classes], bool))
