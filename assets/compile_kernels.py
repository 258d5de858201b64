"""Compile baker's kernels ahead of time into one extension module, for the argument types the
warm-up bakes gave them (``warm_kernels.py``): ``baker/_kernels*.so`` and its index
``baker/_kernels.json``, which ``baker.jit`` reads (what it was built from, and which compiled
function each kernel has for which argument types).

numba's ``pycc`` compiles each recorded (kernel, argument types) with the compiler numba's JIT
uses, for this machine's CPU (as the JIT does: generic x86-64 code ran the ray sampler 2.8 times
slower), each function releasing the GIL (the bake's threads run kernels side by side, as the
JIT's ``nogil`` does). Run by ``warm_kernels.py`` after its bakes, in the same process: numba's
dispatchers hold the types they were called with.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import time
from pathlib import Path

from baker import jit

MODULE = "_kernels"


@contextlib.contextmanager
def _releasing_the_gil():
    """pycc's compiler with every function's wrapper releasing the GIL (pycc has no option)."""
    import numba.pycc.compiler as pycc_compiler
    from numba.core.compiler import Flags

    class GilFree(Flags):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            self.release_gil = True

    pycc_compiler.Flags = GilFree
    try:
        yield
    finally:
        pycc_compiler.Flags = Flags


def exports() -> dict[str, list]:
    """Kernel name (``module:qualname``) → [(argument keys, argument types, defaults)] of every
    type signature this process's dispatchers were compiled for whose types ``jit.type_key``
    knows. A call that left out trailing arguments with defaults (numba's "omitted" types) is
    compiled with those defaults passed (``defaults``: how many; ``jit.Kernel`` passes them)."""
    import numba
    from numba.core import types

    found: dict[str, list] = {}
    for dispatcher in jit.DISPATCHERS:
        func = dispatcher.py_func
        for signature in dispatcher.nopython_signatures:
            given = [t for t in signature.args if not isinstance(t, types.Omitted)]
            defaults = len(signature.args) - len(given)
            if any(isinstance(t, types.Omitted) for t in signature.args[:len(given)]):
                continue  # left out before a given argument: a call by keyword
            keys = tuple(jit.type_key(t) for t in given)
            filled = [numba.typeof(t.value) for t in signature.args[len(given):]]
            if None not in keys:
                found.setdefault(f"{func.__module__}:{func.__qualname__}", []).append(
                    (keys, (*given, *filled), defaults, func))
    return found


def compile_ahead(package: Path) -> str:
    """Build the module into ``package`` (the baker package the warm-up ran); what it did."""
    import numba
    from numba.pycc import CC

    started = time.perf_counter()
    index_path = package / jit.INDEX.name
    for stale in [*package.glob(f"{MODULE}.*.so"), *package.glob(f"{MODULE}.*.pyd"), index_path]:
        stale.unlink(missing_ok=True)
    cc = CC(MODULE)
    cc.output_dir, cc.target_cpu, cc.verbose = str(package), "host", False
    index: dict[str, list] = {}
    numbers = itertools.count()
    for name, entries in exports().items():
        for keys, arguments, defaults, func in entries:
            symbol = f"k{next(numbers)}"
            cc.export(symbol, arguments)(func)
            index.setdefault(name, []).append([keys, symbol, defaults])
    with _releasing_the_gil():
        cc.compile()
    index_path.write_text(json.dumps(
        {"built_for": jit.built_for(), "sources": jit.sources_digest(package),
         "numba": numba.__version__, "kernels": index}, indent=1))
    return (f"compiled {next(numbers)} functions of {len(index)} kernels ahead of time in "
            f"{time.perf_counter() - started:.0f} s")
