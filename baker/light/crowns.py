"""Closed-form visibility of foliage (Hegeman, Premože, Ashikhmin & Drettakis, "Approximate
Ambient Occlusion for Trees", I3D 2006), and the shells that stand for a crown.

A crown is a cloud of leaves inside a shell: a sphere, or an ellipsoid that an affine map turns
into the unit sphere. For a point x with unit normal n, the plane through x cuts from the sphere
(centre c, radius R) a cap of height h on the side n points to, and the cap's centre lies off x
by d in that plane:

    h = clip(R − (x − c)·n, 0, 2R)        d = |(x − c) − ((x − c)·n) n|
    V_cap = π h² (3R − h) / 3             f = h² / (h² + d²)
    V = exp(−αρ f V_cap)                  (αρ: the leaves' density × a constant, per world unit³)

Seen from outside (the ground, a house) a crown of radius r at distance d occludes the solid
angle A_SA = π (r/d)², so V = 1 − A_SA / 2π. Inside a grass layer of height h, at height P_z,
with the normal at θ from the vertical, V = (P_z / 2h)(1 + cos θ).

Everything here is a vectorised function of arrays; ``fit_shells`` fits the shells of a crown's
points and ``fit_density`` the αρ that makes V match visibilities traced at a few texels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from baker.rowwise import matmul_rows

SHELLS_MAX = 8
"""Most shells one crown is split into."""
SPLIT_GAIN = 0.7
"""A crown is split into one more shell when that shrinks the shells' total volume below this
fraction of what it was (k-means on the points; a compact crown does not gain: the two
ellipsoids enclosing the halves of a ball hold more than the ball)."""
_FIT_POINTS = 1 << 15  # points the k-means sees at most (every point is enclosed after)


def cap_volume(h: np.ndarray, radius: np.ndarray | float) -> np.ndarray:
    """(k,) volume π h² (3R − h) / 3 of the caps of height ``h`` (k,), clipped to [0, 2R], of
    spheres of radius ``radius`` (same units; volume in their cube)."""
    h = np.clip(h, 0.0, 2.0 * np.asarray(radius, np.float64))
    return np.pi * h * h * (3.0 * radius - h) / 3.0


def cap_of(offset: np.ndarray, normal: np.ndarray, radius: np.ndarray | float
           ) -> tuple[np.ndarray, np.ndarray]:
    """(h, d), each (k,): the height of the cap that the plane through each point cuts from its
    sphere on the normal's side, and how far off the point the cap's centre lies in that plane.
    offset: (k, 3) point − sphere centre; normal: (k, 3) unit normals; radius: R."""
    along = np.einsum("ij,ij->i", offset, normal)
    h = np.clip(radius - along, 0.0, 2.0 * np.asarray(radius, np.float64))
    d = np.linalg.norm(offset - along[:, None] * normal, axis=1)
    return h, d


def cap_factor(h: np.ndarray, d: np.ndarray) -> np.ndarray:
    """(k,) f = h² / (h² + d²): 1 where the point faces the crown's centre, falling off with the
    cap's offset d; 0 where there is no cap (h = 0)."""
    h2 = h * h
    total = h2 + d * d
    return np.divide(h2, total, out=np.zeros_like(h2), where=total > 0)


def crown_visibility(density: np.ndarray | float, f: np.ndarray, v_cap: np.ndarray
                     ) -> np.ndarray:
    """(k,) V = exp(−αρ f V_cap): the unoccluded fraction of the hemisphere inside a crown of
    density αρ (per unit of V_cap's volume)."""
    return np.exp(-np.asarray(density, np.float64) * f * v_cap)


def large_occluder_visibility(radius: np.ndarray | float, distance: np.ndarray) -> np.ndarray:
    """(k,) V = 1 − A_SA / 2π, A_SA = π (r/d)², the crown of radius r seen from distance d (the
    solid angle of a far sphere); clipped to [0, 1] (a point on or inside the shell: 0)."""
    ratio = np.asarray(radius, np.float64) / np.maximum(distance, 1e-300)
    solid_angle = np.pi * ratio * ratio
    return np.clip(1.0 - solid_angle / (2.0 * np.pi), 0.0, 1.0)


def grass_visibility(height: np.ndarray, layer: np.ndarray | float, cos_theta: np.ndarray
                     ) -> np.ndarray:
    """(k,) V = (P_z / 2h)(1 + cos θ) at height P_z (``height``, clipped to [0, h]) in a grass
    layer of height h (``layer``), the normal at θ from the vertical."""
    layer = np.asarray(layer, np.float64)
    pz = np.clip(height, 0.0, layer)
    return pz / (2.0 * layer) * (1.0 + np.clip(cos_theta, -1.0, 1.0))


