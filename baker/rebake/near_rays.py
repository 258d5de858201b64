"""Which of a texel's rays may pass near the changed geometry's bounding spheres, found without
casting them and mostly without drawing them: the validity probes' fixed directions
(``fixed_may_meet``) and the obscurance rays' own deterministic directions
(``drawn_near_rays``: for a texel whose spheres subtend narrow cones, only the samples whose
cells of the Sobol net lie in them, ``sobol_cells``). The kernels run per texel in numba; a ray
they keep is then cast against the changed geometry (``reach``)."""

from __future__ import annotations

import numpy as np

from baker.jit import inline, jit
from baker.rays.dimensions import OBSCURANCE
from baker.rays.sampling import (
    concentric_hemisphere,
    fill_cosine,
    fill_points,
    net_word,
    point,
    texel_scrambles,
)
from baker.rays.trace import RayCaster, ray_lift
from baker.rebake.sobol_cells import cap_boxes, net_solve, sobol_cell_sample


@inline
def _sphere_locals(starts, t1, t2, normals, i, centres, local, distance_sq):
    """Each sphere centre (b, 3) seen from texel i's ray origin ``starts[i]`` in its frame
    (``t1[i]``, ``t2[i]``, ``normals[i]``; (k, 3) each), into ``local`` (b, 3), and its squared
    distance into ``distance_sq`` (b,): once per texel, so a ray's test costs a dot product,
    not a transform. Scalars only: an array made per texel (a row's view, a difference) cost
    more than the arithmetic."""
    for b in range(len(centres)):
        cx = centres[b, 0] - starts[i, 0]
        cy = centres[b, 1] - starts[i, 1]
        cz = centres[b, 2] - starts[i, 2]
        local[b, 0] = cx * t1[i, 0] + cy * t1[i, 1] + cz * t1[i, 2]
        local[b, 1] = cx * t2[i, 0] + cy * t2[i, 1] + cz * t2[i, 2]
        local[b, 2] = cx * normals[i, 0] + cy * normals[i, 1] + cz * normals[i, 2]
        distance_sq[b] = cx * cx + cy * cy + cz * cz


@inline
def _near_flags(x, y, z, start, stop, local, distance_sq, radii, length, flags):
    """Set ``flags[r]`` for the rays r = ``start`` … ``stop − 1`` from the origin along the
    local directions x, y, z: whether it passes within ``radii[b]`` of some sphere
    ``local[b]`` (``_sphere_locals``) before ``length``; return whether any does. Spheres
    outside (those out of reach skipped, ``_sphere_reachable``), rays inside, without
    branches: the loop over the rays vectorises."""
    for r in range(start, stop):
        flags[r] = False
    for b in range(len(radii)):
        if not _sphere_reachable(local, distance_sq, radii, length, b):
            continue
        cx, cy, cz, radius = local[b, 0], local[b, 1], local[b, 2], radii[b]
        low, high, room = -radius, length + radius, radius * radius - distance_sq[b]
        for r in range(start, stop):
            along = x[r] * cx + y[r] * cy + z[r] * cz
            flags[r] |= (along >= low) & (along <= high) & (-along * along <= room)
    near = False
    for r in range(start, stop):
        near |= flags[r]
    return near


@inline
def _sphere_reachable(local, distance_sq, radii, length, b):
    """Whether a ray of the hemisphere (local z ≥ 0) no longer than ``length`` can pass near
    sphere b (``_sphere_locals``): it is not wholly below the plane nor out of reach."""
    return local[b, 2] >= -radii[b] and distance_sq[b] <= (length + radii[b]) ** 2


@inline
def _reachable(local, distance_sq, radii, length):
    """Whether some sphere is reachable (``_sphere_reachable``). Spares drawing and testing
    the rays of texels that face away from the change."""
    for b in range(len(radii)):
        if _sphere_reachable(local, distance_sq, radii, length, b):
            return True
    return False


