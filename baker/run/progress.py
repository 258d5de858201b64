"""A progress bar with ETA on a terminal, silent in pipelines, CI and with ``quiet``.

tqdm does the drawing: it is small, well kept, and handles terminal widths and ETA smoothing
better than code of our own would.
"""

from __future__ import annotations

import os
import sys
from contextlib import contextmanager
from typing import Callable, Iterator

from tqdm import tqdm


def wanted(quiet: bool) -> bool:
    """Whether to draw a bar: not when asked to be quiet, not in CI, only on a terminal."""
    return not quiet and not os.environ.get("CI") and sys.stderr.isatty()


@contextmanager
def bar(total: int, label: str, show: bool) -> Iterator[Callable[[int], None]]:
    """Yield an ``advance(n)`` callback; draws a bar of ``total`` units when ``show``."""
    if not show:
        yield lambda n: None
        return
    with tqdm(total=total, desc=label, unit="texel", unit_scale=True, leave=False,
              dynamic_ncols=True) as t:
        yield t.update
