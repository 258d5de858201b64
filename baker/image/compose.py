"""Compose the stored terms into lightmap pages: L(P) = D(P) + I_A · W(P).

A recomposition needs no ray: it only combines the terms the integrator kept apart, so a change of
R_ave or I_A costs a few array operations (docs/design.md §2). D, the direct light (direct.py), is kept
per light at unit intensity, so a light's new colour or intensity is a recomposition too.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import numpy as np

from baker.atlas.layout import Atlas
from baker.atlas.rasterise import Texels, flat_pages
from baker.jit import jit
from baker.light.ambient import Ambient
from baker.geometry.surface import luminance
from baker.light.direct import Direct
from baker.light.directional import encode_vectors, fit, smoothed, uniform_aim
from baker.light.hemisphere import Terms, obscurance_at
from baker.light.obscurance import UNIT_REFLECTIVITY
from baker.run.spill import PER_SCENE


@dataclass(frozen=True)
class Lightmaps:
    """Float lightmap pages, linear RGB.

    light: (P, H, W, 3) float64, what arrives at the surface (the shader multiplies by albedo).
    visibility: (P, H, W, 3) float64, for the occlusion texture: the fraction of the texel's
    (cosine-weighted) rays that meet nothing within d_max, the same in each channel — 1 where
    nothing occludes, as glTF's occlusion is (W is R-weighted: R_ave on an open surface); (0, H,
    W, 3) when not kept (a bake without ``occlusion`` does not need it: 400 MB at 4096²). covered: (P, H, W) bool, texels that were baked
    (the rest are padding, filled by dilation).
    direction: (P, H, W, 3) float64, with directional pages: each texel's g
    (``light.directional.fit``) as composed, then h (``directional_pages``: what the page
    holds), 0 in padding until dilation; (0, H, W, 3) without.
    """

    light: np.ndarray
    visibility: np.ndarray
    covered: np.ndarray
    direction: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 0, 3)))


def effective_r_ave(ambient: Ambient, rho: str) -> np.ndarray:
    """R_ave as the estimator uses it, what rays that meet nothing count: 1 for classic ambient
    occlusion (every surface white), the environment's colour when it is set (environment.py)."""
    if rho in UNIT_REFLECTIVITY:
        return np.ones(3)
    return ambient.r_ave if ambient.escape is None else ambient.escape


def blank(atlas: Atlas, visibility: bool = True, directional: bool = False) -> Lightmaps:
    """Lightmaps of zeros, no texel covered, the atlas's pages in size (``visibility``: with
    pages of the visibility, else 0 of them; ``directional``: with directional pages)."""
    shape = (atlas.page_count, atlas.height, atlas.width)
    return Lightmaps(light=np.zeros(shape + (3,)),
                     visibility=np.zeros((shape[0] if visibility else 0,) + shape[1:] + (3,)),
                     covered=np.zeros(shape, bool),
                     direction=np.zeros((shape[0] if directional else 0,) + shape[1:] + (3,)))


def compose_into(lightmaps: Lightmaps, texels: Texels, terms: Terms, ambient: Ambient, rho: str,
                 direct: Direct | None = None, light_colours: np.ndarray | None = None,
                 indirect: np.ndarray | None = None,
                 indirect_aim: np.ndarray | None = None) -> None:
    """Scatter the texels' light L = D + I_A·W and their visibility into ``lightmaps``' page
    images, in place: a bake made part by part composes each part as it is done. The pixels of
    other texels are left as they are.

    ``direct``: the texels' direct light (None: L = I_A·W); ``light_colours`` (L, 3) replaces the
    baked colour × intensity of its punctual lights (relighting without rays). ``indirect``
    (N, 3): path-traced indirect irradiance (``--method gi``) to use instead of I_A·W, and
    ``indirect_aim`` (N, 3) its first moment (``gi.Indirect.aim``). With directional pages,
    each texel's h from every term's first moment (``_directions``).

    A block of ``_TEXELS_AT_ONCE`` texels at a time: at once, the (N, 3) values and their
    temporaries would be 200 MB each at 4096².
    """
    r_ave = effective_r_ave(ambient, rho)
    count = len(texels)
    pages, covered, visibility = (flat_pages(lightmaps.light), flat_pages(lightmaps.covered),
                                  flat_pages(lightmaps.visibility))
    none = np.zeros((0, 3))
    for start in range(0, count, _TEXELS_AT_ONCE):
        block = slice(start, start + _TEXELS_AT_ONCE)
        _compose_kernel(texels.pixel_index(block), *_rows(terms, block, count).w_parts(),
                        np.asarray(r_ave, np.float64), np.asarray(ambient.intensity, np.float64),
                        none if indirect is None else indirect[block],
                        none if direct is None else
                        _rows(direct, block, count).irradiance(light_colours),
                        pages, visibility, covered)
        if len(lightmaps.direction):
            index = texels.pixel_index(block)
            flat_pages(lightmaps.direction)[index] = _directions(
                pages[index], texels.normal[block], _rows(terms, block, count), ambient, r_ave,
                None if direct is None else _rows(direct, block, count), light_colours,
                None if indirect_aim is None else indirect_aim[block])


