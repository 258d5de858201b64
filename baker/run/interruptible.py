"""Ctrl-C and SIGTERM honoured within a fraction of a second, in long C calls and through code
that swallows exceptions.

Python runs a signal's handler in the main thread, between two of its bytecodes: while the main
thread is inside one long C call — decoding an 8192² WebP took 1.1 s, transcoding a large KTX 2
as long — a Ctrl-C or a SIGTERM waits for the call to return (SIGTERM took 2.8 s to stop a bake
decoding WebP textures). ``call_interruptibly`` runs such a call on a thread of its own while the
main thread waits for it in short slices, so that the signal's exception (``KeyboardInterrupt``,
``cli.main.Terminated``) is raised in the main thread at once and the bake unwinds through its
usual clean-up. The call, left running, is abandoned: its thread is a daemon, its result
dropped, and the process is ending. The decoders it is used for release the GIL while they
work (pillow's, opengl-basisu's), so the waiting thread runs.

An exception a signal raises can also be swallowed: one that comes while numba loads a compiled
kernel from its cache is raised inside llvmlite's ctypes callback, which prints "Exception
ignored on calling ctypes callback function" and goes on (a Ctrl-C 0.1 s into a small bake was
lost so, and the bake ended with exit 0). So the command line's handlers raise through
``raise_interrupt``, which remembers the interrupt, and ``check_interrupted`` raises it again
where the bake passes often (each stage, each chunk of work, before the outputs are put in
place), so that a swallowed interrupt is raised again at the next of them.

And an exception a signal raises can fall between two steps that must not be parted: a
temporary file made, and recorded for its removal (a Ctrl-C 0.68 s into a small bake left a
``.baked.glb.….tmp`` beside the output, 3 times in 80). ``deferred()`` holds the interrupt back
for such a few steps, and raises it as they end.
"""

from __future__ import annotations

import os
import threading
from contextlib import contextmanager
from typing import Any, Callable, Iterator

_SLICE = 0.05  # seconds the main thread waits at once
_came: list[type[BaseException]] = []  # the interrupt a signal raised, until forgotten
_holding = {"depth": 0, "held": None}  # deferred blocks entered; the interrupt held back
_FRAGILE = (f"{os.sep}llvmlite{os.sep}", f"{os.sep}ctypes{os.sep}")  # code C calls back into


def raise_interrupt(kind: type[BaseException], frame: Any = None) -> None:
    """Raise ``kind`` (a signal's handler: KeyboardInterrupt, …; ``frame``: the frame it
    interrupted) and remember it for ``check_interrupted``; inside a ``deferred`` block, hold
    it back until the block ends; in a callback from C (``_FRAGILE``), raise it only at the
    next ``check_interrupted``: raised in llvmlite's, it was swallowed, and twice in 150 runs
    the process then crashed (SIGSEGV, a double free)."""
    if not _came:
        _came.append(kind)
    if _holding["depth"]:
        _holding["held"] = kind
        return
    if frame is not None and any(part in frame.f_code.co_filename for part in _FRAGILE):
        return
    raise kind()


@contextmanager
def deferred() -> Iterator[None]:
    """Hold back the interrupt a signal raises (``raise_interrupt``) while the block runs, and
    raise it when the block ends: for a few short steps that must not be parted. Only the main
    thread takes signals: elsewhere the block runs as it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _holding["depth"] += 1
    try:
        yield
    finally:
        _holding["depth"] -= 1
    held = _holding["held"]
    if held is not None and not _holding["depth"]:
        _holding["held"] = None
        raise held()


def check_interrupted() -> None:
    """Raise again the interrupt ``raise_interrupt`` raised, if one was (and swallowed)."""
    if _came:
        raise _came[0]()


def forget_interrupts() -> None:
    """Forget the interrupt remembered (the command that got it has ended)."""
    _came.clear()
    _holding["held"] = None


def call_interruptibly(function: Callable[..., Any], *args: Any) -> Any:
    """``function(*args)``: its value, or the exception it raised, raised here; run on a
    thread of its own when called from the main thread (see the module's docstring)."""
    if threading.current_thread() is not threading.main_thread():
        return function(*args)
    outcome: list = []

    def run() -> None:
        try:
            outcome.append((True, function(*args)))
        except BaseException as error:  # handed to the caller as it is
            outcome.append((False, error))

    worker = threading.Thread(target=run, name="baker-interruptible", daemon=True)
    worker.start()
    while worker.is_alive():
        worker.join(_SLICE)
        check_interrupted()
    done, value = outcome[0]
    if not done:
        raise value
    return value
