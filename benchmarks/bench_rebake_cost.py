"""Benchmark: the rebake's cost model (``baker/rebake/cost.py``) against what rebakes take.

For each edit — 1, 6, 20 or all 60 crates of a 12 × 3 × 12 m room moved 0.1 m, one crate's
material or the others' recoloured (priced by a sample of the colour search), 1 or 4 of 9
big boxes moved, a tree's crown and trunk or the box beside it moved (``--foliage approx``),
and, given ``--vase``, a flower of the Khronos GlassVaseFlowers moved 4 mm — the scene before
is baked fully (default settings, its stage times recorded beside the state), then the edit is
rebaked incrementally whatever the model says (``incremental="always"``). Prints, per edit,
the texels dirty, the seconds the model gave the rebake's search and rays
(``rebake.modelled_seconds``), the seconds they took (the report's "dirty", "trace" and
"direct" stages), their ratio, and the whole rebake's seconds against the full bake's. The
model's constants (``REDO_COST``, ``SEARCH_COST``) are fitted so that the ratios stay near 1
over all the edits: the model is what a rebake prints when it chooses a full bake instead.

    python benchmarks/bench_rebake_cost.py [--vase ../shared/scenes/GlassVaseFlowers/GlassVaseFlowers.glb]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import baker  # noqa: E402
from assets.foliage_scenes import tree_and_boxes  # noqa: E402
from assets.gltf_builder import edited_glb  # noqa: E402
from assets.rebake_scenes import box_room, grid_boxes  # noqa: E402

ROOM, BIG_ROOM = (12.0, 3.0, 12.0), (6.0, 3.0, 6.0)


def _shifted(boxes: list[dict], count: int) -> list[dict]:
    """``boxes`` with the first ``count`` moved 0.1 m along x."""
    return [dict(b, at=(b["at"][0] + 0.1, b["at"][1])) if k < count else dict(b)
            for k, b in enumerate(boxes)]


def edits(folder: Path, vase: Path | None):
    """(name, scene before, scene after, settings) of every edit measured."""
    crates = grid_boxes(60, room=ROOM, size=0.4)
    before = box_room(crates, room=ROOM).save(folder / "crates.glb")
    for count in (1, 6, 20, 60):
        yield (f"{count} of 60 crates moved", before,
               box_room(_shifted(crates, count), room=ROOM).save(folder / f"crates{count}.glb"),
               baker.Settings())
    for material in ("accent", "crate"):  # one crate's colour, then every other crate's
        yield (f"the {material} material recoloured", before,
               box_room(crates, room=ROOM, colours={material: (0.2, 0.6, 0.3)}).save(
                   folder / f"{material}.glb"), baker.Settings())
    big = grid_boxes(9, room=BIG_ROOM, size=1.2)
    before = box_room(big, room=BIG_ROOM).save(folder / "big.glb")
    for count in (1, 4):
        yield (f"{count} of 9 big boxes moved", before,
               box_room(_shifted(big, count), room=BIG_ROOM).save(folder / f"big{count}.glb"),
               baker.Settings())
    before = tree_and_boxes({}).save(folder / "tree.glb")
    foliage = baker.Settings(foliage="approx")
    yield ("tree moved", before, tree_and_boxes({"crown": (0.4, 0.0, 0.2), "trunk": (
        0.4, 0.0, 0.2)}).save(folder / "tree_moved.glb"), foliage)
    yield ("box by the tree moved", before,
           tree_and_boxes({"near": (2.3, 0.25, 0.3)}).save(folder / "near.glb"), foliage)
    if vase is not None:
        def move(document) -> None:
            node = document.nodes[0]
            node.translation = [*(node.translation or [0.0, 0.0, 0.0])]
            node.translation[0] += 0.004
        moved = edited_glb(vase, move, folder / "vase_moved.glb")  # a .glb: it holds all its data
        yield f"{vase.stem}: the first node moved 4 mm", vase, moved, baker.Settings()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--vase", type=Path, default=None,
                        help="GlassVaseFlowers.glb (../shared/scenes), to add its edit")
    args = parser.parse_args()
    ratios = []
    print(f"{'edit':42s} {'dirty':>6s} {'model s':>8s} {'spent s':>8s} {'ratio':>6s} "
          f"{'rebake s':>9s} {'full s':>7s}")
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        for name, before, after, settings in edits(folder, args.vase):
            out = folder / "out.glb"
            baker.bake(before, out, settings)
            result = baker.bake(after, out, settings, incremental="always")
            again, stages = result.rebake, result.report["stage_seconds"]
            spent = sum(stages.get(key, 0.0) for key in ("dirty", "trace", "direct"))
            model = again["modelled_seconds"]
            ratios.append(model / spent)
            print(f"{name:42s} {again['dirty_fraction']:6.1%} {model:8.2f} {spent:8.2f} "
                  f"{model / spent:6.2f} {again['seconds']:9.2f} "
                  f"{again['last_full_bake_seconds']:7.2f}", flush=True)
    print(f"model ÷ spent: median {statistics.median(ratios):.2f}, "
          f"{min(ratios):.2f}–{max(ratios):.2f}")


if __name__ == "__main__":
    main()
