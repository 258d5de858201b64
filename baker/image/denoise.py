"""Optional denoising of the composed lightmap pages with Intel Open Image Denoise (``--denoise``).

OIDN's lightmap filter ("RTLightmap", HDR, non-directional) is a neural network trained on
ray-traced lightmaps; the Python binding ``pyoidn`` runs it on the CPU (``pip install
"baker[denoise]"``). Run on a whole page it would mix light between charts that only lie side by
side in the atlas — the network sees a hundred texels around each texel, far more than the
padding — so this module denoises each *chart* on its own:

1. charts are the connected groups of covered texels (8-neighbours, same instance) on a page,
   cut further at creases (neighbours whose shading normals differ by more than about 26°:
   xatlas packs the faces of thin boxes into one chart, and the light really jumps there);
2. each such patch is cut out with a margin (``MARGIN`` texels) into its own small image, in
   which only the patch's *valid* texels keep their value: invalid and enclosed texels
   (validity.py), the padding and any other chart inside the crop are filled from the patch's
   own valid texels (ring-by-ring mean of filled neighbours, then the patch's mean for the rest);
3. the image is denoised and only the patch's valid texels take the result.

Patches with fewer than ``MIN_TEXELS`` valid texels are left as baked: their detail is texel-
sized, the network cannot tell it from noise (on the vase room, denoising them made their RMSE
up to 20× worse, and the scene's 1.3× better instead of 1.8×).

So no texel of another chart, of the padding or a flagged texel ever feeds a valid texel; the
invalid ones are filled afterwards from their (denoised) valid neighbours by ``postprocess``, and
dilation and seam stitching run after denoising as before.

Determinism: the CPU device runs with a fixed thread count (``Settings.threads``) and no thread
pinning; the same input gives the same bytes (tests/test_denoise.py checks it, also across
thread counts). OIDN picks kernels for the CPU's instruction set (AVX2, AVX-512, NEON), so two
different machines may differ in the last bits.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from baker.atlas.rasterise import Texels
from baker.image.compose import Lightmaps
from baker.image.postprocess import dilate
from baker.settings import require_oidn

MARGIN = 8  # texels of filler around each chart's crop: keeps the image border off the chart
CREASE_COS = 0.9  # neighbours whose shading normals differ by more (about 26°) are not linked
MIN_TEXELS = 64  # smaller patches keep their baked values: their detail is texel-sized
FILL_RINGS = 2 * MARGIN  # rings of neighbour-mean fill before the rest takes the chart's mean


@dataclass(frozen=True)
class DenoiseInfo:
    """What ``denoise`` did, for the report.

    charts: charts denoised (each one OIDN run); texels: valid texels whose value the network
    set; seconds: wall time of the whole step; images: which page images ("light", and
    "visibility" when the occlusion texture is written).
    """

    charts: int
    texels: int
    seconds: float
    images: tuple[str, ...]

    def as_dict(self) -> dict:
        """JSON-able, for the report's ``denoise`` entry."""
        return {"denoised": True, "charts": self.charts, "texels": self.texels,
                "seconds": self.seconds, "images": list(self.images), "filter": "RTLightmap"}


def chart_labels(texels: Texels, shape: tuple[int, int, int]) -> np.ndarray:
    """(N,) int64 patch of every texel, 0 … C−1 in order of each patch's first texel.

    Two texels are in one patch when a chain of 8-neighbours on the same page, each of the same
    instance and with shading normals within ``CREASE_COS`` of the next, joins them: a chart,
    cut at its creases (xatlas packs a thin box's faces into one chart, and the light really
    jumps at its edges; the network would blur the jump). ``shape``: (P, H, W) of the pages. Union-find over the neighbour
    pairs, vectorised: hook every pair's larger root onto the smaller, then pointer jumping,
    until every pair shares a root (a few rounds).
    """
    n = len(texels)
    index = np.full(shape, -1, np.int64)
    page, texel_y, texel_x = texels.pixels()
    index[page, texel_y, texel_x] = np.arange(n)
    pages, height, width = shape
    a_parts, b_parts = [], []
    for dy, dx in ((0, 1), (1, -1), (1, 0), (1, 1)):  # each unordered 8-neighbour pair once
        y, x = texel_y + dy, texel_x + dx
        inside = (y < height) & (x >= 0) & (x < width)
        rows = np.flatnonzero(inside)
        other = index[page[rows], y[rows], x[rows]]
        keep = other >= 0
        rows, other = rows[keep], other[keep]
        keep = ((texels.instance(rows) == texels.instance(other)) &
                (np.einsum("ij,ij->i", texels.normal[rows], texels.normal[other]) > CREASE_COS))
        a_parts.append(rows[keep])
        b_parts.append(other[keep])
    a, b = np.concatenate(a_parts), np.concatenate(b_parts)
    parent = np.arange(n)
    while True:
        ra, rb = parent[a], parent[b]
        differ = ra != rb
        if not differ.any():
            break
        low, high = np.minimum(ra[differ], rb[differ]), np.maximum(ra[differ], rb[differ])
        np.minimum.at(parent, high, low)
        while True:  # pointer jumping: every texel straight to its root
            jumped = parent[parent]
            if np.array_equal(jumped, parent):
                break
            parent = jumped
    _, labels = np.unique(parent, return_inverse=True)
    return labels.astype(np.int64)


