"""The seconds numba spends compiling kernels (or loading them from its cache) during a bake.

A ``baker`` process compiles each kernel on its first call: after an install that is seconds of a
first bake, later only the cache's loading. A rebake's "N % of the last full bake" compares
times with this taken out of both, so it says what the rebake saves, not whether the full bake
happened to pay a compile (issue 21 saw 23-33 % printed where the wall-clock ratio was 0.76-0.85).
"""

from __future__ import annotations

import threading
import time

from numba.core import event

_KIND = "numba:compile"


class CompileClock(event.Listener):
    """Wall time during which some kernel was being compiled, in ``seconds``, while the
    ``with`` block runs: nested compiles (a kernel's callees) and compiles on several threads
    at once count once."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._depth = 0
        self._since = 0.0
        self.seconds = 0.0

    def __enter__(self) -> "CompileClock":
        event.register(_KIND, self)
        return self

    def __exit__(self, *exc) -> None:
        event.unregister(_KIND, self)

    def on_start(self, ev) -> None:
        with self._lock:
            if self._depth == 0:
                self._since = time.perf_counter()
            self._depth += 1

    def on_end(self, ev) -> None:
        with self._lock:
            self._depth -= 1
            if self._depth == 0:
                self.seconds += time.perf_counter() - self._since
