"""A bake's per-texel results, which a full bake makes a part of the texels at a time.

``bake.compute`` rasterises, probes, traces and composes ``PART_TEXELS`` texels at a time, so
that no stage holds every texel's arrays at once: each part is composed into the pages as it is
done, and its rows go to disk (``spill.py``) for the bake state. ``PerTexel`` gives back the
texels and their results whole, in memory, to whoever asks (tests, ``--error-map``, the
denoiser); ``Tally`` adds up, part by part, what the report needs of them. Each texel's values
do not depend on the parts (its rays are a function of its key), so neither do the bytes.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from functools import cached_property

import numpy as np

from baker.atlas.layout import Atlas
from baker.atlas.rasterise import Coverage, Texels, texels_of
from baker.atlas.validity import STATE_NAMES, Validity
from baker.geometry.surface import luminance
from baker.geometry.world import World
from baker.light.direct import Direct
from baker.light.gi import Indirect
from baker.light.hemisphere import Terms, rmse_of
from baker.run.parallel import even_slices
from baker.run.spill import Spill

# Texels made at once, at most. The part's arrays (texels, probes, the integrator's sums, terms,
# direct light) take about 400 bytes a texel: 100 MB. At 2¹⁹ the 4096² Cornell bake peaked
# 80 MiB higher, at 2²⁰ 300 MiB (bench_memory.py); the trace is no slower in parts of 2¹⁸
# (2.47 s in 3 parts against 2.46 s in one, Cornell 1024², 64 rays). A bake of at most this
# many texels holds them in memory.
PART_TEXELS = 1 << 18


def part_slices(count: int, most: int | None = None) -> list[slice]:
    """The rows of each part of ``count`` texels, in order: as few parts of at most ``most``
    (None: ``PART_TEXELS``; a cluster asks for smaller ones, ``cluster.part_texels``) as will
    do, of equal size (no small last part, whose threads would idle; one empty part for
    none)."""
    return even_slices(count, most or PART_TEXELS) or [slice(0, 0)]


def texel_rows(texels, rows: np.ndarray | slice) -> dict[str, np.ndarray]:
    """The per-texel arrays of ``texels`` (Texels, Terms: a dataclass of per-texel arrays) at
    ``rows``, by field name: every array field but the per-triangle ``triangle_*`` ones and
    empty ones (an absent terminator_push)."""
    return {f.name: value[rows] for f in fields(texels)
            if isinstance(value := getattr(texels, f.name), np.ndarray)
            and not f.name.startswith("triangle_") and len(value)}


def take(texels, rows: np.ndarray | slice):
    """The texels ``rows`` (k,) of ``texels`` (as ``texel_rows``) as one of k rows (the
    per-triangle fields and empty ones kept whole)."""
    return replace(texels, **texel_rows(texels, rows))


@dataclass(frozen=True)
class TexelPoints:
    """What the state keeps of the texels: their coverage (``rasterise.Coverage``: key (N,)
    uint64, owning world triangle (N,) int64, triangle_texels (T,) int64) and where the
    validity probes (and the terminator push) moved their sample points: moved (N,) bool,
    moved_position (N, 3) float64 world, the moved texels' points (0 for the others). The rest
    of ``Texels``, the other sample points included, follows from the stored atlas and the
    scene (``rasterise.texels_of``), bit for bit, without rasterising again; on flat surfaces
    few points move, and the state stores only their rows (``spill.Column.encoding``)."""

    key: np.ndarray
    triangle: np.ndarray
    triangle_texels: np.ndarray
    moved: np.ndarray
    moved_position: np.ndarray

    @classmethod
    def of(cls, texels: Texels, made: np.ndarray) -> "TexelPoints":
        """The points of ``texels``, whose sample points ``texels_of`` made at ``made`` (N, 3)
        before the probes moved some (a point counts as moved if any bit differs)."""
        moved = _moved(texels.position, made)
        return cls(texels.key, texels.triangle, texels.triangle_texels, moved,
                   np.where(moved[:, None], texels.position, 0.0))

    def positions(self, made: np.ndarray) -> np.ndarray:
        """(N, 3) the texels' sample points, from those ``texels_of`` made (N, 3): a copy of
        ``made`` with the moved rows' points (few: a copy and a scatter, not a where)."""
        out = made.copy()
        rows = np.flatnonzero(self.moved)
        out[rows] = self.moved_position[rows]
        return out

    def record(self, rows: np.ndarray, position: np.ndarray, made: np.ndarray) -> None:
        """In place, what ``of`` gives the texels ``rows`` (k,) whose sample points are now
        ``position`` (k, 3), made at ``made`` (k, 3): a rebake probes a few texels again and
        keeps the other rows as they were."""
        moved = _moved(position, made)
        self.moved[rows] = moved
        self.moved_position[rows] = np.where(moved[:, None], position, 0.0)


def _moved(position: np.ndarray, made: np.ndarray) -> np.ndarray:
    """(n,) bool: whether any bit of each point ``position`` (n, 3) differs from ``made``."""
    moved = np.zeros(len(made), bool)
    for c in range(3):  # column by column: numpy reduces a 3-long axis slowly
        moved |= position[:, c].view(np.int64) != made[:, c].view(np.int64)
    return moved


