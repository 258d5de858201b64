"""``baker rebake``: bake a scene again with the settings of its last bake, incrementally."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import baker
from baker.cli.bake import add_cluster_option, print_summary
from baker.cli.common import finish, report_file
from baker.cli.state import add_update_options, print_rebake

EPILOG = """examples:
  baker rebake level.glb -o level_baked.glb
  baker rebake level.glb -o level_baked.glb --moved crate_03 lamp
  baker rebake level.glb -o level_baked.glb --cluster 10.0.0.1:6379

The settings are those of the bake that wrote the state (OUTPUT.bake, or --state). The scene is
diffed against the state, so the result is always the same as a full bake of the scene;
--moved names what the pipeline expects to have moved, and the command says if the diff found
something else (exit code 0 either way).
"""


def add_parser(commands) -> None:
    """Register ``rebake`` on the ``baker`` command's subparsers."""
    parser = commands.add_parser(
        "rebake", help="bake again after an edit, recomputing only what changed", epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Diff the scene against the bake state of its last bake and recompute only "
                    "the texels the change can reach; the result is bit-identical to a full bake.")
    parser.set_defaults(run=run)
    parser.add_argument("scene", type=Path, help="the edited scene, .glb or .gltf")
    parser.add_argument("-o", "--output", type=Path, required=True,
                        help="the baked scene to update (.glb or .gltf)")
    parser.add_argument("--moved", nargs="+", default=(), metavar="NODE",
                        help="names (or indices) of the nodes that moved, to check the diff "
                             "against")
    parser.add_argument("--threads", type=int, default=0,
                        help="ray-casting threads (default: one per core)")
    add_cluster_option(parser)
    add_update_options(parser)


def run(args: argparse.Namespace) -> int:
    """Rebake; exit code 0 (1 with a message when there is no usable state or scene, 4 when
    no surface got a lightmap)."""
    from baker.api import last_settings, scene_node_names

    settings = last_settings(args.output, args.state, threads=args.threads,
                             cluster=args.cluster)
    result = baker.bake(args.scene, args.output, settings, report_path=report_file(args),
                        quiet=args.quiet, incremental=True, state=args.state)
    code = finish(args, result, print_rebake, print_summary)
    if args.moved:
        names = scene_node_names(args.scene)
        named = {names.get(int(n), n) if n.isdigit() else n for n in args.moved}
        unknown = sorted(named - set(names.values()))
        if unknown:  # said whichever way the bake went (the cost model may choose a full one)
            print(f"baker: note: {args.scene} has no node named {', '.join(unknown)} (--moved)",
                  file=sys.stderr)
        found = set(result.rebake.get("moved_nodes", ()))
        if result.rebake.get("incremental") and found != named:
            print(f"baker: note: --moved named {', '.join(sorted(named))}; the diff found "
                  f"{', '.join(sorted(found)) or 'no node'} moved (the rebake followed the diff)",
                  file=sys.stderr)
    return code
