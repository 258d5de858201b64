"""Benchmark: directional lightmaps as ``baker view`` shows them (issue 42).

Two bumped floors (``assets.light_scenes.normal_mapped_floor``: a point light; ``window_room``:
a closed room lit by a uniform sky through an opening in one wall, ``--sky-rays``), each baked
plain and with ``--directional`` (24 texels a metre, 16 rays, I_A 0 so that the closed form is
the whole light) and shown from above in headless Chromium through ``baker view`` and by
``baker preview``. Prints, over the floor's pixels (``tests/directional_measure.py``): the
correlation of each picture's relief (its luminance over the plain bake's picture) with the
closed form's E(n)/E(n₀) — issue 42 asks for ≥ 0.95 where the plain lightmap's is 0 —, the
same against the closed form at n₀ (the lightmap's own noise included), the two renderers'
correlation, and the pages' PNG bytes against the plain bake's (≤ 2.5×).

    python benchmarks/bench_directional.py [--sky-rays 256]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from assets.light_scenes import normal_mapped_floor, window_room  # noqa: E402
from chromium import Browser, find_chromium  # noqa: E402
from tests.directional_measure import (  # noqa: E402
    point_light,
    reliefs,
    top_view,
    window_light,
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sky-rays", type=int, default=256)
    args = parser.parse_args()
    executable = find_chromium()
    if executable is None:
        sys.exit("no Chromium (Debian's chromium package)")
    room = window_room()
    cases = [("point light", normal_mapped_floor(), top_view(2.6), {},
              lambda p, n: point_light(p, n, (1.2, 1.0, 0.3), 4.0)),
             ("window", room, top_view(5.5, fov=40.0),
              dict(sky=(1.0, 1.0, 1.0), sky_rays=args.sky_rays),
              lambda p, n: window_light(p, n, room.info["window"], 1.0))]
    with Browser(executable) as browser, tempfile.TemporaryDirectory() as folder:
        for name, builder, view, settings, closed in cases:
            here = Path(folder) / name.replace(" ", "_")
            here.mkdir()
            found = reliefs(browser, builder, view, here, closed, **settings)
            print(f"\n{name}: {found['pixels']:,} floor pixels")
            print(f"  relief against the closed form: baker view {found['browser']:.4f}, "
                  f"baker preview {found['preview']:.4f}; the plain bake's "
                  f"{found['browser, plain']:.4f}")
            print(f"  against the closed form at n0 (the lightmap's noise in): "
                  f"{found['browser, against E(n0)']:.4f}")
            print(f"  baker view against baker preview: {found['browser ~ preview']:.6f}")
            print(f"  page bytes: {found['directional bytes']:,} against the plain bake's "
                  f"{found['plain bytes']:,} ({found['directional bytes'] / found['plain bytes']:.2f}x)")


if __name__ == "__main__":
    main()
