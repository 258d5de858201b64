"""HDR lightmaps: the embedded 8-bit encoding's error on a page spanning seven decades, the
Radiance .hdr and OpenEXR float exports, and a bake that writes them (docs/output.md)."""

import io
import json
import re

import numpy as np
import OpenEXR
import pytest
from PIL import Image

import baker
from assets.light_scenes import lit_floor
from baker.image.compose import Lightmaps
from baker.image.encode import decode, encode, linear_to_srgb, srgb_to_linear
from baker.image.hdr import exr_bytes, hdr_bytes
from baker.cli.main import main
from tests.bakehelp import computed, saved
from tests.gltf_validator import ERROR, describe, issue_codes, validate


def _hdr_page(shape=(256, 256), low=1e-2, high=1e5, seed=1) -> np.ndarray:
    """(H, W, 3) texels whose brightness is log-uniform in [low, high], tinted up to 2:1."""
    rng = np.random.default_rng(seed)
    grey = 10 ** rng.uniform(np.log10(low), np.log10(high), shape)
    tint = rng.uniform(0.5, 1.0, shape + (3,))
    return grey[..., None] * tint / tint.max(axis=-1, keepdims=True)


def error_bound(values: np.ndarray, intensity: float, encoding: str) -> np.ndarray:
    """The largest |decoded − value| that encoding ``values`` (linear, ≥ 0, any shape) can give
    (docs/output.md's error bound).

    Below ``intensity``: half a code step of the curve at the value, measured exactly on the
    curve (``linear``: intensity/510 everywhere; ``srgb``: smaller in the darks, larger near the
    top). Above it the texel clips: the error is ``value − intensity``.
    """
    x = np.asarray(values, np.float64) / intensity
    inside = np.clip(x, 0.0, 1.0)
    if encoding == "srgb":
        e = linear_to_srgb(inside)
        half = 0.5 / 255.0
        step = np.maximum(srgb_to_linear(e + half) - inside, inside - srgb_to_linear(e - half))
    else:
        step = np.full_like(inside, 0.5 / 255.0)
    return np.where(x > 1.0, x - 1.0, step) * intensity


def _read_png(png: bytes) -> np.ndarray:
    image = Image.open(io.BytesIO(png))
    assert image.mode == "RGB"  # 8 bits a channel: what a browser gives WebGL
    return np.asarray(image)


def _band_error(light, back, intensity, low, high) -> float:
    """Largest relative error of texels (any channel) with value/intensity in (low, high]."""
    x = light / intensity
    band = (x > low) & (x <= high)
    assert band.sum() > 100  # the band is really populated
    return float((np.abs(back - light) / light)[band].max())


# documented in docs/output.md ("Measured round trip"): largest relative error per band of
# value / intensity, linear and srgb encodings
DOCUMENTED = {"linear": {(0.1, 1.0): 0.020, (0.01, 0.1): 0.20},
              "srgb": {(0.1, 1.0): 0.012, (0.01, 0.1): 0.031, (0.001, 0.01): 0.15}}


@pytest.mark.parametrize("encoding", ["linear", "srgb"])
def test_embedded_encoding_round_trip_on_a_page_from_1e_minus_2_to_1e5(encoding):
    light = _hdr_page()
    page = Lightmaps(light=light[None], visibility=np.zeros((1,) + light.shape),
                     covered=np.ones((1,) + light.shape[:2], bool))
    (encoded,) = encode(page, encoding, occlusion=False)
    s = encoded.intensity
    back = decode(_read_png(encoded.png), s, encoding)

    # the scale is the 99.9th percentile: 0.1 % of the texels clip, and only a little
    brightest = light.max(axis=-1)
    assert encoded.peak == brightest.max()
    assert 0.0009 < encoded.clipped < 0.0011
    assert np.isclose(encoded.clipped, np.mean(brightest > s))
    assert 0.98 * encoded.peak < s < encoded.peak
    clipped = light > s
    assert np.allclose(back[clipped], s)  # a clipped channel decodes to the intensity
    assert (np.abs(back - light) / light)[clipped].max() <= 1 - s / encoded.peak < 0.02

    # every texel within the exact bound (half a code of the curve; value − intensity above it)
    assert np.all(np.abs(back - light) <= error_bound(light, s, encoding) * (1 + 1e-9))
    # brights and darks within the documented relative errors
    for (low, high), bound in DOCUMENTED[encoding].items():
        assert _band_error(light, back, s, low, high) <= bound, (low, high)
    # the darkest decade of a seven-decade page cannot survive 8 bits: it decodes to about 0,
    # within the absolute bound (linear: half a code, intensity / 510)
    darks = light < 1e-6 * s
    assert darks.sum() > 1000 and np.all(back[darks] == 0.0)
    if encoding == "linear":
        assert np.abs(back - light)[light <= s].max() <= s / 510 * (1 + 1e-12)


