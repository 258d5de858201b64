"""A generated tree for the foliage mode (baker/light/foliage.py): a trunk, a crown of alpha-cut
leaf quads, a ground and a patch of grass marked in its node's extras.

Everything is built with whole-array numpy (``leaves`` and ``blades`` make every quad at once),
so a crown of 500,000 leaves takes a second. The same ``seed`` gives the same file.

    python assets/foliage_scenes.py 200000 tree.glb     # a crown of 200,000 leaves
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

if __package__ in (None, ""):  # run as a script: make the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from assets.gltf_builder import GltfBuilder, box, cylinder, quad, transformed  # noqa: E402
from assets.light_scenes import _add_light  # noqa: E402

LEAF = (0.12, 0.35, 0.06)
BARK = (0.30, 0.20, 0.12)
SOIL = (0.35, 0.30, 0.22)
GRASS = (0.20, 0.40, 0.08)


def leaf_texture(size: int = 16) -> np.ndarray:
    """(size, size, 4) uint8 sRGB: white, opaque inside the ellipse inscribed in the square and
    clear outside it (the leaf's shape, cut by alpha MASK)."""
    t = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    inside = (t[:, None] ** 2 + (t[None, :] / 0.6) ** 2) <= 1.0
    pixels = np.full((size, size, 4), 255, np.uint8)
    pixels[..., 3] = np.where(inside, 255, 0)
    return pixels


def _quads(centres: np.ndarray, u: np.ndarray, v: np.ndarray) -> tuple:
    """(positions, triangles, normals, uv) of quads centre ± u ± v (each (n, 3)): 4 corners and
    2 triangles each, facing u × v, uv 0–1 over each quad."""
    n = len(centres)
    corners = np.stack([centres - u - v, centres + u - v, centres + u + v, centres - u + v],
                       axis=1)
    normal = np.cross(u, v)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    base = 4 * np.arange(n)[:, None]
    triangles = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=0)
    uv = np.tile([[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]], (n, 1))
    return (corners.reshape(-1, 3), triangles.astype(np.int64),
            np.repeat(normal, 4, axis=0), uv)


def leaves(count: int, centre, radii, size: float, seed: int = 0) -> tuple:
    """``count`` leaf quads of side ``size`` at points uniform in the ellipsoid ``centre`` ±
    ``radii``, each turned at random (uniform normal, uniform twist about it)."""
    rng = np.random.default_rng(seed)
    direction = rng.normal(size=(count, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    at = np.asarray(centre) + direction * rng.uniform(0, 1, (count, 1)) ** (1 / 3) * radii
    normal = rng.normal(size=(count, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    helper = np.where(np.abs(normal[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(normal, u)
    twist = rng.uniform(0, 2 * np.pi, (count, 1))
    u, v = np.cos(twist) * u + np.sin(twist) * v, -np.sin(twist) * u + np.cos(twist) * v
    return _quads(at, 0.5 * size * u, 0.5 * size * v)


def blades(count: int, extent: float, height: float, width: float, seed: int = 1) -> tuple:
    """``count`` upright grass blades (quads ``width`` × ``height``) standing on y = 0 at
    points uniform in the square ±``extent``/2, each turned at random about +Y."""
    rng = np.random.default_rng(seed)
    base = np.column_stack([rng.uniform(-extent / 2, extent / 2, count), np.zeros(count),
                            rng.uniform(-extent / 2, extent / 2, count)])
    angle = rng.uniform(0, np.pi, count)
    u = 0.5 * width * np.column_stack([np.cos(angle), np.zeros(count), np.sin(angle)])
    v = np.tile([[0.0, 0.5 * height, 0.0]], (count, 1))
    return _quads(base + v, u, v)


def tree(leaf_count: int = 2000, grass_count: int = 500, seed: int = 0,
         leaf_size: float = 0.15) -> GltfBuilder:
    """A tree on a 12 × 12 m ground: a trunk 3 m high (radius 0.15 m), a crown of
    ``leaf_count`` alpha-cut double-sided leaf quads in an ellipsoid of radii (2, 1.5, 2) m
    centred 4 m up, and ``grass_count`` blades 0.3 m high on a 3 × 3 m patch beside it (node
    ``grass``, ``extras.foliage = "grass"``). No light: the lightmap is the obscurance. Leaf
    size shrinks as 1/sqrt of the count past 2000 leaves so the crown's density stays alike."""
    b = GltfBuilder()
    soil = b.material("soil", SOIL)
    bark = b.material("bark", BARK)
    leaf = b.material("leaf", LEAF, double_sided=True, alpha_mode="MASK", alpha_cutoff=0.5,
                      base_color_image=leaf_texture())
    grass = b.material("grass", GRASS, double_sided=True)
    size = leaf_size * min(1.0, np.sqrt(2000 / max(leaf_count, 1)))
    nodes = {
        "ground": b.node("ground", b.shape_mesh("ground", quad(12.0, 12.0), material=soil)),
        "trunk": b.node("trunk", b.shape_mesh("trunk", transformed(
            cylinder(0.15, 3.0, 12), translation=(0, 1.5, 0)), material=bark)),
        "crown": b.node("crown", b.shape_mesh("crown", leaves(
            leaf_count, (0.0, 4.0, 0.0), (2.0, 1.5, 2.0), size, seed), material=leaf)),
    }
    if grass_count:
        nodes["grass"] = b.node("grass", b.shape_mesh("grass", transformed(
            blades(grass_count, 3.0, 0.3, 0.03, seed + 1), translation=(4.0, 0.0, 0.0)),
            material=grass), extras={"foliage": "grass"})
    b.info["nodes"] = nodes
    return b


BOXES = {"near": (2.6, 0.25, 0.0), "far": (5.2, 0.25, -5.2)}
"""Where ``tree_and_boxes`` puts its two 0.5 m boxes: one beside the crown, one far from it."""


def tree_and_boxes(moves: dict[str, tuple], **tree_args) -> GltfBuilder:
    """``tree(**tree_args)`` lit by a point light 6 m up, with the boxes of ``BOXES`` (nodes
    "near" and "far"); ``moves``: node name → its translation instead (an edit to rebake)."""
    b = tree(**tree_args)
    _add_light(b, "point", (3.0, 6.0, 2.0), (0.0, -1.0, 0.0), intensity=20.0)
    stone = b.material("stone", (0.6, 0.6, 0.6))
    for name, at in BOXES.items():
        b.info["nodes"][name] = b.node(name, b.shape_mesh(name, box((0.5, 0.5, 0.5)),
                                                          material=stone))
        b._nodes[b.info["nodes"][name]].translation = list(at)
    for name, at in moves.items():
        b._nodes[b.info["nodes"][name]].translation = list(at)
    return b


if __name__ == "__main__":
    count = int(sys.argv[1]) if len(sys.argv) > 1 else 200_000
    out = Path(sys.argv[2]) if len(sys.argv) > 2 else Path("tree.glb")
    print(tree(count, grass_count=5000).save(out))