@jit
def fixed_may_meet(x: np.ndarray, y: np.ndarray, z: np.ndarray, starts: np.ndarray,
                   t1: np.ndarray, t2: np.ndarray, normals: np.ndarray, centres: np.ndarray,
                   radii: np.ndarray, length: float) -> np.ndarray:
    """(k,) bool: whether some ray of texel i may pass near the spheres (``_near_flags``), when
    every texel casts the same local directions x, y, z (m,) (the validity probes) in its
    frame t1, t2, normals (k, 3) each, from ``starts`` (k, 3) (``ray_starts``)."""
    k = len(starts)
    out = np.zeros(k, np.bool_)
    local = np.empty((len(centres), 3))
    distance_sq = np.empty(len(centres))
    flags = np.empty(len(x), np.bool_)
    for i in range(k):
        _sphere_locals(starts, t1, t2, normals, i, centres, local, distance_sq)
        out[i] = (_reachable(local, distance_sq, radii, length)
                  and _near_flags(x, y, z, 0, len(x), local, distance_sq, radii, length, flags))
    return out


# Rays whose directions ``drawn_near_rays`` draws at once: they stay in the cache (a whole
# chunk's fresh arrays would cost more in page faults than the drawing).
_DRAWN_RAYS = 1 << 12


# A texel's rays are found cell by cell (``_cell_candidates``) when the cells that its
# spheres' cones cross number at most this share of its rays; else all its rays are drawn.
_CELL_SHARE = 0.25


@inline
def _cell_range(low, high, cells):
    """The first and last of ``cells`` equal intervals of [0, 1) that [low, high] meets."""
    return (min(max(int(np.floor(low * cells)), 0), cells - 1),
            min(max(int(np.floor(high * cells)), 0), cells - 1))


@inline
def _box_grid(box, bits):
    """(columns, cells) for the box (u0, u1, v0, v1) of [0, 1)²: the grid of 2^columns ×
    2^(bits − columns) cells (``sampling.sobol_cell_sample``) that it crosses fewest cells of,
    and how many."""
    best, fewest = bits, 1 << 30
    for columns in range(bits + 1):
        low_u, high_u = _cell_range(box[0], box[1], 1 << columns)
        low_v, high_v = _cell_range(box[2], box[3], 1 << (bits - columns))
        count = (high_u - low_u + 1) * (high_v - low_v + 1)
        if count < fewest:
            best, fewest = columns, count
    return best, fewest


@inline
def _cell_candidates(local, distance_sq, radii, length, rays, bits, scrambles, solve, boxes,
                     counts, grids, marks, candidates):
    """The samples of a texel (``sobol`` points, its ``scrambles``) whose directions can lie in
    the cone of some sphere ``local`` (``_sphere_locals``) that rays of ``length`` can reach
    (``_sphere_reachable``), into ``candidates`` (rays,) int64:
    returns how many, or −1 when finding them would cost more than drawing every ray.
    ``boxes`` (b, 8, 4), ``counts`` (b,), ``grids`` (b, 8) and ``marks`` (rays,) uint8 (all 0,
    and left so) are scratch; ``solve`` is ``sampling.net_solve(bits)``. A cone's directions
    come from a few boxes of the unit square (``sampling.cap_boxes``); a box crosses few cells
    of some grid of 2^bits cells (``_box_grid``), and each cell holds one of the texel's first
    2^bits points (``sampling.sobol_cell_sample``): those of samples below ``rays`` are the
    candidates. A texel a few metres from a small object has a ray or two of 64 in its cone,
    and no reason to draw the others."""
    budget = int(_CELL_SHARE * rays)
    for b in range(len(radii)):  # first the boxes, and whether their cells are few enough
        counts[b] = 0
        if not _sphere_reachable(local, distance_sq, radii, length, b):
            continue  # no ray of the texel comes near it
        distance = np.sqrt(distance_sq[b])
        if distance <= 1.5 * radii[b]:
            return -1  # a wide cone, and rays that start near the sphere
        counts[b] = cap_boxes(local[b, 0] / distance, local[b, 1] / distance,
                              local[b, 2] / distance, radii[b] / distance, boxes[b])
        if counts[b] < 0:
            return -1
        for row in range(counts[b]):
            grids[b, row], cells = _box_grid(boxes[b, row], bits)
            budget -= cells
        if budget < 0:
            return -1
    found = 0
    for b in range(len(radii)):
        for row in range(counts[b]):
            columns = grids[b, row]
            low_u, high_u = _cell_range(boxes[b, row, 0], boxes[b, row, 1], 1 << columns)
            low_v, high_v = _cell_range(boxes[b, row, 2], boxes[b, row, 3], 1 << (bits - columns))
            for column in range(low_u, high_u + 1):
                for cell_row in range(low_v, high_v + 1):
                    sample = sobol_cell_sample(columns, column, cell_row, bits, scrambles, solve)
                    if sample < rays and not marks[sample]:
                        marks[sample] = 1
                        candidates[found] = sample
                        found += 1
    for c in range(found):
        marks[candidates[c]] = 0
    return found


