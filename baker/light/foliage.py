"""Foliage fast mode (``--foliage approx``): the obscurance of leaves from a closed form.

A tree is hundreds of thousands of alpha-cut leaf quads, and tracing among them is where
obscurance rays cost most and matter least: the result is a soft darkening with depth into the
crown. In this mode (Hegeman et al. 2006, ``crowns.py``):

- **What is foliage.** Per node: its ``extras.foliage`` ("crown", "grass" or "none") when set,
  else its triangles whose material is thin, double-sided and alpha-cut or translucent (what
  ``materials.classify`` already says: a leaf). One crown per node, its shells fitted to its
  leaves' corners (``crowns.fit_shells``).
- **Leaf and grass texels** cast no ray: V = exp(−αρ f V_cap) in the crown's nearest shell (grass:
  V = (P_z / 2h)(1 + cos θ), P_z the height above the node's lowest point, h its height, θ the
  normal's angle from +Y), escaped = V and w_hit = (1 − V) · c, c the colour an occluded ray
  picks up. A leaf's back face (``inner.py``) gets the same from −n.
- **Every other texel** is traced as before, but against the scene without the crowns' leaves
  (``Tracer(hidden=...)``); what the crowns take from it is put back in closed form: inside a
  shell (a trunk) the crown's V, outside it the large-occluder term V = 1 − A_SA / 2π for each
  shell whose surface is within d_max, weighted by the share of the shell above the texel's
  plane; the escaped rays' share 1 − V picks up the crown's colour c.
- **αρ and c are fitted per crown** from a few texels traced in the full scene
  (``FIT_TEXELS`` a crown, ``settings.rays`` each): αρ by least squares on V
  (``crowns.fit_density``), c by least squares on w_hit ≈ (1 − V) c. ``extras.foliage_density``
  or ``--foliage-density`` sets αρ instead. As many texels again, held out, measure the error:
  RMSE and bias of W's luminance (at the bake's R_ave) against the traced W, per crown and
  overall, on the fit's texels and on the held-out ones (``Foliage.report``).

Determinism: the fit's texels are chosen by a hash of (seed, texel key), the fit is a function
of their traced terms, and the closed forms are functions of a texel's point and normal: the same
bytes however the bake is cut into parts, chunks or threads.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np

from baker.atlas.rasterise import Coverage, Owners, Texels, texels_of
from baker.atlas.layout import Atlas
from baker.atlas.validity import Faces, check_texels
from baker.errors import InputError
from baker.geometry.surface import luminance
from baker.context import Context
from baker.geometry.world import World
from baker.light.crowns import (
    DensityFit,
    Shell,
    crown_visibility,
    fit_density,
    fit_shells,
    grass_visibility,
    large_occluder_visibility,
    nearest_shell,
    shell_terms,
)
from baker.light.directional import uniform_aim
from baker.light.hemisphere import Surfaces, Terms
from baker.light.inner import translucent
from baker.light.integrate import integrate
from baker.materials import TRANSLUCENT
from baker.rays.dimensions import FOLIAGE_FIT
from baker.rays.sampling import hash_u32
from baker.rays.trace import Tracer

FIT_TEXELS = 128
"""Texels a crown's fit traces (and as many again held out for its error), at most."""
KINDS = ("crown", "grass", "none")  # what a node's extras.foliage may say


@dataclass(frozen=True)
class Error:
    """W's luminance, approximate minus traced, over some texels: RMSE, bias (mean), count."""

    rmse: float
    bias: float
    texels: int

    @classmethod
    def of(cls, approx: np.ndarray, traced: np.ndarray) -> "Error":
        diff = approx - traced
        if not len(diff):
            return cls(0.0, 0.0, 0)
        return cls(float(np.sqrt(np.mean(diff * diff))), float(diff.mean()), len(diff))

    def as_dict(self) -> dict:
        return {"rmse": self.rmse, "bias": self.bias, "texels": self.texels}


