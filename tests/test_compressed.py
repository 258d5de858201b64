"""The corpus test: exports as studios ship them bake as their plain originals. Variants of the
demo scenes made with glTF Transform (``tests/gltf_transform.py``: Draco, meshopt,
KHR_mesh_quantization, KHR_texture_transform, an animated node, an emissive decal material) and
alktx2 (KTX 2 textures), each baked, validated, and its lightmap compared with the plain scene's
where a viewer sees it (layouts differ)."""

from __future__ import annotations

import sys
from dataclasses import replace

import numpy as np
import pytest

import baker
from assets import make_scenes
from baker.errors import InputError
from baker.gltf.load import load
from baker.preview import render
from tests.bakehelp import REAL_SCENES
from tests.gltf_transform import KINDS, variant
from tests.gltf_validator import issue_codes, validate

SETTINGS = baker.Settings(rays=32, texel_density=24)
# name → how to save the plain scene into a folder, and the density it is baked at (the shared
# scene, in its own units, at about as many texels as the Cornell box).
SCENES = {"cornell_box": (lambda folder: make_scenes.cornell_box().save(folder / "cb.glb"), 24),
          "textured_floor": (lambda folder: make_scenes.textured_floor().save(folder / "tf.glb"), 24),
          "NegativeScaleTest": (lambda folder: REAL_SCENES["NegativeScaleTest"], 8)}


def _seen(path, size=(160, 120)):
    """The baked file's lightmap as the default view sees it, exposure fixed."""
    return render(load(path), "lightmap", size, exposure=1.0)


def _difference(a, b) -> float:
    """Mean absolute difference of two views of a lightmap where both see one, relative to the
    first's mean."""
    both = a.lightmapped & b.lightmapped
    return float(np.abs(a.radiance[both] - b.radiance[both]).mean() / a.radiance[both].mean())


@pytest.fixture(scope="module")
def plain(tmp_path_factory):
    """Each scene saved plain and baked: {name: (source, settings, lightmap as seen, noise)},
    noise the difference the sampler's seed alone makes (another seed's bake of the file)."""
    folder = tmp_path_factory.mktemp("plain")
    out = {}
    for name, (save, density) in SCENES.items():
        source, settings = save(folder), replace(SETTINGS, texel_density=density)
        seen = []
        for seed in (0, 7):
            baker.bake(source, folder / f"{name}_{seed}.glb", replace(settings, seed=seed))
            seen.append(_seen(folder / f"{name}_{seed}.glb"))
        out[name] = source, settings, seen[0], _difference(*seen)
    return out


def _darker(a, b) -> float:
    """Mean of how much darker the second view is than the first where both see a lightmap
    (0 where it is lighter), relative to the first's mean."""
    both = a.lightmapped & b.lightmapped
    return float(np.clip(a.radiance[both] - b.radiance[both], 0, None).mean()
                 / a.radiance[both].mean())


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("name", sorted(SCENES))
def test_a_variant_bakes_validates_and_matches_the_plain_one(tmp_path, plain, name, kind):
    """Within noise: the difference to the plain bake is at most 1.5 times what another seed
    makes (measured: Draco 0.97 and 1.0 times, its 14-bit positions change the atlas; meshopt
    and quantized 0.02 and 1.0 times). The emissive variant adds a decal's light, so it is
    held to adding only: darker than the plain bake by no more than that noise anywhere on
    average (a prop lit by its decals once came out black). The animated one bakes its rest
    pose, with the warning."""
    source, settings, seen, noise = plain[name]
    made = variant(kind, source, tmp_path / f"{name}_{kind}.glb")
    baked = tmp_path / f"{name}_{kind}_baked.glb"
    result = baker.bake(made, baked, settings)
    assert result.texels > 1000
    errors = [set(issue_codes(validate(p), 0)) for p in (made, baked)]
    assert errors[1] <= errors[0], errors  # the bake adds no error to the file's own
    ours = _seen(baked)
    assert (ours.lightmapped == seen.lightmapped).mean() > 0.99
    if kind == "emissive":
        assert _darker(seen, ours) < 1.5 * noise, (_darker(seen, ours), noise)
        return
    assert _difference(seen, ours) < 1.5 * noise, (_difference(seen, ours), noise)
    if kind == "animated":
        assert any("baked in its rest pose" in reason for _where, reason in result.plan.left_out)


def test_a_missing_decoder_names_the_package_that_installs_it(tmp_path, plain, monkeypatch):
    compressed = variant("draco", plain["cornell_box"][0], tmp_path / "draco.glb")
    monkeypatch.setitem(sys.modules, "DracoPy", None)  # import DracoPy raises ImportError
    with pytest.raises(InputError) as error:
        load(compressed)
    assert "KHR_draco_mesh_compression" in error.value.message
    assert 'pip install "DracoPy>=2"' in error.value.fix
    assert "meshes[0].primitives[0]" in error.value.where
