"""Issue 21, faceting: obscurance hemispheres follow the interpolated shading normal, rays below
the front face folded above it (``sampling.fold``), flat surfaces keep their bits."""

import numpy as np

from assets.artifact_scenes import icosphere_on_floor
from assets.gltf_builder import GltfBuilder, icosphere, quad, quat_axis_angle
from assets.make_scenes import WHITE
from baker.atlas.rasterise import Texels, owners_uv
from baker.geometry.surface import LUMINANCE
from tests.bakehelp import computed

def _runs(texels: Texels) -> np.ndarray:
    """(m, 4) rows of texels, four consecutive ones along an atlas row or column whose world
    points lie within 1.5 texel sides of each other (one chart)."""
    page, y, x = texels.pixels()
    grid = np.full((page.max() + 1, y.max() + 4, x.max() + 4), -1)
    grid[page, y, x] = np.arange(len(texels))
    runs = np.concatenate([np.stack([grid[page, y + k * dy, x + k * dx] for k in range(4)], 1)
                           for dy, dx in ((0, 1), (1, 0))])
    runs = runs[(runs >= 0).all(axis=1)]
    gaps = np.linalg.norm(np.diff(texels.position[runs], axis=1), axis=2)
    return runs[(gaps < 1.5 * texels.size(runs[:, 0])[:, None]).all(axis=1)]


