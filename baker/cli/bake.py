"""``baker bake``: parse the bake's options into ``baker.Settings``, bake, print the summary."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import baker
import baker.settings
from baker.cli.common import add_debug, add_report, finish, positive_float, report_file
from baker.cli.state import add_state_options, print_rebake, state_arguments
from baker.settings import DEFAULT_RAYS, FIRST_ROUND_RAYS

EPILOG = """examples:
  baker bake level.glb -o level_baked.glb
  baker bake level.gltf -o out/level.gltf --rays 256 --texel-density 20 --report report.json
  baker bake prop.glb -o prop_ao.glb --rho step          (classic ambient occlusion)

The output is the same scene with the lightmap UVs as TEXCOORD_1 and the bake embedded as PNG,
carried to viewers as --carrier says: emissive (the default: the baked light as the emission of
each material, which keeps its specular response: every glTF viewer, no plugin), moz
(MOZ_lightmap: three.js with our plugin, Hubs, baker view) or occlusion (visibility as the core
occlusionTexture). baker view OUT.glb shows it in a browser.
"""


def add_parser(commands) -> None:
    """Register ``bake`` and its options on the ``baker`` command's subparsers."""
    bake = commands.add_parser(
        "bake", help="bake a glTF scene's lightmaps", epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Unwrap every static surface into lightmap pages, compute the light arriving "
                    "at each texel, and write the scene back with the lightmaps embedded.")
    bake.set_defaults(run=run)
    bake.add_argument("scene", type=Path, help="the input scene, .glb or .gltf")
    bake.add_argument("-o", "--output", type=Path, required=True,
                      help="where to write the baked scene (.glb or .gltf; its folder is made if "
                           "missing); the input itself only with --overwrite")
    bake.add_argument("--overwrite", action="store_true",
                      help="allow the output to replace the input (or a file it uses); the "
                           "replacement is atomic and happens only once the bake succeeded")
    d = baker.Settings()
    quality = bake.add_argument_group("lightmap layout")
    quality.add_argument("--texel-density", type=positive_float, metavar="TEXELS_PER_UNIT",
                         help="lightmap texels per scene unit (metre) along a surface "
                              "(default: fill about half of one page, lowered until the "
                              "charts fit one page when they can)")
    quality.add_argument("--page-size", type=int, default=d.page_size, metavar="TEXELS",
                         help=f"largest lightmap page side; more pages when one is full (default {d.page_size})")
    quality.add_argument("--uv", type=int, metavar="N",
                         help="bake into the lightmap UVs the artist authored, TEXCOORD_N of "
                              "every baked primitive (one --page-size page, checked: inside "
                              "[0, 1], no overlaps, --padding texels between islands) instead "
                              "of unwrapping; written as TEXCOORD_1 (default: unwrap)")
    quality.add_argument("--padding", type=int, default=d.padding, metavar="TEXELS",
                         help=f"free texels around each chart (default {d.padding})")
    model = bake.add_argument_group("light model")
    model.add_argument("--rays", type=int, default=None,
                       help=f"obscurance rays per texel: more is smoother and slower (default "
                            f"{DEFAULT_RAYS}; {FIRST_ROUND_RAYS}, the first round, with "
                            f"--target-error)")
    model.add_argument("--d-max", type=positive_float, metavar="DISTANCE",
                       help="obscurance distance in scene units: farther surfaces count as open "
                            f"(default {d.d_max_fraction:g} × the baked surfaces' bounds diagonal, rounded to "
                            "a quarter octave)")
    model.add_argument("--rho", choices=baker.settings.RHO_FUNCTIONS, default=d.rho,
                       help="obscurance function ρ(d): sqrt (the paper's), linear, or step "
                            "(classic ambient occlusion) (default sqrt)")
    model.add_argument("--ambient", type=positive_float, metavar="I_A",
                       help="ambient intensity I_A (default: from the scene's lights and "
                            "emissive surfaces, or 1 when it has none or is an open prop, see "
                            "--escape)")
    model.add_argument("--escape", choices=baker.settings.ESCAPES, default=d.escape,
                       help="what rays that meet nothing within --d-max count: scene (R_ave, "
                            "the scene's mean albedo: the rest of a closed level), white (a "
                            "neutral environment; I_A = 1 without lights or sky), or auto: "
                            "white for an open scene without lights (a prop), else R_ave "
                            "(default auto; the plan says which and why)")
    model.add_argument("--animated", choices=baker.settings.ANIMATED, default=d.animated,
                       help="what becomes of objects an animation moves (their node or an "
                            "ancestor's transform): bake them in their rest pose, with a "
                            "warning; occlude: no lightmap, their rest pose still casts "
                            "shadows; skip: left out, no shadow either (default bake)")
    model.add_argument("--seed", type=int, default=d.seed, help="sampler seed (default 0)")
    model.add_argument("--sampling", choices=baker.settings.TECHNIQUES, default=d.sampling,
                       help="how each texel's ray directions are drawn: sobol (Owen-scrambled, "
                            "least noise per ray), stratified or random (default sobol)")
    model.add_argument("--target-error", type=positive_float, metavar="E",
                       help="adaptive sampling: obscurance, shadow, emissive and sky rays (GI "
                            "paths with --method gi) in rounds (--rays, even, then doubling) "
                            "until each texel's predicted error is at most E/2 in lightmap "
                            "units (95 %% of texels within E), or its rays of a kind reach "
                            "--max-rays; the first round is the least a texel gets: quiet "
                            "texels stop there (default: every texel gets --rays)")
    model.add_argument("--method", choices=baker.settings.METHODS, default=d.method,
                       help="obscurance: direct light + I_A·W (fast, the default); gi: direct "
                            "light + path-traced indirect light, --rays paths per texel (a "
                            "reference to judge obscurances by; slower)")
    model.add_argument("--specular", choices=baker.settings.SPECULAR_STRATEGIES,
                       default=d.specular,
                       help="at a mirror or glass: b follows the path, ρ of its summed length "
                            "(default); a follows it, ρ of the first distance; c counts R_ave "
                            "and ρ = 1 with no extra ray")
    model.add_argument("--mirror-roughness", type=positive_float, default=d.mirror_roughness,
                       metavar="R", help="metals smoother than this are mirrors "
                                         f"(default {d.mirror_roughness:g})")
    model.add_argument("--translucent", type=positive_float, default=d.translucent,
                       metavar="F", help="a translucent neighbour reflects F × R_ave, with ρ = 1 "
                                         f"(default {d.translucent:g})")
    model.add_argument("--max-depth", type=int, default=d.max_depth, metavar="N",
                       help="most mirror/glass bounces of one ray (default "
                            f"{d.max_depth}; rays that reach it are counted)")
    model.add_argument("--max-rays", type=int, default=d.max_rays, metavar="N",
                       help=f"the most rays a texel gets with --target-error (default {d.max_rays})")
    model.add_argument("--foliage", choices=baker.settings.FOLIAGE_MODES, default=d.foliage,
                       help="approx: leaves and marked grass get their obscurance from a closed "
                            "form (Hegeman et al.) fitted per crown to a few traced texels, and "
                            "the crowns shade the rest in closed form; the report gives its "
                            "error against tracing (default none: trace every texel)")
    model.add_argument("--foliage-density", type=positive_float, metavar="AR",
                       help="with --foliage approx: the crowns' αρ per cubic unit, instead of "
                            "fitting it (a node's extras.foliage_density wins)")
    direct = bake.add_argument_group("direct light (KHR_lights_punctual, emissive surfaces, sky)")
    direct.add_argument("--shadow-rays", type=int, default=d.shadow_rays, metavar="N",
                        help="shadow rays per texel towards a light with a size (soft shadows); "
                             f"a hard light casts 1 (default {d.shadow_rays})")
    direct.add_argument("--light-radius", type=positive_float, default=d.light_radius,
                        metavar="DISTANCE",
                        help="sphere radius of point and spot lights without extras.radius, in "
                             "scene units; 0: hard shadows (default 0)")
    direct.add_argument("--light-angle", type=positive_float, default=d.light_angle,
                        metavar="DEGREES",
                        help="angular diameter of directional lights without "
                             "extras.angular_diameter (the sun's is 0.53); 0: hard (default 0)")
    direct.add_argument("--emissive-rays", type=int, default=d.emissive_rays, metavar="N",
                        help="shadow rays per texel towards emissive surfaces "
                             f"(default {d.emissive_rays})")
    direct.add_argument("--sky", type=rgb, metavar="R,G,B",
                        help="add a sky of this linear radiance at the zenith (an open floor "
                             "under a uniform sky L gets π·L); default: no sky")
    direct.add_argument("--sky-horizon", type=rgb, metavar="R,G,B",
                        help="the sky's radiance at the horizon and below: a two-colour "
                             "gradient (default: uniform)")
    direct.add_argument("--sky-image", metavar="FILE",
                        help="light the scene with an equirectangular panorama (.hdr or .exr, "
                             "linear, +Y up, three.js's layout) instead of --sky, "
                             "importance-sampled by its brightness; see docs/sky.md")
    direct.add_argument("--sky-rotation", type=float, default=d.sky_rotation, metavar="DEGREES",
                        help="turn --sky-image about +Y (+Z towards +X) (default 0)")
    direct.add_argument("--sky-intensity", type=positive_float, default=d.sky_intensity,
                        metavar="F", help="factor on --sky-image's radiance (default 1)")
    direct.add_argument("--sky-rays", type=int, default=None, metavar="N",
                        help=f"rays per texel that look for the sky (default {DEFAULT_RAYS}; "
                             f"{FIRST_ROUND_RAYS} with --target-error)")
    direct.add_argument("--supersample", type=int, default=d.supersample, metavar="N",
                        help="sub-texel positions the shadow, emissive, sky and obscurance "
                             "rays of each texel start from (ray s from position s mod N): "
                             "anti-aliased shadow edges and obscurance details; a hard light "
                             f"casts N rays (default {d.supersample}: none)")
    out = bake.add_argument_group("output")
    out.add_argument("--carrier", choices=baker.settings.CARRIERS, default=d.carrier,
                     help="how the bake reaches viewers: emissive (the baked diffuse light as "
                          "the emission of a copy of each material, which keeps its specular "
                          "response: shows in every glTF viewer, no plugin; base colour "
                          "textures at lightmap resolution), moz (MOZ_lightmap, for three.js "
                          "with our plugin, Hubs, baker view) or occlusion (visibility, 1 = "
                          "open, as the core occlusionTexture, for viewers' own lights) "
                          "(default emissive; moz with --directional)")
    out.add_argument("--baked-lights", choices=baker.settings.BAKED_LIGHTS,
                     help="the KHR_lights_punctual lights once baked: remove them (viewers "
                          "would light the baked surfaces twice), keep them, or keep them and "
                          "bake indirect light only (default: keep; remove for --carrier "
                          "moz)")
    out.add_argument("--encoding", choices=baker.settings.ENCODINGS, default=d.encoding,
                     help="how PNG texels map to light, by what reads them: linear (the "
                          "three.js MOZ_lightmap plugin, Hubs, baker view) or srgb (the "
                          "MOZ_lightmap extension text) (default: srgb, and only srgb, for "
                          "--carrier emissive; linear for the others)")
    out.add_argument("--clip-percentile", type=float, default=d.clip_percentile, metavar="P",
                     help="each page's MOZ_lightmap intensity is this percentile of its texels' "
                          "brightness; the few brighter texels clip (reported), the rest keep "
                          f"the 8 bits; 100 scales to the peak (default {d.clip_percentile:g})")
    out.add_argument("--occlusion", choices=baker.settings.OCCLUSION_MODES, default=d.occlusion,
                     help="also write the visibility (1 = unoccluded) as the core "
                          "occlusionTexture next to the bake: viewers dim their environment's "
                          "light by it (three.js: a MOZ_lightmap too) (default none)")
    out.add_argument("--directional", action="store_true",
                     help="directional lightmaps: an extra page holding each texel's dominant "
                          "light direction, which baker view and the three.js plugin decode "
                          "with the material's normal map (BAKER_lightmap_directional; the "
                          "carrier is then moz unless --carrier says otherwise: see "
                          "docs/directional.md)")
    out.add_argument("--denoise", action="store_true",
                     help="denoise each chart of the lightmap with Intel Open Image Denoise's "
                          "lightmap filter before dilation (needs pip install \"baker[denoise]\"; "
                          "RMSE at 16 rays 3-3.5x lower, see docs/denoise.md)")
    out.add_argument("--smooth", action="store_true",
                     help="smooth the light across texels near each other in the world (across "
                          "charts and objects, never across creases, walls or gaps), as wide "
                          "as its own error estimate says pays; the report gives that error "
                          "(RMSE at 16 rays 2-7x lower where surfaces are smooth, see "
                          "docs/denoise.md)")
    out.add_argument("--lightmaps", type=Path, metavar="DIR",
                     help="also write each lightmap page as a file in DIR (see --format)")
    out.add_argument("--format", choices=baker.settings.LIGHTMAP_FORMATS, default="png", dest="lightmaps_format",
                     help="the --lightmaps files: png (the embedded 8-bit image) or the float "
                          "pages, unclipped: hdr (Radiance RGBE, 0.4%%) or exr (float32) "
                          "(default png)")
    out.add_argument("--error-map", type=Path, metavar="DIR",
                     help="also write each page's per-texel standard error (lightmap units) "
                          "as .hdr (values) and .png (scaled to the page's largest) in DIR")
    add_report(out)
    running = bake.add_argument_group("running")
    running.add_argument("--allow-hard-links", action="store_true",
                         help="read files the scene names that have other names too (hard "
                              "links; refused by default: one may be outside its folder)")
    running.add_argument("--max-total-rays", type=int, default=d.max_total_rays, metavar="N",
                         help="refuse, before any ray, a bake that would cast more rays than N "
                              "(texels × rays a texel; default %(default).0e)")
    running.add_argument("--threads", type=int, default=d.threads,
                         help="ray-casting threads (default: one per core)")
    add_cluster_option(running)
    running.add_argument("--quiet", action="store_true", help="print nothing but errors")
    add_state_options(running)
    add_debug(running)