@inline
def _mirrored_locals(t1, t2, normals, geometric, i, count, local, distance_sq):
    """After ``_sphere_locals`` filled the first ``count`` spheres of texel i: their mirror
    images in its front face's plane (through the ray origin) into ``local[count:]``, when the
    texel's hemisphere normal ``normals[i]`` tilts from its front-face normal ``geometric[i]``
    (its rays below the face are folded, ``sampling.fold``: a folded ray passes near a sphere
    exactly when its direction as drawn passes near the sphere's mirror image); else spheres
    no ray reaches (below the hemisphere, ``_sphere_reachable``)."""
    gx, gy, gz = geometric[i, 0], geometric[i, 1], geometric[i, 2]
    tilted = normals[i, 0] != gx or normals[i, 1] != gy or normals[i, 2] != gz
    lx = t1[i, 0] * gx + t1[i, 1] * gy + t1[i, 2] * gz  # the face normal in the texel's frame
    ly = t2[i, 0] * gx + t2[i, 1] * gy + t2[i, 2] * gz
    lz = normals[i, 0] * gx + normals[i, 1] * gy + normals[i, 2] * gz
    for b in range(count):
        m = count + b
        distance_sq[m] = distance_sq[b]
        if not tilted:
            local[m, 0], local[m, 1], local[m, 2] = 0.0, 0.0, -np.inf
            continue
        dot = local[b, 0] * lx + local[b, 1] * ly + local[b, 2] * lz
        local[m, 0] = local[b, 0] - 2.0 * dot * lx
        local[m, 1] = local[b, 1] - 2.0 * dot * ly
        local[m, 2] = local[b, 2] - 2.0 * dot * lz


