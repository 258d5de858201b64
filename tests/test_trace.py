"""The tracer's declared interface (``rays.trace``): what every caster answers, and its records."""

import numpy as np

from assets.make_scenes import cornell_box
from baker.geometry.world import build_world
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
