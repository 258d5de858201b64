"""Every buffer of a document as bytes (``resolve_buffers``): the GLB's binary chunk, a data URI,
or a file beside the ``.gltf`` opened inside its folder; their declared sizes checked against the
input's budget first (``check_buffer_budget``)."""

from __future__ import annotations

import base64
import binascii
import urllib.parse


from baker.errors import InputError
from baker.gltf import budget, objects
from baker.gltf.context import invalid, schema
from baker.gltf.decompress import draco_declared_bytes, is_meshopt_fallback
from baker.gltf.files import SceneFolder


def check_buffer_budget(document: objects.GLTF2, file: str, spent: budget.Budget) -> None:
    """Check every buffer's declared byteLength, before any is read, against the input's
    budget (``budget.check_buffers``): files, bytes embedded in the scene file, and the
    meshopt fallback buffers and Draco primitives that compressed geometry decodes into."""
    blob = document.binary_blob()
    lengths = []
    for i, buffer in enumerate(document.buffers or []):
        embedded = (buffer.uri is None and i == 0 and blob is not None) or (
            isinstance(buffer.uri, str) and buffer.uri.startswith("data:"))
        kind = ("embedded" if embedded else "file" if buffer.uri is not None
                else "decoded" if is_meshopt_fallback(buffer) else "embedded")
        lengths.append((f"buffers[{i}]", buffer.byteLength, kind))
    budget.check_buffers(lengths, draco_declared_bytes(document), spent)


def resolve_buffers(document: objects.GLTF2, folder: SceneFolder) -> list[bytes]:
    """The bytes of every ``document.buffers[i]``, exactly ``byteLength`` of them.

    A buffer without ``uri`` is the GLB binary chunk; a ``data:`` URI is decoded; any other URI is
    a file inside the scene's ``folder``, percent-decoded (``files.SceneFolder``).
    """
    blob = document.binary_blob()
    out = []
    for i, buffer in enumerate(document.buffers):
        where = f"buffers[{i}]"
        with schema(folder.file, where):
            out.append(_buffer_bytes(buffer, blob if i == 0 else None, folder, where))
    return out


def _buffer_bytes(buffer: objects.Buffer, blob: bytes | None, folder: SceneFolder,
                  where: str) -> bytes:
    """The ``byteLength`` bytes of one buffer: ``blob`` (GLB binary chunk) when it has no uri; of
    a file, at most ``byteLength`` bytes are read."""
    file = folder.file
    length = buffer.byteLength
    if not isinstance(length, int) or isinstance(length, bool) or length < 0:
        raise invalid(f"byteLength {length!r} is not a byte count", file, where)
    if buffer.uri is None:
        if blob is None and is_meshopt_fallback(buffer):
            return bytes(length)  # where decompress.decompressed puts the decoded views
        if blob is None:
            raise invalid("buffer has no uri and the file has no GLB binary chunk for it", file, where)
        data = blob
    elif isinstance(buffer.uri, str) and buffer.uri.startswith("data:"):
        data = decode_data_uri(buffer.uri, file, where)
    else:
        data = folder.read(buffer.uri, f"{where}.uri", length)
    if len(data) < length:
        raise InputError(
            f"buffer holds {len(data)} bytes but its byteLength is {length}",
            file=file,
            where=where,
            fix="the binary data is incomplete or from another export: export the asset again",
        )
    return data if len(data) == length else bytes(data[:length])


def decode_data_uri(uri: str, file: str, where: str) -> bytes:
    """Decode ``data:[<mime>][;base64],<payload>``."""
    header, comma, payload = uri[5:].partition(",")
    fix = "the embedded data is damaged: export the asset again"
    if not comma:
        raise InputError("bad data URI: no comma before the data", file=file, where=f"{where}.uri", fix=fix)
    if not header.endswith(";base64"):
        return urllib.parse.unquote_to_bytes(payload)
    try:
        return base64.b64decode(payload, validate=True)
    except (binascii.Error, ValueError) as exc:
        raise InputError(
            f"bad data URI: invalid base64 ({exc})",
            file=file,
            where=f"{where}.uri",
            fix=fix,
        ) from None