@dataclass(frozen=True)
class Shell:
    """An ellipsoid: the points c + axesᵀ (radii · q) for |q| ≤ 1. center (3,) world; axes (3, 3)
    orthonormal rows (its principal directions); radii (3,) world units along them (all equal:
    a sphere)."""

    center: np.ndarray
    axes: np.ndarray
    radii: np.ndarray

    @property
    def volume(self) -> float:
        return float(4.0 / 3.0 * np.pi * np.prod(self.radii))

    @property
    def radius(self) -> float:
        """The radius of the sphere of the same volume (for the large-occluder term)."""
        return float(np.prod(self.radii) ** (1.0 / 3.0))

    def to_unit(self, points: np.ndarray) -> np.ndarray:
        """(k, 3) ``points`` (k, 3) world in the frame where the shell is the unit sphere."""
        return matmul_rows(points - self.center, self.axes.T) / self.radii

    def normals_to_unit(self, normals: np.ndarray) -> np.ndarray:
        """(k, 3) unit normals in the unit-sphere frame (the inverse transpose of ``to_unit``:
        a plane through a point stays the plane through its image)."""
        mapped = matmul_rows(normals, self.axes.T) * self.radii
        return mapped / np.maximum(np.linalg.norm(mapped, axis=1, keepdims=True), 1e-300)

    def as_dict(self) -> dict:
        return {"center": self.center.tolist(), "radii": self.radii.tolist(),
                "axes": self.axes.tolist()}


