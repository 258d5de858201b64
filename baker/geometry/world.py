"""Every instance's triangles in world space, in one set of flat arrays.

Built once per bake from the loaded ``Scene``; the unwrapper, the rasteriser, the tracer and the
material lookups all index into it. Positions are float64 world coordinates; ``center`` is the
middle of their bounds, which the tracer subtracts before going to float32, snapped to a grid of
1/16 of ``scale`` (the bounds' diagonal rounded up to a power of two): moving a node a little, even
at the edge of the scene, leaves the float32 frame — and with it every other ray — bit-identical,
so an incremental rebake can follow (docs/design.md §5).

Winding: glTF front faces are counter-clockwise, but a node whose world matrix has a negative
determinant mirrors its mesh, and the spec says its front faces are then clockwise. Triangles of
such instances are stored with two corners swapped, so that everywhere downstream the geometric
normal ``cross(b - a, c - a)`` points out of the front face.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from baker.frozen import read_only
from baker.geometry.repeats import repeated_triangles
from baker.geometry.surface import alpha_test
from baker.gltf.materials import material_table
from baker.gltf.scene import Scene
from baker.jit import jit
from baker.materials import MaterialTable


@dataclass(frozen=True)
class World:
    """All instances flattened. V world vertices, T world triangles, I instances.

    positions: (V, 3) float64 world. normals: (V, 3) float64 unit shading normals in world space
    (inverse-transpose transformed); rows of primitives without normals are the flat normal of one
    of their triangles, and ``smooth`` is False there. texcoords: tuple of (V, 2) float64, one per
    UV set used by any material texture (zeros where a primitive lacks the set). colors: (V, 4)
    float64 linear RGBA (ones where absent; ``coloured`` says whether any vertex has one).
    triangles: (T, 3) int64 into positions.
    tri_instance / tri_material: (T,) int64, the triangle's instance and its material.
    vertex_start / tri_start: (I + 1,) int64 offsets of each instance.
    alpha: ``surface.AlphaTest`` when some triangle may let rays through (alphaMode MASK or
    BLEND), else None; the tracer reads it.
    materials: the scene's materials as the estimators see them (``materials.MaterialTable``,
    rows follow ``tri_material``'s indices), made once with the world (``build_world``).
    """

    positions: np.ndarray
    normals: np.ndarray
    smooth: np.ndarray
    texcoords: tuple[np.ndarray, ...]
    colors: np.ndarray
    triangles: np.ndarray
    tri_instance: np.ndarray
    tri_material: np.ndarray
    vertex_start: np.ndarray
    tri_start: np.ndarray
    center: np.ndarray
    alpha: object = field(default=None, compare=False, repr=False)
    materials: MaterialTable | None = field(default=None, compare=False, repr=False)
    coloured: bool = True  # some vertex has a COLOR_0 (else ``colors`` is all ones)


    def __post_init__(self) -> None:
        read_only(self)  # a hand-off: later stages read it (frozen.py)

    def corners(self, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World positions of the three corners of triangles ``tris`` (k,), each (k, 3)."""
        v = self.triangles[tris]
        return self.positions[v[:, 0]], self.positions[v[:, 1]], self.positions[v[:, 2]]

    @property
    def scale(self) -> float:
        """The bounds' diagonal rounded up to a power of two (``bounds_scale``), world units: the
        length that epsilons scale with, unchanged by small moves of a node."""
        return bounds_scale(self.positions)

    def geometric_normals(self, tris: np.ndarray | None = None) -> np.ndarray:
        """Unit front-face normals (k, 3) of triangles ``tris`` (all when None); 0 for no area."""
        n = self._cross if tris is None else self._cross[tris]
        length = self._cross_length if tris is None else self._cross_length[tris]
        return np.divide(n, length[:, None], out=np.zeros_like(n), where=length[:, None] > 0)

    def areas(self, tris: np.ndarray | None = None) -> np.ndarray:
        """World areas (k,) of triangles ``tris`` (all when None)."""
        return 0.5 * (self._cross_length if tris is None else self._cross_length[tris])

    @cached_property
    def degenerate(self) -> np.ndarray:
        """(T,) bool: triangles without a usable area — collinear or collapsed corners, area at
        most 1e-12 of their longest edge squared (a sliver of aspect 10⁶ has 10⁻⁶). They have no
        front face to cast rays from, so they own no texel (the report counts them)."""
        out = self.areas() <= 1e-12 * longest_edges(self.positions, self.triangles)
        out.flags.writeable = False
        return out

    @cached_property
    def repeated(self) -> np.ndarray:
        """(T,) bool: triangles whose corners are those of a lower-numbered one, bit for bit
        and in the same winding — copies of one surface at one place, which the tracer leaves
        out (``repeats.py``); never a triangle without area or one the alpha test may let rays
        through."""
        eligible = ~self.degenerate
        if self.alpha is not None:
            eligible &= self.alpha.mode == 0
        out = repeated_triangles(self.positions, self.triangles, eligible)
        out.flags.writeable = False
        return out

    @cached_property
    def _cross(self) -> np.ndarray:
        """(T, 3) cross(b − a, c − a) of every triangle, made once: areas and normals are asked
        for by many stages (the same bits as made for the triangles asked)."""
        cross = triangle_cross(self.positions, self.triangles)
        cross.flags.writeable = False
        return cross

    @cached_property
    def _cross_length(self) -> np.ndarray:
        """(T,) |``_cross``|: twice each triangle's area."""
        length = np.linalg.norm(self._cross, axis=1)
        length.flags.writeable = False
        return length

    def instance_triangles(self, instance: int) -> np.ndarray:
        """The world triangle indices (k,) of one instance, in the primitive's order."""
        return np.arange(self.tri_start[instance], self.tri_start[instance + 1])


