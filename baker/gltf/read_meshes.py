"""A mesh's primitives read into ``Primitive``s (``read_mesh``): positions, normals, UV sets,
colours and triangles (strips and fans expanded, ``expand_triangles``), each checked."""

from __future__ import annotations

import numpy as np

from baker.errors import InputError
from baker.gltf import objects
from baker.gltf.accessors import read_accessor
from baker.gltf.context import (MAX_ALBEDO, Context, attributes_of, checked_item, invalid,
                                or_default, referred, schema)
from baker.gltf.scene import Primitive


_MODE_NAMES = {
    0: "POINTS",
    1: "LINES",
    2: "LINE_LOOP",
    3: "LINE_STRIP",
    4: "TRIANGLES",
    5: "TRIANGLE_STRIP",
    6: "TRIANGLE_FAN",
}


_TRIANGLES, _STRIP, _FAN = 4, 5, 6


def read_mesh(ctx: Context, mesh: int, material_count: int) -> list[Primitive | None]:
    """The Primitives of ``meshes[mesh]``, None where a primitive is left out (see ``ctx.skipped``)."""
    out = []
    for j, primitive in enumerate(ctx.document.meshes[mesh].primitives):
        where = f"meshes[{mesh}].primitives[{j}]"
        with schema(ctx.file, where):
            out.append(_read_primitive(ctx, mesh, j, primitive, material_count, where))
    return out


def _read_primitive(
    ctx: Context, mesh: int, j: int, primitive: objects.Primitive, material_count: int, where: str
) -> Primitive | None:
    """One mesh primitive as local-space triangles, or None (recorded) when it has none."""
    mode = or_default(primitive.mode, _TRIANGLES)
    if mode not in (_TRIANGLES, _STRIP, _FAN):
        ctx.skip(where, f"mode {_MODE_NAMES.get(mode, mode)}: not triangles")
        return None
    attributes = attributes_of(primitive)
    if "POSITION" not in attributes:
        ctx.skip(where, "no POSITION attribute: nothing to place")
        return None
    positions = read_attribute(ctx, attributes, "POSITION", (3,), None, where)
    n = len(positions)
    bad = np.flatnonzero(~np.isfinite(positions).all(axis=1))
    if bad.size:
        raise InputError(
            f"POSITION has NaN or infinite values ({bad.size} vertices, first vertex {bad[0]})",
            file=ctx.file,
            where=f"{where}.attributes.POSITION",
            fix="clean up the mesh in your DCC tool (e.g. Blender: Mesh > Clean Up) and export again",
        )
    normals = read_attribute(ctx, attributes, "NORMAL", (3,), n, where) if "NORMAL" in attributes else None
    colors = read_attribute(ctx, attributes, "COLOR_0", (3, 4), n, where) if "COLOR_0" in attributes else None
    if colors is not None and colors.shape[1] == 3:
        colors = np.concatenate([colors, np.ones((n, 1))], axis=1)
    triangles = _triangles(ctx, primitive, mode, n, where)
    if not len(triangles):
        ctx.skip(where, "no whole triangle: nothing to bake or to occlude")
        return None
    texcoords = _texcoords(ctx, attributes, n, where)
    _check_counts(ctx, primitive, attributes, n, where)
    return Primitive(
        mesh=mesh,
        index=j,
        positions=positions,
        normals=normals,
        texcoords=texcoords,
        colors=colors,
        triangles=triangles,
        material=_material_index(ctx, primitive.material, material_count, where),
        has_morph_targets=bool(primitive.targets),
    )


def _check_counts(ctx: Context, primitive: objects.Primitive, attributes: dict, n: int,
                  where: str) -> None:
    """Require every attribute of the primitive and of its morph targets to hold ``n``
    elements, POSITION's count (the spec's rule; the ones read here checked theirs as they
    were read, the others — TANGENT, JOINTS_0, custom ones, morph targets — only here, from
    their accessors' counts): the output copies each vertex's row of each of them, and a
    shorter one would leave vertices without theirs. Indices are checked already
    (``references``)."""
    targets = primitive.targets or []
    named = [(f"attributes.{name}", index) for name, index in attributes.items()] + [
        (f"targets[{k}].{name}", index) for k, target in enumerate(targets)
        for name, index in (target if isinstance(target, dict) else vars(target)).items()
        if index is not None]
    for name, index in named:
        count = ctx.document.accessors[index].count
        if count != n:
            said = f"{count:,}" if isinstance(count, int) else repr(count)
            raise invalid(f"accessors[{index}] has a count of {said}, POSITION {n:,}: an "
                          "attribute has one element a vertex", ctx.file, f"{where}.{name}")


