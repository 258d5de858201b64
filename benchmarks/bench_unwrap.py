"""Benchmark: what an unwrap costs cold, after an edit, from the cache and at another density,
and the atlas it makes (texels used, stretch, seams), against another checkout's baker.

Scenes: the room of 200 boxes and a sphere (``assets/many_objects.py``, 98,732 triangles in 202
meshes, a 512² page as ``bench_fixed_cost.py``); with ``--level`` the level of 400 distinct
meshes (``many_objects.level``, 1,024,812 triangles) at a 4096² page; with ``--million`` the
1M-triangle terrain of ``bench_million.py`` (default settings); with ``--rock`` a crumpled rock
of 327,680 triangles on a floor (default settings), with ``--small-rock`` one of 20,480; with
``--ramp`` a helical ramp of 16,002 long thin triangles. For each, ``unwrap.unwrap`` at the
derived density (fitted to one page, as a default bake) is timed cold (empty cache), after an
edit (the mesh of (lower) median triangle count stretched 10 % along x, which changes the
derived density: the cache holds the scene before the edit), from the cache, and at 0.8 of the
density (the cache holding the charts: ``--texel-density`` changed),
medians of ``--repeat``, with the atlas's:

- pages and utilisation (texels the charts cover over the pages');
- stretch: triangles' texel area over world area × density², area-weighted mean and 5–95 %;
- seams: the share of the length of the mesh's inner edges (two triangles meeting at an edge,
  corners welded by position) whose two sides have different UVs, in metres and as a share.

``--against DIR`` first runs the same in a child with DIR's baker (e.g. /work/main), scene by
scene, interleaved: an A/B in one run.

    python benchmarks/bench_unwrap.py [--level] [--million] [--rock] [--repeat 3] [--against DIR]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
CODE = os.environ.get("BENCH_UNWRAP_CODE", str(ROOT))  # whose baker (``--against``)
sys.path.insert(0, str(ROOT))
sys.path.insert(0, CODE)  # before anything imports baker: the scenes are built by this
# checkout's assets (which use its baker's glTF objects) in the parent only (``scene_file``)

from baker.atlas import unwrap  # noqa: E402
from baker.geometry.world import build_world  # noqa: E402
from baker.gltf.load import load  # noqa: E402
from baker.pipeline.full import bounds_of_baked  # noqa: E402
from baker.settings import Settings, resolve  # noqa: E402


def scene_file(name: str, folder: Path) -> Path:
    """The scene ``name`` of ``SCENES`` saved as a .glb in ``folder``."""
    from assets.many_objects import boxes_and_sphere, level
    from benchmarks.bench_million import terrain

    builders = {"boxes": boxes_and_sphere, "level": level, "million": terrain,
                "rock": rock_on_a_floor, "small_rock": lambda: rock_on_a_floor(5), "ramp": ramp}
    return builders[name]().save(folder / f"{name}.glb")


def ramp(steps: int = 8001):
    """A ramp winding twice round, 1 to 2 m from its axis, of 2 · ``steps`` long thin
    triangles (1 m by 1.2 mm at the default): one chart that overlaps itself once projected,
    split until it does not (``planar``), its triangles across many cells of a grid."""
    from assets.gltf_builder import GltfBuilder

    angle = np.linspace(0, 4 * np.pi, steps + 1)
    inner = np.stack([np.cos(angle), angle * 0.05, np.sin(angle)], axis=1)
    k = np.arange(steps)
    b = GltfBuilder()
    b.node("ramp", b.mesh("ramp", np.concatenate([inner, inner * [2.0, 1.0, 2.0]]),
                          np.concatenate([np.stack([k, k + 1, k + steps + 1], 1),
                                          np.stack([k + 1, k + steps + 2, k + steps + 1], 1)]),
                          material=b.material("ramp", (0.6, 0.6, 0.6))))
    return b


def rock_on_a_floor(subdivisions: int = 7):
    """A crumpled rock of 20·4^subdivisions triangles (``gltf_builder.rock``, 1 m; 327,680 by
    default) on an 8 m floor: charts of its projection fold over (``planar``: split until they
    do not), where xatlas's time per triangle grows with a mesh's size."""
    from assets.gltf_builder import GltfBuilder, quad, rock

    b = GltfBuilder()
    stone, grey = b.material("rock", (0.5, 0.45, 0.4)), b.material("floor", (0.7, 0.7, 0.7))
    b.node("rock", b.shape_mesh("rock", rock(1.0, subdivisions), material=stone),
           translation=(0.0, 1.0, 0.0))
    b.node("floor", b.shape_mesh("floor", quad(8.0, 8.0), material=grey))
    return b


def edited(scene):
    """``scene`` with the primitive of the baked instance of (lower) median triangle count
    stretched by 10 % along its x axis (every instance of it)."""
    instances = unwrap.baked_instances(scene)
    counts = [len(scene.primitives[scene.instances[i].primitive].triangles) for i in instances]
    lower_median = int(np.argsort(counts, kind="stable")[(len(counts) - 1) // 2])
    chosen = scene.instances[instances[lower_median]]
    primitives = list(scene.primitives)
    prim = primitives[chosen.primitive]
    primitives[chosen.primitive] = dataclasses.replace(prim, positions=prim.positions * [1.1, 1, 1])
    return dataclasses.replace(scene, primitives=tuple(primitives))


def quality(atlas, world) -> str:
    """Pages, utilisation, stretch and seams of ``atlas`` (see the module's docstring)."""
    uv_area, world_area, seam, inner = [], [], 0.0, 0.0
    for inst in atlas.instances:
        uv = inst.uv[inst.triangles] * [atlas.width, atlas.height]
        a, b = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
        uv_area.append(0.5 * np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]))
        corners = np.stack(world.corners(world.instance_triangles(inst.instance)), axis=1)
        world_area.append(0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0],
                                                        corners[:, 2] - corners[:, 0]), axis=1))
        cut, length = _seams(corners, uv)
        seam, inner = seam + cut, inner + length
    uv_area, world_area = np.concatenate(uv_area), np.concatenate(world_area)
    ratio = uv_area / np.maximum(world_area * atlas.texel_density ** 2, 1e-30)
    keep = world_area > 0
    order = np.argsort(ratio[keep])
    ratio, weights = ratio[keep][order], world_area[keep][order] / world_area[keep].sum()
    cumulative = np.cumsum(weights)
    low, high = (ratio[min(np.searchsorted(cumulative, q), len(ratio) - 1)] for q in (0.05, 0.95))
    used = uv_area.sum() / (atlas.page_count * atlas.width * atlas.height)
    return (f"density {atlas.texel_density:.4g}, {atlas.page_count} page(s) of "
            f"{atlas.width}x{atlas.height}, utilisation {used:.3f}, stretch "
            f"{float(weights @ ratio):.3f} [{low:.3f}, {high:.3f}], seams {seam:.1f} m "
            f"({seam / max(inner, 1e-30):.3f} of the inner edges)")


