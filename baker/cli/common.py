"""What the subcommands share: argument types, the report option, the end of a bake."""

from __future__ import annotations

import argparse
import json
import sys
from contextlib import nullcontext, redirect_stdout
from pathlib import Path
from typing import Callable

import baker

NOTHING_BAKED = 4  # exit code: the bake ran and wrote its output, but no surface got a lightmap
OUTPUTS_CHANGED = 5  # exit code of ``baker hook``: it wrote files to add to the commit


def positive_float(text: str) -> float:
    """A number from the command line (the library's settings check says if it is out of range)."""
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None


def add_debug(parser: argparse.ArgumentParser) -> None:
    """Accept ``--debug`` after the subcommand too (``baker bake … --debug``).

    SUPPRESS keeps the top-level ``baker --debug`` value when the subcommand's flag is absent.
    """
    parser.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                        help="show the traceback of an error")


STDOUT = Path("-")
REPORT_HELP = ("write the JSON report (settings used, plan, stage times, rays/s) to FILE; "
               "- writes it to stdout, and the bake's own lines to stderr")


def add_report(parser) -> None:
    """``--report FILE`` (``-``: stdout)."""
    parser.add_argument("--report", type=Path, metavar="FILE", help=REPORT_HELP)


def report_file(args: argparse.Namespace) -> Path | None:
    """The report's file for ``baker.bake``: None when there is none or it goes to stdout."""
    return None if args.report in (None, STDOUT) else args.report


def finish(args: argparse.Namespace, result: baker.BakeResult,
           *printers: Callable[[baker.BakeResult], None]) -> int:
    """The end of a bake on the command line: ``printers`` print its summary on stdout unless
    ``--quiet``; a texture left out for want of a package is said on stderr even then; with
    ``--report -`` the summary goes to stderr and the JSON report alone to stdout (a pipe into
    ``jq`` gets nothing else). Returns the exit code (``exit_code``)."""
    streamed = args.report == STDOUT
    with redirect_stdout(sys.stderr) if streamed else nullcontext():
        if args.quiet:
            for warning, count in result.report["warnings"].items():
                if "pip install" in warning:  # what the user can mend: said even when quiet
                    print(f"baker: warning: {count} × {warning}", file=sys.stderr)
        else:
            for show in printers:
                show(result)
        code = exit_code(result)
    if streamed:
        sys.stdout.write(json.dumps(result.report, indent=2) + "\n")
        sys.stdout.flush()
    return code


def exit_code(result: baker.BakeResult) -> int:
    """0 for a bake that gave some surface a lightmap; ``NOTHING_BAKED`` (4), said on stderr
    with why, for one that gave none (0 texels: every mesh left out, e.g. only
    EXT_mesh_gpu_instancing instances, which are occluders only)."""
    if result.texels > 0:
        return 0
    why = "; ".join(f"{count} × {reason}" for reason, count in result.plan.left_out_counts().items())
    print(f"baker: nothing baked: no surface of {result.report['input']} got a lightmap "
          f"(0 texels{': ' + why if why else ''}); {result.output} is the scene without one "
          f"(exit code {NOTHING_BAKED})", file=sys.stderr)
    return NOTHING_BAKED
