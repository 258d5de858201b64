"""The atlas from lightmap UVs the artist authored (``--uv N``: a primitive's TEXCOORD_N),
checked, instead of xatlas's unwrap.

A DCC tool's second UV set (what Unity, Unreal and Godot bake into) is one page: every baked
primitive's UVs in [0, 1] of a ``page_size``² page, no two baked triangles covering the same
texel, and the UV islands (charts) at least ``padding`` texels apart at that page size, as
xatlas keeps its charts. Each check that fails is an ``InputError`` naming the mesh and
primitive and the fix. Instances of one mesh share its UVs, so they overlap: an authored set
suits meshes used once (the error says so).
"""

from __future__ import annotations

import numpy as np

from baker.atlas.layout import Atlas, InstanceUV
from baker.atlas.rasterise import cover
from baker.atlas.unwrap import baked_instances, frame_area
from baker.errors import InputError
from baker.geometry.rows import joined_roots
from baker.geometry.world import World
from baker.gltf.scene import Scene
from baker.jit import jit
from baker.settings import Resolved

_INSIDE = 1e-6  # texels a texel centre must lie inside two triangles for them to overlap
_BAND = 512  # page rows compared at once in the padding check (bounds its memory)


def authored_atlas(scene: Scene, world: World, settings: Resolved) -> Atlas:
    """One ``page_size``² page holding every baked instance on its primitive's TEXCOORD_N
    (``settings.uv``), after the checks of the module notes. ``texel_density`` is the mean
    the set gives: sqrt(page texels its triangles cover / their world area)."""
    n, page = int(settings.uv), int(settings.page_size)
    units = tuple(_instance_uv(scene, world, i, n) for i in baked_instances(scene))
    uv_area = sum(_uv_areas(u.uv[u.triangles]).sum() for u in units) * page * page
    area = frame_area(scene, world)
    atlas = Atlas(width=page, height=page, page_count=1 if units else 0,
                  texel_density=float(np.sqrt(uv_area / area)) if area > 0 else 1.0,
                  padding=int(settings.padding), instances=units)
    if units:
        check_layout(scene, world, atlas, n)
    return atlas


def check_layout(scene: Scene, world: World, atlas: Atlas, n: int) -> None:
    """Raise InputError when two baked triangles of ``atlas`` (a one-page atlas on TEXCOORD_n)
    overlap, or two of its UV islands come closer than its padding."""
    _check_overlaps(scene, atlas, n)
    _check_padding(scene, world, atlas, n)


def _where(scene: Scene, instance: int) -> str:
    """``nodes[i] meshes[m].primitives[p]`` of a scene instance."""
    inst = scene.instances[instance]
    prim = scene.primitives[inst.primitive]
    return f"nodes[{inst.node}] meshes[{prim.mesh}].primitives[{prim.index}]"


def _instance_uv(scene: Scene, world: World, instance: int, n: int) -> InstanceUV:
    """The instance on its primitive's own vertices and TEXCOORD_n, all on page 0; an
    InputError when the set is missing, not finite or leaves [0, 1]."""
    prim = scene.primitives[scene.instances[instance].primitive]
    where = _where(scene, instance)
    if len(prim.texcoords) <= n:
        have = ", ".join(f"TEXCOORD_{k}" for k in range(len(prim.texcoords))) or "no UV set"
        raise InputError(f"{where} has no TEXCOORD_{n} to bake into (it has {have})",
                         file=str(scene.path), where=f"{where}.attributes",
                         fix=f"give every baked primitive a TEXCOORD_{n} (a lightmap UV set) in "
                             "the DCC tool, or leave out --uv (baker unwraps)")
    triangles = world.triangles[world.instance_triangles(instance)] - world.vertex_start[instance]
    uv = np.asarray(prim.texcoords[n], np.float64)
    used = uv[np.unique(triangles)] if len(triangles) else uv[:0]
    if not np.isfinite(used).all() or (used.size and (used.min() < 0 or used.max() > 1)):
        low, high = np.nanmin(used, axis=0), np.nanmax(used, axis=0)
        raise InputError(
            f"TEXCOORD_{n} of {where} leaves [0, 1] (u {low[0]:.4g} to {high[0]:.4g}, "
            f"v {low[1]:.4g} to {high[1]:.4g}): a lightmap UV set must lie in one page",
            file=str(scene.path), where=f"{where}.attributes.TEXCOORD_{n}",
            fix="pack the lightmap UVs into [0, 1] in the DCC tool, or leave out --uv")
    return InstanceUV(instance=instance, vertices=np.arange(len(uv), dtype=np.int64),
                      triangles=triangles.astype(np.int64), uv=uv,
                      pages=np.zeros(len(triangles), np.int64))


