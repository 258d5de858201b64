"""A ZIP archive of stored (uncompressed) members, written in one pass: the bake state's container.

Python's ``zipfile`` writes the same layout, but checksums every member with zlib's CRC-32
(1.3 GB/s here) while holding up the bake beside it; ISA-L's (``isal_zlib``, 12 GB/s) gives the
same numbers. The bytes depend on the members alone — names, contents and order, every member
dated 1980-01-01 00:00:00, permissions 0644 — so the same state gives the same file
(docs/design.md §4). Members or offsets past 2 GiB get the ZIP64 extensions, as ``zipfile`` gives
them; ``zipfile`` (and ``numpy.load``) read the archives back.

    with StoredZip(file) as archive:   # file: open for writing, seekable
        archive.add("header.json", lambda member: member.write(text))
"""

from __future__ import annotations

import struct
from typing import BinaryIO, Callable

from isal import isal_zlib

ZIP64_LIMIT = (1 << 31) - 1  # sizes and offsets past this get ZIP64 fields (as ``zipfile``)
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


class _Member:
    """What a member's contents are written to: counts its bytes and their CRC-32."""

    def __init__(self, file: BinaryIO):
        self._file, self.size, self.crc = file, 0, 0

    def write(self, data) -> int:
        view = memoryview(data).cast("B")
        self.crc = isal_zlib.crc32(view, self.crc)
        self.size += len(view)
        return self._file.write(view)


def _local(name: bytes, crc: int, size: int, big: bool) -> bytes:
    """A member's local header; ``big``: its sizes in a ZIP64 extra field."""
    extra = _EXTRA64.pack(1, 16) + struct.pack("<QQ", size, size) if big else b""
    sized = _SAT32 if big else size
    return _LOCAL.pack(0x04034B50, 45 if big else 20, 0, 0, _DOS_TIME, _DOS_DATE, crc, sized,
                       sized, len(name), len(extra)) + name + extra


class StoredZip:
    """Writes stored members to ``file`` one after the other (``add``), then the central
    directory (``close``, or leaving the ``with`` block without an error)."""

    def __init__(self, file: BinaryIO):
        self._file = file
        self._start = file.tell()
        self._entries: list[tuple[bytes, int, int, int, bool]] = []  # name, crc, size, offset, 64

    def __enter__(self) -> "StoredZip":
        return self

    def __exit__(self, kind, *_) -> None:
        if kind is None:
            self.close()

    def add(self, name: str, write: Callable[[_Member], None], most: int) -> None:
        """A member ``name`` whose contents ``write(member)`` writes (``member.write``); at
        most ``most`` bytes, which decides whether it needs ZIP64 sizes. The local header is
        written first and its CRC and sizes filled in once the contents are (a seek back)."""
        encoded = name.encode("ascii")
        header = self._file.tell()
        big = most > ZIP64_LIMIT
        self._file.write(_local(encoded, 0, 0, big))
        member = _Member(self._file)
        write(member)
        if member.size > most:
            raise ValueError(f"{name}: {member.size} bytes, more than the {most} announced")
        end = self._file.tell()
        self._file.seek(header)
        self._file.write(_local(encoded, member.crc, member.size, big))
        self._file.seek(end)
        self._entries.append((encoded, member.crc, member.size, header - self._start, big))

    def close(self) -> None:
        """Write the central directory and its end records (ZIP64 ones when needed)."""
        directory = self._file.tell() - self._start
        for name, crc, size, offset, big in self._entries:
            wide_size, wide_offset = big or size > ZIP64_LIMIT, offset > ZIP64_LIMIT
            fields = ([size, size] if wide_size else []) + ([offset] if wide_offset else [])
            extra = (_EXTRA64.pack(1, 8 * len(fields)) + struct.pack(f"<{len(fields)}Q", *fields)
                     if fields else b"")
            version = 45 if extra else 20
            self._file.write(_CENTRAL.pack(
                0x02014B50, _MADE_BY | version, version, 0, 0, _DOS_TIME, _DOS_DATE, crc,
                _SAT32 if wide_size else size, _SAT32 if wide_size else size, len(name),
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
