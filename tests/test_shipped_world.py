"""A cluster's node builds the driver's world from the shipped scene, bit for bit: the bake
ships distinct meshes and each instance's matrix (``cluster._shipped``), not the world, and a
node makes the world and every array derived from it (``cluster._node_bake``) with the
driver's bits, whatever BLAS's and OpenMP's thread counts (``geometry.world.rows_times``: the
transform ``@`` gave with bits that followed BLAS's threads). No Ray here: the shipped bake is
pickled, as Ray pickles it, and made in fresh processes.
"""

from __future__ import annotations

import io
import os
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from assets.many_objects import boxes_and_sphere
from baker.geometry.world import World, build_world
from baker.gltf.load import load
from baker.pipeline import cluster, full
from baker.settings import Settings
from tests.bakehelp import REAL_SCENES
from tests.ray_cluster import ROOT

THREADS = ({"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"},
           {"OPENBLAS_NUM_THREADS": "2", "OMP_NUM_THREADS": "2", "MKL_NUM_THREADS": "2"},
           {"OPENBLAS_NUM_THREADS": "7", "OMP_NUM_THREADS": "3", "MKL_NUM_THREADS": "5"})
"""The environments a node's world is made under: BLAS and OpenMP on one, two and more
threads than the machine has."""

_MAKE = """
import pickle, sys, numpy as np
from baker.pipeline import cluster
with open(sys.argv[1], "rb") as kept:
    shipped = pickle.load(kept)
part, made = cluster._node_bake(shipped)
np.savez(sys.argv[2], *cluster._arrays(cluster._made(made), {id(made.scene)}))
"""


class _Stopped(Exception):
    """Raised where the bake's parts would start, with its ``Baking``."""


def _baking(path: Path, monkeypatch) -> full.Baking:
    """The full bake of ``path``'s ``Baking`` as the driver holds it at its parts."""
    def stop(baking, *_rest):
        raise _Stopped(baking)

    monkeypatch.setattr(full, "_bake_parts", stop)
    with pytest.raises(_Stopped) as stopped:
        full.compute(load(path), Settings(rays=4, page_size=256))
    return stopped.value.args[0]


@pytest.fixture(params=["turned, scaled and mirrored",
                        pytest.param("LightsPunctualLamp", marks=pytest.mark.long)])
def scene(request, tmp_path) -> Path:
    """A scene of instances turned and scaled (boxes of 19,200 triangles each, one mirrored),
    or the real scene whose cluster bake once differed from the local one."""
    if request.param == "LightsPunctualLamp":
        return REAL_SCENES["LightsPunctualLamp"]
    built = boxes_and_sphere(6, cuts=40, sphere_rings=24, instanced=True)
    built._nodes[built.info["nodes"]["box1"]].scale = [-0.5, 0.4, 0.3]  # one box mirrored
    return built.save(tmp_path / "scene.glb")


def test_a_node_builds_the_drivers_world_whatever_the_threads(scene, tmp_path, monkeypatch):
    baking = _baking(scene, monkeypatch)
    assert any(np.linalg.det(i.world[:3, :3]) < 0 for i in baking.scene.instances) or \
        scene.name.startswith("Lights")
    shipped = cluster._shipped(full._bake_part, baking)
    kept = tmp_path / "shipped.pickle"
    kept.write_bytes(pickle.dumps(shipped, protocol=5))
    drivers = list(cluster._arrays(cluster._made(baking), {id(baking.scene)}))
    assert len(drivers) > 20  # positions, normals, ..., owners, faces, surfaces
    for threads in THREADS:
        out = tmp_path / "made.npz"
        subprocess.run([sys.executable, "-c", _MAKE, str(kept), str(out)], check=True,
                       env=dict(os.environ, PYTHONPATH=str(ROOT), **threads), cwd=ROOT)
        with np.load(out) as made:
            arrays = [made[f"arr_{k}"] for k in range(len(made.files))]
        assert len(arrays) == len(drivers)
        for mine, theirs in zip(drivers, arrays):
            assert (mine.dtype, mine.shape) == (theirs.dtype, theirs.shape)
            assert np.array_equal(mine, theirs, equal_nan=mine.dtype.kind == "f")
            assert mine.tobytes() == theirs.tobytes()  # the bits: −0.0, NaN payloads


def test_the_shipped_bake_holds_the_scene_not_the_world(tmp_path, monkeypatch):
    built = boxes_and_sphere(20, cuts=2, sphere_rings=4, instanced=True)
    baking = _baking(built.save(tmp_path / "scene.glb"), monkeypatch)
    shipped = cluster._shipped(full._bake_part, baking)
    found: list[type] = []

    class Looking(pickle.Pickler):
        def persistent_id(self, obj):
            found.append(type(obj))
            return None

    Looking(io.BytesIO(), protocol=5).dump(shipped)
    assert World not in found and baking.world is not None
    assert cluster._array_bytes(shipped) < cluster._array_bytes(baking.world)


def test_a_node_whose_world_differs_is_an_error_not_other_bytes(tmp_path, monkeypatch):
    baking = _baking(boxes_and_sphere(4, cuts=2, sphere_rings=4, instanced=True).save(
        tmp_path / "scene.glb"), monkeypatch)
    shipped = cluster._shipped(full._bake_part, baking)
    part, made = cluster._node_bake(shipped)
    assert np.array_equal(made.world.positions, build_world(baking.scene).positions)
    tampered = type(shipped)(shipped.part, shipped.baking, shipped.owns, shipped.crc ^ 1)
    with pytest.raises(RuntimeError, match="built another world .* than the driver's"):
        cluster._node_bake(tampered)


def test_an_instance_s_cofactor_is_np_cross_to_the_bit():
    """``world._cofactors`` crosses the matrices' columns elementwise (all of a primitive's
    instances at once): every row and det(M) are the bits ``np.cross`` gives each matrix, on
    20,000 matrices of magnitudes 10⁻³⁰ to 10³⁰, with zero rows, float32 values, an inf and a
    NaN (a world built either way is the same bits, so rebakes and states are unchanged)."""
    import warnings

    from baker.geometry.world import _cofactors

    rng = np.random.default_rng(5)
    matrices = rng.normal(size=(20_000, 3, 3)) * 10.0 ** rng.integers(-30, 31, (20_000, 3, 3))
    matrices[::4, 1] = 0.0
    matrices[1::4] = matrices[1::4].astype(np.float32)
    matrices[2, 0, 0], matrices[3, 1, 2] = np.inf, np.nan
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # np.cross's overflows
        cofactors, found = _cofactors(matrices)
        for linear, cofactor, det_found in zip(matrices[::97], cofactors[::97], found[::97]):
            rows = np.stack([np.cross(linear[:, 1], linear[:, 2]),
                             np.cross(linear[:, 2], linear[:, 0]),
                             np.cross(linear[:, 0], linear[:, 1])])
            det = (rows[0, 0] * linear[0, 0] + rows[0, 1] * linear[1, 0]) + rows[0, 2] * linear[2, 0]
            assert cofactor.tobytes() == rows.tobytes() and det_found.tobytes() == det.tobytes()
        columns = [matrices[:, :, c] for c in range(3)]  # and all 20,000 by np.cross on rows
        rows = np.stack([np.cross(columns[1], columns[2]), np.cross(columns[2], columns[0]),
                         np.cross(columns[0], columns[1])], axis=1)
        assert cofactors.tobytes() == rows.tobytes()
