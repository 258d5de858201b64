"""The tracer's declared interface (``rays.trace``): what every caster answers, and its records."""

import numpy as np
import pytest

from assets.make_scenes import cornell_box
from baker.geometry.world import build_world
from baker.rays import native
from baker.rays.trace import LocalHits, Occluder, RayCaster, Tracer
from baker.rebake.changed import Changed
from baker.rebake.shadows import Recorder
from tests.bakehelp import loaded


def test_every_tracer_implements_the_declared_interface(tmp_path):
    """``Tracer`` and the rebake's stand-ins answer what ``rays.trace`` declares, the hits of
    ``cast_local`` are the typed ``LocalHits`` whichever casts them, and a stand-in over some
    triangles finds the same hits as the whole tracer where those are the triangles hit."""
    world = build_world(loaded(cornell_box(), tmp_path))
    tracer = Tracer(world)
    changed = Changed([world.positions[world.triangles]], world.center)  # every triangle
    assert isinstance(tracer, RayCaster) and isinstance(changed, RayCaster)
    assert isinstance(Recorder(changed), Occluder)
    assert not isinstance(Recorder(changed), RayCaster)
    rng = np.random.default_rng(0)
    directions = rng.normal(size=(64, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    origins = np.zeros((64, 3), np.float32)  # the room's centre, in the recentred frame
    whole = tracer.cast_local(origins, directions.astype(np.float32), np.full(64, 1e3, np.float32))
    part = changed.cast_local(origins, directions.astype(np.float32), np.full(64, 1e3, np.float32))
    for hits in (whole, part):
        assert isinstance(hits, LocalHits) and hits.triangle.dtype == np.int32
        assert len(hits.distance) == len(hits.u) == len(hits.v) == 64
    assert (whole.triangle >= 0).mean() > 0.5  # a room open on one side
    assert np.array_equal(whole.triangle, part.triangle)
    assert np.array_equal(whole.distance, part.distance)


def _random_rays(world, count: int, seed: int):
    """Float32 rays in a tracer's recentred frame from random points of ``world``'s bounds,
    random unit directions and lengths from 0 to the bounds' diagonal."""
    rng = np.random.default_rng(seed)
    low, high = world.positions.min(axis=0), world.positions.max(axis=0)
    origins = (rng.uniform(low, high, (count, 3)) - world.center).astype(np.float32)
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    lengths = rng.uniform(0.0, np.linalg.norm(high - low), count).astype(np.float32)
    return origins, directions.astype(np.float32), lengths


def test_the_occlusion_query_blocks_the_rays_that_have_a_nearest_hit(tmp_path):
    """``blocked_local`` (Embree's occlusion query: no distance) blocks exactly the rays that
    ``cast_local`` finds a hit for, within each ray's own length; through an alpha-blended
    sheet too, whose coin is the ray's own (``pass_alpha``)."""
    from assets.material_scenes import alpha_cut_quad

    for builder in (cornell_box(), alpha_cut_quad(blend=True)):
        world = build_world(loaded(builder, tmp_path))
        tracer = Tracer(world)
        origins, directions, lengths = _random_rays(world, 20000, 3)
        blocked = tracer.blocked_local(origins, directions, lengths)
        hits = tracer.cast_local(origins, directions, lengths.copy())
        assert blocked.dtype == np.int32 and set(np.unique(blocked)) <= {-1, 0}
        assert np.array_equal(blocked >= 0, hits.triangle >= 0)
        assert 0.1 < (blocked >= 0).mean() < 0.9  # both answers are asked about


def _copies(count: int, flipped: bool = False):
    """A 2 m floor quad placed ``count`` times at one place (each its own node), one more
    turned upside down (its winding, so its front face, reversed) when ``flipped``, and a
    0.4 m box standing on it."""
    from assets.gltf_builder import GltfBuilder, box, quad, quat_axis_angle

    b = GltfBuilder()
    grey = b.material("grey", (0.5, 0.5, 0.5))
    floor = b.shape_mesh("floor", quad(2.0, 2.0), material=grey)
    nodes = [b.node(f"floor{k}", floor) for k in range(count)]
    if flipped:
        nodes.append(b.node("under", floor, rotation=quat_axis_angle((1, 0, 0), 180)))
    nodes.append(b.node("box", b.shape_mesh("box", box((0.4, 0.4, 0.4)), material=grey),
                        translation=(0.0, 0.2, 0.0)))
    b.roots(nodes)
    return b


def test_exact_copies_of_a_surface_are_traced_once(tmp_path):
    """A floor placed 40 times at one place: the world keeps every copy, the tracer the first
    alone (a ray would test them all: 100,000 such copies made a 4 kB file bake for hours), and
    a ray meets it where one floor is met, at the same distance and point; a copy turned upside
    down (the other face) and the box are no copies. (The rays are cast without the upside-down
    copy: which of two faces in one plane a ray meets first is Embree's tie, and it differs
    between CPUs: AVX2 met the first floor, AVX-512 the upside-down one for some rays.)"""
    from baker.geometry.repeats import repeated_triangles

    alone = build_world(loaded(_copies(1), tmp_path))
    floor = len(alone.triangles) - (alone.tri_start[2] - alone.tri_start[1])  # one floor's
    repeated = build_world(loaded(_copies(40, flipped=True), tmp_path)).repeated
    assert repeated.sum() == 39 * floor
    assert not repeated[:floor].any() and repeated[floor:40 * floor].all()
    assert not repeated[40 * floor:].any()  # the flipped floor and the box
    world = build_world(loaded(_copies(40), tmp_path))
    assert world.repeated.sum() == 39 * floor
    rng = np.random.default_rng(1)
    origins = np.column_stack([rng.uniform(-0.9, 0.9, 500), np.full(500, 1.0),
                               rng.uniform(-0.9, 0.9, 500)])
    down = np.tile([0.0, -1.0, 0.0], (500, 1))
    hits, once = Tracer(world).cast(origins, down, 5.0), Tracer(alone).cast(origins, down, 5.0)
    on_floor = once.triangle < floor
    assert on_floor.mean() > 0.5 and (hits.triangle[on_floor] < floor).all()
    for key in ("triangle", "distance", "u", "v"):
        assert np.array_equal(getattr(hits, key)[on_floor], getattr(once, key)[on_floor]), key
    # the same corners in another cyclic order are a copy; reversed, or one corner moved, not
    positions = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1], [0, 0, np.nextafter(1.0, 2.0)]])
    triangles = np.array([[0, 1, 2], [1, 2, 0], [2, 0, 1], [0, 2, 1], [1, 3, 0]])
    assert repeated_triangles(positions, triangles, np.ones(5, bool)).tolist() == [
        False, True, True, False, False]
    assert not repeated_triangles(positions, triangles, np.array([0, 1, 0, 1, 1], bool))[1]


