"""Extreme and stiff scenes for the numerics tests (issue 7, DESIGN.md §7).

Each function returns a ``GltfBuilder`` (assets/gltf_builder.py); tests save and bake it.
"""

from __future__ import annotations

import numpy as np

from assets.gltf_builder import GltfBuilder, box


def closed_room(scale: float = 1.0, offset=(0.0, 0.0, 0.0), albedo: float = 0.5,
                emission: float = 0.0) -> GltfBuilder:
    """A closed box room of side 2·``scale`` seen from inside, centred at ``offset`` (world units),
    walls of one grey ``albedo``; ``emission`` > 0 makes the walls glow uniformly."""
    b = GltfBuilder()
    wall = b.material("wall", (albedo,) * 3, emissive=(min(emission, 1.0),) * 3,
                      emissive_strength=max(emission, 1.0) if emission > 1.0 else None)
    shape = box((2.0 * scale,) * 3, inward=True)
    b.node("room", b.shape_mesh("room", shape, material=wall), translation=tuple(offset))
    return b


def single_triangle(size: float = 1.0) -> GltfBuilder:
    """One triangle of legs ``size`` facing up, nothing else."""
    b = GltfBuilder()
    positions = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -size], [size, 0.0, 0.0]])
    b.node("tri", b.mesh("tri", positions, np.array([[0, 2, 1]]), material=b.material("w")))
    return b
