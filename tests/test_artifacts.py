"""Issue 8 with light: no leak from a light outside a closed room, anti-aliased shadow edges
(supersampling), no faceted shadow terminator on low-poly smooth surfaces."""

import importlib

import numpy as np
import pytest

from assets.artifact_scenes import lit_leak_room, low_poly_sphere, shadow_edge
from baker.errors import SettingsError
from baker.geometry.world import build_world
from baker.settings import Settings
from baker.atlas.supersample import sub_offsets
from baker.rays.trace import Tracer
from baker.atlas.validity import _raise
from tests.bakehelp import computed, loaded, rasterised
from tests.test_validity import DENSITY, _floor_lookup_texels, _grid, _interior_points, _node_of

LIGHTS = {  # a bright light outside the room: steep sun, grazing suns at the thin and thick
    # walls, a point light low beside the thin +x wall
    "sun": ("directional", (0.0, 10.0, 0.0), (0.6, -1.0, 0.3)),
    "grazing_thin_wall": ("directional", (9.0, 1.0, 0.0), (-1.0, -0.15, 0.05)),
    "grazing_thick_wall": ("directional", (-9.0, 1.0, 0.0), (1.0, -0.12, -0.07)),
    "point_by_wall": ("point", (1.9, 0.3, 0.0), (0.0, -1.0, 0.0)),
}


def _light_leaks(done, builder):
    """(leaking, corner, read, lit_outside) for the final lightmap (direct + I_A·W) of the lit
    leak room baked with step ρ and d_max longer than the room's diagonal, where every texel
    inside the room gets exactly 0 unless light leaks in:

    leaking: floor texels whose square overlaps the room's open floor by 10 % or more and are
    above 0; corner: those overlapping it by less (a square past an outer corner, mostly in the
    open); read: floor texels above 0 that bilinear lookups anywhere on the room's open floor
    read; lit_outside: fraction of the floor texels wholly outside the room that the light
    reaches directly (that there is light to leak)."""
    info = builder.info
    h = info["half"]
    floor = _node_of(done) == info["nodes"]["floor"]
    centre = rasterised(done.atlas, done.world).position[floor]  # before any was moved
    r = done.texels.size(floor)[:, None] / 2
    overlap = (np.clip(h - (np.abs(centre[:, [0, 2]]) - r), 0.0, 2 * r) / (2 * r)).prod(axis=1)
    t = done.texels
    light = done.lightmaps.light[t.pixels(floor)].max(axis=1)
    lit = light > 1e-6
    texels, weights = _floor_lookup_texels(done, info["nodes"]["floor"],
                                           _interior_points(info, 0.25 / DENSITY))
    read = np.unique(texels[weights > 0], axis=0)
    read_lit = done.lightmaps.light[read[:, 0], read[:, 1], read[:, 2]].max(axis=1) > 1e-6
    direct = done.direct.punctual[floor, 0]
    assert (overlap >= 0.1).sum() > 800
    return (int((lit & (overlap >= 0.1)).sum()), int((lit & (overlap > 0) & (overlap < 0.1)).sum()),
            int(read_lit.sum()), float((direct[overlap == 0] > 0).mean()))


SETTINGS = dict(texel_density=DENSITY, rays=16, rho="step", d_max=6.0)


@pytest.mark.parametrize("light,supersample", [("sun", 1), ("grazing_thin_wall", 1),
                                               ("grazing_thick_wall", 16), ("point_by_wall", 16)])
def test_no_floor_texel_is_lit_through_the_walls(light, supersample, tmp_path):
    kind, position, direction = LIGHTS[light]
    room = lit_leak_room(kind, position, direction, half=1.57)
    done = computed(room, tmp_path, supersample=supersample, **SETTINGS)
    leaking, corner, read, lit_outside = _light_leaks(done, room)
    assert leaking == 0, (light, leaking)
    # As in test_validity: a square past each outer corner by the thick wall, 4 % over the room.
    assert corner <= 2 and read <= 2, (corner, read)
    assert lit_outside > 0.35  # there is light outside to leak
    # Under the box and under the thick wall: dark in the final lightmap.
    info = room.info
    margin = 2.5 / DENSITY
    bx, _, bz = info["box_centre"]
    sx, _, sz = info["box_size"]
    h, t = info["half"], info["wall_thickness"]
    for points in (_grid(bx - sx / 2 + margin, bx + sx / 2 - margin, bz - sz / 2 + margin,
                         bz + sz / 2 - margin, 0.5 / DENSITY),
                   _grid(-h - t + margin, -h - margin, -h + margin, h - margin, 0.5 / DENSITY)):
        texels, _ = _floor_lookup_texels(done, info["nodes"]["floor"], points)
        assert len(points) > 30
        assert done.lightmaps.light[texels[:, 0], texels[:, 1], texels[:, 2]].max() == 0.0


