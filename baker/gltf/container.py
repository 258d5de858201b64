"""The scene file read into a document of glTF objects (``read_document``): ``.gltf`` JSON or a
``.glb`` container, told apart by the magic bytes; its JSON parsed within bounds (depth, integer
digits), its asset version, top-level arrays, references and required extensions checked; and the
files it names, for ``baker watch`` (``used_uris``, ``file_stamps``)."""

from __future__ import annotations

import json
import math
import os
import re
import struct
import sys
from pathlib import Path
from typing import Any

from baker.errors import InputError
from baker.gltf import budget
from baker.gltf import document as gltf_document
from baker.gltf import objects
from baker.gltf.context import invalid
from baker.gltf.extensions import SUPPORTED_EXTENSIONS, unsupported_kind
from baker.gltf.files import SceneFolder
from baker.gltf.references import check_references


_GLB_MAGIC = b"glTF"


_CHUNK_JSON = 0x4E4F534A


_CHUNK_BIN = 0x004E4942


MAX_JSON_DEPTH = 64
"""Deepest nesting of arrays and objects in the glTF JSON (glTF's own is 5; extras may add)."""


MAX_INTEGER_DIGITS = 400
"""Longest integer in the glTF JSON: glTF's are below 2^53 (16 digits), but a float of the input
(1e300) written back as an integer index has up to 309; Python refuses 4,300, and converting
10^5 digits takes seconds."""


def read_document(path: str | Path, folder: SceneFolder | None = None, contained: bool = False,
                  spent: budget.Budget | None = None) -> objects.GLTF2:
    """Parse a ``.gltf`` or ``.glb`` file into a document (``objects``), checking what baker
    relies on.

    A GLB's binary chunk is kept as ``document.binary_blob()``; ``document._path`` is the
    file's folder and ``document._name`` its name. The file is read through
    ``folder`` (its folder, opened: ``files.SceneFolder.read_scene``; ``contained`` as there) and
    counted in ``spent`` (the input's budget), each made here when not given.
    """
    path = Path(path)
    file = str(path)
    spent = spent or budget.Budget(file)
    if folder is None:
        with SceneFolder(path.parent, file) as own:
            data = own.read_scene(path, contained, budget.MAX_INPUT_BYTES)
    else:
        data = folder.read_scene(path, contained, budget.MAX_INPUT_BYTES)
    spent.spend(len(data), "the scene file", "")
    if data[:4] == _GLB_MAGIC:
        text, blob = _split_glb(data, file)
    else:
        text, blob = _decode_text(data, file), None
    raw = _parse_json(text, file)
    _check_asset(raw, file)
    _check_arrays(raw, file)
    _check_primitives(raw, file)
    _check_buffer_views(raw, file)
    budget.check_nodes(raw, file)
    check_references(raw, file)
    _check_required_extensions(raw, file)
    try:
        document = gltf_document.document(raw)
    except gltf_document.WrongType as exc:
        raise invalid(exc.what, file, exc.where) from None
    if blob is not None:
        document.set_binary_blob(blob)
    document._path = path.parent
    document._name = path.name
    return document


def used_uris(path: str | Path) -> list[tuple[str, str]]:
    """(JSON path, URI) of every file the scene at ``path`` names (its buffers' and images'),
    none when it cannot be read or parsed. For ``baker watch`` (``file_stamps``)."""
    path = Path(path)
    try:
        with SceneFolder(path.parent, str(path)) as folder:
            data = folder.read_scene(path, False, budget.MAX_INPUT_BYTES)
        text = _split_glb(data, str(path))[0] if data[:4] == _GLB_MAGIC else _decode_text(data, "")
        raw = _parse_json(text, str(path))
    except InputError:
        return []
    out = []
    for kind in ("buffers", "images"):
        items = raw.get(kind)
        for i, item in enumerate(items if isinstance(items, list) else []):
            uri = item.get("uri") if isinstance(item, dict) else None
            if isinstance(uri, str) and not uri.startswith("data:"):
                out.append((f"{kind}[{i}].uri", uri))
    return out


