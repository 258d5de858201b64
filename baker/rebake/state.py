"""The bake state: a sidecar file that lets the next bake recompute only what changed.

Written next to the output (``<output>.bake`` by default) after every bake; read by an
incremental rebake (``incremental.py``), which diffs the new scene against its fingerprints
(``diff.py``). The format is documented in ``docs/bake_state.md``:

- a ZIP archive (``zipwriter.py``: arrays deflated unless they hardly compress, the header
  stored) whose members have a fixed timestamp, so the same bake gives the same bytes
  (docs/design.md §4: an incremental rebake's state equals a full bake's);
- ``header.json``: ``{"format": "baker-bake-state", "version": 13, "fingerprints": {...},
  "groups": {name: {"class": ..., "fields": {...}, "scalars": {...}}}, "zeros": {...},
  "repeated": {...}, "sparse": {...}}``;
- one ``<group>/<field>.npy`` member per array (numpy's .npy format), so ``numpy.load`` of the
  file as an .npz reads the arrays; arrays that are all zero, all one row repeated, or mostly
  zero rows are listed under ``zeros``, ``repeated`` or ``sparse`` (shape, dtype) and stored
  as nothing, their first row, or their rows that are not zero with ``<name>.rows.npy``.

Dataclasses (Texels, Validity, Terms, Direct) are stored field by field, generically: a new term
field needs no format change — a state that lacks a field the code now has is "old" and leads to
a full bake, never to a wrong result. Anything unreadable (missing, truncated, foreign, another
version, fields that do not match) raises ``StateUnusable`` with a one-line reason.
"""

from __future__ import annotations

import errno
import hashlib
import io
import json
import math
import os
import stat
import struct
import zipfile
from dataclasses import dataclass, fields, is_dataclass
from pathlib import Path
from typing import Any, BinaryIO, Callable

import numpy as np
from isal import isal_zlib

from baker.atlas.layout import Atlas, InstanceUV
from baker.atlas.validity import Validity
from baker.light.direct import Direct
from baker.light.hemisphere import Terms
from baker.pipeline.parts import TexelPoints
from baker.rebake.zipwriter import BLOCK_BYTES, DEFLATED, STORED, ZipWriter, deflate
from baker.run.atomic import write_atomically
from baker.run.spill import Column, Group
from baker.settings import MAX_TEXELS

FORMAT = "baker-bake-state"
VERSION = 17
SUFFIX = ".bake"
_NPY_HEAD = 1 << 16  # bytes enough for any .npy header baker writes (version 1.0: < 64 KiB)


class StateUnusable(Exception):
    """The bake state cannot be used; ``str(error)`` says why in one line."""


def state_classes() -> dict[str, type]:
    """The dataclasses a bake state stores, by group name (``load``'s ``classes``)."""
    return {"texels": TexelPoints, "validity": Validity, "terms": Terms, "direct": Direct}


def default_path(output: str | Path) -> Path:
    """Where the state of a bake written to ``output`` lives by default: ``<output>.bake``."""
    output = Path(output)
    return output.with_name(output.name + SUFFIX)


def timing_path(state_path: str | Path) -> Path:
    """Where the time of the last full bake is kept beside the state: ``<state>.json``. Apart
    from the state, because the state's bytes must not depend on how long the bake took."""
    state_path = Path(state_path)
    return state_path.with_name(state_path.name + ".json")


def save_full_bake_seconds(state_path: str | Path, seconds: float,
                           write: Callable[[Path, bytes], None] = write_atomically,
                           stages: dict[str, float] | None = None,
                           rebake_correction: float | None = None,
                           rebake_overhead: float | None = None) -> None:
    """Record that a full bake for this state took ``seconds``, and ``stages`` (stage name →
    seconds, as the bake's report has them) if given; and, as the last rebake measured them,
    its search and rays' time over the cost model's figure (``cost.rebake_measured``)
    and its seconds besides them, if given; with ``write(path, bytes)`` (an atomic writer, or
    ``run.atomic.Outputs.stage``)."""
    record: dict = {"full_bake_seconds": round(float(seconds), 3)}
    if stages:
        record["stage_seconds"] = {k: round(float(v), 4) for k, v in sorted(stages.items())}
    if rebake_correction is not None:
        record["rebake_correction"] = round(float(rebake_correction), 4)
    if rebake_overhead is not None:
        record["rebake_overhead"] = round(float(rebake_overhead), 3)
    write(timing_path(state_path), json.dumps(record).encode())


