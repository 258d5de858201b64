"""Running a call in a forked child process, so that a crash there is retried, not the end.

xatlas's task scheduler has a data race: a worker thread takes a pointer into a task queue,
lets go of the queue's lock and only then reads the task, while another thread may be pushing a
task that makes the queue reallocate (``TaskScheduler::workerThread`` and ``run`` in xatlas.cpp).
The worker then calls a stale function pointer: SIGSEGV in an xatlas worker, seen in 2 of about
12 runs of the test suite here (gdb: ``?? ()`` called from ``TaskScheduler::workerThread``).
``unwrap.py`` runs xatlas through ``call_forked``: the child is forked (copy-on-write, so the
inputs cost nothing to pass), its result comes back pickled through a pipe, and a child killed
by a signal is run again — xatlas's result does not depend on its threads' timing. Where
``os.fork`` is missing (Windows) the call runs in this process, unprotected.
"""

from __future__ import annotations

import ctypes
import os
import pickle
import signal
import sys
import warnings
from typing import Any, Callable

from .errors import BakerError

ATTEMPTS = 3  # runs of a call whose child was killed by a signal, before giving up


class ChildCrashed(BakerError):
    """Every attempt at a forked call died of a signal."""


def call_forked(function: Callable[[], Any], what: str) -> Any:
    """``function()`` run in a forked child: its value, or the exception it raised, raised here
    (as RuntimeError when it cannot be pickled). A child killed by a signal is run again, up to
    ``ATTEMPTS`` times, then ChildCrashed names ``what`` was being done. Ctrl-C here kills the
    child. Without ``os.fork``, ``function()`` is simply called."""
    if not hasattr(os, "fork") or not sys.platform.startswith("linux"):
        return function()
    signals = []
    for _ in range(ATTEMPTS):
        outcome = _attempt(function)
        if isinstance(outcome, int):
            signals.append(signal.Signals(outcome).name)
            continue
        ok, value = outcome
        if ok:
            return value
        raise value
    raise ChildCrashed(f"{what} crashed {ATTEMPTS} times in a row ({', '.join(signals)})",
                       fix="run the bake again; if it keeps crashing, report it with the scene")


def _attempt(function: Callable[[], Any]) -> tuple[bool, Any] | int:
    """One forked run: (True, value) or (False, exception), or the number of the signal that
    killed the child."""
    _trim_heap()
    read, write = os.pipe()
    with warnings.catch_warnings():  # Python 3.12+ warns of forking a threaded process: the
        warnings.simplefilter("ignore", DeprecationWarning)  # child only runs ``function``
        pid = os.fork()
    if pid == 0:
        _child(function, read, write)
    os.close(write)
    try:
        with os.fdopen(read, "rb") as pipe:
            data = pipe.read()
    except BaseException:  # Ctrl-C while the child runs: it goes too
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        raise
    _, status = os.waitpid(pid, 0)
    if os.WIFSIGNALED(status):
        return os.WTERMSIG(status)
    try:
        return pickle.loads(data)
    except Exception as error:  # a child that exited without a whole answer
        return False, RuntimeError(f"the forked call gave no usable result ({error!r})")


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
