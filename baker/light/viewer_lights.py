"""What a glTF viewer's punctual lights add to a surface: glTF's BRDF as three.js evaluates it.

A file baked with the emissive carrier keeps its ``KHR_lights_punctual`` lights
(``output/write.py``): its material copies have no diffuse response, so a viewer's lights give
them only their specular highlights, which the bake leaves out. ``baker preview`` adds them with
this module, so that it shows what the viewers show (tests/test_browser.py compares them).

For each light, at a surface point with shading normal n seen along v:

    L += (diffuse / π + F · V · D) · E_l · (n · l)

the diffuse colour being base colour × (1 − metallic) × (1 − transmission), F Schlick's Fresnel
of F0 = mix(((ior − 1)/(ior + 1))², base colour, metallic), V the height-correlated Smith
visibility and D the GGX distribution of α = roughness² (three.js's ``BRDF_GGX``), and E_l the
light's colour × intensity, over the distance squared for point and spot lights, with the
extension's range window and spot cone. Viewers cast no shadows unless an application asks, so
neither does this.
"""

from __future__ import annotations

import numpy as np

from baker.geometry.surface import interpolate, viewer_brdf_at
from baker.geometry.world import World
from baker.light.direct_estimators import range_window, spot_attenuation
from baker.punctual import Light

_MIN_ROUGHNESS = 0.0525  # three.js clamps roughness here (its lights' highlights stay finite)


def punctual_shading(lights: tuple[Light, ...], surfaces, world: World, tris: np.ndarray,
                     bary: np.ndarray, points: np.ndarray, to_eye: np.ndarray) -> np.ndarray:
    """(k, 3) linear radiance the punctual ``lights`` add at points (k, 3) of world
    triangles ``tris`` (k,) at barycentric ``bary`` (k, 3), seen from unit directions ``to_eye``
    (k, 3) pointing from the points to the eye; ``surfaces``: the loaded scene, for what its
    materials look like there (``surface.viewer_brdf_at``)."""
    out = np.zeros((len(tris), 3))
    if not lights or not len(tris):
        return out
    normal = _facing(interpolate(world.normals, world, tris, bary),
                     world.geometric_normals(tris), to_eye)
    base, metallic, roughness, transmission, ior = viewer_brdf_at(surfaces, world, tris, bary)
    dielectric = (((ior - 1.0) / (ior + 1.0)) ** 2)[:, None]
    f0 = (1.0 - metallic[:, None]) * dielectric + metallic[:, None] * base
    diffuse = base * ((1.0 - metallic) * (1.0 - np.clip(transmission, 0.0, 1.0)))[:, None]
    alpha = np.maximum(roughness, _MIN_ROUGHNESS) ** 2
    for light in lights:
        to_light, irradiance = _incident(light, points)
        cos_l = np.einsum("kj,kj->k", normal, to_light)
        lit = cos_l > 0
        if not lit.any():
            continue
        brdf = diffuse[lit] / np.pi + _ggx(normal[lit], to_eye[lit], to_light[lit], f0[lit],
                                           alpha[lit])
        out[lit] += brdf * (irradiance[lit] * cos_l[lit])[:, None] * light.colour * light.intensity
    return out


def _facing(normal: np.ndarray, flat: np.ndarray, to_eye: np.ndarray) -> np.ndarray:
    """Unit shading normals (k, 3) from interpolated vertex normals (``flat``, the triangles'
    own, where they vanish), turned towards the eye (a double-sided surface seen from behind)."""
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    unit = np.where(length > 1e-12, normal / np.maximum(length, 1e-300), flat)
    return np.where((np.einsum("kj,kj->k", unit, to_eye) < 0)[:, None], -unit, unit)


def _incident(light: Light, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit directions (k, 3) from the points to ``light`` and its irradiance (k,) there on a
    surface facing it, at unit colour and intensity."""
    if light.kind == "directional":
        return (np.broadcast_to(-light.direction, points.shape).copy(),
                np.ones(len(points)))
    offset = light.position - points
    distance = np.maximum(np.linalg.norm(offset, axis=1), 1e-6)
    to_light = offset / distance[:, None]
    irradiance = range_window(light, distance) / np.maximum(distance * distance, 0.01)
    if light.kind == "spot":
        irradiance = irradiance * spot_attenuation(light, -to_light)
    return to_light, irradiance


def _ggx(n: np.ndarray, v: np.ndarray, l: np.ndarray, f0: np.ndarray,
         alpha: np.ndarray) -> np.ndarray:
    """(k, 3) three.js's ``BRDF_GGX``: Schlick Fresnel × Smith height-correlated visibility ×
    GGX distribution, for unit vectors (k, 3) and α (k,)."""
    h = v + l
    h /= np.maximum(np.linalg.norm(h, axis=1, keepdims=True), 1e-300)
    dot_nl = np.clip(np.einsum("kj,kj->k", n, l), 0.0, 1.0)
    dot_nv = np.clip(np.einsum("kj,kj->k", n, v), 0.0, 1.0)
    dot_nh = np.clip(np.einsum("kj,kj->k", n, h), 0.0, 1.0)
    dot_vh = np.clip(np.einsum("kj,kj->k", v, h), 0.0, 1.0)
    fresnel = f0 + (1.0 - f0) * ((1.0 - dot_vh) ** 5)[:, None]
    a2 = alpha * alpha
    gv = dot_nl * np.sqrt(a2 + (1.0 - a2) * dot_nv * dot_nv)
    gl = dot_nv * np.sqrt(a2 + (1.0 - a2) * dot_nl * dot_nl)
    visibility = 0.5 / np.maximum(gv + gl, 1e-12)
    denominator = dot_nh * dot_nh * (a2 - 1.0) + 1.0
    distribution = a2 / (np.pi * denominator * denominator)
    return fresnel * (visibility * distribution)[:, None]
