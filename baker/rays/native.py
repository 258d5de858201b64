"""Embree's ray queries through baker's own small C library, where the install built it.

``baker/native/rays.c`` asks the libembree4 that embreex's wheel ships the questions embreex
asks (nearest hit, occlusion, default arguments), from a plain C loop over float32 rows instead
of embreex's item-by-item Cython loop: 1.04–1.10× embreex's rate on nearest hits, 1.3–1.5× on
occlusion (cast in packets of 16 rays on a CPU with AVX-512, of 8 with AVX2;
``benchmarks/bench_rays.py``), and
a scene built 5× faster (0.012 against 0.06 s for the boxes' 98,732 triangles: embreex copies
the vertices one by one through Python).
The install compiles it into ``baker/_rays.so`` (setup.py) with no Embree headers: its Embree
symbols are resolved when it is loaded here, after embreex's libembree4 is loaded for all
(``RTLD_GLOBAL``). Its scenes are built as embreex builds them (the same vertex layout and
scene flags), so its hits are embreex's, bit for bit (``tests/test_native_rays.py``): where it
is missing or cannot load (no C compiler at install, a platform other than Linux, an embreex
without its own libembree4), ``Tracer`` uses embreex, more slowly, for the same bake — but
where rays pass alpha cut-outs: embreex sets no tnear, so a ray let through one starts again
past the hit (``Tracer._run``), on its line to float32 rounding.
"""

from __future__ import annotations

import ctypes
import sys
from pathlib import Path

import numpy as np

_LIBRARY = Path(__file__).resolve().parent.parent / "_rays.so"
_void, _long = ctypes.c_void_p, ctypes.c_long


def _embree_library() -> Path:
    """The libembree4 that embreex's extension modules load (its wheel's ``embreex.libs``)."""
    import embreex

    found = sorted((Path(embreex.__file__).resolve().parent.parent / "embreex.libs")
                   .glob("libembree4*.so*"))
    if not found:
        raise OSError("embreex ships no libembree4 beside it")
    return found[0]


def _load() -> tuple[ctypes.CDLL | None, str]:
    """(the library, "") or (None, why not)."""
    if not sys.platform.startswith("linux"):
        return None, f"baker's native ray calls are built on Linux only, not {sys.platform}"
    if not _LIBRARY.exists():
        return None, f"{_LIBRARY.name} was not built at install (no C compiler?)"
    try:
        ctypes.CDLL(str(_embree_library()), mode=ctypes.RTLD_GLOBAL)
        library = ctypes.CDLL(str(_LIBRARY))
    except OSError as error:
        return None, f"{_LIBRARY.name} does not load: {error}"
    try:
        library.baker_scene.restype = _void
        library.baker_scene.argtypes = [_void, _long, _void, _long]
        library.baker_release.argtypes = [_void]
        library.baker_nearest.argtypes = [_void, _void, _void, _void, _void, _long, _void, _void,
                                          _void]
        library.baker_occluded.argtypes = [_void, _void, _void, _void, _long, _void]
        library.baker_packets.argtypes = []
    except AttributeError as error:  # an older baker's build: ``pip install`` builds it anew
        return None, f"{_LIBRARY.name} is from another version of baker ({error}): reinstall"
    return library, ""


_NATIVE, _WHY_NOT = _load()


def engine() -> str:
    """What casts this process's rays, for ``baker --version`` and the report."""
    if not _NATIVE:
        return f"embreex ({_WHY_NOT})"
    width = _NATIVE.baker_packets()
    packets = f", occlusion in packets of {width}" if width > 1 else ""
    return f"Embree 4 through baker's native calls{packets}"


class NativeScene:
    """An Embree scene of one triangle mesh, asked as embreex's ``EmbreeScene.run`` is (the
    subset ``Tracer`` uses), or None from ``scene`` where the native library is missing."""

    def __init__(self, handle: int):
        self._handle = handle
        self.packets = _NATIVE.baker_packets() > 1  # occlusion cast 8 or 16 rays at a time

    def run(self, origins: np.ndarray, directions: np.ndarray, dists: np.ndarray,
            query: str = "INTERSECT", near: np.ndarray | None = None, **_):
        """Rays (n, 3) float32 origins and directions, ``dists`` (n,) float32 lengths: for
        INTERSECT (which ``Tracer`` always asks with embreex's ``output=1``), embreex's dict
        (``primID``, ``tfar``: ``dists`` overwritten with the hit distances, ``u``, ``v``),
        searched from ``near`` (n,) float32 along each ray where given (else from its origin);
        for OCCLUDED, (n,) int32 0 where something lies along the ray, −1 where nothing does."""
        origins = np.ascontiguousarray(origins, np.float32)
        directions = np.ascontiguousarray(directions, np.float32)
        n = len(dists)
        if query == "OCCLUDED":
            blocked = np.empty(n, np.int32)
            _NATIVE.baker_occluded(self._handle, origins.ctypes.data, directions.ctypes.data,
                                   np.ascontiguousarray(dists, np.float32).ctypes.data, n,
                                   blocked.ctypes.data)
            return blocked
        tfar = np.require(dists, np.float32, ["C", "W"])  # dists itself where it can be
        triangle, u, v = np.empty(n, np.int32), np.empty(n, np.float32), np.empty(n, np.float32)
        if near is not None:
            near = np.ascontiguousarray(near, np.float32)
        _NATIVE.baker_nearest(self._handle, origins.ctypes.data, directions.ctypes.data,
                              None if near is None else near.ctypes.data, tfar.ctypes.data, n,
                              triangle.ctypes.data, u.ctypes.data, v.ctypes.data)
        return {"primID": triangle, "tfar": tfar, "u": u, "v": v}

    def __del__(self):
        if _NATIVE is not None:  # None once the interpreter has torn the module down
            _NATIVE.baker_release(self._handle)


def scene(vertices: np.ndarray, triangles: np.ndarray) -> NativeScene | None:
    """The native scene of ``vertices`` (V, 3) float32 and ``triangles`` (T, 3) int32, or
    None where there is no native library (or Embree refused the scene: embreex then tries)."""
    if _NATIVE is None:
        return None
    vertices = np.ascontiguousarray(vertices, np.float32)
    triangles = np.ascontiguousarray(triangles, np.int32)
    handle = _NATIVE.baker_scene(vertices.ctypes.data, len(vertices), triangles.ctypes.data,
                                 len(triangles))
    return NativeScene(handle) if handle else None
