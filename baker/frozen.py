"""Hand-offs that cannot be changed: the arrays of a stage's frozen result made read-only.

``dataclass(frozen=True)`` stops a field from being rebound, not its array from being written.
The geometry a bake hands from stage to stage (the world, the atlas, which triangle owns each
texel) is read by every later stage and written by none; ``read_only`` makes numpy enforce
that, so that a stage that wrote into another's result fails where it writes. The per-texel
results (texels, terms, direct light, validity) stay writable: the rebake merges fresh rows
into the stored ones (``rebake.rows.merge``), and its dirty search (``rebake.dirty.Search``)
owns the texels whose sample points the probes move.
"""

from __future__ import annotations

import dataclasses

import numpy as np


def read_only(result) -> None:
    """Make every numpy array of the dataclass ``result``'s fields read-only, those in tuples
    of arrays too (``World.texcoords``). Call it from ``__post_init__``."""
    for field in dataclasses.fields(result):
        value = getattr(result, field.name)
        for array in value if isinstance(value, tuple) else (value,):
            if isinstance(array, np.ndarray):
                array.flags.writeable = False
