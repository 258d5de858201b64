"""Turning float lightmap pages into the images embedded in the glTF.

A viewer shows ``decoded(texel) × MOZ_lightmap.intensity``, from an 8-bit PNG: the three.js
MOZ_lightmap plugin and the Hubs client load the lightmap as an ordinary glTF texture, and
browsers hand WebGL 8 bits per channel even from a 16-bit PNG, so 8 bits and one scale per page
are all the precision a viewer gets (docs/output.md gives the evidence and the measured error).

What the encoder chooses is the scale. Irradiance has no upper bound — a texel beside a point
light can be a hundred times its neighbours — so the page's *maximum* would spend the whole 8-bit
range on a few hot texels and crush everything else. The scale is instead a high percentile
(``CLIP_PERCENTILE``, default the 99.9th) of the covered texels' brightest channel: at most 0.1 %
of the texels clip, the rest keep 8 bits of the range they actually span. ``EncodedPage`` reports
the peak and the clipped fraction; the float pages are kept intact for ``--lightmaps DIR
--format hdr|exr`` (``hdr.py``).

Texels are quantised linearly (``linear``: what three.js and Hubs read, the default) or through
the sRGB curve (``srgb``: what the proposed MOZ_lightmap text says; more precision in the darks).
"""

from __future__ import annotations

import io
import struct
import zlib
from dataclasses import dataclass

import numpy as np
from PIL import Image as PILImage

from baker.errors import InputError
from baker.geometry.surface import luminance
from baker.image.compose import Lightmaps
from baker.jit import jit
from baker.light.directional import page_texels
from baker.run.parallel import run_chunks
from baker.settings import MAX_LIGHT

CLIP_PERCENTILE = 99.9
"""Default percentile of a page's covered texels (brightest channel) that becomes its intensity."""


