"""The node tree walked into float64 world matrices (``walk_nodes``): local matrices from a
node's matrix or T·R·S (``trs_matrices``), the nodes an animation moves (``moving_nodes``,
``animated_nodes``), and EXT_mesh_gpu_instancing's transforms (``gpu_instances``)."""

from __future__ import annotations

from typing import Any

import numpy as np

from baker.errors import InputError
from baker.gltf import budget, objects
from baker.gltf.context import Context, checked_item, finite, invalid, or_default, schema
from baker.gltf.read_meshes import read_attribute


def walk_nodes(ctx: Context) -> list[tuple[int, np.ndarray]]:
    """Every node of the scene with its (4, 4) float64 world matrix, depth first, children in order.

    The scene is ``document.scene`` (0 when unset); a file without scenes uses every root node.
    A node reached twice (a cycle, or two parents) is an error: glTF node hierarchies are trees;
    so is one nested deeper than ``budget.MAX_NODE_DEPTH``. The nodes' local matrices are made
    all at once (``_local_matrices``), so that a walk costs a matrix product a node.
    """
    document = ctx.document
    if document.scenes:
        s = or_default(document.scene, 0)
        scene = checked_item(document.scenes, s, "scenes", ctx.file, "scene")
        roots = [_checked_node(ctx, r, f"scenes[{s}].nodes") for r in scene.nodes or []]
    else:
        with schema(ctx.file, "nodes"):
            children = {c for node in document.nodes for c in node.children or []}
        roots = [i for i in range(len(document.nodes)) if i not in children]
    local = _local_matrices(ctx)
    out, visited = [], set()
    stack = [(root, np.eye(4), 1) for root in reversed(roots)]
    while stack:
        index, parent, depth = stack.pop()
        where = f"nodes[{index}]"
        if index in visited:
            raise InputError(
                "node is reached twice: the node hierarchy has a cycle or a node with two parents",
                file=ctx.file,
                where=where,
                fix="give every node at most one parent (glTF node hierarchies are trees) and export again",
            )
        budget.check_depth(depth, where, ctx.file)
        visited.add(index)
        node = document.nodes[index]
        with schema(ctx.file, where):
            matrix = local.get(index)
            with np.errstate(over="ignore", invalid="ignore"):  # checked in _check_reach
                world = parent if matrix is None else parent @ matrix
            children = [_checked_node(ctx, c, f"{where}.children") for c in node.children or []]
        out.append((index, world))
        stack.extend((child, world, depth + 1) for child in reversed(children))
    return out


def _checked_node(ctx: Context, index: Any, referrer: str) -> int:
    """``index`` if it names a node, else an InputError at ``referrer``."""
    checked_item(ctx.document.nodes, index, "nodes", ctx.file, referrer)
    return index


def _local_matrices(ctx: Context) -> dict[int, np.ndarray]:
    """Each node's (4, 4) float64 local matrix that is not the identity: its ``matrix``
    (column-major in the file), or T @ R @ S, made for all such nodes at once."""
    matrices: dict[int, np.ndarray] = {}
    trs: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]] = []
    for index, node in enumerate(ctx.document.nodes):
        where = f"nodes[{index}]"
        with schema(ctx.file, where):
            if node.matrix is not None:
                matrices[index] = finite(ctx, node.matrix, 16, f"{where}.matrix").reshape(4, 4).T
            elif not (node.translation is None and node.rotation is None and node.scale is None):
                trs.append((index,
                            finite(ctx, or_default(node.translation, [0.0, 0.0, 0.0]), 3,
                                   f"{where}.translation"),
                            finite(ctx, or_default(node.rotation, [0.0, 0.0, 0.0, 1.0]), 4,
                                   f"{where}.rotation"),
                            finite(ctx, or_default(node.scale, [1.0, 1.0, 1.0]), 3,
                                   f"{where}.scale")))
    if trs:
        zero = next((i for i, _, rotation, _ in trs if not np.any(rotation)), None)
        if zero is not None:
            raise invalid("rotation quaternion has zero length", ctx.file, f"nodes[{zero}]")
        indices, translation, rotation, scale = zip(*trs)
        made = trs_matrices(np.array(translation), np.array(rotation), np.array(scale))
        matrices.update(zip(indices, made))
    return matrices


