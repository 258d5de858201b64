"""baker's numba kernels run in the environment a user installs: nothing they call needs a
package baker does not declare.

numba implements ``np.dot``, ``np.vdot``, ``np.matmul`` (``@``) and ``np.linalg`` by calling BLAS
and LAPACK through scipy's Cython wrappers. scipy is not one of baker's dependencies: such a
kernel fails to compile where scipy is missing (exit 3 on every scene with many flat parts, as
issue 45 found), and a kernel cached where scipy was importable aborts the process where it is
not. So no kernel may use them; the kernels sum by hand. The check reads every function that
``baker.jit``'s decorators compile, and is itself tested on made-up sources so that it is known
to fail.
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "baker"
KERNEL_DECORATORS = {"jit", "inline", "njit"}
BLAS_CALLS = {"dot", "vdot", "matmul", "inner", "tensordot", "einsum", "kron"}


def _decorator_name(node: ast.expr) -> str:
    target = node.func if isinstance(node, ast.Call) else node
    return target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")


def blas_uses(source: str) -> list[str]:
    """``function: expression`` for every BLAS or LAPACK use inside a compiled kernel of
    ``source`` (a module's text)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.FunctionDef):
            continue
        if not any(_decorator_name(d) in KERNEL_DECORATORS for d in node.decorator_list):
            continue
        for inner in ast.walk(node):
            if isinstance(inner, ast.BinOp) and isinstance(inner.op, ast.MatMult):
                found.append(f"{node.name}: {ast.unparse(inner)}")
            elif isinstance(inner, ast.Call) and isinstance(inner.func, ast.Attribute):
                text = ast.unparse(inner.func)
                if inner.func.attr in BLAS_CALLS or ".linalg." in text:
                    found.append(f"{node.name}: {ast.unparse(inner)}")
    return found


def test_no_kernel_calls_blas():
    uses = {str(path.relative_to(PACKAGE.parent)): blas_uses(path.read_text())
            for path in PACKAGE.rglob("*.py")}
    assert {path: found for path, found in uses.items() if found} == {}


def test_the_check_finds_blas_in_a_kernel_and_only_there():
    source = '''
@jit
def kernel(a, b):
    return np.dot(a, b) + (a @ b).sum() + np.linalg.norm(a)

@inline
def helper(a):
    return a.dot(a)

def host(a, b):
    return np.dot(a, b) + a @ b
'''
    assert sorted(blas_uses(source)) == ["helper: a.dot(a)", "kernel: a @ b",
                                         "kernel: np.dot(a, b)", "kernel: np.linalg.norm(a)"]


KERNEL_RUN = """
import sys
import numpy as np
import baker.jit
if len(sys.argv) > 1:
    baker.jit.ENVIRONMENT = ("another environment",)
from baker.rays.sampling import hash4
print(hash4(np.uint64(1), np.uint64(2), np.uint64(3), np.uint64(4)))
"""


def _run_kernel(cache: Path, *other_environment: str) -> tuple[str, str]:
    """(what the kernel returned, what numba's cache did) in a new process."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), NUMBA_DEBUG_CACHE="1",
               PYTHONPATH=str(PACKAGE.parent), BAKER_JIT="1")  # numba's JIT: its cache
    done = subprocess.run([sys.executable, "-c", KERNEL_RUN, *other_environment], env=env,
                          capture_output=True, text=True, check=True)
    lines = done.stdout.strip().splitlines()
    return lines[-1], " ".join(sorted({what for what in ("data saved", "data loaded")
                                       if any(what in line for line in lines)}))


def test_a_cache_from_another_environment_is_compiled_again(tmp_path):
    first, saved = _run_kernel(tmp_path)
    again, loaded = _run_kernel(tmp_path)
    other, recompiled = _run_kernel(tmp_path, "other")
    assert (saved, loaded) == ("data saved", "data loaded")
    assert recompiled == "data saved"  # not loaded from the other environment's cache
    assert first == again == other


# Products on per-texel and per-ray rows (docs/design.md §4): numpy's ``@`` and ``np.dot`` go
# through BLAS, whose sum for a row can change in its last bit with the row's place in the
# array; a rebake computes its texels in other arrays than a full bake, so the packages that
# make or compose the texels' values use ``baker.rowwise`` (and ``surface.luminance``) instead.
ROW_PACKAGES = ("light", "image", "rebake", "pipeline", "rays", "atlas", "geometry")
SMALL_PRODUCTS = {  # products over the same rows whichever texels a bake computes, and why
    ("atlas/unwrap.py", "vt.T * sigma @ vt"): "an instance's 3 × 3 stretch, rounded after",
    ("atlas/unwrap.py", "scene.primitives[inst.primitive].positions"
                        " @ stretch(inst.world[:3, :3]).T"):
        "a whole mesh's charting frame, the same array in every bake of it",
    ("light/crowns.py", "spread.T @ spread"): "a crown's 3 × 3 spread over all its leaf points",
    ("light/foliage.py", "occluded @ occluded"): "a crown's fit over all its fitting texels",
    ("light/foliage.py", "occluded @ traced.w_hit[fit_rows]"): "the same fit",
}


def row_products(source: str) -> list[str]:
    """Every ``@``, ``np.dot``, ``.dot``, ``np.matmul``, ``np.inner`` or ``np.tensordot`` of
    ``source`` (a module's text), as written."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.MatMult):
            found.append(ast.unparse(node))
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
              and node.func.attr in {"dot", "vdot", "matmul", "inner", "tensordot"}):
            found.append(ast.unparse(node))
    return found


def test_no_blas_product_makes_a_texel_s_value():
    """Every ``@`` or ``dot`` of the packages that make, place or compose texels is one of
    ``SMALL_PRODUCTS``."""
    found = {(str(path.relative_to(PACKAGE)), product)
             for package in ROW_PACKAGES for path in (PACKAGE / package).rglob("*.py")
             for product in row_products(path.read_text())}
    assert found - set(SMALL_PRODUCTS) == set()


def test_the_row_check_finds_every_kind_of_product():
    source = "a @ b\nnp.dot(a, b)\nx.dot(y)\nnp.matmul(a, b)\nnp.einsum('ij,j->i', a, b)\n"
    assert row_products(source) == ["a @ b", "np.dot(a, b)", "x.dot(y)", "np.matmul(a, b)"]


def test_row_sums_give_a_row_the_same_bits_in_any_array():
    """BLAS gives some rows other bits within shorter slices of the same array (measured:
    12 of 7,000 rows × a 7 × 3 matrix); ``rowwise`` gives each row its bits in the whole."""
    import numpy as np

    from baker.geometry.surface import luminance
    from baker.rowwise import matmul_rows

    rng = np.random.default_rng(0)
    rows, matrix = rng.uniform(size=(7000, 7)), rng.uniform(size=(7, 3))
    colours = rng.uniform(0, 8, (7000, 3))
    whole, lum = matmul_rows(rows, matrix), luminance(colours)
    blas_whole, blas_lum = rows @ matrix, colours @ np.array([0.2126, 0.7152, 0.0722])
    ours = blas = 0
    for start in range(0, 60):
        for length in (1, 2, 3, 5, 7, 13, 100):
            part = slice(start, start + length)
            ours += np.count_nonzero(matmul_rows(rows[part], matrix) != whole[part])
            ours += np.count_nonzero(luminance(colours[part]) != lum[part])
            blas += np.count_nonzero(rows[part] @ matrix != blas_whole[part])
            blas += np.count_nonzero(colours[part] @ np.array([0.2126, 0.7152, 0.0722])
                                     != blas_lum[part])
    assert ours == 0
    np.testing.assert_allclose(whole, rows @ matrix, rtol=1e-14)
    print(f"rows given other bits in a slice: rowwise {ours}, BLAS {blas}")
