"""Supersampling: several sample positions inside each texel, so shadow edges and small
obscurance details are anti-aliased.

With one sample point per texel, a hard shadow edge crossing a texel makes it either fully lit
or fully dark: a stair-step along the edge at low resolution. With ``supersample`` = S > 1 each
texel gets S sub-positions spread over its square, and its rays spread over them — shadow,
emissive and sky ray s starts from sub-position s mod S (``direct_estimators.Receivers``),
obscurance ray j (the texel's sample j, in every adaptive round) from sub-position j mod S
(``integrate.hemisphere_rays``) — so a texel half in shadow comes out half lit, and a texel
half under a low shelf half dark (a box filter of the texel's footprint). A hard light casts S
rays per texel then, one from each sub-position. Sub-positions lie on the owning triangle's
plane, so rays from them use the texel's normal and frame.

Where they are: the texel's square in the atlas, mapped onto the owning triangle's plane by the
UV→world Jacobian (``Texels.triangle_axes``), around the texel's sample point after the validity probes
moved it (``validity.py``). The offsets inside the square are Owen-scrambled Sobol points of the
texel's key (``dimensions.SUPERSAMPLE``), so they are a pure function of (seed, key, sub-sample index):
the bake stays the same bytes for any chunking or thread count.

What keeps them out of walls: a sub-position is used only if the straight segment from the
(valid) sample point to it, both lifted off the surface like ray origins (``trace.ray_lift``),
meets nothing, with ``MARGIN`` texel sides to spare; otherwise that sub-position falls back to
the sample point itself. A floor texel whose sample point the probes moved inside a room
therefore never gets a sub-position on the far side of the wall (no leak), and one at the foot
of a box never gets a sub-position inside it.
"""

from __future__ import annotations

import numpy as np

from baker.atlas.rasterise import Texels
from baker.rays.dimensions import SUPERSAMPLE
from baker.rays.sampling import sample_2d
from baker.rays.trace import Tracer, ray_lift

MARGIN = 0.1  # texel sides the segment to a sub-position is checked beyond it


def sub_offsets(texels: Texels, rows: slice | np.ndarray, count: int, seed: int) -> np.ndarray:
    """(k, count, 3) world offsets of each texel's sub-positions from its sample point.

    The offsets are points of the texel's square, (−½, ½)² in texel units around its centre,
    times the owning triangle's texel axes (``Texels.triangle_axes``, (2, 3) each): on its plane.
    """
    keys = texels.key[rows]
    square = sample_2d(seed, keys[:, None], np.arange(count)[None, :], SUPERSAMPLE) - 0.5
    return np.einsum("ksj,kjc->ksc", square, texels.axes(rows))


def sub_positions(tracer: Tracer, texels: Texels, rows: slice | np.ndarray, count: int,
                  seed: int) -> np.ndarray:
    """(k, count, 3) world sub-positions of the texels ``rows``: sample point + ``sub_offsets``,
    or the sample point itself for a sub-position that the sample point cannot see (the segment
    between them, lifted off the surface, meets geometry within its length + ``MARGIN`` texels).
    """
    position = texels.position[rows]
    k = len(position)
    offsets = sub_offsets(texels, rows, count, seed).reshape(-1, 3)
    size = np.repeat(texels.size(rows), count)
    lift = np.repeat(ray_lift(position, texels.size(rows), tracer.center), count)
    start = np.repeat(position + 0.0, count, axis=0)
    origins = start + lift[:, None] * np.repeat(texels.geometric_normal(rows), count, axis=0)
    length = np.linalg.norm(offsets, axis=1)
    moving = length > 0
    blocked = np.zeros(k * count, bool)
    if moving.any():
        directions = offsets[moving] / length[moving, None]
        blocked[moving] = tracer.occluded(origins[moving], directions,
                                          length[moving] + MARGIN * size[moving])
    result = start + np.where(blocked, 0.0, 1.0)[:, None] * offsets
    return result.reshape(k, count, 3)
