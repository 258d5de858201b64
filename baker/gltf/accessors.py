"""An accessor's numbers as a numpy array (``read_accessor``): its buffer view's elements,
strides and sparse substitution, normalized integers divided out (glTF §3.6–3.11)."""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from baker.errors import InputError
from baker.gltf import budget, objects
from baker.gltf.context import checked_item, invalid, schema
from baker.gltf.document import COMPONENT_DTYPES


# componentType → the divisor of normalized integers (glTF §3.11).
_NORMALIZED_DIVISORS = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0, 5125: 4294967295.0}


# accessor type → (columns, rows); a matrix is stored column by column.
TYPE_SHAPES = {
    "SCALAR": (1, 1),
    "VEC2": (1, 2),
    "VEC3": (1, 3),
    "VEC4": (1, 4),
    "MAT2": (2, 2),
    "MAT3": (3, 3),
    "MAT4": (4, 4),
}


def read_accessor(
    document: objects.GLTF2, buffers: Sequence[bytes], index: int, *, file: str = ""
) -> np.ndarray:
    """The elements of ``document.accessors[index]`` as a (count, ncomp) array.

    ncomp is 1, 2, 3, 4, 4, 9 or 16 for SCALAR … MAT4 (matrices column-major, as stored).
    float64 for FLOAT and for ``normalized`` integers (mapped to [0, 1] or [-1, 1] per glTF §3.11),
    int64 for integers that are not normalized (indices; quantized data, which callers cast).
    Honours byteOffset of accessor and bufferView, byteStride, matrix column alignment, accessors
    without bufferView (zeros) and sparse substitution. ``file`` only goes into error messages.
    """
    where = f"accessors[{index}]"
    accessor = checked_item(document.accessors, index, "accessors", file, where)
    with schema(file, where):
        dtype = COMPONENT_DTYPES.get(accessor.componentType)
        if dtype is None:
            raise invalid(
                f"componentType {accessor.componentType} is not a glTF component type", file, where
            )
        shape = TYPE_SHAPES.get(accessor.type)
        if shape is None:
            raise invalid(f"type {accessor.type!r} is not a glTF accessor type", file, where)
        count = accessor.count
        if not isinstance(count, int) or count < 0:
            raise invalid(f"count {count!r} is not an element count", file, where)
        if accessor.bufferView is None:
            if count * shape[0] * shape[1] > budget.MAX_UNBACKED_NUMBERS:
                raise invalid(f"count {count:,} is too large for an accessor without a bufferView",
                              file, where)
            raw = np.zeros((count, shape[0] * shape[1]), dtype)
        else:
            view, stride = buffer_view(document, buffers, accessor.bufferView, file, f"{where}.bufferView")
            raw = _elements(view, accessor.byteOffset or 0, count, dtype, shape, stride, file, where)
        if accessor.sparse is not None:
            _substitute_sparse(document, buffers, accessor.sparse, raw, shape, file, f"{where}.sparse")
        return _to_numbers(raw, accessor.componentType, bool(accessor.normalized))


def buffer_view(
    document: objects.GLTF2, buffers: Sequence[bytes], index: int, file: str, referrer: str
) -> tuple[memoryview, int | None]:
    """The bytes of ``document.bufferViews[index]`` (bounds checked) and its byteStride."""
    view = checked_item(document.bufferViews, index, "bufferViews", file, referrer)
    where = f"bufferViews[{index}]"
    data = checked_item(buffers, view.buffer, "buffers", file, f"{where}.buffer")
    start, length = view.byteOffset or 0, view.byteLength
    if not isinstance(length, int) or length < 0 or not isinstance(start, int) or start < 0:
        raise invalid("byteOffset/byteLength are not byte counts", file, where)
    if start + length > len(data):
        raise InputError(
            f"bufferView spans bytes {start}–{start + length} but buffers[{view.buffer}] has {len(data)}",
            file=file,
            where=where,
            fix="the binary data does not match the JSON: export the asset again",
        )
    stride = view.byteStride
    if stride is not None and (not isinstance(stride, int) or stride <= 0):
        raise invalid(f"byteStride {stride!r} is not a positive byte count", file, where)
    return memoryview(data)[start : start + length], stride


