"""Per-texel results kept on disk, part by part, so a bake holds one part of its texels at a time.

A 4096² page has 8 million texels, and what the bake state keeps of each (``incremental.py``:
sample point, validity, obscurance terms, direct light) is about 200 bytes: 1.7 GB, seven times
the float page itself. A full bake (``bake.compute``) therefore makes its texels a part at a
time, composes each part into the pages, and appends the part's rows here, one file per field;
the state is then written from these files (``state.write_state``), and nothing holds every
texel's terms at once.

A group is a dataclass of per-texel arrays (``Terms``, ``Direct``, ``Validity``,
``TexelPoints``). Each part appends one instance: its per-texel arrays (as many rows as the
part has texels) are appended to their files; the fields named in ``PER_SCENE`` (a light's
colour, a triangle's texel count) and empty optional terms (0 rows) are the same in every part
and kept once; so are the scalar fields.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import threading
import uuid
import weakref
from dataclasses import dataclass, fields
from functools import cached_property
from typing import BinaryIO

import numpy as np

# Array fields of the per-texel dataclasses that are not per texel: the same in every part.
PER_SCENE = ("light_colours", "triangle_texels")

_COPY_BYTES = 1 << 24  # bytes copied or read at once from a column's file (bounds memory)
_SCAN_ROWS = 1 << 16  # rows of a column in memory counted at once (``Column.encoding``)


@dataclass
class Column:
    """One per-texel array field, its rows in ``path`` (raw C-order bytes), or held whole in
    ``array`` (a per-scene field, an empty optional term, or any array in memory).

    While rows are appended it counts those with a byte other than 0 and whether they all
    equal the first, so that ``state.write_state`` can store a mostly-zero or constant column
    in a few bytes (``encoding``) without reading the file first.
    """

    path: str | None
    dtype: np.dtype
    tail: tuple[int, ...]  # the shape after the row count
    rows: int = 0
    nonzero_rows: int = 0  # rows appended so far with some byte not 0
    first: np.ndarray | None = None  # the first row appended, (1, *tail)
    repeated: bool = True  # whether every row appended so far equals ``first``
    array: np.ndarray | None = None

    @classmethod
    def of(cls, array: np.ndarray) -> "Column":
        """A column held in memory (its rows are counted when ``encoding`` is first asked)."""
        return cls(None, array.dtype, array.shape[1:], array=array)

    @property
    def shape(self) -> tuple[int, ...]:
        return self.array.shape if self.array is not None else (self.rows,) + self.tail

    @cached_property
    def encoding(self) -> str:
        """How ``state.write_state`` stores the column: "zeros" (every byte 0, and there is at
        least one: not stored at all), "repeated" (two rows or more, all the same: one row
        stored), "sparse" (the rows with a byte not 0 and their indices, when that takes at most
        half the bytes) or "dense" (as it is). A column in memory is counted here, a block of
        rows at a time, and no further once it can only be dense (most are, at once). Asked
        once every row is in: the answer is kept."""
        count = self.shape[0] if self.shape else 0
        row_bytes = self._row_bytes()
        if count * row_bytes == 0:
            return "dense"
        sparse_most = count * row_bytes // (2 * (8 + row_bytes))  # nonzero rows, at most
        if self.array is not None:
            for start in range(0, count, _SCAN_ROWS):
                self._count(self.array[start:start + _SCAN_ROWS])
                if self.nonzero_rows > sparse_most and not self.repeated:
                    break
        if self.nonzero_rows == 0:
            return "zeros"
        if count > 1 and self.repeated:
            return "repeated"
        return "sparse" if self.nonzero_rows <= sparse_most else "dense"

    def sparse_rows(self) -> tuple[np.ndarray, np.ndarray]:
        """(indices (m,) int64, rows (m, *tail)) of the rows with a byte not 0, in order; read
        from disk a block at a time."""
        indices, rows = [], []
        for start, block in self._blocks():
            keep = np.flatnonzero(_nonzero_rows(_words(block)))
            indices.append(keep + start)
            rows.append(block[keep])
        return (np.concatenate(indices) if indices else np.zeros(0, np.int64),
                np.concatenate(rows) if rows else np.zeros((0,) + self.tail, self.dtype))

    def write_npy(self, file: BinaryIO) -> None:
        """Write the column as a ``.npy`` file: the same bytes as ``numpy.lib.format.write_array``
        of the whole array, copied from disk a block at a time."""
        if self.array is not None:
            np.lib.format.write_array(file, np.ascontiguousarray(self.array), allow_pickle=False)
            return
        np.lib.format.write_array_header_1_0(file, {
            "descr": np.lib.format.dtype_to_descr(self.dtype), "fortran_order": False,
            "shape": self.shape})
        with open(self.path, "rb") as source:
            shutil.copyfileobj(source, file, _COPY_BYTES)

    def load(self) -> np.ndarray:
        """The whole array, in memory."""
        if self.array is not None:
            return self.array
        return np.fromfile(self.path, self.dtype).reshape(self.shape)

    def _row_bytes(self) -> int:
        return self.dtype.itemsize * int(np.prod(self.shape[1:], dtype=np.int64))

    def _blocks(self):
        """(first row, rows (n, *tail)) of the column, a block of about ``_COPY_BYTES`` at a time."""
        if self.array is not None:
            yield 0, self.array
            return
        step = max(1, _COPY_BYTES // max(self._row_bytes(), 1))
        for start in range(0, self.rows, step):
            yield start, np.fromfile(self.path, self.dtype, count=min(step, self.rows - start)
                                     * int(np.prod(self.tail, dtype=np.int64)),
                                     offset=start * self._row_bytes()).reshape((-1,) + self.tail)

    def _count(self, values: np.ndarray) -> None:
        """Update ``nonzero_rows``, ``first`` and ``repeated`` with the rows ``values``."""
        words = _words(values)
        self.nonzero_rows += int(np.count_nonzero(_nonzero_rows(words)))
        if self.first is None:
            self.first = values[:1].copy()
        if self.repeated:
            first = _words(self.first)[0]
            self.repeated = all(bool((words[:, c] == first[c]).all())
                                for c in range(words.shape[1]))

    def _append(self, values: np.ndarray) -> None:
        values = np.ascontiguousarray(values, self.dtype)
        with open(self.path, "ab") as file:
            values.tofile(file)
        self.rows += len(values)
        self._count(values)


def _words(values: np.ndarray) -> np.ndarray:
    """``values`` (n, ...) as (n, w) unsigned integers of their own size: equal bits, equal
    words (so −0.0 is not 0, and NaNs compare)."""
    flat = np.ascontiguousarray(values).reshape(len(values), -1)
    size = flat.dtype.itemsize
    return flat.view(np.dtype(f"u{size}") if size in (1, 2, 4, 8) else np.uint8)


def _nonzero_rows(words: np.ndarray) -> np.ndarray:
    """(n,) bool: the rows of ``words`` (n, w) (``_words``) with some bit set. Column by
    column: numpy reduces a short last axis slowly."""
    out = np.zeros(len(words), bool)
    for c in range(words.shape[1]):
        out |= words[:, c] != 0
    return out


@dataclass
class Group:
    """A spilled dataclass: ``cls`` (its type), its columns by field name in field order, and
    its scalar fields."""

    cls: type
    columns: dict[str, Column]
    scalars: dict

    @classmethod
    def of(cls, obj) -> "Group":
        """A dataclass instance held in memory, as a group."""
        values = {f.name: getattr(obj, f.name) for f in fields(obj)}
        return cls(type(obj), {k: Column.of(v) for k, v in values.items() if isinstance(v, np.ndarray)},
                   {k: v for k, v in values.items() if not isinstance(v, np.ndarray)})

    def load(self):
        """The whole dataclass instance, in memory."""
        return self.cls(**self.scalars, **{name: c.load() for name, c in self.columns.items()})


_PREFIX = ".baker-spill-"


class Spill:
    """A temporary folder of groups appended part by part; removed by ``close``, or when the
    object is garbage collected or the interpreter exits.

    ``folder``: where to make it (None: the system's temporary folder). A bake puts it beside
    its output, on the disk that will hold the bake state anyway. Its name holds this process's
    id: the folders a killed bake left there (power loss) are removed when the next one starts
    (``remove_stale``). A process ended at once (SIGKILL, or Ray's hard exit when a cluster's
    head is lost) runs nothing more: a small watcher process started with the folder
    (``_watched``) removes it then, and says why on standard error.
    """

    def __init__(self, folder: str | os.PathLike | None = None):
        remove_stale(folder)
        self.folder = os.path.join(tempfile.gettempdir() if folder is None else os.fspath(folder),
                                   f"{_PREFIX}{os.getpid()}-{uuid.uuid4().hex[:12]}")
        # The watcher first: a bake killed before the folder exists leaves nothing behind,
        # one killed after it has the watcher (mkdtemp, then the watcher, left a gap).
        watcher = _watched(self.folder)
        try:
            os.mkdir(self.folder, 0o700)
        except OSError:
            _removed(self.folder, watcher)
            raise
        self.groups: dict[str, Group] = {}
        self._cleanup = weakref.finalize(self, _removed, self.folder, watcher)

    def append(self, name: str, part) -> None:
        """Append the rows of ``part`` (a dataclass of per-texel arrays) to the group ``name``."""
        rows = _rows_of(part)
        group = self.groups.get(name)
        if group is None:
            group = self.groups[name] = Group(type(part), {}, {})
            for f in fields(part):
                value = getattr(part, f.name)
                if not isinstance(value, np.ndarray):
                    group.scalars[f.name] = value
                elif f.name in PER_SCENE or not len(value):
                    group.columns[f.name] = Column.of(value)
                else:
                    group.columns[f.name] = Column(os.path.join(self.folder, f"{name}.{f.name}"),
                                                   value.dtype, value.shape[1:])
        for field_name, column in group.columns.items():
            value = getattr(part, field_name)
            if column.array is None:
                assert value.shape == (rows,) + column.tail, (name, field_name)
                column._append(value)
            else:
                assert np.array_equal(value, column.array), (name, field_name)
        assert all(getattr(part, k) == v for k, v in group.scalars.items()), name

    def close(self) -> None:
        """Remove the folder and everything in it."""
        self._cleanup()


_WATCHER = """import os, shutil, sys
sys.stdin.buffer.read()  # until the bake's process closes its end, or ends: then
if os.path.isdir(sys.argv[1]):  # not removed by the bake: it ended at once
    shutil.rmtree(sys.argv[1], ignore_errors=True)
    sys.stderr.write("baker: the bake ended abruptly (killed, or its Ray cluster's head was "
                     "lost); nothing was written, and its temporary rows are removed\\n")
"""


def _watched(folder: str) -> subprocess.Popen | None:
    """A process (Python, no baker imported) that waits for this one to end and then
    removes ``folder`` if it is still there, saying so on standard error; in a session of its
    own, so that Ctrl-C at the terminal leaves it to see the bake's own clean-up. None where
    it cannot start (the folder is then left to ``remove_stale``)."""
    try:
        return subprocess.Popen([sys.executable, "-c", _WATCHER, folder], stdin=subprocess.PIPE,
                                stdout=subprocess.DEVNULL, start_new_session=True)
    except OSError:
        return None


def _removed(folder: str, watcher: subprocess.Popen | None) -> None:
    """Remove ``folder``, then let its watcher go (it finds nothing left to do)."""
    shutil.rmtree(folder, ignore_errors=True)
    if watcher is not None:
        watcher.stdin.close()
        watcher.wait()


def remove_stale(folder: str | os.PathLike | None = None) -> list[str]:
    """Remove the spill folders in ``folder`` (None: the system's temporary folder), and the
    files ``set_aside`` named there, whose process is no longer running; return their paths.
    One whose process id is in use (perhaps by another program since) is kept."""
    folder = tempfile.gettempdir() if folder is None else os.fspath(folder)
    removed = []
    for name in os.listdir(folder):
        pid = name[len(_PREFIX):].split("-", 1)[0]
        if not name.startswith(_PREFIX) or not pid.isdigit() or _running(int(pid)):
            continue
        path = os.path.join(folder, name)
        if os.path.isdir(path):
            shutil.rmtree(path, ignore_errors=True)
        else:
            _remove_quietly(path)
        removed.append(path)
    return removed


def set_aside(path: str | os.PathLike) -> str | None:
    """Give the file at ``path``, if there is one, a second name beside it that
    ``remove_stale`` knows (this process's id in it): replacing ``path`` then frees nothing,
    and ``remove_later`` frees it on a thread of its own. Freeing a large file's pages takes a
    while — 30 ms for a 50 MB bake state, a tenth of a small rebake. None when there is no
    file, or its disk has no hard links (the replacement then frees it, as usual)."""
    folder = os.path.dirname(os.fspath(path)) or "."
    link = os.path.join(folder, f"{_PREFIX}{os.getpid()}-{uuid.uuid4().hex}.old")
    try:
        os.link(path, link)
    except OSError:
        return None
    return link


LATER_BYTES = 8 << 20
"""Files smaller than this are deleted at once (microseconds): only freeing a larger one's pages
is worth a thread, and a folder right after a bake then holds no second name of a small file."""


def remove_later(path: str) -> None:
    """Delete the file ``path``: on a thread of its own if it has ``LATER_BYTES`` or more, else
    at once. The thread is not a daemon: the interpreter waits for it before it exits, so
    nothing is left behind but after a kill (``remove_stale``)."""
    try:
        small = os.stat(path).st_size < LATER_BYTES
    except OSError:
        return
    if small:
        _remove_quietly(path)
        return
    threading.Thread(target=_remove_quietly, args=(path,), name="baker-remove-later").start()


def _remove_quietly(path: str) -> None:
    """Delete the file ``path``; one already gone is no error."""
    try:
        os.unlink(path)
    except OSError:
        pass


def _running(pid: int) -> bool:
    """Whether a process with id ``pid`` exists (signal 0 tests without sending anything)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def _rows_of(part) -> int:
    """The texel count of a per-texel dataclass: the rows of its first per-texel array."""
    for f in fields(part):
        value = getattr(part, f.name)
        if isinstance(value, np.ndarray) and f.name not in PER_SCENE and len(value):
            return len(value)
    return 0
