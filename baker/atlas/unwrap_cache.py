"""Meshes' charts kept across bakes, keyed by a hash of everything the charting is given.

A mesh's charting is a pure function of its input (its positions in the instance's rigid-free
frame and its triangles, the chart builder's constants, xatlas's version and options), so its
result (``charts.py``) is stored under the SHA-256 of that input and a later bake of the same
mesh reads it back instead of charting it: the result is the same arrays either way, so the
bake's bytes do not depend on whether the cache was hit. The charts hold no texel density, so a
bake at another density hits too and only packs them again; a rigid move of a node leaves its
input bit-identical (``unwrap.frame_positions``), so a rebake after moving objects hits.

The folder is ``$BAKER_CACHE_DIR`` if set (``off`` or empty: no cache), else
``$XDG_CACHE_HOME/baker`` or ``~/.cache/baker``; entries are ``unwrap/charts/<hash>.charts``
(``_packed``: the arrays' shapes and bytes behind a CRC-32, no pickle), written atomically, at
most ``KEEP_CHARTS`` (the least recently used go first). An entry that cannot be read whole
(truncated, a bad CRC, arrays of the wrong shape) is ignored, and the fresh result written over
it. A cache that cannot be written (read-only, full) only costs the next bake the charting.

Each scene file's last joint entry (all its meshes' charts in one, ``charts.chart_meshes``) is
named in ``unwrap/scenes/<hash of its path>.last`` with its meshes' names (``remember_joint``):
the next bake of that file after an edit reads its unchanged meshes' charts from that one entry
(``last_joint``), not from one file each (about a millisecond each: 0.2 s for 200 boxes). Only
a hint: the charts are found by their meshes' names, which hash their input.
"""

from __future__ import annotations

import hashlib
import math
import os
import struct
import zlib
from pathlib import Path
from typing import Iterable

import numpy as np

from baker.run.atomic import write_private

FORMAT = b"baker unwrap cache 6"  # bump when what an entry holds, or how it is keyed, changes
KEEP_CHARTS = 16384  # meshes' charts kept (a scene has one per distinct mesh; most are small)
KEEP_SCENES = 1024  # scene files whose last joint entry is named
_LAST = ".last"
_HEX = frozenset("0123456789abcdef")
PER_MESH = 5  # arrays per mesh: vertices, triangles, uv and chart of each vertex, chart sides
SUFFIX = ".charts"
_OLD_SUFFIXES = (".npz",)  # entries of earlier formats: never read again, pruned as the oldest
_KINDS = {b"i": np.dtype("<i8"), b"f": np.dtype("<f8")}  # what an entry's arrays may hold


def folder() -> Path | None:
    """The cache folder, or None when caching is off (``BAKER_CACHE_DIR=off`` or empty)."""
    chosen = os.environ.get("BAKER_CACHE_DIR")
    if chosen is not None:
        return None if chosen.strip().lower() in ("", "off", "0", "none") else Path(chosen)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "baker"


def key(meshes: Iterable[tuple[np.ndarray, np.ndarray]], options: Iterable[object]) -> str:
    """Hex SHA-256 of the charting's input: each mesh's (positions (n, 3), triangles (m, 3))
    with their types and shapes, and ``options`` (their ``repr``s: constants and versions)."""
    digest = hashlib.sha256(FORMAT)
    for option in options:
        digest.update(repr(option).encode() + b"\0")
    for positions, triangles in meshes:
        for array in (positions, triangles):
            digest.update(f"{array.dtype.str}{array.shape}".encode())
            digest.update(np.ascontiguousarray(array).data)
    return digest.hexdigest()


def entries() -> Path | None:
    """The folder of the entries, or None when caching is off."""
    place = folder()
    return None if place is None else place / "unwrap" / "charts"


def _scene_path(scene: str) -> Path | None:
    """Where the scene file ``scene``'s last joint entry is named, or None when caching is off."""
    place = folder()
    digest = hashlib.sha256(scene.encode(errors="surrogateescape")).hexdigest()
    return None if place is None else place / "unwrap" / "scenes" / f"{digest}{_LAST}"


def remember_joint(scene: str, joint: str, names: list[str]) -> None:
    """Name ``joint`` (an entry of the charts of the meshes ``names``, in order) as the scene
    file ``scene``'s last; then keep only the ``KEEP_SCENES`` scenes baked last. Any failure
    to write leaves it as it was."""
    path = _scene_path(scene)
    if path is None:
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_private(path, "\n".join([joint, *names]).encode())
        _prune(path.parent, KEEP_SCENES, _LAST)
    except OSError:
        pass


def last_joint(scene: str) -> tuple[str, list[str]] | None:
    """The scene file ``scene``'s last joint entry and its meshes' names (``remember_joint``),
    or None."""
    path = _scene_path(scene)
    try:
        lines = path.read_bytes().decode().split("\n") if path is not None else []
    except (OSError, UnicodeDecodeError):
        return None
    if len(lines) < 2 or not all(len(line) == 64 and _HEX.issuperset(line) for line in lines):
        return None
    return lines[0], lines[1:]


def entry_path(name: str) -> Path | None:
    """Where the entry ``name`` is kept, or None when caching is off."""
    place = entries()
    return None if place is None else place / f"{name}{SUFFIX}"


