"""The two ways baker compiles its kernels with numba, ``jit`` and ``inline``, and where the
compiled code comes from: ahead of time, or numba's just-in-time compiler.

**Ahead of time.** The install compiles every kernel, for each argument types its warm-up bakes
gave it, into one extension module beside the package (``baker/_kernels*.so``, and its index
``_kernels.json``: ``assets/compile_kernels.py``, run by ``setup.py``). A process whose package
is the one the module was built from (the same ``sources_digest``, Python, numpy and machine)
calls those functions and never imports numba: numba's import and its first kernel's load
(0.22 s and 0.24 s, measured in issue 46) are half a small bake's fixed cost. Each kernel is then
a ``Kernel``, which reads its arguments' types (``value_key``, the types numba would give them)
and calls the function compiled for them. Types it has none for, a stale or missing module, or
``BAKER_JIT=1`` start numba (``_start_numba``): every ``Kernel`` becomes a numba dispatcher in
its module, and the call goes on there. Both compile the same code with the same compiler (LLVM
through numba), so both give the same bits (``tests/test_compile_kernels.py``).

**Just in time.** Every kernel is compiled ``nogil`` (the bake's threads run them side by side)
and cached on disk beside its module (``__pycache__``; under ``NUMBA_CACHE_DIR`` when that is
set), so a process pays the compile once per install; the install itself fills the cache
(``setup.py``). numba keys a cached kernel by its argument types, numba's version and the CPU;
baker's kernels are keyed as well by their module's text (not its mtime, which an install does
not keep) and, since a cache is only good for the environment that wrote it, by
``ENVIRONMENT`` (Python, numpy and llvmlite versions), so that a cache written under another
one (a venv upgraded, a wheel built beside other packages) is compiled again, not loaded.

No kernel calls BLAS or LAPACK (``np.dot``, ``@``, ``np.linalg``: numba reaches them through
scipy, which baker does not depend on; ``tests/test_kernels.py`` checks it).
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import json
import os
import platform
import sys
import threading
from pathlib import Path
from typing import Callable

import numpy

_PACKAGE = Path(__file__).resolve().parent
INDEX = _PACKAGE / "_kernels.json"
"""The ahead-of-time module's index: what it was built from, and each kernel's functions."""
EXTENSION = "baker._kernels"
_OPTIONS = {"jit": dict(nogil=True, cache=True),
            # For helpers that take arrays and run once per texel or ray inside a kernel: inlined
            # into the kernels that call them (numba IR), where a call passing arrays costs
            # several times their arithmetic (``rebake.near_rays._near_flags``: 907 -> 105 ns a
            # texel of 64 rays).
            "inline": dict(nogil=True, cache=True, inline="always")}


def sources_digest(package: Path = _PACKAGE) -> str:
    """SHA-256 of every ``.py`` file under ``package`` (subpackages included), each by its path
    relative to ``package`` and its bytes: a file moved, added, removed or edited changes it.
    What compiled code (a bake state's terms, the ahead-of-time kernels) is good for."""
    sha = hashlib.sha256()
    for path in sorted(package.rglob("*.py"), key=lambda p: p.relative_to(package).as_posix()):
        for part in (path.relative_to(package).as_posix().encode(), path.read_bytes()):
            sha.update(len(part).to_bytes(8, "little"))
            sha.update(part)
    return sha.hexdigest()


@functools.lru_cache(maxsize=1)
def package_digest() -> str:
    """``sources_digest`` of this baker package, once a process (the ahead-of-time module's
    check and the bake state's code fingerprint both ask for it)."""
    return sources_digest(_PACKAGE)


def built_for() -> dict[str, str]:
    """What besides the sources an ahead-of-time module is only good for: Python, numpy, and
    the CPU its code was compiled for (code for another CPU may use instructions this one
    lacks: ``_cpu``)."""
    return {"python": platform.python_version(), "numpy": numpy.__version__,
            "platform": sys.platform, "machine": platform.machine(), "cpu": _cpu()}


def _cpu() -> str:
    """This CPU, as a hash: on Linux of its model name and feature flags (``/proc/cpuinfo``,
    the first processor's: a millisecond), elsewhere of its model and features as LLVM names
    them (importing LLVM's library: 0.04 s)."""
    try:
        lines = Path("/proc/cpuinfo").read_text().split("\n\n")[0].splitlines()
        described = [line for line in lines if line.split(":")[0].strip() in (
            "model name", "flags", "Features", "CPU part")]
    except OSError:
        described = []
    if not described:
        from llvmlite import binding

        described = [binding.get_host_cpu_name(), binding.get_host_cpu_features().flatten()]
    return hashlib.sha256("\n".join(described).encode()).hexdigest()


_NUMBER_NAMES = {numpy.dtype(kind).num: numpy.dtype(kind).name for kind in (
    numpy.bool_, numpy.int8, numpy.int16, numpy.int32, numpy.int64, numpy.longlong, numpy.uint8,
    numpy.uint16, numpy.uint32, numpy.uint64, numpy.ulonglong, numpy.float16, numpy.float32,
    numpy.float64, numpy.complex64, numpy.complex128)}
"""numpy's type number → name of its numeric dtypes: ``dtype.name`` is made in Python at every
call (an array's key took 1.9 µs with it, 0.36 µs without; a level of 20,000 instances keyed
120,000 arrays)."""


def value_key(value) -> object:
    """The type numba gives ``value`` as an argument, as a hashable key (``type_key`` gives the
    same key for the numba type); None for a value the ahead-of-time kernels do not take."""
    if isinstance(value, numpy.ndarray):
        flags, dtype = value.flags, value.dtype
        if type(value) not in (numpy.ndarray, numpy.memmap) or not (
                flags.aligned and dtype.isnative):
            return None
        layout = "C" if flags.c_contiguous else "F" if flags.f_contiguous else "A"
        name = _NUMBER_NAMES.get(dtype.num) if dtype.isbuiltin == 1 else None
        return ("array", name or dtype.name, value.ndim, layout, not flags.writeable)
    kind = type(value)
    if kind is bool or kind is numpy.bool_:
        return "bool"
    if kind is int:
        return ("int64" if -(1 << 63) <= value < (1 << 63)
                else "uint64" if 0 <= value < (1 << 64) else None)
    if kind is float:
        return "float64"
    if isinstance(value, numpy.generic):
        return value.dtype.name if value.dtype.isnative else None
    if kind is tuple:
        keys = tuple(value_key(item) for item in value)
        return None if None in keys else ("tuple", *keys)
    if value is None:
        return "none"
    return None


def type_key(numba_type) -> object:
    """``value_key`` of a value numba types as ``numba_type``; None for types it does not take
    (at the install: the argument types no ahead-of-time function is made for)."""
    from numba.core import types

    if isinstance(numba_type, types.Array):
        if not numba_type.aligned:
            return None
        return ("array", str(numba_type.dtype), numba_type.ndim, numba_type.layout,
                not numba_type.mutable)
    if isinstance(numba_type, types.Boolean):
        return "bool"
    if isinstance(numba_type, (types.Integer, types.Float)):
        return str(numba_type)
    if isinstance(numba_type, types.BaseTuple) and not isinstance(numba_type,
                                                                  types.BaseNamedTuple):
        keys = tuple(type_key(item) for item in numba_type.types)
        return None if None in keys else ("tuple", *keys)
    if numba_type == types.none:
        return "none"
    return None


def _as_key(item) -> object:
    """A key read back from JSON (lists) as ``value_key`` makes it (tuples)."""
    return tuple(_as_key(part) for part in item) if isinstance(item, list) else item


def _ahead_of_time() -> tuple[dict[str, dict[tuple, tuple[Callable, int]]] | None, str]:
    """(kernel name (``module:qualname``) → {argument keys: (compiled function, how many of the
    kernel's last arguments it takes their defaults for)} of the ahead-of-time module, or None
    when there is none this package can use; why not, when not)."""
    if os.environ.get("BAKER_JIT"):
        return None, "BAKER_JIT is set"
    try:
        index = json.loads(INDEX.read_text())
    except (OSError, ValueError):
        return None, (f"no compiled module ({INDEX.name} is missing: the install could not build "
                      "it, maybe for want of a C compiler)")
    if index.get("sources") != package_digest():
        return None, "the compiled module is of other sources: install baker again"
    if index.get("built_for") != built_for():
        return None, ("the compiled module is for another Python, numpy or CPU: install baker "
                      "again")
    try:
        module = importlib.import_module(EXTENSION)
    except ImportError as error:
        return None, f"the compiled module does not load ({error})"
    return {name: {_as_key(key): (getattr(module, export), defaults)
                   for key, export, defaults in entries}
            for name, entries in index["kernels"].items()}, ""


_AHEAD, _WHY_NOT = _ahead_of_time()
_KERNELS: list["Kernel"] = []
_LOCK = threading.RLock()
_NUMBA_STARTED: list[Callable[[], None]] = []  # run when numba starts (``on_numba``)
_numba_jit: dict[str, Callable] = {}  # decorator kind → numba's decorator, once started
DISPATCHERS: list = []
"""Every kernel's numba dispatcher made in this process (what the install compiles ahead of
time: ``assets/compile_kernels.py``)."""


class Kernel:
    """A kernel compiled ahead of time: called with the argument types it was compiled for, it
    runs that code (without numba); with others, numba's dispatcher for it (``_start_numba``)."""

    def __init__(self, func: Callable, kind: str, exports: dict[tuple, tuple[Callable, int]]):
        functools.update_wrapper(self, func)
        self.py_func, self.kind, self._exports = func, kind, exports
        self.dispatcher: Callable | None = None

    def __call__(self, *args, **keywords):
        export = None
        if not keywords:
            keys = tuple(value_key(arg) for arg in args)
            export = self._exports.get(keys) or self._taking(keys)
        if export is not None:
            compiled, defaults = export
            return compiled(*args, *self.py_func.__defaults__[-defaults:] if defaults else ())
        if self.dispatcher is None:
            _start_numba()
        return self.dispatcher(*args, **keywords)

    def _taking(self, keys: tuple) -> tuple[Callable, int] | None:
        """A function compiled for types that take arguments of types ``keys`` as they are
        (``_takes``), remembered for ``keys``; None if there is none."""
        for compiled, export in list(self._exports.items()):
            if len(compiled) == len(keys) and all(map(_takes, compiled, keys)):
                self._exports[keys] = export
                return export
        return None


def _takes(compiled, given) -> bool:
    """Whether code compiled for an argument of type ``compiled`` (a ``value_key``) runs one of
    type ``given`` unchanged: the same type, or an array of its dtype and dimensions that is
    writable where ``compiled`` is read-only, or of any layout where ``compiled`` is "A" (any
    strides): the same arithmetic on the same values, only the checks or strides differ."""
    if compiled == given:
        return True
    if not (isinstance(compiled, tuple) and isinstance(given, tuple)):
        return False
    if compiled[0] == given[0] == "tuple":
        return len(compiled) == len(given) and all(map(_takes, compiled[1:], given[1:]))
    return (compiled[0] == given[0] == "array" and compiled[1:3] == given[1:3]
            and compiled[3] in ("A", given[3]) and (compiled[4] or not given[4]))


def _start_numba() -> None:
    """Import numba (with baker's cache locators), give every ``Kernel`` its dispatcher and put
    the dispatchers in place of the ``Kernel`` objects in baker's modules, where numba looks up
    a kernel's callees; later decorations return dispatchers. Once a process."""
    with _LOCK:
        if _numba_jit:
            return
        import numba

        _install_locators()
        decorators = {kind: numba.njit(**options) for kind, options in _OPTIONS.items()}
        for kernel in _KERNELS:
            kernel.dispatcher = decorators[kernel.kind](kernel.py_func)
            DISPATCHERS.append(kernel.dispatcher)
        for name, module in list(sys.modules.items()):
            if name == "baker" or name.startswith("baker."):
                for attribute, value in list(vars(module).items()):
                    if isinstance(value, Kernel):
                        setattr(module, attribute, value.dispatcher)
        _numba_jit.update(decorators)
        callbacks, _NUMBA_STARTED[:] = list(_NUMBA_STARTED), []
        for callback in callbacks:
            callback()


def on_numba(callback: Callable[[], None]) -> None:
    """Run ``callback`` once numba is imported: now if it is, else when baker's kernels start
    it (``forget`` cancels)."""
    with _LOCK:
        if _numba_jit or "numba" in sys.modules:
            callback()
        else:
            _NUMBA_STARTED.append(callback)


def forget(callback: Callable[[], None]) -> None:
    """Cancel an ``on_numba`` callback that has not run."""
    with _LOCK:
        if callback in _NUMBA_STARTED:
            _NUMBA_STARTED.remove(callback)


def _compile(kind: str, func: Callable):
    """``func`` as a kernel of ``kind`` ("jit" or "inline")."""
    with _LOCK:
        if _AHEAD is None and not _numba_jit:
            _start_numba()
        if _numba_jit:
            DISPATCHERS.append(_numba_jit[kind](func))
            return DISPATCHERS[-1]
        kernel = Kernel(func, kind, _AHEAD.get(f"{func.__module__}:{func.__qualname__}", {}))
        _KERNELS.append(kernel)
        return kernel


def status() -> str:
    """How this process's kernels are compiled (``baker --version``, a bake's report)."""
    if _AHEAD is None:
        return f"numba's JIT: {_WHY_NOT}"
    if _numba_jit:
        return ("compiled ahead of time; numba's JIT for argument types the install's "
                "warm-up did not give")
    return "compiled ahead of time"


def jit(func: Callable):
    """Compile ``func`` as one of baker's kernels: nopython, nogil, cached."""
    return _compile("jit", func)


def inline(func: Callable):
    """``jit``, inlined into the kernels that call it."""
    return _compile("inline", func)


# ----------------------------------------------------------------------------- numba's cache


@functools.lru_cache(maxsize=None)
def _source_hash(path: str) -> str:
    """SHA-256 of a module's text. numba before 0.68 stamps a cache by the file's mtime, which an
    install from a wheel does not keep: the content is what the kernels were compiled from."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


@functools.lru_cache(maxsize=None)
def _bakers(py_file: str) -> bool:
    """Whether the module file ``py_file`` is one of baker's (resolved once a file: a process
    makes a hundred kernels in a few dozen modules)."""
    return str(Path(py_file).resolve()).startswith(str(_PACKAGE))


_WRITABLE: set[str] = set()
"""The cache folders found writable in this process (``Keyed.ensure_cache_path``)."""


def environment() -> tuple:
    """What besides numba's own key a cached kernel of baker's was compiled for."""
    import llvmlite

    return sys.version_info[:3], numpy.__version__, llvmlite.__version__


ENVIRONMENT: tuple | None = None
"""``environment()`` once numba has started (a test sets another to see a cache missed)."""


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


def _install_locators() -> None:
    """Put baker's cache locators first in numba's list (once)."""
    global ENVIRONMENT
    from numba.core import caching

    if ENVIRONMENT is None:
        ENVIRONMENT = environment()
    if not any(cls.__name__.startswith("Baker") for cls in caching.CacheImpl._locator_classes):
        caching.CacheImpl._locator_classes[:0] = [_keyed_by_environment(base) for base in (
            caching.UserProvidedCacheLocator, caching.InTreeCacheLocator,
            caching.UserWideCacheLocator)]