@dataclass(frozen=True)
class EncodedPage:
    """One lightmap page as stored in the output.

    ``png`` holds the page; a viewer's linear value is ``decoded texel × intensity``, where
    "decoded" is the texel / 255 (encoding ``linear``) or the sRGB-decoded texel (encoding
    ``srgb``). ``occlusion_png`` is the visibility (1 = unoccluded, ``Lightmaps.visibility``) as
    a grey PNG for the core ``occlusionTexture`` (read from its red channel), or None when not
    asked for.

    ``peak``: the page's largest covered value (any channel, linear light units); ``clipped``:
    the fraction of covered texels whose brightest channel is above ``intensity`` (those texels
    decode to ``intensity``, losing ``value − intensity``). ``direction_png``: the page's
    directional page (``light.directional.page_texels``), or None without one.
    """

    png: bytes
    intensity: float
    occlusion_png: bytes | None = None
    peak: float = 0.0
    clipped: float = 0.0
    direction_png: bytes | None = None


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """The sRGB transfer function on linear values in [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def srgb_to_linear(e: np.ndarray) -> np.ndarray:
    """The inverse of ``linear_to_srgb`` on encoded values in [0, 1]."""
    e = np.clip(e, 0.0, 1.0)
    return np.where(e <= 0.04045, e / 12.92, np.power((e + 0.055) / 1.055, 2.4))


PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_ZLIB_HEADER = b"\x78\x5e"  # deflate, 32 KiB window, "fast" level (the level is a hint only)
# zlib's deflate level. On the demo's 766 × 870 page (2.0 MB of filtered rows, one core, load
# about 10): ISA-L's level 2, used before, 4.0 ms and 606 KB, but its bytes are not always the
# same for the same input (rebake/zipwriter.py); zlib's level 1 16 ms and 630 KB, level 3
# 30 ms and 594 KB, level 6 109 ms and 556 KB.
_LEVEL = 3
_BAND_ROWS = 64  # image rows compressed as one piece (pieces go to every core)


def smooth_png_bytes(rgb: np.ndarray) -> bytes:
    """A (H, W, 3) uint8 image that varies smoothly in both directions (a directional page's
    light directions) as PNG bytes, through PIL's per-row choice of filter: its Paeth and
    Average filters predict a gradient from both neighbours, where ``png_bytes``' one "Up"
    filter sees it only from above (a bumped floor's 49² directional page: 1,351 bytes
    against 1,829). Deterministic: no timestamps, fixed settings."""
    out = io.BytesIO()
    PILImage.fromarray(np.ascontiguousarray(rgb, np.uint8)).save(out, format="PNG",
                                                                 compress_level=9)
    return out.getvalue()


def png_bytes(rgb: np.ndarray) -> bytes:
    """A (H, W, 3) uint8 image as PNG bytes (deterministic: no timestamps, fixed settings).

    Every row has the "Up" filter (its difference from the row above): on lightmaps it
    compresses within 0.5 % of the per-row adaptive choice (PIL's), at a fraction of the cost.
    The filtered rows are deflated in bands of ``_BAND_ROWS`` rows side by side, each band a
    raw deflate stream ending on a byte boundary (a sync flush; the last one finishes), so that
    their concatenation is one valid zlib stream (as pigz makes it). The deflate is zlib's, at
    ``_LEVEL``: the same bytes in every process (ISA-L's, 7 times as fast, is not).
    """
    height, width = rgb.shape[:2]
    rows = np.ascontiguousarray(rgb, np.uint8).reshape(height, 3 * width)
    filtered = np.empty((height, 3 * width + 1), np.uint8)
    filtered[:, 0] = 2  # the "Up" filter type
    filtered[:1, 1:] = rows[:1]  # the row above the first counts as zeros
    np.subtract(rows[1:], rows[:-1], out=filtered[1:, 1:])  # uint8: modulo 256, as PNG wants
    starts = range(0, height, _BAND_ROWS)
    pieces: list[bytes] = [b""] * len(starts)

    def deflate(band: int) -> None:  # zlib releases the GIL: bands compress side by side
        stream = zlib.compressobj(_LEVEL, zlib.DEFLATED, -15)
        last = band == len(pieces) - 1
        pieces[band] = (stream.compress(filtered[starts[band]:starts[band] + _BAND_ROWS])
                        + stream.flush(zlib.Z_FINISH if last else zlib.Z_SYNC_FLUSH))

    run_chunks(deflate, range(len(pieces)))
    data = b"".join([_ZLIB_HEADER, *pieces, struct.pack(">I", zlib.adler32(filtered))])
    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)  # 8-bit RGB, no interlace
    return b"".join([PNG_SIGNATURE, _chunk(b"IHDR", header), _chunk(b"IDAT", data),
                     _chunk(b"IEND", b"")])


def _chunk(kind: bytes, data: bytes) -> bytes:
    """One PNG chunk: length, type, data, CRC-32 of type and data."""
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def quantise(values: np.ndarray, encoding: str) -> np.ndarray:
    """Values in [0, 1] (…, 3) to 8-bit texels under ``encoding`` ("linear" or "srgb")."""
    encoded = linear_to_srgb(values) if encoding == "srgb" else np.clip(values, 0.0, 1.0)
    return np.round(encoded * 255.0).astype(np.uint8)


_ROWS = 128  # page rows converted at once: the float temporaries stay a few MB at any page size


def _page_texels(page: np.ndarray, convert) -> np.ndarray:
    """(H, W, 3) uint8: ``convert`` (rows of ``page`` → their 8-bit texels) on ``_ROWS`` rows at
    a time. A whole 4096² page at once would hold several float copies of it (400 MB each)."""
    out = np.empty(page.shape[:2] + (3,), np.uint8)
    for start in range(0, len(page), _ROWS):
        out[start:start + _ROWS] = convert(page[start:start + _ROWS])
    return out


def decode(texels: np.ndarray, intensity: float, encoding: str) -> np.ndarray:
    """What a viewer reads back: 8-bit ``texels`` (any shape) → linear light, float64."""
    unit = texels.astype(np.float64) / 255.0
    return (srgb_to_linear(unit) if encoding == "srgb" else unit) * intensity


@jit
def _covered_brightest(light: np.ndarray, covered: np.ndarray) -> np.ndarray:
    """(n,) the brightest channel of each of the n ``covered`` (H, W) texels of ``light``
    (H, W, 3), row by row: one pass, no (n, 3) copy (``np.maximum``, so NaN stays NaN)."""
    out = np.empty(np.count_nonzero(covered))
    k = 0
    for y in range(light.shape[0]):
        for x in range(light.shape[1]):
            if covered[y, x]:
                out[k] = np.maximum(np.maximum(light[y, x, 0], light[y, x, 1]), light[y, x, 2])
                k += 1
    return out


@jit
def _quantise_linear(page: np.ndarray, scale: float, out: np.ndarray) -> None:
    """``quantise(page / scale, "linear")`` into ``out`` (H, W, 3) uint8 in one pass, with the
    same arithmetic (clip, round half to even), so the same bytes, and no float temporaries
    of the page. (Not the sRGB curve: numba's pow differs from numpy's in the last bit at a
    few values, and a code's rounding edge can fall there.)"""
    for y in range(page.shape[0]):
        for x in range(page.shape[1]):
            for c in range(3):
                value = min(max(page[y, x, c] / scale, 0.0), 1.0)
                out[y, x, c] = np.uint8(np.round(value * 255.0))


def page_scale(light: np.ndarray, covered: np.ndarray,
               percentile: float = CLIP_PERCENTILE) -> tuple[float, float, float]:
    """(intensity, peak, clipped fraction) of one page.

    light: (H, W, 3) linear; covered: (H, W) bool. The intensity is the ``percentile`` of the
    covered texels' brightest channel among those above 0 (an actual texel value: numpy's
    "higher" method), so a page mostly in the dark still scales to its lit part; 100 gives the
    peak (nothing clips). A page with nothing above 0 gets intensity 1.
    """
    brightest = _covered_brightest(np.ascontiguousarray(light, np.float64),
                                   np.ascontiguousarray(covered, np.bool_))
    lit = brightest[brightest > 0]
    if not len(lit):
        return 1.0, 0.0, 0.0
    peak = float(lit.max())
    intensity = float(np.percentile(lit, percentile, method="higher"))
    return intensity, peak, float(np.count_nonzero(brightest > intensity) / len(brightest))


def encode(lightmaps: Lightmaps, encoding: str, occlusion: bool,
           clip_percentile: float = CLIP_PERCENTILE) -> list[EncodedPage]:
    """One EncodedPage per page; ``occlusion`` adds the visibility as a grey PNG, directional
    pages (``Lightmaps.direction``) their PNG.

    Each page's intensity is ``page_scale`` of its covered texels at ``clip_percentile``.
    """
    pages = []
    for p, (light, covered) in enumerate(zip(lightmaps.light, lightmaps.covered)):
        intensity, peak, clipped = page_scale(light, covered, clip_percentile)
        if not intensity <= MAX_LIGHT:
            raise InputError(f"lightmap page {p} is lit up to {intensity:g}, above {MAX_LIGHT:g}, "
                             "past what baker writes", where=f"lightmap page {p}",
                             fix="scale the scene's lights and emission down")
        occlusion_png = None
        if occlusion:
            occlusion_png = png_bytes(_page_texels(lightmaps.visibility[p], lambda rows: quantise(
                np.repeat(luminance(rows)[..., None], 3, axis=-1), "linear")))
        if encoding == "linear":
            texels = np.empty(light.shape[:2] + (3,), np.uint8)
            _quantise_linear(np.ascontiguousarray(light, np.float64), intensity, texels)
        else:
            texels = _page_texels(light, lambda rows: quantise(rows / intensity, encoding))
        direction_png = (smooth_png_bytes(page_texels(lightmaps.direction[p]))
                         if len(lightmaps.direction) else None)
        pages.append(EncodedPage(png=png_bytes(texels),
                                 intensity=intensity, occlusion_png=occlusion_png,
                                 peak=peak, clipped=clipped, direction_png=direction_png))
    return pages
