"""The only module that talks to Embree: through baker's own C calls (``native``), else embreex.

The scene is built once from every world triangle, recentred on the world's centre so that
float32 keeps its precision far from the origin; callers pass float64 world coordinates and get
float64 back. Embree releases the GIL while it traces, so the integrator runs several ``cast``
calls at once from a thread pool.

Alpha: when the world has alpha-tested triangles (``World.alpha``, materials.py), every query
lets rays through the hits whose alpha is below the cutoff (MASK) or, with probability
1 − alpha, through BLEND surfaces: the rays that hit such triangles — and only those — are cast
again along their own line from just past the hit (Embree's tnear), up to ``MAX_CONTINUATIONS``
times, and their hits merged back. The BLEND coin is a hash of the ray's own float32 bits and
the continuation number: a pure function of what made the ray (seed, texel key, sample), so
the result does not depend on chunking or threads.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from baker.geometry.world import World
from baker.rays import native
from baker.rays.dimensions import alpha_dimension
from baker.rays.sampling import hash_u32

# Smallest ray offset, in texel sizes and in float32 units of the position's magnitude.
_OFFSET_TEXELS = 1e-3
_OFFSET_ULPS = 64 * 2.0 ** -23


MAX_CONTINUATIONS = 16
"""Most alpha-tested surfaces one ray passes through; the next one then stops it."""


def _coin(origins: np.ndarray, directions: np.ndarray, step: int) -> np.ndarray:
    """(n,) uniform in [0, 1): a hash of each ray's float32 origin and direction bits and the
    continuation ``step``."""
    bits = np.concatenate([np.ascontiguousarray(origins, np.float32).view(np.uint32),
                           np.ascontiguousarray(directions, np.float32).view(np.uint32)], axis=1)
    h = hash_u32(bits[:, 0], bits[:, 1], bits[:, 2], bits[:, 3])
    h = hash_u32(h, bits[:, 4], bits[:, 5], np.uint64(alpha_dimension(step)))
    return ((h >> np.uint32(8)) + 0.5) * 2.0 ** -24


def pass_alpha(run, alpha, origins: np.ndarray, directions: np.ndarray, limit: np.ndarray,
               result: dict[str, np.ndarray]) -> int:
    """Let the rays of ``result`` (embreex arrays, changed in place) through alpha-tested hits.

    run(origins, directions, near, lengths) casts float32 rays in the tracer's frame, searched
    from ``near`` (n,) float32 along each; origins and directions: (n, 3) float32 the rays as
    first cast; limit: (n,) float64 their lengths. Only rays whose hit is on a triangle of
    ``alpha.mode`` are looked at; those that pass are cast again along their own line from just
    past the hit (``_past``) to their end. So a ray's path through cut-outs is its straight
    line, which is what the rebake's searches test (``rebake/reach.py``). Returns how many
    continuation rays were cast.
    """
    primitive, tfar, u, v = result["primID"], result["tfar"], result["u"], result["v"]
    live = np.flatnonzero(primitive >= 0)
    live = live[alpha.mode[primitive[live]] > 0]
    cast = 0
    for step in range(MAX_CONTINUATIONS):
        if not len(live):
            break
        tris = primitive[live].astype(np.int64)
        uu, vv = u[live].astype(np.float64), v[live].astype(np.float64)
        bary = np.stack([1.0 - uu - vv, uu, vv], axis=1)
        through = alpha.passes(tris, bary, _coin(origins[live], directions[live], step))
        live, tris = live[through], tris[through]
        if not len(live):
            break
        near = _past(alpha, origins[live], directions[live], tfar[live], tris)
        sub = run(origins[live], directions[live], near, limit[live].astype(np.float32))
        cast += len(live)
        hit = sub["primID"] >= 0
        primitive[live] = sub["primID"]
        tfar[live] = np.where(hit, sub["tfar"], limit[live])
        u[live], v[live] = sub["u"], sub["v"]
        live = live[hit]
        live = live[alpha.mode[primitive[live]] > 0]
    return cast


def _past(alpha, origins: np.ndarray, directions: np.ndarray, distance: np.ndarray,
          triangles: np.ndarray) -> np.ndarray:
    """(n,) float32: where along rays (origins, directions (n, 3) float32) that pass
    ``triangles`` (n,) at ``distance`` (n,) float32 their search goes on: clear of that surface
    by the larger of ``alpha.step`` and 64 float32 ulps of the hit point measured off its plane
    (so along the ray that over the cosine, at most 64 times it), and at least one float32 step
    past the hit."""
    d = directions.astype(np.float64)
    t = distance.astype(np.float64)
    point = origins.astype(np.float64) + t[:, None] * d
    cosine = np.abs(np.einsum("ij,ij->i", d, alpha.normals[triangles]))
    lift = np.maximum(alpha.step, _OFFSET_ULPS * np.abs(point).max(axis=1))
    near = (t + lift / np.maximum(cosine, 1.0 / 64)).astype(np.float32)
    return np.maximum(near, np.nextafter(distance.astype(np.float32), np.float32(np.inf)))


def ray_lift(position: np.ndarray, size: np.ndarray, center: np.ndarray) -> np.ndarray:
    """How far (k,) to lift ray origins at ``position`` (k, 3) off their surface, world units.

    The larger of 10⁻³ of the texel's world size ``size`` (k,) and 64 float32 ulps of the
    position's distance from the tracer's ``center``: neither big texels nor scenes far from the
    origin self-intersect inside Embree's float32.
    """
    offset = np.abs(position - center)
    magnitude = np.maximum(np.maximum(offset[:, 0], offset[:, 1]), offset[:, 2])  # 7× max(axis=1)
    return np.maximum(_OFFSET_TEXELS * size, _OFFSET_ULPS * np.maximum(magnitude, 1e-30))


@dataclass(frozen=True)
class Hits:
    """Nearest hits of n rays. triangle: (n,) int64 world triangle, -1 for a miss; distance:
    (n,) float64 along the (unit) direction, inf for a miss; u, v: (n,) float64 barycentric
    weights of the triangle's second and third corners at the hit."""

    triangle: np.ndarray
    distance: np.ndarray
    u: np.ndarray
    v: np.ndarray

    def barycentric(self) -> np.ndarray:
        """(n, 3) barycentric coordinates of the hit points (meaningless for misses)."""
        return np.stack([1.0 - self.u - self.v, self.u, self.v], axis=1)


