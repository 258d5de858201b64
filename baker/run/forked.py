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
    return call_forked_together([function], what, seconds)[0]


def call_forked_together(functions: list[Callable[[], Any]], what: str, seconds: float
                         ) -> list[Any]:
    """Every function of ``functions`` run as ``call_forked`` runs one, each in its own child
    and all at once (one per core would be busy), ``seconds`` for each: their values in order.
    A crashed or hung child is run again on its own; the first error raised ends them all."""
    if not hasattr(os, "fork") or not sys.platform.startswith("linux"):
        return [function() for function in functions]
    values: dict[int, Any] = {}
    failures: dict[int, list[str]] = {i: [] for i in range(len(functions))}
    pending = list(range(len(functions)))
    while pending:
        outcomes = _attempts([functions[i] for i in pending], seconds)
        for i, outcome in zip(pending, outcomes):
            if isinstance(outcome, str):
                failures[i].append(outcome)
            elif outcome[0]:
                values[i] = outcome[1]
            else:
                raise outcome[1]
        lost = [i for i in pending if i not in values]
        for i in lost:
            if len(failures[i]) >= ATTEMPTS:
                raise ChildCrashed(f"{what} crashed {ATTEMPTS} times in a row "
                                   f"({', '.join(failures[i])})",
                                   fix="run the bake again; if it keeps crashing, report it "
                                       "with the scene")
        pending = lost
    return [values[i] for i in range(len(functions))]


def _attempts(functions: list[Callable[[], Any]], seconds: float) -> list[tuple[bool, Any] | str]:
    """One forked run of each function, all at once: per function (True, value) or (False,
    exception), or why its child was lost: the name of the signal that killed it, or that it
    ran past ``seconds`` (it is killed)."""
    _trim_heap()
    children = []  # (pid, read end of its pipe)
    try:
        for function in functions:
            read, write = os.pipe()
            with warnings.catch_warnings():  # Python 3.12+ warns of forking a threaded
                warnings.simplefilter("ignore", DeprecationWarning)  # process: the child
                pid = os.fork()  # only runs ``function``
            if pid == 0:
                _child(function, read, write)
            os.close(write)
            children.append((pid, read))
        data = _read_until([read for _, read in children], time.monotonic() + seconds)
    except BaseException:  # Ctrl-C while the children run: they go too
        for pid, _ in children:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        raise
    finally:
        for _, read in children:
            os.close(read)
    return [_outcome(pid, got, seconds) for (pid, _), got in zip(children, data)]


def _outcome(pid: int, data: bytes | None, seconds: float) -> tuple[bool, Any] | str:
    """What child ``pid`` gave, from the whole of its pipe ``data`` (None: it did not end in
    ``seconds``, and is killed now); the child is reaped."""
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


def _read_until(fds: list[int], deadline: float) -> list[bytes | None]:
    """All of each pipe of ``fds`` up to its end, or None for those that have not ended by
    ``deadline`` (``time.monotonic``)."""
    parts: dict[int, list[bytes]] = {fd: [] for fd in fds}
    done: dict[int, bytes] = {}
    while len(done) < len(fds):
        left = deadline - time.monotonic()
        ready = select.select([fd for fd in fds if fd not in done], [], [], max(left, 0))[0]
        if left <= 0 or not ready:
            break
        for fd in ready:
            part = os.read(fd, 1 << 20)
            if part:
                parts[fd].append(part)
            else:
                done[fd] = b"".join(parts[fd])
    return [done.get(fd) for fd in fds]


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