def read(name: str, mesh_count: int
         ) -> tuple[tuple[int, ...], tuple[tuple[np.ndarray, ...], ...]] | None:
    """The entry ``name``: (header ints, per mesh ``PER_MESH`` arrays), or None
    when there is none or it cannot be read whole (it is then rewritten by the next ``write``)."""
    path = entry_path(name)
    if path is None or not path.is_file():
        return None
    try:
        arrays = _unpacked(bytearray(path.read_bytes()))
        os.utime(path)  # recently used: kept longest
    except OSError:
        return None
    if arrays is None or len(arrays) != 2 + PER_MESH:
        return None
    header, lengths, joined = arrays[0], arrays[1], arrays[2:]
    if (header.ndim != 1 or header.dtype != np.int64 or lengths.shape != (mesh_count, PER_MESH)
            or lengths.dtype != np.int64 or (lengths < 0).any()):
        return None
    if any(len(a) != n for a, n in zip(joined, lengths.sum(axis=0))):
        return None
    split = [np.split(a, np.cumsum(n)[:-1]) for a, n in zip(joined, lengths.T)]
    return (tuple(int(v) for v in header),
            tuple(tuple(parts[m] for parts in split) for m in range(mesh_count)))


def write(name: str, header: tuple[int, ...], meshes: tuple[tuple[np.ndarray, ...], ...],
          prune: bool = True) -> None:
    """Store an entry (atomically): the header, each array's length per mesh, and
    per kind of array all meshes' joined (a few large arrays read much faster than thousands of
    small ones). Then (``prune``) drop the least recently used beyond ``KEEP_CHARTS``. Any failure to
    write leaves the cache as it was, and the bake goes on."""
    path = entry_path(name)
    if path is None or not meshes:
        return
    arrays = [np.asarray(header, np.int64),
              np.array([[len(a) for a in mesh] for mesh in meshes], np.int64)]
    arrays += [np.concatenate([np.asarray(mesh[k]) for mesh in meshes]) for k in range(PER_MESH)]
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_private(path, _packed(arrays))
    except OSError:
        return
    if prune:
        prune_entries()


def _packed(arrays: list[np.ndarray]) -> bytes:
    """An entry's bytes: ``FORMAT``, the CRC-32 of the rest, the count of ``arrays`` and each
    one's kind (``_KINDS``), dimensions and shape, zeros to a multiple of 8 bytes (the arrays
    read back aligned: numba's kernels take no other), then their data in turn (C order). What
    ``np.savez`` stored before, in less of the time to write and read (0.5 and 1.4 ms an entry
    there, a scene of 200 boxes writing 203 entries cold and reading 202 after an edit): integer
    arrays as int64, others as float64."""
    kinds = [b"i" if array.dtype.kind in "iub" else b"f" for array in arrays]
    layout = [struct.pack("<I", len(arrays))]
    for kind, array in zip(kinds, arrays):
        layout.append(struct.pack(f"<cB{array.ndim}q", kind, array.ndim, *array.shape))
    layout.append(bytes(-(len(FORMAT) + 4 + sum(map(len, layout))) % 8))
    rest = b"".join(layout + [np.ascontiguousarray(array, _KINDS[kind]).tobytes()
                              for kind, array in zip(kinds, arrays)])
    return FORMAT + struct.pack("<I", zlib.crc32(rest)) + rest


def _unpacked(data: bytearray) -> list[np.ndarray] | None:
    """The arrays of an entry's bytes (``_packed``), views of ``data``; None when they are not
    such bytes whole (another format, truncated, a CRC that does not match, a shape past the
    end)."""
    start = len(FORMAT) + 4
    if data[:len(FORMAT)] != FORMAT or len(data) < start + 4:
        return None
    if struct.unpack_from("<I", data, len(FORMAT))[0] != zlib.crc32(memoryview(data)[start:]):
        return None
    try:
        count, = struct.unpack_from("<I", data, start)
        at, shapes = start + 4, []
        for _ in range(count):
            kind, ndim = struct.unpack_from("<cB", data, at)
            shape = struct.unpack_from(f"<{ndim}q", data, at + 2)
            shapes.append((_KINDS[kind], shape))
            at += 2 + 8 * ndim
    except (struct.error, KeyError):
        return None
    at += -at % 8
    arrays = []
    for dtype, shape in shapes:
        size = math.prod(shape)
        if min(shape, default=0) < 0 or at + size * dtype.itemsize > len(data):
            return None
        array = np.frombuffer(data, dtype, size, at).reshape(shape)
        arrays.append(array if array.flags.aligned else array.copy())
        at += size * dtype.itemsize
    return arrays if at == len(data) else None


def prune_entries() -> None:
    """Remove all but the ``KEEP_CHARTS`` most recently used entries; once after writing many
    entries, not after each (a folder scan each)."""
    place = entries()
    if place is not None and place.is_dir():
        try:
            _prune(place, KEEP_CHARTS, SUFFIX, *_OLD_SUFFIXES)
        except OSError:
            pass


def _prune(place: Path, keep: int, *suffixes: str) -> None:
    """Remove all but the ``keep`` most recently used files of ``place`` named with ``suffixes``."""
    entries = sorted(((e.stat().st_mtime, e.path) for e in os.scandir(place)
                      if e.name.endswith(suffixes)), reverse=True)
    for _mtime, path in entries[keep:]:
        try:
            os.unlink(path)
        except FileNotFoundError:
            pass
