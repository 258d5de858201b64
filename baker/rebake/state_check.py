"""Whether a bake state read back (``state.load``) can be used, member by member, before any use.

A state passes its CRCs when it was edited and its CRCs recomputed, or written by a build that
had a bug: its CRCs say only that the bytes are the ones written. Used as it is, an edited state
made a rebake fail with "a bug in baker" on this and every later bake (fingerprints ``{}``, an
atlas width of 0, a triangle index out of range), or bake a wrong lightmap without a word (NaN
terms: all black; ``escaped`` of 5: a page five times too bright). So every member is checked
against what this build writes — dtype, shape, rows, range, finite values, index bounds, the
fingerprints' structure — and anything else raises ``StateUnusable``, which the rebake turns into
a full bake with the reason (``fallback.FullBake``): "the bake state is unusable: …".

What cannot be told from a well-formed state is a plausible value edited into another plausible
value (an ``escaped`` of 0.7 for 0.6): the state is trusted as far as the files beside the output
are; it holds nothing that runs.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from baker.atlas.validity import STATE_NAMES
from baker.light.hemisphere import most_escaped
from baker.rebake.state import BakeState, StateUnusable

_ROUNDING = 1e-9  # fractions are means of values on a 2^-40 grid: at most 1 plus rounding
_MAX_SIDE = 1 << 16  # a page side; settings cap page_size far below
_PER_TEXEL = {
    # group: {field: (dtype, trailing shape (-1: any width), rows may be 0, lowest, highest)}
    "texels": {"key": ("<u8", (), False, None, None),
               "triangle": ("<i8", (), False, 0, None),
               "moved": ("|b1", (), False, None, None),
               "moved_position": ("<f8", (3,), False, None, None)},
    "validity": {"state": ("|i1", (), False, 0, len(STATE_NAMES) - 1),
                 "moved_by": ("<f8", (), False, 0.0, None),
                 "back_fraction": ("<f8", (), False, 0.0, 1.0 + _ROUNDING),
                 "touching": ("|b1", (), False, None, None)},
    "terms": {"w_hit": ("<f8", (3,), False, 0.0, None),
              "escaped": ("<f8", (), False, 0.0, None),  # ≤ most_escaped: check_state
              "hit_sq": ("<f8", (), False, 0.0, None),
              "counts": ("<i8", (), False, 0, None),
              "half_split": ("<f8", (2,), False, None, None),
              "chain_rays": ("<i8", (), True, 0, None),
              "capped": ("<i8", (), True, 0, None),
              "through_hit": ("<f8", (3,), True, None, None),
              "through_ave": ("<f8", (3,), True, None, None),
              "aim_hit": ("<f8", (3,), True, None, None),
              "aim_escaped": ("<f8", (3,), True, None, None),
              "aim_split": ("<f8", (6,), True, None, None),
              "escaped_tint": ("<f8", (3,), True, None, None)},
    "direct": {"punctual": ("<f8", (-1,), False, 0.0, None),
               "punctual_var": ("<f8", (-1,), False, 0.0, None),
               "emission": ("<f8", (3,), True, None, None),
               "emission_var": ("<f8", (), True, 0.0, None),
               "sky": ("<f8", (3,), True, None, None),
               "sky_var": ("<f8", (), True, 0.0, None),
               "texel_rays": ("<i8", (), True, 0, None),
               "punctual_aim": ("<f8", (-1, 3), True, None, None),
               "punctual_aim_var": ("<f8", (-1,), True, 0.0, None),
               "emission_aim": ("<f8", (3,), True, None, None),
               "emission_aim_var": ("<f8", (), True, 0.0, None),
               "sky_aim": ("<f8", (3,), True, None, None),
               "sky_aim_var": ("<f8", (), True, 0.0, None)},
}
"""Every per-texel array of a state: N rows (or 0 where the field may be absent), its dtype,
the shape of a row, and the range of its values (all finite)."""


def unusable(what: str) -> StateUnusable:
    return StateUnusable(f"the bake state is unusable: {what}")


def check_state(state: BakeState, max_depth: int) -> None:
    """Raise ``StateUnusable`` unless every member of ``state`` is as this build writes it:
    the atlas's scalars and per-instance arrays, the instances' world matrices, and every
    per-texel array (``_PER_TEXEL``) with as many rows as there are texels; ``escaped`` at most
    what chains of ``max_depth`` bounces reach (``hemisphere.most_escaped``: above 1 through
    glass and mirrors; a state of another max_depth is baked anew by the diff anyway)."""
    _check_atlas(state)
    world = state.instance_world
    _array("instance_world", world, "<f8", (4, 4))
    texels = state.groups.get("texels")
    if texels is None:
        return
    count = len(texels.key)
    for group, members in _PER_TEXEL.items():
        obj = state.groups.get(group)
        if obj is None:
            continue
        for name, (dtype, row, may_be_empty, low, high) in members.items():
            value = getattr(obj, name)
            if value is None and may_be_empty:
                continue
            _array(f"{group}/{name}", value, dtype, row, low, high)
            if len(value) != count and not (may_be_empty and len(value) == 0):
                raise unusable(f"{group}/{name} has {len(value)} rows for {count} texels")
    _check_texels(state, texels, count)
    terms = state.groups.get("terms")
    if terms is not None:
        _array("terms/escaped", terms.escaped, "<f8", (), 0.0,
               most_escaped(max_depth) + _ROUNDING)
    direct = state.groups.get("direct")
    if direct is not None:
        lights = direct.punctual.shape[1]
        _array("direct/light_colours", direct.light_colours, "<f8", (3,))
        if direct.punctual_var.shape[1] != lights or len(direct.light_colours) != lights:
            raise unusable(f"direct light of {lights} lights, but {len(direct.light_colours)} "
                           f"light colours and {direct.punctual_var.shape[1]} variances")
        if not _whole(direct.rays_per_texel) or direct.rays_per_texel < 0:
            raise unusable(f"direct/rays_per_texel is {direct.rays_per_texel!r}")


def _check_atlas(state: BakeState) -> None:
    """The atlas: page sides and count, density and padding in range; each instance's vertex
    and triangle arrays of the right dtype and shape, its triangles indexing its own vertices,
    its pages existing pages (or -1), its UVs finite."""
    atlas = state.atlas
    if not _whole(atlas.page_count) or atlas.page_count < 0:
        raise unusable(f"atlas page_count {atlas.page_count!r}")
    for name in ("width", "height"):  # 0 when nothing is baked (no page)
        side = getattr(atlas, name)
        if not _whole(side) or not (0 if atlas.page_count == 0 else 1) <= side <= _MAX_SIDE:
            raise unusable(f"atlas {name} {side!r} is not a page side")
    if not _whole(atlas.padding) or atlas.padding < 0:
        raise unusable(f"atlas padding {atlas.padding!r}")
    density = atlas.texel_density
    if not isinstance(density, (int, float)) or isinstance(density, bool) or not (
            math.isfinite(density) and density > 0):
        raise unusable(f"atlas texel_density {density!r}")
    for unwrap in atlas.instances:
        at = f"atlas instance {unwrap.instance!r}"
        if not _whole(unwrap.instance) or unwrap.instance < 0:
            raise unusable(f"{at} is not an instance index")
        _array(f"{at} vertices", unwrap.vertices, "<i8", (), 0)
        _array(f"{at} triangles", unwrap.triangles, "<i8", (3,), 0, len(unwrap.vertices) - 1)
        _array(f"{at} uv", unwrap.uv, "<f8", (2,))
        _array(f"{at} pages", unwrap.pages, "<i8", (), -1, atlas.page_count - 1)
        if len(unwrap.uv) != len(unwrap.vertices) or len(unwrap.pages) != len(unwrap.triangles):
            raise unusable(f"{at}: {len(unwrap.vertices)} vertices, {len(unwrap.uv)} UVs, "
                           f"{len(unwrap.triangles)} triangles, {len(unwrap.pages)} pages")


def _check_texels(state: BakeState, texels, count: int) -> None:
    """Texel keys strictly increasing and inside the atlas's pages; triangle counts whole."""
    atlas = state.atlas
    _array("texels/triangle_texels", texels.triangle_texels, "<i8", (), 0)
    if count:
        key = texels.key
        if np.any(key[1:] <= key[:-1]):
            raise unusable("texels/key is not strictly increasing")
        texels_in_pages = atlas.page_count * atlas.height * atlas.width
        if int(key[-1]) >= texels_in_pages:
            raise unusable(f"texel key {int(key[-1])} lies past the atlas's {texels_in_pages} "
                           "texels")
        if int(texels.triangle.max()) >= len(texels.triangle_texels):
            raise unusable(f"texel triangle {int(texels.triangle.max())} of "
                           f"{len(texels.triangle_texels)} triangles")


