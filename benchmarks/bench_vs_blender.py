"""Benchmark: baker against Blender Cycles' AO bake, per unit of error (issue 27).

    python benchmarks/bench_vs_blender.py [--blender bpy|system] [--repeat 3]
        [--scenes cornell boxes] [--images DIR] [--smooth]

``--blender bpy`` (the default): Blender 4.5 LTS from PyPI (the ``bpy`` wheel, Blender as a
Python module, for Python 3.11 only), installed by this benchmark into a venv of its own
(``--bpy-venv``, made with ``python -m venv`` and ``pip install "bpy==4.5.*"`` when missing:
about 1 GB; not a dependency of baker). ``--blender system``: ``blender`` on PATH (Debian:
``apt-get install blender python3-numpy``; measured with 3.4.1). Both need the OpenEXR
package (``--format exr``). Not run in CI.

Two scenes, built as ``bench_fixed_cost.py`` builds them (``assets.make_scenes.cornell_box``,
``assets.many_objects.boxes_and_sphere``, saved to a temporary .glb), except that the Cornell
room's lamp has its emission set to 0: with it, baker's page is L = D + I_A·W, the lamp's direct
light (cast with rays of its own) added to the ambient term, where Blender's AO bake has no
light. With no light and no emission, baker's classic AO (``--rho step --d-max 1``) page is W,
the cosine-weighted fraction of obscurance rays that meet nothing within 1 unit (I_A = 1,
R = 1 for a ray that escapes, 0 for a hit), R = G = B; Cycles' AO bake with the world's AO
distance 1.0 is the same quantity, its AO pass at the surface point (rays cosine-distributed,
1 when nothing is hit within the distance). So the two tools' errors are in the same units.

Each tool, in turn for every ray count N in 4, 16, 64, 256 and every repeat (interleaved, seed
r for repeat r, medians of ``--repeat``), as a new process whose wall time is measured:

- baker: ``python -m baker bake X -o Y --rho step --d-max 1 --page-size 512 --rays N --threads 2
  --quiet --no-state --lightmaps DIR --format exr --seed r``, the checkout's code (the ``baker``
  command on PATH may be an older install), after a warm-up bake that fills a temporary
  ``BAKER_CACHE_DIR`` (the unwrap cache) and numba's cache;
- Blender: ``blender -b --factory-startup -P <script> -- ...`` (with ``bpy``: ``python
  <script> -- ...`` in its venv, the same script importing ``bpy``): import the glTF, join the mesh
  objects into one, one new UV map by Smart UV Project (island margin 2 texels), one plain
  material whose active image node is a 512² float image, Cycles on the CPU, 2 threads,
  N samples, seed r, denoising off, no bounces (``max_bounces`` 0: the default 12 traces paths
  whose light an AO bake throws away; the AO pages were the same bits and the bake call took
  5.8–6.6 s against 9.1–13.2 s on the Cornell room at 64 samples), then
  ``bpy.ops.object.bake(type="AO", margin=2)``. The script prints the bake call's own seconds (the Blender "bake" column); the process's wall
  time includes Blender's start, the import, the join and the unwrap.

Blender pitfalls the script avoids: Cycles' denoising is on by default, and Debian's Blender has
no OpenImageDenoise, so a bake with it on leaves the image untouched (all zero, no error;
``render.render`` at least raises "Build without OpenImageDenoiser"); and ``image.save()`` of a
generated float image writes its pixels sRGB-encoded into the .exr (0.1 read back as 0.349),
so the script saves ``image.pixels`` with numpy instead.

RMSE: against each tool's own high-sample bake of the same layout, another seed
(``--reference-rays`` 2048 for baker, ``--reference-spp`` 1024 for Blender), over the texels the
reference covers, one channel. baker's reference is baked in this process
(``pipeline.full.compute``, the same settings; its ``lightmaps.covered`` are the texels), after
checking that the API and the CLI give identical pages at 4 rays (same layout, same bits).
Blender's reference is baked with margin 0 into an image filled with −1 first, so the pixels
still at −1 are the ones no triangle covers (Smart UV Project is deterministic: every run has
the layout of the reference). The RMSE holds the reference's own noise as well; with two or
more repeats the run also prints each tool's noise from pairs of its own bakes (repeats 0 and
1, other seeds: RMSE between them / √2, no reference involved) and, from the 256-sample
points, what the reference adds (√(RMSE² − noise²)).

Per unit of error: each tool's (RMSE, median wall seconds) points joined in log-log; at every
RMSE both reach within their measured ranges (each measured point's RMSE), the time each tool
takes to reach it. Then the issue's row: at the error of N = 4, 16, 64, 256 rays (the RMSE of
Blender's N-sample bake), Blender's time ÷ baker's, baker's time read off its line (beyond
its measured points, the line through its last two, marked ~). What this does not say: the texel counts differ (Smart UV Project packs the
page fuller than baker's xatlas layout at its derived density: both counts are printed), so at
equal RMSE Blender may be baking more texels, or fewer; the two layouts differ in where the
texels are, and so in the error's spatial pattern; Blender's margin fill and baker's
post-process (dilation, seams) are not in the RMSE; the seconds are whole processes on this
machine's 2 cores, Blender's including 1.2–2.7 s of start, import, join and unwrap; baker's
sampler is Owen-scrambled Sobol, Cycles' its default pattern. ``--images DIR`` writes
PNGs (clipped to [0, 1]) of repeat 0's pages and the references, to look at. ``--smooth``:
baker's bakes smoothed in world space (``baker bake --smooth``, docs/denoise.md), measured
against the same unsmoothed reference.
"""