def file_stamps(path: str | Path, uris: list[tuple[str, str]]) -> tuple:
    """(size, modification time) of the scene file at ``path`` and of each file of ``uris``
    (``used_uris``) as opened (``files.SceneFolder``), None for one that cannot be: what
    changes when any of them does, for ``baker watch``."""
    path = Path(path)
    try:
        folder = SceneFolder(path.parent, str(path))
    except InputError:
        return (None,)
    stamps = []
    with folder:
        for at, uri in [("", None)] + uris:
            try:
                descriptor = (folder.open(uri, at)[0] if uri is not None
                              else os.open(path, os.O_RDONLY | os.O_NONBLOCK))
            except (InputError, OSError):
                stamps.append(None)
                continue
            try:
                info = os.fstat(descriptor)
                stamps.append((info.st_size, info.st_mtime_ns))
            finally:
                os.close(descriptor)
    return tuple(stamps)


def _split_glb(data: bytes, file: str) -> tuple[str, bytes | None]:
    """Split a GLB container into its JSON text and its binary chunk (None when it has none)."""
    fix = "the file was cut short or is damaged: copy or export it again"
    if len(data) < 20:
        raise InputError(
            f"truncated GLB: {len(data)} bytes, too short for a header",
            file=file,
            where="GLB header",
            fix=fix,
        )
    version, length = struct.unpack_from("<II", data, 4)
    if version != 2:
        raise InputError(
            f"GLB container version {version}: baker reads version 2 (glTF 2.0)",
            file=file,
            where="GLB header",
            fix="convert the file to glTF 2.0, e.g. by re-exporting it",
        )
    if length > len(data):
        raise InputError(
            f"truncated GLB: the header says {length} bytes but the file has {len(data)}",
            file=file,
            where="GLB header",
            fix=fix,
        )
    text, blob, offset, chunk = None, None, 12, 0
    while offset < length:
        if offset + 8 > length:
            raise InputError(
                f"truncated GLB: chunk {chunk} has no complete header",
                file=file,
                where=f"GLB chunk {chunk}",
                fix=fix,
            )
        size, kind = struct.unpack_from("<II", data, offset)
        start, end = offset + 8, offset + 8 + size
        if end > length:
            raise InputError(
                f"truncated GLB: chunk {chunk} needs {size} bytes but only {length - start} remain",
                file=file,
                where=f"GLB chunk {chunk}",
                fix=fix,
            )
        if chunk == 0 and kind != _CHUNK_JSON:
            raise InputError("GLB's first chunk is not JSON", file=file, where="GLB chunk 0", fix=fix)
        if chunk == 0:  # padded with spaces, or by some exporters with NUL bytes
            text = _decode_text(data[start:end].rstrip(b"\0"), file)
        elif chunk == 1 and kind == _CHUNK_BIN:
            blob = data[start:end]
        offset, chunk = end, chunk + 1
    if text is None:
        raise InputError("GLB has no JSON chunk", file=file, where="GLB chunk 0", fix=fix)
    return text, blob


def _decode_text(data: bytes, file: str) -> str:
    """The glTF JSON as text (UTF-8, a byte-order mark tolerated)."""
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise InputError(
            "not a glTF file: neither a GLB container nor UTF-8 JSON text",
            file=file,
            fix="give baker a .gltf or .glb file",
        ) from None


_MAYBE_NOT_A_NUMBER = re.compile(r"NaN|Infinity|[eE][+-]?0*[1-9]\d\d")
"""Text that may parse as a float no float64 holds: NaN, Infinity, an exponent of three digits
(1e400). Where none is, floats are parsed on the fast path (C's); where one is (perhaps inside
a string), each is checked (``_NotANumber``)."""


class _NotANumber:
    """A number JSON has no value for, where the parser met it: ``NaN``, ``Infinity`` (which
    Python's parser takes and JSON does not) or a literal past float64's range (``1e400``, or
    an integer of 309 digits). Kept, the output's JSON could not be written (a NaN morph weight
    once ended a bake in an internal error there) or a float could not be made of it (a light's
    intensity); ``_parse_json`` refuses the file naming where it is."""

    def __init__(self, text: str):
        digits = len(text.lstrip("-"))
        self.text = text if digits <= 20 else f"{text[:8]}… (an integer of {digits:,} digits)"


def _float(text: str) -> float | _NotANumber:
    """``float(text)`` for the JSON parser, or ``_NotANumber`` where it is not finite."""
    value = float(text)
    return value if math.isfinite(value) else _NotANumber(text)


class _LongNumber(Exception):
    """An integer in the JSON with more digits than ``MAX_INTEGER_DIGITS``."""


