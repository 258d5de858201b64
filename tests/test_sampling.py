"""The sampler: a pure function of (seed, key, sample, dimension), well stratified."""

import numpy as np

from baker.rays.sampling import (cosine_hemisphere, fill_points, hash_u32, owen_scramble, sample_2d,
                                 tangent_frames, texel_scrambles)
from baker.rebake.sobol_cells import cap_boxes, net_solve, sobol_cell_sample


def test_same_arguments_same_numbers_however_split():
    keys = np.arange(50, dtype=np.uint64)
    whole = sample_2d(7, keys[:, None], np.arange(64)[None, :], 0)
    parts = np.concatenate([sample_2d(7, keys[:20, None], np.arange(64)[None, :], 0),
                            sample_2d(7, keys[20:, None], np.arange(64)[None, :], 0)])
    late = sample_2d(7, keys[:, None], np.arange(32, 64)[None, :], 0)
    assert np.array_equal(whole, parts)
    assert np.array_equal(whole[:, 32:], late)


def test_seed_key_and_dimension_all_change_the_points():
    base = sample_2d(0, np.uint64(5), np.arange(16), 0)
    for other in (sample_2d(1, np.uint64(5), np.arange(16), 0),
                  sample_2d(0, np.uint64(6), np.arange(16), 0),
                  sample_2d(0, np.uint64(5), np.arange(16), 1)):
        assert not np.allclose(base, other)


def test_every_power_of_two_prefix_is_a_stratified_net():
    """The first 4^k samples of a texel put one point in each cell of a 2^k × 2^k grid."""
    for key in range(20):
        points = sample_2d(3, np.uint64(key), np.arange(64), 0)
        cells = np.floor(points * 8).astype(int)
        assert len({(x, y) for x, y in cells}) == 64
        assert points.min() > 0 and points.max() < 1


