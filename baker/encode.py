"""Turning float lightmap pages into the images embedded in the glTF.

Each page is scaled by its largest value (stored as MOZ_lightmap ``intensity``) and quantised to
8-bit PNG, either linearly (``linear``: what the three.js MOZ_lightmap plugin and the Hubs client
read) or through the sRGB curve (``srgb``: what the proposed MOZ_lightmap text says). The default
is ``linear`` because that is what the viewers people use show correctly; docs/output.md says
more.
"""

from __future__ import annotations

import io
from dataclasses import dataclass

import numpy as np
from PIL import Image

from .compose import Lightmaps
from .surface import LUMINANCE


@dataclass(frozen=True)
class EncodedPage:
    """One lightmap page as stored in the output.

    ``png`` holds the page; a viewer's linear value is ``decoded texel × intensity``, where
    "decoded" is the texel / 255 (encoding ``linear``) or the sRGB-decoded texel (encoding
    ``srgb``). ``occlusion_png`` is the obscurance W as a greyscale-in-red PNG for the core
    ``occlusionTexture``, or None when not asked for.
    """

    png: bytes
    intensity: float
    occlusion_png: bytes | None = None


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """The sRGB transfer function on linear values in [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def png_bytes(rgb: np.ndarray) -> bytes:
    """A (H, W, 3) uint8 image as PNG bytes (deterministic: no timestamps, fixed settings)."""
    buffer = io.BytesIO()
    Image.fromarray(rgb, "RGB").save(buffer, format="PNG", optimize=False, compress_level=6)
    return buffer.getvalue()


def quantise(values: np.ndarray, encoding: str) -> np.ndarray:
    """Values in [0, 1] (…, 3) to 8-bit texels under ``encoding`` ("linear" or "srgb")."""
    encoded = linear_to_srgb(values) if encoding == "srgb" else np.clip(values, 0.0, 1.0)
    return np.round(encoded * 255.0).astype(np.uint8)


def encode(lightmaps: Lightmaps, encoding: str, occlusion: bool) -> list[EncodedPage]:
    """One EncodedPage per page; ``occlusion`` adds the obscurance W as a greyscale PNG."""
    pages = []
    for light, obscurance in zip(lightmaps.light, lightmaps.obscurance):
        peak = float(light.max())
        intensity = peak if peak > 0 else 1.0
        occlusion_png = None
        if occlusion:
            grey = np.repeat((obscurance @ LUMINANCE)[..., None], 3, axis=-1)
            occlusion_png = png_bytes(quantise(grey, "linear"))
        pages.append(EncodedPage(png=png_bytes(quantise(light / intensity, encoding)),
                                 intensity=intensity, occlusion_png=occlusion_png))
    return pages
