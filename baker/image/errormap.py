"""Per-texel error pages (``--error-map DIR``): where the lightmap is still noisy.

Each texel's standard error of its lightmap luminance, in lightmap units, the terms of the
bake's ``rmse_estimate`` texel by texel (``texel_errors``). Written per page as ``<stem>_error_<p>.hdr`` (float,
Radiance RGBE, grey) and ``<stem>_error_<p>.png`` (8-bit grey, scaled to the page's largest
error, for a quick look).
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from PIL import Image

from baker.geometry.surface import luminance
from baker.image.compose import effective_r_ave
from baker.image.hdr import hdr_bytes


POOL_RADIUS = 2  # the per-texel variances are pooled over (2r + 1)² texels


def texel_errors(done) -> np.ndarray:
    """(N,) standard error of each texel's lightmap luminance, lightmap units (``done``: a
    ``bake.Computed``), in quadrature:

    - the obscurance's, I_A·W: each texel's e² from its rays' two independent halves
      (``Terms.split_errors``), or with ``--method gi`` its paths' variance
      (``gi.Indirect.variance``); and the direct light's, from its rays' halves too
      (``direct_estimators.mean_and_variance``): ``light_variance``. With ``--smooth``, each
      texel's Stein risk estimate at the width chosen (``world_filter.Smoothed.sure``, its
      squared bias and filtered noise) instead. A texel's halves give one degree of freedom, so
      these are averaged over the baked texels of the (2·``POOL_RADIUS`` + 1)² window about it on
      its page, whose light is alike (rescaled to keep their sum: the map's mean square is
      the report's), and a texel's error is not judged from two numbers;
    - I_A's own, common to every texel: I_A·W × I_A's relative standard error
      (``ambient.Ambient.relative_variance``, the power estimate's).
    """
    texels = done.texels
    if not len(texels):
        return np.zeros(0)
    r_ave = effective_r_ave(done.ambient, done.settings.rho)
    intensity = done.ambient.intensity
    if done.smoothed is not None and done.smoothed.width > 0:  # the smoothed light's own
        own = np.maximum(done.smoothed.sure, 0.0)
    else:
        own = light_variance(done.terms, r_ave, intensity, done.direct,
                             indirect_variance=done.indirect_variance)
    around = pooled(own, texels.pixels(),
                    (done.atlas.page_count, done.atlas.height, done.atlas.width))
    total = float(around.sum())
    variance = around * (float(own.sum()) / total if total > 0 else 0.0)
    if done.settings.method != "gi":
        shared = luminance(done.terms.obscurance(r_ave) * intensity)
        variance = variance + done.ambient.relative_variance * shared ** 2
    return np.sqrt(variance)


def light_variance(terms, r_ave: np.ndarray, intensity: np.ndarray, direct=None,
                   light_colours: np.ndarray | None = None,
                   indirect_variance: np.ndarray | None = None,
                   floor: bool = True) -> np.ndarray:
    """(N,) each texel's estimated variance of its lightmap luminance from its own rays, lightmap
    units²: I_A·W's (``Terms.split_errors`` × lum(I_A)², or with ``--method gi``
    ``indirect_variance``, the paths' own) plus D's (``Direct.variance``, with
    ``light_colours`` as composed). ``floor``: False for the unbiased e² alone
    (``Terms.split_squares``: 0 where every ray agreed), what Stein's risk estimate needs
    (``world_filter``); True for the floor a texel whose rays all agreed takes."""
    if indirect_variance is not None:
        own = indirect_variance
    else:
        split = terms.split_errors(r_ave) if floor else terms.split_squares(r_ave)
        own = split * float(luminance(intensity)) ** 2
    if direct is not None:
        own = own + direct.variance(light_colours)
    return own


def pooled(values: np.ndarray, pixels: tuple[np.ndarray, np.ndarray, np.ndarray],
           shape: tuple[int, int, int], radius: int = POOL_RADIUS) -> np.ndarray:
    """(N,) the mean of ``values`` (N,) over the texels within ``radius`` texels (a square
    window) of each one on its page; ``pixels``: the texels' (page, y, x), ``shape`` the
    pages' (P, H, W). Summed-area tables: O(P·H·W)."""
    page, y, x = pixels
    total = np.zeros((shape[0], shape[1] + 1, shape[2] + 1))
    count = np.zeros_like(total)
    total[page, y + 1, x + 1] = values
    count[page, y + 1, x + 1] = 1.0
    sums = []
    for table in (total, count):
        table = table.cumsum(axis=1).cumsum(axis=2)
        top, bottom = np.maximum(y - radius, 0), np.minimum(y + radius + 1, shape[1])
        left, right = np.maximum(x - radius, 0), np.minimum(x + radius + 1, shape[2])
        sums.append(table[page, bottom, right] - table[page, top, right]
                    - table[page, bottom, left] + table[page, top, left])
    return np.maximum(sums[0], 0.0) / np.maximum(sums[1], 1.0)  # (the tables' differences
    # of non-negative values may round below 0)


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
