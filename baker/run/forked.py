"""Running a call in a forked child process, so that a crash there is retried, not the end.

xatlas's task scheduler has a data race: a worker thread takes a pointer into a task queue,
lets go of the queue's lock and only then reads the task, while another thread may be pushing a
task that makes the queue reallocate (``TaskScheduler::workerThread`` and ``run`` in xatlas.cpp).
The worker then calls a stale function pointer: SIGSEGV in an xatlas worker, seen in 1 of 9
fresh-clone CI runs here and in 2 runs with numba's bounds checks on (gdb: ``?? ()`` called
from ``TaskScheduler::workerThread``, the main thread in ``AddMeshJoin``).
The same race can leave a task unfinished, so that xatlas waits for it for ever (a fuzzed bake
of a few triangles once ran past the test's 20 s). ``charts.py`` runs xatlas through
``call_forked_together``: each child is forked (copy-on-write, so the inputs cost nothing to pass), its
result comes back pickled through a pipe, and a child killed by a signal, or hung, is killed and
run again — xatlas's result does not depend on its threads' timing. Where ``os.fork`` is
missing (Windows) the call runs in this process, unprotected.

Hung is judged by the child's CPU time (``/proc/PID/stat``: all its threads, user and system),
not the clock: a machine loaded by other work slows a child's clock time, never its CPU time,
so a genuine run is never taken for hung however busy the cores are (on 2 cores shared by 9
bakes a 250,000-triangle unwrap was killed at its clock limit and started again). A hung xatlas
either spins (its main thread yields in a loop waiting for a task that never ends: CPU time
grows past the limit) or sleeps (its CPU time stops growing: ``STALL_SECONDS`` of clock time
without a single tick of CPU is no runnable process, however loaded the machine).
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
STALL_SECONDS = 30.0  # clock seconds without any CPU time gained after which a child is hung
_POLL_SECONDS = 0.25  # how often the children's CPU time is read
_TICK = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100  # /proc's CPU time unit


class ChildCrashed(BakerError):
    """Every attempt at a forked call died of a signal or hung."""


def call_forked_together(functions: list[Callable[[], Any]], what: str, seconds: float,
                         tick: Callable[[], None] | None = None) -> list[Any]:
    """Every function of ``functions`` run in a forked child of its own, all at once (one per
    core would be busy): their values in order. A function's exception is raised here (as
    RuntimeError when it cannot be pickled); the first error raised ends them all. A child
    killed by a signal, or hung (more than ``seconds`` of CPU time, or none gained for
    ``STALL_SECONDS``, or ``seconds`` if less), is killed and run again on its own, up to
    ``ATTEMPTS`` times; then ChildCrashed names ``what`` was being done. Ctrl-C here kills the
    children. ``tick()`` is called every ``_POLL_SECONDS`` while they run (to show their
    progress). Without ``os.fork`` (or off Linux) each function is simply called."""
    if not hasattr(os, "fork") or not sys.platform.startswith("linux"):
        return [function() for function in functions]
    values: dict[int, Any] = {}
    failures: dict[int, list[str]] = {i: [] for i in range(len(functions))}
    pending = list(range(len(functions)))
    while pending:
        outcomes = _attempts([functions[i] for i in pending], seconds, tick)
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


def _attempts(functions: list[Callable[[], Any]], seconds: float,
              tick: Callable[[], None] | None = None) -> list[tuple[bool, Any] | str]:
    """One forked run of each function, all at once: per function (True, value) or (False,
    exception), or why its child was lost: the name of the signal that killed it, or why it was
    taken for hung (it is killed)."""
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
        data = _read_until(children, seconds, min(seconds, STALL_SECONDS), tick)
    except BaseException:  # Ctrl-C while the children run: they go too
        for pid, _ in children:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        raise
    finally:
        for _, read in children:
            os.close(read)
    return [_outcome(pid, got) for (pid, _), got in zip(children, data)]


def _outcome(pid: int, data: bytes | str) -> tuple[bool, Any] | str:
    """What child ``pid`` gave, from the whole of its pipe ``data`` (a str: why it was taken
    for hung, and it is killed now); the child is reaped."""
    if isinstance(data, str):
        os.kill(pid, signal.SIGKILL)
    _, status = os.waitpid(pid, 0)
    if isinstance(data, str):
        return data
    if os.WIFSIGNALED(status):
        return signal.Signals(os.WTERMSIG(status)).name
    try:
        return pickle.loads(data)
    except Exception as error:  # a child that exited without a whole answer
        return False, RuntimeError(f"the forked call gave no usable result ({error!r})")


def _read_until(children: list[tuple[int, int]], cpu_seconds: float, stall_seconds: float,
                tick: Callable[[], None] | None = None) -> list[bytes | str]:
    """All of each child's pipe (``children``: (pid, read end)) up to its end, or, for a child
    taken for hung first, why: more than ``cpu_seconds`` of CPU time used, or none gained in
    ``stall_seconds`` of clock time. ``tick()`` after each wait."""
    parts: dict[int, list[bytes]] = {fd: [] for _, fd in children}
    done: dict[int, bytes | str] = {}
    progress = {fd: (-1.0, time.monotonic()) for _, fd in children}  # (CPU s, when it grew)
    while len(done) < len(children):
        ready = select.select([fd for _, fd in children if fd not in done], [], [],
                              _POLL_SECONDS)[0]
        for fd in ready:
            part = os.read(fd, 1 << 20)
            if part:
                parts[fd].append(part)
            else:
                done[fd] = b"".join(parts[fd])
        if tick is not None:
            tick()
        now = time.monotonic()
        for pid, fd in children:
            if fd in done:
                continue
            used = cpu_seconds_of(pid)
            if used is None:  # exited: its pipe's end comes with the next select
                continue
            if used > cpu_seconds:
                done[fd] = f"past {cpu_seconds:.0f} s of CPU time"
            elif used > progress[fd][0]:
                progress[fd] = (used, now)
            elif now - progress[fd][1] > stall_seconds:
                done[fd] = f"no CPU time used in {stall_seconds:.0f} s"
    return [done[fd] for _, fd in children]


def cpu_seconds_of(pid: int) -> float | None:
    """CPU seconds process ``pid`` has used so far, all its threads, user and system time
    (``/proc/PID/stat`` fields 14 and 15, in clock ticks); None once it has exited (a zombie
    counts as exited) or where /proc cannot tell."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as stat:
            fields = stat.read().rsplit(b")", 1)[1].split()  # the name may hold spaces, ")"
    except (OSError, IndexError):
        return None
    if fields[0] == b"Z":
        return None
    return (int(fields[11]) + int(fields[12])) / _TICK


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
