"""Argument types the subcommands share."""

from __future__ import annotations

import argparse


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