def test_unchecked_sub_positions_would_leak(tmp_path, monkeypatch):
    """Without the segment check (sub-positions straight from the texel's square) floor texels
    moved inside the room get sub-positions beyond the thin walls: light leaks in."""
    direct = importlib.import_module("baker.light.direct")
    monkeypatch.setattr(direct, "sub_positions", lambda tracer, texels, rows, count, seed: (
        texels.position[rows][:, None] + sub_offsets(texels, rows, count, seed)))
    room = lit_leak_room(*LIGHTS["grazing_thin_wall"], half=1.57)
    leaking, _, read, _ = _light_leaks(computed(room, tmp_path, supersample=16, **SETTINGS), room)
    assert leaking > 20 and read > 20, (leaking, read)


def _coverage(done, lit, n=32):
    """(N,) exact fraction of each texel's square (on its triangle's plane) that ``lit`` says
    is lit, from an n × n grid of points: the box-filtered reference."""
    t = done.texels
    d = (np.arange(n) + 0.5) / n - 0.5
    square = np.stack(np.meshgrid(d, d), axis=-1).reshape(-1, 2)
    points = t.position[:, None] + np.einsum("sj,kjc->ksc", square, t.axes())
    return lit(points.reshape(-1, 3)).reshape(len(t), -1).mean(axis=1)


def test_supersampling_antialiases_a_hard_shadow_edge(tmp_path):
    """A hard shadow edge at 17° across 0.1 m floor texels: one sample point gives each texel 0
    or 1; 16 sub-positions give the crossed texels their lit fraction (error against the exact
    box-filtered coverage: RMSE 0.24 → 0.04, measured), and leave the others exact."""
    scene = shadow_edge()
    results = {}
    for n in (1, 4, 16):
        done = computed(scene, tmp_path, only_nodes={scene.info["floor"]}, texel_density=10.0,
                        rays=4, supersample=n)
        t = done.texels
        inner = (np.abs(t.position[:, [0, 2]]) < 0.85).all(axis=1)  # whole squares on the floor
        value, reference = done.direct.punctual[inner, 0], _coverage(done, scene.info["lit"])[inner]
        edge = (reference > 0) & (reference < 1)
        assert edge.sum() > 15 and (~edge).sum() > 200
        assert np.abs(value - reference)[~edge].max() < 1e-12  # off the edge: exact
        results[n] = (np.sqrt(np.mean((value - reference)[edge] ** 2)),
                      int(((value > 0) & (value < 1)).sum()))
    assert results[1][1] == 0 and results[1][0] > 0.2  # stair steps: only 0 or 1
    assert results[4][1] > 8 and results[4][0] < 0.6 * results[1][0]
    assert results[16][1] > 15 and results[16][0] < 0.25 * results[1][0], results


def test_supersampling_does_not_depend_on_threads_or_chunks(tmp_path):
    scene = shadow_edge()
    one = computed(scene, tmp_path, texel_density=10.0, rays=4, supersample=8, threads=1,
                   chunk_texels=4096)
    other = computed(scene, tmp_path, texel_density=10.0, rays=4, supersample=8, threads=2,
                     chunk_texels=37)
    np.testing.assert_array_equal(one.direct.punctual, other.direct.punctual)
    np.testing.assert_array_equal(one.lightmaps.light, other.lightmaps.light)
    assert one.direct.rays == 8 * len(one.texels)  # a hard light: one ray per sub-position


def test_supersample_setting_is_checked():
    for bad in (0, 65, 2.5):
        with pytest.raises(SettingsError, match="supersample"):
            Settings(supersample=bad).check()


