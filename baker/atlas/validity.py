"""Texel validity: find sample points that lie inside or behind geometry, move or flag them.

A texel's sample point is the centre of its square mapped onto its triangle. Where another
surface cuts through that square — a floor running under a wall, a box standing on the floor —
the centre may sit behind the wall or inside the box, while part of the square is in the open.
Rays started there see the far side of the wall (light leaks through the corner) or only the
inside of the box (a dark rim round a box that should have a contact shadow only).

What the mature bakers do (Bakery, Godot's LightmapperRD, Unity's backface tolerance), here:

0. Shadow terminator: a texel on a smooth-shaded curved facet is first pushed towards the smooth
   surface (``Texels.terminator``, rasterise.py), unless a ray along the push (lifted like a ray
   origin, ``RAISE_MARGIN`` texel sides longer) meets something: a sphere's underside resting on
   a floor is never pushed through the floor.
1. Hemisphere probes from the sample point: ``HEMISPHERE_RAYS`` fixed cosine-spread rays up to
   d_max; the fraction that meets back faces of single-sided surfaces says whether the point
   is inside geometry (at least ``BACKFACE_TOLERANCE``: under a box, in a thick wall) or in
   the open, maybe behind a single-sided panel (a wall, a pane, a fence, a card standing on a
   floor: its back faces fill at most half of the hemisphere). The last seven go that far only
   where one of the first ``FIRST_PROBES`` met a back face: else the fraction stays below the
   tolerance whatever they meet, and they look only for a surface touching the point (short
   rays, most meeting nothing: ``Tracer.cast_local_sparse`` casts them, and the tangent
   probes below).
2. Tangent probes: from the sample point, lifted off the surface by the integrator's offset,
   ``TANGENT_RAYS`` short rays in the texel's plane, ``PROBE_RADIUS`` texel sides long. A ray
   that meets the *back* of a single-sided surface first means the sample is behind it: the
   point moves along that ray past the nearest such face, ``PUSH`` texel sides into the open
   (the point stays in the texel's plane, within about a texel of where it was), where the
   move may go: anywhere within reach for a point inside geometry (its rays would see only
   the inside), but for a point in the open only through a face that crosses the texel's own
   square (a floor texel straddling a wall takes the light of the wall's front side, where
   its square meets the room). A point in the open behind a panel that does not cross its
   square stays where it is: moved, it would take light from the panel's other side, which
   the texel cannot see. Repeated up to ``TANGENT_ROUNDS`` times, so a point behind two walls
   (a corner) gets out too.
3. Hemisphere probes again from the final point, if it moved. The fraction decides:
   - at least ``ENCLOSED_FRACTION``: the point is shut inside a solid (a floor under a box or a
     thick wall). No light reaches it: its lightmap value is 0 (dark), its own rays are unused.
   - at least ``BACKFACE_TOLERANCE``: inside or behind geometry, and it could not be moved out:
     *invalid*. Post-processing gives it the mean of its valid neighbours, never the value of
     rays that started inside a wall.
   - else valid.

Double-sided materials have no back: their faces never count. Everything is vectorised over
texels (one ray batch per probe step) and a pure function of the geometry, so the result does not
depend on chunking or threads (docs/design.md §4).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from baker.atlas.rasterise import Texels, flat_pages
from baker.geometry.world import World
from baker.gltf.scene import Scene
from baker.jit import jit
from baker.rays.trace import LocalHits, Tracer, ray_lift
from baker.run.parallel import run_chunks

TANGENT_RAYS = 8
TANGENT_ROUNDS = 3
PROBE_RADIUS = 1.5  # texel sides: a texel centre up to one texel behind a wall, or diagonally (1.41) behind a corner
PUSH = 0.1  # texel sides past the back face the point is moved to
TIE = 0.25  # texel sides: back faces this close to the nearest count as equally near
RAISE_MARGIN = 0.1  # texel sides: the terminator push is checked this much past its end
HEMISPHERE_RAYS = 12
TOUCH = 2.0  # ray lifts: a probe hit this close to its origin touches (see Validity.touching)
ENCLOSED_FRACTION = 0.9
BACKFACE_TOLERANCE = 0.6
FIRST_PROBES = HEMISPHERE_RAYS + 1 - next(c for c in range(HEMISPHERE_RAYS + 1)
                                          if c / HEMISPHERE_RAYS >= BACKFACE_TOLERANCE)
"""Hemisphere probes always cast to d_max (5 of 12): if none of them meets a back face, the
others cannot make the fraction ``BACKFACE_TOLERANCE`` (``_back_fraction``)."""

VALID, MOVED, INVALID, ENCLOSED = 0, 1, 2, 3
STATE_NAMES = ("valid", "moved", "invalid", "enclosed")

_CHUNK = 1 << 13  # texels per ray batch (one thread's work unit)


@dataclass(frozen=True)
class Validity:
    """What the probes found for N texels (rows in ``Texels`` order).

    state: (N,) int8, one of VALID, MOVED (sample moved past a back face, then valid), INVALID
    (filled from neighbours later), ENCLOSED (inside a solid: value 0). moved_by: (N,) float64
    world distance each sample point moved past back faces (0 for most; the terminator push is
    not counted). back_fraction: (N,) float64 fraction of
    the hemisphere probes that met a back face within their reach (``_back_fraction``: all of
    them where it could reach ``BACKFACE_TOLERANCE``). touching: (N,) bool, some probe met a surface
    within ``TOUCH`` ray lifts of its origin: the point touches other geometry, where which of
    the triangles meeting there Embree reports first can depend on its whole BVH — so on every
    object in the scene, near or not (an incremental rebake redoes these texels). Rare: sample
    points keep off their triangle's edges (``rasterise.INSET``), so a room's corners and a
    crate's foot do not touch (14 of 546,638 texels in ``benchmarks/bench_rebake.py``'s room).
    """

    state: np.ndarray
    moved_by: np.ndarray
    back_fraction: np.ndarray
    touching: np.ndarray

    def counts(self) -> dict[str, int]:
        """How many texels are in each state, by name (for the report)."""
        return {name: int((self.state == code).sum()) for code, name in enumerate(STATE_NAMES)}

    def page_masks(self, texels: Texels, shape: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray]:
        """(invalid, enclosed): (P, H, W) bool page masks of the INVALID and ENCLOSED texels."""
        masks = np.zeros(shape, bool), np.zeros(shape, bool)
        self.mark(texels, *masks)
        return masks

    def mark(self, texels: Texels, invalid: np.ndarray, enclosed: np.ndarray) -> None:
        """Set the texels' pixels of the ``page_masks`` ``invalid`` and ``enclosed`` in place
        (a bake made part by part marks each part)."""
        invalid, enclosed = flat_pages(invalid), flat_pages(enclosed)  # (P·H·W,) views
        for start in range(0, len(texels), _CHUNK):  # the pixels of a chunk at a time
            rows = slice(start, start + _CHUNK)
            where = texels.pixel_index(rows)
            invalid[where] = self.state[rows] == INVALID
            enclosed[where] = self.state[rows] == ENCLOSED


def probe_frames(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (k, 3) each, orthogonal to the unit normals (k, 3) and to each other:
    t1 = normal × helper, normalised, with helper the x axis (the y axis where the normal is
    within 26° of x), and t2 = normal × t1."""
    normal = np.ascontiguousarray(normal, np.float64)
    t1, t2 = np.empty_like(normal), np.empty_like(normal)
    _frames_kernel(normal, t1, t2)
    return t1, t2


