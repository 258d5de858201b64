"""The seconds numba spends compiling kernels (or loading them from its cache) during a bake.

A ``baker`` process compiles each kernel on its first call: after an install that is seconds of a
first bake, later only the cache's loading. A rebake's "N % of the last full bake" compares
times with this taken out of both, so it says what the rebake saves, not whether the full bake
happened to pay a compile (issue 21 saw 23-33 % printed where the wall-clock ratio was 0.76-0.85).
A process whose kernels were compiled ahead of time (``baker.jit``) imports numba only if one is
missing: the clock listens from then on.
"""

from __future__ import annotations

import threading
import time

import baker.jit as jit

_KIND = "numba:compile"


class CompileClock:
    """Wall time during which some kernel was being compiled, in ``seconds``, while the
    ``with`` block runs: nested compiles (a kernel's callees) and compiles on several threads
    at once count once."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._depth = 0
        self._since = 0.0
        self.seconds = 0.0

    def __enter__(self) -> "CompileClock":
        self._listener = None
        jit.on_numba(self._listen)
        return self

    def __exit__(self, *exc) -> None:
        jit.forget(self._listen)
        if self._listener is not None:
            from numba.core import event

            event.unregister(_KIND, self._listener)

    def _listen(self) -> None:
        """Register with numba's events (numba has started)."""
        from numba.core import event

        clock = self

        class Listener(event.Listener):
            def on_start(self, ev) -> None:
                clock.on_start(ev)

            def on_end(self, ev) -> None:
                clock.on_end(ev)

        self._listener = Listener()
        event.register(_KIND, self._listener)

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
