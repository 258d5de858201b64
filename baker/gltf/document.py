"""baker's glTF objects (``objects``) made from parsed glTF JSON (``document``), checking that
every value has its field's JSON type, and turned back into JSON (``data``).

``document`` walks the JSON once with a plan made per class from its fields' types (``_plan``):
int, float, str, bool, Optional, List, Dict[str, Any], other such dataclasses, and
``Attributes``. A value of another JSON type than its field's (a string where an index is
expected, say) is an error that names where it is (``WrongType``); an integral float where an
integer is expected (``"count": 3.0``, as some exporters write them) is read as that integer
(an index into another array must be a JSON integer: ``references`` refuses one first).
``data`` goes the other way, cleaned for writing, in one walk.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import typing

import numpy as np

from baker.gltf import objects

# accessor componentType → little-endian numpy dtype (glTF §3.6.2.2), for reading and writing.
COMPONENT_DTYPES = {
    5120: np.dtype("<i1"),
    5121: np.dtype("<u1"),
    5122: np.dtype("<i2"),
    5123: np.dtype("<u2"),
    5125: np.dtype("<u4"),
    5126: np.dtype("<f4"),
}


class WrongType(Exception):
    """A JSON value whose type is not its field's: ``where`` is its JSON path (``nodes[3].mesh``),
    ``what`` says what it is and what glTF expects there."""

    def __init__(self, where: str, expected: str, value) -> None:
        shown = repr(value)
        shown = shown if len(shown) <= 40 else f"a JSON {_JSON_NAMES[type(value)]}"
        self.what = f"is {shown}, where glTF expects {expected}"
        super().__init__(f"{where} {self.what}")
        self.where = where


_JSON_NAMES = {dict: "object", list: "array", str: "string", int: "number", float: "number",
               bool: "boolean", type(None): "null"}


# Field kinds of ``_plan``: how a JSON value becomes the field's value.
_ANY, _INT, _FLOAT, _STR, _BOOL, _DICT, _LIST, _CLASS, _ATTRIBUTES = range(9)
_SCALARS = {int: _INT, float: _FLOAT, str: _STR, bool: _BOOL}
_EXPECTED = {_INT: "an integer", _FLOAT: "a number", _STR: "a string", _BOOL: "true or false",
             _DICT: "an object", _LIST: "an array", _CLASS: "an object",
             _ATTRIBUTES: "an object"}


def _kind(hint) -> tuple:
    """(kind, inner) of a type hint: inner is the plan of a list's items or a dataclass."""
    args = typing.get_args(hint)
    origin = typing.get_origin(hint)
    if origin is typing.Union and len(args) == 2 and type(None) in args:  # Optional[X]
        return _kind(next(a for a in args if a is not type(None)))
    if hint in _SCALARS:
        return _SCALARS[hint], None
    if hint is typing.Any:
        return _ANY, None
    if hint is objects.Attributes:
        return _ATTRIBUTES, None
    if origin is dict:
        return _DICT, None
    if origin is list and len(args) == 1:
        return _LIST, _kind(args[0])
    if dataclasses.is_dataclass(hint):
        return _CLASS, hint
    raise TypeError(f"glTF field type {hint!r} has no plan")


@functools.cache
def _plan(cls) -> tuple[dict, tuple]:
    """({JSON name: (field name, kind, inner)}, the names of fields without a default) of an
    ``objects`` dataclass."""
    hints = typing.get_type_hints(cls)
    plan, required = {}, []
    for f in dataclasses.fields(cls):
        # extras may hold any JSON value (the spec's "SHOULD be an object" is advice)
        plan[f.name] = (f.name, _ANY, None) if f.name == "extras" else (
            f.name, *_kind(hints[f.name]))
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            required.append(f.name)
    return plan, tuple(required)


