"""What a pipeline's clean-up keeps of each carrier (issue 20): glTF Transform's optimize steps
(``tests/transform/optimize.js``: dedup, instance, palette, flatten, join, weld, resample,
prune, sparse) run on baked files, and the result previewed against the baked file.

- emissive and occlusion are core glTF: they survive, and the picture is the same;
- moz does not: glTF Transform drops the extension it does not know, then prunes the lightmap
  image and its UV set (docs/output.md says so; this test notices if that changes).
"""

from __future__ import annotations

import subprocess

import numpy as np
import pygltflib
import pytest

import baker
from assets.make_scenes import cornell_box
from baker.geometry.surface import LUMINANCE
from baker.gltf.load import load
from baker.preview import render
from tests.bakehelp import REAL_SCENES, saved

import gltf_transform

SIZE = (160, 120)


def _optimized(source, folder, name, carrier):
    out = folder / f"{name}_{carrier}.glb"
    baker.bake(source, out, baker.Settings(texel_density=8 if name == "cornell" else 4, rays=16,
                                           carrier=carrier), state=False)
    optimized = folder / f"{name}_{carrier}_optimized.glb"
    script = gltf_transform.TRANSFORM_DIR / "optimize.js"
    run = subprocess.run([gltf_transform._node(), str(script), str(out), str(optimized)],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    return out, optimized


@pytest.mark.parametrize("name, carrier", [("cornell", "emissive"), ("cornell", "occlusion"),
                                           ("MultiUVTest", "emissive")])
def test_core_carriers_survive_optimize(tmp_path, name, carrier):
    source = saved(cornell_box(), tmp_path) if name == "cornell" else REAL_SCENES[name]
    out, optimized = _optimized(source, tmp_path, name, carrier)
    before = render(load(out), "lit", SIZE, exposure=2.0)
    after = render(load(optimized), "lit", SIZE, exposure=2.0)
    assert after.lightmapped.sum() == before.lightmapped.sum() > 0
    both = before.lightmapped & after.lightmapped
    a, b = (p.radiance[both] @ LUMINANCE for p in (before, after))
    lit = a > 1e-3
    np.testing.assert_allclose(b[lit], a[lit], rtol=1e-3)


def test_moz_is_lost_by_optimize(tmp_path):
    out, optimized = _optimized(saved(cornell_box(), tmp_path), tmp_path, "cornell", "moz")
    document = pygltflib.GLTF2.load(str(optimized))
    assert "MOZ_lightmap" not in (document.extensionsUsed or [])
    assert not document.images  # the lightmap page pruned with it
    assert not render(load(optimized), "lit", SIZE).lightmapped.any()