def _elements(
    view: memoryview,
    offset: int,
    count: int,
    dtype: np.dtype,
    shape: tuple[int, int],
    stride: int | None,
    file: str,
    where: str,
) -> np.ndarray:
    """Copy ``count`` elements of (columns, rows) components out of ``view`` into (count, ncomp).

    Elements start ``stride`` bytes apart (tightly packed when None); matrix columns start on
    4-byte boundaries (glTF §3.6.2.4). Bounds are checked against the view.
    """
    columns, rows = shape
    size = dtype.itemsize
    column_bytes = rows * size
    column_stride = column_bytes if columns == 1 else -(-column_bytes // 4) * 4
    extent = column_stride * (columns - 1) + column_bytes
    stride = stride or column_stride * columns
    if stride < extent:
        raise invalid(f"byteStride {stride} is smaller than one element ({extent} bytes)", file, where)
    if not isinstance(offset, int) or offset < 0:
        raise invalid(f"byteOffset {offset!r} is not a byte count", file, where)
    end = offset + (stride * (count - 1) + extent if count else 0)
    if end > len(view):
        raise InputError(
            f"{count} elements from byte {offset} need {end} bytes but the bufferView has {len(view)}",
            file=file,
            where=where,
            fix="the binary data does not match the JSON: export the asset again",
        )
    if count == 0:
        return np.zeros((0, columns * rows), dtype)
    strides = (stride, column_stride, size)
    strided = np.ndarray((count, columns, rows), dtype, buffer=view, offset=offset, strides=strides)
    return np.array(strided).reshape(count, columns * rows)


def _substitute_sparse(
    document: objects.GLTF2,
    buffers: Sequence[bytes],
    sparse: Any,
    raw: np.ndarray,
    shape: tuple[int, int],
    file: str,
    where: str,
) -> None:
    """Write a sparse accessor's values, laid out as ``shape`` (columns, rows), into ``raw``
    (count, ncomp) at its indices, in place."""
    count = sparse.count
    if not isinstance(count, int) or count < 0:
        raise invalid(f"count {count!r} is not an element count", file, where)
    index_type = sparse.indices.componentType
    if index_type not in (5121, 5123, 5125):
        raise invalid(
            f"indices.componentType {index_type} is not an unsigned integer type", file, f"{where}.indices"
        )
    view, _ = buffer_view(document, buffers, sparse.indices.bufferView, file, f"{where}.indices.bufferView")
    offset, dtype = sparse.indices.byteOffset or 0, COMPONENT_DTYPES[index_type]
    indices = _elements(view, offset, count, dtype, (1, 1), None, file, f"{where}.indices")
    indices = indices[:, 0].astype(np.int64)
    if indices.size and indices.max() >= len(raw):
        raise invalid(
            f"sparse index {indices.max()} is past the accessor's {len(raw)} elements",
            file,
            f"{where}.indices",
        )
    view, _ = buffer_view(document, buffers, sparse.values.bufferView, file, f"{where}.values.bufferView")
    offset = sparse.values.byteOffset or 0
    values = _elements(view, offset, count, raw.dtype, shape, None, file, f"{where}.values")
    raw[indices] = values


def _to_numbers(raw: np.ndarray, component_type: int, normalized: bool) -> np.ndarray:
    """float64 for floats and normalized integers (signed ones clamped at -1), else int64. A
    signalling NaN among the floats stays a NaN, for the checks after to refuse, without
    numpy's RuntimeWarning on the bake's stderr."""
    if component_type == 5126:
        with np.errstate(invalid="ignore"):
            return raw.astype(np.float64)
    if normalized:
        values = raw.astype(np.float64) / _NORMALIZED_DIVISORS[component_type]
        return np.maximum(values, -1.0) if raw.dtype.kind == "i" else values
    return raw.astype(np.int64)
