"""Small scenes with non-diffuse materials, for the material tests (issue 4, docs/design.md §2).

Every function returns a ``GltfBuilder`` and records in ``builder.info`` what the tests need.
Metres, linear RGB. The floor is node 0 unless said otherwise: a horizontal quad at y = 0,
normal +Y.
"""

from __future__ import annotations

import numpy as np

from assets.gltf_builder import (GltfBuilder, box, box_face, quad, rotation_matrix, transformed,
                                 uv_sphere)
from baker.gltf import objects

# The extensions' own sample values (their README examples in the Khronos glTF repository).
TRANSMISSION = {"KHR_materials_transmission": {"transmissionFactor": 1.0},
                "KHR_materials_ior": {"ior": 1.5}}
VOLUME = {"KHR_materials_volume": {"thicknessFactor": 1.0, "attenuationDistance": 0.006,
                                   "attenuationColor": [0.5, 0.5, 0.5]}}
DIFFUSE_TRANSMISSION = {"KHR_materials_diffuse_transmission": {
    "diffuseTransmissionFactor": 0.25, "diffuseTransmissionColorFactor": [1.0, 0.5, 0.0]}}
UNLIT = {"KHR_materials_unlit": {}}


def mirror_wall(size: float = 4.0, height: float = 2.0, mirror: bool = True,
                colour=(0.9, 0.9, 0.9)) -> GltfBuilder:
    """A ``size``-metre white floor and, along its x = size/2 edge, a wall ``height`` tall
    facing −x: a perfect mirror (metallic 1, roughness 0, base ``colour``), or diffuse of that
    colour when not ``mirror``. info: floor, wall (nodes), wall_x (its plane), and the wall as
    a rectangle (``tests/plane_reference.py``: centre, normal, axes, half)."""
    b = GltfBuilder()
    floor = b.material("floor", (0.8, 0.8, 0.8))
    wall = b.material("mirror" if mirror else "wall", colour,
                      metallic=1.0 if mirror else 0.0, roughness=0.0 if mirror else 1.0)
    b.info["floor"] = b.node("floor", b.shape_mesh("floor", quad(size, size), material=floor))
    face = transformed(box_face((0.0, height, size), "-x"),
                       translation=(size / 2, height / 2, 0.0))
    b.info["wall"] = b.node("wall", b.shape_mesh("wall", face, material=wall))
    b.info["wall_x"] = size / 2
    b.info["rectangle"] = dict(centre=(size / 2, height / 2, 0.0), normal=(-1.0, 0.0, 0.0),
                               axes=((0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
                               half=(height / 2, size / 2))
    return b


def facing_mirrors(gap: float = 1.0, size: float = 1.0) -> GltfBuilder:
    """Two parallel square mirrors (size × size, base 0.9, metallic 1, roughness 0) facing
    each other across ``gap`` on the x axis, and a small grey diffuse floor strip between them
    at y = −size/2 (so long chains end somewhere). info: gap."""
    b = GltfBuilder()
    mirror = b.material("mirror", (0.9, 0.9, 0.9), metallic=1.0, roughness=0.0)
    grey = b.material("floor", (0.5, 0.5, 0.5))
    left = transformed(box_face((0.0, size, size), "+x"), translation=(-gap / 2, 0.0, 0.0))
    right = transformed(box_face((0.0, size, size), "-x"), translation=(gap / 2, 0.0, 0.0))
    b.node("mirrors", b.shape_mesh("mirrors", _merge(left, right), material=mirror))
    strip = transformed(quad(gap, size), translation=(0.0, -size / 2, 0.0))
    b.info["floor"] = b.node("floor", b.shape_mesh("floor", strip, material=grey))
    b.info["gap"] = gap
    return b


def _merge(*shapes):
    from assets.gltf_builder import merged

    return merged(*shapes)


def alpha_cut_quad(height: float = 0.5, size: float = 2.0, blend: bool = False) -> GltfBuilder:
    """A 4 m white floor under a horizontal ``size``-metre quad at ``height`` facing down whose
    texture is fully transparent (alpha 0) on its x < 0 half and opaque (alpha 255) on the
    other: alphaMode MASK, cutoff 0.5, double-sided (or BLEND when ``blend``).
    info: floor, leaf (nodes), height, size."""
    b = GltfBuilder()
    floor = b.material("floor", (0.8, 0.8, 0.8))
    pixels = np.full((8, 8, 4), 255, np.uint8)
    pixels[4:, :, 3] = 0  # v > 0.5: x < 0 (a quad's v runs along −x; turning it over keeps that)
    leaf = b.material("leaf", (0.3, 0.6, 0.2), alpha_mode="BLEND" if blend else "MASK",
                      alpha_cutoff=None if blend else 0.5, double_sided=True,
                      base_color_image=pixels)
    b.info["floor"] = b.node("floor", b.shape_mesh("floor", quad(4.0, 4.0), material=floor))
    down = transformed(quad(size, size), rotation=rotation_matrix((1, 0, 0), 180),
                       translation=(0.0, height, 0.0))
    b.info["leaf"] = b.node("leaf", b.shape_mesh("leaf", down, material=leaf))
    b.info["height"], b.info["size"] = height, size
    return b


def glass_slab(thickness: float = 0.2, ior: float = 1.5) -> GltfBuilder:
    """A clear glass slab (transmission 1, IOR ``ior``, KHR_materials_volume thickness) 2 m
    square, ``thickness`` thick, its top at y = 1, over a floor whose x > 0 half is red and
    x < 0 half is green (two quads). info: floor_red, floor_green, slab (nodes)."""
    b = GltfBuilder()
    red = b.material("red", (0.9, 0.1, 0.1))
    green = b.material("green", (0.1, 0.9, 0.1))
    glass = b.material("glass", (1.0, 1.0, 1.0), roughness=0.0, extensions={
        "KHR_materials_transmission": {"transmissionFactor": 1.0},
        "KHR_materials_ior": {"ior": float(ior)},
        "KHR_materials_volume": {"thicknessFactor": float(thickness)}})
    b.info["floor_red"] = b.node("red", b.shape_mesh(
        "red", transformed(quad(4.0, 4.0), translation=(2.0, 0.0, 0.0)), material=red))
    b.info["floor_green"] = b.node("green", b.shape_mesh(
        "green", transformed(quad(4.0, 4.0), translation=(-2.0, 0.0, 0.0)), material=green))
    slab = transformed(box((2.0, thickness, 2.0)), translation=(0.0, 1.0 - thickness / 2, 0.0))
    b.info["slab"] = b.node("slab", b.shape_mesh("slab", slab, material=glass))
    return b


def material_zoo() -> GltfBuilder:
    """One box per kind of material, side by side on a floor: diffuse, mirror, clear glass,
    unlit, translucent (diffuse transmission 1). info["boxes"]: kind → node index."""
    b = GltfBuilder()
    floor = b.material("floor", (0.8, 0.8, 0.8))
    kinds = {
        "diffuse": b.material("diffuse", (0.5, 0.5, 0.5)),
        "mirror": b.material("mirror", (0.9, 0.9, 0.9), metallic=1.0, roughness=0.0),
        "glass": b.material("glass", (1.0, 1.0, 1.0), roughness=0.0, extensions=TRANSMISSION),
        "unlit": b.material("unlit", (0.7, 0.7, 0.7), extensions=UNLIT),
        "translucent": b.material("wax", (0.9, 0.8, 0.6), extensions={
            "KHR_materials_diffuse_transmission": {"diffuseTransmissionFactor": 1.0}}),
    }
    b.node("floor", b.shape_mesh("floor", quad(12.0, 4.0), material=floor))
    b.info["boxes"] = {}
    for i, (kind, material) in enumerate(kinds.items()):
        mesh = b.shape_mesh(kind, box((0.8, 0.8, 0.8)), material=material)
        b.info["boxes"][kind] = b.node(kind, mesh, translation=(-5.0 + 2.0 * i, 0.4, 0.0))
    return b


WAX = {"KHR_materials_diffuse_transmission": {"diffuseTransmissionFactor": 0.5},
       "KHR_materials_volume": {"thicknessFactor": 0.3, "attenuationDistance": 0.25,
                                "attenuationColor": [0.9, 0.6, 0.4]}}
"""A wax: half diffuse, half translucent, a closed volume whose light fades within 0.25 m."""


def wax_cylinder(radius: float = 0.5, height: float = 0.2, extensions: dict | None = None,
                 scale: float = 1.0) -> GltfBuilder:
    """A closed wax cylinder (``WAX`` unless ``extensions``), ``radius`` × ``height``, standing
    on a 3 m grey floor, scaled by ``scale`` about the origin: its top cap's texels near the rim
    have little wax behind them, those at its centre ``height`` or more (§4 inner obscurances).
    info: floor, wax (nodes), radius, height (unscaled)."""
    from assets.gltf_builder import cylinder

    b = GltfBuilder()
    floor = b.material("floor", (0.5, 0.5, 0.5))
    wax = b.material("wax", (0.9, 0.8, 0.6), extensions=WAX if extensions is None else extensions)
    b.info["floor"] = b.node("floor", b.shape_mesh("floor", quad(3.0, 3.0), material=floor))
    shape = transformed(cylinder(radius, height, segments=48), translation=(0.0, height / 2, 0.0))
    b.info["wax"] = b.node("wax", b.shape_mesh("wax", shape, material=wax),
                           scale=(scale, scale, scale))
    b.info["radius"], b.info["height"] = radius, height
    return b


def leaf(height: float = 0.2, translucency: float = 0.4, facing: str = "up") -> GltfBuilder:
    """A 1 m square leaf at ``height`` over a 4 m green-grey floor, under the open sky.

    facing "up": double-sided, ``KHR_materials_diffuse_transmission`` factor ``translucency``,
    colour (1, 0.8, 0.5) — a leaf (§4). "up-opaque" / "down-opaque": the same quad with an
    opaque single-sided diffuse material, facing up or turned over (its front is then the
    leaf's back face). info: floor, leaf (nodes)."""
    b = GltfBuilder()
    floor = b.material("floor", (0.3, 0.7, 0.4))
    extensions = ({"KHR_materials_diffuse_transmission": {
        "diffuseTransmissionFactor": float(translucency),
        "diffuseTransmissionColorFactor": [1.0, 0.8, 0.5]}} if facing == "up" else None)
    material = b.material("leaf", (0.4, 0.8, 0.3), double_sided=facing == "up",
                          extensions=extensions)
    b.info["floor"] = b.node("floor", b.shape_mesh("floor", quad(4.0, 4.0), material=floor))
    turn = rotation_matrix((1, 0, 0), 180 if facing == "down-opaque" else 0)
    sheet = transformed(quad(1.0, 1.0), rotation=turn, translation=(0.0, height, 0.0))
    b.info["leaf"] = b.node("leaf", b.shape_mesh("leaf", sheet, material=material))
    return b


def metal_glass_room() -> GltfBuilder:
    """A 4 × 3 × 4 m room seen from outside (its walls face in; the +z wall is left open so the
    default view sees in), lit by a point lamp under the ceiling and an emissive ceiling panel,
    holding every kind of surface a viewer shades differently: a rough gold sphere (metallic
    1), a glossy steel sphere (metallic 1, roughness 0.3), a box whose metallicRoughnessTexture
    is metal on its left half and dielectric on its right, a half-transmissive frosted pane,
    a clear glass pane (transmission 1) and a red and a white dielectric. info["nodes"]: name →
    node index."""
    b = GltfBuilder()
    white = b.material("white", (0.75, 0.75, 0.75), roughness=0.8)
    red = b.material("red", (0.7, 0.1, 0.08), roughness=0.6)
    gold = b.material("gold", (1.0, 0.77, 0.34), metallic=1.0, roughness=0.7)
    steel = b.material("steel", (0.56, 0.57, 0.58), metallic=1.0, roughness=0.3)
    frosted = b.material("frosted", (0.8, 0.9, 1.0), roughness=0.5,
                         extensions={"KHR_materials_transmission": {"transmissionFactor": 0.5}})
    glass = b.material("glass", (1.0, 1.0, 1.0), roughness=0.0, extensions=TRANSMISSION)
    panel = b.material("panel", (0.8, 0.8, 0.8), emissive=(1.0, 0.95, 0.85),
                       emissive_strength=4.0)
    halves = np.zeros((8, 8, 3), np.uint8)
    halves[..., 1] = 160  # roughness 0.63
    halves[:, :4, 2] = 255  # metal on the left half (u < 0.5)
    mixed = b.material("mixed", (0.9, 0.6, 0.5), metallic=1.0, roughness=1.0)
    b._materials[mixed].pbrMetallicRoughness.metallicRoughnessTexture = objects.TextureInfo(
        index=b._image_texture(halves, "mixed metal roughness"))
    nodes = {}
    walls = {"floor": ("-y", white), "ceiling": ("+y", white), "left": ("-x", red),
             "right": ("+x", white), "back": ("-z", white)}
    for name, (face, material) in walls.items():
        nodes[name] = b.node(name, b.shape_mesh(name, box_face((4.0, 3.0, 4.0), face,
                                                               inward=True), material=material),
                             translation=(0.0, 1.5, 0.0))
    nodes["panel"] = b.node("panel", b.shape_mesh("panel", transformed(
        quad(1.0, 1.0), rotation=rotation_matrix((1, 0, 0), 180.0)), material=panel),
        translation=(0.8, 2.98, -0.8))
    for name, material, radius, at in (("gold", gold, 0.45, (-0.9, 0.45, -0.6)),
                                       ("steel", steel, 0.35, (0.9, 0.35, 0.4))):
        nodes[name] = b.node(name, b.shape_mesh(name, uv_sphere(radius, 16, 32),
                                                material=material), translation=at)
    nodes["mixed"] = b.node("mixed", b.shape_mesh("mixed", box((0.6, 0.6, 0.6)),
                                                  material=mixed), translation=(0.3, 0.3, -1.2))
    for name, material, x in (("frosted", frosted, -0.2), ("glass", glass, 1.4)):
        nodes[name] = b.node(name, b.shape_mesh(name, box((0.9, 1.2, 0.04)), material=material),
                             translation=(x, 0.6, 1.0))
    lamp = b.light("point", name="lamp", intensity=6.0, color=(1.0, 0.9, 0.8))
    nodes["lamp"] = b.node("lamp", translation=(-0.5, 2.4, 0.2),
                           extensions={"KHR_lights_punctual": {"light": lamp}})
    b.info["nodes"] = nodes
    return b