class _Filter:
    """One OIDN CPU device and RTLightmap filter, reused for every chart of a bake."""

    def __init__(self, threads: int):
        import pyoidn

        self._pyoidn = pyoidn
        self.device = pyoidn.Device(pyoidn.OIDN_DEVICE_TYPE_CPU)
        self.device.set_int("numThreads", int(threads))  # 0: one per core
        self.device.set_bool("setAffinity", False)  # leave the cores to Embree and numba too
        self.device.commit()
        self._check("device")
        self.filter = pyoidn.Filter(self.device, pyoidn.OIDN_FILTER_TYPE_RT_LIGHTMAP)
        self._check("filter creation")
        self.filter.set_bool("directional", False)  # an HDR irradiance map, not SH directions
        self.filter.set_quality(pyoidn.OIDN_QUALITY_HIGH)

    def _check(self, what: str) -> None:
        error = self.device.get_error()
        if error is not None:
            raise RuntimeError(f"Open Image Denoise {what} failed: {error}")

    def run(self, image: np.ndarray) -> np.ndarray:
        """Denoise ``image`` (h, w, 3) float32, linear HDR ≥ 0; the result, same shape."""
        output = np.zeros_like(image)
        fmt = self._pyoidn.OIDN_FORMAT_FLOAT3
        self.filter.set_image(self._pyoidn.OIDN_IMAGE_COLOR, image, fmt)
        self.filter.set_image(self._pyoidn.OIDN_IMAGE_OUTPUT, output, fmt)
        self.filter.commit()
        self.filter.execute()
        self._check("filtering")
        return output

    def close(self) -> None:
        self.filter.release()
        self.device.release()


def _chart_image(page: np.ndarray, ys: np.ndarray, xs: np.ndarray, valid: np.ndarray,
                 origin: tuple[int, int], size: tuple[int, int]) -> np.ndarray:
    """(h, w, 3) float32 crop holding one chart's valid texels and filler made from them only.

    page: (H, W, 3) float64 page image; ys, xs: (k,) the chart's texels; valid: (k,) bool which
    of them feed the network; origin: page (y, x) of the crop's corner; size: (h, w).
    """
    h, w = size
    values = np.zeros((1, h, w, 3))
    known = np.zeros((1, h, w), bool)
    cy, cx = ys[valid] - origin[0], xs[valid] - origin[1]
    values[0, cy, cx] = page[ys[valid], xs[valid]]
    known[0, cy, cx] = True
    values, filled = dilate(values, known, FILL_RINGS)
    values[~filled] = page[ys[valid], xs[valid]].mean(axis=0)
    return np.ascontiguousarray(np.maximum(values[0], 0.0), dtype=np.float32)


def denoise(lightmaps: Lightmaps, texels: Texels, invalid: np.ndarray | None = None,
            enclosed: np.ndarray | None = None, threads: int = 0,
            visibility: bool = False) -> tuple[Lightmaps, DenoiseInfo]:
    """Denoise each chart of the composed pages on its own (see the module notes).

    lightmaps: straight from ``compose`` (before ``postprocess``); texels: the baked texels;
    invalid, enclosed: (P, H, W) bool masks from ``validity.Validity.page_masks`` (None: none),
    texels that neither feed the network nor take its output; threads: OIDN's CPU threads
    (0: one per core); visibility: also denoise the visibility (when it is written as the occlusion
    texture).
    Returns the new lightmaps (only valid covered texels changed) and what was done.
    """
    started = time.perf_counter()
    require_oidn()
    shape = lightmaps.covered.shape
    n = len(texels)
    valid = np.ones(n, bool)
    for mask in (invalid, enclosed):
        if mask is not None:
            valid &= ~mask[texels.pixels()]
    labels = chart_labels(texels, shape)
    order = np.argsort(labels, kind="stable")
    starts = np.flatnonzero(np.r_[True, np.diff(labels[order]) != 0]) if n else np.zeros(0, int)
    names = ("light", "visibility") if visibility else ("light",)
    sources = {name: getattr(lightmaps, name) for name in names}
    results = {name: image.copy() for name, image in sources.items()}
    charts = changed = 0
    oidn = _Filter(threads)
    try:
        for rows in np.split(order, starts[1:]) if n else []:
            keep = valid[rows]
            if keep.sum() < MIN_TEXELS:  # too small to tell noise from detail: keep it
                continue
            pages_of, ys, xs = texels.pixels(rows)
            page = int(pages_of[0])
            origin = (int(ys.min()) - MARGIN, int(xs.min()) - MARGIN)
            size = (int(ys.max()) - origin[0] + 1 + MARGIN, int(xs.max()) - origin[1] + 1 + MARGIN)
            for name in names:
                image = _chart_image(sources[name][page], ys, xs, keep, origin, size)
                out = oidn.run(image)
                results[name][page, ys[keep], xs[keep]] = out[ys[keep] - origin[0],
                                                              xs[keep] - origin[1]]
            charts += 1
            changed += int(keep.sum())
    finally:
        oidn.close()
    info = DenoiseInfo(charts=charts, texels=changed, seconds=time.perf_counter() - started,
                       images=names)
    return replace(lightmaps, **results), info
