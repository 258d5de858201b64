"""A punctual light as the estimators see it: where it is, where it points, how bright.

The glTF loader makes them from ``KHR_lights_punctual`` (``gltf.read_lights``); the direct-light
estimators (``light/``) read them, knowing nothing of the file they came from.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Light:
    """A KHR_lights_punctual light placed in the world by a node.

    kind: "directional", "point" or "spot". colour: (3,) float64 linear RGB. intensity: lux
    (lm/m²) for directional lights, candela (lm/sr) for point and spot lights, as the extension
    defines them (node scale changes neither). position: (3,) float64 world, from the node's world
    matrix (meaningless for directional lights). direction: (3,) float64 unit world vector the light
    shines along, the node's local −Z (meaningless for point lights). range: metres beyond which
    a point/spot light is zero (inf when the file gives none). inner_cone / outer_cone: spot cone
    half-angles, radians. radius: metres of the sphere a point/spot light is (soft shadows), None
    when the file gives none (the bake's fallback setting applies). angular_diameter: radians of
    a directional light's disc (the sun's is about 0.0093), None when the file gives none.
    ``index`` is the light's index in the extension's ``lights`` array, ``node`` the node using it.
    """

    index: int
    node: int
    name: str
    kind: str
    colour: np.ndarray
    intensity: float
    position: np.ndarray
    direction: np.ndarray
    range: float = float("inf")
    inner_cone: float = 0.0
    outer_cone: float = float(np.pi / 4)
    radius: float | None = None
    angular_diameter: float | None = None