def shell_terms(shell: Shell, points: np.ndarray, normals: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """(f, V_cap), each (k,), of ``points`` (k, 3) with unit ``normals`` (k, 3) in ``shell``:
    the cap is cut in the unit-sphere frame and its volume scaled back to world units³ (an
    affine map keeps ratios of volumes, and planes stay planes), so for a sphere these are
    exactly πh²(3R − h)/3 and h²/(h² + d²) in world units."""
    h, d = cap_of(shell.to_unit(points), shell.normals_to_unit(normals), 1.0)
    return cap_factor(h, d), cap_volume(h, 1.0) * float(np.prod(shell.radii))


def _principal_axes(points: np.ndarray, center: np.ndarray) -> np.ndarray:
    """(3, 3) orthonormal rows: the points' principal directions, largest spread first, each
    signed so that its largest component is positive (the same axes for the same points)."""
    spread = points - center
    _, vectors = np.linalg.eigh(spread.T @ spread)
    axes = vectors[:, ::-1].T.copy()
    flip = axes[np.arange(3), np.argmax(np.abs(axes), axis=1)] < 0
    axes[flip] *= -1.0
    return axes


def enclosing_shell(points: np.ndarray) -> Shell:
    """The smaller of two shells enclosing every one of ``points`` (n, 3) world: the sphere about
    their mean, and the ellipsoid along their principal axes with radii in proportion to the
    points' spread (scaled until the farthest point is on it)."""
    center = points.mean(axis=0)
    radius = max(float(np.linalg.norm(points - center, axis=1).max()), 1e-9)
    sphere = Shell(center, np.eye(3), np.full(3, radius))
    axes = _principal_axes(points, center)
    local = matmul_rows(points - center, axes.T)
    spread = np.maximum(local.std(axis=0), 1e-6 * radius)
    scale = float(np.linalg.norm(local / spread, axis=1).max())
    ellipsoid = Shell(center, axes, np.maximum(spread * scale, 1e-9))
    return ellipsoid if ellipsoid.volume < sphere.volume else sphere


def nearest_shell(shells: list[Shell], points: np.ndarray) -> np.ndarray:
    """(n,) int64 index of the shell each of ``points`` (n, 3) is nearest to, measured in each
    shell's unit-sphere frame (|q|: 1 on its surface), the first on ties."""
    reach = np.stack([np.linalg.norm(s.to_unit(points), axis=1) for s in shells], axis=1)
    return np.argmin(reach, axis=1)


def _kmeans(points: np.ndarray, k: int, rounds: int = 25) -> np.ndarray:
    """(n,) int64 cluster of each point: Lloyd's iterations from farthest-point seeds (the first
    the point farthest from the mean), deterministic for the same points."""
    seeds = [int(np.argmax(np.linalg.norm(points - points.mean(axis=0), axis=1)))]
    gap = np.linalg.norm(points - points[seeds[0]], axis=1)
    for _ in range(1, k):
        seeds.append(int(np.argmax(gap)))
        gap = np.minimum(gap, np.linalg.norm(points - points[seeds[-1]], axis=1))
    centres = points[seeds]
    label = np.zeros(len(points), np.int64)
    for _ in range(rounds):
        distance = ((points[:, None, :] - centres[None, :, :]) ** 2).sum(axis=2)
        label = np.argmin(distance, axis=1)
        counts = np.bincount(label, minlength=k)
        sums = np.stack([np.bincount(label, points[:, c], minlength=k) for c in range(3)], axis=1)
        centres = np.where(counts[:, None] > 0, sums / np.maximum(counts, 1)[:, None], centres)
    return label


def _shells_of(points: np.ndarray, label: np.ndarray, k: int) -> list[Shell] | None:
    """One enclosing shell per cluster; None when a cluster has fewer than 4 points."""
    groups = [points[label == j] for j in range(k)]
    if min(len(g) for g in groups) < 4:
        return None
    return [enclosing_shell(g) for g in groups]


def fit_shells(points: np.ndarray, most: int = SHELLS_MAX) -> list[Shell]:
    """The shells of a crown of leaf points (n, 3) world: one enclosing shell, split into k + 1
    by k-means while that shrinks their total volume below ``SPLIT_GAIN`` of the k shells' (up
    to ``most``). Each point then belongs to its nearest shell (``nearest_shell``), and every
    shell is grown to enclose its points."""
    points = np.asarray(points, np.float64)
    sample = points[::max(1, len(points) // _FIT_POINTS)]
    shells = [enclosing_shell(sample)]
    for k in range(2, most + 1):
        split = _shells_of(sample, _kmeans(sample, k), k)
        if split is None or sum(s.volume for s in split) > SPLIT_GAIN * sum(s.volume for s in shells):
            break
        shells = split
    return _enclose(shells, points)


def _enclose(shells: list[Shell], points: np.ndarray) -> list[Shell]:
    """``shells`` each scaled (about its centre) just enough to hold the points nearest to it."""
    owner = nearest_shell(shells, points)
    out = []
    for j, shell in enumerate(shells):
        mine = points[owner == j]
        reach = float(np.linalg.norm(shell.to_unit(mine), axis=1).max()) if len(mine) else 1.0
        out.append(Shell(shell.center, shell.axes, shell.radii * max(reach, 1.0)))
    return out


@dataclass(frozen=True)
class DensityFit:
    """αρ fitted by least squares on V (``fit_density``): density (per world unit³), the RMS of
    V's residual at the fit's points, and how many points it saw."""

    density: float
    residual: float
    count: int


def fit_density(g: np.ndarray, visibility: np.ndarray) -> DensityFit:
    """The αρ ≥ 0 minimising Σ (exp(−αρ g_i) − V_i)², g = f·V_cap (k,) and V (k,) the traced
    visibilities: a dense scan of log αρ over 12 decades about 1/mean(g), then golden-section
    search in the best bracket (the sum is smooth in αρ; the scan finds the right valley)."""
    g, visibility = np.asarray(g, np.float64), np.asarray(visibility, np.float64)
    if not len(g) or not (g > 0).any():
        return DensityFit(0.0, float(np.sqrt(np.mean((1.0 - visibility) ** 2))) if len(g) else 0.0,
                          len(g))
    scale = 1.0 / float(g[g > 0].mean())

    def cost(log_density: np.ndarray) -> np.ndarray:
        density = np.exp(np.atleast_1d(log_density))[:, None]
        return ((np.exp(-density * g[None, :]) - visibility[None, :]) ** 2).sum(axis=1)

    grid = np.log(scale) + np.linspace(-6.0, 6.0, 241) * np.log(10.0)
    best = int(np.argmin(cost(grid)))
    lo, hi = grid[max(best - 1, 0)], grid[min(best + 1, len(grid) - 1)]
    ratio = (np.sqrt(5.0) - 1.0) / 2.0
    for _ in range(60):
        a, b = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
        if cost(a)[0] < cost(b)[0]:
            hi = b
        else:
            lo = a
    log_density = 0.5 * (lo + hi)
    residual = float(np.sqrt(cost(log_density)[0] / len(g)))
    return DensityFit(float(np.exp(log_density)), residual, len(g))