def add_cluster_option(group) -> None:
    """``--cluster HOST:PORT`` (``Settings.cluster``), for ``bake`` and ``rebake``."""
    group.add_argument("--cluster", metavar="HOST:PORT",
                       help="trace the bake's parts (a rebake's: its dirty texels) on the Ray "
                            "cluster whose head is at HOST:PORT (`ray start --head`); the same "
                            "bytes as on this machine. --threads is then the CPUs of a worker "
                            "each part takes (default 1). Needs pip install \"baker[cluster]\" "
                            "here and on every machine; see docs/cluster.md")


def settings_from(args: argparse.Namespace) -> baker.Settings:
    """The ``baker.Settings`` that the command line asks for: every field of ``Settings`` that
    the parser has an option for (``chunk_texels`` and ``d_max_fraction`` have none and keep
    their defaults), so a new setting needs only its option."""
    return baker.Settings(**{f.name: getattr(args, f.name) for f in dataclasses.fields(baker.Settings)
                             if hasattr(args, f.name)})


def rgb(text: str) -> tuple[float, float, float]:
    """``R,G,B`` (or one number for grey) from the command line as three floats."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"not R,G,B numbers: {text!r}") from None
    if len(values) == 1:
        values *= 3
    if len(values) != 3:
        raise argparse.ArgumentTypeError(f"give three numbers R,G,B (or one), not {text!r}")
    return (values[0], values[1], values[2])


def _rays_per_texel(result: baker.BakeResult) -> str:
    """The obscurance rays a texel got, and with ``--method gi`` its GI paths: ``--rays``, or
    with adaptive rounds their mean and range (the first round alone would understate them).
    With ``--method gi`` the obscurance has no rounds: W is not in the lightmap."""
    s = result.settings
    adaptive = s.target_error is not None and result.texels > 0
    if s.method == "gi":
        paths = (f"{result.report['gi']['paths'] / result.texels:.1f} GI paths/texel on average "
                 f"(rounds from {s.rays}, at most {s.max_rays})" if adaptive
                 else f"{s.rays} GI paths/texel")
        return f"{paths}, {s.rays} obscurance rays/texel"
    if not adaptive:
        return f"{s.rays} rays/texel"
    return (f"{result.rays / result.texels:.1f} rays/texel on average (rounds from {s.rays}, "
            f"at most {s.max_rays})")


def print_summary(result: baker.BakeResult) -> None:
    """What was baked, the plan, notes, rays/s and stage times, on stdout."""
    s = result.settings
    times = result.report["stage_seconds"]
    print(f"baked {result.output}")
    print(f"  {result.texels:,} texels on {result.pages} page(s) of "
          f"{result.report['atlas']['width']}×{result.report['atlas']['height']}, "
          + (f"TEXCOORD_{s.uv} (about {result.report['atlas']['texel_density']:.4g} "
             "texels/unit)" if s.uv is not None else f"texel density {s.texel_density:.4g}/unit")
          + f", d_max {s.d_max:.4g}, {_rays_per_texel(result)}")
    print(f"  carrier {s.carrier} ({s.encoding}), baked lights {s.baked_lights}; "
          f"baker view {result.output} shows it")
    print("\n".join(result.plan.lines()))
    for note in result.report["notes"]:
        print(f"  note: {note}")
    for warning, count in result.report["warnings"].items():
        print(f"  warning: {count} × {warning}")
    rebake = result.rebake or {}
    rays = (f"{rebake['rays']:,} rays cast (the lightmaps rest on {result.rays:,} obscurance "
            f"and {result.report.get('shadow_rays', 0):,} shadow/sky rays)"
            if rebake.get("incremental") else
            f"{result.rays:,} obscurance rays, {result.report['rays_per_second'] / 1e6:.2f} M rays/s, "
            f"{result.report.get('shadow_rays', 0):,} shadow/sky rays"
            + (f", {result.report['gi']['rays']:,} GI path rays" if "gi" in result.report else ""))
    foliage = result.report.get("foliage")
    if foliage is not None:
        held = foliage["error"]["held_out"]
        print(f"  foliage approx: {len(foliage['crowns'])} crown(s) fitted with "
              f"{foliage['rays']:,} rays; against tracing (held out) RMSE {held['rmse']:.3g}, "
              f"bias {held['bias']:+.3g}")
    smooth = result.report.get("smooth", {})
    if smooth.get("smoothed"):
        print(f"  smooth: {smooth['width_texels']:g} texel sides wide; estimated RMSE "
              f"{smooth['rmse_before']:.3g} before, {smooth['rmse_after']:.3g} after"
              if smooth["width_texels"] else
              "  smooth: left as baked (smoothing would not lower the error)")
    unseen = result.report.get("rmse_estimate_leaves_out", [])
    error = (f"estimated RMSE at least {result.rmse_estimate:.3g} (it leaves out the noise of "
             f"{' and '.join(unseen)}: 2 rays or more measure it)" if unseen
             else f"estimated RMSE {result.rmse_estimate:.3g}")
    print(f"  {rays}; {error}; {result.seconds:.1f} s "
          f"({', '.join(f'{k} {v:.1f}' for k, v in times.items())})")
    on = result.report.get("cluster")
    if on:  # which worker baked how much, and where the workers' time went
        print(f"  on the cluster at {on['address']}: {on['parts']} parts, "
              + ", ".join(f"{name} {w['texels']:,} texels" for name, w in on["workers"].items())
              + "; workers' " + ", ".join(f"{k} {v:.1f}" for k, v in
                                          on["worker_stage_seconds"].items()) + " s")
        for lost in on.get("parts_run_again", []):  # a worker lost: its part made elsewhere
            print(f"  part {lost['part'] + 1} was run again: its worker was lost "
                  f"({lost['error']})")


def run(args: argparse.Namespace) -> int:
    """Bake; exit code 0, or 4 when no surface got a lightmap (``common.exit_code``)."""
    result = baker.bake(args.scene, args.output, settings_from(args),
                        report_path=report_file(args), lightmaps_dir=args.lightmaps,
                        lightmaps_format=args.lightmaps_format, error_map_dir=args.error_map,
                        quiet=args.quiet, overwrite=args.overwrite, **state_arguments(args))
    return finish(args, result, print_rebake, print_summary)
