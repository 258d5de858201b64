"""``baker preview``: render a baked glTF to a PNG picture (as viewers shade it, Embree rays)."""

from __future__ import annotations

import argparse
from pathlib import Path

from baker.cli.common import add_debug, positive_float
from baker.settings import PREVIEW_MODES

EPILOG = """examples:
  baker preview level_baked.glb -o preview.png
  baker preview level_baked.glb -o lightmap.png --lightmap-only --size 1280x720
  baker preview level_baked.glb -o density.png --checker

The view is the scene's first glTF camera, or a three-quarter view from above that frames the
whole scene. Single-sided surfaces are seen through from behind, as in glTF viewers, so a closed
room is seen from outside looking in.
"""


def parse_size(text: str) -> tuple[int, int]:
    """'800x600' → (800, 600); ValueError unless both are whole numbers from 1 to 16384."""
    parts = text.lower().replace("×", "x").split("x")
    if len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
        raise ValueError(f"size must be WIDTHxHEIGHT, e.g. 800x600, not {text!r}")
    width, height = (int(p) for p in parts)
    if not (1 <= width <= 16384 and 1 <= height <= 16384):
        raise ValueError(f"size {width}x{height} must be 1 to 16384 pixels a side")
    return width, height


def _size(text: str) -> tuple[int, int]:
    try:
        return parse_size(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def add_parser(commands) -> None:
    """Register ``preview`` and its options on the ``baker`` command's subparsers."""
    parser = commands.add_parser(
        "preview", help="render a baked scene to a PNG picture", epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Render a baked glTF (one with MOZ_lightmap materials) as a viewer shows it: "
                    "diffuse colour × lightmap / π + emission, the diffuse colour being base "
                    "colour × (1 − metallic) × (1 − transmission), one Embree ray per pixel.")
    parser.set_defaults(run=run)
    parser.add_argument("scene", type=Path, help="the baked scene, .glb or .gltf")
    parser.add_argument("-o", "--output", type=Path, required=True, help="the picture, .png")
    what = parser.add_mutually_exclusive_group()
    what.add_argument("--lightmap-only", dest="mode", action="store_const", const="lightmap",
                      help="show the lightmap alone, as if every surface were white")
    what.add_argument("--checker", dest="mode", action="store_const", const="checker",
                      help="show a checker of lightmap texels (texel density), tinted per page; "
                           "surfaces without a lightmap are magenta")
    what.add_argument("--unlit", dest="mode", action="store_const", const="unlit",
                      help="show diffuse colour + emission with the lightmaps left out, to compare")
    parser.set_defaults(mode=PREVIEW_MODES[0])
    parser.add_argument("--size", type=_size, metavar="WxH",
                        help="picture size in pixels (default 640 wide, the camera's aspect "
                             "ratio or 4:3)")
    parser.add_argument("--exposure", type=positive_float, metavar="FACTOR",
                        help="multiply linear values by FACTOR before the sRGB curve (default: "
                             "automatic, the brightest lightmapped 1%% of pixels near white)")
    parser.add_argument("--quiet", action="store_true", help="print nothing but errors")
    add_debug(parser)


def run(args: argparse.Namespace) -> int:
    """Render and write the picture; exit code 0."""
    from baker.preview import preview

    picture = preview(args.scene, args.output, args.mode, args.size, args.exposure)
    if not args.quiet:
        height, width = picture.triangle.shape
        extra = (f", checker squares of {picture.checker_texels} texel(s)"
                 if args.mode == "checker" else f", exposure {picture.exposure:.3g}")
        print(f"wrote {args.output} ({width}×{height}, {args.mode}{extra})")
    return 0
