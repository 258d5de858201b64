"""The default texel density fills one page when the charts fit in one (``unwrap._fitted``).

The derived density asks for half a page of texels; xatlas's padding around many small charts
can spill them onto a second, nearly empty page. The default then lowers the density until
they fit one page, and keeps several pages only where no density down to half the derived one
packs them into one (padding, which does not shrink, fills the page)."""

from __future__ import annotations

import shutil
from dataclasses import replace

import numpy as np
import pytest

import baker
from assets.many_objects import strewn_props as props
from assets.rebake_scenes import box_room, grid_boxes, moved
from baker.atlas.unwrap import unwrap
from baker.geometry.world import build_world
from baker.gltf.load import load
from baker.pipeline.full import bounds_of_baked
from baker.rebake.state import default_path
from baker.settings import Settings, resolve


def _unwraps(path, page_size: int):
    """The default unwrap of the scene at ``path`` without the fit, with it, and the derived
    settings."""
    scene = load(path)
    world = build_world(scene)
    resolved = resolve(Settings(page_size=page_size), *bounds_of_baked(world, scene))
    return (unwrap(scene, world, resolved), unwrap(scene, world, resolved, fit_one_page=True),
            resolved, scene, world)


CASES = [(count, seed, page) for count in (10, 20, 40) for seed in range(2) for page in (128, 256)]


@pytest.mark.parametrize("count,seed,page", CASES)
def test_the_default_density_packs_one_page_whenever_a_lower_one_does(tmp_path, count, seed, page):
    """Whenever some density down to half the derived one packs the charts into one page, the
    default atlas is one page, at a density no higher than derived; otherwise it is the derived
    density's own atlas, on several pages."""
    path = props(count, seed).save(tmp_path / "props.glb")
    plain, fitted, resolved, scene, world = _unwraps(path, page)
    assert fitted.texel_density <= resolved.texel_density
    if plain.page_count == 1:
        assert fitted.texel_density == resolved.texel_density and fitted.page_count == 1
        return
    lower = [unwrap(scene, world, replace(resolved, texel_density=resolved.texel_density * f))
             for f in (0.9, 0.8, 0.7, 0.6, 0.5)]
    if any(a.page_count == 1 for a in lower):
        assert fitted.page_count == 1 and max(fitted.width, fitted.height) <= page
        best = max(a.texel_density for a in lower if a.page_count == 1)
        assert fitted.texel_density >= 0.9 * best  # not shrunk further than it needs
    else:
        assert fitted.page_count == plain.page_count > 1
        assert fitted.texel_density == resolved.texel_density


def test_the_generated_cases_cover_both_outcomes(tmp_path):
    """The cases above include scenes that spill and then fit, and one that cannot fit."""
    outcomes = set()
    for count, seed, page in ((20, 0, 256), (40, 0, 128)):
        plain, fitted, *_ = _unwraps(props(count, seed).save(tmp_path / f"{count}.glb"), page)
        outcomes.add((plain.page_count > 1, fitted.page_count))
    assert (True, 1) in outcomes
    assert any(spilled and pages > 1 for spilled, pages in outcomes)


def test_a_user_density_keeps_its_pages(tmp_path):
    """A density the user gives is never changed: the spilled atlas stays."""
    path = props(20, 0).save(tmp_path / "props.glb")
    plain, _fitted, resolved, *_ = _unwraps(path, 256)
    assert plain.page_count > 1
    done = baker.bake(path, tmp_path / "out.glb", Settings(
        page_size=256, texel_density=resolved.texel_density, rays=2, shadow_rays=1, threads=1))
    assert done.settings.texel_density == resolved.texel_density
    assert done.report["atlas"]["pages"] == plain.page_count


ROOM = (4.0, 3.0, 4.0)
BOXES = grid_boxes(36, room=ROOM, size=0.3)
SETTINGS = Settings(page_size=128, rays=4, shadow_rays=1, threads=1)


def test_a_fitted_default_bakes_one_page_and_rebakes_like_a_full_bake(tmp_path):
    """Through the pipeline: the room spills at its derived density, bakes to one page by
    default, and a rebake after moving a box gives the full bake's bytes."""
    first = box_room(BOXES, room=ROOM).save(tmp_path / "room.glb")
    plain, *_ = _unwraps(first, SETTINGS.page_size)
    assert plain.page_count > 1
    done = baker.bake(first, tmp_path / "baked.glb", SETTINGS)
    assert done.report["atlas"]["pages"] == 1
    assert done.settings.texel_density < plain.texel_density
    edited = box_room(moved(BOXES, "box3", at=(1.1, -1.2)), room=ROOM).save(tmp_path / "b.glb")
    shutil.copy(default_path(tmp_path / "baked.glb"), default_path(tmp_path / "again.glb"))
    again = baker.bake(edited, tmp_path / "again.glb", SETTINGS, incremental="always")
    baker.bake(edited, tmp_path / "full.glb", SETTINGS)
    assert again.rebake["incremental"] is True, again.rebake.get("full_bake_reason")
    assert (tmp_path / "again.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()


def test_a_derived_density_too_small_for_a_texel_still_gives_every_chart_one(tmp_path):
    """A stray vertex 10⁹ m away makes the derived density so small that the floor is far
    under a texel (once a division by zero, found by tests/test_fuzz.py): the bake finishes,
    each chart in a texel of its own, and the floor's texel is lit."""
    from assets.gltf_builder import GltfBuilder, quad

    b = GltfBuilder()
    positions, triangles, normals, uv0 = quad(1.0, 1.0)
    b.node("floor", b.mesh("floor", positions, triangles, normals=normals, uv0=uv0,
                           material=b.material("floor")))
    stray = positions.copy()
    stray[0, 2] = 8.6e9
    b.node("stray", b.mesh("stray", stray, triangles, normals=normals, uv0=uv0,
                           material=b.material("stray")))
    path = b.save(tmp_path / "stray.glb")
    done = baker.bake(path, tmp_path / "out.glb", Settings(page_size=32, padding=1, rays=2))
    assert done.pages == 1 and done.texels >= 2 and (tmp_path / "out.glb").is_file()
    assert done.settings.texel_density < 1e-6  # the floor: a millionth of a texel a side
    scene = load(path)
    world = build_world(scene)
    atlas = unwrap(scene, world, done.settings)
    floor = atlas.instances[0].uv * [atlas.width, atlas.height]
    assert len(np.unique(np.floor(floor), axis=0)) == 1  # its four corners in one texel
