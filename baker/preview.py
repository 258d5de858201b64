"""A picture of a baked scene, rendered with Embree: see the lightmaps without another program.

    baker preview level_baked.glb -o preview.png [--lightmap-only | --checker] [--size 800x600]

Every pixel is one primary ray (all pixels in one batch, cast in chunks through
``trace.Tracer``). Where a ray meets a lightmapped surface the pixel shows what a glTF viewer
shows there (three.js, measured by tests/test_browser.py): diffuse colour × lightmap / π +
emission, where the diffuse colour is the base colour × (1 − metallic) × (1 − transmission)
(``surface.viewer_diffuse_weight_at``, metallic read from its texture at the point as viewers
read it: viewers light only a material's diffuse part with a lightmap, so a metal shows black)
and the lightmap is sampled bilinearly (clamped, as the writer's sampler says) at the hit's lightmap UV — the TEXCOORD set named by
``MOZ_lightmap.texCoord`` — decoded by ``asset.extras.baker.lightmap_encoding`` (linear when
absent) and scaled by ``MOZ_lightmap.intensity``. The emissive carrier's surfaces show their
emission (the bake itself, base colour black); the occlusion carrier's visibility is shaded as a
lightmap of intensity 1 (what a viewer's ambient light of 1 gives). Modes:

- ``lit`` (default): diffuse colour × lightmap / π + emission, auto-exposed.
- ``lightmap``: the lightmap alone (as if every surface were white).
- ``checker``: a checker of lightmap texels, tinted per page, to judge texel density: squares of
  one texel, or of 2, 4, 8… texels a side when single texels would be smaller than about four
  pixels in the picture (``Picture.checker_texels`` says which).
- ``unlit``: diffuse colour + emission with every lightmap left out (as if it were π), the same view:
  what the lightmap adds is the difference from ``lit``.

Single-sided materials are culled from behind, as glTF viewers do, so the default view from
outside a closed room looks in. Surfaces without a lightmap (unlit, skinned, GPU-instanced) are
drawn flat: unlit ones in their base colour, the others albedo × |cos| to the eye × the mean
lightmap level, so they read as "not baked" rather than as black.

The view is the scene's first camera node (perspective or orthographic), else a default that
frames the bounds of every triangle from a three-quarter angle above (+x, +y, +z side).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from baker.errors import InputError, OutputError, SettingsError
from baker.geometry.surface import (SRGB_TO_LINEAR, albedo, alpha, base_colour, emission,
                                    luminance, transformed_uv, viewer_brdf_at,
                                    viewer_diffuse_weight_at)
from baker.geometry.world import World, build_world
from baker.gltf.load import load
from baker.gltf.read_images import image_pixels
from baker.gltf.read_nodes import trs_matrices
from baker.gltf.scene import Scene
from baker.light.viewer_lights import punctual_shading
from baker.image.encode import linear_to_srgb, png_bytes
from baker.light.directional import decode_vectors, shading_factor, texel_vectors
from baker.materials import BLEND
from baker.output.write import DIRECTIONAL_EXTENSION
from baker.rays.trace import Tracer
from baker.run.atomic import write_atomically
from baker.settings import PREVIEW_MODES

MODES = PREVIEW_MODES
_RAYS_PER_CHUNK = 1 << 16
_MAX_CULLED_LAYERS = 16  # back faces a primary ray may pass through before it gives up
_BACKGROUND = np.array([0.02, 0.02, 0.025])  # linear RGB behind the scene
_UNBAKED_CHECKER = np.array([1.0, 0.0, 1.0])  # magenta: no lightmap here
_DEFAULT_YFOV = np.radians(50.0)
_DEFAULT_FROM = np.array([0.6, 0.55, 1.0])  # direction from the scene's centre to the eye
_WHITE = 0.85  # auto exposure maps the lightmapped pixels' 99th luminance percentile here


@dataclass(frozen=True)
class View:
    """A pinhole (or orthographic) camera in world space.

    origin: (3,) eye position. axes: (3, 3) rows right, up, backward (the camera looks along
    −backward, glTF's camera convention). yfov: vertical field of view in radians for a
    perspective camera, None for orthographic; ymag: half the orthographic view's height (world
    units). aspect: width / height the camera asks for, None when it leaves it to the picture.
    """

    origin: np.ndarray
    axes: np.ndarray
    yfov: float | None
    ymag: float = 1.0
    aspect: float | None = None


@dataclass(frozen=True)
class SceneLightmaps:
    """Every world triangle's lightmap, decoded to linear light.

    pages: list of (h, w, 3) float64 linear pages, intensity already applied. page: (T,) int64
    index into ``pages`` per world triangle, −1 where the triangle has no lightmap. uv: (T, 3, 2)
    float64 lightmap UV of each triangle's corners, in ``World.triangles`` corner order.
    encoding: the encoding the pages were decoded with. directional: the triangles' directional
    pages and normal maps (``Directional``), None when no material has both.
    """

    pages: list[np.ndarray]
    page: np.ndarray
    uv: np.ndarray
    encoding: str
    directional: "Directional | None" = None


@dataclass(frozen=True)
class Directional:
    """What the decode of directional pages needs (``light.directional``), per world triangle.

    pages: (h, w, 3) float64 h of each directional page; page: (T,) int64 index into them (−1:
    none, the triangle shades as a plain lightmap). normal_maps: (h, w, 3) float64 tangent-space
    normals (texel/255·2 − 1) of each normal texture; normal_map: (T,) int64 index into them;
    normal_uv: (T, 3, 2) its UVs at the triangle's corners; normal_scale: (T,) its scale.
    """

    pages: list[np.ndarray]
    page: np.ndarray
    normal_maps: list[np.ndarray]
    normal_map: np.ndarray
    normal_uv: np.ndarray
    normal_scale: np.ndarray


@dataclass(frozen=True)
class Picture:
    """A rendered preview.

    rgb: (H, W, 3) uint8 sRGB, what the PNG holds. radiance: (H, W, 3) float64 linear value of
    each pixel before exposure (lightmap value × albedo + emission in ``lit`` mode, lightmap in
    ``lightmap`` mode, checker shade in ``checker`` mode, albedo + emission in ``unlit`` mode).
    triangle: (H, W) int64 world triangle seen at the pixel, −1 for the background.
    lightmapped: (H, W) bool, pixels showing a lightmapped surface. exposure: the factor
    applied before the sRGB curve. from_lightmap: (H, W, 3) float64 the part of ``radiance``
    the lightmap gives (diffuse colour × lightmap / π in ``lit`` mode, the lightmap in
    ``lightmap`` mode, zero in the others): what a viewer's picture loses when it leaves the
    lightmap out (tests/test_browser.py compares the two).
    """

    rgb: np.ndarray
    radiance: np.ndarray
    triangle: np.ndarray
    lightmapped: np.ndarray
    exposure: float
    position: np.ndarray
    from_lightmap: np.ndarray
    checker_texels: int = 1


# --------------------------------------------------------------------------------------------
# cameras


def _node_world(document, index: int) -> np.ndarray:
    """(4, 4) world matrix of node ``index``: the product of its ancestors' local matrices."""
    parent = {c: p for p, node in enumerate(document.nodes) for c in node.children or []}
    matrix = np.eye(4)
    seen = set()
    while index is not None and index not in seen:
        seen.add(index)
        node = document.nodes[index]
        if node.matrix is not None:
            local = np.asarray(node.matrix, np.float64).reshape(4, 4).T
        else:
            t = np.asarray(node.translation if node.translation is not None else [0, 0, 0], float)
            r = np.asarray(node.rotation if node.rotation is not None else [0, 0, 0, 1], float)
            s = np.asarray(node.scale if node.scale is not None else [1, 1, 1], float)
            local = trs_matrices(t[None], r[None], s[None])[0]
        matrix = local @ matrix
        index = parent.get(index)
    return matrix


