"""Peak memory: the stages after the rays work on the lightmap pages in place or in blocks, so a
large page costs little more than itself, and blocks never change a value."""

import tracemalloc

import numpy as np
import pytest

from assets.make_scenes import cornell_box
from baker.image import compose as compose_module
from baker.image import encode as encode_module
from baker.light import hemisphere as integrate_module
from baker.image.encode import encode
from baker.image.postprocess import postprocess
from baker.image.seams import find_seams
from tests.bakehelp import composed, computed


@pytest.fixture(scope="module")
def done(tmp_path_factory):
    return computed(cornell_box(), tmp_path_factory.mktemp("memory"), page_size=384, rays=4,
                    occlusion="also")  # with the pages of W


def _composed(done):
    return composed(done, done.direct)


def _extra_bytes(run) -> int:
    """Bytes ``run()`` allocates at its peak beyond what is allocated when it starts."""
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        run()
        return tracemalloc.get_traced_memory()[1] - before
    finally:
        tracemalloc.stop()


def test_post_processing_and_encoding_hold_no_whole_page_temporaries(done, monkeypatch):
    """Beyond their inputs and outputs they need a fraction of a page (blocks of 16 rows here:
    the encoder's temporaries follow its block, not the page)."""
    monkeypatch.setattr(encode_module, "_ROWS", 16)
    page = done.lightmaps.light.nbytes  # the light pages, float64 RGB
    masks = done.validity.page_masks(done.texels, done.lightmaps.covered.shape)
    seams = find_seams(done.atlas, done.world)
    composed = _composed(done)
    assert _extra_bytes(lambda: postprocess(composed, done.settings.padding, *masks,
                                            seams=seams)) < 0.5 * page  # (was 4.4 pages)
    # the 8-bit pages, PIL's copy and the percentile's copy of the texels remain (whole-page
    # float temporaries were 4 pages and more)
    assert _extra_bytes(lambda: encode(done.lightmaps, "srgb", True)) < page
    # compose: its two pages and a block's temporaries, no (N, 3) W or D (was 4.3 pages)
    monkeypatch.setattr(compose_module, "_TEXELS_AT_ONCE", 4096)
    assert _extra_bytes(lambda: _composed(done)) < 2.5 * page


def test_blocks_give_the_same_values_as_one_block(done, monkeypatch):
    """Compose, the integrator's means and the encoder work in blocks; tiny blocks change
    nothing (the bytes of a bake do not depend on the block sizes)."""
    whole = _composed(done)
    pages = encode(done.lightmaps, "srgb", True)
    means = integrate_module.terms_of_sums(np.arange(7 * 1000.0).reshape(1000, 7) % 17,
                                           np.arange(1000) % 40)
    monkeypatch.setattr(compose_module, "_TEXELS_AT_ONCE", 7)
    monkeypatch.setattr(encode_module, "_ROWS", 5)
    monkeypatch.setattr(integrate_module, "_MEAN_ROWS", 3)
    blocked = _composed(done)
    assert np.array_equal(blocked.light, whole.light)
    assert np.array_equal(blocked.visibility, whole.visibility)
    assert [(p.png, p.occlusion_png, p.intensity) for p in encode(done.lightmaps, "srgb", True)] \
        == [(p.png, p.occlusion_png, p.intensity) for p in pages]
    again = integrate_module.terms_of_sums(np.arange(7 * 1000.0).reshape(1000, 7) % 17,
                                           np.arange(1000) % 40)
    for name in ("w_hit", "escaped", "hit_sq", "half_split"):
        assert np.array_equal(getattr(again, name), getattr(means, name)), name


def test_a_bake_in_parts_grows_with_its_pages_not_its_texels(tmp_path, monkeypatch):
    """Made a part at a time, with the parts' rows on disk (parts.py), a bake's peak grows by
    its pages (two float pages, the coverage's page-sized arrays, masks), not by what it holds
    per texel: all at once, the same growth was 9 light pages."""
    from baker.pipeline import parts as parts
    from baker.pipeline.full import compute
    from baker.settings import Settings
    from tests.bakehelp import loaded

    scene = loaded(cornell_box(), tmp_path)
    monkeypatch.setattr(parts, "PART_TEXELS", 4096)
    peaks, pages = [], []
    for size in (256, 640):
        held = []
        peaks.append(_extra_bytes(lambda: held.append(
            compute(scene, Settings(page_size=size, rays=4), spill_folder=tmp_path))))
        pages.append(held[0].lightmaps.light.nbytes)
        assert held[0].per_texel.spill is not None and len(held[0].texels) > 4 * 4096
        held[0].per_texel.close()
    assert peaks[1] - peaks[0] < 3.5 * (pages[1] - pages[0])


def test_pages_of_w_are_kept_only_for_the_occlusion_texture(done, tmp_path):
    """Without ``occlusion`` the bake holds no pages of W (a float page pair less), and its
    light is the same."""
    from baker.pipeline.full import compute
    from baker.settings import Settings

    plain = compute(done.scene, Settings(page_size=384, rays=4))
    assert plain.lightmaps.visibility.shape[0] == 0 and done.lightmaps.visibility.shape[0] == 1
    assert np.array_equal(plain.lightmaps.light, done.lightmaps.light)
    assert [p.png for p in encode(plain.lightmaps, "srgb", False)] == \
        [p.png for p in encode(done.lightmaps, "srgb", True)]