@dataclass
class Tally:
    """What the report needs of every texel, added up part by part (``add``).

    texels: how many; rays: obscurance rays cast; shadow_rays: shadow and sky rays cast;
    states: texels in each validity state, by name; split_square: ``Terms.split_square``
    summed; direct_variance: the sum over texels of the variance of D's luminance; with
    ``--method gi``, indirect_variance the same of E_ind's, the paths traced (gi_paths), their
    rays (gi_rays) and the paths cut at ``gi.MAX_BOUNCES`` (gi_capped); ambient_squares: the
    sum over texels of the squared luminance of I_A·W, which an error of I_A scales
    (``Ambient.relative_variance``); aim_variance: with directional pages, the sum over texels
    of the variance of their first moment U's estimate (``light.directional``; lightmap
    luminance units, the obscurance's at I_A's luminance).
    """

    texels: int = 0
    rays: int = 0
    shadow_rays: int = 0
    states: dict[str, int] = field(default_factory=lambda: dict.fromkeys(STATE_NAMES, 0))
    split_square: float = 0.0
    direct_variance: float = 0.0
    indirect_variance: float = 0.0
    gi_paths: int = 0
    gi_rays: int = 0
    gi_capped: int = 0
    ambient_squares: float = 0.0
    aim_variance: float = 0.0

    def add(self, terms: Terms, direct: Direct | None, validity: Validity,
            r_ave: np.ndarray, indirect: Indirect | None = None,
            intensity: np.ndarray | None = None) -> None:
        """Count the texels of one part (``r_ave``: the R_ave the estimator used; ``intensity``:
        I_A (3,), for ``ambient_squares``)."""
        self.texels += len(terms.counts)
        self.rays += terms.rays
        self.split_square += terms.split_square(r_ave)
        if intensity is not None:
            self.ambient_squares += float(np.sum(
                luminance(terms.obscurance(r_ave) * intensity) ** 2))
        if direct is not None:
            self.shadow_rays += direct.rays
            self.direct_variance += float(np.sum(direct.variance()))
            self.aim_variance += float(np.sum(direct.aim_variance()))
        if indirect is not None and len(indirect.aim):
            self.aim_variance += float(np.sum(indirect.aim_variance))
        elif len(terms.aim_hit) and intensity is not None:
            scale = float(luminance(intensity)) ** 2
            self.aim_variance += scale * float(np.sum(terms.aim_errors(r_ave)))
        if indirect is not None:
            self.indirect_variance += float(np.sum(indirect.variance))
            self.gi_paths += indirect.paths
            self.gi_rays += indirect.rays
            self.gi_capped += indirect.capped
        for name, count in validity.counts().items():
            self.states[name] += count

    def aim_rmse(self) -> float:
        """The RMS over the texels of the standard error of their first moment U."""
        return float(np.sqrt(self.aim_variance / self.texels)) if self.texels else 0.0

    def obscurance_rmse(self) -> float:
        """``Terms.rmse`` over every texel (of W's luminance, R_ave as in ``add``)."""
        return rmse_of(self.split_square, self.texels)


class PerTexel:
    """The texels of a bake and their results — ``Validity``, ``Terms`` and ``Direct`` — held
    in memory (``held``) or on disk (``spilled``), loaded whole on first use."""

    def __init__(self, groups: dict, texels: Texels | None = None,
                 rebuild: tuple[Atlas, World] | None = None, spill: Spill | None = None):
        self._groups, self._texels, self._rebuild, self.spill = groups, texels, rebuild, spill

    @classmethod
    def held(cls, texels: Texels, points: TexelPoints, validity: Validity, terms: Terms,
             direct: Direct | None) -> "PerTexel":
        """Results held in memory (``points``: what the state keeps of ``texels``)."""
        return cls({"texels": points, "validity": validity, "terms": terms, "direct": direct},
                   texels)

    @classmethod
    def spilled(cls, spill: Spill, atlas: Atlas, world: World) -> "PerTexel":
        """Results in ``spill``'s groups "texels" (``TexelPoints``), "validity", "terms" and
        "direct"; the texels are made again from their coverage on ``atlas`` and ``world``."""
        return cls(spill.groups, rebuild=(atlas, world), spill=spill)

    def state_groups(self) -> dict:
        """The per-texel groups of the bake state (``staging.bake_state_writer``), by name: the
        dataclasses, or their spilled rows (``spill.Group``), which are written from disk."""
        return dict(self._groups)

    def close(self) -> None:
        """Remove the rows on disk, if any (what was loaded stays usable)."""
        if self.spill is not None:
            self.spill.close()

    def _group(self, name: str):
        value = self._groups.get(name)
        return value.load() if self.spill is not None and value is not None else value

    @cached_property
    def texels(self) -> Texels:
        if self._texels is not None:
            return self._texels
        points = self._group("texels")
        made = texels_of(*self._rebuild, Coverage(points.key, points.triangle,
                                                  points.triangle_texels))
        return replace(made, position=points.positions(made.position))

    @cached_property
    def coverage(self) -> Coverage:
        """The texels' keys and owning triangles, without making the texels again where
        they went to disk (what the carriers read of them)."""
        texels = self._texels if self._texels is not None else self._group("texels")
        return Coverage(texels.key, texels.triangle, texels.triangle_texels)

    @cached_property
    def validity(self) -> Validity:
        return self._group("validity")

    @cached_property
    def terms(self) -> Terms:
        return self._group("terms")

    @cached_property
    def direct(self) -> Direct | None:
        return self._group("direct")