def test_percentile_100_scales_each_page_to_its_peak():
    light = _hdr_page(shape=(64, 64), low=1.0, high=1e3)
    page = Lightmaps(light=light[None], visibility=np.zeros((1,) + light.shape),
                     covered=np.ones((1, 64, 64), bool))
    (peak,) = encode(page, "linear", False, clip_percentile=100.0)
    (robust,) = encode(page, "linear", False)
    assert peak.intensity == peak.peak == light.max() and peak.clipped == 0.0
    assert robust.intensity < peak.intensity and robust.clipped > 0


def test_a_hot_spot_no_longer_crushes_the_page(tmp_path):
    """A point light 5 cm above a floor: its peak is far above the rest of the floor."""
    done = computed(lit_floor("point", position=(0.3, 0.05, 0.0), intensity=100.0), tmp_path,
                    texel_density=32.0, rays=4, page_size=256)
    lit = done.lightmaps.light[0][done.lightmaps.covered[0]].max(axis=-1)
    (robust,) = encode(done.lightmaps, "linear", False)
    (peak,) = encode(done.lightmaps, "linear", False, clip_percentile=100.0)
    assert peak.intensity / robust.intensity > 4  # the peak is a few hot texels
    assert robust.clipped <= 0.001 + 1 / len(lit)
    # the median texel's worst-case error shrinks by the same factor
    median = np.median(lit)
    assert (error_bound(median, peak.intensity, "linear")
            / error_bound(median, robust.intensity, "linear")) > 4


# -- float exports -------------------------------------------------------------------------------


def read_hdr(data: bytes) -> np.ndarray:
    """A Radiance .hdr reader written for the test (flat RGBE scanlines, "-Y H +X W" only):
    decodes mantissa · 2^(exponent − 136), as stb_image does."""
    head, _, rest = data.partition(b"\n\n")
    lines = head.decode("ascii").split("\n")
    assert lines[0] == "#?RADIANCE" and "FORMAT=32-bit_rle_rgbe" in lines
    size, _, pixels = rest.partition(b"\n")
    match = re.fullmatch(r"-Y (\d+) \+X (\d+)", size.decode("ascii"))
    assert match
    height, width = int(match[1]), int(match[2])
    rgbe = np.frombuffer(pixels, np.uint8)
    assert rgbe.size == height * width * 4
    rgbe = rgbe.reshape(height, width, 4).astype(np.int64)
    # a flat scanline must not start like a run-length one (2, 2, width < 32768)
    assert not np.any((rgbe[:, 0, 0] == 2) & (rgbe[:, 0, 1] == 2) & (rgbe[:, 0, 2] < 128))
    value = rgbe[..., :3] * np.ldexp(1.0, rgbe[..., 3] - 136)[..., None]
    return np.where(rgbe[..., 3:] == 0, 0.0, value)


def test_hdr_writer_round_trips_within_rgbe_precision():
    light = np.concatenate([_hdr_page((40, 64), 1e-3, 1e3, seed=2),  # the issue's range
                            _hdr_page((40, 64), 1e-2, 1e5, seed=3)])
    light[0, 0] = 0.0
    light[0, 1] = [1.0, 0.0, 0.0]
    light[0, 2] = 255.9 / 256 * 2.0 ** 10  # a mantissa that rounds up to the next exponent
    back = read_hdr(hdr_bytes(light))
    assert back.shape == light.shape
    assert np.all(back[0, 0] == 0) and np.array_equal(back[0, 1], [1.0, 0.0, 0.0])
    brightest = light.max(axis=-1, keepdims=True)
    relative = np.abs(back - light) / np.where(brightest > 0, brightest, 1.0)
    assert relative.max() <= 0.004  # rounded 8-bit mantissas: 0.5/128 of the brightest channel
    grey = np.repeat(light[1:, :, :1], 3, axis=-1)  # no zero texel: every channel within 0.4 %
    assert np.abs(read_hdr(hdr_bytes(grey)) / grey - 1).max() <= 0.004