def _orthonormal(axes: np.ndarray) -> np.ndarray | None:
    """Rows right, up, backward made orthonormal (scale and shear removed); None if degenerate."""
    back = axes[2] / max(np.linalg.norm(axes[2]), 1e-300)
    right = np.cross(axes[1], back)
    if np.linalg.norm(right) < 1e-12 or not np.all(np.isfinite(right)):
        return None
    right /= np.linalg.norm(right)
    return np.stack([right, np.cross(back, right), back])


def scene_camera(scene: Scene) -> View | None:
    """The view of the first node (in node order) that has a camera, or None."""
    document = scene.document
    for index, node in enumerate(document.nodes or []):
        if node.camera is None or not 0 <= node.camera < len(document.cameras or []):
            continue
        camera = document.cameras[node.camera]
        world = _node_world(document, index)
        axes = _orthonormal(world[:3, :3].T.copy())
        if axes is None:
            continue
        origin = world[:3, 3].copy()
        if camera.type == "orthographic" and camera.orthographic is not None:
            o = camera.orthographic
            aspect = float(o.xmag) / float(o.ymag) if o.xmag and o.ymag else None
            return View(origin, axes, None, float(abs(o.ymag or 1.0)), aspect)
        if camera.perspective is not None:
            p = camera.perspective
            yfov = float(p.yfov) if p.yfov and 0 < p.yfov < np.pi else _DEFAULT_YFOV
            aspect = float(p.aspectRatio) if p.aspectRatio else None
            return View(origin, axes, yfov, 1.0, aspect)
    return None