@jit
def longest_edges(positions: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(m,) the longest edge squared of each triangle (m, 3) of ``positions`` (n, 3), in one
    pass: each edge's dx² + dy² + dz², the bits of numpy's sum over its squared differences
    (a million triangles' corners gathered by numpy took a tenth of a second)."""
    out = np.empty(len(triangles))
    for i in range(len(triangles)):
        longest = 0.0
        for k in range(3):
            a, b = triangles[i, k], triangles[i, (k + 1) % 3]
            dx = positions[b, 0] - positions[a, 0]
            dy = positions[b, 1] - positions[a, 1]
            dz = positions[b, 2] - positions[a, 2]
            longest = max(longest, dx * dx + dy * dy + dz * dz)
        out[i] = longest
    return out


@jit
def triangle_cross(positions: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(m, 3) cross(b − a, c − a) of the triangles (m, 3) (corners a, b, c) of ``positions``
    (n, 3): np.cross's arithmetic, to the bit, in one pass without its temporaries (whose cost,
    on a scene of many small meshes, is mostly numpy's per-call overhead)."""
    out = np.empty((len(triangles), 3))
    for i in range(len(triangles)):
        a, b, c = triangles[i, 0], triangles[i, 1], triangles[i, 2]
        ux, uy, uz = (positions[b, 0] - positions[a, 0], positions[b, 1] - positions[a, 1],
                      positions[b, 2] - positions[a, 2])
        vx, vy, vz = (positions[c, 0] - positions[a, 0], positions[c, 1] - positions[a, 1],
                      positions[c, 2] - positions[a, 2])
        out[i, 0] = uy * vz - uz * vy
        out[i, 1] = uz * vx - ux * vz
        out[i, 2] = ux * vy - uy * vx
    return out


def _texcoord_sets(scene: Scene) -> int:
    """How many UV sets material textures use (at least 1): a primitive without one of them
    gets zeros there, the UV a viewer reads for an attribute a primitive does not have."""
    used = [ref.texcoord for m in scene.materials for ref in m.textures()]
    return max(used, default=0) + 1


def _flat_normals(positions: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Per-vertex normals for a primitive without NORMAL: each vertex takes the normal of the
    last triangle that uses it (only used where ``smooth`` is False, i.e. never interpolated)."""
    n = triangle_cross(positions, triangles.astype(np.int64, copy=False))
    normals = np.zeros_like(positions)
    normals[triangles.reshape(-1)] = np.repeat(n, 3, axis=0)
    return normals


def _unit(v: np.ndarray) -> np.ndarray:
    length = np.linalg.norm(v, axis=1, keepdims=True)
    return np.divide(v, length, out=np.zeros_like(v), where=length > 0)


def bounds_scale(positions: np.ndarray) -> float:
    """The diagonal of the bounds of ``positions`` (n, 3) rounded up to a power of two (1 for
    none or a single point): a scene-size length that moving a node changes only when the
    scene's size crosses a power of two."""
    if not len(positions):
        return 1.0
    diagonal = float(np.linalg.norm(positions.max(0) - positions.min(0)))
    if not (np.isfinite(diagonal) and diagonal > 0):
        return 1.0
    return float(2.0 ** np.ceil(np.log2(diagonal)))


@jit
def rows_times(rows: np.ndarray, matrices: np.ndarray) -> np.ndarray:
    """(k, n, 3) the row vectors ``rows`` (n, 3) times each of ``matrices`` (k, 3, 3): out[m,
    i, j] = (r_i0·M_0j + r_i1·M_1j) + r_i2·M_2j, each product rounded, summed in that order, in
    one compiled pass. ``rows @ matrix`` would hand the product to BLAS, whose kernels (fused
    multiply-adds, row blocks cut by its thread count) change the last bit with the number of
    threads: a cluster's nodes must build the driver's world to the bit."""
    out = np.empty((len(matrices), len(rows), 3))
    for m in range(len(matrices)):
        for i in range(len(rows)):
            x, y, z = rows[i, 0], rows[i, 1], rows[i, 2]
            for j in range(3):
                out[m, i, j] = (x * matrices[m, 0, j] + y * matrices[m, 1, j]) + z * matrices[m, 2, j]
    return out


def _cofactors(linear: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The cofactor matrices det(M)·M⁻¹ (k, 3, 3) of the linear parts ``linear`` (k, 3, 3) of
    instances' matrices, as rows, and det(M) (k,) from them (elementwise arithmetic, no
    LAPACK): both exist for a singular M too. Row r is the cross product of columns r + 1 and
    r + 2, each component a·b − c·d as ``np.cross`` rounds it."""
    (a, b, c), (d, e, f), (g, h, i) = np.moveaxis(linear, (1, 2), (0, 1))  # M's rows, (k,) each

    def cross(x0, x1, x2, y0, y1, y2) -> np.ndarray:
        return np.stack([x1 * y2 - x2 * y1, x2 * y0 - x0 * y2, x0 * y1 - x1 * y0], axis=-1)

    cofactor = np.stack([cross(b, e, h, c, f, i), cross(c, f, i, a, d, g),
                         cross(a, d, g, b, e, h)], axis=1)
    det = (cofactor[:, 0, 0] * a + cofactor[:, 0, 1] * d) + cofactor[:, 0, 2] * g
    return cofactor, det


def placed_positions(positions: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """(n, 3) world positions of mesh ``positions`` (n, 3) placed by the world ``matrix``
    (4, 4): M·p + t, through ``rows_times`` (every world position baker makes: the same bits
    on every machine and thread count)."""
    return _placed_positions(positions, matrix[None])[0]


def _placed_positions(positions: np.ndarray, matrices: np.ndarray) -> np.ndarray:
    """(k, n, 3) ``placed_positions`` of ``positions`` (n, 3) by each of ``matrices`` (k, 4, 4)."""
    return (rows_times(positions, np.ascontiguousarray(np.swapaxes(matrices[:, :3, :3], 1, 2)))
            + matrices[:, None, :3, 3])


def placed(prim, matrices: np.ndarray, cofactor: np.ndarray, det: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The instances of the primitive ``prim`` (``gltf.scene.Primitive``) placed by their world
    ``matrices`` (k, 4, 4), all at once: world positions (k, n, 3), unit world normals
    (k, n, 3) and triangles (k, m, 3) into each instance's own rows, two corners swapped where
    a matrix mirrors (see the module notes). Normals go through det(M)·M⁻ᵀ with det's sign
    (``cofactor`` (k, 3, 3) and ``det`` (k,), ``_cofactors`` of the matrices: a zero scale
    flattens them, never NaNs them); a primitive without normals gets flat ones
    (``_flat_normals``). Elementwise arithmetic and ``rows_times`` only: the same bits on every
    machine and thread count, however many instances are placed together."""
    positions = _placed_positions(prim.positions, matrices)
    mirrored = det < 0
    triangles = np.where(mirrored[:, None, None], prim.triangles[:, [0, 2, 1]], prim.triangles)
    k, n = positions.shape[:2]
    if prim.normals is None:
        rows = (triangles + n * np.arange(k)[:, None, None]).reshape(-1, 3)
        flat = _flat_normals(positions.reshape(-1, 3), rows)
        return positions, _unit(flat).reshape(k, n, 3), triangles
    turned = np.where((det >= 0)[:, None, None], cofactor, -cofactor)
    normals = rows_times(prim.normals, turned).reshape(-1, 3)
    return positions, _unit(normals).reshape(k, n, 3), triangles


def build_world(scene: Scene) -> World:
    """Transform every instance of ``scene`` to world space (``placed``) and concatenate them;
    classify its materials (``gltf.materials.material_table``). A pure function of the scene
    whose bits depend on no thread count: a cluster's nodes build the driver's world from the
    shipped scene (``pipeline.cluster``)."""
    sets = _texcoord_sets(scene)
    instances = scene.instances
    primitives = [scene.primitives[inst.primitive] for inst in instances]
    vertex_start = np.r_[0, np.cumsum([len(p.positions) for p in primitives], dtype=np.int64)]
    tri_start = np.r_[0, np.cumsum([len(p.triangles) for p in primitives], dtype=np.int64)]
    positions, normals = np.empty((vertex_start[-1], 3)), np.empty((vertex_start[-1], 3))
    smooth, colors = np.empty(vertex_start[-1], bool), np.ones((vertex_start[-1], 4))
    texcoords = tuple(np.zeros((vertex_start[-1], 2)) for _ in range(sets))
    triangles = np.empty((tri_start[-1], 3), np.int64)
    tri_instance, tri_material = np.empty(tri_start[-1], np.int64), np.empty(tri_start[-1], np.int64)
    by_primitive: dict[int, list[int]] = {}
    for i, inst in enumerate(instances):
        by_primitive.setdefault(inst.primitive, []).append(i)
    matrices = np.stack([inst.world for inst in instances]) if instances else np.zeros((0, 4, 4))
    cofactor, det = _cofactors(matrices[:, :3, :3])  # every instance's at once: elementwise
    for index, placed_here in by_primitive.items():  # every instance of a primitive at once
        prim, ids = scene.primitives[index], np.asarray(placed_here, np.int64)
        at, normal_at, tris = placed(prim, matrices[ids], cofactor[ids], det[ids])
        vrows = (vertex_start[ids][:, None] + np.arange(len(prim.positions))).reshape(-1)
        trows = (tri_start[ids][:, None] + np.arange(len(prim.triangles))).reshape(-1)
        positions[vrows], normals[vrows] = at.reshape(-1, 3), normal_at.reshape(-1, 3)
        smooth[vrows] = prim.normals is not None
        if prim.colors is not None:
            colors[vrows] = np.tile(prim.colors, (len(ids), 1))
        for k in range(min(sets, len(prim.texcoords))):
            texcoords[k][vrows] = np.tile(prim.texcoords[k], (len(ids), 1))
        triangles[trows] = (tris + vertex_start[ids][:, None, None]).reshape(-1, 3)
        tri_instance[trows] = np.repeat(ids, len(prim.triangles))
        tri_material[trows] = prim.material
    center = np.zeros(3)
    if len(positions):
        grid = bounds_scale(positions) / 16
        center = np.round((positions.min(0) + positions.max(0)) / 2 / grid) * grid
    world = World(
        positions=positions,
        normals=normals,
        smooth=smooth,
        texcoords=texcoords,
        colors=colors,
        triangles=triangles,
        tri_instance=tri_instance,
        tri_material=tri_material,
        vertex_start=vertex_start,
        tri_start=tri_start,
        center=center,
        coloured=any(p.colors is not None for p in primitives),
        materials=material_table(scene),
    )
    return replace(world, alpha=alpha_test(scene, world))
