"""``baker`` — bake lightmaps into glTF scenes from the command line.

Each subcommand is a module of this package with ``add_parser(commands)``, which registers its
options and sets ``run``; ``main`` parses, runs it, and renders ``baker.BakerError`` as a short
message (the traceback only with ``--debug``). Exit codes: 0 done, 1 bad input or settings
(message printed), 2 bad command line (argparse), 3 internal error (a bug: please report it),
4 nothing baked (``common.exit_code``), 5 ``baker hook`` wrote files to add to the commit,
130 interrupted (Ctrl-C), 143 terminated (SIGTERM: cleaned up as after Ctrl-C).
"""

from __future__ import annotations

import argparse
import gc
import signal
import sys
import threading
from contextlib import contextmanager
from typing import Iterator

import baker
from baker.cli import INTERRUPTED, started
from baker.run.allocator import keep_freed_memory
from baker.run.interruptible import raise_interrupt

SUBCOMMANDS = ("bake", "rebake", "relight", "watch", "hook", "preview", "view", "plugin", "study")


def build_parser() -> argparse.ArgumentParser:
    """The ``baker`` parser with every subcommand registered. Their modules import only the
    names their options need (``baker.settings``); the pipeline (numpy, numba, Embree, PIL:
    most of a second) is imported by the command that runs, so ``baker --help`` and a wrong
    option answer at once."""
    from importlib import import_module

    parser = argparse.ArgumentParser(
        prog="baker", description="Bake lightmaps (obscurances with colour bleeding) into glTF scenes.")
    parser.add_argument("--version", action=_Version, nargs=0,
                        help="show baker's version and how its kernels are compiled, and exit")
    parser.add_argument("--debug", action="store_true", help="show the traceback of an error")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in SUBCOMMANDS:
        import_module(f"baker.cli.{name}").add_parser(commands)
    return parser


class _Version(argparse.Action):
    """``--version``: baker's version, whether its kernels run compiled ahead of time or
    through numba's JIT, and why (``jit.status``: an install without a C compiler, or older
    than its sources, runs about 0.3 s slower a bake), and what casts its rays (without a C
    compiler, embreex: a few per cent slower, its scenes built 5× slower):
    ``api.build_status``."""

    def __call__(self, parser, *_):  # argparse passes the namespace, values and option
        from baker.api import build_status

        status = build_status()
        print(f"baker {baker.__version__}\nkernels: {status['kernels']}\nrays: {status['rays']}")
        parser.exit()


class Terminated(BaseException):
    """SIGTERM arrived: raised in the main thread, as Ctrl-C raises KeyboardInterrupt, so that a
    bake stopped by ``kill`` or a CI timeout unwinds through the same clean-up (temporaries and
    ``.baker-spill-*`` folders removed, the previous output kept)."""


def _raise_terminated(signum, frame) -> None:
    raise_interrupt(Terminated, frame)


def _raise_interrupted(signum, frame) -> None:
    raise_interrupt(KeyboardInterrupt, frame)


@contextmanager
def _signals_raise() -> Iterator[None]:
    """While the command runs, SIGTERM raises ``Terminated`` and SIGINT KeyboardInterrupt (if
    it is not ignored) through ``run.interruptible.raise_interrupt``, which raises them again
    where the bake passes often should some code swallow them — a ``__del__`` or a ctypes
    callback, which would print the swallowed one as "Exception ignored in …": not printed
    (the previous handlers after)."""
    if threading.current_thread() is not threading.main_thread():  # only it takes signals
        yield
        return
    from baker.run.interruptible import forget_interrupts

    previous = signal.signal(signal.SIGTERM, _raise_terminated)
    previous_int = signal.getsignal(signal.SIGINT)
    if previous_int is signal.default_int_handler:
        signal.signal(signal.SIGINT, _raise_interrupted)
    unraisable = sys.unraisablehook

    def quiet(what) -> None:  # swallowed (a __del__, a ctypes callback), raised again later
        if not isinstance(what.exc_value, (KeyboardInterrupt, Terminated)):
            unraisable(what)

    sys.unraisablehook = quiet
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
        if previous_int is signal.default_int_handler:
            signal.signal(signal.SIGINT, previous_int)
        sys.unraisablehook = unraisable
        forget_interrupts()


def main(argv: list[str] | None = None) -> int:
    """Run the command line; return the exit code."""
    args = build_parser().parse_args(argv)
    try:
        with _signals_raise():
            return args.run(args)
    except baker.BakerError as error:
        if args.debug:
            raise
        print(f"baker: error: {error}", file=sys.stderr)
        return 1
    except BrokenPipeError:  # the reader of our output went away (e.g. `| head`): not an error
        sys.stderr.close()
        return 0
    except KeyboardInterrupt:
        print(INTERRUPTED, file=sys.stderr)
        return 130
    except Terminated:
        print("baker: terminated; the bake under way, if any, changed no output", file=sys.stderr)
        return 143
    except Exception as error:  # a bug, not bad input: say so in one line
        if args.debug:
            raise
        print(f"baker: internal error ({type(error).__name__}: {error}); this is a bug in baker — "
              "please report it with the output of the same command run with --debug",
              file=sys.stderr)
        return 3


def entry() -> int:
    """The ``baker`` command: ``main`` on the process's arguments. A Ctrl-C while the pipeline's
    modules are imported (by the subcommand that runs: numpy, numba and Embree take most of a
    second) exits 130 with one line, as one during the bake does (before, while the command line
    loads, ``baker.cli``'s handler does the same). Once ``main`` has returned, a second Ctrl-C
    (an impatient user presses it twice) has nothing left to stop: it is ignored while Python waits
    for the worker threads to end their chunk, rather than printing a traceback from the
    interpreter's shutdown. Every object the command made is then frozen out of the cyclic
    garbage collector (``gc.freeze``): the shutdown's collections do not walk them (numba's
    types and kernels: 0.1 s of a bake's exit, more than its compose stage), and memory goes
    back to the system with the process. The C allocator keeps what the stages free for the
    next stage's arrays (``run.allocator``)."""
    started()
    keep_freed_memory()
    try:
        return main()
    except KeyboardInterrupt:
        print(INTERRUPTED, file=sys.stderr)
        return 130
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        gc.freeze()


if __name__ == "__main__":
    sys.exit(entry())