def _ring(done, latitude, width=1.0):
    """The direct light (N,) of the sphere's texels within ``width``° of ``latitude``, in order
    of longitude, their longitudes (radians), and their shading normals' cosine to the light."""
    t = done.texels
    direction = t.position / np.linalg.norm(t.position, axis=1, keepdims=True)
    lat = np.degrees(np.arcsin(direction[:, 1]))
    lon = np.arctan2(direction[:, 2], direction[:, 0])
    ring = np.flatnonzero(np.abs(lat - latitude) < width)
    ring = ring[np.argsort(lon[ring])]
    towards = np.asarray(done.scene.lights[0].direction) * -1.0
    return done.direct.punctual[ring, 0], lon[ring], np.maximum(t.normal[ring] @ towards, 0.0)


@pytest.mark.parametrize("elevation", [0.0, 30.0])
def test_no_faceted_shadow_terminator_on_a_low_poly_sphere(elevation, tmp_path, monkeypatch):
    """A smooth-shaded 8 × 12-facet sphere under a hard sun: along rings across the terminator
    the light follows the smooth shading (cosine of the interpolated normal) and steps between
    neighbouring texels no more than that cosine does; without the terminator push it drops to
    0 at facet edges (errors and extra steps of 0.21 at 0°, 0.12 at 30° elevation, measured)."""
    scene = low_poly_sphere(elevation=elevation)
    rasterise_module = importlib.import_module("baker.atlas.rasterise")

    def worst(done):
        errors, steps = [], []
        for latitude in (-56.0, -33.75, -11.25, 11.25, 33.75, 56.0):
            value, lon, smooth = _ring(done, latitude)
            assert len(value) > 60
            errors.append(np.abs(value - smooth).max())
            steps.append((np.abs(np.diff(value)) - np.abs(np.diff(smooth))).max())
        return max(errors), max(steps)

    error, step = worst(computed(scene, tmp_path, texel_density=60.0, rays=4))
    assert error < 0.01 and step < 0.01, (error, step)
    points = rasterise_module._texel_points

    def unpushed(*args):
        position, normal, push = points(*args)
        return position, normal, np.zeros_like(push)

    monkeypatch.setattr(rasterise_module, "_texel_points", unpushed)
    faceted_error, faceted_step = worst(computed(scene, tmp_path, texel_density=60.0, rays=4))
    assert faceted_error > 0.1 and faceted_step > 0.1, (faceted_error, faceted_step)


def test_terminator_push_stops_at_geometry(tmp_path):
    """The push (validity._raise) moves a point only when nothing lies along it."""
    scene = loaded(low_poly_sphere(), tmp_path)
    world = build_world(scene)
    tracer = Tracer(world)
    position = np.array([[3.0, 0.0, 0.0], [0.0, 0.0, 0.0]])  # outside the sphere; its centre
    push = np.array([[0.05, 0.0, 0.0], [0.6, 0.0, 0.0]])  # the second crosses the sphere
    normal = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    moved = _raise(tracer, position, normal, np.array([0.01, 0.01]), push)
    np.testing.assert_array_equal(moved[0], position[0] + push[0])
    np.testing.assert_array_equal(moved[1], position[1])


def test_report_counts_validity_states_and_cli_sets_supersample(tmp_path):
    import baker
    from baker.cli.bake import settings_from
    from baker.cli.main import build_parser

    room = lit_leak_room(*LIGHTS["sun"], half=1.57)
    result = baker.bake(room.save(tmp_path / "room.glb"), tmp_path / "out.glb",
                        Settings(texel_density=DENSITY, rays=4, d_max=6.0, supersample=4))
    counts = result.report["validity"]
    assert set(counts) == {"valid", "moved", "invalid", "enclosed"}
    assert sum(counts.values()) == result.texels
    assert counts["moved"] > 20 and counts["enclosed"] > 10, counts  # walls, box, thick wall
    assert result.report["settings"]["supersample"] == 4
    args = build_parser().parse_args(["bake", "in.glb", "-o", "out.glb", "--supersample", "8"])
    assert settings_from(args).supersample == 8