from __future__ import annotations

import argparse
import glob
import math
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from assets.gltf_builder import edited_glb  # noqa: E402
from assets.make_scenes import cornell_box  # noqa: E402
from assets.many_objects import boxes_and_sphere  # noqa: E402
from bench_fixed_cost import compile_bytecode  # noqa: E402

SCENES = {"cornell": ("Cornell room, lamp off", cornell_box),
          "boxes": ("200 boxes + sphere", boxes_and_sphere)}
RAYS = (4, 16, 64, 256)
SIZE = 512  # the page, both tools
DISTANCE = 1.0  # baker's --d-max, Blender's world AO distance
MARGIN = 2  # texels: Blender's island margin and bake margin (baker's --padding default)
THREADS = 2
REFERENCE_SEED = 1000

# Runs inside Blender: argv after "--" is the glTF file, samples, seed, page size, AO distance,
# margin in texels, 1 for the coverage run (no margin; pixels no triangle covers left at -1) and
# the .npy to write (the R channel, row 0 at the bottom as Blender stores it). Prints "BAKE <s> ...".
IN_BLENDER = r'''
import sys, time
import numpy
numpy.bool = bool  # Blender 3.4's glTF importer uses numpy.bool, which Debian's numpy 1.24 no longer has
import bpy
args = sys.argv[sys.argv.index("--") + 1:]
path, samples, seed, size, distance, margin, coverage, out = (
    args[0], int(args[1]), int(args[2]), int(args[3]), float(args[4]), int(args[5]), args[6] == "1", args[7])
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=path)
scene = bpy.context.scene
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = samples
scene.cycles.seed = seed
scene.cycles.use_adaptive_sampling = False
scene.cycles.use_denoising = False  # on by default: without OIDN (Debian) the bake writes nothing
scene.render.threads_mode = "FIXED"
scene.render.threads = 2
scene.cycles.max_bounces = 0  # the AO pass's bits unchanged, the bake call about half as long
scene.world = bpy.data.worlds.new("ao")
scene.world.light_settings.distance = distance  # Cycles' AO distance
meshes = [o for o in scene.objects if o.type == "MESH"]
bpy.ops.object.select_all(action="DESELECT")
for o in meshes:
    o.select_set(True)
bpy.context.view_layer.objects.active = meshes[0]
bpy.ops.object.make_single_user(object=True, obdata=True)
bpy.ops.object.join()  # one object: one image, one bake
joined = bpy.context.view_layer.objects.active
mesh = joined.data
mesh.uv_layers.active = mesh.uv_layers.new(name="lightmap")  # the bake's UV map: the active one
bpy.ops.object.mode_set(mode="EDIT")
bpy.ops.mesh.select_all(action="SELECT")
bpy.ops.uv.smart_project(island_margin=margin / size)
bpy.ops.object.mode_set(mode="OBJECT")
image = bpy.data.images.new("ao", size, size, alpha=True, float_buffer=True)
plain = bpy.data.materials.new("plain")  # AO ignores the material: one slot, one image node
plain.use_nodes = True
mesh.materials.clear()
mesh.materials.append(plain)
mesh.polygons.foreach_set("material_index", numpy.zeros(len(mesh.polygons), numpy.int32))
for slot in joined.material_slots:
    node = slot.material.node_tree.nodes.new("ShaderNodeTexImage")
    node.image = image
    slot.material.node_tree.nodes.active = node  # the bake writes the active image node
if coverage:
    image.pixels.foreach_set(numpy.full(size * size * 4, -1.0, numpy.float32))
started = time.perf_counter()
bpy.ops.object.bake(type="AO", margin=0 if coverage else margin, margin_type="EXTEND",
                    use_clear=not coverage)
seconds = time.perf_counter() - started
pixels = numpy.empty(size * size * 4, numpy.float32)
image.pixels.foreach_get(pixels)  # image.save() would write these sRGB-encoded
numpy.save(out, pixels.reshape(size, size, 4)[..., 0])
triangles = sum(len(p.vertices) - 2 for p in mesh.polygons)
print(f"BAKE {seconds:.4f} s, {triangles} triangles, {len(joined.material_slots)} material slot(s)")
'''