@jit
def drawn_near_rays(technique: int, seed, keys: np.ndarray, rays: int, starts: np.ndarray,
                    t1: np.ndarray, t2: np.ndarray, normals: np.ndarray,
                    geometric: np.ndarray, centres: np.ndarray, radii: np.ndarray,
                    length: float, cells: bool):
    """The obscurance rays of texels keys (k,) — each texel's rays from ``starts[i]`` (k, 3) in
    its frame t1, t2, normals (k, 3) each (``Texels.hemisphere_normal``; ``geometric`` (k, 3)
    its front-face normal, which rays below are folded about) — that may pass near the spheres
    (``_near_flags``, against the spheres and, for a tilted frame, their mirror images:
    ``_mirrored_locals``): (texel (m,) int64 index into keys, sample (m,) int64 its sample
    index, x, y, z (m,) their local directions as drawn, the bits
    ``hemisphere.cosine_directions`` gives; ``hemisphere.world_rays`` folds them). Texels that
    cannot reach a sphere (``_reachable``) draw nothing. With ``sobol`` points (and ``cells``:
    the bake's; False draws every ray, the tests' reference, in the same compiled code), a
    texel whose spheres subtend narrow cones draws only the rays that may lie in them
    (``_cell_candidates``, in each of the texel's two nets: ``sampling.fill_points``); the
    others' directions are drawn (``sampling.fill_points``, ``fill_cosine``) a few texels at a
    time into small buffers, so that no (k·rays,) arrays are made. Either way each drawn ray
    meets the same test."""
    k = len(starts)
    spheres = len(centres)
    local = np.empty((2 * spheres, 3))  # the spheres, then their mirror images
    distance_sq = np.empty(2 * spheres)
    radii = np.concatenate((radii, radii))
    block = max(1, _DRAWN_RAYS // rays)
    todo, todo_keys = np.empty(block, np.int64), np.empty(block, keys.dtype)
    u, v = np.empty(block * rays), np.empty(block * rays)
    x, y, z = np.empty(block * rays), np.empty(block * rays), np.empty(block * rays)
    flags = np.empty(block * rays, np.bool_)
    half = rays // 2  # the texel's two nets: samples 0 … half − 1, half … rays − 1
    sizes = np.array([half, rays - half], np.int64)
    nets_bits = np.zeros(2, np.int64)
    for net in range(2):
        while (1 << nets_bits[net]) < sizes[net]:
            nets_bits[net] += 1
    boxes, counts = np.empty((2 * spheres, 8, 4)), np.empty(2 * spheres, np.int64)
    grids = np.empty((2 * spheres, 8), np.int64)
    marks, candidates = np.zeros(rays, np.uint8), np.empty(rays, np.int64)
    cells = cells and technique == 0 and nets_bits[1] <= 24  # (a point has 24 bits: ``_unit``)
    solves = (net_solve(min(nets_bits[0], 24)), net_solve(min(nets_bits[1], 24)))
    texel = np.empty(k * rays, np.int64)  # room for every ray: only the pages written are
    sample = np.empty(k * rays, np.int64)  # touched, and no test to grow them slows the loops
    near = np.empty((k * rays, 3))
    m = 0
    for first in range(0, k, block):
        count = 0
        for i in range(first, min(first + block, k)):
            _sphere_locals(starts, t1, t2, normals, i, centres, local, distance_sq)
            _mirrored_locals(t1, t2, normals, geometric, i, spheres, local, distance_sq)
            if not _reachable(local, distance_sq, radii, length):
                continue
            found = 0 if cells else -1
            for net in range(2 if cells else 0):  # each net's candidates, then their points
                if sizes[net] == 0:
                    continue
                start = 0 if net == 0 else half
                scrambles = texel_scrambles(seed, keys[i], net_word(OBSCURANCE, start))
                got = _cell_candidates(local, distance_sq, radii, length, sizes[net],
                                       nets_bits[net], scrambles, solves[net], boxes, counts,
                                       grids, marks, candidates[found:])
                if got < 0:
                    found = -1
                    break
                for c in range(found, found + got):
                    pu, pv = point(0, candidates[c], sizes[net], scrambles)
                    x[c], y[c], z[c] = concentric_hemisphere(pu, pv)
                    candidates[c] += start
                found += got
            if found < 0:  # drawn with the block's other texels, below
                todo[count], todo_keys[count] = i, keys[i]
                count += 1
                continue
            if not _near_flags(x, y, z, 0, found, local, distance_sq, radii, length, flags):
                continue
            for r in range(found):
                if flags[r]:
                    texel[m], sample[m] = i, candidates[r]
                    near[m, 0], near[m, 1], near[m, 2] = x[r], y[r], z[r]
                    m += 1
        drawn = count * rays
        fill_points(technique, seed, todo_keys[:count], 0, rays, np.uint64(OBSCURANCE), u[:drawn],
                    v[:drawn])
        fill_cosine(u[:drawn], v[:drawn], x[:drawn], y[:drawn], z[:drawn])
        for c in range(count):
            i = todo[c]
            _sphere_locals(starts, t1, t2, normals, i, centres, local, distance_sq)
            _mirrored_locals(t1, t2, normals, geometric, i, spheres, local, distance_sq)
            base = c * rays
            if not _near_flags(x, y, z, base, base + rays, local, distance_sq, radii, length,
                               flags):
                continue
            for r in range(base, base + rays):
                if flags[r]:
                    texel[m], sample[m] = i, r - base
                    near[m, 0], near[m, 1], near[m, 2] = x[r], y[r], z[r]
                    m += 1
    return (texel[:m], sample[:m], near[:m, 0].copy(), near[:m, 1].copy(),
            near[:m, 2].copy())


def lifted_origins(center: np.ndarray, position, normal, size) -> np.ndarray:
    """The rays' origins (k, 3) in the tracer's frame (world − ``center``): the sample points
    ``position`` (k, 3) lifted along ``normal`` (k, 3) by ``trace.ray_lift``."""
    return position - center + ray_lift(position, size, center)[:, None] * normal


def ray_starts(tracer: RayCaster, position, normal, size, length: float):
    """The rays' origins (k, 3) in the tracer's frame (``lifted_origins``) and the changed
    geometry's bounding-sphere radii padded for the float32 rays Embree gets (``_near_flags``)."""
    starts = lifted_origins(tracer.center, position, normal, size)
    slack = 1e-5 * (length + np.abs(starts).max(initial=0.0))  # float32 directions, origins
    return starts, tracer.sphere_radii + slack
