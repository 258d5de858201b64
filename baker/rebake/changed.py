"""The changed geometry the dirty search casts against: an Embree scene of just the changed
triangles with the boxes that hold them (``Changed``), a moved node's triangles at its new or
its last bake's place (``placed_corners``, ``world_before``), and the mirrors and glass whose
rays go on (``chain_corners``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from baker.geometry.world import World, placed_positions
from baker.gltf.scene import Scene
from baker.jit import jit
from baker.materials import SPECULAR, TRANSPARENT
from baker.rays.trace import Hits, LocalHits, Tracer


def _small_world(corners: np.ndarray, center: np.ndarray) -> World:
    """A World of just the triangles ``corners`` (k, 3, 3) world, in ``center``'s frame (so its
    float32 vertices are bit-identical to the full scene's)."""
    k = len(corners)
    empty = np.zeros(0, np.int64)
    return World(positions=corners.reshape(-1, 3), normals=np.zeros((3 * k, 3)),
                 smooth=np.zeros(3 * k, bool), texcoords=(), colors=np.ones((3 * k, 4)),
                 triangles=np.arange(3 * k, dtype=np.int64).reshape(-1, 3), tri_instance=empty,
                 tri_material=empty, vertex_start=empty, tri_start=empty, center=center)


@jit
def _crossing(origins: np.ndarray, directions: np.ndarray, lengths: np.ndarray,
              low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """(n,) bool: whether each ray (origins, directions (n, 3) in the tracer's frame, lengths
    (n,)) passes through any of the boxes [low, high] (b, 3) within its length (slab test)."""
    n, boxes = len(origins), len(low)
    out = np.zeros(n, np.bool_)
    for i in range(n):
        for b in range(boxes):
            near, far = 0.0, float(lengths[i])
            for c in range(3):
                o, d = float(origins[i, c]), float(directions[i, c])
                if d == 0.0:
                    if o < low[b, c] or o > high[b, c]:
                        near, far = 1.0, 0.0
                else:
                    t0, t1 = (low[b, c] - o) / d, (high[b, c] - o) / d
                    near, far = max(near, min(t0, t1)), min(far, max(t0, t1))
            if near <= far:
                out[i] = True
                break
    return out


class Changed:
    """An Embree scene of just the changed triangles, for the dirty search, with the boxes that
    hold each group of them: a ray that crosses no box cannot meet them and is not cast, so the
    search costs little more than generating each candidate texel's rays.

    ``parts``: list of (t, 3, 3) world corners, one box each (a moved node's old and new
    place). The boxes, in the tracer's float32 frame, are padded far beyond float32 rounding.
    A ``rays.trace.RayCaster``, as ``Tracer`` is: the searches cast through either.
    """

    def __init__(self, parts: list[np.ndarray], center: np.ndarray):
        parts = [p for p in parts if len(p)]
        corners = np.concatenate(parts) if parts else np.zeros((0, 3, 3))
        self.center = center
        self._tracer = Tracer(_small_world(corners, center))
        local = [p.reshape(-1, 3) - center for p in parts]
        pad = [1e-4 * (np.abs(p).max() + np.ptp(p, axis=0).max()) + 1e-12 for p in local]
        self._low = np.array([p.min(0) - e for p, e in zip(local, pad)]).reshape(-1, 3)
        self._high = np.array([p.max(0) + e for p, e in zip(local, pad)]).reshape(-1, 3)
        # The boxes' bounding spheres, for the cheaper test on local directions (``near_rays``).
        self.sphere_centres = (self._low + self._high) / 2
        self.sphere_radii = np.linalg.norm(self._high - self._low, axis=1) / 2

    def _maybe(self, local: np.ndarray, directions: np.ndarray, lengths: np.ndarray) -> np.ndarray:
        return np.flatnonzero(_crossing(local, directions, lengths * (1 + 1e-6),
                                        self._low, self._high))

    def cast_local(self, origins, directions, lengths) -> LocalHits:
        """As ``Tracer.cast_local``: −1 and the ray's length for rays that cross no box; the
        barycentrics are not computed (0)."""
        primitive = np.full(len(origins), -1, np.int32)
        distance = np.array(lengths, np.float32)
        rows = self._maybe(origins, directions, lengths)
        if len(rows):
            met = self._tracer.cast_local(origins[rows], directions[rows], lengths[rows].copy())
            primitive[rows], distance[rows] = met.triangle, met.distance
        return LocalHits(primitive, distance, np.zeros(len(origins), np.float32),
                         np.zeros(len(origins), np.float32))

    def _local(self, origins, directions, length):
        lengths = np.empty(len(origins), np.float32)
        lengths[:] = length
        return ((origins - self.center).astype(np.float32), directions.astype(np.float32),
                lengths)

    def cast(self, origins, directions, length) -> Hits:
        """As ``Tracer.cast``; the triangle only (distances and barycentrics left empty)."""
        triangle = self.cast_local(*self._local(origins, directions, length)).triangle
        n = len(origins)
        return Hits(triangle.astype(np.int64), np.full(n, np.inf), np.zeros(n), np.zeros(n))

    def occluded(self, origins, directions, length) -> np.ndarray:
        """As ``Tracer.occluded``."""
        blocked = np.zeros(len(origins), bool)
        rows = self._maybe(*self._local(origins, directions, length))
        if len(rows):
            lengths = np.broadcast_to(np.asarray(length, np.float64), (len(origins),))[rows]
            blocked[rows] = self._tracer.occluded(origins[rows], directions[rows], lengths)
        return blocked


def _placed_positions(scene: Scene, instance: int, matrix: np.ndarray) -> np.ndarray:
    """(v, 3) world positions of an instance's vertices had its node the world ``matrix``,
    with the arithmetic of ``geometry.build_world`` (so the new place matches it bit for bit)."""
    return placed_positions(scene.primitives[scene.instances[instance].primitive].positions,
                            matrix)


def placed_corners(scene: Scene, world: World, instance: int, matrix: np.ndarray) -> np.ndarray:
    """(t, 3, 3) corners of an instance's world triangles had its node the world ``matrix``
    (``_placed_positions``)."""
    local = world.triangles[world.instance_triangles(instance)] - world.vertex_start[instance]
    return _placed_positions(scene, instance, matrix)[local]


def world_before(scene: Scene, world: World, moved: np.ndarray,
                 old_worlds: np.ndarray) -> World:
    """``world`` with the ``moved`` instances back at their world matrices of the last bake
    (``old_worlds`` (I, 4, 4)): the triangles that bake traced, bit for bit (a move that
    changes the tracer's frame is a full bake, so its ``center`` is the same)."""
    positions = world.positions.copy()
    for i in moved:
        positions[world.vertex_start[i]:world.vertex_start[i + 1]] = _placed_positions(
            scene, i, old_worlds[i])
    return replace(world, positions=positions)


def chain_corners(world: World) -> np.ndarray:
    """(t, 3, 3) world corners of the triangles whose material reflects or refracts rays on
    (a mirror or glass branch, ``materials.SPECULAR``/``TRANSPARENT``)."""
    weights = world.materials.weights
    chained = (weights[:, SPECULAR] > 0) | (weights[:, TRANSPARENT] > 0)
    tris = np.flatnonzero(chained[world.tri_material]) if len(weights) else np.zeros(0, np.int64)
    a, b, c = world.corners(tris)
    return np.stack([a, b, c], axis=1)