def default_view(world: World) -> View:
    """A perspective view framing every triangle's bounds from the (+x, +y, +z) side, above.

    The eye looks at the bounds' centre from direction (0.6, 0.55, 1.0), far enough that the
    bounding sphere fits in a 50° vertical field of view.
    """
    points = world.positions[world.triangles.reshape(-1)] if len(world.triangles) else np.zeros((1, 3))
    lo, hi = points.min(0), points.max(0)
    centre, radius = (lo + hi) / 2, max(np.linalg.norm(hi - lo) / 2, 1e-6)
    back = _DEFAULT_FROM / np.linalg.norm(_DEFAULT_FROM)
    origin = centre + back * radius / np.sin(_DEFAULT_YFOV / 2) * 1.02
    axes = _orthonormal(np.stack([np.zeros(3), np.array([0.0, 1.0, 0.0]), back]))
    return View(origin, axes, _DEFAULT_YFOV)


def primary_rays(view: View, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Origins and unit directions (H·W, 3) of the pixel centres' rays, row-major from the top."""
    aspect = width / height
    py = 1.0 - 2.0 * (np.arange(height) + 0.5) / height
    px = 2.0 * (np.arange(width) + 0.5) / width - 1.0
    gx, gy = np.meshgrid(px, py)
    gx, gy = gx.reshape(-1), gy.reshape(-1)
    right, up, back = view.axes
    if view.yfov is None:
        origins = (view.origin + (gx * view.ymag * aspect)[:, None] * right
                   + (gy * view.ymag)[:, None] * up)
        directions = np.broadcast_to(-back, origins.shape).copy()
        return origins, directions
    t = np.tan(view.yfov / 2)
    directions = -back + (gx * t * aspect)[:, None] * right + (gy * t)[:, None] * up
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return np.broadcast_to(view.origin, directions.shape).copy(), directions


# --------------------------------------------------------------------------------------------
# lightmaps


def read_lightmaps(scene: Scene, world: World) -> SceneLightmaps:
    """Decode every page of the bake that the scene's materials carry, and each triangle's UVs.

    A material carries the bake as its ``MOZ_lightmap`` (decoded by
    ``asset.extras.baker.lightmap_encoding``, × its intensity), or, in a file baker wrote with
    the emissive carrier, as its emissiveTexture (sRGB × emissive factor and strength: the
    radiance itself), or with the occlusion carrier as its occlusionTexture (the visibility,
    linear, red channel). Raises InputError when nothing carries a bake and
    ``asset.extras.baker`` is absent (the file was not baked); a file baker wrote in which
    nothing got a lightmap (e.g. only GPU-instanced meshes) has no pages, and renders flat.
    """
    document = scene.document
    recorded = scene.recorded_bake() or {}
    encoding = recorded.get("lightmap_encoding") or "linear"
    carrier = recorded.get("carrier") or "moz"
    pages: list[np.ndarray] = []
    page_of_key: dict[tuple, int] = {}
    count = len(world.triangles)
    tri_page = np.full(count, -1, np.int64)
    tri_uv = np.zeros((count, 3, 2))
    directional = _DirectionalReader(scene, count)
    for i, inst in enumerate(scene.instances):
        prim = scene.primitives[inst.primitive]
        found = _carried_texture(document, scene.materials[prim.material], carrier, encoding,
                                 str(scene.path))
        if found is None or found[1] >= len(prim.texcoords):
            continue
        directional.add(scene, world, i)
        texture, texcoord, scale, curve, red = found
        source = document.textures[texture].source
        key = (source, scale, curve, red)
        if key not in page_of_key:
            texels = image_pixels(scene, source)[..., :3]
            if red:
                texels = np.repeat(texels[..., :1], 3, axis=-1)
            decoded = SRGB_TO_LINEAR[texels] if curve == "srgb" else texels / 255.0
            pages.append(decoded * scale)
            page_of_key[key] = len(pages) - 1
        tris = world.instance_triangles(i)
        local = world.triangles[tris] - world.vertex_start[i]
        tri_page[tris] = page_of_key[key]
        tri_uv[tris] = transformed_uv(prim.texcoords[texcoord][local],
                                      _carrier_transform(scene.materials[prim.material], carrier))
    if not pages and not recorded:
        raise InputError("the scene has no lightmap: no material has a MOZ_lightmap extension",
                         file=str(scene.path),
                         fix="bake it first: baker bake SCENE -o SCENE_baked.glb, then preview "
                             "the baked file")
    return SceneLightmaps(pages=pages, page=tri_page, uv=tri_uv, encoding=encoding,
                          directional=directional.made())


class _DirectionalReader:
    """Gathers ``Directional`` instance by instance (``read_lightmaps``)."""

    def __init__(self, scene: Scene, count: int):
        self.scene = scene
        self.pages: dict[int, int] = {}  # image index → row of ``Directional.pages``
        self.normals: dict[int, int] = {}
        self.page, self.normal_map = np.full(count, -1, np.int64), np.full(count, -1, np.int64)
        self.normal_uv, self.normal_scale = np.zeros((count, 3, 2)), np.ones(count)
        self.images: list[np.ndarray] = []
        self.maps: list[np.ndarray] = []

    def add(self, scene: Scene, world: World, instance: int) -> None:
        """The directional page and the normal map of ``instance``'s material, when it has
        both (``BAKER_lightmap_directional`` on the lightmap's UV set, a normalTexture)."""
        prim = scene.primitives[scene.instances[instance].primitive]
        index = scene.materials[prim.material].index
        if index is None:
            return
        gltf = self.scene.document.materials[index]
        ext = (gltf.extensions or {}).get(DIRECTIONAL_EXTENSION)
        normal = gltf.normalTexture  # one without an image is shaded as none
        if not isinstance(ext, dict) or ext.get("index") is None or normal is None or \
                _not_an_image(self.scene.document, normal.index):
            return
        page, _ = _page_texture(self.scene.document, ext.get("index"), 0, str(scene.path),
                                f"materials[{index}].extensions.{DIRECTIONAL_EXTENSION}")
        texcoord = int(normal.texCoord or 0)
        if not 0 <= texcoord < len(prim.texcoords):
            return
        tris = world.instance_triangles(instance)
        local = world.triangles[tris] - world.vertex_start[instance]
        self.page[tris] = self._image(self.pages, self.images, page, texel_vectors)
        self.normal_map[tris] = self._image(self.normals, self.maps, normal.index, texel_vectors)
        self.normal_uv[tris] = prim.texcoords[texcoord][local]
        self.normal_scale[tris] = 1.0 if normal.scale is None else float(normal.scale)

    def _image(self, seen: dict, out: list, texture: int, decode) -> int:
        source = self.scene.document.textures[texture].source
        if source not in seen:
            out.append(decode(image_pixels(self.scene, source)[..., :3]))
            seen[source] = len(out) - 1
        return seen[source]

    def made(self) -> Directional | None:
        if not self.images:
            return None
        return Directional(self.images, self.page, self.maps, self.normal_map, self.normal_uv,
                           self.normal_scale)


def _carried_texture(document, material, carrier: str, encoding: str, file: str):
    """(texture, texCoord, scale, curve, red channel only) of the bake that ``material``
    (scene.Material) carries, or None: its MOZ_lightmap, else the emissive or occlusion
    carrier's texture when the file says that carrier wrote it. InputError (naming the
    material) for a MOZ_lightmap whose index, texCoord or intensity is not one."""
    if material.index is None:
        return None
    gltf = document.materials[material.index]
    ext = (gltf.extensions or {}).get("MOZ_lightmap")
    if isinstance(ext, dict) and ext.get("index") is not None:
        where = f"materials[{material.index}].extensions.MOZ_lightmap"
        intensity = ext.get("intensity", 1.0)
        if type(intensity) not in (int, float) or not np.isfinite(intensity):
            raise _not_a_page(f"its intensity {intensity!r} is not a finite number", file, where)
        texture, texcoord = _page_texture(document, ext.get("index"), ext.get("texCoord", 0),
                                          file, where)
        return texture, texcoord, float(intensity), encoding, False
    if carrier == "emissive" and gltf.emissiveTexture is not None:
        return (*_page_texture(document, gltf.emissiveTexture.index,
                               gltf.emissiveTexture.texCoord or 0, file,
                               f"materials[{material.index}].emissiveTexture"),
                float(material.emissive[0]), "srgb", False)
    if carrier == "occlusion" and gltf.occlusionTexture is not None:
        return (*_page_texture(document, gltf.occlusionTexture.index,
                               gltf.occlusionTexture.texCoord or 0, file,
                               f"materials[{material.index}].occlusionTexture"),
                1.0, "linear", True)
    return None


def _page_texture(document, texture, texcoord, file: str, where: str) -> tuple[int, int]:
    """(texture, texCoord) of a lightmap page's texture reference at ``where``: one of the
    file's textures, with an image, and a UV set's number; InputError otherwise."""
    wrong = _not_an_image(document, texture)
    if wrong:
        raise _not_a_page(wrong, file, where)
    if type(texcoord) is not int or texcoord < 0:
        raise _not_a_page(f"its texCoord {texcoord!r} is not a UV set's number", file, where)
    return texture, texcoord


def _not_an_image(document, texture) -> str:
    """Why ``texture`` is not one of the file's textures with an image ("" when it is)."""
    textures, images = document.textures or [], document.images or []
    if type(texture) is not int or not 0 <= texture < len(textures):
        return f"its texture {texture!r} is not one of the file's {len(textures)}"
    source = textures[texture].source
    if type(source) is not int or not 0 <= source < len(images):
        return f"textures[{texture}] has no image ({source!r})"
    return ""


def _not_a_page(what: str, file: str, where: str) -> InputError:
    """The error for a lightmap page the preview cannot read."""
    return InputError(f"the lightmap page is not readable: {what}", file=file, where=where,
                      fix="bake the scene again (baker bake SCENE -o OUT.glb) and preview that "
                          "output")


def _carrier_transform(material, carrier: str) -> tuple[float, ...] | None:
    """The KHR_texture_transform (``TextureRef.transform``) through which ``material`` reads the
    emissive or occlusion carrier's page: an instance sharing another's lightmap UVs
    (``output/write.py``), or UVs quantized by gltfpack."""
    ref = {"emissive": material.emissive_texture,
           "occlusion": material.occlusion_texture}.get(carrier)
    return None if ref is None else ref.transform


def sample_bilinear(page: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear, clamp-to-edge lookup of a (h, w, C) image at glTF UVs (k, 2) → (k, C).

    UV (0, 0) is the image's top-left corner; texel centres sit at half-integers, as GPUs do.
    """
    h, w = page.shape[:2]
    x = uv[:, 0] * w - 0.5
    y = uv[:, 1] * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
    xa, xb = np.clip(x0, 0, w - 1), np.clip(x0 + 1, 0, w - 1)
    ya, yb = np.clip(y0, 0, h - 1), np.clip(y0 + 1, 0, h - 1)
    top = page[ya, xa] * (1 - fx) + page[ya, xb] * fx
    bottom = page[yb, xa] * (1 - fx) + page[yb, xb] * fx
    return top * (1 - fy) + bottom * fy


# --------------------------------------------------------------------------------------------
# rendering


def _first_front_hits(scene: Scene, world: World, tracer: Tracer, origins: np.ndarray,
                      directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nearest hit (triangle (n,), barycentric (n, 3)) of each ray, passing through the back faces
    of single-sided materials; triangle −1 where the ray leaves the scene."""
    single = ~np.array([m.double_sided for m in scene.materials], bool)[world.tri_material]
    normals = world.geometric_normals()
    points = world.positions[world.triangles.reshape(-1)] if len(world.triangles) else np.zeros((1, 3))
    scale = float(np.abs(points - world.center).max(initial=1.0))
    step = 1e-6 * scale  # past a culled face: above float32 spacing at the scene's extent
    triangle = np.full(len(origins), -1, np.int64)
    bary = np.zeros((len(origins), 3))
    active = np.arange(len(origins) if len(world.triangles) else 0)  # none: every ray leaves
    start = origins.copy()
    for _ in range(_MAX_CULLED_LAYERS):
        if not len(active):
            break
        hits = tracer.cast(start[active], directions[active], np.inf)
        hit = hits.triangle >= 0
        tri = np.where(hit, hits.triangle, 0)
        facing = np.einsum("ij,ij->i", normals[tri], directions[active])
        culled = hit & single[tri] & (facing > 0)
        done = hit & ~culled
        triangle[active[done]] = hits.triangle[done]
        bary[active[done]] = hits.barycentric()[done]
        again = active[culled]
        start[again] += directions[again] * (hits.distance[culled] + step)[:, None]
        active = again
    return triangle, bary


def render(scene: Scene, mode: str = "lit", size: tuple[int, int] | None = None,
           exposure: float | None = None, view: View | None = None) -> Picture:
    """Render ``scene`` (a baked glTF, loaded) into a Picture.

    mode: one of MODES. size: (width, height) pixels; None takes 640 wide and the camera's
    aspect ratio (480 high without one). exposure: factor on linear values before the sRGB curve;
    None picks one so the 99th percentile of the lightmapped pixels' luminance (those above 0)
    maps to 0.85 (lit,
    lightmap and unlit modes; checker shades are used as they are). view: None uses the scene's
    camera or the default view.
    """
    if mode not in MODES:
        raise SettingsError(f"preview mode must be one of {', '.join(MODES)}, not {mode!r}",
                            fix="use lit, lightmap, checker or unlit")
    if exposure is not None and not (np.isfinite(exposure) and exposure > 0):
        raise SettingsError(f"exposure must be a finite number above 0, not {exposure}",
                            fix="give --exposure a positive factor, or leave it out (automatic)")
    world = build_world(scene)
    lightmaps = read_lightmaps(scene, world)
    view = view or scene_camera(scene) or default_view(world)
    if size is None:
        aspect = view.aspect or 4 / 3
        size = (640, max(1, int(round(640 / aspect))))
    width, height = size
    origins, directions = primary_rays(view, width, height)
    tracer = Tracer(_blended_opaque(world))
    triangle, bary = _front_hits(scene, world, tracer, origins, directions)
    cell = _checker_cell(lightmaps, triangle, bary, width, height) if mode == "checker" else 1
    radiance, lightmapped, from_lightmap = _shade(scene, world, lightmaps, mode, triangle, bary,
                                                  directions, cell)
    if mode in ("lit", "unlit"):
        radiance = _composited(scene, world, tracer, lightmaps, mode, triangle, bary, directions,
                               radiance)
    if exposure is None:
        exposure = 1.0
        shown = luminance(radiance[lightmapped])
        shown = shown[shown > 0]  # a metal shows black: it says nothing of the level
        if mode != "checker" and len(shown):
            exposure = _WHITE / np.percentile(shown, 99)
    shown = np.where((triangle >= 0)[:, None], radiance * exposure, _BACKGROUND)
    rgb = np.round(linear_to_srgb(shown) * 255).astype(np.uint8)
    return Picture(rgb=rgb.reshape(height, width, 3), radiance=radiance.reshape(height, width, 3),
                   triangle=triangle.reshape(height, width),
                   lightmapped=lightmapped.reshape(height, width), exposure=float(exposure),
                   position=_points(world, triangle, bary).reshape(height, width, 3),
                   from_lightmap=from_lightmap.reshape(height, width, 3), checker_texels=cell)


def _front_hits(scene: Scene, world: World, tracer: Tracer, origins: np.ndarray,
                directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``_first_front_hits`` of every ray (n,), ``_RAYS_PER_CHUNK`` rays at a time."""
    n = len(origins)
    triangle, bary = np.full(n, -1, np.int64), np.zeros((n, 3))
    for start in range(0, n, _RAYS_PER_CHUNK):
        rows = slice(start, min(start + _RAYS_PER_CHUNK, n))
        triangle[rows], bary[rows] = _first_front_hits(scene, world, tracer, origins[rows],
                                                       directions[rows])
    return triangle, bary


def _blended_opaque(world: World) -> World:
    """``world`` whose blended (BLEND) triangles stop a ray, for primary rays: the preview
    draws what is behind them by compositing (``_composited``), as viewers blend, where the
    bake's tracer lets a ray through at random (1 − alpha of them). Alpha-cut (MASK) stays."""
    if world.alpha is None or not np.any(world.alpha.mode == BLEND):
        return world
    return replace(world, alpha=replace(world.alpha, mode=np.where(
        world.alpha.mode == BLEND, 0, world.alpha.mode).astype(np.uint8)))


def _see_through(scene: Scene, world: World, tris: np.ndarray,
                 bary: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For hits (k,) on world triangles: the share (k,) of the surface's own shading a viewer
    shows (alpha for a blended material, else 1), and what of the scene behind it shows through
    (k, 3): 1 − alpha for a blended material; for a transmissive one its dielectric part's
    transmission, (1 − metallic) × transmission (``transmission_at``), × base colour (three.js
    tints what it lets through by the base colour, and a metal lets nothing through); else 0."""
    material = world.tri_material[tris]
    blended = np.array([m.alpha_mode == "BLEND" for m in scene.materials])[material]
    transmissive = np.array([m.transmission > 0 for m in scene.materials])[material]
    own = np.ones(len(tris))
    behind = np.zeros((len(tris), 3))
    if blended.any():
        own[blended] = np.clip(alpha(scene, world, tris[blended], bary[blended]), 0.0, 1.0)
        behind[blended] = (1.0 - own[blended])[:, None]
    clear = ~blended & transmissive
    if clear.any():
        base, metallic, _, transmission, _ = viewer_brdf_at(scene, world, tris[clear],
                                                            bary[clear])
        behind[clear] = ((1.0 - metallic) * transmission)[:, None] * base
    return own, behind


def _composited(scene: Scene, world: World, tracer: Tracer, lightmaps: SceneLightmaps, mode: str,
                triangle: np.ndarray, bary: np.ndarray, directions: np.ndarray,
                radiance: np.ndarray) -> np.ndarray:
    """``radiance`` (n, 3) of the first hits with what shows through blended and transmissive
    surfaces composited front to back, as a viewer draws them: each layer's own shading × its
    alpha, plus what its ``_see_through`` lets pass of the layers behind, up to
    ``_MAX_CULLED_LAYERS`` of them (the background where nothing is behind)."""
    out = radiance.copy()
    through = np.zeros((len(triangle), 3))
    hit = np.flatnonzero(triangle >= 0)
    own, through[hit] = _see_through(scene, world, triangle[hit], bary[hit])
    out[hit] *= own[:, None]
    step = 1e-6 * float(np.abs(world.positions - world.center).max(initial=1.0))
    tri, bar = triangle, bary
    for _ in range(_MAX_CULLED_LAYERS):
        rows = np.flatnonzero(through.max(axis=1) > 1e-3)
        if not len(rows):
            break
        starts = _points(world, tri[rows], bar[rows]) + directions[rows] * step
        tri, bar = np.full(len(triangle), -1, np.int64), np.zeros_like(bary)
        tri[rows], bar[rows] = _front_hits(scene, world, tracer, starts, directions[rows])
        layer, _, _ = _shade(scene, world, lightmaps, mode, tri[rows], bar[rows],
                             directions[rows])
        missed = tri[rows] < 0
        layer[missed] = _BACKGROUND
        own, behind = np.ones(len(rows)), np.zeros((len(rows), 3))
        seen = ~missed
        own[seen], behind[seen] = _see_through(scene, world, tri[rows][seen], bar[rows][seen])
        out[rows] += through[rows] * layer * own[:, None]
        through[rows] *= behind
    return out


def _points(world: World, triangle: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """World points (n, 3) at barycentric ``bary`` (n, 3) of ``triangle`` (n,); NaN where −1."""
    if not len(world.triangles):
        return np.full((len(triangle), 3), np.nan)
    corners = world.positions[world.triangles[np.maximum(triangle, 0)]]
    points = np.einsum("nc,ncj->nj", bary, corners)
    points[triangle < 0] = np.nan
    return points


def _lightmap_texel_coords(lightmaps: SceneLightmaps, tris: np.ndarray,
                           bary: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lightmap page (k,) and position in texels (k, 2) of barycentric points of triangles."""
    page = lightmaps.page[tris]
    uv = np.einsum("kc,kcj->kj", bary, lightmaps.uv[tris])
    shape = np.array([p.shape[1::-1] for p in lightmaps.pages] or [[1, 1]], np.float64)
    return page, uv * shape[np.maximum(page, 0)]


def _checker_cell(lightmaps: SceneLightmaps, triangle: np.ndarray, bary: np.ndarray,
                  width: int, height: int) -> int:
    """Texels per checker square side: the smallest power of two whose squares are at least
    about four pixels wide, from the median texel step between neighbouring pixels that see the
    same lightmapped triangle."""
    tri = triangle.reshape(height, width)
    same = (tri[:, 1:] == tri[:, :-1]) & (tri[:, 1:] >= 0)
    if not same.any():
        return 1
    left = np.flatnonzero(np.pad(same, ((0, 0), (0, 1))).reshape(-1))
    page, texel = _lightmap_texel_coords(lightmaps, triangle[left], bary[left])
    _, beside = _lightmap_texel_coords(lightmaps, triangle[left + 1], bary[left + 1])
    steps = np.linalg.norm(beside - texel, axis=1)[page >= 0]
    if not len(steps):
        return 1
    per_pixel = float(np.median(steps))
    return int(2 ** max(0, int(np.ceil(np.log2(max(4.0 * per_pixel, 1.0))))))


def _shade(scene: Scene, world: World, lightmaps: SceneLightmaps, mode: str, triangle: np.ndarray,
           bary: np.ndarray, directions: np.ndarray,
           cell: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Linear pixel values (n, 3), which pixels show a lightmap (n,), and the part of the
    values the lightmap gives (n, 3), for ``mode``; ``cell`` is the checker square's side in
    texels."""
    n = len(triangle)
    radiance = np.zeros((n, 3))
    from_lightmap = np.zeros((n, 3))
    hit = np.flatnonzero(triangle >= 0)
    tris, b = triangle[hit], bary[hit]
    page, texel = _lightmap_texel_coords(lightmaps, tris, b)
    baked = page >= 0
    light = np.zeros((len(hit), 3))
    for p in np.unique(page[baked]):
        on = page == p
        if mode == "checker":
            parity = np.floor(texel[on] / cell).sum(axis=1) % 2
            tint = 0.7 + 0.3 * np.cos(2.4 * p + np.array([3.0, 5.1, 1.0]))
            light[on] = (0.25 + 0.6 * parity)[:, None] * tint
        else:
            shape = np.array(lightmaps.pages[p].shape[1::-1], np.float64)
            light[on] = sample_bilinear(lightmaps.pages[p], texel[on] / shape)
    if mode != "checker" and lightmaps.directional is not None:
        light *= _directional_factor(world, lightmaps, tris, b, texel)[:, None]
    cosine = np.abs(np.einsum("kj,kj->k", world.geometric_normals(tris), directions[hit]))
    level = luminance(light[baked]).mean() if baked.any() else 1.0
    if mode == "checker":
        light[~baked] = _UNBAKED_CHECKER
        radiance[hit] = light
        return radiance, np.isin(np.arange(n), hit[baked]), from_lightmap
    unlit = np.array([m.unlit for m in scene.materials], bool)[world.tri_material[tris]]
    flat = np.where(unlit, 1.0, cosine * level)[:, None]
    if mode == "lightmap":
        radiance[hit] = np.where(baked[:, None], light, flat * 0.5)
        from_lightmap[hit[baked]] = light[baked]
    else:
        weight = viewer_diffuse_weight_at(scene, world, tris, b)
        diffuse = base_colour(scene, world, tris, b) * weight[:, None]
        shaded = diffuse * (1.0 if mode == "unlit" else light / np.pi)
        radiance[hit] = (np.where(baked[:, None], shaded, albedo(scene, world, tris, b) * flat)
                         + emission(scene, world, tris, b))
        if mode == "lit" and baked.any():  # the file's lights, as a viewer adds them
            on = hit[baked]
            radiance[on] += punctual_shading(scene.lights, scene, world, tris[baked], b[baked],
                                             _points(world, triangle[on], bary[on]),
                                             -directions[on])
        if mode == "lit":
            from_lightmap[hit[baked]] = shaded[baked]
    lightmapped = np.zeros(n, bool)
    lightmapped[hit[baked]] = True
    return radiance, lightmapped, from_lightmap


def _directional_factor(world: World, lightmaps: SceneLightmaps, tris: np.ndarray,
                        bary: np.ndarray, texel: np.ndarray) -> np.ndarray:
    """(k,) what directional pages do to the lightmap at barycentric points ``bary`` (k, 3)
    of ``tris`` (k,), at lightmap texel positions ``texel`` (k, 2): the factor
    max(0, 1 + (n − n₀)·g) (``light.directional.shading_factor``), 1 where a triangle has no
    directional page. n₀ is the interpolated vertex normal; n the normal map's, in a tangent
    frame from the normal texture's UVs (T along +u, the bitangent towards the image's top, as
    MikkTSpace tangents and three.js without them have it)."""
    directional = lightmaps.directional
    out = np.ones(len(tris))
    on = np.flatnonzero(directional.page[tris] >= 0)
    if not len(on):
        return out
    t, w = tris[on], bary[on]
    base = np.einsum("kc,kcj->kj", w, world.normals[world.triangles[t]])
    base /= np.maximum(np.linalg.norm(base, axis=1, keepdims=True), 1e-300)
    tangent, bitangent = _tangent_frames(world, directional.normal_uv[t], t, base)
    mapped = np.zeros((len(on), 3))
    g = np.zeros((len(on), 3))
    uv = np.einsum("kc,kcj->kj", w, directional.normal_uv[t])
    page = lightmaps.page[t]
    for m in np.unique(directional.normal_map[t]):
        mine = directional.normal_map[t] == m
        mapped[mine] = sample_bilinear(directional.normal_maps[m], uv[mine] % 1.0)
    for p in np.unique(directional.page[t]):
        mine = directional.page[t] == p
        shape = np.array(lightmaps.pages[page[mine][0]].shape[1::-1], np.float64)
        g[mine] = decode_vectors(sample_bilinear(directional.pages[p], texel[on][mine] / shape))
    scale = directional.normal_scale[t][:, None]
    normal = (mapped[:, :1] * scale * tangent + mapped[:, 1:2] * scale * bitangent
              + mapped[:, 2:] * base)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    out[on] = shading_factor(normal, base, g)
    return out


def _tangent_frames(world: World, uv: np.ndarray, tris: np.ndarray,
                    normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit tangents and bitangents (k, 3) at unit ``normals`` (k, 3) of triangles ``tris``
    (k,) with UVs ``uv`` (k, 3, 2) at their corners: T = ∂P/∂u made normal to n, the bitangent
    n × T, turned to point where v decreases (the image's top)."""
    a, b, c = world.corners(tris)
    e1, e2 = b - a, c - a
    du1, dv1 = uv[:, 1, 0] - uv[:, 0, 0], uv[:, 1, 1] - uv[:, 0, 1]
    du2, dv2 = uv[:, 2, 0] - uv[:, 0, 0], uv[:, 2, 1] - uv[:, 0, 1]
    det = du1 * dv2 - du2 * dv1
    det = np.where(np.abs(det) > 1e-300, det, 1e-300)
    along_u = (e1 * dv2[:, None] - e2 * dv1[:, None]) / det[:, None]
    along_v = (e2 * du1[:, None] - e1 * du2[:, None]) / det[:, None]
    tangent = along_u - normals * np.einsum("kj,kj->k", along_u, normals)[:, None]
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-300)
    bitangent = np.cross(normals, tangent)
    up = np.where(np.einsum("kj,kj->k", bitangent, along_v) > 0, -1.0, 1.0)
    return tangent, bitangent * up[:, None]


def preview(input: str | os.PathLike, output: str | os.PathLike, mode: str = "lit",
            size: tuple[int, int] | None = None, exposure: float | None = None) -> Picture:
    """Load the baked glTF at ``input``, render it (see ``render``) and write ``output`` (.png).

    The PNG is written atomically; nothing is written when anything fails.
    """

    output = Path(output)
    if output.suffix.lower() != ".png":
        raise OutputError(f"the preview is a PNG picture; the output ends in "
                          f"{output.suffix or '(nothing)'}", file=str(output),
                          fix="name the output e.g. preview.png")
    if not output.parent.exists():
        raise OutputError("the output's folder does not exist", file=str(output),
                          fix=f"create {output.parent} first, or choose another -o path")
    picture = render(load(input), mode, size, exposure)
    write_atomically(output, png_bytes(picture.rgb))
    return picture
