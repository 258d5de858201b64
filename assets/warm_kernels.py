"""Compile baker's numba kernels ahead of a user's first bake: small bakes that run every kernel.

numba compiles a kernel the first time it is called and caches the machine code beside its
module (``__pycache__/*.nbi``, ``*.nbc``), keyed by a hash of the module's source, the argument
types and the CPU. Run at build time (``setup.py``'s ``build_py``) on the built package, these
bakes fill that cache inside the wheel, so that the first ``baker bake`` after ``pip install`` runs
warm. The scenes are tiny: the time is the compiling.

    python assets/warm_kernels.py      # warms the baker package it imports
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

sys.path.append(str(Path(__file__).resolve().parent.parent))  # assets/, after the package to warm

import baker  # noqa: E402
from assets.foliage_scenes import tree  # noqa: E402
from assets.make_scenes import cornell_box, vase_room  # noqa: E402
from assets.rebake_scenes import box_room, grid_boxes, moved  # noqa: E402

SMALL = dict(rays=16, page_size=128)


def warm(folder: Path) -> None:
    """Bake, rebake, relight and preview small scenes in ``folder``: the paths a first session
    takes (the README's commands), so that their kernels are compiled."""
    cornell = cornell_box().save(folder / "cornell.glb")
    baker.bake(cornell, folder / "cornell_baked.glb", baker.Settings(**SMALL))
    baker.bake(vase_room().save(folder / "vase.glb"), folder / "vase_baked.glb",
               baker.Settings(**SMALL))
    flowers = Path(__file__).resolve().parent.parent / "tests" / "scenes" / "GlassVaseFlowers"
    if flowers.is_dir():  # alpha-cut leaves and glass (in a checkout)
        baker.bake(flowers / "GlassVaseFlowers.glb", folder / "flowers_baked.glb",
                   baker.Settings(**SMALL, occlusion="also"))
    baker.bake(tree(leaf_count=200, grass_count=0).save(folder / "tree.glb"),  # flat charts
               folder / "tree_baked.glb", baker.Settings(**SMALL))
    boxes, lamp = grid_boxes(6), {"intensity": 20.0, "radius": 0.1}
    room = box_room(boxes, lamp=lamp).save(folder / "room.glb")
    out = folder / "room_baked.glb"
    baker.bake(room, out, baker.Settings(**SMALL))
    edited = box_room(moved(boxes, boxes[0]["name"], at=(1.0, 1.0)), lamp=lamp).save(
        folder / "room.glb")
    baker.bake(edited, out, baker.Settings(**SMALL), incremental=True)
    baker.bake(edited, out, baker.Settings(**SMALL), incremental=True, relight=True)
    from baker.preview import preview

    preview(folder / "cornell_baked.glb", folder / "preview.png", size=(64, 48))


def main() -> None:
    with tempfile.TemporaryDirectory() as folder:
        warm(Path(folder))
    print(f"compiled baker's kernels into {Path(baker.__file__).parent}")


if __name__ == "__main__":
    main()
