"""Float lightmap files: Radiance RGBE (.hdr) and OpenEXR (.exr), for ``--lightmaps DIR --format``.

The embedded PNG pages are 8-bit (encode.py); an engine that imports lightmaps separately can
have the bake's float pages instead, unclipped:

- ``.hdr`` (Radiance RGBE, written here with numpy): one 8-bit mantissa per channel and a shared
  exponent, so every value from about 1e-38 to 1e38 is kept within 0.4 % of the texel's
  brightest channel (rounded mantissas, decoded as m · 2^(e−136) like stb_image; readers that add
  half a step, as Radiance does, stay within 0.8 %). Dimmer channels of a strongly coloured texel
  are relatively coarser.
- ``.exr`` (OpenEXR through the ASWF ``OpenEXR`` bindings): 32-bit float RGB, ZIP-compressed,
  lossless for the bake's values (float64 rounded to float32: 6e-8 relative). Not half floats:
  half stops at 65504, below the 100 000 lux of direct sun.

Rows run top to bottom in the same order as the PNG pages, so one set of lightmap UVs serves all
three formats.
"""

from __future__ import annotations

import os
import tempfile

import numpy as np

from baker.errors import SettingsError
from baker.settings import LIGHTMAP_FORMATS

FORMATS = LIGHTMAP_FORMATS


def rgbe(rgb: np.ndarray) -> np.ndarray:
    """(H, W, 3) linear float (≥ 0) → (H, W, 4) uint8 RGBE with rounded mantissas.

    The brightest channel's mantissa lands in [128, 255]; a pixel whose brightest channel is
    below 2^-128 (or not above 0) is stored as 0 0 0 0. Negative and NaN channels count 0.
    """
    rgb = np.nan_to_num(np.maximum(np.asarray(rgb, np.float64), 0.0), nan=0.0, posinf=0.0)
    brightest = rgb.max(axis=-1)
    _, exponent = np.frexp(brightest)  # brightest = f · 2^exponent, f in [0.5, 1)
    mantissa = np.round(rgb * np.ldexp(256.0, -exponent)[..., None])
    over = mantissa.max(axis=-1) > 255  # f rounded up to 1: one more exponent, halve
    exponent = exponent + over
    mantissa = np.where(over[..., None], np.round(rgb * np.ldexp(256.0, -exponent)[..., None]),
                        mantissa)
    biased = exponent + 128
    zero = (brightest <= 0) | (biased < 1)
    biased = np.minimum(biased, 255)  # beyond 2^127: saturate (no lightmap gets there)
    out = np.concatenate([np.minimum(mantissa, 255), biased[..., None]], axis=-1)
    out[zero] = 0
    return out.astype(np.uint8)


def hdr_bytes(rgb: np.ndarray, comment: str = "baker lightmap, linear irradiance") -> bytes:
    """A Radiance .hdr file (flat, uncompressed RGBE scanlines) of the (H, W, 3) float image.

    Flat scanlines are valid Radiance; a reader tells them from run-length ones by the first
    pixel, which cannot look like a run-length marker here (its brightest mantissa is ≥ 128).
    """
    height, width = rgb.shape[:2]
    header = (f"#?RADIANCE\n# {comment}\nFORMAT=32-bit_rle_rgbe\n\n-Y {height} +X {width}\n")
    return header.encode("ascii") + rgbe(rgb).tobytes()


def exr_bytes(rgb: np.ndarray) -> bytes:
    """An OpenEXR file of the (H, W, 3) float image: float32 RGB, ZIP compression."""
    try:
        import OpenEXR
    except ImportError:  # a declared dependency; only a broken install gets here
        raise SettingsError("writing .exr needs the OpenEXR package, which is not installed",
                            fix="pip install openexr, or use --format hdr") from None
    pixels = np.ascontiguousarray(rgb, dtype=np.float32)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with tempfile.TemporaryDirectory(prefix="baker-exr-") as folder:
        path = os.path.join(folder, "page.exr")
        with OpenEXR.File(header, {"RGB": pixels}) as exr:
            exr.write(path)
        with open(path, "rb") as f:
            return f.read()


def check_format(format: str) -> None:
    """SettingsError unless ``format`` is one of ``FORMATS`` (before any work is done)."""
    if format not in FORMATS:
        raise SettingsError(f"unknown lightmap file format {format!r}",
                            fix=f"use --format {' or '.join(FORMATS)}")


def page_file(light: np.ndarray, png: bytes, format: str) -> bytes:
    """The bytes of one ``--lightmaps`` file: the embedded ``png``, or ``light`` (H, W, 3) as
    float .hdr or .exr."""
    check_format(format)
    if format == "png":
        return png
    return hdr_bytes(light) if format == "hdr" else exr_bytes(light)
