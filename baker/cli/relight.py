"""``baker relight``: new light colours and intensities, recomposed from the bake state, no ray."""

from __future__ import annotations

import argparse
from pathlib import Path

import baker
from baker.cli.bake import print_summary
from baker.cli.common import finish, report_file
from baker.cli.state import add_update_options, print_rebake


def add_parser(commands) -> None:
    """Register ``relight`` on the ``baker`` command's subparsers."""
    parser = commands.add_parser(
        "relight", help="recompose the lightmaps for new light colours/intensities (no rays)",
        description="The scene's punctual lights changed only in colour or intensity "
                    "(KHR_lights_punctual color/intensity): recompose the lightmaps from the "
                    "bake state of the last bake, casting no ray. The result equals a full "
                    "bake. Any other change, an emissive material's colour or strength "
                    "included (the state holds emitters' light at their baked strength), is "
                    "refused, and nothing is written: use `baker bake`.")
    parser.set_defaults(run=run)
    parser.add_argument("scene", type=Path, help="the scene with its new lights, .glb or .gltf")
    parser.add_argument("-o", "--output", type=Path, required=True,
                        help="the baked scene to update (.glb or .gltf)")
    add_update_options(parser)


def run(args: argparse.Namespace) -> int:
    """Relight; exit code 0 (1 with a message when more than the lights' colours changed)."""
    from baker.api import last_settings

    result = baker.bake(args.scene, args.output, last_settings(args.output, args.state),
                        report_path=report_file(args), quiet=args.quiet, relight=True,
                        state=args.state)
    finish(args, result, print_rebake, print_summary)
    return 0
