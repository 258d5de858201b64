"""The sampler dimensions: one table, and no two estimators drawing the same numbers.

Two estimators that share a dimension of one stream with the same keys get the same random
numbers, so their errors stop being independent (with 13 lights, light 12's shadow rays once
used the GI's first-bounce dimension). These tests check the table for any number of lights and
bounces, and that no module keeps a dimension of its own outside it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import pytest

from baker.rays import dimensions
from baker.rays.dimensions import (ALPHA, EMISSIVE, FOLIAGE_FIT, GI_EMITTER, GI_FIRST, MATERIAL,
                                   MATERIAL_STRIDE, OBSCURANCE, POWER, POWER_TRACED, SKY,
                                   SUPERSAMPLE, alpha_dimension, light_dimension,
                                   material_dimension)
from baker.rays.trace import MAX_CONTINUATIONS

PACKAGE = Path(__file__).resolve().parents[1] / "baker"


@dataclass(frozen=True)
class Range:
    """Dimensions ``start`` … ``stop − 1`` of ``stream``, owned by ``owner``."""

    owner: str
    stream: str
    start: int
    stop: int


def ranges(lights: int, max_depth: int, continuations: int) -> list[Range]:
    """Every range of ``baker.rays.dimensions`` in use by a bake with ``lights`` punctual
    lights, material chains of at most ``max_depth`` bounces and ``continuations`` alpha-test
    steps a ray (a range added there is added here)."""
    table = [Range("obscurance", "sobol", OBSCURANCE, OBSCURANCE + 1),
             Range("supersample", "sobol", SUPERSAMPLE, SUPERSAMPLE + 1),
             Range("power", "sobol", POWER[0], POWER[1] + 1),
             Range("sky", "sobol", SKY, SKY + 1),
             Range("emissive", "sobol", EMISSIVE, EMISSIVE + 1),
             Range("traced power", "sobol", POWER_TRACED[0], POWER_TRACED[1] + 1),
             Range("gi", "sobol", GI_FIRST, GI_EMITTER + 1)]
    table += [Range(f"light {l}", "sobol", light_dimension(l), light_dimension(l) + 1)
              for l in range(lights)]
    table += [Range("foliage fit", "uniform", FOLIAGE_FIT, FOLIAGE_FIT + 1),
              Range("material", "uniform", MATERIAL,
                    material_dimension(max_depth) + MATERIAL_STRIDE),
              Range("alpha", "ray", ALPHA, alpha_dimension(continuations))]
    return table


def _overlaps(table):
    """Pairs of ranges of one stream that share a dimension."""
    found = []
    for i, a in enumerate(table):
        for b in table[i + 1:]:
            if a.stream == b.stream and a.start < b.stop and b.start < a.stop:
                found.append((a, b))
    return found


@pytest.mark.parametrize("lights", [0, 1, 11, 12, 13, 40, 300, 5000])
@pytest.mark.parametrize("max_depth", [1, 16, 200])
def test_no_two_ranges_of_a_stream_overlap(lights, max_depth):
    table = ranges(lights, max_depth, MAX_CONTINUATIONS)
    assert all(r.start < r.stop for r in table)
    assert _overlaps(table) == []


def test_the_checker_finds_an_overlap():
    """The layout before the table (16 + 2l for every light) is caught at light 12."""
    table = [Range("gi", "sobol", dimensions.GI_FIRST, dimensions.GI_EMITTER + 1)]
    table += [Range(f"light {l}", "sobol", 16 + 2 * l, 17 + 2 * l) for l in range(13)]
    assert [(a.owner, b.owner) for a, b in _overlaps(table)] == [("gi", "light 12")]


def test_lights_before_the_twelfth_keep_their_dimensions():
    """Bakes of scenes with fewer than 13 lights give the bytes they gave before the table."""
    assert [dimensions.light_dimension(l) for l in range(12)] == list(range(16, 40, 2))


def test_the_uniform_stream_never_takes_a_scramble_word():
    """sample_2d's scrambles hash (seed, key, dimension, j) with j ≤ 4; the uniform stream hashes
    (seed, key, sample, dimension): its dimensions must never be such a j."""
    assert dimensions.MATERIAL > 4 and dimensions.FOLIAGE_FIT > 4


def test_no_module_keeps_a_dimension_of_its_own():
    """Every `X_DIMENSION = <number>` lives in the table, not beside its estimator."""
    pattern = re.compile(r"^\s*_?[A-Z_]*DIMENSIONS?\s*=\s*[\d(]", re.M)
    strays = [str(p.relative_to(PACKAGE)) for p in PACKAGE.rglob("*.py")
              if p.name != "dimensions.py" and pattern.search(p.read_text())]
    assert strays == []
