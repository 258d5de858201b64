"""The ``baker`` command line: a thin layer over the library's public API (``baker.bake``).

Imported first when the command starts (``baker.cli.main:entry``, ``python -m baker``), before
argparse or any of baker: it sets a Ctrl-C handler at once, so that a Ctrl-C while the rest of
the command line loads exits 130 with the one line a Ctrl-C during the bake prints, not with a
traceback from inside an import. ``main.entry`` gives Python's own handler back before it
parses (KeyboardInterrupt then unwinds the bake). Only the command sets it: a program or test
that imports ``baker.cli`` keeps its handler, as does a process that ignores SIGINT (started
in the background with ``&``). A Ctrl-C during Python's own start-up, before this runs, is
Python's (docs/robustness.md).
"""

import os
import signal
import sys

INTERRUPTED = "baker: interrupted; no output was changed"


def _interrupted_while_starting(signum, frame) -> None:
    """SIGINT before ``main.entry`` runs: the one line, exit code 130 (SystemExit unwinds the
    imports under way without a traceback)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C: the same end
    print(INTERRUPTED, file=sys.stderr)
    raise SystemExit(130)


def _starting_the_command() -> bool:
    """Whether this process is the ``baker`` command starting: the console script (argv[0]
    ``baker``) or ``python -m baker`` / ``-m baker.cli.main``, during which Python's argv[0] is
    "-m" while the module is found (its packages imported)."""
    program = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else ""
    return program == "-m" or os.path.splitext(program)[0] == "baker"


def started() -> None:
    """Python's own Ctrl-C handler back in place of the start-up's (if it was set): from here
    on a Ctrl-C raises KeyboardInterrupt, which the command turns into the same line."""
    if signal.getsignal(signal.SIGINT) is _interrupted_while_starting:
        signal.signal(signal.SIGINT, signal.default_int_handler)


if _starting_the_command() and signal.getsignal(signal.SIGINT) is signal.default_int_handler:
    signal.signal(signal.SIGINT, _interrupted_while_starting)
