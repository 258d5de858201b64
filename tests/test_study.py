"""The convergence study: error falls with rays as each technique should, and the bake's own
error estimate tracks the measured error."""

import numpy as np
import pytest

from assets.make_scenes import cornell_box, parallel_planes
from baker.study import plot, run_study
from tests.bakehelp import computed

RAYS = (16, 32, 64, 128, 256)


@pytest.fixture(scope="module")
def planes(tmp_path_factory):
    """The probe under a parallel plane (smooth integrand: the closed-form case)."""
    builder = parallel_planes(height=0.3)
    done = computed(builder, tmp_path_factory.mktemp("planes"),
                    only_nodes={builder.info["nodes"]["probe"]}, texel_density=100.0, d_max=1.0, escape="scene")
    return run_study(done, RAYS, reference_rays=4096)


@pytest.fixture(scope="module")
def cornell(tmp_path_factory):
    """The Cornell room: visibility edges everywhere (the hard case)."""
    done = computed(cornell_box(), tmp_path_factory.mktemp("cornell"), page_size=48)
    return run_study(done, RAYS, reference_rays=4096)


def test_random_falls_as_one_over_sqrt_n_and_the_others_faster(planes, cornell):
    for study in (planes, cornell):
        assert -0.6 < study.slope("random") < -0.4
        assert study.slope("sobol") < -0.65
        assert study.slope("stratified") < -0.6
    assert planes.slope("sobol") < cornell.slope("sobol")  # smooth integrands converge faster


def test_the_bakes_error_estimate_tracks_the_measured_error(planes, cornell):
    for study in (planes, cornell):
        for row in study.rows:
            if row.rays >= 64:  # every technique: sobol, stratified, random
                assert 1 / 1.5 < row.estimated_rmse / row.rmse < 1.5, row
    assert {row.technique for row in planes.rows} == {"sobol", "stratified", "random"}


def test_the_table_and_plot_show_every_run(cornell):
    table = cornell.table()
    assert len([line for line in table.splitlines() if line.startswith("sobol ")]) == len(RAYS)
    assert "RMSE ∝ rays^" in table
    png = plot(cornell)
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000


def test_error_maps_show_where_the_lightmap_is_noisy(tmp_path):
    """--error-map writes per-page errors whose RMS is the report's estimate."""
    from PIL import Image

    from assets.make_scenes import cornell_box as room
    from baker.image.errormap import error_pages, texel_errors
    from baker.cli.main import main

    done = computed(room(), tmp_path, page_size=48, rays=32)
    errors = texel_errors(done)
    assert np.isclose(np.sqrt(np.mean(errors ** 2)), done.rmse_estimate())
    assert errors.min() >= 0 and errors.max() > 2 * np.median(errors)  # some texels are noisier
    pages = error_pages(done)
    assert np.isclose(pages.sum(), errors.sum())
    scene = room().save(tmp_path / "room.glb")
    assert main(["bake", str(scene), "-o", str(tmp_path / "out.glb"), "--page-size", "48",
                 "--rays", "8", "--error-map", str(tmp_path / "errors"), "--quiet"]) == 0
    png = Image.open(tmp_path / "errors" / "out_error_0.png")
    assert png.size == (pages.shape[2], pages.shape[1])
    assert (tmp_path / "errors" / "out_error_0.hdr").read_bytes().startswith(b"#?RADIANCE")
