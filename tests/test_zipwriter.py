"""The bake state's container (``zipwriter.py``): a ZIP of deflated or stored members that
Python's ``zipfile`` and ``numpy.load`` read back, the same bytes for the same members however
their contents are handed over, ZIP64 past 2 GiB; and the state's reader of its members
(``state._read_member``), which inflates no more than a member declares."""

from __future__ import annotations

import io
import struct
import zipfile

import numpy as np
import pytest

from baker.rebake import state
from baker.rebake import zipwriter as zipwriter
from baker.rebake.zipwriter import ZipWriter
from baker.run.spill import Column


def _archive(members: dict[str, np.ndarray | bytes], deflate: bool = True) -> bytes:
    file = io.BytesIO()
    with ZipWriter(file) as archive:
        for name, data in members.items():
            if isinstance(data, bytes):
                archive.add(name, lambda member, data=data: member.write(data), len(data),
                            deflate=False)
            else:
                archive.add(name, Column.of(data).write_npy, data.nbytes + 4096, deflate)
    return file.getvalue()


RNG = np.random.default_rng(7)
MEMBERS = {"header.json": b'{"format": "test"}', "a/w.npy": np.arange(30.0).reshape(10, 3),
           "a/key.npy": np.arange(7, dtype=np.uint64), "empty.npy": np.zeros((0, 3)),
           "noise.npy": RNG.random((3 * zipwriter.BLOCK_BYTES // 16 + 5, 2))}


@pytest.mark.parametrize("deflate", [True, False], ids=["deflated", "stored"])
@pytest.mark.parametrize("zip64", [False, True], ids=["zip", "zip64"])
def test_zipfile_and_numpy_read_the_members_back(monkeypatch, zip64, deflate):
    """Every member comes back with its bytes and a CRC that ``zipfile`` checks; with ZIP64
    (forced here by a limit of 16 bytes) too; and ``state._read_member`` reads every array."""
    if zip64:
        monkeypatch.setattr(zipwriter, "ZIP64_LIMIT", 16)
    data = _archive(MEMBERS, deflate)
    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        assert archive.testzip() is None  # every CRC checks
        assert archive.namelist() == list(MEMBERS)
        assert archive.read("header.json") == MEMBERS["header.json"]
        assert archive.getinfo("header.json").compress_type == zipfile.ZIP_STORED
        info = archive.getinfo("a/w.npy")
        assert info.date_time == (1980, 1, 1, 0, 0, 0) and info.compress_type == (
            zipfile.ZIP_DEFLATED if deflate else zipfile.ZIP_STORED)
        for name, value in MEMBERS.items():
            if name.endswith(".npy"):
                read = state._read_member(archive, io.BytesIO(data), name[:-4])
                assert np.array_equal(read, value) and read.dtype == value.dtype
    arrays = np.load(io.BytesIO(data))
    for name, value in MEMBERS.items():
        if name.endswith(".npy"):
            read = arrays[name[:-4]]
            assert np.array_equal(read, value) and read.dtype == value.dtype
    assert (b"PK\x06\x06" in data) == zip64  # the ZIP64 end record only when needed


def test_deflated_members_are_smaller_where_their_bytes_repeat():
    repetitive = {"r.npy": np.repeat(RNG.random(1000), 400)}
    assert len(_archive(repetitive)) * 10 < len(_archive(repetitive, deflate=False))


def test_the_same_members_give_the_same_bytes():
    assert _archive(MEMBERS) == _archive(dict(MEMBERS))
    other = dict(MEMBERS, **{"a/key.npy": np.arange(8, dtype=np.uint64)})
    assert _archive(MEMBERS) != _archive(other)


@pytest.mark.parametrize("seed", range(4))
def test_contents_handed_over_in_any_pieces_give_the_same_bytes(seed):
    """A member written in pieces cut at random (as a spilled column's file is copied, or an
    array in memory written) deflates to the same bytes as written whole."""
    rng = np.random.default_rng(seed)
    contents = np.round(rng.random(3 * zipwriter.BLOCK_BYTES // 8 + 11), 3).tobytes()
    cuts = np.sort(rng.integers(0, len(contents), rng.integers(1, 40)))

    def pieces(member):
        for start, end in zip(np.r_[0, cuts], np.r_[cuts, len(contents)]):
            member.write(contents[start:end])

    def whole(member):
        member.write(contents)

    written = []
    for write in (whole, pieces):
        file = io.BytesIO()
        with ZipWriter(file) as archive:
            archive.add("x", write, len(contents))
        written.append(file.getvalue())
    assert written[0] == written[1]
    with zipfile.ZipFile(io.BytesIO(written[0])) as archive:
        assert archive.read("x") == contents


def test_a_member_longer_than_announced_is_refused():
    with pytest.raises(ValueError, match="more than"):
        ZipWriter(io.BytesIO()).add("x", lambda member: member.write(b"12345"), 4)


def _declaring(data: bytes, size: int) -> bytes:
    """The one-member archive ``data`` with the member's uncompressed size (local header and
    central directory) changed to ``size``: what it declares no longer what it holds."""
    data = bytearray(data)
    for signature, at in ((b"PK\x03\x04", 22), (b"PK\x01\x02", 24)):
        start = data.index(signature)
        struct.pack_into("<I", data, start + at, size)
    return bytes(data)


def test_a_deflated_member_is_inflated_no_further_than_it_declares():
    """A deflated ``.npy`` whose stream goes on past the size its directory entry declares (here
    an array of 10 values followed by 64 MiB of zeros, a deflate bomb in small) is refused
    once the declared bytes are in: what is made of it is bounded by that size (the array
    allocated from its header, checked against it)."""
    head = io.BytesIO()
    np.save(head, np.arange(10.0))
    npy = head.getvalue()
    file = io.BytesIO()
    with ZipWriter(file) as archive:
        archive.add("x.npy", lambda member: member.write(npy + bytes(64 << 20)), 65 << 20)
    bomb = _declaring(file.getvalue(), len(npy))
    with zipfile.ZipFile(io.BytesIO(bomb)) as archive:
        assert archive.getinfo("x.npy").file_size == len(npy)
        with pytest.raises(ValueError, match="more bytes than its directory entry declares"):
            state._read_member(archive, io.BytesIO(bomb), "x")


def test_a_member_declaring_another_size_than_its_array_is_not_read():
    """The directory declares 4 GiB for an array of 10 values: refused from the array's
    header, before anything but that header is inflated or allocated."""
    file = io.BytesIO()
    with ZipWriter(file) as archive:
        archive.add("x.npy", Column.of(np.arange(10.0)).write_npy, 4096)
    huge = _declaring(file.getvalue(), 0xFFFF_FFF0)
    with zipfile.ZipFile(io.BytesIO(huge)) as archive:
        with pytest.raises(EOFError, match="cut short|does not hold its array"):
            state._read_member(archive, io.BytesIO(huge), "x")


def test_the_state_stores_arrays_that_hardly_deflate_and_reads_both_back():
    """``state._member`` deflates an array whose bytes repeat (runs of keys) and stores one of
    noise (uniform float64: about 1.1× deflated, under ``state.MIN_RATIO``); both read back
    with their exact bits, dtype and shape."""
    arrays = {"noise": RNG.random((200_000, 3)),
              "runs": np.repeat(np.arange(2_000, dtype=np.int64), 300)}
    file = io.BytesIO()
    with ZipWriter(file) as archive:
        for name, data in arrays.items():
            state._member(archive, f"{name}.npy", Column.of(data))
    with zipfile.ZipFile(file) as archive:
        assert archive.getinfo("noise.npy").compress_type == zipfile.ZIP_STORED
        assert archive.getinfo("runs.npy").compress_type == zipfile.ZIP_DEFLATED
        for name, data in arrays.items():
            back = state._read_member(archive, file, name)
            assert back.dtype == data.dtype and back.shape == data.shape
            assert back.tobytes() == data.tobytes()


_DEFLATE_DIGEST = """
import hashlib, numpy as np
from baker.rebake import zipwriter
rng = np.random.default_rng(22)
junk = [rng.integers(0, 256, int(n)).astype(np.uint8).tobytes()  # the heap dirtied first
        for n in rng.integers(1000, 3_000_000, 8)]
del junk
inputs = [np.array([3818, 3200, 3818]).tobytes()] + [  # the counts that first varied
    rng.integers(0, 1 << int(rng.integers(4, 16)), int(rng.integers(1, 40))).tobytes()
    for _ in range(300)] + [  # whole blocks of a noisy mean and of keys, as a state's
    np.round(rng.random(zipwriter.BLOCK_BYTES // 8), 2).tobytes(),
    np.repeat(rng.integers(0, 1 << 40, 4096), 32).tobytes()]
from baker.image.encode import png_bytes
pages = [rng.integers(0, 256, (h, w, 3)).astype(np.uint8) // k
         for h, w, k in ((8, 8, 1), (49, 49, 16), (70, 130, 64))]
print(hashlib.sha256(b"".join([zipwriter.deflate(b) for b in inputs]
                              + [png_bytes(page) for page in pages])).hexdigest())
"""


def test_small_arrays_deflate_to_the_same_bytes_in_every_process():
    """``zipwriter.deflate`` (what ``state._deflates`` judges a member by, and how members are
    deflated) and ``encode.png_bytes`` (the pages in the output) give the same bytes for the
    same inputs in fresh processes. ISA-L's one-shot
    compressor did not: a 24-byte array of three counts deflated to 14, 15 or 16 bytes from
    one process to the next (in 2 of 40), and a bake in parts stored a member that the bake
    at once deflated. 301 short arrays of small integers and two whole blocks (zlib-ng's
    deflate, since it replaced zlib's), in 16 processes."""
    import subprocess
    import sys
    digests = {subprocess.run([sys.executable, "-c", _DEFLATE_DIGEST], capture_output=True,
                              text=True, check=True).stdout for _ in range(16)}
    assert len(digests) == 1
