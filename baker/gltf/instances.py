"""One ``Instance`` per placed (node, primitive), or per GPU instance of it (``instantiate``),
with why it gets no lightmap; the meshes the nodes use, their accessors' declared sizes checked
against the budget before any is read (``check_declared_sizes``), and the reach of every mesh
from the origin (``MAX_WORLD_UNITS``)."""

from __future__ import annotations

from typing import Any, Iterator

import numpy as np

from baker.errors import InputError
from baker.gltf import budget
from baker.gltf.accessors import TYPE_SHAPES
from baker.gltf.context import Context, attributes_of, checked_item, schema
from baker.gltf.read_meshes import read_mesh
from baker.gltf.read_nodes import animated_nodes, gpu_instances, moving_nodes
from baker.gltf.scene import Instance, Material, Primitive


MAX_WORLD_UNITS = 1e12
"""Farthest a mesh may lie from the origin, in scene units (Embree's float32 has a resolution of
1e5 units there already; a scale of 1e300 would overflow every later computation)."""


MAX_SCENE_COMPONENTS = 1 << 28
"""Most numbers the accessors baker reads may declare in all (2 GiB as float64: some 40 million
vertices with normals and UVs); those without a bufferView, ``budget.MAX_UNBACKED_NUMBERS``."""


_GPU_REASON = "GPU-instanced (EXT_mesh_gpu_instancing): occluder only"


_SKIN_REASON = "skinned: occluder only (rest pose)"




_MOVING = "node-animated (an animation moves it or an ancestor)"


_MOVING_REASON = {  # what becomes of a node-animated instance, by ``Settings.animated``
    "bake": f"{_MOVING}: baked in its rest pose, its lightmap does not follow the animation "
            "(--animated occlude or skip leaves it out)",
    "occlude": f"{_MOVING}: occluder only (rest pose), no lightmap (--animated occlude)",
    "skip": f"{_MOVING}: left out, not even as an occluder (--animated skip)",
}


_MORPH_REASON = "morph-animated (animated weights): occluder only (rest pose)"


def instantiate(
    ctx: Context, placements: list[tuple[int, np.ndarray]], materials: list[Material],
    unbaked: list[str], animated: str, input_bytes: int,
) -> tuple[list[Primitive], list[Instance]]:
    """Read the meshes the placed nodes use (in mesh order) and make their instances (in walk order).

    ``unbaked``: per material, why its primitives get no lightmap ("" when they do);
    ``animated``: what becomes of node-animated instances (``load``); ``input_bytes``: the
    input's size, which bounds the triangles the nodes may place (``budget.check_placed``,
    checked once the meshes are read, before any GPU instance's transform is)."""
    document = ctx.document
    used = _used_meshes(ctx, placements)
    primitives: list[Primitive] = []
    slots: dict[int, list[int | None]] = {}
    for mesh in sorted(used):
        slots[mesh] = []
        for primitive in read_mesh(ctx, mesh, len(materials)):
            slots[mesh].append(None if primitive is None else len(primitives))
            if primitive is not None:
                primitives.append(primitive)
    budget.check_placed(
        [(index, _copies(ctx, document.nodes[index]) * sum(
            len(primitives[slot].triangles) for slot in slots[document.nodes[index].mesh]
            if slot is not None))
         for index, _ in placements if document.nodes[index].mesh is not None],
        input_bytes, ctx.file)
    instances = []
    morphed = animated_nodes(document, ("weights",))
    moving = moving_nodes(document)
    for index, world in placements:
        node = document.nodes[index]
        if node.mesh is None:
            continue
        animated_here = index in moving and node.skin is None
        if animated_here and animated != "occlude":
            ctx.skip(f"nodes[{index}]", _MOVING_REASON[animated])
            if animated == "skip":
                continue
        with schema(ctx.file, f"nodes[{index}].extensions.EXT_mesh_gpu_instancing"):
            gpu = gpu_instances(ctx, index, node)
        worlds = [world] if gpu is None else list(world @ gpu)
        _check_reach(ctx, index, worlds, [primitives[slot] for slot in slots[node.mesh]
                                          if slot is not None])
        node_reasons = [_GPU_REASON] if gpu is not None else []
        node_reasons += [_SKIN_REASON] if node.skin is not None else []
        node_reasons += [_MORPH_REASON] if index in morphed and node_reasons[-1:] != [_SKIN_REASON] else []
        node_reasons += [_MOVING_REASON["occlude"]] if animated_here and animated == "occlude" else []
        for slot in slots[node.mesh]:
            if slot is None:
                continue
            material_reason = unbaked[primitives[slot].material]
            reasons = node_reasons + ([material_reason] if material_reason else [])
            for k, matrix in enumerate(worlds):
                instances.append(
                    Instance(
                        node=index,
                        primitive=slot,
                        world=np.array(matrix, dtype=np.float64),
                        baked=not reasons,
                        reason="; ".join(reasons),
                        gpu_instance=None if gpu is None else k,
                    )
                )
    return primitives, instances


def _copies(ctx: Context, node: Any) -> int:
    """How many times a node places its mesh: the count its EXT_mesh_gpu_instancing transforms'
    accessors declare (the largest; ``gpu_instances`` checks that they agree), else 1."""
    extension = (node.extensions or {}).get("EXT_mesh_gpu_instancing")
    attributes = extension.get("attributes") if isinstance(extension, dict) else None
    if not isinstance(attributes, dict):
        return 1
    accessors = ctx.document.accessors or []
    counts = [accessors[index].count for index in attributes.values()
              if isinstance(index, int) and 0 <= index < len(accessors)
              and isinstance(accessors[index].count, int)]
    return max(counts, default=1)