def last_full_bake(state_path: str | Path) -> dict | None:
    """The record of the last full bake beside the state: ``full_bake_seconds`` (> 0), if
    recorded ``stage_seconds`` (name → seconds ≥ 0), and ``rebake_correction`` (> 0) and
    ``rebake_overhead`` (≥ 0) where a rebake has measured itself since; None if none or
    unreadable."""
    try:
        with _open_regular(timing_path(state_path)) as file:
            record = json.loads(file.read(1 << 16))
        seconds = float(record["full_bake_seconds"])
        stages = {str(k): float(v) for k, v in record.get("stage_seconds", {}).items()}
        measured = {name: float(record[name]) for name in ("rebake_correction",
                                                          "rebake_overhead") if name in record}
    except (OSError, ValueError, KeyError, TypeError, AttributeError, StateUnusable):
        return None
    if not seconds > 0 or not all(v >= 0 for v in stages.values()):
        return None
    return {"full_bake_seconds": seconds, "stage_seconds": stages,
            **{name: value for name, value in measured.items()
               if value >= 0 and math.isfinite(value)
               and (value > 0 or name == "rebake_overhead")}}


def last_full_bake_seconds(state_path: str | Path) -> float | None:
    """The seconds of the last full bake recorded beside the state (None if none or unreadable)."""
    record = last_full_bake(state_path)
    return None if record is None else record["full_bake_seconds"]


def digest(*parts: Any) -> str:
    """A short hex SHA-256 of arrays (dtype, shape and bytes), strings and numbers, in order."""
    h = hashlib.sha256()
    for part in parts:
        if isinstance(part, np.ndarray):
            a = np.ascontiguousarray(part)
            h.update(f"{a.dtype.str}{a.shape}".encode())
            h.update(a.reshape(-1).view(np.uint8))  # its bytes, not a copy (a texture's 256 MiB)
        else:
            h.update(repr(part).encode())
        h.update(b"\x00")
    return h.hexdigest()[:32]


@dataclass(frozen=True)
class BakeState:
    """What a rebake needs of the last bake.

    fingerprints: JSON-able dict from ``diff.fingerprints`` (settings, unwrap input, every
    instance, material, light; the tracer's centre). atlas: the lightmap layout (UVs).
    groups: name → dataclass instance (or its rows spilled to disk, ``spill.Group``), at least "texels" (Texels after the validity probes moved
    their sample points), "validity", "terms", and "direct" when the scene has direct light;
    rows of every per-texel array in texel order. instance_world: (I, 4, 4) float64 world matrix
    of every instance as baked (to rebuild a moved node's old placement).
    """

    fingerprints: dict
    atlas: Atlas
    groups: dict[str, Any]
    instance_world: np.ndarray


MIN_RATIO = 1.7
"""An array is deflated only if zlib-ng deflates its first ``zipwriter.BLOCK_BYTES`` to at most
1/MIN_RATIO of their size, else stored: the terms' noisy means (``w_hit`` 1.39×, ``hit_sq``
1.2–1.3× by zlib's level 1 in the crates of bench_rebake.py) inflate at a fraction of a stored
read's speed and are the bulk of a rebake's read, for a few MB saved."""