@dataclass(frozen=True)
class LocalHits:
    """Nearest hits of float32 rays in a tracer's recentred frame (``cast_local``, the hot
    path), as Embree gives them. triangle: (n,) int32 world triangle, −1 for a miss; distance:
    (n,) float32 along the ray (its length for a miss); u, v: (n,) float32 barycentric weights
    of the triangle's second and third corners (0 where a caster does not compute them)."""

    triangle: np.ndarray
    distance: np.ndarray
    u: np.ndarray
    v: np.ndarray

    @classmethod
    def of_embree(cls, result: dict[str, np.ndarray]) -> "LocalHits":
        """From embreex's result arrays (``primID``, ``tfar``, ``u``, ``v``)."""
        return cls(result["primID"], result["tfar"], result["u"], result["v"])

    @classmethod
    def missed(cls, lengths: np.ndarray) -> "LocalHits":
        """Rays of ``lengths`` (n,) float32 that meet nothing."""
        n = len(lengths)
        return cls(np.full(n, -1, np.int32), lengths, np.zeros(n, np.float32),
                   np.zeros(n, np.float32))

    def take(self, rows: np.ndarray) -> "LocalHits":
        """The hits of rays ``rows`` (index array or mask)."""
        return LocalHits(self.triangle[rows], self.distance[rows], self.u[rows], self.v[rows])

    @staticmethod
    def concatenate(parts: "list[LocalHits]") -> "LocalHits":
        """The hits of several batches of rays, in order (at least one batch)."""
        return LocalHits(*(np.concatenate([getattr(p, f) for p in parts])
                           for f in ("triangle", "distance", "u", "v")))


