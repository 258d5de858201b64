"""Benchmark: speed and memory against scene size, and adaptive against uniform sampling.

For rooms holding 1k, 100k and 1M triangles (a 4 m room, baked, with spheres on a grid as
occluders, not baked, so that unwrapping does not dominate), each in its own process so that
peak memory is its own, prints: texels, obscurance rays, seconds, end-to-end rays/s against raw
embreex on the same rays in the same run, texels/s and peak resident memory.

Then, on the Cornell room, adaptive sampling (``--target-error``) against uniform sampling:
the total rays each needs for the same worst-texel error.

    python benchmarks/bench_scaling.py [--sizes 1000 100000 1000000] [--page-size 1024]
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path


sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from assets.gltf_builder import GltfBuilder, box, uv_sphere  # noqa: E402
from assets.make_scenes import cornell_box  # noqa: E402
from baker.pipeline.full import compute  # noqa: E402
from baker.image.compose import effective_r_ave  # noqa: E402
from baker.gltf.load import load  # noqa: E402
from baker.run.parallel import cores  # noqa: E402
from baker.gltf.scene import Scene  # noqa: E402
from baker.settings import Settings  # noqa: E402
from baker.geometry.surface import LUMINANCE  # noqa: E402
from benchmarks.bench_cornell import raw_embree_rate  # noqa: E402


def room_with_spheres(triangles: int) -> GltfBuilder:
    """A closed 4 m room and a grid of spheres on its floor adding up to ``triangles``."""
    b = GltfBuilder()
    white = b.material("white", (0.7, 0.7, 0.7))
    grey = b.material("grey", (0.5, 0.5, 0.5))
    b.node("room", b.shape_mesh("room", box((4.0, 3.0, 4.0), inward=True), material=white),
           translation=(0.0, 1.5, 0.0))
    count = max(1, int(round((triangles / 2000) ** 0.5))) ** 2  # spheres of ~2000 triangles
    side = int(count ** 0.5)
    rings = max(4, int(round((triangles / count / 4) ** 0.5)))
    sphere = b.shape_mesh("sphere", uv_sphere(1.2 / side, rings, 2 * rings), material=grey)
    for i in range(side):
        for j in range(side):
            b.node(f"sphere {i} {j}", sphere,
                   translation=((i + 0.5) * 3.6 / side - 1.8, 1.2 / side, (j + 0.5) * 3.6 / side - 1.8))
    return b


def _only_the_room(scene: Scene) -> Scene:
    """The scene with only the room baked (the spheres occlude and reflect)."""
    from dataclasses import replace

    room = 0
    return replace(scene, instances=tuple(
        replace(inst, baked=inst.node == room, reason="benchmark occluder")
        for inst in scene.instances))


def measure(triangles: int, page_size: int, rays: int) -> dict:
    """Bake one scene size in this process; its figures as a dict."""
    with tempfile.TemporaryDirectory() as folder:
        scene = _only_the_room(load(room_with_spheres(triangles).save(Path(folder) / "room.glb")))
    started = time.perf_counter()
    done = compute(scene, Settings(page_size=page_size, rays=rays))
    seconds = time.perf_counter() - started
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # the bake's, not the raw test's
    raw, _ = raw_embree_rate(done, done.settings.threads or cores())
    trace = done.stage_seconds["trace"]
    return {"triangles": len(done.world.triangles), "texels": len(done.texels),
            "rays": done.terms.rays, "seconds": seconds, "trace_seconds": trace,
            "rays_per_second": done.terms.rays / trace, "raw_rays_per_second": raw,
            "texels_per_second": len(done.texels) / seconds,
            "peak_mib": peak,
            "lightmap_mib": done.lightmaps.light.nbytes / 2 ** 20}


def adaptive_against_uniform() -> None:
    """Total rays to reach the same worst-texel error: adaptive rounds against uniform rays."""
    with tempfile.TemporaryDirectory() as folder:
        scene = load(cornell_box().save(Path(folder) / "cornell.glb"))
    base = dict(page_size=128, rays=16, max_rays=1024)

    def worst(done) -> float:
        r_ave = effective_r_ave(done.ambient, done.settings.rho)
        scale = float(done.ambient.intensity @ LUMINANCE)
        return float((done.terms.standard_error(r_ave) * scale).max())

    adaptive = compute(scene, Settings(target_error=0.004, **base))
    target = worst(adaptive)
    for rays in (16, 32, 64, 128, 256, 512, 1024):
        uniform = compute(scene, Settings(**{**base, "rays": rays}))
        if worst(uniform) <= target:
            break
    print("\nadaptive sampling, Cornell room at 128², target error 0.004 (lightmap units):")
    print(f"  adaptive: {adaptive.terms.rays:,} rays, worst texel error {target:.4g}, "
          f"rays per texel {adaptive.terms.counts.min()}–{adaptive.terms.counts.max()}")
    print(f"  uniform:  {uniform.terms.rays:,} rays ({rays} per texel) for worst texel error "
          f"{worst(uniform):.4g}")
    print(f"  adaptive needs {adaptive.terms.rays / uniform.terms.rays:.0%} of the uniform rays")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 100_000, 1_000_000])
    parser.add_argument("--page-size", type=int, default=1024)
    parser.add_argument("--rays", type=int, default=64)
    parser.add_argument("--one", type=int, help=argparse.SUPPRESS)  # a child process's size
    args = parser.parse_args()
    if args.one:
        print(json.dumps(measure(args.one, args.page_size, args.rays)))
        return
    print(f"{'triangles':>10}{'texels':>10}{'rays':>13}{'s':>8}{'M rays/s':>10}{'raw':>8}"
          f"{'e2e/raw':>9}{'texels/s':>10}{'peak MiB':>10}{'lightmap MiB':>13}")
    for size in args.sizes:
        run = subprocess.run([sys.executable, __file__, "--one", str(size), "--page-size",
                              str(args.page_size), "--rays", str(args.rays)],
                             capture_output=True, text=True, check=True)
        r = json.loads(run.stdout.strip().splitlines()[-1])
        print(f"{r['triangles']:>10,}{r['texels']:>10,}{r['rays']:>13,}{r['seconds']:>8.1f}"
              f"{r['rays_per_second'] / 1e6:>10.2f}{r['raw_rays_per_second'] / 1e6:>8.2f}"
              f"{r['rays_per_second'] / r['raw_rays_per_second']:>9.0%}"
              f"{r['texels_per_second']:>10,.0f}{r['peak_mib']:>10,.0f}{r['lightmap_mib']:>13,.0f}")
    adaptive_against_uniform()


if __name__ == "__main__":
    main()
