"""Per-texel error pages (``--error-map DIR``): where the lightmap is still noisy.

Each texel's standard error of its lightmap luminance, in lightmap units: the obscurance term's
from its rays' sample variance, scaled so that the map's RMS equals the bake's ``rmse_estimate``
(the sample variance overstates quasi-Monte Carlo error; ``Terms.rmse`` measures by how much),
plus the direct light's own variance. Written per page as ``<stem>_error_<p>.hdr`` (float,
Radiance RGBE, grey) and ``<stem>_error_<p>.png`` (8-bit grey, scaled to the page's largest
error, for a quick look).
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from PIL import Image

from baker.geometry.surface import LUMINANCE
from baker.image.compose import effective_r_ave
from baker.image.hdr import hdr_bytes


def texel_errors(done) -> np.ndarray:
    """(N,) standard error of each texel's lightmap luminance, lightmap units.

    ``done``: a ``bake.Computed``.
    """
    r_ave = effective_r_ave(done.ambient, done.settings.rho)
    scale = float(done.ambient.intensity @ LUMINANCE)
    sample = done.terms.standard_error(r_ave) * scale
    rms = float(np.sqrt(np.mean(sample ** 2))) if len(sample) else 0.0
    target = done.obscurance_rmse()
    obscurance = sample * (target / rms if rms > 0 else 0.0)
    direct = done.direct.variance() if done.direct is not None else 0.0
    return np.sqrt(obscurance ** 2 + direct)


def error_pages(done) -> np.ndarray:
    """(P, H, W) float64 pages of ``texel_errors`` (0 where no texel is baked)."""
    atlas, texels = done.atlas, done.texels
    pages = np.zeros((atlas.page_count, atlas.height, atlas.width))
    pages[texels.pixels()] = texel_errors(done)
    return pages


def write_error_maps(folder: Path, stem: str, done, write) -> list[Path]:
    """Write every page's error map into the existing ``folder`` with ``write(path, bytes)``
    (an atomic writer, or ``run.atomic.Outputs.stage``); return the paths written."""
    paths = []
    for p, page in enumerate(error_pages(done)):
        grey = np.repeat(page[..., None], 3, axis=-1)
        hdr = folder / f"{stem}_error_{p}.hdr"
        write(hdr, hdr_bytes(grey))
        peak = page.max()
        buffer = io.BytesIO()
        Image.fromarray(np.round(255 * page / peak if peak > 0 else page).astype(np.uint8)).save(
            buffer, "PNG")
        png = folder / f"{stem}_error_{p}.png"
        write(png, buffer.getvalue())
        paths += [hdr, png]
    return paths
