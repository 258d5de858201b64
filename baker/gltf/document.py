"""pygltflib documents made straight from parsed glTF JSON, as pygltflib itself would make them,
and back.

pygltflib decodes every JSON object through dataclasses_json, which looks up each field's type
hints anew for every object: about 0.5 ms a node, 50 ms for a room of 60 crates (a tenth of a
rebake) and 5 s for a level of 10 000 nodes. pygltflib's classes are plain dataclasses whose
fields are int, float, str, bool, Optional, List, Dict[str, Any], other such dataclasses, and
``Attributes``; ``document`` walks the JSON once with a plan made per class (``_plan``), with
dataclasses_json's rules for these types (see ``_value``). Any value of another JSON type than
its field's (an int where a str is expected, say) is left to pygltflib (``NotPlain``), so that
what it makes of it, or the error it raises, stays pygltflib's. ``data`` goes the other way
(what ``pygltflib.gltf_asdict`` gives, cleaned for writing) in one walk.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import typing

import numpy as np
import pygltflib

# accessor componentType → little-endian numpy dtype (glTF §3.6.2.2), for reading and writing.
COMPONENT_DTYPES = {
    5120: np.dtype("<i1"),
    5121: np.dtype("<u1"),
    5122: np.dtype("<i2"),
    5123: np.dtype("<u2"),
    5125: np.dtype("<u4"),
    5126: np.dtype("<f4"),
}


class NotPlain(Exception):
    """A JSON value whose type is not its field's own; pygltflib decides what it means."""


# Field kinds of ``_plan``: how a JSON value becomes the field's value.
_ANY, _INT, _FLOAT, _STR, _BOOL, _DICT, _LIST, _CLASS, _ATTRIBUTES = range(9)
_SCALARS = {int: _INT, float: _FLOAT, str: _STR, bool: _BOOL}


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
    if hint is pygltflib.Attributes:
        return _ATTRIBUTES, None
    if origin is dict:
        return _DICT, None
    if origin is list and len(args) == 1:
        return _LIST, _kind(args[0])
    if dataclasses.is_dataclass(hint):
        return _CLASS, hint
    raise TypeError(f"pygltflib field type {hint!r} has no plan")  # a new pygltflib version


@functools.cache
def _plan(cls) -> tuple[dict, tuple]:
    """({JSON name: (field name, kind, inner)}, the names of fields without a default) of a
    pygltflib dataclass; fields not given to __init__ are left out."""
    hints = typing.get_type_hints(cls)
    plan, required = {}, []
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        # extras may hold any JSON value (the spec's "SHOULD be an object" is advice):
        # pygltflib types it as a dict and fails on a list or a string, so it is taken as is.
        plan[f.name] = (f.name, _ANY, None) if f.name == "extras" else (
            f.name, *_kind(hints[f.name]))
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            required.append(f.name)
    return plan, tuple(required)


def _value(kind: int, inner, value):
    """A JSON value as the field of that kind holds it, with dataclasses_json's rules: ints of
    a float field become floats, a dict field is copied, lists and dataclasses are decoded
    item by item, ``Attributes`` dicts stay dicts (``document`` makes the primitives' own
    ones), and null stays None whatever the field."""
    if value is None:
        return None
    kind_of = type(value)
    if kind == _FLOAT and kind_of in (float, int):
        return float(value)
    if (kind == _INT and kind_of is int) or (kind == _STR and kind_of is str) or (
            kind == _BOOL and kind_of is bool) or kind == _ANY:
        return value
    if kind == _DICT and kind_of is dict:
        return dict(value)
    if kind == _ATTRIBUTES and kind_of is dict:
        return value
    if kind == _LIST and kind_of is list:
        item_kind, item_inner = inner
        return [_value(item_kind, item_inner, item) for item in value]
    if kind == _CLASS and kind_of is dict:
        return _object(inner, value)
    raise NotPlain(f"{value!r} for a field of kind {kind}")


def _object(cls, raw: dict):
    """The pygltflib ``cls`` of a JSON object; keys that are not fields are dropped, as
    dataclasses_json drops them, and fields without a default are None when absent."""
    plan, required = _plan(cls)
    values = {name: None for name in required}
    for key, value in raw.items():
        entry = plan.get(key)
        if entry is not None:
            name, kind, inner = entry
            values[name] = _value(kind, inner, value)
    return cls(**values)


def document(raw: dict) -> pygltflib.GLTF2:
    """The pygltflib document of the parsed glTF JSON ``raw``: equal, field by field and type
    by type, to ``pygltflib.GLTF2.gltf_from_json`` of its text. Raises NotPlain for a value of
    another type than its field's."""
    if type(raw) is not dict:
        raise NotPlain("the document is not a JSON object")
    result = _object(pygltflib.GLTF2, raw)
    if result.meshes is None or any(mesh.primitives is None for mesh in result.meshes):
        raise NotPlain("null meshes or primitives")
    for mesh in result.meshes:
        for primitive in mesh.primitives:
            if primitive.attributes:  # as pygltflib's from_json does
                primitive.attributes = pygltflib.Attributes(**primitive.attributes)
    return result


_IMMUTABLE = frozenset((int, float, str, bool))
"""The JSON leaves ``data`` gives back as they are (exact types: a subclass is deep-copied)."""


@functools.cache
def _field_names(cls) -> tuple[str, ...]:
    return tuple(f.name for f in dataclasses.fields(cls))


def data(value):
    """The glTF JSON data of a pygltflib document (or any object in it), a deep copy: None and
    empty properties dropped, ``extensions`` and ``extras`` values kept verbatim unless they
    are {} (an extension's empty object means something), list items never dropped (indices
    stay valid). What cleaning ``pygltflib.gltf_asdict(value)`` so gives, without building the
    uncleaned copy first: 18 -> 2 ms for a room of 60 crates. Numbers, strings and booleans
    are immutable: they are the copy (deepcopy gives them back, at 1 µs a call)."""
    if type(value) in _IMMUTABLE:
        return value
    if isinstance(value, pygltflib.Attributes):
        value = value.__dict__
    elif dataclasses.is_dataclass(value):
        value = {name: getattr(value, name) for name in _field_names(type(value))}
    if isinstance(value, dict):
        out = {}
        for key, item in value.items():
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
        return [data(item) for item in value]
    return copy.deepcopy(value)
