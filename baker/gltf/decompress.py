"""Compressed geometry made plain: Draco primitives and meshopt bufferViews decoded at load.

Exporters ship geometry compressed with ``KHR_draco_mesh_compression`` (Draco, decoded by the
``DracoPy`` package) or ``EXT_meshopt_compression`` / ``KHR_meshopt_compression`` (meshoptimizer,
decoded by the ``meshopt`` package); both are in baker's ``compression`` extra. ``decompressed``
turns such a document into a plain one, so that every later stage, the writer included, reads
accessors as usual:

- a meshopt bufferView's decoded bytes are put where the view says uncompressed data lies, in its
  own (fallback) buffer, and the view loses the extension. A fallback buffer without data
  (``fallback: true``, no uri) comes in as zeros of its byteLength (``buffers._buffer_bytes``)
  and is filled here; one whose data is there is used as it is, nothing decoded.
- a Draco primitive's decoded attributes and indices go to a new buffer appended after the
  file's, one bufferView each, set on the accessors the extension maps (their counts set to the
  decoded ones), and the primitive loses the extension.

The output is then written uncompressed (its extensionsUsed/Required lose the three names):
compress it again with the tool that compressed the input if its size matters.
"""

from __future__ import annotations

import copy

import numpy as np

from baker.errors import InputError
from baker.gltf import objects
from baker.gltf.document import COMPONENT_DTYPES

DRACO = "KHR_draco_mesh_compression"
MESHOPT = ("EXT_meshopt_compression", "KHR_meshopt_compression")
COMPRESSION_EXTENSIONS = frozenset({DRACO, *MESHOPT})
EXTRA = 'pip install "DracoPy>=2" "meshopt>=0.1"'
"""What installs the decoders: both are baker's own dependencies, so only an install that lost
them (a package removed by hand) needs it."""

_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}  # the accessor types Draco decodes
_REEXPORT = "re-export the asset (or decompress it, e.g. gltf-transform copy, and bake that)"


def is_meshopt_fallback(buffer: objects.Buffer) -> bool:
    """Whether ``buffer`` is a meshopt fallback buffer: its bytes may be absent, and decoded
    bufferViews are put in it."""
    extensions = buffer.extensions or {}
    return any(isinstance(extensions.get(name), dict) and extensions[name].get("fallback")
               for name in MESHOPT)


def compressed(document: objects.GLTF2) -> bool:
    """Whether some primitive is Draco-compressed or some bufferView meshopt-compressed."""
    return bool(_meshopt_views(document) or _draco_primitives(document))


def decompressed(document: objects.GLTF2, buffers: list[bytes],
                 file: str) -> tuple[objects.GLTF2, list[bytes]]:
    """The plain document and buffers of a compressed one (see the module's docstring); the
    input is left as it was. A fallback buffer with a uri holds the uncompressed data itself:
    its views are read as stored. An ``InputError`` names the primitive or view that cannot be
    decoded, or the extra to install when a decoder is missing."""
    supplied = {i for i, b in enumerate(document.buffers or []) if b.uri is not None}
    document = copy.deepcopy(document)
    buffers = [bytearray(b) for b in buffers]
    for index, view, extension, name in _meshopt_views(document):
        if view.buffer not in supplied:
            _decode_meshopt_view(buffers, index, view, extension, name, file)
        del view.extensions[name]
    draco = _draco_primitives(document)
    if draco:
        appended = bytearray()
        for where, primitive, extension in draco:
            _decode_draco_primitive(document, buffers, appended, where, primitive, extension, file)
            del primitive.extensions[DRACO]
        document.buffers.append(objects.Buffer(byteLength=len(appended)))
        buffers.append(appended)
    for buffer in document.buffers:
        for name in MESHOPT:
            (buffer.extensions or {}).pop(name, None)
    for key in ("extensionsUsed", "extensionsRequired"):
        names = getattr(document, key)
        if names:
            setattr(document, key, [n for n in names if n not in COMPRESSION_EXTENSIONS])
    return document, [bytes(b) for b in buffers]


def draco_declared_bytes(document: objects.GLTF2) -> list[tuple[str, int]]:
    """(where, bytes) that each Draco primitive's accessors declare (count × element size of
    the attributes its extension maps, and of its indices): what decoding it may make, for the
    input's budget (``gltf.budget.check_buffers``) before anything is decoded. Accessors that
    are not valid are left for the decoding to report."""
    accessors = document.accessors or []
    out = []
    for where, primitive, extension in _draco_primitives(document):
        names = set(extension.get("attributes") or {})
        indices = [primitive.indices] if primitive.indices is not None else []
        used = [getattr(primitive.attributes, n, None) for n in names] + indices
        total = 0
        for index in used:
            if isinstance(index, int) and 0 <= index < len(accessors):
                accessor = accessors[index]
                dtype = COMPONENT_DTYPES.get(accessor.componentType)
                width = _WIDTHS.get(accessor.type)
                if dtype is not None and width and isinstance(accessor.count, int) \
                        and accessor.count > 0:
                    total += accessor.count * width * np.dtype(dtype).itemsize
        out.append((where, total))
    return out


