"""What the bake dropped or changed in the input, counted for the report (``report["warnings"]``).

Exporters leave debris — collinear triangles, zero-length or missing normals, NaNs, materials
baker does not understand. None of it stops a bake; each kind is counted once here, not printed
per triangle, so a technical artist sees at a glance what to clean up.
"""

from __future__ import annotations

import numpy as np

from baker.geometry.world import World
from baker.gltf.scene import Primitive, Scene


def input_warnings(scene: Scene, world: World) -> dict[str, int]:
    """Warning text → how many times it happened, for the baked instances of ``scene``; every
    ``Scene.skipped`` entry (left out or changed while loading, by reason) included."""
    out: dict[str, int] = {}
    baked = np.array([inst.baked for inst in scene.instances], bool)
    tris = np.flatnonzero(baked[world.tri_instance]) if len(world.triangles) else np.zeros(0, np.int64)
    counts = {
        "degenerate triangles (no area): given no texels": int(world.degenerate[tris].sum()),
        "primitives without normals: flat normals computed": len(
            {inst.primitive for inst in scene.instances
             if inst.baked and scene.primitives[inst.primitive].normals is None}),
        "vertices with a zero-length (or NaN) normal: their triangles' own normal used": _zero_normals(
            world, baked),
        "primitives without a UV set their material's textures read: sampled at UV (0, 0) there, "
        "as viewers do": len({inst.primitive for inst in scene.instances
                              if _lacks_uv(scene, scene.primitives[inst.primitive])}),
    }
    out.update({text: n for text, n in counts.items() if n})
    for skipped in scene.skipped:
        out[skipped.reason] = out.get(skipped.reason, 0) + 1
    return out


def _zero_normals(world: World, baked: np.ndarray) -> int:
    """Vertices of baked instances given a NORMAL of zero length (unusable as a direction)."""
    if not len(world.positions):
        return 0
    vertex_instance = np.repeat(np.arange(len(baked)), np.diff(world.vertex_start))
    zero = world.smooth & ~np.any(world.normals, axis=1)
    return int(np.count_nonzero(zero & baked[vertex_instance]))


def _lacks_uv(scene: Scene, prim: Primitive) -> bool:
    """Whether a texture of ``prim``'s material reads a TEXCOORD set ``prim`` does not have."""
    return any(ref.texcoord >= len(prim.texcoords) for ref in scene.materials[prim.material].textures())
