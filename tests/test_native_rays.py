"""baker's own Embree calls (``rays.native``) against embreex's, on the same scene and rays."""

import sys
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from assets.make_scenes import cornell_box
from baker.geometry.world import build_world
from baker.gltf.load import load
from baker.rays import native
from baker.rays.trace import Tracer, embree_mesh, embreex_scene


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    return build_world(load(cornell_box().save(tmp_path_factory.mktemp("c") / "c.glb")))


def _rays(world, n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """n rays in the tracer's frame, float32: origins anywhere in the room's bounds (some
    inside its boxes), random directions, lengths up to the room's size."""
    rng = np.random.default_rng(seed)
    low, high = world.positions.min(axis=0), world.positions.max(axis=0)
    origins = low + rng.random((n, 3)) * (high - low) - world.center
    directions = rng.normal(size=(n, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    lengths = rng.random(n) * np.linalg.norm(high - low)
    return origins.astype(np.float32), directions.astype(np.float32), lengths.astype(np.float32)


def test_the_install_built_the_native_calls():
    """On Linux the install compiles them (setup.py) and bakes use them."""
    assert sys.platform.startswith("linux")
    assert native.engine().startswith("Embree 4 through baker's native calls"), native.engine()


@pytest.mark.parametrize("seed", [1, 2])
def test_native_hits_are_embreexs_to_the_bit(world, seed):
    """200,000 rays, some from inside the room's boxes, some ending short of any surface: the
    same triangles, distances and barycentrics as embreex's, bit for bit (the same library,
    the same scene flags: a bake does not depend on which of the two cast its rays)."""
    origins, directions, lengths = _rays(world, 200_000, seed)
    mesh = embree_mesh(world)
    ours = native.scene(*mesh).run(origins, directions, lengths.copy(), output=1)
    theirs = embreex_scene(*mesh).run(origins, directions, dists=lengths.copy(), output=1)
    hit = theirs["primID"] >= 0
    assert 0.5 < hit.mean() < 1
    for key in ("primID", "tfar"):
        assert ours[key].tobytes() == theirs[key].tobytes(), key
    for key in ("u", "v"):  # embreex leaves a miss's from the ray before
        assert ours[key][hit].tobytes() == theirs[key][hit].tobytes(), key


def test_a_surface_through_a_rays_origin_is_met_as_embreex_meets_it():
    """A ray that starts on a triangle's plane, inside it, meets it at distance 0, as
    embreex's robust scene does (the validity probes of texels on another surface's plane, as
    where a wall meets a floor, rely on it); one that starts a hair off the plane, going away
    from it, does not."""
    vertices = np.array([[-1, 0, -1], [1, 0, -1], [0, 0, 1], [np.nan] * 3], np.float32)
    scene = native.scene(vertices, np.array([[0, 1, 2]], np.int32))
    origins = np.array([[0, 0, 0], [0, 1e-6, 0], [0, 0, 0]], np.float32)
    directions = np.array([[0, 1, 0], [0, 1, 0], [0, -1, 0]], np.float32)
    hits = scene.run(origins, directions, np.full(3, 5, np.float32), output=1)
    assert list(hits["primID"]) == [0, -1, 0] and list(hits["tfar"]) == [0, 5, 0]
    many = np.arange(48) % 3  # occlusion in whole packets (of 8 or 16), and alone
    for rows in (many, many[:2]):
        blocked = scene.run(origins[rows], directions[rows], np.full(len(rows), 5, np.float32),
                            query="OCCLUDED")
        np.testing.assert_array_equal(blocked, np.where(rows == 1, -1, 0))


def _surface_rays(world, n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """n rays in the tracer's frame, float32, from random points of the room's triangles (a
    third of them on the plane exactly, as float32 rounds it; the rest lifted up to 10⁻³ off
    it, either way) in random directions: the rays a bake casts, and the grazing ones."""
    rng = np.random.default_rng(seed)
    tri = rng.integers(len(world.triangles), size=n)
    corners = world.positions[world.triangles[tri]]
    r1, r2 = np.sqrt(rng.random(n)), rng.random(n)
    bary = np.column_stack([1 - r1, r1 * (1 - r2), r1 * r2])
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    lift = np.where(rng.random(n) < 1 / 3, 0.0, rng.uniform(-1e-3, 1e-3, n))
    origins = np.einsum("nk,nkc->nc", bary, corners) + lift[:, None] * normal - world.center
    directions = rng.normal(size=(n, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    lengths = rng.random(n) * np.ptp(world.positions, axis=0).max()
    return origins.astype(np.float32), directions.astype(np.float32), lengths.astype(np.float32)


@pytest.mark.parametrize("make", [_rays, _surface_rays])
def test_native_occlusion_is_embreexs_whatever_rays_share_a_packet(world, make):
    """200,000 rays, cast in packets of 16 (AVX-512) or 8 (AVX2): the same answer for each
    as embreex's single rays give, and the same again when every packet holds other rays (the
    rays cast from the 7th on, the first 7 alone): a ray's answer does not depend on the rays
    beside it, so neither does a bake's on its chunks."""
    origins, directions, lengths = make(world, 200_000, 6)
    mesh = embree_mesh(world)
    ours = native.scene(*mesh).run(origins, directions, lengths, query="OCCLUDED")
    theirs = embreex_scene(*mesh).run(origins, directions, dists=lengths.copy(),
                                      query="OCCLUDED")
    assert 0.2 < (theirs == 0).mean() < 0.95
    np.testing.assert_array_equal(ours, theirs)
    scene = native.scene(*mesh)
    shifted = [scene.run(origins[rows], directions[rows], lengths[rows], query="OCCLUDED")
               for rows in (slice(0, 7), slice(7, None))]
    np.testing.assert_array_equal(np.concatenate(shifted), theirs)


def _same_hits(tracer, origins, directions, lengths) -> int:
    """How many of the rays meet something; asserts ``cast_local_sparse`` finds the hits
    ``cast_local`` finds, bit for bit (lengths overwritten alike)."""
    kept, sparse_lengths = lengths.copy(), lengths.copy()
    whole = tracer.cast_local(origins, directions, kept)
    sparse = tracer.cast_local_sparse(origins, directions, sparse_lengths)
    for key in ("triangle", "distance", "u", "v"):
        assert getattr(sparse, key).tobytes() == getattr(whole, key).tobytes(), key
    assert sparse_lengths.tobytes() == kept.tobytes()
    return int((whole.triangle >= 0).sum())


def test_sparse_casting_finds_the_nearest_hits_bit_for_bit(world):
    """Short rays from the room's surfaces (as the validity's probes; those into the surface
    meet it) and rays across the room: occlusion first, then the nearest hits of the rays that
    met something, gives ``cast_local``'s hits."""
    origins, directions, lengths = _surface_rays(world, 100_000, 7)
    short = (lengths * 1e-2).astype(np.float32)
    near = _same_hits(Tracer(world), origins, directions, short)
    far = _same_hits(Tracer(world), origins, directions, lengths)
    assert 1000 < near < far < 99_000


def test_sparse_casting_lets_rays_through_alpha_cut_holes(tmp_path):
    """Through an alpha-cut quad's hole a ray meets nothing, sparse or not; on its opaque half
    it meets the quad."""
    from assets.material_scenes import alpha_cut_quad
    from bakehelp import loaded

    tracer = Tracer(build_world(loaded(alpha_cut_quad(), tmp_path)))
    xs = np.linspace(-0.95, 0.95, 400)
    xs = xs[np.abs(xs) > 0.05]  # the hole is where x < 0
    origins = np.stack([xs, np.full(len(xs), 0.01), np.zeros(len(xs))], axis=1) - tracer.center
    directions = np.tile(np.float32([0, 1, 0]), (len(xs), 1))
    met = _same_hits(tracer, origins.astype(np.float32), directions,
                     np.full(len(xs), 10, np.float32))
    assert met == (xs > 0).sum()


def test_occlusion_is_whether_the_nearest_hit_lies_within_the_ray(world):
    """OCCLUDED says 0 exactly where INTERSECT finds a hit, −1 elsewhere (the same rays and
    scene, lengths left as they were)."""
    origins, directions, lengths = _rays(world, 100_000, 2)
    scene = native.scene(*embree_mesh(world))
    kept = lengths.copy()
    blocked = scene.run(origins, directions, lengths, query="OCCLUDED")
    np.testing.assert_array_equal(lengths, kept)
    hits = scene.run(origins, directions, lengths.copy(), output=1)["primID"]
    np.testing.assert_array_equal(blocked == 0, hits >= 0)
    assert set(np.unique(blocked)) == {0, -1}


def test_native_hits_do_not_depend_on_the_scene_build_chunks_or_threads(world):
    """Two scenes of the same mesh, and one call against 97 chunks cast from 2 threads, give
    the same bytes."""
    origins, directions, lengths = _rays(world, 100_000, 3)
    mesh = embree_mesh(world)
    one = native.scene(*mesh).run(origins, directions, lengths.copy(), output=1)
    other = native.scene(*mesh)
    parts = np.array_split(np.arange(len(lengths)), 97)

    def cast(rows):
        return other.run(origins[rows], directions[rows], lengths[rows], output=1)

    with ThreadPoolExecutor(2) as pool:
        chunks = list(pool.map(cast, parts))
    for key in ("primID", "tfar", "u", "v"):
        assert np.concatenate([c[key] for c in chunks]).tobytes() == one[key].tobytes()


def test_hidden_triangles_are_never_hit(world):
    """A Tracer with the room's first half of triangles hidden meets only the others, and
    meets those where the whole room's tracer does when it hits them first."""
    hidden = np.zeros(len(world.triangles), bool)
    hidden[: len(hidden) // 2] = True
    origins, directions, lengths = _rays(world, 100_000, 4)
    part = Tracer(world, hidden=hidden).cast_local(origins, directions, lengths.copy())
    whole = Tracer(world).cast_local(origins, directions, lengths.copy())
    assert (part.triangle >= 0).any() and not hidden[part.triangle[part.triangle >= 0]].any()
    first = (whole.triangle >= 0) & ~hidden[np.maximum(whole.triangle, 0)]
    assert first.any()
    np.testing.assert_array_equal(part.triangle[first], whole.triangle[first])


def test_without_the_native_calls_the_tracer_uses_embreex(world, monkeypatch):
    """Where the library did not build, ``native.scene`` is None and the Tracer casts through
    embreex: the same hits as embreex's own scene, bit for bit."""
    monkeypatch.setattr(native, "_NATIVE", None)
    assert native.scene(*embree_mesh(world)) is None and native.engine().startswith("embreex")
    origins, directions, lengths = _rays(world, 50_000, 5)
    got = Tracer(world).cast_local(origins, directions, lengths.copy())
    theirs = embreex_scene(*embree_mesh(world)).run(origins, directions, dists=lengths.copy(),
                                                    output=1)
    np.testing.assert_array_equal(got.triangle, theirs["primID"])
    np.testing.assert_array_equal(got.distance, theirs["tfar"])