def _meshopt_views(document: objects.GLTF2) -> list[tuple[int, objects.BufferView, dict, str]]:
    out = []
    for index, view in enumerate(document.bufferViews or []):
        for name in MESHOPT:
            extension = (view.extensions or {}).get(name)
            if isinstance(extension, dict):
                out.append((index, view, extension, name))
    return out


def _draco_primitives(document: objects.GLTF2) -> list[tuple[str, objects.Primitive, dict]]:
    out = []
    for m, mesh in enumerate(document.meshes or []):
        for j, primitive in enumerate(mesh.primitives or []):
            extension = (primitive.extensions or {}).get(DRACO)
            if isinstance(extension, dict):
                out.append((f"meshes[{m}].primitives[{j}].extensions.{DRACO}", primitive, extension))
    return out


def _decoder(module: str, extension: str, where: str, file: str):
    """The decoding package, or an InputError naming the extra that installs it."""
    try:
        return __import__(module)
    except ImportError:
        raise InputError(f"the geometry is compressed with {extension}, and decoding it needs the "
                         f"{module} package, which is not installed", file=file, where=where,
                         fix=f"{EXTRA} (DracoPy and meshopt), or re-export without compression"
                         ) from None


def _slice(data: bytes | bytearray, offset, length, file: str, where: str) -> bytes:
    """``data[offset:offset + length]``, checked to be whole byte counts inside ``data``."""
    if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in (offset, length)) \
            or offset + length > len(data):
        raise InputError(f"byteOffset {offset!r} and byteLength {length!r} do not lie inside the "
                         f"buffer's {len(data)} bytes", file=file, where=where, fix=_REEXPORT)
    return bytes(data[offset:offset + length])


def _decode_meshopt_view(buffers: list[bytearray], index: int, view: objects.BufferView,
                         extension: dict, name: str, file: str) -> None:
    """Decode one meshopt bufferView into its place in its own buffer."""
    where = f"bufferViews[{index}].extensions.{name}"
    meshopt = _decoder("meshopt", name, where, file)
    source = extension.get("buffer")
    if not isinstance(source, int) or not 0 <= source < len(buffers):
        raise InputError(f"buffer {source!r} is not one of the file's {len(buffers)} buffers",
                         file=file, where=f"{where}.buffer", fix=_REEXPORT)
    data = _slice(buffers[source], extension.get("byteOffset", 0), extension.get("byteLength"),
                  file, where)
    count, stride = extension.get("count"), extension.get("byteStride")
    mode, filter_ = extension.get("mode"), extension.get("filter", "NONE")
    offset, length = view.byteOffset or 0, view.byteLength
    target = buffers[view.buffer] if isinstance(view.buffer, int) and 0 <= view.buffer < len(buffers) \
        else None

    def must_fit(size: int) -> None:
        """Refuse ``size`` decoded bytes that the bufferView has no room for: checked on the
        declared count × byteStride before decoding too, which allocates them (a count of 2³¹
        ended in the decoder's std::bad_alloc)."""
        if target is None or not isinstance(length, int) or size > length \
                or offset + size > len(target):
            raise InputError(f"{size:,} decoded bytes do not fit the bufferView ({length!r} "
                             f"bytes at {offset} of buffers[{view.buffer}])", file=file,
                             where=f"bufferViews[{index}]", fix=_REEXPORT)

    if all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in (count, stride)):
        must_fit(count * stride)
    try:
        decoded = meshopt.decode_gltf_buffer(data, count, stride, mode, filter_)
    except (ValueError, TypeError, RuntimeError) as exc:
        raise InputError(f"cannot decode the meshopt data ({exc})", file=file, where=where,
                         fix=_REEXPORT) from None
    payload = np.ascontiguousarray(decoded).tobytes()
    must_fit(len(payload))
    target[offset:offset + len(payload)] = payload