@jit
def _frames_kernel(normal: np.ndarray, t1: np.ndarray, t2: np.ndarray) -> None:
    """``probe_frames`` into t1, t2, in one pass: the arithmetic of np.cross and np.linalg.norm
    (the same bits), 18× faster than they are on (k, 3) rows."""
    for i in range(len(normal)):
        nx, ny, nz = normal[i, 0], normal[i, 1], normal[i, 2]
        hx, hy = (1.0, 0.0) if abs(nx) < 0.9 else (0.0, 1.0)
        ax, ay, az = ny * 0.0 - nz * hy, nz * hx - nx * 0.0, nx * hy - ny * hx
        norm = np.sqrt(ax * ax + ay * ay + az * az)
        ax, ay, az = ax / norm, ay / norm, az / norm
        t1[i, 0], t1[i, 1], t1[i, 2] = ax, ay, az
        t2[i, 0], t2[i, 1], t2[i, 2] = ny * az - nz * ay, nz * ax - nx * az, nx * ay - ny * ax


def hemisphere_directions(count: int) -> np.ndarray:
    """(count, 3) fixed cosine-spread directions about +z (a Fibonacci spiral on the disc)."""
    i = np.arange(count) + 0.5
    r = np.sqrt(i / count)
    phi = i * np.pi * (3.0 - np.sqrt(5.0))
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1.0 - r * r)], axis=1)


