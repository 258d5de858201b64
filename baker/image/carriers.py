"""What the emissive carrier writes: the radiance a lit surface sends to the eye, per texel.

The moz carrier stores the light arriving at the surface, E (irradiance), and leaves the shading
to the viewer (three.js shades a lightmap as diffuse colour × E / π). A viewer that reads no
lightmap extension still shows a material's emission as it is, so the emissive carrier writes
what the viewer would have shown,

    radiance = R · E / π + emission

with R the diffuse albedo that the bake itself used at the texel (``geometry.surface.albedo``: base
colour factor × base colour texture × COLOR_0 × the material's diffuse weight, rough metal
counting as diffuse as in ``gltf/materials.py``) and the material's own emission. A base colour
*texture* is therefore sampled once per lightmap texel, at the texel's centre: the output shows
the texture's detail only down to the lightmap's resolution (docs/output.md says so; the moz
carrier keeps the texture at full resolution). The writer sets the copied materials' base colour
to black so that nothing else lights them (``output/write.py``).
"""

from __future__ import annotations

import numpy as np

from baker.atlas.layout import Atlas
from baker.atlas.rasterise import Texels, flat_pages, texel_barycentrics
from baker.geometry.surface import albedo, emission, viewer_diffuse_weight
from baker.geometry.world import World
from baker.gltf.scene import Scene
from baker.image.compose import Lightmaps
from baker.image.postprocess import dilate
from baker.light.inner import OTHER_SIDE

_DARK_WEIGHT = 0.5  # a viewer shows less than half the bake's diffuse light: worth a warning


def emissive_lightmaps(scene: Scene, world: World, atlas: Atlas, texels: Texels,
                       lightmaps: Lightmaps, padding: int) -> Lightmaps:
    """The post-processed ``lightmaps`` turned into outgoing radiance pages, R·E/π + emission.

    Every front texel (``texels`` without the other-side bit of ``inner.py``) gets its owning
    surface's albedo and emission at its centre, multiplied into the page's (denoised, filled,
    stitched) irradiance there; the padding around charts is grown from those texels by
    ``padding`` rings, as the lightmap's was. The visibility pages are kept as they are.
    """
    front = np.flatnonzero((texels.key & OTHER_SIDE) == 0)
    tris = texels.triangle[front]
    bary = texel_barycentrics(atlas, world, texels)[front]
    index = texels.pixel_index(front)
    irradiance = flat_pages(lightmaps.light)[index]
    radiance = np.zeros_like(lightmaps.light)
    flat_pages(radiance)[index] = (albedo(scene, world, tris, bary) * irradiance / np.pi
                                   + emission(scene, world, tris, bary))
    filled = np.zeros(lightmaps.covered.shape, bool)
    flat_pages(filled)[index] = True
    radiance, _ = dilate(radiance, filled, padding)
    return Lightmaps(light=radiance, visibility=lightmaps.visibility, covered=lightmaps.covered)


def viewer_notes(scene: Scene, materials: set[int], carrier: str) -> list[str]:
    """Report notes for the baked ``materials`` (indices into ``scene.materials``) that viewers
    will show darker than the bake: a lightmap lights only the diffuse part of a material,
    (1 − metallic) × (1 − transmission) of its base colour (``viewer_diffuse_weight``), so a
    metal or glass shows little of it in moz; the emissive carrier shows the bake on them as
    it is, and the occlusion carrier only darkens the viewer's own light."""
    if carrier != "moz":
        return []
    weights = viewer_diffuse_weight(scene)
    notes = []
    for m in sorted(materials):
        material = scene.materials[m]
        if weights[m] < _DARK_WEIGHT:
            notes.append(f"material {material.name!r} (metallic {material.metallic:g}, "
                         f"transmission {material.transmission:g}): viewers light only its "
                         f"diffuse part with the lightmap, {weights[m]:.0%} of its base colour, "
                         "so it shows dark where the bake has light; --carrier emissive shows "
                         "the bake on it")
    return notes
