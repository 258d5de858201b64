"""Directional lightmaps as a person sees them: ``baker view`` in headless Chromium and
``baker preview``, per pixel, against the closed form of the light at the normal-mapped
normal (tests/test_directional.py, benchmarks/bench_directional.py).

The scenes (``assets.light_scenes.normal_mapped_floor``, ``window_room``) have a bumped floor
whose normal map is known in closed form (``bumped_normals``'s height field), so the normal at
every pixel's floor point follows from its position alone, independently of both renderers:
- a point light of intensity I at p: E(n) = I·max(0, n·l)/r²;
- a window of uniform sky radiance L: E(n) = L·n·Φ, Φ = ½ Σ θ_i·(v_i × v_{i+1})/|v_i × v_{i+1}|
  over the opening's edges seen from the point (Lambert's vector irradiance of a polygon: exact
  while the opening lies above the plane of n).
With nothing else lighting the floor (I_A 0), a picture's "relief" — its luminance over the plain
bake's picture (or over the closed form at n₀) — is what the normal map adds; its correlation
with the closed form's E(n)/E(n₀) is 0 for a plain lightmap (a flat face) and what
``--directional`` must bring to ≥ 0.95 (issue 42).
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image

import baker
from baker.geometry.surface import LUMINANCE, SRGB_TO_LINEAR
from baker.gltf.load import load
from baker.preview import View, render
from baker.view import start
from tests.bakehelp import saved

SIZE = (240, 240)
BUMPS, TILT = 6, 30.0  # ``bumped_normals``'s defaults


def floor_normals(position: np.ndarray, size: float = 2.0) -> np.ndarray:
    """(…, 3) world normals of the bumped floor of side ``size`` at floor points (…, 3): its UVs
    run u = (z + s/2)/s, v = (s/2 − x)/s; its tangent is +Z, the image's up +X."""
    u = (position[..., 2] + size / 2) / size
    v = (size / 2 - position[..., 0]) / size
    slope = math.tan(math.radians(TILT))
    dx = slope * np.cos(2 * np.pi * BUMPS * u) * np.sin(2 * np.pi * BUMPS * v)
    dy = -slope * np.sin(2 * np.pi * BUMPS * u) * np.cos(2 * np.pi * BUMPS * v)
    n = np.stack([-dy, np.ones_like(dx), -dx], axis=-1)  # (−dx, −dy, 1) on (T, B, N) = (Z, X, Y)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def point_light(position: np.ndarray, normals: np.ndarray, light, intensity: float) -> np.ndarray:
    """I·max(0, n·l)/r² at points (…, 3) of normals (…, 3)."""
    towards = np.asarray(light, np.float64) - position
    r = np.linalg.norm(towards, axis=-1)
    return intensity * np.maximum(0.0, np.sum(normals * towards, axis=-1) / r) / r ** 2


def window_light(position: np.ndarray, normals: np.ndarray, corners: np.ndarray,
                 radiance: float) -> np.ndarray:
    """L·max(0, n·Φ) at points (…, 3) of normals (…, 3) through a polygon ``corners`` (m, 3)."""
    flux = np.zeros(position.shape)
    m = len(corners)
    for i in range(m):
        a = corners[i] - position
        b = corners[(i + 1) % m] - position
        a /= np.linalg.norm(a, axis=-1, keepdims=True)
        b /= np.linalg.norm(b, axis=-1, keepdims=True)
        cross = np.cross(a, b)
        angle = np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0))
        flux += 0.5 * angle[..., None] * cross / np.linalg.norm(cross, axis=-1, keepdims=True)
    flux *= np.sign(np.sum(flux * [0.0, 1.0, 0.0], axis=-1, keepdims=True))  # towards the room
    return radiance * np.maximum(0.0, np.sum(normals * flux, axis=-1))


def top_view(height: float, target=(0.0, 0.0, 0.0), fov: float = 50.0) -> View:
    """A camera ``height`` above ``target`` looking straight down, +X up in the picture."""
    eye = np.asarray(target, np.float64) + [0.0, height, 1e-4]
    back = (eye - target) / np.linalg.norm(eye - target)
    right = np.cross([1.0, 0.0, 0.0], back)
    right /= np.linalg.norm(right)
    return View(eye, np.stack([right, np.cross(back, right), back]), math.radians(fov))


def _camera(view: View) -> str:
    right, up, back = view.axes
    return ",".join(f"{v:.9g}" for v in [*view.origin, *(view.origin - back), *up,
                                         math.degrees(view.yfov)])


@dataclass(frozen=True)
class Pictures:
    """One baked file seen by both renderers, the same camera and exposure: ``browser`` and
    ``preview`` (H, W) linear luminance, ``position`` (H, W, 3) world points (preview's rays),
    ``floor`` (H, W) bool the floor's pixels, neither clipped nor at a silhouette."""

    browser: np.ndarray
    preview: np.ndarray
    position: np.ndarray
    floor: np.ndarray


