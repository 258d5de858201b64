"""Pages and fill of the default texel density's atlas, before and after it is fitted to one page.

For each scene, unwraps at the derived density as baker did before (``fit_one_page=False``: the
charts spilled onto a second page when xatlas's padding around many small charts filled the
first) and as the default does now, and prints the page count, the texel density, the texels
the charts cover and their share of the pages (the fill). Scenes: the demo scenes, the real ones
in tests/scenes, the 200-box room of ``assets/many_objects.py`` and props strewn through a cube
(``strewn_props``: 20, 60 and 200 of them).

    python benchmarks/bench_default_pages.py [--page-size 1024]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from assets.make_scenes import cornell_box, vase_room  # noqa: E402
from assets.many_objects import boxes_and_sphere, strewn_props  # noqa: E402
from baker.atlas.rasterise import cover  # noqa: E402
from baker.atlas.unwrap import unwrap  # noqa: E402
from baker.geometry.world import build_world  # noqa: E402
from baker.gltf.load import load  # noqa: E402
from baker.pipeline.full import bounds_of_baked  # noqa: E402
from baker.settings import Settings, resolve  # noqa: E402
from tests.bakehelp import REAL_SCENES  # noqa: E402


def scenes(folder: Path) -> dict[str, Path]:
    """Every scene measured, by name."""
    made = {"Cornell box": cornell_box(), "vase room": vase_room(),
            "200 boxes and a sphere": boxes_and_sphere(),
            **{f"{n} strewn props": strewn_props(n, seed=n) for n in (20, 60, 200)}}
    paths = {name: builder.save(folder / f"{k}.glb") for k, (name, builder) in enumerate(made.items())}
    return {**paths, **REAL_SCENES}


def measure(path: Path, page_size: int, fit: bool) -> str:
    """One line: pages, density, covered texels and fill of the scene's default atlas."""
    scene = load(path)
    world = build_world(scene)
    resolved = resolve(Settings(page_size=page_size), *bounds_of_baked(world, scene))
    start = time.perf_counter()
    atlas = unwrap(scene, world, resolved, fit_one_page=fit)
    seconds = time.perf_counter() - start
    texels = len(cover(atlas, world).key)
    area = max(1, atlas.page_count * atlas.width * atlas.height)
    return (f"{atlas.page_count} page(s) {atlas.width}×{atlas.height}, density "
            f"{atlas.texel_density:.4g}, {texels:,} texels, fill {texels / area:.1%} "
            f"({seconds:.2f} s)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--page-size", type=int, default=1024)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        for name, path in scenes(Path(folder)).items():
            print(f"{name}:\n  before: {measure(path, args.page_size, False)}\n"
                  f"  now:    {measure(path, args.page_size, True)}", flush=True)


if __name__ == "__main__":
    main()