def test_exr_writer_keeps_float32(tmp_path):
    light = _hdr_page((32, 48), 1e-3, 1e5, seed=4)
    path = tmp_path / "page.exr"
    path.write_bytes(exr_bytes(light))
    with OpenEXR.File(str(path)) as exr:
        back = exr.channels()["RGB"].pixels
    assert back.dtype == np.float32 and back.shape == light.shape
    assert np.array_equal(back, light.astype(np.float32))


# -- a bake with --lightmaps DIR --format hdr|exr -----------------------------------------------

SETTINGS = dict(texel_density=16.0, rays=4, page_size=128)


def test_bake_writes_float_pages_that_match_the_float_lightmaps(tmp_path):
    scene = lit_floor("point", position=(0.3, 0.05, 0.0), intensity=100.0)
    source = saved(scene, tmp_path)
    (tmp_path / "float").mkdir()
    expected = computed(scene, tmp_path / "float", **SETTINGS).lightmaps.light
    out = tmp_path / "baked.glb"
    code = main(["bake", str(source), "-o", str(out), "--carrier", "moz",
                 "--texel-density", "16", "--rays", "4",
                 "--page-size", "128", "--lightmaps", str(tmp_path / "maps"), "--format", "hdr",
                 "--report", str(tmp_path / "report.json"), "--quiet"])
    assert code == 0
    files = sorted((tmp_path / "maps").iterdir())
    assert [f.name for f in files] == [f"baked_lightmap_{p}.hdr" for p in range(len(expected))]
    for p, path in enumerate(files):
        back = read_hdr(path.read_bytes())
        brightest = expected[p].max(axis=-1, keepdims=True)
        assert back.shape == expected[p].shape
        assert (np.abs(back - expected[p]) / np.maximum(brightest, 1e-30)).max() <= 0.004
        assert back.max() > 50 * np.median(back[back > 0])  # the hot spot is kept, unclipped
    report = json.loads((tmp_path / "report.json").read_text())
    (page,) = report["lightmap_pages"]
    assert page["peak"] == pytest.approx(expected[0].max())
    assert 0 < page["clipped_fraction"] <= 0.002 and page["intensity"] < page["peak"]
    assert any("clip to it" in note for note in report["notes"])
    assert report["settings"]["clip_percentile"] == 99.9
    gltf = baker.gltf.load.load(out).document
    assert gltf.asset.extras["baker"]["lightmap_intensity_percentile"] == 99.9
    assert gltf.materials[-1].extensions["MOZ_lightmap"]["intensity"] == page["intensity"]
    validation = validate(out)
    assert issue_codes(validation, ERROR) == {}, describe(validation, ERROR)

    result = baker.bake(source, tmp_path / "exr.glb", baker.Settings(**SETTINGS),
                        lightmaps_dir=tmp_path / "exr", lightmaps_format="exr")
    assert result.pages == len(expected)
    with OpenEXR.File(str(tmp_path / "exr" / "exr_lightmap_0.exr")) as exr:
        assert np.array_equal(exr.channels()["RGB"].pixels, expected[0].astype(np.float32))


def test_unknown_format_and_bad_percentile_are_refused_before_baking(tmp_path):
    source = saved(lit_floor("point", intensity=1.0), tmp_path)
    with pytest.raises(baker.SettingsError, match="lightmap file format"):
        baker.bake(source, tmp_path / "out.glb", lightmaps_dir=tmp_path, lightmaps_format="tiff")
    for bad in (50.0, 100.5, float("nan")):
        with pytest.raises(baker.SettingsError, match="clip_percentile"):
            baker.Settings(clip_percentile=bad).check()
    assert not (tmp_path / "out.glb").exists()
