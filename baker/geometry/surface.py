"""What a surface looks like at a point: diffuse albedo and emission, linear RGB.

Albedo R(Q) = baseColorFactor × baseColorTexture(uv) × COLOR_0 × the material's diffuse weight
(``materials.classify``: metal mirrors, glass and translucency take their share), the texture
sRGB-decoded and sampled bilinearly with its sampler's wrap modes at the UVs its
KHR_texture_transform maps the stored ones to (``texture_uv``). Emission = emissiveFactor × emissive strength ×
emissiveTexture(uv). Work is vectorised over points, looping only over the scene's materials.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from baker.geometry.rows import row_groups
from baker.gltf.scene import CLAMP_TO_EDGE, MIRRORED_REPEAT, Image, Scene, TextureRef
from baker.materials import BLEND, MASK
from baker.rowwise import dot_rows

if TYPE_CHECKING:  # world.build_world makes the AlphaTest below: a type, not an import
    from baker.geometry.world import World

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709 weights of linear RGB


def luminance(rgb: np.ndarray) -> np.ndarray:
    """(...,) the luminance of linear RGB (..., 3): R, G and B times ``LUMINANCE`` added in that
    order, the same bits for a row in any array (``rowwise.dot_rows``; ``rgb @ LUMINANCE``
    can differ in the last bit with the row's place, and the rebake's texels lie elsewhere
    than the full bake's)."""
    return dot_rows(rgb, LUMINANCE)

# sRGB transfer function, decoded once for every 8-bit value.
_levels = np.arange(256) / 255.0
SRGB_TO_LINEAR = np.where(_levels <= 0.04045, _levels / 12.92, ((_levels + 0.055) / 1.055) ** 2.4)
LINEAR_LEVELS = _levels  # a data texture's 8-bit levels, as values in [0, 1]


def _wrap(coord: np.ndarray, size: int, mode: int) -> np.ndarray:
    """Integer texel coordinates wrapped into [0, size) by a glTF sampler wrap mode."""
    if mode == CLAMP_TO_EDGE:
        return np.clip(coord, 0, size - 1)
    if mode == MIRRORED_REPEAT:
        period = np.mod(coord, 2 * size)
        return np.where(period < size, period, 2 * size - 1 - period)
    return np.mod(coord, size)


def sample_texture(image: Image, ref: TextureRef, uv: np.ndarray,
                   decode: np.ndarray = SRGB_TO_LINEAR) -> np.ndarray:
    """Bilinear lookup of an sRGB colour texture at glTF UVs (k, 2); returns linear RGB (k, 3).
    ``decode`` maps the 8-bit levels to values: SRGB_TO_LINEAR for colour, LINEAR_LEVELS for
    data textures (metallic-roughness).

    UV (0, 0) is the top-left corner of the image; texel centres sit at half-integers.
    """
    pixels = image.pixels
    h, w = pixels.shape[:2]
    uv = np.clip(uv, -1e6, 1e6)  # past this, float UVs hold no sub-texel position; int64-safe
    x = uv[:, 0] * w - 0.5
    y = uv[:, 1] * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
    xs = [_wrap(x0, w, ref.wrap_s), _wrap(x0 + 1, w, ref.wrap_s)]
    ys = [_wrap(y0, h, ref.wrap_t), _wrap(y0 + 1, h, ref.wrap_t)]

    def tap(yy: np.ndarray, xx: np.ndarray) -> np.ndarray:
        return decode[pixels[yy, xx, :3]]

    top = tap(ys[0], xs[0]) * (1 - fx) + tap(ys[0], xs[1]) * fx
    bottom = tap(ys[1], xs[0]) * (1 - fx) + tap(ys[1], xs[1]) * fx
    return top * (1 - fy) + bottom * fy


def interpolate(values: np.ndarray, world: World, tris: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """Interpolate a per-vertex array (V, c) at barycentric points (k, 3) of triangles (k,)."""
    return np.einsum("kv,kvc->kc", bary, values[world.triangles[tris]])


def texture_uv(world: World, ref: TextureRef, tris: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """The UVs (k, 2) at which ``ref`` is sampled at barycentric points (k, 3) of world
    triangles (k,): its UV set interpolated, then its KHR_texture_transform applied (an affine
    map, so transforming the interpolated UVs equals interpolating transformed corners)."""
    return transformed_uv(interpolate(world.texcoords[ref.texcoord], world, tris, bary),
                          ref.transform)


def transformed_uv(uv: np.ndarray, transform: tuple[float, ...] | None) -> np.ndarray:
    """UVs (..., 2) through a ``TextureRef.transform`` (a, b, c, d, e, f): u' = a·u + b·v + c,
    v' = d·u + e·v + f; as they are without one."""
    if transform is None:
        return uv
    a, b, c, d, e, f = transform
    return np.stack([a * uv[..., 0] + b * uv[..., 1] + c, d * uv[..., 0] + e * uv[..., 1] + f],
                    axis=-1)


def _textured(scene: Scene, world: World, tris: np.ndarray, bary: np.ndarray,
              factor: np.ndarray, texture_of, decode: np.ndarray = SRGB_TO_LINEAR) -> np.ndarray:
    """factor[material] (k, 3) times each material's texture (its levels read by ``decode``),
    looked up where it has one."""
    materials = world.tri_material[tris]
    result = factor[materials]  # a new array (fancy indexing)
    for m, material in enumerate(scene.materials):
        ref = texture_of(material)
        if ref is None:
            continue
        mask = materials == m
        if not mask.any():
            continue
        uv = texture_uv(world, ref, tris[mask], bary[mask])
        result[mask] *= sample_texture(scene.images[ref.image], ref, uv, decode)
    return result


def diffuse_factors(world: World) -> np.ndarray:
    """(M, 3) diffuse albedo factor of every material: baseColorFactor RGB × diffuse weight
    (``World.materials``)."""
    return np.array([c.diffuse for c in world.materials.classes], np.float64).reshape(-1, 3)


def metallic_roughness_at(scene: Scene, world: World, tris: np.ndarray,
                          bary: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(k,) metallic and (k,) roughness in [0, 1] at barycentric points (k, 3) of world
    triangles (k,): the factors × the metallicRoughnessTexture's blue and green channels
    (linear) where there is one, as viewers sample it per pixel."""
    factor = np.array([[1.0, m.roughness, m.metallic] for m in scene.materials],
                      np.float64).reshape(-1, 3)
    values = _textured(scene, world, tris, bary, factor, lambda m: m.metallic_roughness_texture,
                       LINEAR_LEVELS)
    return np.clip(values[:, 2], 0.0, 1.0), np.clip(values[:, 1], 0.0, 1.0)


def metallic_at(scene: Scene, world: World, tris: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """(k,) metallic in [0, 1] at barycentric points (``metallic_roughness_at``)."""
    return metallic_roughness_at(scene, world, tris, bary)[0]


def transmission_at(scene: Scene, world: World, tris: np.ndarray, bary: np.ndarray
                    ) -> np.ndarray:
    """(k,) KHR_materials_transmission's share in [0, 1] at barycentric points (k, 3) of world
    triangles (k,): its factor × the transmissionTexture's red channel (linear) where there is
    one, as viewers sample it per pixel."""
    factor = np.array([[m.transmission] * 3 for m in scene.materials], np.float64).reshape(-1, 3)
    values = _textured(scene, world, tris, bary, factor, lambda m: m.transmission_texture,
                       LINEAR_LEVELS)
    return np.clip(values[:, 0], 0.0, 1.0)


def viewer_diffuse_weight_at(scene: Scene, world: World, tris: np.ndarray,
                             bary: np.ndarray) -> np.ndarray:
    """(k,) the share of the base colour that a glTF viewer shades as diffuse at barycentric
    points (k, 3) of world triangles (k,), (1 − metallic) × (1 − transmission) (three.js's
    MeshPhysicalMaterial, and every viewer that follows glTF's BRDF): the part that a lightmap
    lights. A metal or glass therefore shows little or nothing of a MOZ_lightmap, whatever the
    bake gave it. Metallic is read per point (``metallic_at``): a textured metal's dielectric
    parts show a lightmap (LightsPunctualLamp's stand); transmission too (``transmission_at``)."""
    return ((1.0 - metallic_at(scene, world, tris, bary))
            * (1.0 - transmission_at(scene, world, tris, bary)))


def base_colour(scene: Scene, world: World, tris: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """Base colour (k, 3), linear RGB, at barycentric points (k, 3) of world triangles (k,):
    factor × texture × COLOR_0, every branch's weight left out (tints of mirrors and glass)."""
    factor = np.array([m.base_color[:3] for m in scene.materials], np.float64).reshape(-1, 3)
    colour = _textured(scene, world, tris, bary, factor, lambda m: m.base_color_texture)
    return _vertex_coloured(colour, world, tris, bary)


def albedo(scene: Scene, world: World, tris: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """Diffuse albedo (k, 3), linear RGB, at barycentric points (k, 3) of world triangles (k,)."""
    colour = _textured(scene, world, tris, bary, diffuse_factors(world),
                       lambda m: m.base_color_texture)
    return _vertex_coloured(colour, world, tris, bary)


def _vertex_coloured(colour: np.ndarray, world: World, tris: np.ndarray,
                     bary: np.ndarray) -> np.ndarray:
    """``colour`` (k, 3) × COLOR_0's RGB interpolated at the points; as it is when no vertex
    has a COLOR_0 (the interpolation of ones would cost as much as the rest)."""
    if not world.coloured:
        return colour
    return colour * interpolate(world.colors[:, :3], world, tris, bary)


# Barycentric points (4, 3) at which each triangle's albedo and emission are averaged.
MEAN_POINTS = np.array([[1 / 3, 1 / 3, 1 / 3], [2 / 3, 1 / 6, 1 / 6],
                        [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]])


def triangle_means(scene: Scene, world: World, lookup, texture_of) -> np.ndarray:
    """Mean (T, 3) of ``lookup`` (``albedo`` or ``emission``) over each world triangle's
    ``MEAN_POINTS``.

    Where a material has no texture for it (``texture_of(material)`` None), the lookup depends
    only on the material and the corner colours (alike everywhere without COLOR_0): it is made
    at the first triangle of each distinct pair and those bits given to the others (a scene of
    many objects has few pairs). Where it has one, the lookup depends on the triangle of its
    primitive, not on where an instance places it: it is made at the triangle of the
    primitive's first instance (1,714 GPU instances of a textured flower: 6.5 M triangles, 29 s
    and 10 GB, looked up as 3,818)."""
    t = len(world.triangles)
    if t == 0:
        return np.zeros((0, 3))
    textured = np.array([texture_of(m) is not None for m in scene.materials], bool)
    key = [world.tri_material[:, None], _first_instance_triangle(scene, world)[:, None]]
    key[1][~textured[world.tri_material]] = -1  # untextured: alike by material and colours
    if not (world.colors == world.colors[0]).all():
        corners = np.ascontiguousarray(world.colors[world.triangles])  # (T, 3, 4)
        key.append(corners.reshape(t, -1).view(np.int64))
    first, group = row_groups(np.concatenate(key, axis=1))
    tris = np.repeat(first, len(MEAN_POINTS))
    bary = np.tile(MEAN_POINTS, (len(first), 1))
    means = lookup(scene, world, tris, bary).reshape(len(first), len(MEAN_POINTS), 3).mean(axis=1)
    return means[group]


def _first_instance_triangle(scene: Scene, world: World) -> np.ndarray:
    """(T,) for each world triangle the same triangle of its primitive in the primitive's first
    instance (itself there)."""
    primitive = np.array([inst.primitive for inst in scene.instances], np.int64)
    _, first = np.unique(primitive, return_index=True)  # each primitive's first instance
    first_of = np.zeros(int(primitive.max()) + 1, np.int64)
    first_of[primitive[first]] = first
    own = world.tri_instance
    return world.tri_start[first_of[primitive[own]]] + np.arange(len(own)) - world.tri_start[own]


def albedo_means(scene: Scene, world: World) -> np.ndarray:
    """(T, 3) each world triangle's mean diffuse albedo (``triangle_means`` of ``albedo``)."""
    return triangle_means(scene, world, albedo, lambda m: m.base_color_texture)


def emission_means(scene: Scene, world: World) -> np.ndarray:
    """(T, 3) each world triangle's mean emitted radiance (``triangle_means`` of ``emission``)."""
    return triangle_means(scene, world, emission, emission_texture)


def emission_texture(material) -> TextureRef | None:
    """The emissive texture of a ``scene.Material``, None without one."""
    return material.emissive_texture


def emission_textured(scene: Scene) -> np.ndarray:
    """(M,) bool: which materials have an emissive texture (their emission varies over a
    triangle, so it is looked up where it is sampled)."""
    return np.array([emission_texture(m) is not None for m in scene.materials], bool)


def viewer_brdf_at(scene: Scene, world: World, tris: np.ndarray, bary: np.ndarray
                   ) -> tuple[np.ndarray, ...]:
    """What a glTF viewer's BRDF reads at barycentric points (k, 3) of world triangles (k,):
    base colour (k, 3) linear RGB, metallic (k,), roughness (k,) and transmission (k,) in
    [0, 1] (``transmission_at``), and the material's index of refraction (k,)."""
    metallic, roughness = metallic_roughness_at(scene, world, tris, bary)
    ior = np.array([m.ior for m in scene.materials])[world.tri_material[tris]]
    return (base_colour(scene, world, tris, bary), metallic, roughness,
            transmission_at(scene, world, tris, bary), ior)


def sample_alpha(image: Image, ref: TextureRef, uv: np.ndarray) -> np.ndarray:
    """Bilinear lookup of a texture's alpha channel (linear, [0, 1]) at glTF UVs (k, 2): (k,)."""
    pixels = image.pixels
    h, w = pixels.shape[:2]
    x, y = uv[:, 0] * w - 0.5, uv[:, 1] * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
    xs = [_wrap(x0, w, ref.wrap_s), _wrap(x0 + 1, w, ref.wrap_s)]
    ys = [_wrap(y0, h, ref.wrap_t), _wrap(y0 + 1, h, ref.wrap_t)]
    a = pixels[..., 3]
    top = a[ys[0], xs[0]] * (1 - fx) + a[ys[0], xs[1]] * fx
    bottom = a[ys[1], xs[0]] * (1 - fx) + a[ys[1], xs[1]] * fx
    return (top * (1 - fy) + bottom * fy) / 255.0


def alpha(scene: Scene, world: World, tris: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """Coverage alpha (k,) at barycentric points (k, 3) of world triangles (k,): base colour
    factor alpha × base colour texture alpha × COLOR_0 alpha (what alphaMode tests)."""
    materials = world.tri_material[tris]
    out = np.array([m.base_color[3] for m in scene.materials], np.float64)[materials]
    for m, material in enumerate(scene.materials):
        ref = material.base_color_texture
        mask = materials == m
        if ref is None or not mask.any():
            continue
        uv = texture_uv(world, ref, tris[mask], bary[mask])
        out[mask] *= sample_alpha(scene.images[ref.image], ref, uv)
    return out * interpolate(world.colors[:, 3:4], world, tris, bary)[:, 0]


def triangle_albedo(scene: Scene, world: World) -> tuple[np.ndarray, np.ndarray]:
    """Albedo per world triangle where it is constant over the triangle, for the ray kernels.

    Returns ``table`` (T, 3) linear RGB and ``varying`` (T,) bool: True where the material has a
    base colour texture or the corners' vertex colours differ, so ``albedo`` must be evaluated at
    each hit (``table`` is then meaningless for that triangle).
    """
    textured = np.array([m.base_color_texture is not None for m in scene.materials], bool)
    table = diffuse_factors(world)[world.tri_material]
    if not world.coloured:  # every corner's colour is 1: no (T, 3, 3) gather (170 MB at 1 M)
        return table, textured[world.tri_material]
    corners = world.colors[world.triangles][..., :3]  # (T, 3 corners, 3)
    uniform = np.all(corners == corners[:, :1], axis=(1, 2))
    return table * corners[:, 0], textured[world.tri_material] | ~uniform


def emission(scene: Scene, world: World, tris: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """Emitted radiance (k, 3), linear RGB, at barycentric points of world triangles."""
    factor = np.array([m.emissive for m in scene.materials], np.float64)
    return _textured(scene, world, tris, bary, factor, emission_texture)


@dataclass(frozen=True)
class AlphaTest:
    """What the tracer needs to let rays through alpha-cut and blended surfaces.

    mode: (T,) uint8 per world triangle: 0 opaque (never tested), MASK or BLEND. normals: (T, 3)
    unit geometric normals (to step past a hit). cutoff: (M,) alphaCutoff per material.
    step: world units a continued ray starts past its hit, besides 64 float32 ulps.
    ``scene`` and ``world`` give the alpha at a hit (``surface.alpha``).
    """

    scene: object
    world: object
    mode: np.ndarray
    normals: np.ndarray
    cutoff: np.ndarray
    step: float

    def passes(self, tris: np.ndarray, bary: np.ndarray, u: np.ndarray) -> np.ndarray:
        """(k,) bool: does a ray through hit ``tris`` (k,) at ``bary`` (k, 3) go on? ``u`` (k,)
        uniform in [0, 1) decides BLEND hits (through with probability 1 − alpha)."""
        value = alpha(self.scene, self.world, tris, bary)
        cut = self.cutoff[self.world.tri_material[tris]]
        return np.where(self.mode[tris] == MASK, value < cut, u >= value)


def alpha_test(scene, world) -> AlphaTest | None:
    """The scene's ``AlphaTest``, or None when no triangle can let a ray through."""
    classes = world.materials.classes
    by_material = np.array([{"MASK": MASK, "BLEND": BLEND}.get(c.alpha_mode, 0) for c in classes],
                           np.uint8)
    tested = np.array([c.alpha_tested for c in classes], bool)
    if not len(world.triangles) or not by_material.any():
        return None
    mode = by_material[world.tri_material]
    vertex_alpha = (world.colors[:, 3] < 1.0)[world.triangles].any(axis=1)  # (T,)
    mode = np.where(tested[world.tri_material] | vertex_alpha, mode, 0).astype(np.uint8)
    if not mode.any():
        return None
    return AlphaTest(scene=scene, world=world, mode=mode, normals=world.geometric_normals(),
                     cutoff=np.array([c.alpha_cutoff for c in classes]), step=world.scale * 1e-6)
