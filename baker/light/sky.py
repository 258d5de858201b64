"""The sky: the radiance that reaches a surface along directions that meet nothing at all.

Two kinds (``Sky``), both linear RGB radiance, scene units with +Y up:

- a gradient (``--sky R,G,B`` and ``--sky-horizon``): the zenith colour blended linearly in
  the sine of the elevation down to the horizon colour, which holds below the horizon; drawn
  with cosine-distributed rays, whose estimate of the irradiance is π × the mean radiance seen;
- an image (``--sky-image FILE``): an equirectangular (latitude-longitude) panorama in a
  Radiance ``.hdr`` or an OpenEXR ``.exr`` file, × ``--sky-intensity``, turned about +Y by
  ``--sky-rotation`` degrees. Its layout is three.js's (``equirectUv``): the top row looks up
  (+Y), the bottom row down, and column u ∈ [0, 1) looks along azimuth φ = 2π(u − ½) from +X
  towards +Z (+X at the middle column, +Z at three quarters, −X at the edges). Each pixel is
  radiance constant over its patch of the sphere (nearest lookup, no filtering).

An image is importance-sampled (``Sky.draw``). Its radiance is split in two, L = L_smooth +
L_peak: L_peak = L·max(0, 1 − c/lum L), the part of each pixel brighter than c, the luminance
that ``SMOOTH_SHARE`` of the sphere's solid angle does not exceed (a sun, the bright sky around
it), and L_smooth = L − L_peak, at most c. A share of a point's sample points (those whose first
coordinate is at least 1 − s) is drawn in proportion to L_peak's luminance × each pixel's solid
angle (a pixel picked through a row and a column distribution, then a point uniform in solid
angle inside it) and counts L_peak·cosθ / (s·p); the others are cosine-distributed about the
point's normal (folded above its face, as the obscurance's: ``sampling.fold``) and count
π·L_smooth / (1 − s). Both parts are unbiased whichever sample points fall in each. s is the
peak's share of the image's power, at most ½ (1 when nothing is smooth; 0 when nothing stands
out, as in a uniform or two-level image, whose rays are then the cosine rays of a colour sky):
a small bright sun that one cosine ray in 10⁴ meets is met by half the rays, every one at
nearly the same weight. benchmarks/bench_sky_image.py measures it.

The same sky lights the direct term (``direct_estimators.sky_samples``), the power that sets I_A —
the light that obscurance rays escaping within d_max bring back (``power.delivered_power``) — and
every vertex of a GI path (``gi.py``, next-event estimation), so all three see one sky.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from baker.errors import InputError
from baker.geometry.surface import luminance
from baker.jit import jit
from baker.rays.sampling import concentric_hemisphere, fold, frame

SKY_IMAGE_SUFFIXES = (".hdr", ".exr")
SMOOTH_SHARE = 0.9
"""The share of the sphere's solid angle whose pixels are at most the smooth part's ceiling c
(``Sky``): the brightest tenth's excess over it is the peak, drawn by the image."""
MOST_IMAGE_SHARE = 0.5
"""The most of a point's rays the peak is drawn with, while some radiance is smooth."""
MAX_SKY_PIXELS = 1 << 23
"""The most pixels a sky image may have (8.4 M: a 4096 × 2048 panorama): its float radiance
and sampling tables take about 50 bytes a pixel."""