def _deflates(column: Column) -> bool:
    """Whether ``column``'s bytes deflate by ``MIN_RATIO`` or more, judged by their first
    ``zipwriter.BLOCK_BYTES`` (by its bytes alone, through ``zipwriter.deflate``, so the same
    state gives the same file)."""
    size = min(int(np.prod(column.shape, dtype=np.int64)) * column.dtype.itemsize, BLOCK_BYTES)
    if not size:
        return False
    if column.array is not None:
        sample = np.ascontiguousarray(column.array).reshape(-1).view(np.uint8)[:size]
    else:
        sample = np.fromfile(column.path, np.uint8, count=size)
    return len(deflate(sample)) * MIN_RATIO <= size


def _member(archive: ZipWriter, name: str, data: bytes | Column) -> None:
    """Add one member: bytes as they are, stored; an array (``spill.Column``, in memory or
    spilled to disk) as ``.npy``, deflated if it deflates well (``_deflates``) else stored,
    streamed into the archive (no copy of its bytes in memory)."""
    if isinstance(data, bytes):
        archive.add(name, lambda member: member.write(data), len(data), deflate=False)
        return
    nbytes = int(np.prod(data.shape)) * data.dtype.itemsize
    archive.add(name, data.write_npy, nbytes + _NPY_HEAD, deflate=_deflates(data))


# The per-instance arrays of the atlas, each as an empty array of its dtype and row shape.
_UNWRAP = {"vertices": np.zeros(0, np.int64), "triangles": np.zeros((0, 3), np.int64),
           "uv": np.zeros((0, 2)), "pages": np.zeros(0, np.int64)}


def _atlas_group(atlas: Atlas) -> tuple[dict, dict[str, np.ndarray]]:
    """The atlas as scalars plus arrays: each ``InstanceUV`` array of every instance joined
    into one (a level of a thousand objects would otherwise make four thousand members), and
    each instance's vertex and triangle counts to split them again (``_atlas_of``)."""
    scalars = {"width": atlas.width, "height": atlas.height, "page_count": atlas.page_count,
               "texel_density": atlas.texel_density, "padding": atlas.padding,
               "instances": [u.instance for u in atlas.instances]}
    units = atlas.instances
    arrays = {name: np.concatenate([empty] + [getattr(u, name) for u in units])
              for name, empty in _UNWRAP.items()}
    arrays["vertex_counts"] = np.array([len(u.vertices) for u in units], np.int64)
    arrays["triangle_counts"] = np.array([len(u.triangles) for u in units], np.int64)
    return scalars, arrays


def _atlas_of(scalars: dict, array) -> Atlas:
    """The atlas ``_atlas_group`` stored: ``array(name)`` reads ``atlas/<name>``. Counts that do
    not split the arrays into one part per instance are a ValueError."""
    counts = {"vertices": array("atlas/vertex_counts"), "triangles": array("atlas/triangle_counts")}
    counts["uv"], counts["pages"] = counts["vertices"], counts["triangles"]
    split = {}
    for name in _UNWRAP:
        values, each = array(f"atlas/{name}"), counts[name]
        if (each.ndim != 1 or len(each) != len(scalars["instances"]) or (each < 0).any()
                or int(each.sum()) != len(values)):
            raise ValueError(f"atlas/{name}: counts do not split it by instance")
        split[name] = np.split(values, np.cumsum(each)[:-1])
    return Atlas(width=scalars["width"], height=scalars["height"],
                 page_count=scalars["page_count"], texel_density=scalars["texel_density"],
                 padding=scalars["padding"],
                 instances=tuple(InstanceUV(instance=i, **{n: split[n][k] for n in _UNWRAP})
                                 for k, i in enumerate(scalars["instances"])))