def _uv_areas(corners: np.ndarray) -> np.ndarray:
    """Unsigned areas (k,) of triangles given as (k, 3, 2) corners."""
    a, b = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    return 0.5 * np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])


def _corners(atlas: Atlas) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every baked triangle's (k, 3, 2) corners in texels, its instance (k,) and its index
    within the instance (k,)."""
    corners = (np.concatenate([u.uv[u.triangles] for u in atlas.instances])
               * [atlas.width, atlas.height])
    owner = np.concatenate([np.full(len(u.triangles), u.instance) for u in atlas.instances])
    local = np.concatenate([np.arange(len(u.triangles)) for u in atlas.instances])
    return corners, owner, local


@jit
def _first_overlap(corners: np.ndarray, width: int, height: int, eps: float
                   ) -> tuple[int, int, int, int]:
    """The first texel centre (x, y) that two triangles both hold strictly inside (by more
    than ``eps`` texels from every edge), with the two triangles; (-1, -1, -1, -1) if none.
    ``corners``: (k, 3, 2) float64 in texels of a ``width`` × ``height`` page. A shared edge holds its
    centres in neither triangle, so adjacent triangles never count as overlapping."""
    owner = np.full(width * height, -1, np.int64)
    for t in range(corners.shape[0]):
        ax, ay = corners[t, 0, 0], corners[t, 0, 1]
        bx, by = corners[t, 1, 0], corners[t, 1, 1]
        cx, cy = corners[t, 2, 0], corners[t, 2, 1]
        area2 = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
        if area2 == 0.0:
            continue
        sign = 1.0 if area2 > 0 else -1.0
        lab = np.hypot(bx - ax, by - ay)
        lbc = np.hypot(cx - bx, cy - by)
        lca = np.hypot(ax - cx, ay - cy)
        x0 = max(int(np.floor(min(ax, bx, cx))), 0)
        x1 = min(int(np.ceil(max(ax, bx, cx))), width - 1)
        y0 = max(int(np.floor(min(ay, by, cy))), 0)
        y1 = min(int(np.ceil(max(ay, by, cy))), height - 1)
        for y in range(y0, y1 + 1):
            py = y + 0.5
            for x in range(x0, x1 + 1):
                px = x + 0.5
                e0 = sign * ((bx - ax) * (py - ay) - (by - ay) * (px - ax))
                e1 = sign * ((cx - bx) * (py - by) - (cy - by) * (px - bx))
                e2 = sign * ((ax - cx) * (py - cy) - (ay - cy) * (px - cx))
                if e0 > eps * lab and e1 > eps * lbc and e2 > eps * lca:
                    k = y * width + x
                    if owner[k] >= 0:
                        return x, y, owner[k], t
                    owner[k] = t
    return -1, -1, -1, -1


def _check_overlaps(scene: Scene, atlas: Atlas, n: int) -> None:
    """An InputError naming both triangles when two baked triangles cover one texel centre
    (they would share its light)."""
    corners, owner, local = _corners(atlas)
    x, y, first, second = _first_overlap(np.ascontiguousarray(corners), atlas.width,
                                         atlas.height, _INSIDE)
    if first < 0:
        return
    a, b = int(owner[first]), int(owner[second])
    same = scene.instances[a].primitive == scene.instances[b].primitive and a != b
    shared = (" (two instances of one mesh share its UVs: an authored lightmap set suits "
              "meshes used once)" if same else "")
    raise InputError(
        f"TEXCOORD_{n} overlaps itself: triangle {local[first]} of {_where(scene, a)} and "
        f"triangle {local[second]} of {_where(scene, b)} cover the same texel ({x}, {y}) of "
        f"the {atlas.width}×{atlas.height} page{shared}", file=str(scene.path),
        where=f"{_where(scene, b)}.attributes.TEXCOORD_{n}",
        fix="give every baked triangle its own place in the lightmap UVs in the DCC tool, or "
            "leave out --uv (baker unwraps)")


def _islands(atlas: Atlas) -> np.ndarray:
    """The UV island (chart) of every baked triangle (k,), in ``_corners`` order: triangles
    of one instance that share a corner's UV position are connected."""
    keys = []
    for u in atlas.instances:
        at = np.ascontiguousarray(u.uv[u.triangles].reshape(-1, 2) + 0.0)  # -0.0 is 0.0
        keys.append(np.column_stack([np.full(len(at), u.instance), at.view(np.int64)]))
    _unique, corner_key = np.unique(np.concatenate(keys), axis=0, return_inverse=True)
    return _components(corner_key.reshape(-1, 3).astype(np.int64), int(corner_key.max()) + 1)