def _seams(corners: np.ndarray, uv: np.ndarray) -> tuple[float, float]:
    """(seam length, inner edge length), world units, of one instance: triangles' world
    corners (m, 3, 3) and page UVs (m, 3, 2); an inner edge is one of exactly two triangles
    (corners welded by position), a seam one whose ends differ in UV between them."""
    _, ids = np.unique(corners.reshape(-1, 3), axis=0, return_inverse=True)
    ids = ids.reshape(-1, 3)
    start, end = ids.reshape(-1), ids[:, [1, 2, 0]].reshape(-1)
    uv_start, uv_end = uv.reshape(-1, 2), uv[:, [1, 2, 0]].reshape(-1, 2)
    swap = start > end
    low, high = np.where(swap, end, start), np.where(swap, start, end)
    uv_low = np.where(swap[:, None], uv_end, uv_start)
    uv_high = np.where(swap[:, None], uv_start, uv_end)
    keys = low * (int(ids.max(initial=0)) + 1) + high
    order = np.argsort(keys, kind="stable")
    ordered = keys[order]
    group_start = np.flatnonzero(np.r_[True, ordered[1:] != ordered[:-1]])
    sizes = np.diff(np.r_[group_start, len(ordered)])
    first = order[group_start[sizes == 2]]
    second = order[group_start[sizes == 2] + 1]
    length = np.linalg.norm(corners - corners[:, [1, 2, 0]], axis=2).reshape(-1)[first]
    differs = (np.abs(uv_low[first] - uv_low[second]).max(axis=1) > 1e-6) | (
        np.abs(uv_high[first] - uv_high[second]).max(axis=1) > 1e-6)
    return float(length[differs].sum()), float(length.sum())


