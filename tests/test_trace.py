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