class Faces:
    """Which hits are back faces: geometric normals and single-sidedness of every triangle (made
    once per bake and passed to ``check_texels`` for each part of the texels)."""

    def __init__(self, scene: Scene, world: World):
        self.normals = world.geometric_normals()
        self.single = ~np.array([m.double_sided for m in scene.materials], bool)[world.tri_material]

    def back(self, triangle: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """(n,) bool: the ray met the back of a single-sided triangle (False for misses)."""
        return _back_faces(triangle, directions, self.normals, self.single)


@jit
def _back_faces(triangle: np.ndarray, directions: np.ndarray, normals: np.ndarray,
                single: np.ndarray) -> np.ndarray:
    """(n,) bool: hit ``triangle`` (n,) (−1: none) is single-sided and faces along the ray's
    direction (n, 3), i.e. the ray met its back."""
    out = np.zeros(len(triangle), np.bool_)
    for i in range(len(triangle)):
        t = triangle[i]
        if t >= 0 and single[t]:
            out[i] = (normals[t, 0] * directions[i, 0] + normals[t, 1] * directions[i, 1]
                      + normals[t, 2] * directions[i, 2]) > 0
    return out


def _tangent_step(tracer: Tracer, faces: Faces, position: np.ndarray, normal: np.ndarray,
                  size: np.ndarray, home: np.ndarray, origin: np.ndarray, axes: np.ndarray,
                  free: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One round of tangent probes for k points: (new position (k, 3), moved (k,) bool,
    touching (k,) bool: some probe met a surface within ``TOUCH`` ray lifts).

    Of the back faces within ``TIE`` texel sides of the nearest that the point may cross — any
    where ``free`` (k,) (it is inside geometry), else only one met within the texel's own
    square (centred on ``origin`` (k, 3), the sample point before any move, spanned by its
    texel ``axes`` (k, 2, 3)) — the point crosses the one whose direction points most towards
    ``home`` (k, 3), the centroid of the texel's own triangle: where the surface really is (a
    wall's corner texel poking past the ceiling and a side wall moves back into the room, not
    over the ceiling)."""
    t1, t2 = probe_frames(normal)
    angle = 2 * np.pi * np.arange(TANGENT_RAYS) / TANGENT_RAYS
    in_plane = np.stack([np.cos(angle), np.sin(angle), np.zeros(TANGENT_RAYS)], axis=1)
    lift = ray_lift(position, size, tracer.center)
    directions, hits = _cast_fan(tracer, position, normal, t1, t2, lift, in_plane,
                                 np.repeat(PROBE_RADIUS * size, TANGENT_RAYS), sparse=True)
    new, moved, touching = (np.empty_like(position), np.empty(len(position), np.bool_),
                            np.empty(len(position), np.bool_))
    _cross_nearest(position, size, home, origin, np.ascontiguousarray(axes, np.float64),
                   free, directions, hits.triangle, hits.distance, lift, faces.normals,
                   faces.single, new, moved, touching)
    return new, moved, touching


@jit
def _in_square(px: float, py: float, pz: float, origin: np.ndarray, axes: np.ndarray,
               i: int) -> bool:
    """Whether the point (px, py, pz), on texel i's plane, lies within its square: the texel
    ``axes[i]`` (2, 3) (world steps of one texel in x and y) about ``origin[i]``, with a
    margin of 10⁻⁶ texel (its Gram system solved by hand; no square without UV area)."""
    ox, oy, oz = px - origin[i, 0], py - origin[i, 1], pz - origin[i, 2]
    a = axes[i, 0, 0] * axes[i, 0, 0] + axes[i, 0, 1] * axes[i, 0, 1] + axes[i, 0, 2] * axes[i, 0, 2]
    b = axes[i, 0, 0] * axes[i, 1, 0] + axes[i, 0, 1] * axes[i, 1, 1] + axes[i, 0, 2] * axes[i, 1, 2]
    c = axes[i, 1, 0] * axes[i, 1, 0] + axes[i, 1, 1] * axes[i, 1, 1] + axes[i, 1, 2] * axes[i, 1, 2]
    u = axes[i, 0, 0] * ox + axes[i, 0, 1] * oy + axes[i, 0, 2] * oz
    v = axes[i, 1, 0] * ox + axes[i, 1, 1] * oy + axes[i, 1, 2] * oz
    det = a * c - b * b
    if not det > 1e-12 * a * c:
        return False
    s, t = (c * u - b * v) / det, (a * v - b * u) / det
    return abs(s) <= 0.5 + 1e-6 and abs(t) <= 0.5 + 1e-6


@jit
def _cross_nearest(position: np.ndarray, size: np.ndarray, home: np.ndarray,
                   origin: np.ndarray, axes: np.ndarray, free: np.ndarray,
                   directions: np.ndarray, triangle: np.ndarray, distance: np.ndarray,
                   lift: np.ndarray, normals: np.ndarray, single: np.ndarray, new: np.ndarray,
                   moved: np.ndarray, touching: np.ndarray) -> None:
    """What ``_tangent_step``'s probes found, in one compiled pass over k points (numpy's
    passes over (k, m) temporaries took most of the stage's time outside Embree): their m rays
    point-major, ``directions`` (k·m, 3) and hits ``triangle`` (k·m,) (−1: none) at
    ``distance`` (k·m,) (``LocalHits``'). Writes ``new`` (k, 3), the point moved past the
    chosen back face and ``PUSH`` texel sides ``size`` (k,) further (or where it was),
    ``moved`` (k,) and ``touching`` (k,): a probe met anything within ``TOUCH`` × ``lift``
    (k,). A back face: ``_back_faces`` with the faces' ``normals`` and ``single``; one the
    point may cross: any where ``free`` (k,), else one met within the texel's square
    (``_in_square`` about ``origin`` (k, 3) with ``axes`` (k, 2, 3))."""
    k = len(position)
    m = len(triangle) // max(k, 1)
    back = np.empty(m)
    for i in range(k):
        tx, ty, tz = (home[i, 0] - position[i, 0], home[i, 1] - position[i, 1],
                      home[i, 2] - position[i, 2])
        length = max(np.sqrt(tx * tx + ty * ty + tz * tz), 1e-300)
        tx, ty, tz = tx / length, ty / length, tz / length
        nearest, touch = np.inf, False
        for j in range(m):
            r = i * m + j
            t = triangle[r]
            touch |= t >= 0 and distance[r] <= TOUCH * lift[i]
            facing = t >= 0 and single[t] and (normals[t, 0] * directions[r, 0]
                                               + normals[t, 1] * directions[r, 1]
                                               + normals[t, 2] * directions[r, 2]) > 0
            if facing and not free[i]:
                d = distance[r]
                facing = _in_square(position[i, 0] + d * directions[r, 0],
                                    position[i, 1] + d * directions[r, 1],
                                    position[i, 2] + d * directions[r, 2], origin, axes, i)
            back[j] = distance[r] if facing else np.inf
            nearest = min(nearest, back[j])
        within = nearest + TIE * size[i]
        chosen, best = 0, -np.inf
        for j in range(m):  # the first of the most aligned, as np.argmax takes it
            r = i * m + j
            alignment = directions[r, 0] * tx + directions[r, 1] * ty + directions[r, 2] * tz
            if back[j] <= within and alignment > best:
                chosen, best = j, alignment
        touching[i] = touch
        moved[i] = np.isfinite(back[chosen])
        step = back[chosen] + PUSH * size[i]
        r = i * m + chosen
        for c in range(3):
            new[i, c] = position[i, c] + step * directions[r, c] if moved[i] else position[i, c]


def hemisphere_probes(position: np.ndarray, normal: np.ndarray, size: np.ndarray,
                      center: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The fixed hemisphere probes of k points: origins and directions, each (k·HEMISPHERE_RAYS,
    3) float64 world, point-major; origins lifted off the surface by ``trace.ray_lift``."""
    t1, t2 = probe_frames(normal)
    m = HEMISPHERE_RAYS
    origins, directions = np.empty((len(position) * m, 3)), np.empty((len(position) * m, 3))
    _fan(position, normal, t1, t2, ray_lift(position, size, center),
         hemisphere_directions(m), np.zeros(3), origins, directions)
    return origins, directions


def _cast_fan(tracer: Tracer, position: np.ndarray, normal: np.ndarray, t1: np.ndarray,
              t2: np.ndarray, lift: np.ndarray, local: np.ndarray, lengths: np.ndarray,
              sparse: bool = False) -> tuple[np.ndarray, LocalHits]:
    """Cast ``_fan``'s rays within ``lengths`` (k·m,): their directions (k·m, 3) float64 and
    hits. The rays go to Embree as ``Tracer.cast`` would send them (origins − centre, then
    float32), made so in the fan's one pass; ``sparse`` for short rays most of which meet
    nothing (``Tracer.cast_local_sparse``: the same hits, sooner)."""
    origins = np.empty((len(lengths), 3), np.float32)
    directions = np.empty((len(lengths), 3))
    _fan(position, normal, t1, t2, lift, local, tracer.center, origins, directions)
    cast = tracer.cast_local_sparse if sparse else tracer.cast_local
    return directions, cast(origins, directions.astype(np.float32), lengths.astype(np.float32))


@jit
def _fan(position: np.ndarray, normal: np.ndarray, t1: np.ndarray, t2: np.ndarray,
         lift: np.ndarray, local: np.ndarray, shift: np.ndarray, origins: np.ndarray,
         directions: np.ndarray) -> None:
    """Write the origins − ``shift`` (3,) and the directions, (k·m, 3) each, point-major, of
    the m ``local`` directions (m, 3) in each point's frame (t1, t2, normal) (k, 3), from the
    point lifted by ``lift`` (k,); float32 ``origins`` take the float64 values rounded."""
    k, m = len(position), len(local)
    for i in range(k):
        for j in range(m):
            r = i * m + j
            for c in range(3):
                origins[r, c] = position[i, c] + lift[i] * normal[i, c] - shift[c]
                directions[r, c] = (local[j, 0] * t1[i, c] + local[j, 1] * t2[i, c]
                                    + local[j, 2] * normal[i, c])


def _back_fraction(tracer: Tracer, faces: Faces, position: np.ndarray, normal: np.ndarray,
                   size: np.ndarray, d_max: float) -> tuple[np.ndarray, np.ndarray]:
    """(k,) fraction of the fixed hemisphere probes from each point that meet a back face, and
    (k,) bool whether one touches (meets a surface within ``TOUCH`` ray lifts).

    The first ``FIRST_PROBES`` of a point's probes reach d_max; the others reach only ``TOUCH``
    ray lifts (all touching asks of them) unless one of the first met a back face, when they
    too are cast to d_max. Where none did, the fraction cannot reach ``BACKFACE_TOLERANCE``
    whatever the others would meet: the texel's state and moves are those of twelve full
    probes, with 7 in 12 of the long rays left out where a texel is in the open (3.8 M of the
    boxes' 6.5 M at default settings). The fraction counts the
    back faces the probes met within their reach."""
    t1, t2 = probe_frames(normal)
    lift = ray_lift(position, size, tracer.center)
    k, m, local = len(position), HEMISPHERE_RAYS, hemisphere_directions(HEMISPHERE_RAYS)
    first, rest = FIRST_PROBES, HEMISPHERE_RAYS - FIRST_PROBES
    # A hair past TOUCH lifts, so float32 rounding never shortens a ray that must touch.
    short = np.minimum(d_max, TOUCH * (1 + 1e-6) * lift)
    far, hits = _cast_fan(tracer, position, normal, t1, t2, lift, local[:first],
                          np.full(k * first, d_max))
    close, near = _cast_fan(tracer, position, normal, t1, t2, lift, local[first:],
                            np.repeat(short, rest), sparse=True)
    directions = np.concatenate([far.reshape(k, first, 3), close.reshape(k, rest, 3)], axis=1)
    triangle = np.concatenate([hits.triangle.reshape(k, first), near.triangle.reshape(k, rest)],
                              axis=1)
    distance = np.concatenate([hits.distance.reshape(k, first),
                               near.distance.reshape(k, rest)], axis=1)
    further = np.flatnonzero(faces.back(hits.triangle, far).reshape(k, first).any(axis=1)
                             & (short < d_max))
    if len(further):  # the rest of their probes to d_max, as they were cast at first
        _, more = _cast_fan(tracer, position[further], normal[further], t1[further],
                            t2[further], lift[further], local[first:],
                            np.full(len(further) * rest, d_max))
        triangle[further, first:] = more.triangle.reshape(-1, rest)
        distance[further, first:] = more.distance.reshape(-1, rest)
    directions, triangle, distance = directions.reshape(-1, 3), triangle.ravel(), distance.ravel()
    fraction, touching = np.empty(k), np.empty(k, np.bool_)
    _count_backs(directions, triangle, distance, lift, faces.normals, faces.single,
                 fraction, touching)
    return fraction, touching


@jit
def _count_backs(directions: np.ndarray, triangle: np.ndarray, distance: np.ndarray,
                 lift: np.ndarray, normals: np.ndarray, single: np.ndarray,
                 fraction: np.ndarray, touching: np.ndarray) -> None:
    """Per point of k, of its m probes (point-major, as ``_cross_nearest`` takes them): the
    ``fraction`` (k,) that met a back face (``_back_faces``) and ``touching`` (k,), whether one
    met anything within ``TOUCH`` × ``lift`` (k,)."""
    k = len(lift)
    m = len(triangle) // max(k, 1)
    for i in range(k):
        backs, touch = 0, False
        for r in range(i * m, (i + 1) * m):
            t = triangle[r]
            touch |= t >= 0 and distance[r] <= TOUCH * lift[i]
            if t >= 0 and single[t] and (normals[t, 0] * directions[r, 0]
                                         + normals[t, 1] * directions[r, 1]
                                         + normals[t, 2] * directions[r, 2]) > 0:
                backs += 1
        fraction[i] = backs / m
        touching[i] = touch


def _raise(tracer: Tracer, position: np.ndarray, normal: np.ndarray, size: np.ndarray,
           push: np.ndarray) -> np.ndarray:
    """(k, 3) points ``position`` moved by their terminator ``push`` (k, 3) where a ray along it,
    from the point lifted off the surface along ``normal`` (k, 3), meets nothing within the
    push's length + ``RAISE_MARGIN`` texel sides ``size`` (k,); the others stay."""
    length = np.linalg.norm(push, axis=1)
    pushing = np.flatnonzero(length > 0)
    if not len(pushing):
        return position
    p = position[pushing]
    lift = ray_lift(p, size[pushing], tracer.center)
    blocked = tracer.occluded(p + lift[:, None] * normal[pushing],
                              push[pushing] / length[pushing, None],
                              length[pushing] + RAISE_MARGIN * size[pushing])
    out = position.copy()
    out[pushing[~blocked]] += push[pushing[~blocked]]
    return out


@jit
def _centroids(positions: np.ndarray, triangles: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """(k, 3) world centroids of the triangles ``tri`` (k,): (a + b + c) / 3, corner by corner
    as numpy's mean of the three corners sums them."""
    out = np.empty((len(tri), 3))
    for i in range(len(tri)):
        a, b, c = triangles[tri[i], 0], triangles[tri[i], 1], triangles[tri[i], 2]
        for j in range(3):
            out[i, j] = (positions[a, j] + positions[b, j] + positions[c, j]) / 3.0
    return out


def check_texels(scene: Scene, world: World, tracer: Tracer, texels: Texels,
                 d_max: float, threads: int = 0, faces: Faces | None = None
                 ) -> tuple[Texels, Validity]:
    """Probe every texel's sample point; return the texels with moved positions and their states.

    ``d_max``: the hemisphere probes' length (the obscurance distance), world units.
    ``threads``: 0 for one per core. ``faces``: ``Faces(scene, world)``, made here when not
    given. Only ``Texels.position`` changes; normals, triangle and key
    stay (the point is pushed off its facet by the terminator push, then moves parallel to the
    facet). Chunks write only their own rows, so the
    result does not depend on the chunking or the threads.
    """
    count = len(texels)
    faces = Faces(scene, world) if faces is None else faces
    position = texels.position.copy()
    start = position.copy()  # after the terminator push
    moved = np.zeros(count, bool)
    touching = np.zeros(count, bool)
    fraction = np.zeros(count)

    def work(rows: slice) -> None:
        normal, size = texels.geometric_normal(rows), texels.size(rows)
        ok = np.flatnonzero(np.linalg.norm(normal, axis=1) > 0.5)
        usable = ok[size[ok] > 0]
        p = position[rows]  # a view: the chunk's own rows
        p[:] = _raise(tracer, p, normal, texels.size(rows), texels.terminator(rows))
        start[rows] = p
        origin = p.copy()
        home = _centroids(world.positions, world.triangles, texels.triangle[rows])
        axes = texels.axes(rows)
        step_moved, touched, back = moved[rows], touching[rows], fraction[rows]  # views
        back[ok], touched[ok] = _back_fraction(tracer, faces, p[ok], normal[ok], size[ok],
                                               d_max)
        free = back >= BACKFACE_TOLERANCE  # inside geometry: it may move through any back face
        for _ in range(TANGENT_ROUNDS):
            new, stepped, touch = _tangent_step(tracer, faces, p[usable], normal[usable],
                                                size[usable], home[usable], origin[usable],
                                                axes[usable], free[usable])
            p[usable] = new
            step_moved[usable] |= stepped
            touched[usable] |= touch
            usable = usable[stepped]
            if not len(usable):
                break
        again = np.flatnonzero(step_moved)  # the fraction where each moved point ended
        if len(again):
            back[again], touch = _back_fraction(tracer, faces, p[again], normal[again],
                                                size[again], d_max)
            touched[again] |= touch

    run_chunks(work, [slice(start, min(start + _CHUNK, count))
                      for start in range(0, count, _CHUNK)], threads)
    state = np.where(moved, MOVED, VALID).astype(np.int8)
    state[fraction >= BACKFACE_TOLERANCE] = INVALID
    state[fraction >= ENCLOSED_FRACTION] = ENCLOSED
    moved_by = np.linalg.norm(position - start, axis=1)
    return (replace(texels, position=position),
            Validity(state=state, moved_by=moved_by, back_fraction=fraction, touching=touching))
