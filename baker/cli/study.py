"""``baker study``: error against run time for each sampling technique, as a table and a plot."""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import baker
from baker.cli.common import add_debug
from baker.settings import STUDY_RAYS, TECHNIQUES


def add_parser(commands) -> None:
    """Register ``study`` on the ``baker`` command's subparsers."""
    study = commands.add_parser(
        "study", help="measure error against run time for each sampling technique",
        description="Bake the scene's obscurances at increasing rays per texel with each sampling "
                    "technique, measure the RMSE against a converged reference (many more rays, "
                    "same estimator) next to the RMSE the bake estimates for itself, and print "
                    "the table; --plot writes RMSE against seconds on log axes.")
    study.set_defaults(run=run)
    study.add_argument("scene", type=Path, help="the scene, .glb or .gltf")
    study.add_argument("--page-size", type=int, default=128, metavar="TEXELS",
                       help="lightmap page size for the study (default 128: a study bakes many "
                            "times, so it uses fewer texels than a bake)")
    study.add_argument("--rays", type=int, nargs="+", default=list(STUDY_RAYS), metavar="N",
                       help="rays per texel to try (default 4 8 … 1024)")
    study.add_argument("--techniques", nargs="+", default=list(TECHNIQUES),
                       choices=TECHNIQUES, help="sampling techniques to compare")
    study.add_argument("--reference-rays", type=int, default=4096, metavar="N",
                       help="rays per texel of the converged reference (default 4096)")
    study.add_argument("--d-max", type=float, metavar="DISTANCE",
                       help="obscurance distance (default: as a bake derives it)")
    study.add_argument("--gi-paths", type=int, default=256, metavar="N",
                       help="paths per texel of the full-GI comparison (0: skip it; default 256)")
    study.add_argument("--sky-image", metavar="FILE",
                       help="light the scene with this panorama (.hdr, .exr) and add the sky "
                            "light's rows: as baked (the image's peak drawn by the image) and "
                            "by cosine rays alone")
    study.add_argument("--sky-rotation", type=float, default=0.0, metavar="DEGREES",
                       help="turn --sky-image about +Y (default 0)")
    study.add_argument("--sky-intensity", type=float, default=1.0, metavar="F",
                       help="factor on --sky-image's radiance (default 1)")
    study.add_argument("--directional", action="store_true",
                       help="keep the directions too (--directional): add the rows of the "
                            "obscurance's first moment U for each technique (the scene needs "
                            "a normal-mapped material)")
    study.add_argument("--plot", type=Path, metavar="PNG", help="write the plot here")
    study.add_argument("--json", type=Path, metavar="FILE", help="write the table as JSON")
    add_debug(study)


def run(args: argparse.Namespace) -> int:
    """Run the study; print the table; exit code 0."""
    from baker.run.atomic import write_atomically
    from baker.study import compare_with_gi, plot, run_study, sky_rows

    settings = baker.Settings(page_size=args.page_size, d_max=args.d_max, rays=1, sky_rays=1,
                              sky_image=args.sky_image, sky_rotation=args.sky_rotation,
                              sky_intensity=args.sky_intensity, directional=args.directional)
    done = baker.compute(baker.load(args.scene), settings)
    result = run_study(done, tuple(args.rays), tuple(args.techniques), args.reference_rays,
                       progress=lambda text: print(f"  {text}", flush=True))
    if args.sky_image:
        print("  sky light: as baked and by cosine rays alone", flush=True)
        result = replace(result, sky=sky_rows(done, tuple(args.rays), args.reference_rays))
    if args.gi_paths:
        print(f"  full GI: {args.gi_paths} paths per texel", flush=True)
        result = replace(result, gi=compare_with_gi(done, paths=args.gi_paths))
    print(result.table())
    if args.plot:
        write_atomically(args.plot, plot(result))
        print(f"plot: {args.plot}")
    if args.json:
        write_atomically(args.json, json.dumps(result.as_dict(), indent=2).encode())
    return 0