def unwrap_seconds(scene, settings: Settings, factor: float = 1.0):
    """(wall seconds, CPU seconds of the forked children) of one ``unwrap.unwrap`` at the
    derived density (fitted to one page) or, with ``factor``, at that density × ``factor``
    (not fitted), the atlas and world. The CPU time is steadier on a loaded machine."""
    world = build_world(scene)
    resolved = resolve(settings, *bounds_of_baked(world, scene))
    if factor != 1.0:
        resolved = dataclasses.replace(resolved, texel_density=resolved.texel_density * factor)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    atlas = unwrap.unwrap(scene, world, resolved, fit_one_page=factor == 1.0)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    return (wall, cpu), atlas, world


def times(title: str, path: Path, settings: Settings, repeat: int) -> None:
    """Print the cold / one-edit / cached / other-density unwrap seconds of the scene at
    ``path``, medians of ``repeat``, and the cold atlas's quality."""
    scene = load(path)
    changed = edited(scene)
    cold, edit, cached, density = [], [], [], []
    for _ in range(repeat):
        with tempfile.TemporaryDirectory() as cache:
            os.environ["BAKER_CACHE_DIR"] = cache
            seconds, atlas, world = unwrap_seconds(scene, settings)
            cold.append(seconds)
            cached.append(unwrap_seconds(scene, settings)[0])
            density.append(unwrap_seconds(scene, settings, 0.8)[0])
            edit.append(unwrap_seconds(changed, settings)[0])

    def median(runs, k):
        return statistics.median(run[k] for run in runs)

    print(f"  {title} [{Path(unwrap.__file__).parents[2]}]: unwrap cold {median(cold, 0):.2f} s (children's CPU "
          f"{median(cold, 1):.2f} s), one mesh edited {median(edit, 0):.2f} s (CPU "
          f"{median(edit, 1):.2f} s), cached {median(cached, 0):.3f} s, density × 0.8 "
          f"{median(density, 0):.2f} s (CPU {median(density, 1):.2f} s) (medians of {repeat}, "
          f"load {os.getloadavg()[0]:.1f}); {quality(atlas, world)}", flush=True)


SCENES = {"boxes": ("200 boxes + sphere", Settings(page_size=512, rays=4, rho="step", d_max=1.0)),
          "level": ("400 distinct meshes", Settings(page_size=4096)),
          "million": ("1M-triangle terrain", Settings()),
          "rock": ("a rock of 327,680 triangles", Settings()),
          "small_rock": ("a rock of 20,480 triangles", Settings()),
          "ramp": ("a helical ramp of 16,002 long thin triangles", Settings())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--level", action="store_true", help="also the 400-mesh level")
    parser.add_argument("--million", action="store_true", help="also the 1M-triangle terrain")
    parser.add_argument("--rock", action="store_true", help="also a crumpled rock")
    parser.add_argument("--small-rock", action="store_true", help="also a rock of 20,480")
    parser.add_argument("--ramp", action="store_true", help="also a ramp of long thin triangles")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--against", help="a checkout whose baker is timed first (A/B)")
    parser.add_argument("--scene", nargs=2, help=argparse.SUPPRESS)  # name, file: a child's
    args = parser.parse_args()
    if args.scene:
        name, path = args.scene
        times(SCENES[name][0], Path(path), SCENES[name][1], args.repeat)
        return
    names = ["boxes"] + [name for name in ("level", "million", "rock", "small_rock", "ramp")
                         if getattr(args, name)]
    for name in names:
        title, settings = SCENES[name]
        with tempfile.TemporaryDirectory() as folder:
            path = scene_file(name, Path(folder))
            if args.against:
                subprocess.run([sys.executable, __file__, "--scene", name, str(path), "--repeat",
                                str(args.repeat)], check=True,
                               env=dict(os.environ, BENCH_UNWRAP_CODE=args.against))
            times(title, path, settings, args.repeat)


if __name__ == "__main__":
    main()
