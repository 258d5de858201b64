"""Whether a ray or probe that meets the changed geometry changed what its texel found: judges
the dirty search passes to its ray tests (``reach.rays_meet``, ``reach.probes_meet``). A ray
that meets a recoloured surface behind one that did not change (``NotStopped``), one whose
first hit is the same in the scene now and in the scene of the last bake (``HitsCompared``),
a probe that meets a back face first in both or in neither (``ProbesCompared``): unchanged."""

from __future__ import annotations

import numpy as np

from baker.atlas.validity import Faces
from baker.rays.trace import LocalHits, Tracer


class NotStopped:
    """Judges a ray that meets a recoloured material's triangles (``changed_triangles`` (T,)
    bool) changed unless, in the whole scene (``tracer``), a surface that did not change stops
    it before (``_stopped_before``)."""

    def __init__(self, tracer: Tracer, changed_triangles: np.ndarray):
        self._tracer, self._changed = tracer, changed_triangles

    def __call__(self, rows, samples, origins, directions, distance) -> np.ndarray:
        return ~_stopped_before(self._tracer, self._changed, origins, directions, distance)


class HitsCompared:
    """Judges a ray that meets a moved node (at its old or new place) changed when its nearest
    hit within d_max in the whole scene now (``after``) differs from its hit in the scene of the
    last bake (``before``, of ``changed.world_before``), which gave the stored terms. With
    ``keep``, the changed rays are kept: ``changed`` gives them for ``exact_sums.ray_changes``.
    Called from several threads at once (each call's rays are its own)."""

    def __init__(self, after: Tracer, before: Tracer, d_max: float, keep: bool):
        self._after, self._before, self._d_max, self._keep = after, before, d_max, keep
        self._pieces: list = []  # (list.append is safe across threads)
        self._cast: list[int] = []

    @property
    def cast(self) -> int:
        """Rays cast in all (each judged ray twice: after and before)."""
        return sum(self._cast)

    def __call__(self, rows, samples, origins, directions, distance) -> np.ndarray:
        lengths = np.full(len(origins), self._d_max, np.float32)
        new = self._after.cast_local(origins, directions, lengths.copy())
        old = self._before.cast_local(origins, directions, lengths)
        hit = new.triangle >= 0
        differ = (new.triangle != old.triangle) | (hit & (
            (new.distance != old.distance) | (new.u != old.u) | (new.v != old.v)))
        if self._keep:  # what ``exact_sums.ray_changes`` reads of the hits
            self._pieces.append((rows[differ], samples[differ],
                                 old.take(differ), new.take(differ)))
        self._cast.append(2 * len(origins))
        return differ

    def changed(self) -> tuple[np.ndarray, np.ndarray, LocalHits, LocalHits]:
        """The changed rays kept: texel rows (m,), samples (m,), and their hits before and
        after."""
        if not self._pieces:
            empty = np.zeros(0, np.int64)
            missed = LocalHits.missed(np.zeros(0, np.float32))
            return empty, empty, missed, missed
        rows, samples, old, new = zip(*self._pieces)
        return (np.concatenate(rows), np.concatenate(samples), LocalHits.concatenate(old),
                LocalHits.concatenate(new))


def _stopped_before(tracer: Tracer, changed_triangles: np.ndarray, origins: np.ndarray,
                    directions: np.ndarray, distance: np.ndarray) -> np.ndarray:
    """(m,) bool, for rays (origins, directions (m, 3) float32 in the tracer's frame, as a bake
    casts them) that meet the changed geometry at ``distance`` (m,): whether, in the whole
    scene as it is now (``tracer``, which lets rays through alpha-tested surfaces as a bake
    does), a surface that did not change stops the ray clearly before (``changed_triangles``
    (T,) bool: the world triangles that did, a recoloured material's). That surface is then
    the ray's first hit both before the change and after it, so its part of the texel's terms
    is the same. The margin, 10⁻³ of the distance plus 10⁻⁵ of the coordinates, is far beyond
    float32 rounding; a mirror or glass that stops the ray is the "chain" search's concern."""
    distance = distance.astype(np.float64)
    limit = distance * (1 - 1e-3) - 1e-5 * (np.abs(origins).max(axis=1) + distance)
    rows = np.flatnonzero(limit > 0)
    stopped = np.zeros(len(origins), bool)
    if len(rows):
        met = tracer.cast_local(origins[rows], directions[rows], limit[rows].astype(np.float32))
        hit = met.triangle
        stopped[rows] = (hit >= 0) & ~changed_triangles[np.maximum(hit, 0)]
    return stopped


class ProbesCompared:
    """Judges a hemisphere probe of a far texel (beyond its tangent probes' reach of the move)
    that meets a moved node changed when whether it meets a back face first (what validity
    counts, ``validity.Faces.back``) differs between the whole scene now (``after``) and the
    scene of the last bake (``before``): each a (Tracer, Faces) pair. Its other findings cannot
    change: the tangent probes do not reach the move, and a probe touches (``Validity.touching``)
    only what lies within a few ray lifts of its origin."""

    def __init__(self, after: tuple[Tracer, Faces], before: tuple[Tracer, Faces]):
        self._after, self._before = after, before

    def __call__(self, origins: np.ndarray, directions: np.ndarray, d_max: float) -> np.ndarray:
        (now, faces_now), (then, faces_then) = self._after, self._before
        return (faces_now.back(now.cast(origins, directions, d_max).triangle, directions)
                != faces_then.back(then.cast(origins, directions, d_max).triangle, directions))
