"""Which texels' shadow, emissive and sky rays meet the changed geometry (``shadow_dirty``):
``direct.direct_light`` itself runs against the changed geometry alone (``Recorder``), for the
texels whose shadow rays may pass it by the rays' geometry (``may_shadow``)."""

from __future__ import annotations

import numpy as np

from baker.atlas.rasterise import Texels
from baker.jit import jit
from baker.light.direct import direct_light
from baker.pipeline.parts import part_slices, take
from baker.rays.trace import RayCaster, ray_lift
from baker.rebake.near_rays import lifted_origins


class Recorder:
    """A tracer for ``direct.py``'s estimators that casts against the changed geometry only and
    remembers the origins of the rays that met it (every ray of a texel starts at the same
    lifted point, so the origins name the texels). A ``rays.trace.Occluder``."""

    def __init__(self, tracer: RayCaster):
        self.center = tracer.center
        self._tracer = tracer
        self.origins: list[np.ndarray] = []
        self.rays = 0

    def occluded(self, origins, directions, length):
        hit = self._tracer.occluded(origins, directions, length)
        self.rays += len(origins)
        if hit.any():
            self.origins.append(np.asarray(origins, np.float64)[hit])
        return hit


def _row_keys(points: np.ndarray) -> np.ndarray:
    """(n,) structured keys of the exact bits of points (n, 3) float64, for exact matching."""
    kind = np.dtype([("x", "<i8"), ("y", "<i8"), ("z", "<i8")])
    return np.ascontiguousarray(points, np.float64).view(np.int64).view(kind).ravel()


def may_shadow(texels: Texels, rows: np.ndarray, changed: RayCaster, sources) -> np.ndarray:
    """(k,) bool, conservative: whether a shadow ray of the texels ``rows`` may pass through
    one of the ``changed`` geometry's bounding spheres. Exact on the geometry of the rays
    (``direct_estimators.punctual_irradiance``): a point or spot light's rays run from the lifted
    sample point O towards its sphere (radius ρ, 0 when hard) and stop before it, so they stay
    within ρ of the segment from O to its centre; a directional light's stay within its cone
    (half-angle ρ) around the direction to it. Emitters and the sky send rays anywhere: with
    either, every texel may."""
    if sources.emitters is not None or sources.sky is not None:
        return np.ones(len(rows), bool)
    origin = lifted_origins(changed.center, texels.position[rows], texels.geometric_normal(rows),
                            texels.size(rows))
    lights = sources.lights
    return _shadow_may_pass(
        origin, np.array([light.kind == "directional" for light in lights], np.bool_),
        np.array([light.position - changed.center for light in lights]).reshape(-1, 3),
        np.array([-np.asarray(light.direction, np.float64) for light in lights]).reshape(-1, 3),
        np.asarray(sources.spread, np.float64), changed.sphere_centres, changed.sphere_radii)


@jit
def _shadow_may_pass(origin: np.ndarray, directional: np.ndarray, light_position: np.ndarray,
                     to_light: np.ndarray, spread: np.ndarray, centres: np.ndarray,
                     radii: np.ndarray) -> np.ndarray:
    """``may_shadow``'s test, per texel: origins (k, 3), lights (L,) (``directional``; their
    positions (L, 3) and the unit directions towards them (L, 3), in the tracer's frame; their
    spread ρ), the changed geometry's spheres (b, 3), (b,). The reach of a sphere is its radius
    plus 1e-4 of the distances involved (float32 rays)."""
    out = np.zeros(len(origin), np.bool_)
    for i in range(len(origin)):
        ox, oy, oz = origin[i, 0], origin[i, 1], origin[i, 2]
        size = max(abs(ox), abs(oy), abs(oz))
        for light in range(len(directional)):
            for b in range(len(radii)):
                cx, cy, cz = centres[b, 0] - ox, centres[b, 1] - oy, centres[b, 2] - oz
                distance = np.sqrt(cx * cx + cy * cy + cz * cz)
                reach = radii[b] + 1e-4 * (distance + size + 1.0)
                if directional[light]:
                    cos = (cx * to_light[light, 0] + cy * to_light[light, 1]
                           + cz * to_light[light, 2]) / max(distance, 1e-300)
                    seen = np.arcsin(min(max(reach / max(distance, 1e-300), 0.0), 1.0))
                    near = (distance <= reach or np.arccos(min(max(cos, -1.0), 1.0))
                            <= spread[light] + seen + 1e-6)
                else:
                    sx = light_position[light, 0] - ox
                    sy = light_position[light, 1] - oy
                    sz = light_position[light, 2] - oz
                    t = (cx * sx + cy * sy + cz * sz) / max(sx * sx + sy * sy + sz * sz, 1e-300)
                    t = min(max(t, 0.0), 1.0)
                    gx, gy, gz = cx - t * sx, cy - t * sy, cz - t * sz
                    near = np.sqrt(gx * gx + gy * gy + gz * gz) <= reach + spread[light]
                if near:
                    out[i] = True
                    break
            if out[i]:
                break
    return out


def shadow_dirty(context, recorder_tracer: RayCaster, texels: Texels, rows: np.ndarray,
                 sources, settings) -> tuple[np.ndarray, int]:
    """(k,) bool: whether any shadow, emissive or sky ray of the texels ``rows`` meets the
    changed geometry; and the rays cast. Runs ``direct.direct_light`` itself against it, a
    part of the texels at a time (``parts.PART_TEXELS``: the rows are most of the texels, and
    their copies and direct light at once would take 1 GB at 4096²)."""
    meets = np.zeros(len(rows), bool)
    if not len(rows) or not sources.any():
        return meets, 0
    rays = 0
    maybe = np.flatnonzero(may_shadow(texels, rows, recorder_tracer, sources))
    for part in part_slices(len(maybe)):
        chosen = maybe[part]
        recorder = Recorder(recorder_tracer)
        texels_part = take(texels, rows[chosen])
        direct_light(context.with_settings(settings).with_tracer(recorder), texels_part, sources)
        rays += recorder.rays
        if not recorder.origins:
            continue
        lift = ray_lift(texels_part.position, texels_part.size(), recorder.center)
        starts = texels_part.position + lift[:, None] * texels_part.geometric_normal()
        meets[chosen] = np.isin(_row_keys(starts), _row_keys(np.concatenate(recorder.origins)))
    return meets, rays
