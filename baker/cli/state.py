"""Options and messages the baking subcommands share about the bake state (incremental rebake)."""

from __future__ import annotations

import argparse
from pathlib import Path

import baker
from baker.cli.common import add_debug, add_report


def add_state_options(group) -> None:
    """``--state``, ``--full`` and ``--no-state`` on a subcommand's argument group."""
    group.add_argument("--state", type=Path, metavar="FILE",
                       help="the bake state (sidecar) a rebake starts from and the bake "
                            "writes (default: OUTPUT.bake); delete it at any time")
    group.add_argument("--full", action="store_true",
                       help="bake every texel even when a bake state is there (a new state is "
                            "still written)")
    group.add_argument("--no-state", action="store_true",
                       help="neither read nor write a bake state")


def state_arguments(args: argparse.Namespace) -> dict:
    """The ``incremental`` and ``state`` arguments of ``baker.bake`` for these options."""
    if args.no_state:
        return {"incremental": False, "state": False}
    return {"incremental": not args.full, "state": args.state}


def print_rebake(result: baker.BakeResult) -> None:
    """One line: how much of the bake was redone, and why."""
    info = result.rebake or {}
    if info.get("incremental"):
        changes = "; ".join(info["changes"])
        reasons = ", ".join(f"{k} {v:,}" for k, v in info["dirty_by_reason"].items() if v)
        relit = (f"; shadow rays recast for light(s) {', '.join(map(str, info['relit_lights']))}"
                 if info["relit_lights"] else "")
        full, compiled = info.get("last_full_bake_seconds"), info.get("compile_seconds", 0.0)
        warm = None if info.get("seconds") is None else info["seconds"] - compiled
        against = (f" = {100 * warm / full:.0f} % of the last full bake ({full:.2f} s), both "
                   "without numba's compile"
                   + (f" ({compiled:.2f} s of this one)" if compiled >= 0.005 else "")
                   if full and warm is not None else "")
        print(f"rebake: {changes}: {info['dirty_texels']:,} of {info['texels']:,} texels "
              f"({100 * info['dirty_fraction']:.2f} %) recomputed"
              f"{' (' + reasons + ')' if reasons else ''}{relit}; {info['rays']:,} rays; "
              f"{info['seconds']:.2f} s{against}")
    elif info.get("full_bake_reason") and info["full_bake_reason"] != "full bake asked for":
        print(f"full bake: {info['full_bake_reason']}")


def settings_for(output: Path, **given) -> baker.Settings:
    """The settings of the bake that wrote ``output``'s state (so a rebake can follow), or
    ``Settings(**given)`` when there is no usable state."""
    from baker.api import last_settings

    try:
        return last_settings(output, threads=given.get("threads", 0))
    except baker.SettingsError:
        return baker.Settings(**given)


def add_update_options(parser) -> None:
    """The options of the commands that update a baked scene from its state (rebake, relight):
    --state, --report, --quiet, --debug."""
    parser.add_argument("--state", type=Path, metavar="FILE",
                        help="the bake state (default: OUTPUT.bake)")
    add_report(parser)
    parser.add_argument("--quiet", action="store_true", help="print nothing but errors")
    add_debug(parser)
