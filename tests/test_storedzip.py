"""The bake state's container (``storedzip.py``): a ZIP of stored members that Python's
``zipfile`` and ``numpy.load`` read back, the same bytes for the same members, ZIP64 past 2 GiB."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest

from baker.rebake import storedzip as storedzip
from baker.run.spill import Column
from baker.rebake.storedzip import StoredZip


def _archive(members: dict[str, np.ndarray | bytes]) -> bytes:
    file = io.BytesIO()
    with StoredZip(file) as archive:
        for name, data in members.items():
            if isinstance(data, bytes):
                archive.add(name, lambda member, data=data: member.write(data), len(data))
            else:
                archive.add(name, Column.of(data).write_npy, data.nbytes + 4096)
    return file.getvalue()


MEMBERS = {"header.json": b'{"format": "test"}', "a/w.npy": np.arange(30.0).reshape(10, 3),
           "a/key.npy": np.arange(7, dtype=np.uint64), "empty.npy": np.zeros((0, 3))}


@pytest.mark.parametrize("zip64", [False, True], ids=["zip", "zip64"])
def test_zipfile_and_numpy_read_the_members_back(monkeypatch, zip64):
    """Every member comes back with its bytes and a CRC that ``zipfile`` checks; with ZIP64
    (forced here by a limit of 16 bytes) too."""
    if zip64:
        monkeypatch.setattr(storedzip, "ZIP64_LIMIT", 16)
    data = _archive(MEMBERS)
    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        assert archive.testzip() is None  # every CRC checks
        assert archive.namelist() == list(MEMBERS)
        assert archive.read("header.json") == MEMBERS["header.json"]
        info = archive.getinfo("a/w.npy")
        assert info.date_time == (1980, 1, 1, 0, 0, 0) and info.compress_type == zipfile.ZIP_STORED
    arrays = np.load(io.BytesIO(data))
    for name, value in MEMBERS.items():
        if name.endswith(".npy"):
            read = arrays[name[:-4]]
            assert np.array_equal(read, value) and read.dtype == value.dtype
    assert (b"PK\x06\x06" in data) == zip64  # the ZIP64 end record only when needed


def test_the_same_members_give_the_same_bytes():
    assert _archive(MEMBERS) == _archive(dict(MEMBERS))
    other = dict(MEMBERS, **{"a/key.npy": np.arange(8, dtype=np.uint64)})
    assert _archive(MEMBERS) != _archive(other)


def test_a_member_longer_than_announced_is_refused():
    with pytest.raises(ValueError, match="more than"):
        StoredZip(io.BytesIO()).add("x", lambda member: member.write(b"12345"), 4)
