"""The kernels compiled ahead of time (``baker.jit``, ``assets/compile_kernels.py``): each call
finds the function compiled for its arguments' types as numba would type them, the functions
give the bits numba's JIT gives, and a bake with them never imports numba."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from baker import jit

ROOT = Path(__file__).resolve().parents[1]
DTYPES = ["float64", "float32", "int64", "int32", "uint64", "uint32", "uint8", "bool"]


@st.composite
def arguments(draw):
    """A kernel argument: an array of any dtype, rank, layout and writability, a scalar of
    Python's or numpy's, or a tuple of them."""
    kind = draw(st.sampled_from(["array", "scalar", "tuple"]))
    if kind == "tuple":
        return tuple(draw(st.lists(arguments(), min_size=1, max_size=3)))
    if kind == "scalar":
        return draw(st.sampled_from([True, 3, -(1 << 62), (1 << 63) + 5, 2.5, np.float32(1.5),
                                     np.uint64(7), np.int32(-2), np.bool_(False), None]))
    shape = tuple(draw(st.lists(st.integers(1, 4), min_size=1, max_size=3)))
    array = np.zeros(shape, draw(st.sampled_from(DTYPES)))
    array = array.T if draw(st.booleans()) else array
    if draw(st.booleans()) and array.shape[-1] > 1:
        array = array[..., ::2]
    array.flags.writeable = draw(st.booleans())
    return array


@settings(max_examples=300, deadline=None)
@given(arguments())
def test_an_argument_s_key_is_the_key_of_numba_s_type_for_it(value):
    assert jit.value_key(value) == jit.type_key(numba.typeof(value))


def test_code_for_wider_types_takes_narrower_arguments_only():
    contiguous = jit.value_key(np.zeros((3, 4)))
    strided = jit.value_key(np.zeros((3, 4))[:, ::2])
    frozen = np.zeros((3, 4))
    frozen.flags.writeable = False
    any_layout_read_only = ("array", "float64", 2, "A", True)
    assert jit._takes(any_layout_read_only, contiguous)
    assert jit._takes(any_layout_read_only, strided)
    assert not jit._takes(contiguous, strided)  # C code reads strided rows wrong
    assert not jit._takes(contiguous, jit.value_key(frozen))  # it may write
    assert not jit._takes(contiguous, jit.value_key(np.zeros((3, 4), np.float32)))
    assert not jit._takes("int64", "uint64")


def _bake(folder: Path, scene: Path, name: str, **env) -> tuple[bytes, list[str]]:
    """(the output's bytes, the heavy modules loaded, ``jit.status()``) of a bake in a new
    process: numba, pygltflib with the JSON schema libraries it brings (0.08–0.10 s of
    every command's start until baker read glTF into its own objects, ``gltf/objects.py``),
    and tqdm (0.06 s; only a bar on a terminal needs it, ``progress.bar_class``)."""
    out = folder / f"{name}.glb"
    code = ("import sys, baker; "
            f"baker.bake({str(scene)!r}, {str(out)!r}, baker.Settings(rays=8, page_size=128, "
            "directional=True, smooth=True)); "
            "print(sorted(m for m in ('numba', 'llvmlite.binding', 'pygltflib', 'dataclasses_json', "
            "'marshmallow', 'tqdm') if m in sys.modules)); "
            "print(baker.jit.status())")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                          text=True, check=True, env=dict(os.environ, **env))
    *_, modules, status = done.stdout.strip().splitlines()
    return out.read_bytes(), eval(modules), status


def _index_is_current() -> bool:
    try:
        index = json.loads(jit.INDEX.read_text())
    except OSError:
        return False
    return index["sources"] == jit.sources_digest() and index["built_for"] == jit.built_for()


def test_a_bake_ahead_of_time_is_the_jit_s_bake_and_imports_no_numba(tmp_path):
    """The install's module (``pip install``, ``pip install -e .``: ``setup.py``) runs a bake
    of the demo scene with every kernel it needs, bit for bit as numba's JIT does; the bake
    imports neither numba nor a glTF library."""
    assert _index_is_current(), (
        "baker/_kernels.json is missing or older than the sources: `python "
        "assets/warm_kernels.py` (or `pip install -e .`) builds it")
    from assets.light_scenes import normal_mapped_floor

    scene = normal_mapped_floor().save(tmp_path / "floor.glb")
    ahead, loaded, status = _bake(tmp_path, scene, "ahead")
    jitted, jit_loaded, jit_status = _bake(tmp_path, scene, "jitted", BAKER_JIT="1")
    assert (loaded, status) == ([], "compiled ahead of time")
    assert "numba" in jit_loaded and jit_status == "numba's JIT: BAKER_JIT is set"
    assert ahead == jitted


def test_a_stale_module_is_not_used(tmp_path, monkeypatch):
    """An index whose sources are not this package's is ignored: numba compiles."""
    index = tmp_path / "_kernels.json"
    index.write_text(json.dumps({"built_for": jit.built_for(), "sources": "another",
                                 "kernels": {}}))
    monkeypatch.setattr(jit, "INDEX", index)
    assert jit._ahead_of_time() == (None, "the compiled module is of other sources: install "
                                          "baker again")
    monkeypatch.setattr(jit, "INDEX", tmp_path / "missing.json")
    assert jit._ahead_of_time()[0] is None
    assert "missing" in jit._ahead_of_time()[1]
    monkeypatch.setenv("BAKER_JIT", "1")
    assert jit._ahead_of_time() == (None, "BAKER_JIT is set")


@pytest.mark.parametrize("defaults", [0, 1])
def test_a_kernel_calls_its_compiled_function_with_the_defaults_it_was_compiled_with(defaults):
    calls = []

    def kernel(a, scale=2.0):
        return a * scale

    def compiled(*args):
        calls.append(args)
        return "compiled"

    keys = (("array", "float64", 1, "C", False),) if defaults else (
        ("array", "float64", 1, "C", False), "float64")
    wrapped = jit.Kernel(kernel, "jit", {keys: (compiled, defaults)})
    a = np.zeros(3)
    assert (wrapped(a) if defaults else wrapped(a, 3.0)) == "compiled"
    assert calls[0][1:] == ((2.0,) if defaults else (3.0,))


def test_the_version_says_how_the_kernels_are_compiled_and_why():
    def version(**env) -> str:
        return subprocess.run([sys.executable, "-m", "baker", "--version"], cwd=ROOT,
                              capture_output=True, text=True, check=True,
                              env=dict(os.environ, **env)).stdout
    assert version(BAKER_JIT="1").splitlines()[1] == "kernels: numba's JIT: BAKER_JIT is set"
    assert version().splitlines()[1] == (
        "kernels: compiled ahead of time" if _index_is_current()
        else "kernels: numba's JIT: the compiled module is of other sources: install baker again")