def trs_matrices(
    translation: np.ndarray, rotation: np.ndarray, scale: np.ndarray, *, file: str = "", where: str = ""
) -> np.ndarray:
    """(k, 4, 4) float64 matrices T @ R @ S from (k, 3) translations, (k, 4) quaternions
    [x, y, z, w] and (k, 3) scales. Quaternions are normalised; scale is used as given."""
    norm = np.linalg.norm(rotation, axis=1)
    if (norm == 0).any():
        raise invalid("rotation quaternion has zero length", file, where)
    x, y, z, w = (rotation / norm[:, None]).T
    r = np.empty((len(rotation), 3, 3))
    r[:, 0, 0] = 1 - 2 * (y * y + z * z)
    r[:, 0, 1] = 2 * (x * y - z * w)
    r[:, 0, 2] = 2 * (x * z + y * w)
    r[:, 1, 0] = 2 * (x * y + z * w)
    r[:, 1, 1] = 1 - 2 * (x * x + z * z)
    r[:, 1, 2] = 2 * (y * z - x * w)
    r[:, 2, 0] = 2 * (x * z - y * w)
    r[:, 2, 1] = 2 * (y * z + x * w)
    r[:, 2, 2] = 1 - 2 * (x * x + y * y)
    out = np.zeros((len(rotation), 4, 4))
    out[:, :3, :3] = r * scale[:, None, :]
    out[:, :3, 3] = translation
    out[:, 3, 3] = 1.0
    return out


def animated_nodes(document: objects.GLTF2, paths: tuple[str, ...]) -> set[int]:
    """Nodes that an animation channel drives on one of ``paths`` ("weights": morph targets;
    "translation", "rotation", "scale": the node's transform)."""
    nodes = set()
    for animation in document.animations or []:
        for channel in animation.channels or []:
            target = channel.target
            if target is not None and target.path in paths and isinstance(target.node, int):
                nodes.add(target.node)
    return nodes


def moving_nodes(document: objects.GLTF2) -> set[int]:
    """Nodes whose world transform an animation changes: its own, or an ancestor's."""
    stack = list(animated_nodes(document, ("translation", "rotation", "scale")))
    moving: set[int] = set()
    while stack:
        index = stack.pop()
        if index in moving or not 0 <= index < len(document.nodes):
            continue
        moving.add(index)
        stack.extend(c for c in document.nodes[index].children or [] if isinstance(c, int))
    return moving


def gpu_instances(ctx: Context, index: int, node: objects.Node) -> np.ndarray | None:
    """(k, 4, 4) local matrices T_k @ R_k @ S_k of EXT_mesh_gpu_instancing, None without it."""
    extension = (node.extensions or {}).get("EXT_mesh_gpu_instancing")
    if not isinstance(extension, dict) or not extension.get("attributes"):
        return None
    where = f"nodes[{index}].extensions.EXT_mesh_gpu_instancing.attributes"
    attributes = extension["attributes"]
    read = {}
    for name, width in (("TRANSLATION", 3), ("ROTATION", 4), ("SCALE", 3)):
        if attributes.get(name) is not None:
            read[name] = read_attribute(ctx, attributes, name, (width,), None, where.removesuffix(".attributes"))
    counts = {len(v) for v in read.values()}
    if len(counts) > 1:
        raise invalid(f"TRANSLATION/ROTATION/SCALE have different counts {sorted(counts)}", ctx.file, where)
    if not read:
        return None
    k = counts.pop()
    translation = read.get("TRANSLATION", np.zeros((k, 3)))
    rotation = read.get("ROTATION", np.tile([0.0, 0.0, 0.0, 1.0], (k, 1)))
    scale = read.get("SCALE", np.ones((k, 3)))
    if not all(np.isfinite(v).all() for v in read.values()):
        raise invalid("instance transforms hold NaN or infinite values", ctx.file, where)
    return trs_matrices(translation, rotation, scale, file=ctx.file, where=where)