def make_scene(name: str, folder: Path) -> Path:
    """The scene saved as a .glb in ``folder``; the Cornell room's lamp without emission."""
    path = SCENES[name][1]().save(folder / f"{name}.glb")
    if name == "cornell":
        def lamp_off(document) -> None:
            for material in document.materials:
                material.emissiveFactor = [0.0, 0.0, 0.0]
        edited_glb(path, lamp_off, path)
    return Path(path)


def read_exr(path: Path) -> np.ndarray:
    """(H, W) float64: the R channel of baker's float page."""
    import OpenEXR
    with OpenEXR.File(str(path)) as exr:
        return np.asarray(exr.channels()["RGB"].pixels, np.float64)[..., 0]


def baker_bake(scene: Path, rays: int, seed: int, folder: Path,
               smooth: bool = False) -> tuple[float, np.ndarray]:
    """(wall seconds, page) of one ``baker bake`` process (``smooth``: with ``--smooth``)."""
    pages = folder / "pages"
    shutil.rmtree(pages, ignore_errors=True)
    command = [sys.executable, "-m", "baker", "bake", str(scene), "-o", str(folder / "out.glb"),
               "--rho", "step", "--d-max", f"{DISTANCE:g}", "--page-size", str(SIZE),
               "--rays", str(rays), "--threads", str(THREADS), "--quiet", "--no-state",
               "--lightmaps", str(pages), "--format", "exr", "--seed", str(seed)] + (
                   ["--smooth"] if smooth else [])
    started = time.perf_counter()
    subprocess.run(command, cwd=ROOT, check=True)
    seconds = time.perf_counter() - started
    found = sorted(glob.glob(str(pages / "*.exr")))
    if len(found) != 1:
        sys.exit(f"expected one lightmap page, baker wrote {len(found)}")
    return seconds, read_exr(Path(found[0]))


