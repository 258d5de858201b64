"""Light that comes through translucent surfaces (paper §4): inner obscurances and leaves.

Two terms, added by ``light.integrate.integrate`` to the obscurance W of the texels that need them
(``materials.Classification.leaf`` / ``.inner``; the plan names them, ``plan.material_stages``):

- **Inner obscurance** (§4, equation 5), for texels on closed translucent objects (translucency
  with ``KHR_materials_volume`` thickness > 0, e.g. wax). Light enters the object all over its
  surface and crosses it; the thinner the object behind P, the more of it reaches P. Rays go into
  the object (cosine-distributed about −n) and

      W_in(P) = 1/π ∫ γ(d) A(d) cosθ dω,   γ(d) = 1 − sqrt(d / d_in)  (0 for d ≥ d_in),

  d: the distance to where the ray leaves the object (its first hit), d_in the material's reach:
  ``attenuationDistance`` (world units) when given, else ``thicknessFactor`` (mesh units × the
  instance's scale). A(d) = attenuationColor^(d / attenuationDistance) per channel is the volume's
  absorption (Beer–Lambert, as KHR_materials_volume defines it; 1 without an attenuation
  distance). The texel's light gains t · R_ave · I_A · W_in, t the material's translucency
  (``Classification.translucency``): thin rims come out brighter than thick cores.
- **Leaves** (§4), for texels on thin double-sided translucent geometry (translucency without
  volume thickness, e.g. ``KHR_materials_diffuse_transmission`` on a leaf quad): the back face's
  obscurance W_back, estimated exactly as the front's (colour bleeding, mirrors, glass, alpha),
  counts t · W_back on top of the front's W.

Both stay apart from the front's terms as ``Terms.through_hit`` (t · the back's hit part, RGB)
and ``Terms.through_ave`` (the RGB weight of R_ave: t · the back's escaped fraction + t · W_in),
so a change of R_ave or I_A is still a recomposition with no ray (docs/design.md §2).

Determinism: a texel's other side (its back face, or its inside) is sampled as a texel of its own
whose key is the texel's key with ``OTHER_SIDE`` set (texel keys never reach bit 63), so every
random number of those rays — the hemisphere points (dimension 0) and the chains' choices
(dimensions 60+) — is a pure function of (seed, that key, sample, dimension), independent of the
front's, and the same however the texels are chunked.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from baker.atlas.rasterise import Texels
from baker.context import Context
from baker.light.hemisphere import Terms, hemisphere_rays, hemisphere_terms
from baker.materials import MaterialTable
from baker.rays.trace import Tracer
from baker.run.parallel import run_chunks
from baker.settings import Resolved

OTHER_SIDE = np.uint64(1 << 63)
"""Set in a texel's key to name its other side (back face or inside)."""


@dataclass(frozen=True)
class Translucent:
    """Per material (rows follow ``Scene.materials``): which texels get a term and its numbers.

    leaf, inner: (M,) bool (``Classification.leaf`` / ``.inner``); factor: (M, 3) translucency
    t; reach: (M,) inner d_in in world units for attenuation-bounded volumes, else the thickness
    in mesh units (``by_thickness`` (M,) bool: scaled by each instance); sigma: (M, 3) absorption
    coefficient −ln(attenuationColor) / attenuationDistance per world unit (0: none).
    """

    leaf: np.ndarray
    inner: np.ndarray
    factor: np.ndarray
    reach: np.ndarray
    by_thickness: np.ndarray
    sigma: np.ndarray

    @property
    def any(self) -> bool:
        return bool(self.leaf.any() or self.inner.any())


def translucent(materials: MaterialTable) -> Translucent:
    """The ``Translucent`` table of a scene's ``materials`` (``World.materials``)."""
    classes = materials.classes
    finite = np.array([np.isfinite(c.attenuation_distance) and c.attenuation_distance > 0
                       for c in classes], bool)
    distance = np.array([c.attenuation_distance if f else 1.0 for c, f in zip(classes, finite)])
    colour = np.array([np.clip(c.attenuation_color, 1e-6, 1.0) for c in classes]).reshape(-1, 3)
    return Translucent(
        leaf=np.array([c.leaf for c in classes], bool),
        inner=np.array([c.inner for c in classes], bool),
        factor=np.array([c.translucency for c in classes]).reshape(-1, 3),
        reach=np.where(finite, distance, [c.thickness for c in classes]),
        by_thickness=~finite,
        sigma=np.where(finite[:, None], -np.log(colour) / distance[:, None], 0.0))


def other_side(texels: Texels) -> Texels:
    """The texels seen from their other side: geometric and shading normals flipped,
    ``OTHER_SIDE`` keys."""
    return replace(texels, triangle_normal=-texels.triangle_normal, normal=-texels.normal,
                   key=texels.key | OTHER_SIDE)


