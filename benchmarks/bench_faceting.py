"""The facets' step in a smooth low-poly mesh's lightmap, with hemispheres about the shading
normals (now) and about the face normals (before), measured (issue 21).

For an 80-face icosphere with vertex normals over a floor, no light (``icosphere_on_floor``),
prints the step across triangle edges and one bake's noise (``tests/test_shading_normals.
facet_step``: jumps across edges against jumps within triangles, on the sphere's lower half)
for each ray count and gap between the sphere and the floor (0: resting on a vertex, where ρ =
sqrt(d/d_max) is steep and the stencil's cubic remainder shows too).

    python benchmarks/bench_faceting.py [--rays 64 256] [--gaps 0 0.05]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from assets.artifact_scenes import icosphere_on_floor  # noqa: E402
from baker.atlas.rasterise import Texels  # noqa: E402
from tests.test_shading_normals import facet_step  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rays", type=int, nargs="+", default=[64, 256])
    parser.add_argument("--gaps", type=float, nargs="+", default=[0.0, 0.05])
    args = parser.parse_args()
    shading = Texels.hemisphere_normal
    face = lambda self, rows=slice(None): self.geometric_normal(rows)  # noqa: E731
    print(f"{'hemisphere':>10} {'gap m':>6} {'rays':>5} {'step':>8} {'noise':>8} "
          f"{'step/noise':>10}")
    with tempfile.TemporaryDirectory() as folder:
        for name, normal in (("face", face), ("shading", shading)):
            Texels.hemisphere_normal = normal
            for gap in args.gaps:
                for rays in args.rays:
                    step, noise = facet_step(icosphere_on_floor(gap=gap), Path(folder), rays)
                    print(f"{name:>10} {gap:6.2f} {rays:5d} {step:8.5f} {noise:8.5f} "
                          f"{step / noise:10.2f}", flush=True)
    Texels.hemisphere_normal = shading


if __name__ == "__main__":
    main()