def test_stratified_lays_its_grid_once_in_each_half_of_every_batch():
    """Each half of a batch of 2·m samples puts one point in each of the m cells (8 × 4 for
    m = 32), independently of the other half, so the halves' difference measures the error."""
    keys = np.arange(5, dtype=np.uint64)
    for first, count in ((0, 64), (64, 64), (128, 128)):
        u, v = np.empty(5 * count), np.empty(5 * count)
        fill_points(1, np.uint64(3), keys, first, count, np.uint64(0), u, v)
        rows, columns = (4, 8) if count == 64 else (8, 8)
        cell = (np.floor(v * rows) * columns + np.floor(u * columns)).reshape(5, 2, count // 2)
        assert np.all(np.sort(cell, axis=2) == np.arange(count // 2))
        assert not np.allclose(u.reshape(5, 2, -1)[:, 0], u.reshape(5, 2, -1)[:, 1])
    odd = sample_2d(3, np.uint64(1), np.arange(9), 0, "stratified")  # 4 cells twice, 1 free
    cells = np.floor(odd[:8] * 2).astype(int) @ [1, 2]
    assert sorted(cells[:4]) == sorted(cells[4:]) == [0, 1, 2, 3]


def test_owen_scramble_is_a_permutation_of_aligned_blocks():
    """Owen scrambling maps the 2^m values sharing their top bits to another such block."""
    values = (np.arange(256, dtype=np.uint32) << np.uint32(24))
    scrambled = [int(owen_scramble(v, np.uint32(12345))) >> 24 for v in values]
    assert sorted(scrambled) == list(range(256))


def test_hash_spreads_neighbouring_keys():
    h = hash_u32(0, np.arange(100000, dtype=np.uint64))
    bits = ((h[:, None] >> np.arange(32, dtype=np.uint32)) & 1).mean(axis=0)
    assert np.all(np.abs(bits - 0.5) < 0.01)
    assert len(np.unique(h)) > 99990


def test_cosine_hemisphere_has_the_cosine_moments():
    """E[cosθ] = 2/3 and E[cos²θ] = 1/2 for pdf cosθ/π; directions are unit and upward."""
    d = cosine_hemisphere(sample_2d(0, np.arange(500, dtype=np.uint64)[:, None],
                                    np.arange(256)[None, :], 0))
    assert np.allclose(np.linalg.norm(d, axis=-1), 1.0)
    assert d[..., 2].min() >= 0
    assert abs(d[..., 2].mean() - 2 / 3) < 1e-3
    assert abs((d[..., 2] ** 2).mean() - 0.5) < 1e-3
    assert abs(d[..., 0].mean()) < 1e-3 and abs(d[..., 1].mean()) < 1e-3


def test_tangent_frames_are_orthonormal_even_at_the_poles():
    rng = np.random.default_rng(1)
    n = np.vstack([rng.normal(size=(1000, 3)), [[0, 0, 1], [0, 0, -1], [1, 0, 0]]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    t1, t2 = tangent_frames(n)
    for a, b in ((t1, n), (t2, n), (t1, t2)):
        assert np.abs((a * b).sum(axis=1)).max() < 1e-12
    assert np.allclose(np.linalg.norm(t1, axis=1), 1) and np.allclose(np.linalg.norm(t2, axis=1), 1)


def test_the_sample_in_each_cell_is_found_without_drawing_the_others():
    """Among a texel's first 2^m Sobol points one lies in each cell of every grid of 2^a
    columns × 2^(m − a) rows (strips of x or y at a = m or 0); ``sobol_cell_sample`` names it,
    undoing the scrambles and Sobol's matrix, for every m and a (at m = 17, for 4,096 cells
    drawn at random of each grid: a Python call a cell)."""
    rng = np.random.default_rng(4)
    for trial in range(45):  # bits 0 to 10, and 17 (the loops of each bit range differ)
        seed, key, bits = int(rng.integers(2**32)), int(rng.integers(2**40)), (
            trial % 11 if trial < 44 else 17)
        points = sample_2d(seed, np.uint64(key), np.arange(1 << bits), 0)
        scrambles = texel_scrambles(np.uint64(seed), np.uint64(key), np.uint64(0))
        solve = net_solve(bits)
        for columns in ([0, bits, bits // 2] if bits > 10 else range(bits + 1)):
            rows = bits - columns
            cell = (np.floor(points[:, 0] * (1 << columns)).astype(int) * (1 << rows)
                    + np.floor(points[:, 1] * (1 << rows)).astype(int))
            assert sorted(cell) == list(range(1 << bits))
            asked = (np.arange(1 << bits) if bits <= 10
                     else np.sort(rng.choice(1 << bits, 4096, replace=False)))
            found = [sobol_cell_sample(columns, k >> rows, k & ((1 << rows) - 1), bits,
                                       scrambles, solve) for k in asked.tolist()]
            assert np.array_equal(cell[found], asked), (trial, columns)


def test_cap_boxes_hold_every_point_whose_direction_is_in_the_cap():
    """``cap_boxes`` bounds the points of the unit square that the cosine map sends within a
    cap of directions: no point of 2,000 random ones per cap, over 2,000 caps (axes anywhere,
    some below the horizon; narrow and wide), falls outside them; and narrow caps far from the
    pole keep to a small part of the square."""
    rng = np.random.default_rng(5)
    boxes = np.empty((8, 4))
    inside = outside = 0
    narrow = []
    for trial in range(2000):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        sin_half = float(rng.uniform(0, 0.1 if trial % 2 else 0.8))
        count = cap_boxes(axis[0], axis[1], axis[2], sin_half, boxes)
        if count < 0:
            assert axis[2] >= np.cos(np.arcsin(sin_half)) - 1e-6  # the cap holds the pole
            continue
        points = rng.random((2000, 2))
        seen = cosine_hemisphere(points) @ axis >= np.sqrt(1 - sin_half ** 2)
        b = boxes[:count]
        held = ((points[:, None, 0] >= b[:, 0]) & (points[:, None, 0] <= b[:, 1])
                & (points[:, None, 1] >= b[:, 2]) & (points[:, None, 1] <= b[:, 3])).any(axis=1)
        inside += int(seen.sum())
        outside += int((seen & ~held).sum())
        if sin_half < 0.1 and 0.1 < axis[2] < 0.9:
            narrow.append(np.sum((b[:, 1] - b[:, 0]) * (b[:, 3] - b[:, 2])))
    assert inside > 10000 and outside == 0
    assert np.median(narrow) < 0.05