@dataclass(frozen=True)
class Crown:
    """One node's foliage. kind: "crown" or "grass"; shells: the crown's (empty for grass);
    layer: grass's (lowest world y, height); density: αρ per world unit³ and where it came from
    (``source``: "fit", "extras", "setting", "leaf area" for a crown with no texels to fit,
    "grass term" for grass, which has none);
    colour: (3,) c, the R·ρ an occluded ray picks up; fit: the density fit (None if not fitted);
    errors: {"fit": Error, "held_out": Error}."""

    node: int
    name: str
    kind: str
    shells: tuple[Shell, ...]
    layer: tuple[float, float]
    density: float
    source: str
    colour: np.ndarray
    fit: DensityFit | None = None
    errors: dict | None = None

    def visibility(self, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """(k,) the closed-form V at ``points`` (k, 3) world facing unit ``normals`` (k, 3)."""
        if self.kind == "grass":
            base, height = self.layer
            return grass_visibility(points[:, 1] - base, max(height, 1e-9), normals[:, 1])
        return crown_visibility(self.density, *self.cap_terms(points, normals))

    def cap_terms(self, points: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(f, V_cap), each (k,), in each point's nearest shell (``crowns.shell_terms``)."""
        f, v_cap = np.zeros(len(points)), np.zeros(len(points))
        owner = nearest_shell(list(self.shells), points)
        for j, shell in enumerate(self.shells):
            rows = np.flatnonzero(owner == j)
            f[rows], v_cap[rows] = shell_terms(shell, points[rows], normals[rows])
        return f, v_cap

    def as_dict(self) -> dict:
        out = {"node": self.node, "name": self.name, "kind": self.kind,
               "density": self.density, "density_source": self.source,
               "colour": self.colour.tolist(),
               "shells": [s.as_dict() for s in self.shells]}
        if self.kind == "grass":
            out["layer"] = {"base": self.layer[0], "height": self.layer[1]}
        if self.fit is not None:
            out["fit_residual"] = self.fit.residual
        if self.errors is not None:
            out["error"] = {name: e.as_dict() for name, e in self.errors.items()}
        return out


@dataclass(frozen=True)
class Foliage:
    """The scene's foliage for one bake: group: (T,) int64 crown index of every world triangle
    (−1: not foliage); crowns; tracer: Embree's scene without the crowns' leaves (grass stays);
    errors: the overall {"fit", "held_out"} Error; rays: rays the fit and its check cast."""

    group: np.ndarray
    crowns: tuple[Crown, ...]
    tracer: Tracer
    errors: dict
    rays: int

    def report(self) -> dict:
        """What the bake's report says of the foliage mode."""
        return {"mode": "approx", "rays": self.rays,
                "error": {name: e.as_dict() for name, e in self.errors.items()},
                "crowns": [c.as_dict() for c in self.crowns]}

    def texel_groups(self, texels: Texels, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """(k,) the crown of each texel ``rows`` (−1: traced)."""
        return self.group[texels.triangle[rows]]

    def hidden(self) -> np.ndarray:
        """(T,) bool: the world triangles obscurance rays pass through (the crowns' leaves;
        grass stays), as ``tracer`` hides them."""
        return hidden_leaves(self.group, [c.kind for c in self.crowns])


def hidden_leaves(group: np.ndarray, kinds: list[str]) -> np.ndarray:
    """(T,) bool: the triangles of ``group`` (T,) (crown index, −1: none) whose crown's kind
    (``kinds``) is "crown"."""
    crown = np.array([k == "crown" for k in kinds] + [False], bool)
    return crown[group]  # −1 indexes the appended False


def _node_kind(context: Context, node: int) -> tuple[str | None, float | None]:
    """(extras.foliage, extras.foliage_density) of node ``node``; InputError for values
    that are not one of ``KINDS`` or not a number above 0."""
    extras = context.nodes[node].extras
    kind, density = extras.get("foliage"), extras.get("foliage_density")
    where = f"nodes[{node}].extras"
    if kind is not None and kind not in KINDS:
        raise InputError(f"foliage {kind!r} is not one of {', '.join(KINDS)}",
                         file=context.source, where=where + ".foliage",
                         fix='set "foliage" to "crown", "grass" or "none", or leave it out')
    if density is not None and not (isinstance(density, (int, float)) and not isinstance(
            density, bool) and math.isfinite(density) and density > 0):
        raise InputError(f"foliage_density {density!r} is not a number above 0",
                         file=context.source, where=where + ".foliage_density",
                         fix="give a positive αρ (per cubic metre), or leave it out to fit it")
    return kind, None if density is None else float(density)


def find_foliage(context: Context) -> list[tuple[int, str, np.ndarray, float | None]]:
    """The scene's foliage, node by node: (node, kind, world triangles (k,) int64, density
    from the extras or None). A node's extras decide; without them its triangles of leaf
    materials (thin, double-sided, alpha-cut or translucent) are a crown."""
    world = context.world
    classes = context.materials.classes
    leafy = np.array([c.double_sided and c.thickness <= 0.0 and (
        c.alpha_tested or c.weights[TRANSLUCENT] > 0) for c in classes], bool)
    by_node: dict[int, list[int]] = {}
    for i, node in enumerate(context.instance_node.tolist()):
        by_node.setdefault(node, []).append(i)
    found = []
    for node, instances in sorted(by_node.items()):
        kind, density = _node_kind(context, node)
        tris = np.concatenate([world.instance_triangles(i) for i in instances])
        if kind is None:
            tris, kind = tris[leafy[world.tri_material[tris]]], "crown"
        if kind != "none" and len(tris):
            found.append((node, kind, tris, density))
    return found


def _ranked_rows(coverage: Coverage, wanted: np.ndarray, seed: int) -> np.ndarray:
    """The rows of ``coverage`` whose triangles are ``wanted`` ((T,) bool), ordered by a hash
    of (seed, texel key): the first few are a fixed random sample."""
    rows = np.flatnonzero(wanted[coverage.triangle])
    rank = hash_u32(np.uint64(seed), coverage.key[rows], np.uint64(0), np.uint64(FOLIAGE_FIT))
    return rows[np.lexsort((coverage.key[rows], rank))]


def _prior_density(shells: tuple[Shell, ...], area: float) -> float:
    """αρ for a crown with no texels to fit: a random leaf cloud of leaf area a per volume
    stops a ray at σ = a/2 per unit length; asking V = exp(−σR) where the cap is the whole
    shell (4πR³/3, at its surface facing its centre) gives αρ = 3σ / (4πR²), R the largest
    shell's equal-volume radius."""
    volume = sum(s.volume for s in shells)
    radius = max(s.radius for s in shells)
    return 3.0 * (area / max(volume, 1e-300) / 2.0) / (4.0 * np.pi * radius * radius)


@dataclass(frozen=True)
class FitInputs:
    """What choosing and tracing the fit's texels needs from the bake (``pipeline.full``)."""

    atlas: Atlas
    coverage: Coverage
    owned: Owners
    faces: Faces
    surfaces: Surfaces
    r_ave: np.ndarray  # (3,) the R_ave the estimator uses, for W's luminance


def prepare_foliage(context: Context, inputs: FitInputs) -> Foliage | None:
    """The scene's ``Foliage`` with every crown fitted, or None when it has none."""
    world, tracer, settings = context.world, context.tracer, context.settings
    found = find_foliage(context)
    if not found:
        return None
    group = np.full(len(world.triangles), -1, np.int64)
    samples = []
    for j, (_, kind, tris, _) in enumerate(found):
        group[tris] = j
        wanted = np.zeros(len(world.triangles), bool)
        wanted[tris] = True
        samples.append(_ranked_rows(inputs.coverage, wanted, settings.seed)[:2 * FIT_TEXELS])
    rows = np.concatenate(samples)
    texels = texels_of(inputs.atlas, world, inputs.coverage, rows, inputs.owned)
    texels, _ = check_texels(context.surfaces, world, tracer, texels, settings.d_max,
                             threads=settings.threads, faces=inputs.faces)
    traced = integrate(context, texels, surfaces=inputs.surfaces)
    offsets = np.cumsum([0] + [len(s) for s in samples])
    mine = [np.arange(offsets[j], offsets[j + 1]) for j in range(len(found))]
    crowns = tuple(_fit_crown(context, inputs, node, kind, tris, density, texels, traced,
                              mine[j])
                   for j, (node, kind, tris, density) in enumerate(found))
    hidden = hidden_leaves(group, [kind for _, kind, _, _ in found])
    foliage = Foliage(group, crowns, Tracer(world, hidden=hidden), {},
                      traced.rays + int(traced.chain_ray_counts().sum()))
    return _with_errors(foliage, world, texels, traced, mine, inputs.r_ave)


def _with_errors(foliage: Foliage, world: World, texels: Texels, traced: Terms,
                 mine: list[np.ndarray], r_ave: np.ndarray) -> Foliage:
    """``foliage`` with each crown's Error and the overall one: crown j's sample texels are the
    rows ``mine[j]`` of ``texels`` (traced: ``traced``), every other one fitted (``_fit_crown``)
    and the rest held out; W's luminance at R_ave ``r_ave`` (3,)."""
    approx = foliage_terms(foliage, world, texels, np.arange(len(texels)))
    w_approx, w_traced = (luminance(t.obscurance(r_ave)) for t in (approx, traced))

    def errors(fit: np.ndarray, held: np.ndarray) -> dict:
        return {"fit": Error.of(w_approx[fit], w_traced[fit]),
                "held_out": Error.of(w_approx[held], w_traced[held])}

    crowns = tuple(replace(c, errors=errors(m[0::2], m[1::2]))
                   for c, m in zip(foliage.crowns, mine))
    every = [np.concatenate([m[k::2] for m in mine]) for k in (0, 1)]
    return replace(foliage, crowns=crowns, errors=errors(*every))


def _fit_crown(context: Context, inputs: FitInputs, node: int, kind: str, tris: np.ndarray,
               density: float | None, texels: Texels, traced: Terms, mine: np.ndarray) -> Crown:
    """One crown fitted on the sample rows ``mine`` of ``texels`` (every other one: the rest
    are held out), whose traced terms are ``traced``."""
    world, settings = context.world, context.settings
    name = context.nodes[node].name or f"node {node}"
    corners = world.positions[world.triangles[tris]].reshape(-1, 3)
    shells = () if kind == "grass" else tuple(fit_shells(corners))
    layer = (float(corners[:, 1].min()), float(np.ptp(corners[:, 1])))
    source, value = ("extras", density) if density is not None else (
        ("setting", settings.foliage_density) if settings.foliage_density is not None else
        ("fit", None))
    if kind == "grass":  # the grass term has no density
        source, value = "grass term", 0.0
    albedo = inputs.surfaces.table[tris].mean(axis=0)
    if value is None and not len(mine) and kind == "crown":
        source, value = "leaf area", _prior_density(shells, float(world.areas(tris).sum()))
    crown = Crown(node, name, kind, shells, layer, value or 0.0, source, 0.5 * albedo)
    fit_rows = mine[0::2]
    if not len(fit_rows):
        return crown
    points, normals = texels.position[fit_rows], texels.geometric_normal(fit_rows)
    escaped = traced.escaped[fit_rows]
    fitted = None
    if kind == "crown":
        f, v_cap = crown.cap_terms(points, normals)
        fitted = fit_density(f * v_cap, escaped)
        if value is None:
            crown = replace(crown, density=fitted.density)
    occluded = 1.0 - crown.visibility(points, normals)
    weight = float(occluded @ occluded)
    colour = (occluded @ traced.w_hit[fit_rows]) / weight if weight > 0 else crown.colour
    return replace(crown, colour=np.clip(colour, 0.0, None), fit=fitted)


def foliage_terms(foliage: Foliage, world: World, texels: Texels, rows: np.ndarray,
                  directional: bool = False) -> Terms:
    """The closed-form terms of the foliage texels ``rows`` (k,): escaped = V, w_hit = (1 − V)·c,
    no ray (counts 0, the splits 0); hit_sq as if a share 1 − V of rays met c. A leaf's back
    face (a leaf material, ``inner.py``) adds t·(1 − V_back)·c and t·V_back as the light through
    it. The terms of the rows are in ``rows``' order."""
    k = len(rows)
    group = foliage.texel_groups(texels, rows)
    points, normals = texels.position[rows], texels.geometric_normal(rows)
    visibility, colour = np.ones(k), np.zeros((k, 3))
    back = np.ones(k)
    for j, crown in enumerate(foliage.crowns):
        mine = np.flatnonzero(group == j)
        visibility[mine] = crown.visibility(points[mine], normals[mine])
        back[mine] = crown.visibility(points[mine], -normals[mine])
        colour[mine] = crown.colour
    occluded = (1.0 - visibility)[:, None]
    w_hit = occluded * colour
    lum = luminance(colour)
    terms = Terms(w_hit=w_hit, escaped=visibility, hit_sq=(1.0 - visibility) * lum * lum,
                  counts=np.zeros(k, np.int64), half_split=np.zeros((k, 2)))
    if directional:  # the closed form follows no direction: uniform (``light.directional``)
        terms = replace(terms, aim_hit=uniform_aim(luminance(w_hit), normals),
                        aim_escaped=uniform_aim(visibility, normals), aim_split=np.zeros((k, 6)))
    table = translucent(world.materials)
    if not table.any:
        return terms
    material = world.tri_material[texels.triangle[rows]]
    t = np.where(table.leaf[material][:, None], table.factor[material], 0.0)
    return replace(terms, through_hit=t * (1.0 - back)[:, None] * colour,
                   through_ave=t * back[:, None])


def shade_by_crowns(foliage: Foliage, texels: Texels, rows: np.ndarray, terms: Terms,
                    d_max: float) -> Terms:
    """``terms`` of the traced texels ``rows``, traced without the crowns' leaves, with what the
    crowns take from their escaped rays: in each shell within d_max of a texel, V (inside it,
    the crown's closed form; outside, 1 − A_SA / 2π times the share of the shell above the
    texel's plane); the escaped share 1 − V of the rays picks up the crown's colour."""
    points, normals = texels.position[rows], texels.geometric_normal(rows)
    visibility, picked = np.ones(len(rows)), np.zeros((len(rows), 3))
    for crown in foliage.crowns:
        if crown.kind != "crown":
            continue
        inside = np.zeros(len(rows), bool)
        for shell in crown.shells:
            inside |= np.linalg.norm(shell.to_unit(points), axis=1) < 1.0
        v = np.ones(len(rows))
        v[inside] = crown.visibility(points[inside], normals[inside])
        for shell in crown.shells:
            offset = shell.center - points
            distance = np.linalg.norm(offset, axis=1)
            near = ~inside & (distance - shell.radius < d_max)
            above = np.clip(0.5 + 0.5 * np.einsum("ij,ij->i", offset, normals) / shell.radius,
                            0.0, 1.0)
            occluder = 1.0 - large_occluder_visibility(shell.radius, distance)
            v = np.where(near, v * (1.0 - occluder * above), v)
        picked += (1.0 - v)[:, None] * crown.colour
        visibility *= v
    occluded = 1.0 - visibility
    share = np.divide(picked, occluded[:, None], out=np.zeros_like(picked),
                      where=occluded[:, None] > 0)
    lum = luminance(share)
    escaped = terms.escaped
    w_hit = terms.w_hit + (escaped * occluded)[:, None] * share

    def split(s: np.ndarray) -> np.ndarray:
        return np.column_stack([s[:, 0] + occluded * lum * s[:, 1], visibility * s[:, 1]])

    tint = terms.escaped_tint  # a tinted escape meets the crowns as a grey one does
    return replace(terms, w_hit=w_hit, escaped=escaped * visibility,
                   hit_sq=terms.hit_sq + escaped * occluded * lum * lum,
                   half_split=split(terms.half_split),
                   escaped_tint=None if tint is None else tint * visibility[:, None])


def shaded(foliage: Foliage, texels: Texels, terms: Terms, d_max: float) -> Terms:
    """The terms a texel's light is composed from: ``terms`` (as ``integrate_with_foliage``
    gives them, and the bake state keeps them) with every traced texel shaded by the crowns
    (``shade_by_crowns``), the foliage texels' closed forms as they are. Kept apart from the
    tracing so that a rebake can trace a texel again and shade every texel by crowns that
    moved or were fitted anew, in closed form."""
    rows = np.flatnonzero(foliage.texel_groups(texels) < 0)
    shading = ("w_hit", "escaped", "hit_sq", "half_split")  # what shade_by_crowns changes
    shading += ("escaped_tint",) if terms.escaped_tint is not None else ()
    mine = replace(terms, **{name: getattr(terms, name)[rows] for name in shading})
    done = shade_by_crowns(foliage, texels, rows, mine, d_max)
    columns = {}
    for name in shading:
        columns[name] = getattr(terms, name).copy()
        columns[name][rows] = getattr(done, name)
    return replace(terms, **columns)


def integrate_with_foliage(foliage: Foliage, context: Context, texels: Texels,
                           progress=None, error_scale=None,
                           surfaces: Surfaces | None = None,
                           targets: np.ndarray | None = None) -> Terms:
    """``integrate.integrate`` of every texel in foliage mode: the foliage texels' terms from
    the closed forms, the others traced without the crowns' leaves (not yet shaded by them:
    ``shaded`` does that when their light is composed), in ``texels`` order (``targets``:
    every texel's adaptive target, as ``hemisphere.hemisphere_terms`` takes them). The
    context's settings; its tracer is left for the foliage's, without the crowns' leaves."""
    group = foliage.texel_groups(texels)
    closed, traced_rows = np.flatnonzero(group >= 0), np.flatnonzero(group < 0)
    traced = integrate(context.with_tracer(foliage.tracer), texels, progress, traced_rows,
                       error_scale, surfaces=surfaces,
                       targets=None if targets is None else targets[traced_rows])
    approx = foliage_terms(foliage, context.world, texels, closed,
                           context.settings.directional_pages)
    if progress is not None and len(closed):
        progress(len(closed), 0)  # closed forms: no ray
    return _merged(len(texels), (traced_rows, traced), (closed, approx))


def _merged(count: int, *parts: tuple[np.ndarray, Terms]) -> Terms:
    """One ``Terms`` of ``count`` rows from terms of disjoint rows (each (rows, terms)); an
    optional column (chain counts, light through) that some part lacks is zeros there."""
    if not any(len(rows) for rows, _ in parts):
        return parts[0][1]
    values = {}
    for f in fields(Terms):
        given = [(rows, getattr(t, f.name)) for rows, t in parts if len(rows)]
        full = [(rows, v) for rows, v in given if v is not None and len(v) == len(rows)]
        if not full:  # None, or the empty array of a column not counted
            values[f.name] = given[0][1]
            continue
        out = np.zeros((count,) + full[0][1].shape[1:], full[0][1].dtype)
        for rows, v in full:
            out[rows] = v
        values[f.name] = out
    return Terms(**values)
