"""What a pipeline's clean-up keeps of each carrier (issue 20): glTF Transform's optimize steps
(``tests/transform/optimize.js``: dedup, instance, palette, flatten, join, weld, resample,
prune, sparse) and gltfpack with its defaults (``tests/gltfpack``: quantized attributes) run on
baked files, and the result previewed against the baked file.

- emissive and occlusion are core glTF: they survive, and the picture is the same (within the
  UVs' quantization for gltfpack);
- moz does not: both tools drop the extension they do not know (glTF Transform prunes the
  lightmap image and its UV set too); docs/output.md says so, and this test notices if that
  changes.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pygltflib
import pytest

import baker
from assets.extreme_scenes import instanced_boxes
from assets.make_scenes import cornell_box
from assets.material_scenes import metal_glass_room
from baker.geometry.surface import LUMINANCE
from baker.gltf.load import load
from baker.preview import render
from tests.bakehelp import REAL_SCENES, saved

import gltf_transform
from npm_packages import installed

SIZE = (160, 120)
GLTFPACK = Path(__file__).resolve().parent / "gltfpack"  # the pinned npm package


def _gltfpack() -> list[str]:
    """The command that runs the pinned gltfpack (``npm ci`` once, when it is missing)."""
    node = shutil.which("node")
    if node is None or not installed(GLTFPACK, [Path("gltfpack/cli.js")]):
        pytest.skip("no Node.js: gltfpack cannot run (the README's test command needs it)")
    return [node, str(GLTFPACK / "node_modules" / "gltfpack" / "cli.js")]


def _optimized(source, folder, name, carrier, tool="gltf-transform"):
    out = folder / f"{name}_{carrier}.glb"
    if not out.exists():
        baker.bake(source, out, baker.Settings(texel_density=4 if name in REAL_SCENES else 8,
                                               rays=16, carrier=carrier), state=False)
    optimized = folder / f"{name}_{carrier}_{tool}.glb"
    command = ([gltf_transform._node(), str(gltf_transform.TRANSFORM_DIR / "optimize.js"),
                str(out), str(optimized)] if tool == "gltf-transform" else
               [*_gltfpack(), "-i", str(out), "-o", str(optimized)])
    run = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    return out, optimized


def _source(name: str, folder):
    """The scene ``name``: the demo Cornell box, the room of metals and glass, 40 instances of a
    box (their geometry shared, ``output/write.py``) or a shared scene."""
    made = {"cornell": cornell_box, "metal_glass": metal_glass_room,
            "instances": lambda: instanced_boxes(40)}
    return saved(made[name](), folder) if name in made else REAL_SCENES[name]


@pytest.mark.parametrize("name, carrier", [("cornell", "emissive"), ("cornell", "occlusion"),
                                           ("MultiUVTest", "emissive"),
                                           ("metal_glass", "emissive"),
                                           ("instances", "emissive")])
def test_core_carriers_survive_optimize(tmp_path, name, carrier):
    out, optimized = _optimized(_source(name, tmp_path), tmp_path, name, carrier)
    before = render(load(out), "lit", SIZE, exposure=2.0)
    after = render(load(optimized), "lit", SIZE, exposure=2.0)
    assert after.lightmapped.sum() == before.lightmapped.sum() > 0
    both = before.lightmapped & after.lightmapped
    a, b = (p.radiance[both] @ LUMINANCE for p in (before, after))
    lit = a > 1e-3
    np.testing.assert_allclose(b[lit], a[lit], rtol=1e-3)


@pytest.mark.parametrize("name, carrier", [("cornell", "emissive"), ("cornell", "occlusion"),
                                           ("metal_glass", "emissive"),
                                           ("instances", "emissive")])
def test_core_carriers_survive_gltfpack(tmp_path, name, carrier):
    """gltfpack quantizes the UVs (KHR_mesh_quantization with KHR_texture_transform): the bake
    stays, the picture within a few per cent in the median: 1 %, or 3 standard errors of the
    median (1.253·σ/√n, σ from the ratios' interquartile range) where the pixels' ratios
    spread widely (the occlusion texture's: a quarter of them off by 18 % or more), so that
    the bound does not hang on one draw of the bake's random numbers."""
    out, packed = _optimized(_source(name, tmp_path), tmp_path, name, carrier, "gltfpack")
    before = render(load(out), "lit", SIZE, exposure=2.0)
    after = render(load(packed), "lit", SIZE, exposure=2.0)
    assert before.lightmapped.sum() > 0  # positions quantized: a silhouette pixel may flip
    assert abs(int(after.lightmapped.sum()) - int(before.lightmapped.sum())) <= (
        0.01 * before.lightmapped.sum() + 2)
    both = before.lightmapped & after.lightmapped
    a, b = (p.radiance[both] @ LUMINANCE for p in (before, after))
    lit = a > 1e-3
    ratio = b[lit] / a[lit]
    spread = np.subtract(*np.percentile(ratio, [75, 25])) / 1.349  # σ of a normal's IQR
    assert abs(np.median(ratio) - 1) < max(0.01, 3 * 1.253 * spread / np.sqrt(len(ratio)))


@pytest.mark.parametrize("tool", ["gltf-transform", "gltfpack"])
def test_moz_is_lost_by_pipeline_tools(tmp_path, tool):
    out, optimized = _optimized(saved(cornell_box(), tmp_path), tmp_path, "cornell", "moz", tool)
    document = pygltflib.GLTF2.load(str(optimized))
    assert "MOZ_lightmap" not in (document.extensionsUsed or [])
    assert not any("MOZ_lightmap" in (m.extensions or {}) for m in document.materials)
    if tool == "gltf-transform":
        assert not document.images  # the lightmap page pruned with it
    assert not render(load(optimized), "lit", SIZE).lightmapped.any()