def check_for_scene(state: BakeState, scene, world) -> None:
    """What the state's indices mean in the scene being rebaked, once the fingerprints have
    said it is the same scene (instances, meshes, triangles): each atlas instance an instance of
    the scene whose unwrap has its primitive's triangles and indexes its vertices; one world
    matrix per instance; the texels' triangles the world's."""
    instances = len(scene.instances)
    if len(state.instance_world) != instances:
        raise unusable(f"{len(state.instance_world)} world matrices for {instances} instances")
    for unwrap in state.atlas.instances:
        if unwrap.instance >= instances:
            raise unusable(f"atlas instance {unwrap.instance} of {instances}")
        primitive = scene.primitives[scene.instances[unwrap.instance].primitive]
        if len(unwrap.triangles) != len(primitive.triangles) or (
                len(unwrap.vertices) and int(unwrap.vertices.max()) >= len(primitive.positions)):
            raise unusable(f"atlas instance {unwrap.instance} does not unwrap its primitive "
                           f"({len(unwrap.triangles)} of {len(primitive.triangles)} triangles)")
    texels = state.groups.get("texels")
    if texels is not None and len(texels.triangle_texels) != len(world.triangles):
        raise unusable(f"texels of {len(texels.triangle_texels)} triangles for the scene's "
                       f"{len(world.triangles)}")


