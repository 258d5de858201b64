"""What the emissive carrier writes: the light a lit surface sends out, as its emission.

The moz carrier stores the light arriving at the surface, E (irradiance), and leaves the shading
to a viewer that reads it (three.js shades a lightmap as diffuse colour × E / π). A viewer that
reads no lightmap extension still shows a material's emission as it is, so the emissive carrier
(the default) writes, per texel, the view-independent part of what the surface sends out,

    radiance = base · [(1 − m)(1 − t) · E + m · (E − E_kept)] / π + emission

with base the base colour (factor × texture × COLOR_0), m metallic and t transmission at the
texel's centre, E the bake's irradiance and E_kept the part of it that the punctual lights give
directly when the output keeps them (0 when it drops them). The first term is the diffuse
reflection that glTF's BRDF gives the material. The second is a metal's reflection of its
surroundings, taken as if they were uniform (the bake's own model of a rough metal,
``gltf/materials.py``). The writer keeps each material's specular response
(``output/specular.py``) and takes away its diffuse one, so a viewer adds its own
environment's reflections and nothing lights the baked diffuse twice; where the output keeps
the lights, they give the metals their highlights, in place of E_kept. A base colour *texture* is sampled once per lightmap texel, at its centre: the output shows
its detail down to the lightmap's resolution (the moz carrier keeps the texture whole).
"""

from __future__ import annotations

import numpy as np

from baker.atlas.layout import Atlas
from baker.atlas.rasterise import Coverage, flat_pages, pixel_index, texel_barycentrics
from baker.geometry.surface import (base_colour, emission, metallic_at, transmission_at,
                                    viewer_diffuse_weight_at)
from baker.geometry.world import World
from baker.gltf.scene import Scene
from baker.image.compose import Lightmaps
from baker.image.postprocess import dilate
from baker.light.direct import Direct
from baker.light.inner import OTHER_SIDE
from baker.rowwise import matmul_rows

_DARK_WEIGHT = 0.5  # a viewer shows less than half the bake's diffuse light: worth a warning


def emissive_lightmaps(scene: Scene, world: World, atlas: Atlas, coverage: Coverage,
                       lightmaps: Lightmaps, padding: int, kept: Direct | None) -> Lightmaps:
    """The post-processed ``lightmaps`` turned into pages of outgoing radiance (the module's
    formula), ``kept`` the texels' direct light when the output keeps the punctual lights
    (None: it drops them).

    Every front texel (the keys of ``coverage``, the bake's texels, without the other-side bit
    of ``inner.py``) gets its owning surface's base colour, metallic, transmission and emission
    at its centre, multiplied into the page's (denoised, filled, stitched) irradiance there;
    the padding around charts is grown from those texels by ``padding`` rings, as the
    lightmap's was. The visibility pages are kept as they are. Only the texels' keys and
    triangles are read: a bake whose texels went to disk in parts does not make them again.
    """
    front = np.flatnonzero((coverage.key & OTHER_SIDE) == 0)
    tris = coverage.triangle[front]
    bary = texel_barycentrics(atlas, world, coverage)[front]
    index = pixel_index(coverage.key[front])
    irradiance = flat_pages(lightmaps.light)[index]
    metal = metallic_at(scene, world, tris, bary)[:, None]
    clear = transmission_at(scene, world, tris, bary)[:, None]
    diffuse = (1.0 - metal) * (1.0 - clear) * irradiance
    if metal.any():
        punctual = _punctual_irradiance(kept, front, len(coverage.key))
        diffuse += metal * np.maximum(irradiance - punctual, 0.0)
    radiance = np.zeros_like(lightmaps.light)
    flat_pages(radiance)[index] = (base_colour(scene, world, tris, bary) * diffuse / np.pi
                                   + emission(scene, world, tris, bary))
    filled = np.zeros(lightmaps.covered.shape, bool)
    flat_pages(filled)[index] = True
    radiance, _ = dilate(radiance, filled, padding)
    return Lightmaps(light=radiance, visibility=lightmaps.visibility, covered=lightmaps.covered)


def _punctual_irradiance(direct: Direct | None, rows: np.ndarray, count: int) -> np.ndarray:
    """(len(rows), 3) the irradiance the punctual lights give the texels ``rows`` directly, as
    baked (0 where there is no such light)."""
    if direct is None or not direct.punctual.shape[1] or len(direct.punctual) != count:
        return np.zeros((len(rows), 3))
    return matmul_rows(direct.punctual[rows], direct.light_colours)


def viewer_notes(scene: Scene, world: World, instances: list[int], carrier: str) -> list[str]:
    """Report notes for the materials of the baked ``instances`` that viewers will show darker
    than the bake: a lightmap lights only the diffuse part of a material, (1 − metallic) ×
    (1 − transmission) of its base colour, metallic read from its texture where it has one
    (``diffuse_shares``), so a metal or glass shows little of it in moz; the emissive carrier
    shows the bake on them as it is, and the occlusion carrier only darkens the viewer's own
    light."""
    if carrier != "moz":
        return []
    notes = []
    for m, share in sorted(diffuse_shares(scene, world, instances).items()):
        material = scene.materials[m]
        if share < _DARK_WEIGHT:
            textured = " × its texture" if material.metallic_roughness_texture is not None else ""
            notes.append(f"material {material.name!r} (metallic {material.metallic:g}{textured}, "
                         f"transmission {material.transmission:g}): viewers light only its "
                         f"diffuse part with the lightmap, {share:.0%} of its base colour over "
                         "its surface, so it shows dark where the bake has light; "
                         "--carrier emissive shows the bake on it")
    return notes


_SHARE_POINTS = 4096  # points per material that ``diffuse_shares`` averages over


def diffuse_shares(scene: Scene, world: World, instances: list[int]) -> dict[int, float]:
    """{material: the area-weighted mean of ``viewer_diffuse_weight_at`` over its triangles in
    ``instances``}, measured at ``_SHARE_POINTS`` points per material laid by area: point k at
    the cumulative-area fraction (k + ½)/K, its second coordinate k·(golden ratio) mod 1, so
    the same scene gives the same figure every run."""
    tris = np.flatnonzero(np.isin(world.tri_instance, instances))
    area = world.areas(tris)
    k = np.arange(_SHARE_POINTS)
    shares = {}
    for m in np.unique(world.tri_material[tris]):
        own = world.tri_material[tris] == m
        cumulative = np.cumsum(area[own])
        if cumulative[-1] <= 0:
            continue
        at = (k + 0.5) / _SHARE_POINTS * cumulative[-1]
        pick = np.minimum(np.searchsorted(cumulative, at, side="right"), len(cumulative) - 1)
        before = np.where(pick > 0, cumulative[pick - 1], 0.0)
        r1 = np.clip((at - before) / np.maximum(area[own][pick], 1e-300), 0.0, 1.0)
        r2 = (k * 0.6180339887498949) % 1.0
        root = np.sqrt(r1)  # uniform on the triangle (Osada et al. 2002)
        bary = np.column_stack([1.0 - root, root * (1.0 - r2), root * r2])
        weight = viewer_diffuse_weight_at(scene, world, tris[own][pick], bary)
        shares[int(m)] = float(weight.mean())
    return shares