def _bounded_int(text: str) -> int | _NotANumber:
    """``int(text)`` for the JSON parser, refusing integers of more than ``MAX_INTEGER_DIGITS``
    digits (converting 10^5 digits takes seconds; Python refuses 4300 with a ValueError), and
    ``_NotANumber`` for one past float64's range."""
    if len(text) > MAX_INTEGER_DIGITS + 1:
        raise _LongNumber(len(text.lstrip("-")))
    value = int(text)
    return value if abs(value) <= sys.float_info.max else _NotANumber(text)


class _Careful(Exception):
    """The fast path met an integer past float64's range: parse again, checking every number."""


def _fast_int(text: str) -> int:
    """``_bounded_int`` on the fast path: ``_Careful`` where it would give a ``_NotANumber``."""
    value = _bounded_int(text)
    if isinstance(value, _NotANumber):
        raise _Careful
    return value


def _loads(text: str, careful: bool) -> Any:
    """The parsed JSON: with ``careful``, each number no float64 holds as a ``_NotANumber``;
    without, floats parsed by C (the text holds no NaN, Infinity or large exponent)."""
    if careful:
        return json.loads(text, parse_int=_bounded_int, parse_float=_float,
                          parse_constant=_NotANumber)
    return json.loads(text, parse_int=_fast_int)


def _parse_json(text: str, file: str) -> dict:
    """The top-level JSON object; a syntax error names its line and column. Integers are at most
    ``MAX_INTEGER_DIGITS`` digits long, every number a finite float64 (``_NotANumber``), and
    arrays and objects nested at most ``MAX_JSON_DEPTH`` deep (extras nested 10^5 deep
    overflowed Python's stack, in the parser or after it)."""
    too_deep = InputError(f"the JSON is nested more than {MAX_JSON_DEPTH} arrays or objects deep",
                          file=file, fix="re-export the file; glTF needs a few levels")
    careful = _MAYBE_NOT_A_NUMBER.search(text) is not None
    try:
        try:
            raw = _loads(text, careful)
        except _Careful:
            careful = True
            raw = _loads(text, careful)
    except _LongNumber as exc:
        raise InputError(f"the JSON holds an integer of {exc.args[0]:,} digits (baker reads at "
                         f"most {MAX_INTEGER_DIGITS})", file=file,
                         fix="re-export the file; if it was edited by hand, fix that number") from None
    except RecursionError:
        raise too_deep from None
    except json.JSONDecodeError as exc:
        raise InputError(
            f"not valid JSON: {exc.msg} at line {exc.lineno}, column {exc.colno}",
            file=file,
            where=f"line {exc.lineno}",
            fix="re-export the file; if it was edited by hand, fix the JSON at that line",
        ) from None
    if not isinstance(raw, dict):
        raise InputError(
            "not a glTF file: the JSON is not an object",
            file=file,
            fix="give baker a .gltf or .glb file",
        )
    if _depth(raw) > MAX_JSON_DEPTH:
        raise too_deep
    where, number = _first_not_a_number(raw) if careful else ("", None)
    if number is not None:
        raise InputError(f"{number.text} is not a finite float64, as glTF's numbers are",
                         file=file, where=where,
                         fix="re-export the file; if it was edited by hand, write a finite "
                             "number there")
    return raw


def _depth(value: Any) -> int:
    """How deep arrays and objects nest in the parsed JSON ``value`` (a scalar: 0), walked
    without recursion."""
    deepest, level = 0, [(value, 1)]
    while level:
        item, depth = level.pop()
        children = item.values() if isinstance(item, dict) else item if isinstance(item, list) else None
        if children is None:
            continue
        deepest = max(deepest, depth)
        level.extend((child, depth + 1) for child in children if isinstance(child, (dict, list)))
    return deepest


def _first_not_a_number(value: Any) -> tuple[str, _NotANumber | None]:
    """(where, it): the first ``_NotANumber`` in the parsed JSON ``value`` in document order,
    its path as the errors name objects (``meshes[0].weights[0]``); ("", None) if none."""
    level = [(value, "")]
    while level:
        item, path = level.pop()
        if isinstance(item, _NotANumber):
            return path, item
        if isinstance(item, dict):
            level.extend((child, f"{path}.{key}" if path else str(key))
                         for key, child in reversed(item.items()))
        elif isinstance(item, list):
            level.extend((child, f"{path}[{i}]") for i, child in reversed(list(enumerate(item))))
    return "", None