@dataclass(frozen=True)
class Sky:
    """What the sky sends (see the module's docstring).

    gradient: (2, 3) float64 zenith and horizon radiance, or None for an image.
    image: (H, W, 3) float64 radiance of each pixel (× intensity), top row towards +Y; (0, 0, 3)
    for a gradient. rotation: radians the image is turned about +Y (right-handed: +Z towards
    +X). ceiling: c, the luminance above which a pixel's radiance is peak. image_share: s, the
    share of the sample points drawn by the peak. row_cdf: (H,) running chance of each row;
    column_cdf: (H, W) running chance of each pixel within its row (last of each 1);
    probability: (H, W) chance of each pixel, in proportion to its peak luminance × solid
    angle; solid: (H,) solid angle of one pixel of each row (sr). source: the file's name.
    """

    gradient: np.ndarray | None
    image: np.ndarray
    rotation: float = 0.0
    ceiling: float = math.inf
    image_share: float = 0.0
    row_cdf: np.ndarray | None = None
    column_cdf: np.ndarray | None = None
    probability: np.ndarray | None = None
    solid: np.ndarray | None = None
    source: str = ""

    @classmethod
    def of_gradient(cls, zenith, horizon=None) -> "Sky":
        """A uniform sky of radiance ``zenith`` (3,), or a gradient down to ``horizon``."""
        zenith = np.asarray(zenith, np.float64)
        horizon = zenith if horizon is None else np.asarray(horizon, np.float64)
        return cls(np.stack([zenith, horizon]), np.zeros((0, 0, 3)))

    @classmethod
    def of_image(cls, radiance: np.ndarray, rotation_degrees: float = 0.0,
                 source: str = "") -> "Sky":
        """An image sky of the equirectangular ``radiance`` (H, W, 3) (negative and non-finite
        values count 0), turned ``rotation_degrees`` about +Y, split into its smooth part and
        its peak (``SMOOTH_SHARE``), with the peak's sampling tables."""
        image = np.nan_to_num(np.maximum(np.asarray(radiance, np.float64), 0.0), nan=0.0,
                              posinf=0.0)
        height, width = image.shape[:2]
        edges = np.cos(np.pi * np.arange(height + 1) / height)
        solid = 2.0 * np.pi / width * (edges[:-1] - edges[1:])  # (H,) sr per pixel
        lum = luminance(image)
        ceiling = _weighted_quantile(lum, np.broadcast_to(solid[:, None], lum.shape),
                                     SMOOTH_SHARE)
        peak = np.maximum(lum - ceiling, 0.0) * solid[:, None]
        power = float((lum * solid[:, None]).sum())
        share = float(peak.sum()) / power if power > 0 else 0.0
        share = 1.0 if share >= 1.0 else min(share, MOST_IMAGE_SHARE)
        weight = peak if peak.sum() > 0 else np.broadcast_to(solid[:, None], peak.shape)
        probability = weight / weight.sum()
        rows = probability.sum(axis=1)
        row_cdf = np.cumsum(rows)
        row_cdf[-1] = 1.0
        within = np.where(rows[:, None] > 0, probability / np.where(rows > 0, rows, 1.0)[:, None],
                          1.0 / width)
        column_cdf = np.cumsum(within, axis=1)
        column_cdf[:, -1] = 1.0
        return cls(None, image, math.radians(rotation_degrees), ceiling, share, row_cdf,
                   column_cdf, probability, solid, source)

    @property
    def is_image(self) -> bool:
        return self.gradient is None

    def radiance(self, directions: np.ndarray) -> np.ndarray:
        """Radiance (…, 3) along unit world directions (…, 3)."""
        if not self.is_image:
            up = np.maximum(directions[..., 1:2], 0.0)
            return self.gradient[1] + (self.gradient[0] - self.gradient[1]) * up
        row, column = self._pixels(directions.reshape(-1, 3))
        return self.image[row, column].reshape(directions.shape[:-1] + (3,))

    def _pixels(self, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(row, column) (m,) of the pixel each unit world direction (m, 3) looks through."""
        flat = np.ascontiguousarray(directions, np.float64)
        row, column = np.empty(len(flat), np.int64), np.empty(len(flat), np.int64)
        _pixels_kernel(flat, math.cos(self.rotation), math.sin(self.rotation),
                       self.image.shape[0], self.image.shape[1], row, column)
        return row, column

    def mean_radiance(self) -> np.ndarray:
        """(3,) the radiance averaged over the whole sphere of directions."""
        if not self.is_image:  # the gradient: horizon below, h + (z − h)·sin e above
            return 0.5 * self.gradient[1] + 0.5 * (self.gradient[1] + 0.5 * (
                self.gradient[0] - self.gradient[1]))
        return (self.image * self.solid[:, None, None]).sum(axis=(0, 1)) / (4.0 * np.pi)

    def report(self) -> dict:
        """What the bake's report says of the sky (JSON-able)."""
        if not self.is_image:
            return {"kind": "colour", "zenith": self.gradient[0].tolist(),
                    "horizon": self.gradient[1].tolist()}
        return {"kind": "image", "file": self.source, "width": int(self.image.shape[1]),
                "height": int(self.image.shape[0]),
                "mean_radiance": self.mean_radiance().tolist(),
                "rotation_degrees": math.degrees(self.rotation),
                "smooth_ceiling": self.ceiling, "image_share": self.image_share}

    def draw(self, points: np.ndarray, normals: np.ndarray, geometric: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
        """An image sky's rays for sample points (m, 2) of [0, 1)², one per ray, at receivers
        of hemisphere normals ``normals`` (m, 3) (``sampling.hemisphere_normals``) and
        front-face normals ``geometric`` (m, 3): unit world directions (m, 3) and what each ray
        counts if it meets nothing (m, 3) (the module's docstring: 0 below the front face),
        so that the irradiance is the mean of those over the rays that meet nothing."""
        m = len(points)
        directions, factor = np.empty((m, 3)), np.empty(m)
        row, column = np.empty(m, np.int64), np.empty(m, np.int64)
        peak = np.empty(m, np.bool_)
        _draw_kernel(np.ascontiguousarray(points, np.float64),
                     np.ascontiguousarray(normals, np.float64),
                     np.ascontiguousarray(geometric, np.float64), self.row_cdf,
                     self.column_cdf, self.probability, self.solid,
                     math.cos(self.rotation), math.sin(self.rotation), self.image_share,
                     directions, factor, row, column, peak)
        radiance = self.image[row, column]
        lum = luminance(radiance)
        smooth = np.minimum(1.0, self.ceiling / np.where(lum > 0, lum, 1.0))
        part = np.where(peak, 1.0 - smooth, smooth)
        return directions, radiance * (part * factor)[:, None]


def _weighted_quantile(values: np.ndarray, weights: np.ndarray, share: float) -> float:
    """The least value v such that the values at most v carry ``share`` of the weights."""
    order = np.argsort(values, axis=None, kind="stable")
    running = np.cumsum(weights.reshape(-1)[order])
    at = min(int(np.searchsorted(running, share * running[-1])), len(order) - 1)
    return float(values.reshape(-1)[order[at]])


def sky_of(settings) -> Sky | None:
    """The sky ``settings`` (``Resolved``) ask for: an image (``sky_image``, read here), a
    gradient (``sky``), or None."""
    if settings.sky_image is not None:
        radiance = read_sky_image(settings.sky_image) * float(settings.sky_intensity)
        return Sky.of_image(radiance, settings.sky_rotation, Path(settings.sky_image).name)
    if settings.sky is not None:
        return Sky.of_gradient(settings.sky, settings.sky_horizon)
    return None


# ------------------------------------------------------------------------------------------------
# Reading the image


def read_sky_image(path) -> np.ndarray:
    """(H, W, 3) float64 linear radiance of an equirectangular ``.hdr`` or ``.exr`` file.

    Raises InputError naming the file when it is missing, not such an image, not twice as wide
    as high (within a pixel) or larger than ``MAX_SKY_PIXELS``."""
    path = Path(path)
    fix = ("give --sky-image an equirectangular panorama (twice as wide as high) saved as "
           "Radiance .hdr or OpenEXR .exr")
    if path.suffix.lower() not in SKY_IMAGE_SUFFIXES:
        kind = path.suffix or "a file without suffix"
        raise InputError(f"a sky image is a .hdr or .exr file, not {kind}", file=str(path),
                         fix=fix)
    try:
        data = path.read_bytes()
    except OSError as error:
        raise InputError(f"cannot read the sky image ({error.strerror or error})",
                         file=str(path), fix=fix) from None
    try:
        image = _read_hdr(data) if path.suffix.lower() == ".hdr" else _read_exr(path)
    except ValueError as error:
        raise InputError(f"not a readable sky image: {error}", file=str(path), fix=fix) from None
    height, width = image.shape[:2]
    if height < 1 or abs(width - 2 * height) > 1:
        raise InputError(f"the sky image is {width}×{height} pixels: an equirectangular "
                         "panorama is twice as wide as high", file=str(path), fix=fix)
    if height * width > MAX_SKY_PIXELS:
        raise InputError(f"the sky image has {height * width:,} pixels, more than "
                         f"{MAX_SKY_PIXELS:,}", file=str(path),
                         fix="scale it down (a 2048×1024 panorama lights a scene as well)")
    return image


def _read_hdr(data: bytes) -> np.ndarray:
    """Radiance RGBE bytes → (H, W, 3) float64: flat or run-length scanlines, decoded as
    stb_image does (m · 2^(e − 136), as ``image.hdr.rgbe`` writes them). ValueError when the
    bytes are not such a file."""
    if not (data.startswith(b"#?RADIANCE") or data.startswith(b"#?RGBE")):
        raise ValueError("no #?RADIANCE header")
    end = data.find(b"\n\n")
    if end < 0:
        raise ValueError("the header does not end")
    header = data[:end].decode("latin-1").split("\n")
    formats = [line for line in header if line.startswith("FORMAT=")]
    if formats and formats[0].strip() != "FORMAT=32-bit_rle_rgbe":
        raise ValueError(f"{formats[0].strip()} (only 32-bit_rle_rgbe is read)")
    line_end = data.find(b"\n", end + 2)
    size = data[end + 2:line_end].decode("latin-1").split()
    if len(size) != 4 or size[0] != "-Y" or size[2] != "+X" or not (
            size[1].isdigit() and size[3].isdigit()):
        raise ValueError(f"resolution {' '.join(size)!r} (only -Y H +X W is read)")
    height, width = int(size[1]), int(size[3])
    if height * width > MAX_SKY_PIXELS:
        raise ValueError(f"{width}×{height} pixels, more than {MAX_SKY_PIXELS:,}")
    body = np.frombuffer(data, np.uint8, offset=line_end + 1)
    rgbe = np.zeros((height, width, 4), np.uint8)
    if _decode_rgbe(body, rgbe) < 0:
        raise ValueError("the pixel data is truncated or malformed")
    scale = np.ldexp(1.0, rgbe[..., 3].astype(np.int64) - 136)
    return np.where(rgbe[..., 3:] > 0, rgbe[..., :3] * scale[..., None], 0.0)


@jit
def _decode_rgbe(body, out):
    """Scanlines of RGBE pixels from ``body`` into ``out`` (H, W, 4): each scanline run-length
    encoded (the marker 2 2 w_hi w_lo, then each channel in runs) or flat. Returns the bytes
    read, or −1 when the data ends early or a run overflows its scanline."""
    height, width = out.shape[0], out.shape[1]
    at = 0
    for y in range(height):
        if at + 4 > len(body):
            return -1
        rle = (8 <= width < 32768 and body[at] == 2 and body[at + 1] == 2
               and body[at + 2] < 128 and body[at + 2] * 256 + body[at + 3] == width)
        if not rle:
            if at + 4 * width > len(body):
                return -1
            for x in range(width):
                for c in range(4):
                    out[y, x, c] = body[at + 4 * x + c]
            at += 4 * width
            continue
        at += 4
        for c in range(4):
            x = 0
            while x < width:
                if at >= len(body):
                    return -1
                count = int(body[at])
                at += 1
                if count > 128:  # a run of one value
                    count -= 128
                    if x + count > width or at >= len(body):
                        return -1
                    for i in range(count):
                        out[y, x + i, c] = body[at]
                    at += 1
                else:  # count literal values
                    if count == 0 or x + count > width or at + count > len(body):
                        return -1
                    for i in range(count):
                        out[y, x + i, c] = body[at + i]
                    at += count
                x += count
    return at


def _read_exr(path: Path) -> np.ndarray:
    """An OpenEXR file's R, G, B channels (or Y for grey) → (H, W, 3) float64."""
    import OpenEXR

    try:
        with OpenEXR.File(str(path), separate_channels=True) as exr:
            channels = {name: np.asarray(channel.pixels, np.float64)
                        for name, channel in exr.channels().items()}
    except RuntimeError as error:
        raise ValueError(str(error)) from None
    if all(name in channels for name in "RGB"):
        return np.stack([channels["R"], channels["G"], channels["B"]], axis=-1)
    if "Y" in channels:
        return np.repeat(channels["Y"][..., None], 3, axis=-1)
    raise ValueError(f"no R, G, B (or Y) channels, only {', '.join(sorted(channels))}")


# ------------------------------------------------------------------------------------------------
# Kernels


@jit
def _pixel_of(x, y, z, cos_r, sin_r, height, width):
    """The (row, column) of the image pixel that the unit world direction (x, y, z) looks
    through, the image turned by the rotation whose cosine and sine are ``cos_r``, ``sin_r``."""
    ix = x * cos_r - z * sin_r  # the direction turned back into the image's frame
    iz = x * sin_r + z * cos_r
    u = math.atan2(iz, ix) / (2.0 * math.pi) + 0.5
    column = int(math.floor(u * width)) % width
    polar = math.acos(min(max(y, -1.0), 1.0))
    row = min(max(int(polar / math.pi * height), 0), height - 1)
    return row, column


@jit
def _pixels_kernel(directions, cos_r, sin_r, height, width, row, column):
    for i in range(len(directions)):
        row[i], column[i] = _pixel_of(directions[i, 0], directions[i, 1], directions[i, 2],
                                      cos_r, sin_r, height, width)


@jit
def _folded_cosine_pdf(dx, dy, dz, nx, ny, nz, gx, gy, gz):
    """The density (per sr) of cosine directions about (nx, ny, nz) folded above the face of
    normal (gx, gy, gz) (``sampling.fold``) at the unit direction (dx, dy, dz): 0 below the
    face, else (cos + cos of its mirror image) / π."""
    dot = dx * gx + dy * gy + dz * gz
    if dot <= 0.0:
        return 0.0
    direct = max(dx * nx + dy * ny + dz * nz, 0.0)
    mirrored = max((dx - 2.0 * dot * gx) * nx + (dy - 2.0 * dot * gy) * ny
                   + (dz - 2.0 * dot * gz) * nz, 0.0)
    return (direct + mirrored) / math.pi


@jit
def _draw_kernel(points, normals, geometric, row_cdf, column_cdf, probability, solid, cos_r,
                 sin_r, share, directions, factor, row, column, peak):
    """``Sky.draw``'s directions and pixels: with c = 1 − ``share``, point i whose first
    coordinate u is below c draws a folded cosine direction from (u/c, v) and counts
    π/c × its smooth radiance (``factor``, ``peak`` False); else a pixel by the peak's tables
    from ((u − c)/share, v), a point uniform in solid angle inside it from what is left of both
    coordinates, and counts π·p_cos / (share·p_image) × its peak radiance (π·p_cos: cosθ on a
    flat face, its folded density on a curved one; 0 below the front face)."""
    height, width = column_cdf.shape[0], column_cdf.shape[1]
    cosine_share = 1.0 - share
    for i in range(len(points)):
        u, v = points[i, 0], points[i, 1]
        nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        gx, gy, gz = geometric[i, 0], geometric[i, 1], geometric[i, 2]
        if u < cosine_share:
            lx, ly, lz = concentric_hemisphere(u / cosine_share, v)
            f = frame(nx, ny, nz)
            dx = lx * f[0] + ly * f[3] + lz * nx
            dy = lx * f[1] + ly * f[4] + lz * ny
            dz = lx * f[2] + ly * f[5] + lz * nz
            if nx != gx or ny != gy or nz != gz:
                dx, dy, dz = fold(dx, dy, dz, gx, gy, gz)
            row[i], column[i] = _pixel_of(dx, dy, dz, cos_r, sin_r, height, width)
            factor[i] = math.pi / cosine_share
            peak[i] = False
        else:
            s = (u - cosine_share) / share
            r = min(np.searchsorted(row_cdf, s, side="right"), height - 1)
            low = row_cdf[r - 1] if r > 0 else 0.0
            s = min(max((s - low) / max(row_cdf[r] - low, 1e-300), 0.0), 1.0)
            c = min(np.searchsorted(column_cdf[r], v, side="right"), width - 1)
            left = column_cdf[r, c - 1] if c > 0 else 0.0
            t = min(max((v - left) / max(column_cdf[r, c] - left, 1e-300), 0.0), 1.0)
            top, bottom = math.cos(math.pi * r / height), math.cos(math.pi * (r + 1) / height)
            y = top - s * (top - bottom)
            ring = math.sqrt(max(1.0 - y * y, 0.0))
            azimuth = 2.0 * math.pi * ((c + t) / width - 0.5)
            ix, iz = ring * math.cos(azimuth), ring * math.sin(azimuth)
            dx, dy, dz = ix * cos_r + iz * sin_r, y, -ix * sin_r + iz * cos_r
            cosine = _folded_cosine_pdf(dx, dy, dz, nx, ny, nz, gx, gy, gz)
            density = share * probability[r, c] / solid[r]
            row[i], column[i] = r, c
            factor[i] = math.pi * cosine / density if cosine > 0.0 and density > 0.0 else 0.0
            peak[i] = True
        directions[i, 0], directions[i, 1], directions[i, 2] = dx, dy, dz
