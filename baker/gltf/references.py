"""Every index a glTF file uses to name another of its objects points at one it has.

The loader reads only what the scene's nodes use, so a bad index in a mesh, material or
accessor no node reaches would pass unseen, and the output, which keeps the file's objects,
would carry it to a viewer (the Khronos validator rejects it). ``check_references`` looks at
every index the glTF 2.0 schema defines (and those of the extensions baker reads) in the JSON
as parsed, before anything else is read, and names each one that points past its array.
"""

from __future__ import annotations

from typing import Any, Iterator

from baker.errors import InputError

_MAX_NAMED = 5  # references named in the message; the rest are counted

# The glTF 2.0 schema's references from each top-level array's items, as (path, target):
# a path is the keys from the item to the index ("*" every element of a list or value of a
# dict); the target is the top-level array the index points into.
_REFERENCES: dict[str, tuple[tuple[tuple[str, ...], str], ...]] = {
    "scenes": ((("nodes", "*"), "nodes"),),
    "nodes": ((("children", "*"), "nodes"), (("mesh",), "meshes"), (("camera",), "cameras"),
              (("skin",), "skins"),
              (("extensions", "EXT_mesh_gpu_instancing", "attributes", "*"), "accessors")),
    "meshes": ((("primitives", "*", "attributes", "*"), "accessors"),
               (("primitives", "*", "indices"), "accessors"),
               (("primitives", "*", "material"), "materials"),
               (("primitives", "*", "targets", "*", "*"), "accessors"),
               (("primitives", "*", "extensions", "KHR_draco_mesh_compression", "bufferView"),
                "bufferViews"),
               (("primitives", "*", "extensions", "KHR_materials_variants", "mappings", "*",
                 "material"), "materials")),
    "accessors": ((("bufferView",), "bufferViews"),
                  (("sparse", "indices", "bufferView"), "bufferViews"),
                  (("sparse", "values", "bufferView"), "bufferViews")),
    "bufferViews": ((("buffer",), "buffers"),
                    (("extensions", "EXT_meshopt_compression", "buffer"), "buffers"),
                    (("extensions", "KHR_meshopt_compression", "buffer"), "buffers")),
    "images": ((("bufferView",), "bufferViews"),),
    "textures": ((("source",), "images"), (("sampler",), "samplers"),
                 (("extensions", "*", "source"), "images")),
    "skins": ((("inverseBindMatrices",), "accessors"), (("joints", "*"), "nodes"),
              (("skeleton",), "nodes")),
    "animations": ((("channels", "*", "target", "node"), "nodes"),
                   (("samplers", "*", "input"), "accessors"),
                   (("samplers", "*", "output"), "accessors")),
}
_LIGHTS = "KHR_lights_punctual"


def check_references(raw: dict, file: str) -> None:
    """Raise an InputError naming every index in ``raw`` (the parsed glTF JSON, its top-level
    arrays checked to be arrays of objects) that is not an index into the array it names."""
    bad = list(_bad_references(raw))
    if not bad:
        return
    named = "; ".join(f"{where} → {target}[{index!r}] ({_why(index)}{count} {target} in the file)"
                      for where, target, index, count in bad[:_MAX_NAMED])
    more = f"; and {len(bad) - _MAX_NAMED} more" if len(bad) > _MAX_NAMED else ""
    raise InputError(f"{len(bad)} reference(s) to objects the file does not have: {named}{more}",
                     file=file, where=bad[0][0],
                     fix="export the file again (its indices were not updated when objects "
                         "were removed), or run it through the Khronos glTF Validator")


def _why(index: Any) -> str:
    """What is wrong with an ``index`` besides its range: "" for an integer."""
    return "" if isinstance(index, int) and not isinstance(index, bool) else "not an integer; "


def _bad_references(raw: dict) -> Iterator[tuple[str, str, Any, int]]:
    """(where, target array, index, the target's length) of each reference out of range."""
    sizes = {key: len(value) for key, value in raw.items() if isinstance(value, list)}
    if "scene" in raw:
        yield from _checked("scene", raw["scene"], "scenes", sizes)
    for array, references in _REFERENCES.items():
        for i, item in enumerate(raw.get(array, [])):
            for path, target in references:
                for where, index in _values(item, path, f"{array}[{i}]"):
                    yield from _checked(where, index, target, sizes)
    yield from _material_textures(raw, sizes)
    yield from _light_references(raw)


def _values(node: Any, path: tuple[str, ...], where: str) -> Iterator[tuple[str, Any]]:
    """(JSON path, value) of what ``path`` reaches from ``node`` (missing keys reach nothing)."""
    if not path:
        yield where, node
        return
    key, rest = path[0], path[1:]
    if key == "*":
        if isinstance(node, list):
            for i, value in enumerate(node):
                yield from _values(value, rest, f"{where}[{i}]")
        elif isinstance(node, dict):
            for name, value in node.items():
                yield from _values(value, rest, f"{where}.{name}")
    elif isinstance(node, dict) and key in node:
        yield from _values(node[key], rest, f"{where}.{key}")


def _checked(where: str, index: Any, target: str, sizes: dict[str, int]
             ) -> Iterator[tuple[str, str, Any, int]]:
    """The reference at ``where`` if ``index`` is not an integer in [0, len(target))."""
    count = sizes.get(target, 0)
    if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < count:
        yield where, target, index, count


def _material_textures(raw: dict, sizes: dict[str, int]) -> Iterator[tuple[str, str, Any, int]]:
    """Texture references of materials (``texture_slots``)."""
    for i, material in enumerate(raw.get("materials", [])):
        for where, index in texture_slots(material, f"materials[{i}]"):
            yield from _checked(f"{where}.index", index, "textures", sizes)


def texture_slots(material: Any, where: str) -> Iterator[tuple[str, Any]]:
    """(JSON path, texture index) of every ``…Texture`` object of a material (its JSON, as
    parsed, at ``where``), in the core material and in its extensions (KHR_materials_*:
    clearcoatTexture, transmissionTexture…)."""
    if not isinstance(material, dict):
        return
    for key, value in material.items():
        if key.endswith("Texture") and isinstance(value, dict) and "index" in value:
            yield f"{where}.{key}", value["index"]
        elif key in ("pbrMetallicRoughness", "extensions") or key.startswith("KHR_"):
            yield from texture_slots(value, f"{where}.{key}")


def _light_references(raw: dict) -> Iterator[tuple[str, str, Any, int]]:
    """A node's KHR_lights_punctual ``light`` into the root extension's ``lights``."""
    root = raw.get("extensions")
    extension = root.get(_LIGHTS) if isinstance(root, dict) else None
    lights = extension.get("lights", []) if isinstance(extension, dict) else []
    sizes = {f"{_LIGHTS} lights": len(lights) if isinstance(lights, list) else 0}
    for i, node in enumerate(raw.get("nodes", [])):
        for where, index in _values(node, ("extensions", _LIGHTS, "light"), f"nodes[{i}]"):
            yield from _checked(where, index, f"{_LIGHTS} lights", sizes)