def _value(kind: int, inner, value, where: str):
    """A JSON value as the field of that kind holds it: ints of a float field become floats
    (and integral floats of an int field ints), a dict field is copied, lists and dataclasses
    are decoded item by item, ``Attributes`` dicts stay dicts (``document`` makes the
    primitives' own ones), and null stays None whatever the field. ``where``: the value's JSON
    path, for the error (``WrongType``) a value of another type is."""
    if value is None:
        return None
    kind_of = type(value)
    if kind == _FLOAT and kind_of in (float, int):
        return float(value)
    if (kind == _INT and kind_of is int) or (kind == _STR and kind_of is str) or (
            kind == _BOOL and kind_of is bool) or kind == _ANY:
        return value
    if kind == _INT and kind_of is float and value.is_integer():
        return int(value)
    if kind == _DICT and kind_of is dict:
        return dict(value)
    if kind == _ATTRIBUTES and kind_of is dict:
        return value
    if kind == _LIST and kind_of is list:
        item_kind, item_inner = inner
        return [_value(item_kind, item_inner, item, f"{where}[{i}]")
                for i, item in enumerate(value)]
    if kind == _CLASS and kind_of is dict:
        return _object(inner, value, where)
    raise WrongType(where, _EXPECTED[kind], value)


def _object(cls, raw: dict, where: str):
    """The ``cls`` of a JSON object at ``where``; keys that are not fields are dropped (glTF's
    own data lives in its fields, ``extensions`` and ``extras``)."""
    plan, required = _plan(cls)
    values = {name: None for name in required}
    for key, value in raw.items():
        entry = plan.get(key)
        if entry is not None:
            name, kind, inner = entry
            values[name] = _value(kind, inner, value, f"{where}.{key}" if where else key)
    return cls(**values)


def document(raw: dict) -> objects.GLTF2:
    """The document of the parsed glTF JSON ``raw``. Raises WrongType for a value of another
    JSON type than its field's (a top-level array or a mesh's primitives null among them)."""
    if type(raw) is not dict:
        raise WrongType("the document", "an object", raw)
    result = _object(objects.GLTF2, raw, "")
    for name in ("meshes", "nodes", "accessors", "bufferViews", "buffers", "materials"):
        if getattr(result, name) is None:
            raise WrongType(name, "an array", None)
    for i, mesh in enumerate(result.meshes):
        if mesh.primitives is None:
            raise WrongType(f"meshes[{i}].primitives", "an array", None)
        for primitive in mesh.primitives:  # missing, its default Attributes() stays
            if type(primitive.attributes) is dict:
                primitive.attributes = objects.Attributes(**primitive.attributes)
    return result


_IMMUTABLE = frozenset((int, float, str, bool))
"""The JSON leaves ``data`` gives back as they are (exact types: a subclass is deep-copied)."""


@functools.cache
def _field_names(cls) -> tuple[str, ...]:
    return tuple(f.name for f in dataclasses.fields(cls))


def data(value):
    """The glTF JSON data of a document (or any object in it), a deep copy: None and empty
    properties dropped, ``extensions`` and ``extras`` values kept verbatim unless they are {}
    (an extension's empty object means something), list items never dropped (indices stay
    valid). Numbers, strings and booleans are immutable: they are the copy (deepcopy gives
    them back, at 1 µs a call)."""
    if type(value) in _IMMUTABLE:
        return value
    if isinstance(value, objects.Attributes):
        value = value.__dict__
    elif dataclasses.is_dataclass(value):
        value = {name: getattr(value, name) for name in _field_names(type(value))}
    if isinstance(value, dict):
        out = {}
        for key, item in value.items():
            if type(item) in _IMMUTABLE:  # most values: no call for them
                out[key] = item
                continue
            if item is None:
                continue
            if key in ("extensions", "extras"):
                if item != {}:
                    out[key] = copy.deepcopy(item)
                continue
            item = data(item)
            if isinstance(item, (dict, list)) and not item:
                continue
            out[key] = item
        return out
    if isinstance(value, (list, tuple)):
        return [item if type(item) in _IMMUTABLE else data(item) for item in value]
    return copy.deepcopy(value)
