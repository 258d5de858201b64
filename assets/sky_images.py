"""Equirectangular sky panoramas with closed forms, for ``--sky-image`` tests and benchmarks.

Each function returns (H, W, 3) float64 linear radiance laid out as baker reads a sky image
(``baker/light/sky.py``: top row +Y, column u at azimuth 2π(u − ½) from +X towards +Z);
``save_hdr`` writes one as a Radiance file.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from baker.image.hdr import hdr_bytes


def directions(height: int) -> np.ndarray:
    """(H, 2H, 3) the unit direction through each pixel's centre."""
    width = 2 * height
    polar = np.pi * (np.arange(height) + 0.5) / height
    azimuth = 2.0 * np.pi * ((np.arange(width) + 0.5) / width - 0.5)
    p, a = np.meshgrid(polar, azimuth, indexing="ij")
    return np.stack([np.sin(p) * np.cos(a), np.cos(p), np.sin(p) * np.sin(a)], axis=-1)


def constant(radiance, height: int = 32) -> np.ndarray:
    """The same radiance (3,) everywhere."""
    return np.broadcast_to(np.asarray(radiance, np.float64), (height, 2 * height, 3)).copy()


def upper_half(radiance, height: int = 32, azimuth_half: bool = False) -> np.ndarray:
    """``radiance`` (3,) above the horizon (and, with ``azimuth_half``, only where x > 0), black
    elsewhere. An open floor under it gets π·L (π·L/2 with the azimuth half); a wall facing +X
    gets π·L/2 either way, one facing −X π·L/2 or 0."""
    d = directions(height)
    bright = d[..., 1] > 0
    if azimuth_half:
        bright &= d[..., 0] > 0
    return np.where(bright[..., None], np.asarray(radiance, np.float64), 0.0)


def sun(elevation_degrees: float = 50.0, azimuth_degrees: float = 30.0,
        radius_degrees: float = 1.0, sun_radiance: float = 2.0e4, sky: float = 0.3,
        ground: float = 0.1, height: int = 512) -> np.ndarray:
    """A small bright disc (the sun: ``radius_degrees``, ``sun_radiance``) at the given elevation
    and azimuth (from +X towards +Z), over a uniform sky above the horizon and a darker ground."""
    d = directions(height)
    e, a = math.radians(elevation_degrees), math.radians(azimuth_degrees)
    centre = np.array([math.cos(e) * math.cos(a), math.sin(e), math.cos(e) * math.sin(a)])
    inside = d @ centre >= math.cos(math.radians(radius_degrees))
    grey = np.where(d[..., 1] > 0, sky, ground)
    return np.repeat(np.where(inside, sun_radiance, grey)[..., None], 3, axis=-1)


def save_hdr(image: np.ndarray, path: Path) -> Path:
    """Write ``image`` as a Radiance .hdr file at ``path``; returns the path."""
    path.write_bytes(hdr_bytes(image))
    return path
