"""The two ways baker compiles its kernels with numba: ``jit`` and ``inline``.

Every kernel is compiled ``nogil`` (the bake's threads run them side by side) and cached on
disk beside its module (``__pycache__``; under ``NUMBA_CACHE_DIR`` when that is set), so a
process pays the compile once per install; the install itself fills the cache (``setup.py``).

numba keys a cached kernel by its argument types, numba's version and the CPU; baker's kernels
are keyed as well by their module's text (not its mtime, which an install does not keep) and,
since a cache is only good for the environment that wrote it, by ``ENVIRONMENT`` (Python, numpy
and llvmlite versions), so that a cache written under another one (a venv upgraded, a wheel
built beside other packages) is compiled again, not loaded. No kernel
calls BLAS or LAPACK (``np.dot``, ``@``, ``np.linalg``: numba reaches them through scipy, which
baker does not depend on; ``tests/test_kernels.py`` checks it).
"""

from __future__ import annotations

import functools
import hashlib
import sys
from pathlib import Path

import llvmlite
import numba
import numpy
from numba.core import caching

ENVIRONMENT = (sys.version_info[:3], numpy.__version__, llvmlite.__version__)
"""What besides numba's own key a cached kernel of baker's was compiled for."""

_PACKAGE = str(Path(__file__).resolve().parent)


@functools.lru_cache(maxsize=None)
def _source_hash(path: str) -> str:
    """SHA-256 of a module's text. numba before 0.68 stamps a cache by the file's mtime, which an
    install from a wheel does not keep: the content is what the kernels were compiled from."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


@functools.lru_cache(maxsize=None)
def _bakers(py_file: str) -> bool:
    """Whether the module file ``py_file`` is one of baker's (resolved once a file: a process
    makes a hundred kernels in a few dozen modules)."""
    return str(Path(py_file).resolve()).startswith(_PACKAGE)


_WRITABLE: set[str] = set()
"""The cache folders found writable in this process (``Keyed.ensure_cache_path``)."""


def _keyed_by_environment(locator: type) -> type:
    """``locator`` (one of numba's cache locators) for baker's modules only, its source stamp
    extended by ``ENVIRONMENT``: a stamp that differs makes numba compile and cache again."""

    class Keyed(locator):
        def get_source_stamp(self):
            return _source_hash(self._py_file), ENVIRONMENT

        def ensure_cache_path(self):
            """numba's check (the folder made, a file written in it and removed: OSError when
            it cannot be) once a folder, not once a kernel."""
            path = self.get_cache_path()
            if path not in _WRITABLE:
                super().ensure_cache_path()
                _WRITABLE.add(path)

        @classmethod
        def from_function(cls, py_func, py_file):
            if not _bakers(py_file):
                return None  # not baker's: numba's own locators take it
            return super().from_function(py_func, py_file)

    Keyed.__name__ = Keyed.__qualname__ = f"Baker{locator.__name__}"
    return Keyed


_LOCATORS = [_keyed_by_environment(base) for base in (
    caching.UserProvidedCacheLocator, caching.InTreeCacheLocator, caching.UserWideCacheLocator)]
if not any(cls.__name__.startswith("Baker") for cls in caching.CacheImpl._locator_classes):
    caching.CacheImpl._locator_classes[:0] = _LOCATORS

jit = numba.njit(nogil=True, cache=True)
# For helpers that take arrays and run once per texel or ray inside a kernel: inlined into the
# kernels that call them (numba IR), where a call passing arrays costs several times their
# arithmetic (``rebake.near_rays._near_flags``: 907 -> 105 ns a texel of 64 rays).
inline = numba.njit(nogil=True, cache=True, inline="always")