def pictures(browser, baked: Path, view: View, save: Path | None = None) -> Pictures:
    """``baked`` in ``baker view`` (``browser``: a ``chromium.Browser``) and ``baker preview``."""
    picture = render(load(baked), "lit", SIZE, view=view)
    server, url = start(baked)
    try:
        page = (f"{url}?bare=1&size={SIZE[0]}x{SIZE[1]}&exposure={picture.exposure:.9g}"
                f"&camera={_camera(view)}")
        shown = np.asarray(Image.open(io.BytesIO(browser.canvas_png(page))).convert("RGB"))
    finally:
        server.shutdown()
        server.server_close()
    if save is not None:
        Image.fromarray(np.concatenate([shown, picture.rgb], axis=1)).save(save)
    position = np.nan_to_num(picture.position)
    floor = picture.lightmapped & (np.abs(position[..., 1]) < 1e-6)
    inner = floor.copy()
    inner[1:] &= floor[:-1]
    inner[:-1] &= floor[1:]
    inner[:, 1:] &= floor[:, :-1]
    inner[:, :-1] &= floor[:, 1:]
    inner &= (shown.max(axis=-1) < 254) & (picture.rgb.max(axis=-1) < 254)
    return Pictures(SRGB_TO_LINEAR[shown] @ LUMINANCE, SRGB_TO_LINEAR[picture.rgb] @ LUMINANCE,
                    position, inner)


def relief_correlation(luminance: np.ndarray, base: np.ndarray, pixels: np.ndarray,
                       closed: np.ndarray, flat: np.ndarray) -> float:
    """The correlation over ``pixels`` of a picture's relief, its luminance over ``base``'s
    (the same camera: the plain bake's picture, whose lightmap holds E(n₀) with the same rays,
    so that the lightmap's own noise cancels; or ``flat`` itself, the closed form's E(n₀)), with
    the closed form's, E(n)/E(n₀) (``closed``, ``flat``: (H, W) the closed form at the mapped
    normals and at n₀); 0 when the picture's relief does not vary (a flat face)."""
    shown = luminance[pixels] / base[pixels]
    expected = closed[pixels] / flat[pixels]
    if np.ptp(shown) == 0:
        return 0.0
    return float(np.corrcoef(shown, expected)[0, 1])


def reliefs(browser, builder, view: View, folder: Path, closed_form, **settings) -> dict:
    """The plain and the directional bake of ``builder`` (an assets scene with a bumped floor,
    ``info["floor_size"]``), each in ``baker view`` and ``baker preview``: the reliefs'
    correlations with ``closed_form(points, normals)`` (``relief_correlation``, over the floor
    pixels lit in both), the renderers' correlation, and the PNG bytes of both bakes' pages."""
    source = saved(builder, folder, "scene.glb")
    shown, report = {}, {}
    for directional in (False, True):
        out = folder / f"{'directional' if directional else 'plain'}.glb"
        result = baker.bake(source, out, baker.Settings(  # the plain bake on the same carrier
            directional=directional, carrier="moz", texel_density=24.0, rays=16, ambient=0.0,
            **settings),
            state=False)
        shown[directional], report[directional] = (pictures(browser, out, view,
                                                            out.with_suffix(".png")),
                                                   result.report)
    plain, mapped = shown[False], shown[True]
    normals = floor_normals(mapped.position, builder.info["floor_size"])
    closed = closed_form(mapped.position, normals)
    flat = closed_form(mapped.position, np.broadcast_to([0.0, 1.0, 0.0], normals.shape))
    pixels = (mapped.floor & plain.floor & (flat > 0.01 * flat.max())
              & (plain.browser > 2e-3) & (plain.preview > 2e-3))
    directional = report[True]["directional"]
    out = {"pixels": int(pixels.sum()),
           "browser, plain": relief_correlation(plain.browser, plain.browser, pixels, closed,
                                                flat),
           "browser": relief_correlation(mapped.browser, plain.browser, pixels, closed, flat),
           "preview": relief_correlation(mapped.preview, plain.preview, pixels, closed, flat),
           "browser, against E(n0)": relief_correlation(mapped.browser, flat, pixels, closed,
                                                        flat),
           "browser ~ preview": float(np.corrcoef(mapped.browser[pixels],
                                                  mapped.preview[pixels])[0, 1]),
           "plain bytes": sum(len(b) for b in page_pngs(folder / "plain.glb")),
           "directional bytes": directional["png_bytes"] + directional["lightmap_png_bytes"]}
    print(out)
    return out


def page_pngs(path: Path) -> list[bytes]:
    """The PNG bytes of every lightmap page image a baked .glb holds."""
    import pygltflib

    document = pygltflib.GLTF2.load(str(path))
    blob, views = document.binary_blob(), document.bufferViews
    return [blob[views[i.bufferView].byteOffset or 0:][:views[i.bufferView].byteLength]
            for i in document.images if "page" in (i.name or "")]
