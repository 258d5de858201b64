"""Argument types the subcommands share."""

from __future__ import annotations

import argparse
import sys

import baker

NOTHING_BAKED = 4  # exit code: the bake ran and wrote its output, but no surface got a lightmap


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