def baker_reference(scene: Path, rays: int, seed: int,
                    smooth: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(page, covered) of a bake in this process with the CLI's settings (``smooth``: and
    ``--smooth``): (H, W) float64 (the float32 values the CLI's .exr holds), bool."""
    from baker.gltf.load import load
    from baker.pipeline.full import compute
    from baker.settings import Settings
    done = compute(load(scene), Settings(page_size=SIZE, rays=rays, rho="step", d_max=DISTANCE,
                                         seed=seed, threads=THREADS, smooth=smooth))
    if done.lightmaps.light.shape[0] != 1:
        sys.exit(f"expected one lightmap page, the bake made {done.lightmaps.light.shape[0]}")
    # as float32, what the .exr holds
    return done.lightmaps.light[0, ..., 0].astype(np.float32).astype(np.float64), done.lightmaps.covered[0]


def blender_bake(script: Path, scene: Path, samples: int, seed: int, folder: Path,
                 coverage: bool = False) -> tuple[float, float, np.ndarray]:
    """(wall seconds, bake-call seconds, R channel (H, W), row 0 at the top) of one Blender
    process; ``coverage``: no margin, the pixels no triangle covers left at −1."""
    out = folder / "blender.npy"
    command = [*BLENDER, str(script), "--", str(scene),
               str(samples), str(seed), str(SIZE), f"{DISTANCE:g}", str(MARGIN), "1" if coverage else "0",
               str(out)]
    started = time.perf_counter()
    run = subprocess.run(command, capture_output=True, text=True, env=blender_environment())
    seconds = time.perf_counter() - started
    said = re.search(r"^BAKE ([0-9.]+) s", run.stdout, re.MULTILINE)
    if run.returncode != 0 or said is None:
        sys.exit(f"blender failed ({run.returncode}):\n{run.stdout[-2000:]}\n{run.stderr[-2000:]}")
    return seconds, float(said.group(1)), np.load(out).astype(np.float64)[::-1]


BLENDER = ["blender", "-b", "--factory-startup", "-P"]  # how a Blender process starts on a
# script (``use_bpy`` sets it to the bpy venv's Python)
BPY = "bpy==4.5.*"  # Blender 4.5 LTS


def use_bpy(venv: Path) -> str:
    """Make ``blender_bake`` run the bpy wheel's Blender in ``venv`` (made and filled with
    ``BPY`` when it has no bpy); returns Blender's version line."""
    python = venv / "bin" / "python"
    check = [str(python), "-c", "import bpy; print('Blender', bpy.app.version_string)"]
    if not python.exists() or subprocess.run(check, capture_output=True).returncode != 0:
        print(f"installing {BPY} into {venv} (once)", flush=True)
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
        subprocess.run([str(python), "-m", "pip", "install", "--quiet", BPY], check=True)
    BLENDER[:] = [str(python)]
    return subprocess.run(check, capture_output=True, text=True, check=True).stdout.strip()


def blender_environment() -> dict[str, str]:
    """This environment with PATH rid of this Python's folders: Blender's own Python takes its
    prefix from the first python3 on PATH, and this one's (pyenv, a venv) has no numpy for it."""
    mine = {os.path.realpath(p) for p in (sys.prefix, sys.base_prefix, sys.exec_prefix)}
    kept = [d for d in os.environ.get("PATH", "").split(os.pathsep)
            if not any(os.path.realpath(d).startswith(p + os.sep) for p in mine)]
    return {**os.environ, "PATH": os.pathsep.join(kept)}


def rmse(a: np.ndarray, b: np.ndarray, covered: np.ndarray) -> float:
    """Root mean square of a − b over the covered texels."""
    return float(np.sqrt(np.mean((a[covered] - b[covered]) ** 2)))


def seconds_at(error: float, points: list[tuple[float, float]],
               beyond: bool = False) -> float | None:
    """Seconds to reach RMSE ``error`` along (RMSE, seconds) points joined in log-log; outside
    their range None, or with ``beyond`` the line through the two nearest points."""
    points = sorted(points)
    pairs = list(zip(points, points[1:]))
    for (e0, t0), (e1, t1) in pairs:
        if e0 <= error <= e1:
            break
    else:
        if not beyond or not pairs:
            return None
        (e0, t0), (e1, t1) = pairs[0] if error < points[0][0] else pairs[-1]
    if e1 == e0:
        return t0
    f = math.log(error / e0) / math.log(e1 / e0)
    return math.exp(math.log(t0) + f * (math.log(t1) - math.log(t0)))


def save_png(page: np.ndarray, path: Path) -> None:
    """An 8-bit grey picture of ``page`` clipped to [0, 1]."""
    from PIL import Image
    Image.fromarray(np.round(np.clip(page, 0.0, 1.0) * 255).astype(np.uint8)).save(path)


def bench_scene(name: str, script: Path, args, folder: Path) -> None:
    """Bake one scene with both tools; print its table and the time per unit of error."""
    title = SCENES[name][0]
    scene = make_scene(name, folder)
    _, warm = baker_bake(scene, 4, 0, folder, args.smooth)  # fills the unwrap and numba caches
    check, covered = baker_reference(scene, 4, 0, args.smooth)
    if warm.shape != check.shape or not np.array_equal(warm, check):
        sys.exit("baker's CLI and API gave different pages: the reference would not match")
    reference, covered = baker_reference(scene, args.reference_rays, REFERENCE_SEED)
    _, _, blender_ref = blender_bake(script, scene, args.reference_spp, REFERENCE_SEED, folder,
                                     coverage=True)
    blender_covered = blender_ref >= 0.0
    images = Path(args.images) if args.images else None
    if images:
        images.mkdir(parents=True, exist_ok=True)
        save_png(reference, images / f"{name}_baker_ref.png")
        save_png(np.where(blender_covered, blender_ref, 0.0), images / f"{name}_blender_ref.png")
    runs = {(tool, n): [] for tool in ("baker", "blender") for n in RAYS}
    for r in range(args.repeat):  # interleaved: every count of both tools in each repeat
        for n in RAYS:
            seconds, page = baker_bake(scene, n, r, folder, args.smooth)
            runs["baker", n].append((seconds, None, page))
            seconds, call, page = blender_bake(script, scene, n, r, folder)
            runs["blender", n].append((seconds, call, page))
            if images and r == 0:
                save_png(runs["baker", n][0][2], images / f"{name}_baker_{n}.png")
                save_png(page, images / f"{name}_blender_{n}.png")
    masks = {"baker": (reference, covered), "blender": (blender_ref, blender_covered)}
    table = {}
    for (tool, n), done in runs.items():
        ref, mask = masks[tool]
        errors = [rmse(page, ref, mask) for _, _, page in done]
        noise = (rmse(done[0][2], done[1][2], mask) / math.sqrt(2.0) if len(done) > 1 else None)
        calls = [call for _, call, _ in done if call is not None]
        table[tool, n] = (statistics.median(s for s, _, _ in done), statistics.median(errors),
                          noise, statistics.median(calls) if calls else None)
    print(f"\n{title}: baker {int(covered.sum()):,} texels ({reference.shape[1]}×{reference.shape[0]} "
          f"page), Blender {int(blender_covered.sum()):,} texels ({SIZE}²); mean AO over them "
          f"{reference[covered].mean():.3f} / {blender_ref[blender_covered].mean():.3f}; "
          f"references {args.reference_rays} rays / {args.reference_spp} spp; medians of {args.repeat}")
    print(f"  {'N':>4} | {'baker s':>8} {'RMSE':>8} {'noise':>8} | {'Blender s':>9} "
          f"{'bake call':>9} {'RMSE':>8} {'noise':>8}")
    shown = lambda x: f"{x:8.5f}" if x is not None else f"{'—':>8}"  # noqa: E731
    for n in RAYS:
        bs, be, bn, _ = table["baker", n]
        ls, le, ln, lc = table["blender", n]
        print(f"  {n:>4} | {bs:8.2f} {be:8.5f} {shown(bn)} | {ls:9.2f} {lc:9.2f} {le:8.5f} {shown(ln)}")
    if args.repeat > 1:
        for tool in ("baker", "blender"):
            _, e, noise, _ = table[tool, RAYS[-1]]
            floor = math.sqrt(max(e * e - noise * noise, 0.0))
            print(f"  {tool}: the reference adds about {floor:.5f} in quadrature to the RMSE "
                  f"at {RAYS[-1]} (√(RMSE² − noise²))")
    points = {tool: [(table[tool, n][1], table[tool, n][0]) for n in RAYS] for tool in masks}
    calls = [(table["blender", n][1], table["blender", n][3]) for n in RAYS]
    targets = sorted({e for tool in points for e, _ in points[tool]}, reverse=True)
    print("  per unit of error (log-log between the measured points; wall seconds to reach the RMSE):")
    print(f"  {'RMSE':>8} | {'baker s':>8} | {'Blender s':>9} {'bake call':>9} | Blender / baker")
    for error in targets:
        b, bl, call = seconds_at(error, points["baker"]), seconds_at(error, points["blender"]), \
            seconds_at(error, calls)
        if b is None or bl is None:
            continue
        print(f"  {error:8.5f} | {b:8.2f} | {bl:9.2f} {call:9.2f} | {bl / b:.2f}×")
    ratios = []
    for n in RAYS:
        seconds, error = table["blender", n][:2]
        b = seconds_at(error, points["baker"], beyond=True)
        inside = seconds_at(error, points["baker"]) is not None
        ratios.append(f"{'' if inside else '~'}{seconds / b:.2f}")
    print(f"  | {title} | {' / '.join(ratios)}× | (Blender ÷ baker time at the error of "
          f"{' / '.join(map(str, RAYS))} rays)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--scenes", nargs="+", choices=sorted(SCENES), default=list(SCENES))
    parser.add_argument("--reference-rays", type=int, default=2048)
    parser.add_argument("--reference-spp", type=int, default=1024)
    parser.add_argument("--images", metavar="DIR", help="write PNGs of the pages here")
    parser.add_argument("--smooth", action="store_true",
                        help="baker's bakes with --smooth (its reference without)")
    parser.add_argument("--blender", choices=("bpy", "system"), default="bpy",
                        help="Blender 4.5 LTS from PyPI in a venv of its own, or blender on PATH")
    parser.add_argument("--bpy-venv", type=Path,
                        default=Path.home() / ".cache" / "baker-bench" / "bpy-4.5")
    args = parser.parse_args()
    if args.blender == "bpy":
        if sys.version_info[:2] != (3, 11):
            sys.exit("bench_vs_blender: the bpy 4.5 wheels are for Python 3.11 only")
        version = use_bpy(args.bpy_venv)
    elif shutil.which("blender", path=blender_environment()["PATH"]) is None:
        sys.exit("bench_vs_blender: blender is not on PATH (Debian: apt-get install blender "
                 "python3-numpy); nothing measured")
    else:
        version = subprocess.run(["blender", "--version"], capture_output=True,
                                 text=True).stdout.splitlines()[0]
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                            capture_output=True, text=True).stdout.strip()
    compile_bytecode()  # as Blender's wheel, installed by pip, has its scripts'
    print(f"{version or 'blender'} ({args.blender}); baker at {commit}"
          f"{' with --smooth' if args.smooth else ''}; "
          f"{THREADS} threads each, {os.cpu_count()} cores; "
          f"load average {os.getloadavg()[0]:.2f}")
    with tempfile.TemporaryDirectory(prefix="bench-vs-blender-") as temp:
        folder = Path(temp)
        os.environ["BAKER_CACHE_DIR"] = str(folder / "cache")  # starts empty: the warm-up fills it
        script = folder / "ao_bake.py"
        script.write_text(IN_BLENDER)
        for name in args.scenes:
            bench_scene(name, script, args, folder)
    print(f"\nload average at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