def check_fingerprints(stored: Any, current: dict) -> None:
    """Raise ``StateUnusable`` unless the stored fingerprints have the structure of those this
    build makes of the scene (``current``): the same keys in every object, lists of items like
    the current list's, numbers where numbers are, strings where strings are (``None`` stands
    for any plain value or list of them: a setting left to its default, such as no sky). Values
    may differ: that is the diff."""
    mismatch = _structure(stored, current, "fingerprints")
    if mismatch is not None:
        raise unusable(mismatch)


def stored_density(fingerprints: Any) -> float | None:
    """The texel density the state's bake used (``settings.values.texel_density``), None if it
    derived none; ``StateUnusable`` when it is not a positive finite number."""
    try:
        density = fingerprints["settings"]["values"].get("texel_density")
    except (TypeError, KeyError, AttributeError):
        raise unusable("fingerprints.settings.values is not an object") from None
    if density is not None and not (isinstance(density, (int, float))
                                    and not isinstance(density, bool)
                                    and math.isfinite(density) and density > 0):
        raise unusable(f"stored texel density {density!r}")
    return density


def _structure(stored: Any, current: Any, at: str) -> str | None:
    """Where (a JSON path and what) ``stored`` differs in structure from ``current``; None."""
    if isinstance(current, dict):
        if not isinstance(stored, dict):
            return f"{at} is not an object"
        if set(stored) != set(current):
            return f"{at} has keys {sorted(map(str, stored))[:8]}, not {sorted(current)[:8]}"
        for key, value in current.items():
            found = _structure(stored[key], value, f"{at}.{key}")
            if found is not None:
                return found
        return None
    if stored is None and _plain_list(current) or current is None and _plain_list(stored):
        return None  # a setting given on one bake, left to its default (None) on the other
    if isinstance(current, list):
        if not isinstance(stored, list):
            return f"{at} is not a list"
        if not current:
            return None
        for i, item in enumerate(stored):
            found = _structure(item, current[min(i, len(current) - 1)], f"{at}[{i}]")
            if found is not None:
                return found
        return None
    if isinstance(stored, (dict, list)):
        return f"{at} is a {type(stored).__name__}, not a plain value"
    if stored is None or current is None:
        return None
    if isinstance(current, bool) or isinstance(stored, bool):
        return None if isinstance(current, bool) and isinstance(stored, bool) else (
            f"{at} is {stored!r}, not a true/false")
    if isinstance(current, (int, float)):
        return None if isinstance(stored, (int, float)) else f"{at} is {stored!r}, not a number"
    if isinstance(stored, type(current)):
        return None
    return f"{at} is {stored!r}, not a {type(current).__name__}"


def _plain_list(value: Any) -> bool:
    """Whether ``value`` is a list of plain values (no object or list in it)."""
    return isinstance(value, list) and not any(isinstance(v, (dict, list)) for v in value)


def _array(name: str, value: Any, dtype: str, row: tuple[int, ...], low=None, high=None) -> None:
    """``value`` an ndarray of ``dtype`` whose rows have shape ``row`` (-1: any length), all
    finite, within [``low``, ``high``] where given."""
    if not isinstance(value, np.ndarray) or value.dtype.str != dtype:
        kind = value.dtype.str if isinstance(value, np.ndarray) else type(value).__name__
        raise unusable(f"{name} is {kind}, not {dtype}")
    if value.ndim != 1 + len(row) or any(r not in (-1, s) for r, s in zip(row, value.shape[1:])):
        raise unusable(f"{name} has shape {value.shape}, rows of {row} expected")
    if value.size == 0 or value.dtype.kind == "b":
        return
    least, most = value.min(), value.max()  # NaN anywhere makes both NaN
    if value.dtype.kind == "f" and not (math.isfinite(least) and math.isfinite(most)):
        raise unusable(f"{name} holds values that are not finite")
    if low is not None and least < low:
        raise unusable(f"{name} holds {least}, below {low}")
    if high is not None and most > high:
        raise unusable(f"{name} holds {most}, above {high}")


def _whole(value: Any) -> bool:
    """An int (not a bool) or a numpy integer."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)
