"""A ZIP archive written in one pass, its members deflated or stored: the bake state's container.

Python's ``zipfile`` writes the same layout, but checksums every member with zlib's CRC-32 (1.3
GB/s) and deflates at zlib's default level (about 40 MB/s) while holding up the bake beside it;
here ISA-L's (``isal_zlib``) CRC-32 runs at 12 GB/s and zlib-ng (``zlib_ng``) deflates at level
2: about 170 MB/s and 2.56× smaller on the 200 boxes' state at 4 rays (44 MB of arrays), where
zlib's level 1, used before, made 100 MB/s and 2.46× (its 0.61 s were most of the 0.67 s the
state's writing took, which the bake spent waiting for) and zlib-ng's level 1 300 MB/s but
2.17×. ISA-L's own deflate, faster still, is not used: its output is no pure function of its
input (its hash table starts from memory it does not clear: the same 24 bytes deflated to 14,
15 or 16 bytes from one process to the next, and 1 process in 40 gave other bytes for 301
short arrays through the streaming compressor, 3 in 60 through the one-shot one;
tests/test_zipwriter.py). zlib-ng's gave the same bytes in every process tried, the heap
dirtied first; like zlib's, they may differ on another CPU architecture or release (no deflate
promises more), and nothing compares states across machines.

The bytes depend on the members alone — names, contents and order, every member dated
1980-01-01 00:00:00, permissions 0644, and a deflated member's contents fed to the compressor
in blocks of ``BLOCK_BYTES`` whatever pieces the writer hands over — so the same state gives
the same file (docs/design.md §4). Members or offsets past 2 GiB get the ZIP64 extensions, as
``zipfile`` gives them; ``zipfile`` (and ``numpy.load``) read the archives back.

    with ZipWriter(file) as archive:   # file: open for writing, seekable
        archive.add("header.json", lambda member: member.write(text), len(text), deflate=False)
"""

from __future__ import annotations

import struct
from typing import BinaryIO, Callable

from isal import isal_zlib
from zlib_ng import zlib_ng

ZIP64_LIMIT = (1 << 31) - 1  # sizes and offsets past this get ZIP64 fields (as ``zipfile``)
LEVEL = 2  # zlib-ng's deflate level
BLOCK_BYTES = 1 << 20  # a deflated member's contents are compressed this many bytes at a time
STORED, DEFLATED = 0, 8  # the ZIP compression methods
_DOS_DATE, _DOS_TIME = (0 << 9) | (1 << 5) | 1, 0  # 1980-01-01 00:00:00
_PERMISSIONS = 0o644 << 16  # external attributes: a regular file, rw-r--r-- (Unix)
_MADE_BY = 3 << 8  # Unix
_LOCAL = struct.Struct("<IHHHHHIIIHH")
_CENTRAL = struct.Struct("<IHHHHHHIIIHHHHHII")
_END = struct.Struct("<IHHHHIIH")
_END64 = struct.Struct("<IQHHIIQQQQ")
_LOCATOR64 = struct.Struct("<IIQI")
_EXTRA64 = struct.Struct("<HH")
_SAT32, _SAT16 = 0xFFFFFFFF, 0xFFFF


def deflated_most(size: int) -> int:
    """More bytes than zlib's raw deflate makes of ``size`` bytes (its ``deflateBound``: size +
    size/4096 + size/16384 + size/2^25 + 7)."""
    return size + size // 2048 + 64


def deflate(data) -> bytes:
    """``data`` deflated (raw deflate, ``LEVEL``) as a member's contents are."""
    squeeze = _compressor()
    return squeeze.compress(data) + squeeze.flush()


def _compressor():
    """A raw deflate stream at ``LEVEL`` (zlib-ng: the same bytes in every process)."""
    return zlib_ng.compressobj(LEVEL, zlib_ng.DEFLATED, -15)


class _Member:
    """What a member's contents are written to: counts its bytes and their CRC-32, and
    deflates them (``deflate``) a ``BLOCK_BYTES`` block at a time, or writes them as they are."""

    def __init__(self, file: BinaryIO, deflate: bool):
        self._file, self.size, self.crc, self.written = file, 0, 0, 0
        self._squeeze = _compressor() if deflate else None
        self._pending = bytearray()  # the start of the next block (less than BLOCK_BYTES)

    def write(self, data) -> int:
        view = memoryview(data).cast("B")
        self.crc = isal_zlib.crc32(view, self.crc)
        self.size += len(view)
        if self._squeeze is None:
            self._put(view)
            return len(view)
        start = 0
        if self._pending:
            start = min(len(view), BLOCK_BYTES - len(self._pending))
            self._pending += view[:start]
            if len(self._pending) < BLOCK_BYTES:
                return len(view)
            self._put(self._squeeze.compress(self._pending))
            self._pending = bytearray()
        whole = start + (len(view) - start) // BLOCK_BYTES * BLOCK_BYTES
        for at in range(start, whole, BLOCK_BYTES):
            self._put(self._squeeze.compress(view[at:at + BLOCK_BYTES]))
        self._pending += view[whole:]
        return len(view)

    def finish(self) -> None:
        """Compress what is left and end the deflate stream."""
        if self._squeeze is not None:
            self._put(self._squeeze.compress(self._pending) + self._squeeze.flush())
            self._pending = bytearray()

    def _put(self, data) -> None:
        self.written += len(data)
        self._file.write(data)


