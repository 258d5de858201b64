"""``baker`` — bake lightmaps into glTF scenes from the command line.

Parses arguments into ``baker.Settings``, calls the library, prints the report, and renders
``baker.BakerError`` as a short message (the traceback only with ``--debug``). Exit codes:
0 baked, 1 bad input or settings (message printed), 2 bad command line (argparse), 130 interrupted.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import baker

EPILOG = """examples:
  baker bake level.glb -o level_baked.glb
  baker bake level.gltf -o out/level.gltf --rays 256 --texel-density 20 --report report.json
  baker bake prop.glb -o prop_ao.glb --rho step          (classic ambient occlusion)

The output is the same scene with a second UV set and the lightmaps embedded as PNG, referenced
by the MOZ_lightmap material extension (three.js, Hubs, Spoke read it).
"""


def _positive_float(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="baker", description="Bake lightmaps (obscurances with colour bleeding) into glTF scenes.")
    parser.add_argument("--version", action="version", version=f"baker {baker.__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    bake = commands.add_parser(
        "bake", help="bake a glTF scene's lightmaps", epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Unwrap every static surface into lightmap pages, compute the light arriving "
                    "at each texel, and write the scene back with the lightmaps embedded.")
    bake.add_argument("scene", type=Path, help="the input scene, .glb or .gltf")
    bake.add_argument("-o", "--output", type=Path, required=True,
                      help="where to write the baked scene (.glb or .gltf); never the input")
    d = baker.Settings()
    quality = bake.add_argument_group("lightmap layout")
    quality.add_argument("--texel-density", type=_positive_float, metavar="TEXELS_PER_UNIT",
                         help="lightmap texels per scene unit (metre) along a surface "
                              "(default: fill about half of one page)")
    quality.add_argument("--page-size", type=int, default=d.page_size, metavar="TEXELS",
                         help=f"largest lightmap page side; more pages when one is full (default {d.page_size})")
    quality.add_argument("--padding", type=int, default=d.padding, metavar="TEXELS",
                         help=f"free texels around each chart (default {d.padding})")
    model = bake.add_argument_group("light model")
    model.add_argument("--rays", type=int, default=d.rays,
                       help=f"obscurance rays per texel: more is smoother and slower (default {d.rays})")
    model.add_argument("--d-max", type=_positive_float, metavar="DISTANCE",
                       help="obscurance distance in scene units: farther surfaces count as open "
                            f"(default {d.d_max_fraction:g} × the baked surfaces' bounds diagonal)")
    model.add_argument("--rho", choices=baker.settings.RHO_FUNCTIONS, default=d.rho,
                       help="obscurance function ρ(d): sqrt (the paper's), linear, or step "
                            "(classic ambient occlusion) (default sqrt)")
    model.add_argument("--ambient", type=_positive_float, metavar="I_A",
                       help="ambient intensity I_A (default: from the scene's emissive surfaces, "
                            "or 1 when it has none)")
    model.add_argument("--seed", type=int, default=d.seed, help="sampler seed (default 0)")
    out = bake.add_argument_group("output")
    out.add_argument("--encoding", choices=baker.settings.ENCODINGS, default=d.encoding,
                     help="how PNG texels map to light: linear (three.js, Hubs) or srgb "
                          "(the MOZ_lightmap proposal) (default linear)")
    out.add_argument("--occlusion", choices=baker.settings.OCCLUSION_MODES, default=d.occlusion,
                     help="also (or only) write the obscurance as the core occlusionTexture, "
                          "which every viewer reads (default none)")
    out.add_argument("--lightmaps", type=Path, metavar="DIR",
                     help="also write each lightmap page as a PNG file in DIR")
    out.add_argument("--report", type=Path, metavar="FILE",
                     help="write a JSON report: settings used, plan, stage times, rays/s")
    run = bake.add_argument_group("running")
    run.add_argument("--threads", type=int, default=d.threads,
                     help="ray-casting threads (default: one per core)")
    run.add_argument("--quiet", action="store_true", help="print nothing but errors")
    run.add_argument("--debug", action="store_true", help="show the traceback of an error")
    return parser


def settings_from(args: argparse.Namespace) -> baker.Settings:
    return baker.Settings(
        texel_density=args.texel_density, page_size=args.page_size, padding=args.padding,
        rays=args.rays, d_max=args.d_max, rho=args.rho, ambient=args.ambient, seed=args.seed,
        threads=args.threads, encoding=args.encoding, occlusion=args.occlusion)


def print_summary(result: baker.BakeResult) -> None:
    s = result.settings
    times = result.report["stage_seconds"]
    print(f"baked {result.output}")
    print(f"  {result.texels:,} texels on {result.pages} page(s) of "
          f"{result.report['atlas']['width']}×{result.report['atlas']['height']}, "
          f"texel density {s.texel_density:.4g}/unit, d_max {s.d_max:.4g}, {s.rays} rays/texel")
    print("\n".join(result.plan.lines()))
    for note in result.report["notes"]:
        print(f"  note: {note}")
    print(f"  {result.rays:,} rays, {result.report['rays_per_second'] / 1e6:.2f} M rays/s; "
          f"estimated RMSE {result.rmse_estimate:.3g}; {result.seconds:.1f} s "
          f"({', '.join(f'{k} {v:.1f}' for k, v in times.items())})")


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        result = baker.bake(args.scene, args.output, settings_from(args), report_path=args.report,
                            lightmaps_dir=args.lightmaps, quiet=args.quiet)
    except baker.BakerError as error:
        if args.debug:
            raise
        print(f"baker: error: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("baker: interrupted; nothing was written", file=sys.stderr)
        return 130
    if not args.quiet:
        print_summary(result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