@runtime_checkable
class Occluder(Protocol):
    """What shadow rays ask of a tracer (``light.direct``'s estimators): whether anything lies
    along each ray. ``Tracer`` answers for the whole world; the rebake's ``_Recorder`` for the
    changed triangles, remembering which rays met them."""

    center: np.ndarray

    def occluded(self, origins: np.ndarray, directions: np.ndarray,
                 length: np.ndarray | float) -> np.ndarray: ...


@runtime_checkable
class RayCaster(Occluder, Protocol):
    """What the estimators and searches ask of a tracer: nearest hits in world space (``cast``)
    or in the recentred float32 frame (``cast_local``), and shadow rays. ``Tracer`` casts
    against the whole world; the rebake's ``_Changed`` against the changed triangles only."""

    def cast(self, origins: np.ndarray, directions: np.ndarray,
             length: np.ndarray | float) -> Hits: ...

    def cast_local(self, origins: np.ndarray, directions: np.ndarray,
                   lengths: np.ndarray) -> LocalHits: ...


def embree_mesh(world: World, hidden: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The world's triangles as Embree takes them: (V + 1, 3) float32 vertices − ``center``,
    (T, 3) int32 triangles. Shared vertices (fewer than 3 per triangle: embreex copies them one
    by one), the same float32 corners as each triangle's own; ``hidden`` (T,) bool triangles
    and the exact copies of others (``World.repeated``: a ray would test every copy) point at
    one NaN vertex after the others, which Embree leaves out."""
    vertices = np.vstack([world.positions - world.center, np.full((1, 3), np.nan)])
    triangles = world.triangles.copy()
    left_out = world.repeated if hidden is None else hidden | world.repeated
    if left_out.any():
        triangles[left_out] = len(world.positions)
    return vertices.astype(np.float32), triangles.astype(np.int32)


def embreex_scene(vertices: np.ndarray, triangles: np.ndarray) -> rtcore_scene.EmbreeScene:
    """embreex's scene of ``vertices`` (V, 3) float32 and ``triangles`` (T, 3) int32, committed
    (its first run commits it: done here, not from several threads at once)."""
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, vertices, triangles)
    scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32),
              dists=np.zeros(1, np.float32))
    return scene


class Tracer:
    """Casts rays against all of a ``World``'s triangles, or all but the ``hidden`` ones."""

    def __init__(self, world: World, hidden: np.ndarray | None = None):
        """``hidden``: None, or (T,) bool world triangles that no ray meets (their corners are
        NaN, which Embree leaves out; the others keep their indices as ``primID``)."""
        self.center = world.center
        self.triangle_count = len(world.triangles)
        self.alpha = world.alpha  # materials.AlphaTest or None (nothing to let through)
        self._scene = None
        if self.triangle_count:
            mesh = embree_mesh(world, hidden)
            self._scene = native.scene(*mesh) or embreex_scene(*mesh)

    def cast(self, origins: np.ndarray, directions: np.ndarray, length: np.ndarray | float) -> Hits:
        """Nearest hit of each ray within ``length``.

        origins: (n, 3) float64 world; directions: (n, 3) unit; length: scalar or (n,) float64.
        """
        n = len(origins)
        if n == 0 or self.triangle_count == 0:
            return Hits(np.full(n, -1, np.int64), np.full(n, np.inf), np.zeros(n), np.zeros(n))
        local = (origins - self.center).astype(np.float32)
        dists = np.empty(n, np.float32)
        dists[:] = length
        result = self.cast_local(local, directions.astype(np.float32), dists)
        triangle = result.triangle.astype(np.int64)
        hit = triangle >= 0
        distance = np.where(hit, result.distance.astype(np.float64), np.inf)
        return Hits(np.where(hit, triangle, -1), distance, result.u.astype(np.float64),
                    result.v.astype(np.float64))

    def cast_local(self, origins: np.ndarray, directions: np.ndarray,
                   lengths: np.ndarray) -> LocalHits:
        """Nearest hits of rays already in the tracer's recentred float32 frame (hot path).

        origins: (n, 3) float32 world position − ``center``; directions: (n, 3) float32 unit;
        lengths: (n,) float32, overwritten.
        """
        if self.triangle_count == 0:
            return LocalHits.missed(lengths)
        limit = None if self.alpha is None else lengths.astype(np.float64)  # before Embree
        result = self._scene.run(origins, directions, dists=lengths, output=1)  # writes them
        if self.alpha is not None:
            pass_alpha(self._run, self.alpha, origins, directions, limit, result)
        return LocalHits.of_embree(result)

    def cast_local_sparse(self, origins: np.ndarray, directions: np.ndarray,
                          lengths: np.ndarray) -> LocalHits:
        """``cast_local``'s hits, the same bits, for rays most of which meet nothing (the
        validity's short probes): each ray is first asked only whether it meets anything, an
        occlusion query cast in packets of 8 or 16 (``native.py``: about 3× the rate of nearest
        hits on short rays from one point), and only the rays that do are asked where. Where
        occlusion is not cast in packets it is no cheaper than the nearest hit, and this is
        ``cast_local``. Rays as ``cast_local`` takes them; ``lengths`` (n,) float32 overwritten
        as it overwrites them."""
        if self.triangle_count == 0 or not getattr(self._scene, "packets", False):
            return self.cast_local(origins, directions, lengths)
        met = np.flatnonzero(self._scene.run(origins, directions, dists=lengths,
                                             query="OCCLUDED") >= 0)
        hits = LocalHits.missed(lengths)  # its distance is ``lengths`` itself
        if len(met):
            found = self.cast_local(origins[met], directions[met], lengths[met])
            hits.triangle[met], hits.distance[met] = found.triangle, found.distance
            hits.u[met], hits.v[met] = found.u, found.v
        return hits

    def _run(self, origins: np.ndarray, directions: np.ndarray, near: np.ndarray | None,
             lengths: np.ndarray) -> dict[str, np.ndarray]:
        """Embree's nearest hits of float32 rays in the recentred frame, no alpha test, searched
        from ``near`` (n,) float32 along each ray (None: from the origin). embreex takes no
        ``near``: its rays start there instead (the same line to float32 rounding), their hit
        distances measured from the given origins still."""
        origins, directions = np.ascontiguousarray(origins), np.ascontiguousarray(directions)
        if near is None:
            return self._scene.run(origins, directions, dists=lengths, output=1)
        if isinstance(self._scene, native.NativeScene):
            return self._scene.run(origins, directions, dists=lengths, output=1, near=near)
        start = (origins + near[:, None].astype(np.float64) * directions).astype(np.float32)
        result = self._scene.run(start, directions, output=1,
                                 dists=np.maximum(lengths - near, 0).astype(np.float32))
        result["tfar"] = np.where(result["primID"] >= 0, near + result["tfar"], lengths)
        return result

    def occluded(self, origins: np.ndarray, directions: np.ndarray,
                 length: np.ndarray | float) -> np.ndarray:
        """(n,) bool: whether anything lies along each ray within ``length`` (shadow rays)."""
        n = len(origins)
        if n == 0 or self.triangle_count == 0:
            return np.zeros(n, bool)
        dists = np.empty(n, np.float32)
        dists[:] = length
        return self.blocked_local((origins - self.center).astype(np.float32),
                                  directions.astype(np.float32), dists) >= 0

    def blocked_local(self, origins: np.ndarray, directions: np.ndarray,
                      lengths: np.ndarray) -> np.ndarray:
        """(n,) int32: 0 where something lies along the ray within its length, −1 where
        nothing does (Embree's occlusion query, which stops at the first hit it finds and
        reports no distance: 14–50 % faster than the nearest hit). Rays as ``cast_local`` takes
        them (float32, the recentred frame); ``lengths`` is left as it was."""
        if self.triangle_count == 0:
            return np.full(len(lengths), -1, np.int32)
        result = self._scene.run(origins, directions, dists=lengths, query="OCCLUDED")
        if self.alpha is not None:  # blocked maybe only by see-through hits
            rows = np.flatnonzero(result >= 0)
            if len(rows):
                limit = lengths[rows].astype(np.float64)
                again = self._run(origins[rows], directions[rows], None, lengths[rows])
                pass_alpha(self._run, self.alpha, origins[rows], directions[rows], limit, again)
                result[rows] = np.where(again["primID"] >= 0, 0, -1)
        return result