def _local(name: bytes, method: int, crc: int, size: int, written: int, big: bool) -> bytes:
    """A member's local header; ``big``: its sizes in a ZIP64 extra field."""
    extra = _EXTRA64.pack(1, 16) + struct.pack("<QQ", size, written) if big else b""
    return _LOCAL.pack(0x04034B50, 45 if big else 20, 0, method, _DOS_TIME, _DOS_DATE, crc,
                       _SAT32 if big else written, _SAT32 if big else size, len(name),
                       len(extra)) + name + extra


class ZipWriter:
    """Writes members to ``file`` one after the other (``add``), then the central directory
    (``close``, or leaving the ``with`` block without an error)."""

    def __init__(self, file: BinaryIO):
        self._file = file
        self._start = file.tell()
        # name, method, crc, size, bytes written, offset, ZIP64 local header
        self._entries: list[tuple[bytes, int, int, int, int, int, bool]] = []

    def __enter__(self) -> "ZipWriter":
        return self

    def __exit__(self, kind, *_) -> None:
        if kind is None:
            self.close()

    def add(self, name: str, write: Callable[[_Member], None], most: int,
            deflate: bool = True) -> None:
        """A member ``name`` whose contents ``write(member)`` writes (``member.write``),
        deflated unless ``deflate`` is false; at most ``most`` bytes, which decides whether it
        needs ZIP64 sizes. The local header is written first and its CRC and sizes filled in
        once the contents are (a seek back)."""
        encoded = name.encode("ascii")
        header = self._file.tell()
        method = DEFLATED if deflate else STORED
        big = (deflated_most(most) if deflate else most) > ZIP64_LIMIT
        self._file.write(_local(encoded, method, 0, 0, 0, big))
        member = _Member(self._file, deflate)
        write(member)
        member.finish()
        if member.size > most:
            raise ValueError(f"{name}: {member.size} bytes, more than the {most} announced")
        if not big and member.written > ZIP64_LIMIT:
            raise ValueError(f"{name}: deflated to {member.written} bytes, past ZIP64_LIMIT")
        end = self._file.tell()
        self._file.seek(header)
        self._file.write(_local(encoded, method, member.crc, member.size, member.written, big))
        self._file.seek(end)
        self._entries.append((encoded, method, member.crc, member.size, member.written,
                              header - self._start, big))

    def close(self) -> None:
        """Write the central directory and its end records (ZIP64 ones when needed)."""
        directory = self._file.tell() - self._start
        for name, method, crc, size, written, offset, big in self._entries:
            wide_size, wide_offset = big, offset > ZIP64_LIMIT  # not big: both sizes fit
            fields = ([size, written] if wide_size else []) + ([offset] if wide_offset else [])
            extra = (_EXTRA64.pack(1, 8 * len(fields)) + struct.pack(f"<{len(fields)}Q", *fields)
                     if fields else b"")
            version = 45 if extra else 20
            self._file.write(_CENTRAL.pack(
                0x02014B50, _MADE_BY | version, version, 0, method, _DOS_TIME, _DOS_DATE, crc,
                _SAT32 if wide_size else written, _SAT32 if wide_size else size, len(name),
                len(extra), 0, 0, 0, _PERMISSIONS, _SAT32 if wide_offset else offset)
                + name + extra)
        end = self._file.tell() - self._start
        count, length = len(self._entries), end - directory
        if count >= _SAT16 or directory > ZIP64_LIMIT or length > ZIP64_LIMIT:
            self._file.write(_END64.pack(0x06064B50, 44, _MADE_BY | 45, 45, 0, 0, count, count,
                                         length, directory))
            self._file.write(_LOCATOR64.pack(0x07064B50, 0, end, 1))
            self._file.write(_END.pack(0x06054B50, 0, 0, _SAT16, _SAT16, _SAT32, _SAT32, 0))
        else:
            self._file.write(_END.pack(0x06054B50, 0, 0, count, count, length, directory, 0))