def write_state(file: BinaryIO, state: BakeState) -> None:
    """Write the state's file to ``file`` (deterministic: the same state, the same bytes).

    Each array is stored by its ``spill.Column.encoding``: one whose bytes are all zero (a sky
    term in a scene without sky, chain counts without mirrors) not at all, ``header.json``
    listing it under ``zeros``; one whose rows are all the same (the ray counts without
    adaptive sampling) as its first row, listed under ``repeated``; one whose rows are mostly
    zero (how far the validity probes moved a point) as those rows and their indices
    (``<name>.rows.npy``), listed under ``sparse``. Each list gives shape and dtype.
    """
    groups: dict[str, dict] = {}
    atlas_scalars, atlas_arrays = _atlas_group(state.atlas)
    groups["atlas"] = {"class": "Atlas", "scalars": atlas_scalars, "fields": sorted(atlas_arrays)}
    arrays = {f"atlas/{k}": Column.of(v) for k, v in atlas_arrays.items()}
    arrays["instance_world"] = Column.of(np.asarray(state.instance_world, np.float64))
    for group, obj in sorted(state.groups.items()):
        if obj is None:
            continue
        if not isinstance(obj, Group):  # a dataclass in memory
            assert is_dataclass(obj), group
            obj = Group.of(obj)
        arrays.update({f"{group}/{name}": column for name, column in obj.columns.items()})
        groups[group] = {"class": obj.cls.__name__, "fields": list(obj.columns),
                         "scalars": obj.scalars}
    listed: dict[str, dict] = {"zeros": {}, "repeated": {}, "sparse": {}}
    members: dict[str, Column] = {}
    for name, column in arrays.items():
        encoding = column.encoding
        if encoding != "dense":
            listed[encoding][name] = {"shape": list(column.shape), "dtype": column.dtype.str}
        if encoding == "repeated":
            members[name] = Column.of(column.first)
        elif encoding == "sparse":
            members[f"{name}.rows"], members[name] = map(Column.of, column.sparse_rows())
        elif encoding == "dense":
            members[name] = column
    header = {"format": FORMAT, "version": VERSION, "fingerprints": state.fingerprints,
              "groups": groups, **listed}
    with ZipWriter(file) as archive:
        _member(archive, "header.json", json.dumps(header, sort_keys=True, indent=1).encode())
        for name in sorted(members):
            _member(archive, f"{name}.npy", members[name])


_LOCAL_HEADER = struct.Struct("<4s22xHH")  # a member's local header: signature, name, extra


MAX_ARRAY_ELEMENTS = 16 * MAX_TEXELS
"""Most elements of one array of a state (an (N, 16) array of ``settings.MAX_TEXELS`` texels):
an array declared larger is refused before anything is allocated for it."""
MAX_HEADER_BYTES = 256 << 20
"""Largest ``header.json`` read (the fingerprints of every instance: 3 MB for 10,000)."""
_DTYPES = frozenset({"|b1", "|i1", "|u1", "<i8", "<u8", "<f8"})  # those write_state writes


def _check_declared(name: str, shape: Any, dtype: Any) -> None:
    """Refuse, before allocating, an array declared (in its .npy header or the state's header)
    with a dtype ``write_state`` never writes or more than ``MAX_ARRAY_ELEMENTS`` elements."""
    if not isinstance(shape, (tuple, list)) or not all(
            isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in shape):
        raise ValueError(f"{name}: shape {shape!r}")
    if np.dtype(dtype).str not in _DTYPES:
        raise ValueError(f"{name}: dtype {np.dtype(dtype).str}")
    elements = 1
    for n in shape:
        elements *= n
    if elements > MAX_ARRAY_ELEMENTS:
        raise ValueError(f"{name}: {elements:,} elements, more than a bake holds")


_INFLATE_BYTES = 1 << 22  # deflated bytes read, inflated bytes made, at once