def _components(corner_keys: np.ndarray, key_count: int) -> np.ndarray:
    """Connected components (k,) of triangles whose (k, 3) corners carry keys below
    ``key_count``: two triangles sharing a key are in one (``rows.joined_roots``); each
    component is named by its smallest key."""
    return joined_roots(corner_keys, key_count)[corner_keys[:, 0]]


def _check_padding(scene: Scene, world: World, atlas: Atlas, n: int) -> None:
    """An InputError when texels of two UV islands (as baker bakes them: every texel a
    triangle touches) lie within ``padding`` texels of each other, which dilation and
    bilinear filtering would bleed together."""
    pad = atlas.padding
    if pad == 0:
        return
    owner = _corners(atlas)[1]
    island = _islands(atlas)
    coverage = cover(atlas, world)
    baked = np.full(len(world.triangles), -1, np.int64)
    baked[np.concatenate([world.instance_triangles(u.instance) for u in atlas.instances])] = (
        np.arange(len(island)))
    width, height = atlas.width, atlas.height
    image = np.full(width * height, -1, np.int64)
    image[coverage.key.astype(np.int64)] = island[baked[coverage.triangle]]
    image = image.reshape(height, width)
    for top in range(0, height, _BAND):
        rows = image[top:min(top + _BAND + pad, height)]
        for dy in range(0, pad + 1):
            for dx in range(-pad, pad + 1):
                if dy == 0 and dx <= 0:
                    continue  # each pair of offsets once
                a = rows[:len(rows) - dy, max(0, -dx):width - max(0, dx)]
                b = rows[dy:, max(0, dx):width - max(0, -dx)]
                clash = (a >= 0) & (b >= 0) & (a != b)
                if clash.any():
                    y, x = np.argwhere(clash)[0]
                    _raise_padding(scene, atlas, n, top + int(y), int(x) + max(0, -dx),
                                   int(a[y, x]), int(b[y, x]), island, owner)


def _raise_padding(scene: Scene, atlas: Atlas, n: int, y: int, x: int, first: int, second: int,
                   island: np.ndarray, owner: np.ndarray) -> None:
    """The padding check's error, for islands ``first`` and ``second`` near texel (x, y)."""
    a = int(owner[np.flatnonzero(island == first)[0]])
    b = int(owner[np.flatnonzero(island == second)[0]])
    pad, side = atlas.padding, max(atlas.width, atlas.height)
    raise InputError(
        f"TEXCOORD_{n} has UV islands closer than --padding {pad} texels at page size {side}: "
        f"one of {_where(scene, a)} and one of {_where(scene, b)} near texel ({x}, {y})",
        file=str(scene.path), where=f"{_where(scene, b)}.attributes.TEXCOORD_{n}",
        fix=f"leave {pad} texels ({pad / side:.2%} of the page) between the UV islands in the "
            f"DCC tool, or bake with a larger --page-size or a smaller --padding")