def _used_meshes(ctx: Context, placements: list[tuple[int, np.ndarray]]) -> list[int]:
    """The meshes the placed nodes use, in mesh order (each checked to be one of the file's)."""
    used = set()
    for index, _ in placements:
        mesh = ctx.document.nodes[index].mesh
        if mesh is not None:
            checked_item(ctx.document.meshes, mesh, "meshes", ctx.file, f"nodes[{index}].mesh")
            used.add(mesh)
    return sorted(used)


def check_declared_sizes(ctx: Context, placements: list[tuple[int, np.ndarray]]) -> None:
    """Refuse, before any buffer is read, accessors baker would read (the attributes and
    indices of every primitive of the meshes the nodes use, the GPU instances' transforms; each
    accessor once) that declare more than ``MAX_SCENE_COMPONENTS`` numbers in all, or more
    than ``budget.MAX_UNBACKED_NUMBERS`` in accessors without a bufferView (zeros, whose count
    nothing in the file bounds: a 1 kB file of an index accessor of 30 M took a minute). A
    3 KB file of accessors without a bufferView and large counts took 9 GB and 86 s before it
    failed. The error names the largest accessor and where it is used. Entries that are not
    valid are left for the reading to report; morph targets are not read."""
    accessors = ctx.document.accessors or []
    seen: set[int] = set()
    totals = {"all": [0, -1, 0, ""], "unbacked": [0, -1, 0, ""]}  # total, largest, its count, at
    for at, index in _read_accessors(ctx, placements):
        if not isinstance(index, int) or not 0 <= index < len(accessors) or index in seen:
            continue
        seen.add(index)
        accessor = accessors[index]
        shape = TYPE_SHAPES.get(accessor.type)
        if shape is None or not isinstance(accessor.count, int) or accessor.count < 0:
            continue
        numbers = accessor.count * shape[0] * shape[1]
        for key in ("all",) + (("unbacked",) if accessor.bufferView is None else ()):
            tally = totals[key]
            tally[0] += numbers
            if numbers > tally[2]:
                tally[1:] = [index, numbers, at]
    for key, limit, what in (("unbacked", budget.MAX_UNBACKED_NUMBERS,
                              "accessors without a bufferView (zeros: no data behind them)"),
                             ("all", MAX_SCENE_COMPONENTS, "accessors")):
        total, largest, largest_count, used_at = totals[key]
        if total > limit:
            raise InputError(
                f"the {what} baker reads declare {total:,} numbers in all, more than baker "
                f"holds ({limit:,}, {8 * limit >> 20:,} MiB as float64); the largest, "
                f"accessors[{largest}], declares {largest_count:,}",
                file=ctx.file,
                where=f"{used_at} → accessors[{largest}]",
                fix="check the accessors' counts; split the scene, or bake its parts apart",
            )


def _read_accessors(ctx: Context, placements: list[tuple[int, np.ndarray]]
                    ) -> Iterator[tuple[str, Any]]:
    """(JSON path, accessor index) of every accessor baker reads for the placed nodes: the
    attributes and indices of the primitives of their meshes, and their GPU instances'
    transforms (``EXT_mesh_gpu_instancing``)."""
    document = ctx.document
    for mesh in _used_meshes(ctx, placements):
        for j, primitive in enumerate(document.meshes[mesh].primitives or []):
            for name, index in _accessors_of(primitive):
                yield f"meshes[{mesh}].primitives[{j}].{name}", index
    for node, _ in placements:
        extension = (document.nodes[node].extensions or {}).get("EXT_mesh_gpu_instancing")
        attributes = extension.get("attributes") if isinstance(extension, dict) else None
        for name, index in (attributes.items() if isinstance(attributes, dict) else ()):
            yield f"nodes[{node}].extensions.EXT_mesh_gpu_instancing.attributes.{name}", index


def _accessors_of(primitive: Any) -> list[tuple[str, Any]]:
    """(JSON path within the primitive, accessor index) of every accessor of a primitive baker
    reads: its attributes and its indices."""
    return ([(f"attributes.{k}", v) for k, v in attributes_of(primitive).items()]
            + [("indices", primitive.indices)])


def _check_reach(ctx: Context, index: int, worlds: list[np.ndarray],
                 primitives: list[Primitive]) -> None:
    """Refuse a node whose world matrices (one, or one per GPU instance) take its mesh farther
    than ``MAX_WORLD_UNITS`` from the origin on some axis, or to no finite place (a scale of
    1e300 overflows): a bound from the matrices' absolute values and the mesh's largest local
    coordinate, computed without overflow warnings."""
    if not primitives or not worlds:
        return
    local = max(float(np.abs(p.positions).max(initial=0.0)) for p in primitives)
    matrices = np.asarray(worlds, np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        reach = (np.abs(matrices[:, :3, :3]).sum(axis=2) * local + np.abs(matrices[:, :3, 3])).max()
    if not (np.isfinite(reach) and reach <= MAX_WORLD_UNITS):
        raise InputError(
            f"its world transform places the mesh up to {reach:.3g} units from the origin, more "
            f"than baker bakes ({MAX_WORLD_UNITS:.0e})",
            file=ctx.file,
            where=f"nodes[{index}]",
            fix="check the scale and translation of this node and of its parents "
                "(a scale of 1e300 is an export error)",
        )
