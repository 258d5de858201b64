"""Find every lightmap texel a baked triangle touches, and the surface point it stands for.

Coverage is conservative: a texel belongs to a triangle when the texel's square overlaps the
triangle in UV space at all (separating-axis test), not only when its centre is inside. So a
sliver or a triangle smaller than a texel still gets the texel(s) it touches, and a viewer's
bilinear lookup on any triangle reads texels that were baked.

A texel touched by several triangles (along shared edges) is owned by the one whose interior is
deepest at the texel centre, ties going to the lower triangle index: a fixed rule, so the result
does not depend on how the work is split. The texel's sample point is its centre's barycentric
position in the owner, clamped into the triangle, mapped to world space.

A centre outside its owner, or closer to one of its edges than ``INSET`` texels, is drawn
inside, each edge by its own distance: ``INSET`` × (1 + 0.7·θ/π), θ ∈ [0, π) the edge's
direction in UV (``_inset``), so edges meeting at a corner get unequal insets whatever the
corners' order (a mirrored mesh lists them the other way round). A point clamped onto an edge would lie in every surface that meets
the triangle there (a room's corner, a crate standing on the floor): a probe or ray from it
meets those surfaces at distance 0, or exactly where two of them meet, and which of the tied
triangles Embree reports depends on its BVH of the whole scene, so on every object's place —
an incremental rebake could not match a full bake there. Unequal insets keep the point off
the diagonals too, where a probe would reach two edges at once.

Shadow terminator: on a low-poly curved surface with smooth (interpolated) normals, the flat
facets lie inside the surface the normals describe, so a point on a facet near the light's
terminator sees the light only below its own facet's plane, or is shadowed by the next facet:
the shading shows each facet as a step. As Hanika ("Hacking the shadow terminator", Ray Tracing
Gems II, 2021) and the Godot and Bakery bakers do, the sample point is pushed off the facet
towards the smooth surface: ``_texel_points`` gives the push (``Texels.terminator``); the
validity probes apply it where nothing is in the way (``validity.py``). Flat surfaces (shading
normal = face normal) and concave ones get none.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from baker.atlas.layout import Atlas
from baker.frozen import read_only
from baker.geometry.world import World
from baker.jit import jit
from baker.rays.sampling import hemisphere_normals
from baker.run.parallel import run_chunks

_KEY_BITS = np.uint64((1 << 63) - 1)  # a texel key's bits below inner.OTHER_SIDE


def flat_pages(pages: np.ndarray) -> np.ndarray:
    """Pages (P, H, W, …) as one run of P·H·W pixels, for ``Texels.pixel_index``: a view, so
    that writing to it writes the pages (setting the shape refuses what would need a copy)."""
    flat = pages.view()
    flat.shape = (-1,) + pages.shape[3:]
    return flat


@dataclass(frozen=True)
class Texels:
    """The baked texels, N of them, sorted by ``key``.

    key: (N,) uint64 stable texel key for the sampler, ``(page·height + y)·width + x``, of pages
    ``page_width`` × ``page_height`` texels: ``pixels(rows)`` gives the texels' page, row (0 at
    the top of the page image) and column.
    position: (N, 3) float64 world sample point. normal: (N, 3) unit interpolated shading normal.
    triangle: (N,) int64 owning world triangle (index into World.triangles).
    triangle_instance: (T,) int64 instance of every world triangle; ``instance(rows)`` gives the
    texels'.
    triangle_normal: (T, 3) unit front-face normal of every world triangle that owns texels
    (zeros for the others); ``geometric_normal(rows)`` gives the texels'.
    triangle_size: (T,) float64 world length of one texel side on each triangle (0 without UV
    area or texels); ``size(rows)`` gives the texels'.
    triangle_axes: (T, 2, 3) float64, per world triangle, the world displacement of one texel
    step in x and in y on its plane (the UV→world Jacobian; zeros for a triangle without UV
    area or without texels), for sub-texel sample positions (``supersample.py``). What depends
    on the owning triangle alone is kept per triangle: per texel, normal, size and axes would
    take 80 bytes, 670 MB on a 4096² page.
    terminator_push: (N, 3) float64 world push of the sample point towards the smooth surface
    its shading normals describe (``_texel_points``; zeros on flat and concave surfaces), or
    (0, 3) when every texel's is zero; ``terminator(rows)`` gives the texels'. Not yet applied
    to ``position``: ``validity.check_texels`` does that where the way is clear.
    triangle_texels: (T,) int64, for every world triangle, how many texels its UV footprint
    touches (0 for triangles that are not baked).
    """

    key: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    triangle: np.ndarray
    triangle_instance: np.ndarray
    triangle_normal: np.ndarray
    triangle_size: np.ndarray
    triangle_texels: np.ndarray
    triangle_axes: np.ndarray
    terminator_push: np.ndarray
    page_width: int
    page_height: int

    def __len__(self) -> int:
        return len(self.key)

    def pixels(self, rows: np.ndarray | slice = slice(None)
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(page, y, x), each (k,) int64, of the texels ``rows``, from their keys (the other-side
        bit ``inner.OTHER_SIDE`` ignored): ``pages[texels.pixels(rows)]`` reads them."""
        page, rest = np.divmod(self.pixel_index(rows), self.page_width * self.page_height)
        y, x = np.divmod(rest, self.page_width)
        return page, y, x

    def pixel_index(self, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """(k,) int64 index of the texels ``rows``' pixels in pages (P, H, W, …) seen as one
        run of P·H·W pixels — the key itself, (page·H + y)·W + x, less the other-side bit:
        ``pages.reshape(P * H * W, …)[index]`` reads them, without the divisions of
        ``pixels`` or numpy's work on three index arrays (2-3× faster)."""
        return pixel_index(self.key[rows])

    def instance(self, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """(k,) int64 instance of the texels ``rows`` (their triangles')."""
        return self.triangle_instance[self.triangle[rows]]

    def terminator(self, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """(k, 3) terminator push of the texels ``rows`` (zeros where none is stored)."""
        if len(self.terminator_push):
            return self.terminator_push[rows]
        return np.zeros((len(self.triangle[rows]), 3))

    def geometric_normal(self, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """(k, 3) unit front-face normals of the texels ``rows`` (their triangles')."""
        return self.triangle_normal[self.triangle[rows]]

    def hemisphere_normal(self, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """(k, 3) the normals the texels ``rows``' hemispheres of rays are drawn about: their
        shading normals, or their front-face normals on flat surfaces
        (``sampling.hemisphere_normals``; rays below the front face are folded above it)."""
        return hemisphere_normals(self.normal[rows], self.geometric_normal(rows))

    def size(self, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """(k,) world length of one texel side of the texels ``rows`` (their triangles')."""
        return self.triangle_size[self.triangle[rows]]

    def axes(self, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """(k, 2, 3) texel axes of the texels ``rows`` (their owning triangles' ``triangle_axes``)."""
        return self.triangle_axes[self.triangle[rows]]


def _baked_triangles(atlas: Atlas, world: World) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Texel-space corners (k, 3, 2), page (k,) and world triangle index (k,) of every baked
    triangle that xatlas placed on a page, degenerate ones left out."""
    corners, pages, tris = [], [], []
    scale = np.array([atlas.width, atlas.height], np.float64)
    usable = ~world.degenerate
    for unwrap in atlas.instances:
        own = world.instance_triangles(unwrap.instance)
        placed = (unwrap.pages >= 0) & usable[own]
        corners.append(unwrap.uv[unwrap.triangles[placed]] * scale)
        pages.append(unwrap.pages[placed])
        tris.append(own[placed])
    if not corners:
        return np.zeros((0, 3, 2)), np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(corners), np.concatenate(pages), np.concatenate(tris)


def _edge_terms(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inward unit edge normals (k, 3, 2) and offsets (k, 3) of UV triangles ``corners`` (k, 3, 2).

    For a point p, ``normals[e] · p - offsets[e]`` is its distance inside edge e (negative
    outside), edge e running from corner e to corner e + 1. Degenerate triangles get zero
    normals, so only their bounding box counts.
    """
    corners = np.ascontiguousarray(corners, np.float64)
    normals, offsets = np.empty((len(corners), 3, 2)), np.empty((len(corners), 3))
    _edge_kernel(corners, normals, offsets)
    return normals, offsets


@jit
def _edge_kernel(corners: np.ndarray, normals: np.ndarray, offsets: np.ndarray) -> None:
    """``_edge_terms`` into ``normals`` and ``offsets``, one triangle at a time: numpy's
    arithmetic of the vectorised form (its bits), without its (k, 3, 2) temporaries."""
    for i in range(len(corners)):
        ax, ay = corners[i, 0, 0], corners[i, 0, 1]
        turn = (corners[i, 1, 0] - ax) * (corners[i, 2, 1] - ay) - (
            corners[i, 1, 1] - ay) * (corners[i, 2, 0] - ax)
        orientation = 1.0 if turn > 0 else (-1.0 if turn < 0 else 0.0)
        for e in range(3):
            f = (e + 1) % 3
            ex, ey = corners[i, f, 0] - corners[i, e, 0], corners[i, f, 1] - corners[i, e, 1]
            nx, ny = -ey * orientation, ex * orientation
            length = np.sqrt(nx * nx + ny * ny)
            if length > 0:
                nx, ny = nx / length, ny / length
            else:
                nx, ny = 0.0, 0.0
            normals[i, e, 0], normals[i, e, 1] = nx, ny
            offsets[i, e] = nx * corners[i, e, 0] + ny * corners[i, e, 1]


@jit
def _cover_kernel(corners: np.ndarray, normals: np.ndarray, offsets: np.ndarray,
                  pages: np.ndarray, width: int, height: int, best_depth: np.ndarray,
                  best_owner: np.ndarray, counts: np.ndarray) -> None:
    """Conservative coverage of UV triangles (k, 3, 2) in texel units on pages ``width`` ×
    ``height``, in place, one compiled pass over each triangle's texel box (clipped to its
    page ``pages`` (k,)): a texel whose square overlaps triangle t (separating axes: the box
    axes by the box itself, the three edges by ``normals`` (k, 3, 2) and ``offsets`` (k, 3),
    ``_edge_terms``, each against the square's half-extent along it) counts in ``counts[t]``
    (k,), and t becomes the texel's owner in ``best_owner`` (P·H·W,) int32 when the texel
    centre's depth inside it (the least distance inside its edges, negative outside) is above
    ``best_depth`` (P·H·W,) float64, or equal to it from a lower t. Every pair is looked at
    once, in triangle order, with no temporaries: memory is the pages' (12 bytes a texel)."""
    for t in range(len(corners)):
        x_lo = np.floor(min(corners[t, 0, 0], corners[t, 1, 0], corners[t, 2, 0]))
        y_lo = np.floor(min(corners[t, 0, 1], corners[t, 1, 1], corners[t, 2, 1]))
        x_hi = max(np.floor(max(corners[t, 0, 0], corners[t, 1, 0], corners[t, 2, 0])), x_lo)
        y_hi = max(np.floor(max(corners[t, 0, 1], corners[t, 1, 1], corners[t, 2, 1])), y_lo)
        n0x, n0y, n1x, n1y = normals[t, 0, 0], normals[t, 0, 1], normals[t, 1, 0], normals[t, 1, 1]
        n2x, n2y = normals[t, 2, 0], normals[t, 2, 1]
        r0 = -(0.5 * (abs(n0x) + abs(n0y)))  # the square's half-extent along each normal
        r1 = -(0.5 * (abs(n1x) + abs(n1y)))
        r2 = -(0.5 * (abs(n2x) + abs(n2y)))
        o0, o1, o2 = offsets[t, 0], offsets[t, 1], offsets[t, 2]
        base = np.int64(pages[t]) * height * width
        for y in range(max(np.int64(y_lo), 0), min(np.int64(y_hi), height - 1) + 1):
            cy = y + 0.5
            for x in range(max(np.int64(x_lo), 0), min(np.int64(x_hi), width - 1) + 1):
                cx = x + 0.5
                d0 = n0x * cx + n0y * cy - o0
                d1 = n1x * cx + n1y * cy - o1
                d2 = n2x * cx + n2y * cy - o2
                if not (d0 >= r0 and d1 >= r1 and d2 >= r2):
                    continue
                counts[t] += 1
                depth = min(d0, d1, d2)
                texel = base + y * width + x
                if depth > best_depth[texel] or (depth == best_depth[texel]
                                                 and t < best_owner[texel]):
                    best_depth[texel] = depth
                    best_owner[texel] = t


def pixel_index(key: np.ndarray) -> np.ndarray:
    """(k,) int64 index of the pixels of texel keys ``key`` (k,) in pages (P, H, W, …) seen as
    one run of P·H·W pixels: (page·H + y)·W + x, the key less the other-side bit."""
    return (key & _KEY_BITS).astype(np.int64)


def texel_barycentrics(atlas: Atlas, world: World, coverage: "Coverage | Texels") -> np.ndarray:
    """(N, 3) barycentric coordinates of the texels' centres in their owning world triangles:
    the points ``texels_of`` maps to world (before validity moves any), for what the texel's
    surface looks like there (its albedo and emission, ``image/carriers.py``). ``coverage``:
    the texels' keys and owning triangles (a ``Coverage``, or the ``Texels`` made from it)."""
    return _texel_barycentrics(coverage.key & _KEY_BITS, coverage.triangle,
                               owners_uv(atlas, world), atlas.width, atlas.height)


def owners_uv(atlas: Atlas, world: World) -> np.ndarray:
    """(T, 3, 2) texel-space UV corners of every world triangle on a page (zeros for others)."""
    return _uv_of(world, _baked_triangles(atlas, world))


def _uv_of(world: World, baked: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
    """``owners_uv`` from the atlas's ``_baked_triangles``."""
    corners, _, tris = baked
    uv = np.zeros((len(world.triangles), 3, 2))
    uv[tris] = corners
    return uv


INSET = 0.01  # texels: sample points keep at least this far inside their triangle's edges


@jit
def _texel_barycentrics(key: np.ndarray, tri: np.ndarray, uv: np.ndarray, width: int,
                        height: int) -> np.ndarray:
    """Barycentric coordinates (k, 3) of the texels' centres — from their keys (k,) on pages of
    ``width`` × ``height`` — in their owning triangles ``tri`` (k,), whose UV corners in texel
    units ``uv`` (T, 3, 2) holds (``_barycentric``). One compiled pass: no (k, 3, 2) gather."""
    bary = np.empty((len(tri), 3))
    page = width * height
    for i in range(len(tri)):
        rest = np.int64(key[i]) % page
        x, y = rest % width + 0.5, rest // width + 0.5
        t = tri[i]
        bary[i, 0], bary[i, 1], bary[i, 2] = _barycentric(
            uv[t, 0, 0], uv[t, 0, 1], uv[t, 1, 0], uv[t, 1, 1], uv[t, 2, 0], uv[t, 2, 1], x, y)
    return bary


@jit
def _barycentric(ax, ay, bx, by, cx, cy, px, py):
    """Barycentric coordinates of the point (px, py) in the triangle (a, b, c) (UV, texel
    units), clamped into the triangle (negative weights cut to 0 and the rest renormalised),
    then drawn in from any edge closer than its inset (``INSET``, ``_inset``); degenerate
    triangles give their centroid."""
    x0, y0 = bx - ax, by - ay
    x1, y1 = cx - ax, cy - ay
    x2, y2 = px - ax, py - ay
    d00, d01, d11 = x0 * x0 + y0 * y0, x0 * x1 + y0 * y1, x1 * x1 + y1 * y1
    d20, d21 = x2 * x0 + y2 * y0, x2 * x1 + y2 * y1
    denom = d00 * d11 - d01 * d01
    third = 1.0 / 3.0
    if not abs(denom) > 1e-30 * max(d00 * d11, 1e-300):
        return third, third, third
    v = (d11 * d20 - d01 * d21) / denom
    w = (d00 * d21 - d01 * d20) / denom
    u, v, w = max(1.0 - v - w, 0.0), max(v, 0.0), max(w, 0.0)
    total = u + v + w
    if not total > 0:
        return third, third, third
    return _inset(u / total, v / total, w / total, abs(x0 * y1 - x1 * y0),
                  x1 - x0, y1 - y0, x1, y1, x0, y0)


@jit
def _inset(b0, b1, b2, area2, e0x, e0y, e1x, e1y, e2x, e2y):
    """Barycentric weights (b0, b1, b2) drawn away from edges closer than their inset.

    area2: twice the triangle's UV area (texels²); e_j: the UV vector (dx, dy) of the edge
    facing corner j. The distance to edge j is weight_j · area2 / |edge_j|, so weight j
    must be at least f_j = inset_j · |edge_j| / area2, with inset_j = ``INSET`` ·
    (1 + 0.7·θ_j/π) and θ_j ∈ [0, π) the edge's direction. Where a weight is below its f, the
    weights become f + (1 − Σf) · weights (still summing to 1, each at least its f). A triangle
    too small for the insets (Σf over ½) scales them down to Σf = ½; one whose corners' cross
    product rounds to 0 (``_barycentric``'s Gram determinant, rounded otherwise, may not) is
    left as it is."""
    if not area2 > 0:
        return b0, b1, b2
    reach = 1.7 * INSET  # first the cheap test against the largest inset (no arctan)
    if not (b0 * area2 < reach * (e0x * e0x + e0y * e0y) ** 0.5
            or b1 * area2 < reach * (e1x * e1x + e1y * e1y) ** 0.5
            or b2 * area2 < reach * (e2x * e2x + e2y * e2y) ** 0.5):
        return b0, b1, b2
    f0, f1, f2 = _floor(e0x, e0y, area2), _floor(e1x, e1y, area2), _floor(e2x, e2y, area2)
    total = f0 + f1 + f2
    if total > 0.5:
        scale = 0.5 / total
        f0, f1, f2 = f0 * scale, f1 * scale, f2 * scale
        total = 0.5
    if b0 >= f0 and b1 >= f1 and b2 >= f2:
        return b0, b1, b2
    return f0 + (1.0 - total) * b0, f1 + (1.0 - total) * b1, f2 + (1.0 - total) * b2


@jit
def _floor(dx, dy, area2):
    """The least weight that keeps a point ``INSET`` · (1 + 0.7·θ/π) texels off the edge (dx,
    dy) (θ its direction in [0, π)) of a triangle of twice the area ``area2`` (``_inset``)."""
    theta = np.arctan2(dy, dx) % np.pi
    return INSET * (1.0 + 0.7 * theta / np.pi) * np.sqrt(dx * dx + dy * dy) / area2


@dataclass(frozen=True)
class Coverage:
    """Which baked triangle owns each texel: the UV-space half of rasterising, which depends on
    the atlas and the world's triangle numbering only, not on where the instances stand (a
    rebake of moved nodes reuses it from the bake state, ``incremental.py``).

    key: (N,) uint64 texel keys, sorted (``Texels.key``). triangle: (N,) int64 owning world
    triangle. triangle_texels: (T,) int64 texels each world triangle's footprint touches.
    """

    key: np.ndarray
    triangle: np.ndarray
    triangle_texels: np.ndarray

    def __post_init__(self) -> None:
        read_only(self)  # a hand-off: later stages read it (frozen.py)


def cover(atlas: Atlas, world: World) -> Coverage:
    """The owner of every texel that a baked triangle touches (conservative coverage, the
    deepest triangle at the texel centre, ties to the lower index; see the module notes)."""
    return _cover(atlas, world, _baked_triangles(atlas, world))


def cover_and_owners(atlas: Atlas, world: World) -> tuple[Coverage, "Owners"]:
    """``cover`` and its ``owners``, the atlas's baked triangles gathered once for both (a
    pass over every triangle's UVs: 7 ms for 98,732)."""
    baked = _baked_triangles(atlas, world)
    coverage = _cover(atlas, world, baked)
    return coverage, owners_of(atlas, world, owning_triangles(world, coverage),
                               _uv_of(world, baked))


def _cover(atlas: Atlas, world: World,
           baked: tuple[np.ndarray, np.ndarray, np.ndarray]) -> Coverage:
    """``cover`` from the atlas's ``_baked_triangles``."""
    corners, pages, tris = baked
    page_texels = max(atlas.page_count, 1) * atlas.width * atlas.height
    best_depth = np.full(page_texels, -np.inf)
    best_owner = np.full(page_texels, -1, np.int32)  # index into corners/tris (4 bytes a page texel)
    counts = np.zeros(len(corners), np.int64)
    _cover_kernel(np.ascontiguousarray(corners), *_edge_terms(corners), pages, atlas.width,
                  atlas.height, best_depth, best_owner, counts)
    triangle_texels = np.zeros(len(world.triangles), np.int64)
    triangle_texels[tris] = counts  # a world triangle is baked once, in one instance
    key = np.flatnonzero(best_owner >= 0)
    return Coverage(key=key.astype(np.uint64), triangle=tris[best_owner[key]],
                    triangle_texels=triangle_texels)


@dataclass(frozen=True)
class Owners:
    """What the texels of one ``Coverage`` take from their owning triangles, computed once for a
    bake that makes its texels part by part (``texels_of(..., rows)``).

    uv: (T, 3, 2) texel-space UV corners of every world triangle (zeros for those not baked).
    normal: (T, 3) unit front-face normal, size: (T,) world length of one texel side, axes:
    (T, 2, 3) texel axes — of every world triangle that owns texels (zeros for the others; see
    ``Texels``).
    """

    uv: np.ndarray
    normal: np.ndarray
    size: np.ndarray
    axes: np.ndarray

    def __post_init__(self) -> None:
        read_only(self)  # a hand-off: later stages read it (frozen.py)


def owners(atlas: Atlas, world: World, coverage: Coverage) -> Owners:
    """The per-triangle terms of the triangles that own texels in ``coverage``."""
    return owners_of(atlas, world, owning_triangles(world, coverage))


def owning_triangles(world: World, coverage: Coverage) -> np.ndarray:
    """(T,) bool: which world triangles own a texel of ``coverage``."""
    return np.bincount(coverage.triangle, minlength=len(world.triangles)) > 0


def owners_of(atlas: Atlas, world: World, owns: np.ndarray,
              uv: np.ndarray | None = None) -> Owners:
    """The per-triangle terms of the world triangles where ``owns`` (T,) bool (those that own
    texels: ``owning_triangles``); a cluster's node makes them from the mask alone. ``uv``: the
    atlas's ``owners_uv`` when the caller has gathered it already."""
    triangles = len(world.triangles)
    uv = owners_uv(atlas, world) if uv is None else uv
    owning = np.flatnonzero(owns)
    normal, size, axes = np.zeros((triangles, 3)), np.zeros(triangles), np.zeros((triangles, 2, 3))
    normal[owning], size[owning], axes[owning] = _triangle_terms(world, owning, uv[owning])
    return Owners(uv=uv, normal=normal, size=size, axes=axes)


def texels_of(atlas: Atlas, world: World, coverage: Coverage, rows: slice = slice(None),
              owned: Owners | None = None) -> Texels:
    """The texels ``rows`` of ``coverage`` with their sample points on ``world`` as it stands
    now: each texel centre's barycentrics in its owner's UV triangle (clamped into it), mapped
    to world. ``owned``: ``owners(atlas, world, coverage)``, computed here when not given. A
    texel's values do not depend on which other texels are made with it, so blocks of
    ``_POINTS_AT_ONCE`` are made on every core."""
    owned = owners(atlas, world, coverage) if owned is None else owned
    tri = coverage.triangle[rows]
    key = coverage.key[rows]
    position, normal, terminator = (np.empty((len(tri), 3)) for _ in range(3))

    def work(block: slice) -> None:
        bary = _texel_barycentrics(key[block], tri[block], owned.uv, atlas.width, atlas.height)
        position[block], normal[block], terminator[block] = _texel_points(
            world.positions, world.normals, world.smooth, world.triangles, tri[block], bary,
            owned.normal)

    run_chunks(work, [slice(start, start + _POINTS_AT_ONCE)
                      for start in range(0, len(tri), _POINTS_AT_ONCE)])
    return Texels(key=key, position=position, normal=normal, triangle=tri,
                  triangle_instance=world.tri_instance, triangle_normal=owned.normal,
                  triangle_size=owned.size, triangle_texels=coverage.triangle_texels,
                  triangle_axes=owned.axes,
                  terminator_push=terminator if terminator.any() else np.zeros((0, 3)),
                  page_width=atlas.width, page_height=atlas.height)


_POINTS_AT_ONCE = 1 << 16  # texels per block of ``texels_of``


@jit
def _texel_points(positions: np.ndarray, normals: np.ndarray, smooth: np.ndarray,
                  triangles: np.ndarray, tri: np.ndarray, bary: np.ndarray,
                  geometric: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per texel, from its owning triangle ``tri`` (k,) and barycentrics ``bary`` (k, 3): the
    world sample point (k, 3), the unit shading normal (k, 3) (the front-face normal
    ``geometric`` where the corners are not all smooth or the normals cancel) and the
    terminator push (k, 3), in one compiled pass over the texels.

    Terminator push (Hanika 2021): project the point onto the tangent plane of each corner
    (through the vertex, normal to its shading normal), keep only projections that lie *above*
    the point (a convex neighbourhood), and blend the displacements with the barycentrics:
    ``Σ_i b_i · max(0, (v_i − p)·n_i) · n_i``. Zero at the corners, on flat surfaces (every
    n_i the face normal) and on concave ones; about the sag of the facet below the smooth
    surface in between (a few mm on a 12-ring sphere of 0.5 m). Corners without smooth
    normals, or whose normal faces away from the front face, do not push.
    """
    k = len(tri)
    position = np.empty((k, 3))
    normal = np.empty((k, 3))
    terminator = np.zeros((k, 3))
    for i in range(k):
        t = tri[i]
        v0, v1, v2 = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        b0, b1, b2 = bary[i, 0], bary[i, 1], bary[i, 2]
        for c in range(3):
            position[i, c] = b0 * positions[v0, c] + b1 * positions[v1, c] + b2 * positions[v2, c]
        sx = b0 * normals[v0, 0] + b1 * normals[v1, 0] + b2 * normals[v2, 0]
        sy = b0 * normals[v0, 1] + b1 * normals[v1, 1] + b2 * normals[v2, 1]
        sz = b0 * normals[v0, 2] + b1 * normals[v1, 2] + b2 * normals[v2, 2]
        length = np.sqrt(sx * sx + sy * sy + sz * sz)
        if smooth[v0] and smooth[v1] and smooth[v2] and length > 1e-12:
            normal[i, 0], normal[i, 1], normal[i, 2] = sx / length, sy / length, sz / length
        else:
            normal[i, 0], normal[i, 1], normal[i, 2] = geometric[t, 0], geometric[t, 1], geometric[t, 2]
        for corner, weight in ((v0, b0), (v1, b1), (v2, b2)):
            n0, n1, n2 = normals[corner, 0], normals[corner, 1], normals[corner, 2]
            facing = n0 * geometric[t, 0] + n1 * geometric[t, 1] + n2 * geometric[t, 2]
            if not smooth[corner] or facing <= 0:
                continue
            height = ((positions[corner, 0] - position[i, 0]) * n0
                      + (positions[corner, 1] - position[i, 1]) * n1
                      + (positions[corner, 2] - position[i, 2]) * n2)
            if height > 0:
                terminator[i, 0] += weight * height * n0
                terminator[i, 1] += weight * height * n1
                terminator[i, 2] += weight * height * n2
    return position, normal, terminator


def _texel_axes(world: World, tri: np.ndarray, uv_corners: np.ndarray) -> np.ndarray:
    """(k, 2, 3): the world step of one texel in x and in y on each owning triangle's plane.

    Solves [P1 − P0, P2 − P0] = J · [uv1 − uv0, uv2 − uv0] for the (3, 2) Jacobian J (UV in
    texel units); zeros where the triangle has no UV area."""
    axes = np.empty((len(tri), 2, 3))
    _axes_kernel(world.positions, world.triangles, tri,
                 np.ascontiguousarray(uv_corners, np.float64), axes)
    return axes


@jit
def _axes_kernel(positions: np.ndarray, triangles: np.ndarray, tri: np.ndarray,
                 uv: np.ndarray, axes: np.ndarray) -> None:
    """``_texel_axes`` into ``axes`` (k, 2, 3), a triangle at a time: J = E · U⁻¹, E the world
    edges (3, 2), U the UV edges (2, 2) (numpy's arithmetic of the vectorised form)."""
    for i in range(len(tri)):
        u00, u10 = uv[i, 1, 0] - uv[i, 0, 0], uv[i, 1, 1] - uv[i, 0, 1]  # column 0: uv1 − uv0
        u01, u11 = uv[i, 2, 0] - uv[i, 0, 0], uv[i, 2, 1] - uv[i, 0, 1]  # column 1: uv2 − uv0
        det = u00 * u11 - u01 * u10
        if not abs(det) > 1e-12:
            axes[i] = 0.0
            continue
        inverse = ((u11 / det, -u01 / det), (-u10 / det, u00 / det))
        a, b, c = triangles[tri[i], 0], triangles[tri[i], 1], triangles[tri[i], 2]
        for d in range(3):
            e0, e1 = positions[b, d] - positions[a, d], positions[c, d] - positions[a, d]
            for j in range(2):
                axes[i, j, d] = e0 * inverse[0][j] + e1 * inverse[1][j]


def _triangle_terms(world: World, tri: np.ndarray, uv_corners: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per triangle ``tri`` (k,) with texel-space UV corners (k, 3, 2): unit front-face normal
    (k, 3), world length of one texel side (k,) (0 without UV area) and texel axes (k, 2, 3)."""
    geometric = world.geometric_normals(tri)
    world_area = world.areas(tri)
    uv_edges = uv_corners[:, 1:] - uv_corners[:, :1]
    uv_area = 0.5 * np.abs(uv_edges[:, 0, 0] * uv_edges[:, 1, 1] - uv_edges[:, 0, 1] * uv_edges[:, 1, 0])
    size = np.sqrt(np.divide(world_area, uv_area, out=np.zeros_like(world_area), where=uv_area > 0))
    return geometric, size, _texel_axes(world, tri, uv_corners)