class _Contents:
    """The contents of one member of a state, read from ``file`` where they start: as they are
    (stored) or inflated (deflated), never more than the central directory declares
    (``info.file_size``; a deflate bomb is refused, not inflated), with their CRC-32 (ISA-L's).
    ``_INFLATE_BYTES`` at most are held in memory beside the array they fill."""

    def __init__(self, file: BinaryIO, info: zipfile.ZipInfo, start: int):
        self._file, self._declared, self._left = file, info.file_size, info.file_size
        self._deflated = info.compress_type == DEFLATED
        self._unread = info.compress_size  # bytes of the member's data not yet read
        self._inflate = isal_zlib.decompressobj(-15)
        self._tail = b""  # read, not yet inflated
        self.crc = 0
        file.seek(start)

    def readinto(self, view: memoryview) -> None:
        """Fill ``view`` with the next ``len(view)`` bytes; EOFError if the member ends first."""
        if len(view) > self._left:
            raise EOFError(f"{len(view)} bytes wanted of a member of {self._declared}")
        filled = 0
        while filled < len(view):
            if self._deflated:
                chunk = self._inflated(min(len(view) - filled, _INFLATE_BYTES))
                view[filled:filled + len(chunk)] = chunk
                count = len(chunk)
            else:
                count = self._file.readinto(view[filled:]) or 0
            if count == 0:
                raise EOFError("the member is cut short")
            self.crc = isal_zlib.crc32(view[filled:filled + count], self.crc)
            filled += count
        self._left -= filled

    def end(self, name: str) -> None:
        """Check that the member holds nothing more than was read: its deflate stream ends."""
        if self._deflated and (self._inflated(1) or not self._inflate.eof):
            raise ValueError(f"{name}: more bytes than its directory entry declares")

    def _inflated(self, most: int) -> bytes:
        """Up to ``most`` more inflated bytes (b"" at the end of the stream or the data). ISA-L
        may take in all the input and hold output back: it comes with the next calls."""
        while True:
            if not self._tail and self._unread:
                self._tail = self._file.read(min(self._unread, _INFLATE_BYTES))
                self._unread = self._unread - len(self._tail) if self._tail else 0
            chunk = self._inflate.decompress(self._tail, most)
            self._tail = self._inflate.unconsumed_tail
            if chunk or self._inflate.eof or not (self._tail or self._unread):
                return chunk


def _read_member(archive: zipfile.ZipFile, file: BinaryIO, name: str) -> np.ndarray:
    """The array of the member ``<name>.npy`` of ``archive`` (whose bytes ``file`` reads),
    deflated or stored, read once into its own memory, its CRC-32 checked. ``zipfile`` finds the
    member; its bytes are read (and inflated) straight from the file by ISA-L (``isal_zlib``:
    CRC-32 at 12 GB/s, zlib's 1.3 GB/s; inflate at about 3 times zlib's speed). The array's
    declared shape and dtype are checked before it is allocated, and must fill the size the
    directory declares, which bounds what is inflated."""
    info = archive.getinfo(f"{name}.npy")
    if info.compress_type not in (STORED, DEFLATED):
        raise ValueError(f"{name}.npy: compression method {info.compress_type}")
    file.seek(info.header_offset)
    signature, name_length, extra_length = _LOCAL_HEADER.unpack(file.read(_LOCAL_HEADER.size))
    if signature != b"PK\x03\x04":
        raise ValueError(f"{name}.npy: no local header")
    contents = _Contents(file, info, info.header_offset + _LOCAL_HEADER.size + name_length
                         + extra_length)
    head = bytearray(min(info.file_size, _NPY_HEAD))
    contents.readinto(memoryview(head))
    parse = io.BytesIO(head)
    version = np.lib.format.read_magic(parse)
    if version not in ((1, 0), (2, 0)):
        raise ValueError(f"{name}.npy: .npy version {version}")
    read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                   else np.lib.format.read_array_header_2_0)
    shape, fortran, dtype = read_header(parse)
    if fortran:
        raise ValueError(f"{name}.npy: not a plain C-order array")
    _check_declared(name, shape, dtype)
    offset = parse.tell()
    if offset + int(np.prod(shape, dtype=np.int64)) * dtype.itemsize != info.file_size:
        raise EOFError(f"{name}.npy does not hold its array")
    out = np.empty(shape, dtype)
    data = memoryview(out.reshape(-1).view(np.uint8))
    begun = len(head) - offset  # the array's first bytes, read with its header
    data[:begun] = head[offset:]
    contents.readinto(data[begun:])
    contents.end(f"{name}.npy")
    if contents.crc != info.CRC:
        raise zipfile.BadZipFile(f"{name}.npy: bad CRC-32")
    return out