def _check_asset(raw: dict, file: str) -> None:
    """Require ``asset.version`` 2.x."""
    asset = raw.get("asset")
    if not isinstance(asset, dict):
        raise InputError(
            "no asset object: not a glTF 2.0 file",
            file=file,
            where="asset",
            fix="give baker a glTF 2.0 .gltf or .glb file",
        )
    version = asset.get("version")
    if not isinstance(version, str) or not version.startswith("2."):
        raise InputError(
            f"asset.version is {json.dumps(version)}: baker reads glTF 2.x only",
            file=file,
            where="asset.version",
            fix="convert the file to glTF 2.0: re-export it, or run Khronos gltf-pipeline on glTF 1.0",
        )


_TOP_LEVEL_ARRAYS = (
    "accessors",
    "animations",
    "buffers",
    "bufferViews",
    "cameras",
    "images",
    "materials",
    "meshes",
    "nodes",
    "samplers",
    "scenes",
    "skins",
    "textures",
)


def _check_arrays(raw: dict, file: str) -> None:
    """Require the top-level glTF arrays, where present, to be arrays of objects."""
    for key in _TOP_LEVEL_ARRAYS:
        items = raw.get(key, [])
        if not isinstance(items, list):
            raise invalid(f"{key} is not an array", file, key)
        for i, item in enumerate(items):
            if not isinstance(item, dict):
                raise invalid("is not a JSON object", file, f"{key}[{i}]")


def _check_primitives(raw: dict, file: str) -> None:
    """Require each mesh's primitives, where present, to be an array of objects, and each
    primitive's attributes to be an object (each named where it fails)."""
    for i, mesh in enumerate(raw.get("meshes", [])):
        primitives = mesh.get("primitives", [])
        if not isinstance(primitives, list):
            raise invalid("is not an array", file, f"meshes[{i}].primitives")
        for j, primitive in enumerate(primitives):
            where = f"meshes[{i}].primitives[{j}]"
            if not isinstance(primitive, dict):
                raise invalid("is not a JSON object", file, where)
            if not isinstance(primitive.get("attributes", {}), dict):
                raise invalid(f"attributes is {primitive['attributes']!r}, not a JSON object",
                              file, f"{where}.attributes")


def _check_buffer_views(raw: dict, file: str) -> None:
    """Require each bufferView, read or not, to name its buffer and to lie within it (the
    spec's required ``buffer`` and ``byteLength``, a ``byteOffset`` ≥ 0): the output keeps
    every view, re-pointed into one buffer. The buffer's index is checked with every other
    index (``references.check_references``)."""
    buffers = raw.get("buffers", [])
    for i, view in enumerate(raw.get("bufferViews", [])):
        where = f"bufferViews[{i}]"
        for key, low in (("buffer", 0), ("byteLength", 1), ("byteOffset", 0)):
            value = view.get(key, 0 if key == "byteOffset" else None)
            if value is None:
                raise invalid(f"has no {key}, which the spec requires", file, where)
            if not _whole(value) or value < low:
                raise invalid(f"{key} is {value!r}, not a whole number ≥ {low}", file,
                              f"{where}.{key}")
        buffer, end = int(view["buffer"]), int(view.get("byteOffset", 0) + view["byteLength"])
        size = buffers[buffer].get("byteLength") if buffer < len(buffers) else None
        if _whole(size) and end > size:
            raise invalid(f"ends at byte {end:,}, past its buffer's byteLength {int(size):,}",
                          file, where)


def _whole(value: Any) -> bool:
    """Whether a JSON value is a whole number (an integer, or a float with no fraction)."""
    return (isinstance(value, int) and not isinstance(value, bool)) or (
        isinstance(value, float) and value.is_integer())


def _check_required_extensions(raw: dict, file: str) -> None:
    """Refuse a file that requires an extension baker cannot honour, naming what each one is."""
    required = raw.get("extensionsRequired") or []
    if not isinstance(required, list):
        raise invalid("extensionsRequired is not a list", file, "extensionsRequired")
    for k, name in enumerate(required):
        if not isinstance(name, str):
            raise invalid(f"is {type(name).__name__}, not an extension's name", file,
                          f"extensionsRequired[{k}]")
    missing = [str(name) for name in required if name not in SUPPORTED_EXTENSIONS]
    if missing:
        names = ", ".join(missing)
        kinds = "; ".join(f"{name}: {unsupported_kind(name)}" for name in missing)
        raise InputError(
            f"the file requires {names}, which baker does not support ({kinds})",
            file=file,
            where="extensionsRequired",
            fix=f"re-export without {names}",
        )