def _crossings(done, runs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where each run (m, 4) crosses from one triangle to another: (m,) bool, the first two
    texels on one triangle A and the last two on a neighbour B sharing an edge with A, and
    (m,) e ∈ [1, 2], the crossing's place along the run (texel i at i): where the barycentric
    weight of A's corner off the shared edge, linear along the run, falls to 0."""
    texels, world = done.texels, done.world
    tri = texels.triangle[runs]
    a, b = tri[:, 1], tri[:, 2]
    shared = (world.triangles[a][:, :, None] == world.triangles[b][:, None, :]).any(axis=2)
    across = ((tri[:, 0] == a) & (tri[:, 3] == b) & (a != b) & (shared.sum(axis=1) == 2))
    corners = owners_uv(done.atlas, world)[a]  # (m, 3, 2) texel units
    off = np.argmin(shared, axis=1)[:, None]  # A's corner off the shared edge (where there is one)
    _, y, x = texels.pixels()
    weights = []
    for texel in runs[:, 1], runs[:, 2]:
        p = np.stack([x[texel], y[texel]], axis=1) + 0.5
        e0, e1, q = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0], p - corners[:, 0]
        det = e0[:, 0] * e1[:, 1] - e0[:, 1] * e1[:, 0]
        v = (q[:, 0] * e1[:, 1] - q[:, 1] * e1[:, 0]) / det
        w = (e0[:, 0] * q[:, 1] - e0[:, 1] * q[:, 0]) / det
        weights.append(np.take_along_axis(np.stack([1 - v - w, v, w], axis=1), off, 1)[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        e = 1.0 + weights[0] / (weights[0] - weights[1])
    across &= (e >= 1.0) & (e <= 2.0)
    return across, np.where(across, e, 1.5)


def _jump(values: np.ndarray, e: np.ndarray) -> np.ndarray:
    """(m,) the step at e (m,) of runs' values (m, 4): the line through the last two texels
    less the line through the first two, both at e — 0 for a field that is linear on either
    side, whatever its kink at e (smooth shading's normals are continuous, not smooth)."""
    v0, v1, v2, v3 = values.T
    return (v2 + (e - 2.0) * (v3 - v2)) - (v1 + (e - 1.0) * (v1 - v0))


def facet_step(builder, folder, rays: int = 64, density: float = 40.0) -> tuple[float, float]:
    """(step, noise) of the sphere's lightmap (luminance) in an ``icosphere_on_floor`` scene,
    over the runs (``_runs``) of its lower half, where the floor is in view (above, every ray
    escapes: the lightmap is R_ave there, exactly). Two bakes with seeds 1 and 2: noise is one
    bake's per-texel error, RMS((L₁ − L₂)/√2) over the runs' texels; step is the excess of the
    jumps (``_jump``) across triangle edges (at their crossing, ``_crossings``) over those
    within triangles (at the same places e, so that the lines' curvature remainder is the
    same), sqrt(mean J₁J₂ across − mean J₁J₂ within), J₁ and J₂ each
    bake's: the part of the jump that the smooth field's own variation does not explain (the
    product of two bakes' jumps has no noise in its mean, as a square would)."""
    sphere = builder.info["nodes"]["sphere"]
    bakes = [computed(builder, folder, only_nodes={sphere}, texel_density=density, rays=rays,
                      seed=seed) for seed in (1, 2)]
    texels = bakes[0].texels
    one, two = (done.lightmaps.light[texels.pixels()] @ LUMINANCE for done in bakes)
    runs = _runs(texels)
    runs = runs[(texels.position[runs, 1] < builder.info["centre"][1]).all(axis=1)]
    across, e = _crossings(bakes[0], runs)
    tri = texels.triangle[runs]
    within = (tri == tri[:, :1]).all(axis=1)
    assert across.sum() > 200 and within.sum() > 1000, (across.sum(), within.sum())
    used = np.unique(runs[across | within])
    noise = float(np.sqrt(np.mean((one - two)[used] ** 2) / 2))
    e[within] = np.resize(e[across], within.sum())  # the same places as across the edges
    square = _jump(one[runs], e) * _jump(two[runs], e)  # the seeds' noise is independent
    excess = np.mean(square[across]) - np.mean(square[within])
    return float(np.sqrt(max(excess, 0.0))), noise


def test_no_faceting_on_a_smooth_icosphere(tmp_path, monkeypatch):
    """An 80-face icosphere with vertex normals over a floor, no light, 64 rays (the default):
    with the hemispheres about the shading normals the lightmap's step across the facets'
    edges is below one bake's noise (measured: 0.0000 against 0.0039; 0.0007 against 0.0013 at
    256 rays); about the face normals, as before, it is 6.4× the noise (0.025; 20× at 256
    rays). ``benchmarks/bench_faceting.py`` prints the figures."""
    scene = icosphere_on_floor(gap=0.05)
    step, noise = facet_step(scene, tmp_path)
    assert step <= noise, (step, noise)
    monkeypatch.setattr(Texels, "hemisphere_normal",
                        lambda self, rows=slice(None): self.geometric_normal(rows))
    faceted, noise_before = facet_step(scene, tmp_path)
    assert faceted > 4 * noise_before, (faceted, noise_before)


def test_a_smooth_convex_mesh_alone_sees_no_facet_of_its_own(tmp_path):
    """Rays about a shading normal that tilts 21° from its facet's normal, folded above the
    facet, never meet the convex mesh they start on: every ray escapes, W = R_ave exactly."""
    b = GltfBuilder()
    b.node("sphere", b.shape_mesh("sphere", icosphere(0.5, 1), material=b.material("w", WHITE)))
    done = computed(b, tmp_path, texel_density=30.0, rays=64)
    tilt = np.einsum("ij,ij->i", done.texels.hemisphere_normal(), done.texels.geometric_normal())
    assert tilt.min() < np.cos(np.radians(15))  # the hemispheres do tilt
    np.testing.assert_array_equal(done.terms.escaped, 1.0)
    np.testing.assert_array_equal(done.terms.w_hit, 0.0)


def _panels(normals: bool) -> GltfBuilder:
    """A floor and a panel tilted 37° above it, with or without NORMAL attributes (flat either
    way: the stored normals are the faces')."""
    b = GltfBuilder()
    white = b.material("white", WHITE)
    for name, shape, place in (("floor", quad(3.0, 3.0), {}),
                               ("panel", quad(1.0, 1.0), dict(
                                   translation=(0.2, 0.6, -0.1),
                                   rotation=quat_axis_angle((1.0, 0.3, 0.2), 37.0)))):
        positions, triangles, vertex_normals, uv = shape
        mesh = b.mesh(name, positions, triangles, normals=vertex_normals if normals else None,
                      uv0=uv, material=white)
        b.node(name, mesh, **place)
    return b


def test_flat_surfaces_keep_their_bits(tmp_path):
    """A flat surface's stored normals (float32, turned by the node) differ from its face
    normal by ~1e-7; its hemispheres stay about the face normal: the same terms, bit for bit,
    as without any NORMAL attribute (face normals)."""
    settings = dict(texel_density=12.0, rays=32)
    smooth = computed(_panels(True), tmp_path, **settings)
    flat = computed(_panels(False), tmp_path, **settings)
    shading = smooth.texels.normal
    assert np.any(shading != smooth.texels.geometric_normal())  # float32 normals, turned
    np.testing.assert_array_equal(smooth.texels.hemisphere_normal(),
                                  smooth.texels.geometric_normal())
    for name in ("w_hit", "escaped", "hit_sq"):
        np.testing.assert_array_equal(getattr(smooth.terms, name), getattr(flat.terms, name))