def load(path: str | Path, classes: dict[str, type]) -> BakeState:
    """Read a state written by ``write_state``; ``classes`` maps group name → the dataclass to rebuild.

    Raises StateUnusable (one-line reason) for a missing, truncated, foreign or other-version
    file, or one whose groups or fields differ from the dataclasses' (written by older code).
    """
    path = Path(path)
    try:
        with _open_regular(path) as raw, zipfile.ZipFile(raw) as archive:
            try:
                info = archive.getinfo("header.json")
            except KeyError:
                raise StateUnusable(f"{path} is not a baker bake state (no header)") from None
            if info.compress_type != zipfile.ZIP_STORED or info.file_size > MAX_HEADER_BYTES:
                raise StateUnusable(f"{path} is not a bake state this baker wrote (its header "
                                    f"is compressed or {info.file_size:,} bytes)")
            header = json.loads(archive.read("header.json"))
            if not isinstance(header, dict) or header.get("format") != FORMAT:
                raise StateUnusable(f"{path} is not a baker bake state")
            if header.get("version") != VERSION:
                raise StateUnusable(f"{path} is a bake state of version {header.get('version')!r}, "
                                    f"this baker reads version {VERSION}")

            def array(name: str) -> np.ndarray:
                listed = next((header[k][name] for k in ("zeros", "repeated", "sparse")
                               if name in header[k]), None)
                if listed is None:
                    return _read_member(archive, raw, name)
                _check_declared(name, listed["shape"], listed["dtype"])
                out = np.zeros(listed["shape"], np.dtype(listed["dtype"]))
                if name in header["repeated"]:
                    out[:] = _read_member(archive, raw, name)
                elif name in header["sparse"]:
                    rows = _read_member(archive, raw, f"{name}.rows")
                    out[rows] = _read_member(archive, raw, name)
                return out

            groups = header["groups"]
            atlas = _atlas_of(groups["atlas"]["scalars"], array)
            objects: dict[str, Any] = {}
            for group, cls in classes.items():
                if group not in groups:
                    objects[group] = None
                    continue
                stored = groups[group]
                names = {f.name for f in fields(cls)}
                if stored["class"] != cls.__name__ or set(stored["fields"]) | set(stored["scalars"]) != names:
                    raise StateUnusable(f"{path} was written by another baker version "
                                        f"({group} fields differ)")
                values = dict(stored["scalars"])
                values.update({n: array(f"{group}/{n}") for n in stored["fields"]})
                objects[group] = cls(**values)
            return BakeState(fingerprints=header["fingerprints"], atlas=atlas, groups=objects,
                             instance_world=array("instance_world"))
    except StateUnusable:
        raise
    except FileNotFoundError:
        raise StateUnusable(f"no bake state at {path}") from None
    except Exception as error:  # whatever a damaged or edited file provokes in reading it
        raise StateUnusable(f"{path} is damaged or truncated ({type(error).__name__})") from None


def _open_regular(path: Path) -> BinaryIO:
    """``path`` opened for reading if it is a regular file: a FIFO (which would wait for a
    writer for ever), a device (``/dev/zero``: endless bytes), a folder or a symbolic link (to
    anything: the state beside a scene is as untrusted as the scene, and a bake never replaces
    a link: ``run.atomic.destination``) is ``StateUnusable`` before a byte is read."""
    try:
        descriptor = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOFOLLOW
                             | getattr(os, "O_BINARY", 0))
    except OSError as error:
        if error.errno in (errno.ELOOP, errno.EMLINK):
            raise StateUnusable(f"{path} is a symbolic link: not a bake state") from None
        raise
    mode = os.fstat(descriptor).st_mode
    if not stat.S_ISREG(mode):
        os.close(descriptor)
        raise StateUnusable(f"{path} is not a regular file: not a bake state")
    return os.fdopen(descriptor, "rb")
