"""``run.compile_clock``: the seconds numba spends compiling during a block, which the rebake's
"N % of the last full bake" takes out of both times."""

from __future__ import annotations

import threading
import time

import numba
import numpy as np

from baker.run.compile_clock import CompileClock


def _new_kernel():
    """A kernel numba has not compiled yet (no cache: each call of this makes a new one)."""
    @numba.njit(cache=False)
    def inner(x):
        return x * 2.0

    @numba.njit(cache=False)
    def outer(a):
        total = 0.0
        for v in a:
            total += inner(v)
        return total

    return outer


def test_a_first_call_is_timed_and_a_second_is_not():
    kernel, data = _new_kernel(), np.arange(10.0)
    with CompileClock() as clock:
        started = time.perf_counter()
        assert kernel(data) == 90.0
        wall = time.perf_counter() - started
    first = clock.seconds
    assert 0.01 < first <= wall  # nested (outer compiles inner) counted once, within the call
    with CompileClock() as again:
        kernel(data)
    assert again.seconds == 0.0


def test_compiles_on_two_threads_at_once_count_their_union():
    kernels, data = [_new_kernel(), _new_kernel()], np.arange(10.0)
    with CompileClock() as clock:
        started = time.perf_counter()
        threads = [threading.Thread(target=k, args=(data,)) for k in kernels]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        wall = time.perf_counter() - started
    assert 0.01 < clock.seconds <= wall


def test_the_clock_stops_listening_after_its_block():
    with CompileClock() as clock:
        pass
    _new_kernel()(np.arange(3.0))
    assert clock.seconds == 0.0


def test_a_full_bake_records_its_time_without_its_compile(tmp_path, monkeypatch):
    """The full bake's recorded seconds are its wall time less what the clock measured (here a
    compile of 0.01 s, as the clock reports it: less than the bake itself takes on a quiet
    machine, where a record of 0 s or less would be dropped), so a rebake compares warm with
    warm."""
    import baker
    import baker.api as api
    from assets.make_scenes import cornell_box

    class Compiled(CompileClock):
        def __enter__(self):
            super().__enter__()
            self.seconds = 0.01
            return self

    monkeypatch.setattr(api, "CompileClock", Compiled)
    scene = cornell_box().save(tmp_path / "box.glb")
    out = tmp_path / "out.glb"
    started = time.perf_counter()
    result = baker.bake(scene, out, baker.Settings(rays=4, page_size=64))
    wall = time.perf_counter() - started
    recorded = baker.rebake.state.last_full_bake_seconds(baker.rebake.state.default_path(out))
    assert recorded is not None and recorded <= result.seconds - 0.01 + 0.001
    assert result.seconds <= wall