def _decode_draco_primitive(document: objects.GLTF2, buffers: list[bytearray],
                            appended: bytearray, where: str, primitive: objects.Primitive,
                            extension: dict, file: str) -> None:
    """Decode one Draco primitive; its accessors get views into ``appended``, the buffer added
    after the file's (``len(buffers)`` is its index)."""
    draco = _decoder("DracoPy", DRACO, where, file)
    view_index = extension.get("bufferView")
    views = document.bufferViews or []
    if not isinstance(view_index, int) or not 0 <= view_index < len(views):
        raise InputError(f"bufferView {view_index!r} is not one of the file's {len(views)}",
                         file=file, where=f"{where}.bufferView", fix=_REEXPORT)
    view = views[view_index]
    if not isinstance(view.buffer, int) or not 0 <= view.buffer < len(buffers):
        raise InputError(f"buffer {view.buffer!r} is not one of the file's", file=file,
                         where=f"bufferViews[{view_index}].buffer", fix=_REEXPORT)
    data = _slice(buffers[view.buffer], view.byteOffset or 0, view.byteLength, file,
                  f"bufferViews[{view_index}]")
    try:
        mesh = draco.decode(data)
    except Exception as exc:  # DracoPy raises its own exception types and ValueError
        raise InputError(f"cannot decode the Draco data ({type(exc).__name__}: {exc})", file=file,
                         where=where, fix=_REEXPORT) from None
    attributes = primitive.attributes
    mapping = extension.get("attributes") or {}
    for name, unique_id in mapping.items():
        accessor_index = getattr(attributes, name, None)
        if accessor_index is None:
            continue
        found = mesh.get_attribute_by_unique_id(unique_id) if isinstance(unique_id, int) else None
        if found is None:
            raise InputError(f"the Draco data has no attribute {unique_id!r} for {name}", file=file,
                             where=f"{where}.attributes.{name}", fix=_REEXPORT)
        _set_accessor(document, appended, len(buffers), accessor_index, np.asarray(found["data"]),
                      file, f"{where}.attributes.{name}")
    faces = getattr(mesh, "faces", None)  # a Draco point cloud has none
    if faces is None:
        raise InputError("the Draco data is a point cloud, not triangles", file=file, where=where,
                         fix=_REEXPORT)
    if primitive.indices is None:  # Draco's vertices are indexed whatever the primitive says
        document.accessors.append(objects.Accessor(componentType=5125, type="SCALAR"))
        primitive.indices = len(document.accessors) - 1
    _set_accessor(document, appended, len(buffers), primitive.indices,
                  np.asarray(faces).reshape(-1, 1), file, f"{where} (indices)")
    primitive.mode = 4  # Draco decodes strips to triangles too


def _set_accessor(document: objects.GLTF2, appended: bytearray, buffer: int, index,
                  values: np.ndarray, file: str, where: str) -> None:
    """Point accessor ``index`` at ``values`` (count, components), stored in its component type
    in a new tightly packed bufferView at the end of ``appended``; its count, and its min/max
    when it has them, are the decoded values'."""
    accessors = document.accessors or []
    if not isinstance(index, int) or not 0 <= index < len(accessors):
        raise InputError(f"refers to accessors[{index}] but the file has {len(accessors)}",
                         file=file, where=where, fix=_REEXPORT)
    accessor = accessors[index]
    dtype = COMPONENT_DTYPES.get(accessor.componentType)
    width = _WIDTHS.get(accessor.type)
    values = values.reshape(len(values), -1)
    declared = accessor.count
    if declared is not None and not (isinstance(declared, int) and len(values) <= declared):
        raise InputError(f"the Draco data decodes to {len(values):,} elements where "
                         f"accessors[{index}] declares {declared!r} (what the input's budget "
                         "counted)", file=file, where=where, fix=_REEXPORT)
    if dtype is None or width != values.shape[1]:
        raise InputError(f"accessors[{index}] ({accessor.type}) does not match the decoded data's "
                         f"{values.shape[1]} components", file=file, where=where, fix=_REEXPORT)
    stored = np.ascontiguousarray(values.astype(dtype))
    payload = stored.tobytes()
    bounded = stored[np.isfinite(stored).all(axis=1)] if stored.dtype.kind == "f" else stored
    if len(bounded) and (accessor.min is not None or accessor.max is not None):
        # Draco's quantized values are the data now: bounds of the values as they decode, of
        # the finite ones (damaged data may decode to NaN, which JSON cannot hold: the file's
        # own bounds stay where no value is finite)
        number = float if stored.dtype.kind == "f" else int
        accessor.min = [number(v) for v in bounded.min(axis=0)]
        accessor.max = [number(v) for v in bounded.max(axis=0)]
    appended += b"\0" * (-len(appended) % 4)
    document.bufferViews.append(objects.BufferView(buffer=buffer, byteOffset=len(appended),
                                                     byteLength=len(payload)))
    appended += payload
    accessor.bufferView = len(document.bufferViews) - 1
    accessor.byteOffset = 0
    accessor.count = len(values)
