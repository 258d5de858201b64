"""Compile baker's numba kernels ahead of a user's first bake: small bakes that run every kernel.

numba compiles a kernel the first time it is called and caches the machine code beside its
module (``__pycache__/*.nbi``, ``*.nbc``), keyed by a hash of the module's source, the argument
types and the CPU. Run at build time (``setup.py``'s ``build_py``) on the built package, these
bakes fill that cache inside the wheel, so that the first ``baker bake`` after ``pip install`` runs
warm. The scenes are tiny: the time is the compiling. Then every kernel, for the argument types
these bakes gave it, is compiled into the package's ahead-of-time module
(``compile_kernels.py``), with which a bake never imports numba; where that cannot be built (no
C compiler to link it), the bakes use numba's cache, saying so here.

    python assets/warm_kernels.py      # warms the baker package it imports
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

os.environ["BAKER_JIT"] = "1"  # numba's JIT, whose dispatchers record the types they are given
os.environ["BAKER_CACHE_DIR"] = "off"  # every chart made: the charting kernels run

sys.path.append(str(Path(__file__).resolve().parent.parent))  # assets/, after the package to warm

import baker  # noqa: E402
from assets.compile_kernels import compile_ahead  # noqa: E402
from assets.foliage_scenes import tree  # noqa: E402
from assets.gltf_builder import edited_glb  # noqa: E402
from assets.light_scenes import normal_mapped_floor  # noqa: E402
from assets.make_scenes import cornell_box, vase_room  # noqa: E402
from assets.rebake_scenes import box_room, grid_boxes, moved  # noqa: E402
from assets.sky_images import save_hdr, sun  # noqa: E402

SMALL = dict(rays=16, page_size=128)


def chart_here(scene: Path) -> None:
    """Chart ``scene``'s meshes in this process: a bake charts them in forked children
    (``atlas.charts``), whose kernels' argument types this process would not see."""
    from baker.atlas.charts import chart_list
    from baker.atlas.unwrap import baked_instances, frame_meshes
    from baker.geometry.world import build_world
    from baker.gltf.load import load

    loaded = load(scene)
    chart_list(frame_meshes(loaded, build_world(loaded), baked_instances(loaded)))


def _unmarked(baked: Path) -> Path:
    """A bake's output as a scene with authored lightmap UVs (its TEXCOORD_1), for ``--uv 1``:
    without the ``asset.extras.baker`` mark that makes a bake refuse it
    (``Scene.check_not_a_bake``)."""
    def unmark(document) -> None:
        del document.asset.extras["baker"]
    return edited_glb(baked, unmark, baked.with_name("authored_uv.glb"))


def warm(folder: Path) -> None:
    """Bake, rebake, relight and preview small scenes in ``folder``: the paths a first session
    takes (the README's commands), so that their kernels are compiled."""
    cornell = cornell_box().save(folder / "cornell.glb")
    baker.bake(cornell, folder / "cornell_baked.glb", baker.Settings(**SMALL))
    for options in (dict(rho="step", d_max=1.0), dict(encoding="linear", carrier="moz", smooth=True),
                    dict(directional=True, occlusion="also", supersample=2),
                    dict(sky=(0.5, 0.6, 0.8), method="gi"),
                    dict(sky_image=str(save_hdr(sun(), folder / "sky.hdr")))):
        baker.bake(cornell, folder / "options_baked.glb", baker.Settings(**SMALL, **options),
                   overwrite=True, state=False)
    baker.bake(_unmarked(folder / "cornell_baked.glb"), folder / "uv_baked.glb",
               baker.Settings(**SMALL, uv=1))
    baker.bake(normal_mapped_floor().save(folder / "bumps.glb"), folder / "bumps_baked.glb",
               baker.Settings(**SMALL, directional=True))
    baker.bake(vase_room().save(folder / "vase.glb"), folder / "vase_baked.glb",
               baker.Settings(**SMALL))
    flowers = Path(__file__).resolve().parent.parent / "tests" / "scenes" / "GlassVaseFlowers"
    if flowers.is_dir():  # alpha-cut leaves and glass (in a checkout)
        baker.bake(flowers / "GlassVaseFlowers.glb", folder / "flowers_baked.glb",
                   baker.Settings(**SMALL, occlusion="also"))
    baker.bake(tree(leaf_count=200, grass_count=0).save(folder / "tree.glb"),  # flat charts
               folder / "tree_baked.glb", baker.Settings(**SMALL))
    boxes, lamp = grid_boxes(8), {"intensity": 20.0, "radius": 0.1}
    room = box_room(boxes, lamp=lamp).save(folder / "room.glb")
    out = folder / "room_baked.glb"
    baker.bake(room, out, baker.Settings(**SMALL))
    edited = box_room(moved(boxes, boxes[3]["name"], at=(0.5, -0.7)), lamp=lamp).save(
        folder / "room.glb")
    baker.bake(edited, out, baker.Settings(**SMALL), incremental="always")
    baker.bake(edited, out, baker.Settings(**SMALL), incremental=True, relight=True)
    for scene in (cornell, room, folder / "tree.glb"):
        chart_here(scene)
    from baker.preview import preview

    preview(folder / "cornell_baked.glb", folder / "preview.png", size=(64, 48))


def main() -> None:
    with tempfile.TemporaryDirectory() as folder:
        warm(Path(folder))
    package = Path(baker.__file__).parent
    print(f"compiled baker's kernels into {package}")
    try:
        print(compile_ahead(package))
    except Exception as error:  # noqa: BLE001 — any failure leaves numba's cache to the bakes
        print(f"baker's kernels could not be compiled ahead of time ({type(error).__name__}: "
              f"{error}); bakes will load them with numba, about 0.3 s more a process")


if __name__ == "__main__":
    main()
