"""Running a call in a forked child process, so that a crash there is retried, not the end.

xatlas's task scheduler has a data race: a worker thread takes a pointer into a task queue,
lets go of the queue's lock and only then reads the task, while another thread may be pushing a
task that makes the queue reallocate (``TaskScheduler::workerThread`` and ``run`` in xatlas.cpp).
The worker then calls a stale function pointer: SIGSEGV in an xatlas worker, seen in 1 of 9
fresh-clone CI runs here and in 2 runs with numba's bounds checks on (gdb: ``?? ()`` called
from ``TaskScheduler::workerThread``, the main thread in ``AddMeshJoin``).
The same race can leave a task unfinished, so that xatlas waits for it for ever (a fuzzed bake
of a few triangles once ran past the test's 20 s). ``unwrap.py`` runs xatlas through
``call_forked``: the child is forked (copy-on-write, so the inputs cost nothing to pass), its
result comes back pickled through a pipe, and a child killed by a signal, or running far longer
than its work can take, is killed and run again — xatlas's result does not depend on its
threads' timing. Where ``os.fork`` is missing (Windows) the call runs in this process,
unprotected.
"""

from __future__ import annotations

import ctypes
import os
import pickle
import select
import signal
import sys
import time
import warnings
from typing import Any, Callable

from baker.errors import BakerError

ATTEMPTS = 3  # runs of a call whose child died of a signal or hung, before giving up


class ChildCrashed(BakerError):
    """Every attempt at a forked call died of a signal or hung."""


def call_forked(function: Callable[[], Any], what: str, seconds: float) -> Any:
    """``function()`` run in a forked child: its value, or the exception it raised, raised here
    (as RuntimeError when it cannot be pickled). A child killed by a signal, or still running
    after ``seconds``, is killed and run again, up to ``ATTEMPTS`` times; then ChildCrashed
    names ``what`` was being done. Ctrl-C here kills the child. Without ``os.fork``,
    ``function()`` is simply called."""
    if not hasattr(os, "fork") or not sys.platform.startswith("linux"):
        return function()
    failures = []
    for _ in range(ATTEMPTS):
        outcome = _attempt(function, seconds)
        if isinstance(outcome, str):
            failures.append(outcome)
            continue
        ok, value = outcome
        if ok:
            return value
        raise value
    raise ChildCrashed(f"{what} crashed {ATTEMPTS} times in a row ({', '.join(failures)})",
                       fix="run the bake again; if it keeps crashing, report it with the scene")


def _attempt(function: Callable[[], Any], seconds: float) -> tuple[bool, Any] | str:
    """One forked run: (True, value) or (False, exception), or why the child was lost: the
    name of the signal that killed it, or that it ran past ``seconds`` (it is killed)."""
    _trim_heap()
    read, write = os.pipe()
    with warnings.catch_warnings():  # Python 3.12+ warns of forking a threaded process: the
        warnings.simplefilter("ignore", DeprecationWarning)  # child only runs ``function``
        pid = os.fork()
    if pid == 0:
        _child(function, read, write)
    os.close(write)
    try:
        data = _read_until(read, time.monotonic() + seconds)
    except BaseException:  # Ctrl-C while the child runs: it goes too
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        raise
    finally:
        os.close(read)
    if data is None:
        os.kill(pid, signal.SIGKILL)
    _, status = os.waitpid(pid, 0)
    if data is None:
        return f"still running after {seconds:.0f} s"
    if os.WIFSIGNALED(status):
        return signal.Signals(os.WTERMSIG(status)).name
    try:
        return pickle.loads(data)
    except Exception as error:  # a child that exited without a whole answer
        return False, RuntimeError(f"the forked call gave no usable result ({error!r})")


def _read_until(fd: int, deadline: float) -> bytes | None:
    """All of pipe ``fd`` up to its end, or None if it has not ended by ``deadline``
    (``time.monotonic``)."""
    parts = []
    while True:
        left = deadline - time.monotonic()
        if left <= 0 or not select.select([fd], [], [], left)[0]:
            return None
        part = os.read(fd, 1 << 20)
        if not part:
            return b"".join(parts)
        parts.append(part)


def _trim_heap() -> None:
    """Give the memory malloc holds free back to the system before forking (glibc's
    ``malloc_trim``): pages shared with the child are copied on the parent's next write to them,
    a page fault each, and freed blocks that malloc keeps (arrays of earlier bakes in this
    process) would otherwise be shared too."""
    try:
        ctypes.CDLL(None).malloc_trim(0)
    except (OSError, AttributeError):  # not glibc: nothing to trim this way
        pass


def _child(function: Callable[[], Any], read: int, write: int) -> None:
    """In the child: run ``function``, write the pickled outcome to ``write``, exit at once
    (no cleanup of the parent's state: ``os._exit``)."""
    try:
        os.close(read)
        signal.signal(signal.SIGINT, signal.SIG_DFL)  # Ctrl-C ends the child, not a traceback
        try:
            outcome: tuple[bool, Any] = (True, function())
        except BaseException as error:
            outcome = (False, error)
        try:
            data = pickle.dumps(outcome, protocol=pickle.HIGHEST_PROTOCOL)
        except Exception:
            data = pickle.dumps((False, RuntimeError(repr(outcome[1]))))
        with os.fdopen(write, "wb") as pipe:
            pipe.write(data)
    finally:
        os._exit(0)