def test_a_copy_the_alpha_test_may_pass_is_traced(tmp_path):
    """A surface alpha-cut in places is never left out as a copy (a ray through its cut-out
    part would miss the surface it copies)."""
    from assets.material_scenes import alpha_cut_quad

    b = alpha_cut_quad()
    b.node("leaf again", b._nodes[b.info["leaf"]].mesh)  # the leaf's mesh, placed as it is
    world = build_world(loaded(b, tmp_path))
    assert world.alpha is not None and not world.repeated.any()
    from baker.geometry.repeats import repeated_triangles  # the copy is there, exact

    assert repeated_triangles(world.positions, world.triangles, ~world.degenerate).any()


@pytest.mark.parametrize("engine", ["native", "embreex"])
def test_a_ray_through_cut_outs_goes_on_along_its_own_line(tmp_path, monkeypatch, engine):
    """A ray let through the cut-out halves of two crossed alpha-tested leaves meets what the
    same straight ray meets with the leaves taken away: the same triangle at the same float32
    distance, whatever the leaves' planes (``pass_alpha`` searches on from past the hit along
    the ray, not from a point stepped off the leaf). The rebake's searches test the straight
    ray; a path that bent at a cut-out met a recoloured prop its line misses (room 525 of
    ``tests/test_rebake_property.py``'s crowded rooms). Through embreex (no tnear: the ray
    starts again past the hit) the same line to float32 rounding."""
    if engine == "embreex":
        monkeypatch.setattr(native, "_NATIVE", None)
    from assets.gltf_builder import box, quat_axis_angle
    from assets.material_scenes import alpha_cut_quad

    b = alpha_cut_quad(height=0.5)
    leaf = b._nodes[b.info["leaf"]].mesh
    b.node("leaf crossed", leaf, translation=(0.1, 0.45, -0.05),
           rotation=quat_axis_angle((0.3, 1.0, 0.2), 70))  # tilted, its open half across
    grey = b.material("prop", (0.5, 0.5, 0.5))
    rng = np.random.default_rng(5)
    for k in range(40):  # props under the leaves, their edges everywhere
        b.node(f"prop{k}", b.shape_mesh(f"prop{k}", box(tuple(rng.uniform(0.05, 0.3, 3))),
                                        material=grey),
               translation=(rng.uniform(-1.8, 1.8), rng.uniform(0.0, 0.3),
                            rng.uniform(-1.8, 1.8)),
               rotation=quat_axis_angle(tuple(rng.normal(size=3)), rng.uniform(0, 180)))
    world = build_world(loaded(b, tmp_path))
    assert world.alpha is not None
    leaves = world.alpha.mode > 0  # (T,) the alpha-tested triangles
    n = 40000
    origins = np.column_stack([rng.uniform(-1.5, 1.5, n), np.full(n, 1.6),
                               rng.uniform(-1.5, 1.5, n)])
    directions = np.column_stack([rng.normal(0, 0.6, n), -np.ones(n), rng.normal(0, 0.6, n)])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    local = (origins - world.center).astype(np.float32)
    directions = directions.astype(np.float32)
    lengths = np.full(n, 4.0, np.float32)
    tracer = Tracer(world)
    through = tracer.cast_local(local, directions, lengths.copy())
    blocked = tracer.blocked_local(local, directions, lengths.copy())  # shadow rays, the same
    assert np.array_equal(blocked >= 0, through.triangle >= 0)
    bare = Tracer(world, hidden=leaves).cast_local(local, directions, lengths.copy())
    past = (through.triangle < 0) | ~leaves[np.maximum(through.triangle, 0)]
    assert 0.2 < past.mean() < 0.9  # both stopped by a leaf and let through are asked about
    if engine == "native":
        assert np.array_equal(through.triangle[past], bare.triangle[past])
        assert np.array_equal(through.distance[past], bare.distance[past])
    else:
        assert (through.triangle[past] == bare.triangle[past]).mean() > 0.999
        same = past & (through.triangle == bare.triangle)
        np.testing.assert_allclose(through.distance[same], bare.distance[same], rtol=1e-5)
    stopped = ~past
    assert (through.distance[stopped] <= bare.distance[stopped]).all()