def add_translucency(context: Context, texels: Texels, rows: np.ndarray, terms: Terms,
                     error_scale: tuple[np.ndarray, float] | None = None,
                     targets: np.ndarray | None = None) -> Terms:
    """``terms`` (of the texels ``rows``) with the leaves' and inner obscurances' terms set
    (``targets``: the rows' adaptive targets, as ``hemisphere.hemisphere_terms`` takes them).

    ``through_hit``/``through_ave`` are (k, 3) when the scene has leaf or closed translucent
    materials, else left None (a scene without them pays nothing); ``chain_rays`` counts the
    rays cast for them too (the back face's own and chain rays, the inner rays).
    """
    world, settings = context.world, context.settings
    table = translucent(world.materials)
    if not table.any:
        return terms
    material = world.tri_material[texels.triangle[rows]]
    hit, ave = np.zeros((len(rows), 3)), np.zeros((len(rows), 3))
    extra = terms.chain_ray_counts()
    leaves = np.flatnonzero(table.leaf[material])
    if len(leaves):
        back = hemisphere_terms(context, other_side(texels), rows=rows[leaves], error_scale=error_scale,
                                targets=None if targets is None else targets[leaves])
        t = table.factor[material[leaves]]
        hit[leaves] = t * back.w_hit
        ave[leaves] = t * back.escaped[:, None]
        extra[leaves] += back.counts + back.chain_ray_counts()
    inside = np.flatnonzero(table.inner[material])
    if len(inside):
        texel_rows = rows[inside]
        w_in = inner_obscurance(context.tracer, texels, texel_rows,
                                _reach(context, table, material[inside],
                                       texels.instance(texel_rows)),
                                table.sigma[material[inside]], settings)
        ave[inside] += table.factor[material[inside]] * w_in
        extra[inside] += settings.rays
    return replace(terms, through_hit=hit, through_ave=ave, chain_rays=extra)


def _reach(context: Context, table: Translucent, material: np.ndarray,
           instance: np.ndarray) -> np.ndarray:
    """(k,) d_in in world units of texels of ``material`` (k,) on ``instance`` (k,): a
    thickness in mesh units scales with its instance (``Context.instance_scale``)."""
    return table.reach[material] * np.where(table.by_thickness[material],
                                            context.instance_scale[instance], 1.0)


def _inner_rays(texels: Texels, rows: np.ndarray, reach: np.ndarray, settings: Resolved,
                center: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The inner rays of the texels ``rows`` (k,): origins, directions (k·rays, 3) float32 in
    ``center``'s frame and lengths (k·rays,) float32, their d_in ``reach`` (k,)."""
    origins, directions = hemisphere_rays(other_side(texels), rows, settings.rays, settings.seed,
                                          center, settings.sampling)
    return origins, directions, np.repeat(reach, settings.rays).astype(np.float32)


def other_side_rays(context: Context, texels: Texels, rows: np.ndarray, center: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The rays the texels ``rows`` cast from their other side, for a rebake's dirty search
    (geometry that meets one of them changes the texel, as for its own rays): leaves' back-face
    rays (first ``settings.rays`` samples, d_max long) and closed translucent objects' inner rays
    (d_in long). Returns (m,) the positions in ``rows`` of the texels that cast such rays, and
    their origins, directions (m·rays, 3) float32 in ``center``'s frame and lengths (m·rays,)
    float32, texel-major. The back faces' mirror/glass chains are not included (nor are the
    front's in ``integrate.hemisphere_rays``). Settings: the context's."""
    world, settings = context.world, context.settings
    rows = np.asarray(rows, np.int64)
    table = translucent(world.materials)
    material = world.tri_material[texels.triangle[rows]] if len(rows) else np.zeros(0, np.int64)
    leaves = np.flatnonzero(table.leaf[material]) if table.any else np.zeros(0, np.int64)
    inside = np.flatnonzero(table.inner[material]) if table.any else np.zeros(0, np.int64)
    origins, directions = hemisphere_rays(other_side(texels), rows[leaves], settings.rays,
                                          settings.seed, center, settings.sampling)
    lengths = np.full(len(origins), settings.d_max, np.float32)
    inner = _inner_rays(texels, rows[inside], _reach(context, table, material[inside],
                                                     texels.instance(rows[inside])),
                        settings, center)
    return (np.concatenate([leaves, inside]), np.concatenate([origins, inner[0]]),
            np.concatenate([directions, inner[1]]), np.concatenate([lengths, inner[2]]))


def inner_obscurance(tracer: Tracer, texels: Texels, rows: np.ndarray, reach: np.ndarray,
                     sigma: np.ndarray, settings: Resolved) -> np.ndarray:
    """W_in (k, 3) of the texels ``rows`` (k,): the mean over ``settings.rays`` rays into the
    object of γ(d)·A(d) (module docstring). reach: (k,) d_in, world units; sigma: (k, 3)
    absorption per world unit. Chunked over texels on ``settings.threads`` threads."""
    rays = settings.rays
    out = np.empty((len(rows), 3))

    def work(chunk: np.ndarray) -> None:
        origins, directions, length = _inner_rays(texels, rows[chunk], reach[chunk], settings,
                                                  tracer.center)
        hits = tracer.cast_local(origins, directions, length)
        d = hits.distance.astype(np.float64)
        x = np.minimum(d / np.maximum(np.repeat(reach[chunk], rays), 1e-300), 1.0)
        gamma = np.where(hits.triangle >= 0, 1.0 - np.sqrt(x), 0.0)
        absorbed = np.exp(-np.repeat(sigma[chunk], rays, axis=0) * d[:, None])
        out[chunk] = (gamma[:, None] * absorbed).reshape(len(chunk), rays, 3).mean(axis=1)

    size = max(settings.chunk_texels, 1)
    run_chunks(work, [np.arange(s, min(s + size, len(rows))) for s in range(0, len(rows), size)],
               settings.threads)
    return out