def read_attribute(
    ctx: Context, attributes: dict, name: str, widths: tuple[int, ...], n: int | None, where: str
) -> np.ndarray:
    """Vertex attribute ``name`` as (n, width) float64, its width and vertex count checked."""
    attribute_where = f"{where}.attributes.{name}"
    index = attributes[name]
    checked_item(ctx.document.accessors, index, "accessors", ctx.file, attribute_where)
    with referred(attribute_where):
        values = read_accessor(ctx.document, ctx.buffers, index, file=ctx.file).astype(np.float64)
    if values.shape[1] not in widths:
        expected = " or ".join(f"{w} components" for w in widths)
        raise invalid(
            f"{name} has {values.shape[1]} components per vertex, expected {expected}",
            ctx.file,
            attribute_where,
        )
    if n is not None and len(values) != n:
        raise invalid(f"{name} has {len(values)} vertices but POSITION has {n}", ctx.file, attribute_where)
    bad = ~np.isfinite(values)
    if name.startswith(("NORMAL", "TEXCOORD_", "COLOR_")) and bad.any():
        fallback = 1.0 if name.startswith("COLOR_") else 0.0
        values = np.where(bad, fallback, values)
        used = " (the triangle's own normal is used)" if name == "NORMAL" else ""
        ctx.skip(attribute_where, f"{int(bad.any(axis=1).sum())} vertices had NaN or infinite "
                                  f"values: set to {fallback:g}{used}")
    outside = ((values < 0) | (values > MAX_ALBEDO)).any(axis=1)
    if name.startswith("COLOR_") and outside.any():
        values = np.clip(values, 0.0, MAX_ALBEDO)
        ctx.skip(attribute_where, f"{int(outside.sum())} vertices had colours outside "
                                  f"[0, {MAX_ALBEDO:g}]: clamped")
    return values


def _texcoords(ctx: Context, attributes: dict, n: int, where: str) -> tuple[np.ndarray, ...]:
    """TEXCOORD_0, TEXCOORD_1, … each (n, 2) float64, up to the first missing set."""
    sets = []
    while f"TEXCOORD_{len(sets)}" in attributes:
        sets.append(read_attribute(ctx, attributes, f"TEXCOORD_{len(sets)}", (2,), n, where))
    for name in sorted(k for k in attributes if k.startswith("TEXCOORD_")):
        suffix = name[len("TEXCOORD_") :]
        if suffix.isdigit() and int(suffix) > len(sets):
            # Checked as the sets before the gap are: the output may fill the gap with the
            # lightmap's set, and this one is then read with them.
            read_attribute(ctx, attributes, name, (2,), n, where)
            reason = f"TEXCOORD_{len(sets)} is missing: UV sets after the gap are not used"
            ctx.skip(f"{where}.attributes.{name}", reason)
    return tuple(sets)


def _triangles(ctx: Context, primitive: objects.Primitive, mode: int, n: int, where: str) -> np.ndarray:
    """(m, 3) int64 vertex indices, strips and fans expanded, every index checked below n."""
    if primitive.indices is None:
        indices = np.arange(n, dtype=np.int64)
    else:
        checked_item(ctx.document.accessors, primitive.indices, "accessors", ctx.file, f"{where}.indices")
        with referred(f"{where}.indices"):
            indices = read_accessor(ctx.document, ctx.buffers, primitive.indices, file=ctx.file)
        if indices.dtype != np.int64 or indices.shape[1] != 1:
            raise invalid(
                "indices must be a SCALAR accessor of unsigned integers", ctx.file, f"{where}.indices"
            )
        indices = indices[:, 0]
        out_of_range = np.flatnonzero((indices < 0) | (indices >= n))
        if out_of_range.size:
            k = out_of_range[0]
            raise InputError(
                f"index {indices[k]} (element {k}) is out of range: the primitive has {n} vertices",
                file=ctx.file,
                where=f"{where}.indices",
                fix="the index and vertex data do not match: export the asset again",
            )
    return expand_triangles(indices, mode)


def expand_triangles(indices: np.ndarray, mode: int) -> np.ndarray:
    """Turn a (k,) index list of glTF mode 4, 5 or 6 into (m, 3) int64 triangles.

    Strip triangle i is (v_i, v_{i+1+i%2}, v_{i+2-i%2}), fan triangle i is (v_{i+1}, v_{i+2}, v_0),
    as glTF 2.0 §3.7.2.1 writes them, so the winding of the source is kept.
    """
    indices = np.asarray(indices, dtype=np.int64)
    if mode == _TRIANGLES:
        m = len(indices) // 3
        return indices[: 3 * m].reshape(m, 3)
    if len(indices) < 3:
        return np.zeros((0, 3), np.int64)
    i = np.arange(len(indices) - 2)
    if mode == _STRIP:
        odd = i & 1
        return np.stack([indices[i], indices[i + 1 + odd], indices[i + 2 - odd]], axis=1)
    if mode == _FAN:
        return np.stack([indices[i + 1], indices[i + 2], np.full_like(i, indices[0])], axis=1)
    raise ValueError(f"mode {mode} is not a triangle mode")


def _material_index(ctx: Context, material: int | None, material_count: int, where: str) -> int:
    """Index into Scene.materials: the glTF index, or the default material (last) when None."""
    if material is None:
        return material_count - 1
    checked_item(ctx.document.materials, material, "materials", ctx.file, f"{where}.material")
    return material