def _directions(light: np.ndarray, normals: np.ndarray, terms: Terms, ambient: Ambient,
                r_ave: np.ndarray, direct: Direct | None, light_colours: np.ndarray | None,
                indirect_aim: np.ndarray | None) -> np.ndarray:
    """(k, 3) h of k texels of composed irradiance ``light`` (k, 3) and unit normals
    ``normals`` (k, 3): U summed over the terms (``light.directional``) — D's, and I_A·W's
    (W's moment over its rays times lum(I_A·W)/lum W; the light through translucent surfaces
    counted uniform) or the path-traced light's —, then its g (``fit``)."""
    aim = np.zeros((len(light), 3))
    if direct is not None and len(direct.punctual_aim):
        aim += direct.aim(light_colours)
    if indirect_aim is not None:
        aim += indirect_aim
    else:
        front = terms.w_hit + terms.escaped[:, None] * r_ave
        own = luminance(front)
        lit = luminance(front * ambient.intensity)
        aim += np.where(own > 0, lit / np.where(own > 0, own, 1.0), 0.0)[:, None] * terms.aim(r_ave)
        whole = terms.obscurance(r_ave)
        aim += uniform_aim(luminance((whole - front) * ambient.intensity), normals)
    return fit(luminance(light), aim, normals)


def directional_pages(lightmaps: Lightmaps) -> Lightmaps:
    """``lightmaps`` with its directional pages' g, every texel composed, turned into what the
    pages hold: h of g pooled over each texel's neighbours (``light.directional.smoothed``,
    ``encode_vectors``); as they are without directional pages."""
    if not len(lightmaps.direction):
        return lightmaps
    weight = np.where(lightmaps.covered, luminance(lightmaps.light), 0.0)
    return replace(lightmaps, direction=encode_vectors(smoothed(lightmaps.direction, weight)))


@jit
def _compose_kernel(index, w_hit, escaped, escaped_tint, through_hit, through_ave, r_ave,
                    intensity, indirect, direct, pages, visibility, covered):
    """Scatter the texels' L = I_A·W + D (W: ``obscurance_at``), or the path-traced
    ``indirect`` + D when it has rows (``direct`` D (k, 3), or (0, 3): none), into the flat
    pages at ``index`` (k,) (``Texels.pixel_index``); their visibility (``escaped``, at most 1)
    too when ``visibility`` has rows. In
    one pass: numpy's temporaries made it 3× slower."""
    keep, traced, lit = len(visibility) > 0, len(indirect) > 0, len(direct) > 0
    for i in range(len(index)):
        p = index[i]
        covered[p] = True
        w = obscurance_at(w_hit, escaped, escaped_tint, through_hit, through_ave, r_ave, i)
        for c in range(3):
            if keep:
                visibility[p, c] = min(escaped[i], 1.0)
            light = indirect[i, c] if traced else w[c] * intensity[c]
            pages[p, c] = light + direct[i, c] if lit else light


_TEXELS_AT_ONCE = 1 << 16


def _rows(per_texel, block: slice, count: int):
    """``per_texel`` (Terms, Direct: a dataclass of (N, …) arrays) for the texels ``block``
    only: every array field with ``count`` = N rows sliced (views), the others kept (empty
    optional terms; ``Direct.light_colours``, (L, 3) per light, whatever L is)."""
    return replace(per_texel, **{
        f.name: value[block] for f in fields(per_texel)
        if isinstance(value := getattr(per_texel, f.name), np.ndarray) and value.ndim
        and len(value) == count and f.name not in PER_SCENE})
