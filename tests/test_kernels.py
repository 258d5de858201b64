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
               PYTHONPATH=str(PACKAGE.parent))
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
