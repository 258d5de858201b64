"""The scene's KHR_lights_punctual lights as placed by their nodes (``read_lights``), with the
sizes their extras give (``extras.radius``, ``extras.angular_diameter``)."""

from __future__ import annotations

import numpy as np

from baker.errors import InputError
from baker.gltf.context import Context, checked_item, finite, invalid, or_default, schema
from baker.punctual import Light
from baker.settings import MAX_LIGHT


_LIGHT_KINDS = ("directional", "point", "spot")


def read_lights(ctx: Context, placements: list[tuple[int, np.ndarray]]) -> tuple[Light, ...]:
    """Every node's KHR_lights_punctual light in world space, in node walk order.

    Position is the node's world translation, direction its local −Z through the (float64) world
    matrix, normalised. Range, intensity and cone angles ignore node scale (the extension says so).
    Soft-shadow sizes come from the light's ``extras``: ``radius`` (metres, point/spot) and
    ``angular_diameter`` (degrees, directional). Spot cones outside 0 ≤ inner ≤ outer ≤ π/2 are
    clamped into it and the clamp is recorded in ``ctx.skipped``.
    """
    top = (ctx.document.extensions or {}).get("KHR_lights_punctual") or {}
    definitions = top.get("lights") if isinstance(top, dict) else None
    if definitions is None:
        definitions = []
    if not isinstance(definitions, list):
        raise invalid("KHR_lights_punctual.lights is not a list", ctx.file, "extensions.KHR_lights_punctual")
    lights = []
    for node_index, world in placements:
        extension = (ctx.document.nodes[node_index].extensions or {}).get("KHR_lights_punctual")
        if extension is None:
            continue
        referrer = f"nodes[{node_index}].extensions.KHR_lights_punctual.light"
        index = extension.get("light") if isinstance(extension, dict) else None
        definition = checked_item(definitions, index, "KHR_lights_punctual lights", ctx.file, referrer)
        where = f"extensions.KHR_lights_punctual.lights[{index}]"
        with schema(ctx.file, where):
            light = _read_light(ctx, definition, index, node_index, world, where)
        if light is not None:
            lights.append(light)
    return tuple(lights)


def _read_light(ctx: Context, definition: dict, index: int, node: int, world: np.ndarray,
                where: str) -> Light | None:
    """One placed light; None (recorded as skipped) when the node's matrix collapses −Z."""
    kind = definition.get("type")
    if kind not in _LIGHT_KINDS:
        raise invalid(f"light type {kind!r} is not directional, point or spot", ctx.file, f"{where}.type")
    colour = finite(ctx, or_default(definition.get("color"), [1.0, 1.0, 1.0]), 3, f"{where}.color")
    intensity = finite(ctx, [or_default(definition.get("intensity"), 1.0)], 1, f"{where}.intensity")[0]
    if (colour < 0).any() or intensity < 0:
        raise invalid("light colour and intensity must not be negative", ctx.file, where)
    if (colour * intensity).max() > MAX_LIGHT:
        raise InputError(f"light colour {colour.tolist()} × intensity {intensity:g} is above "
                         f"{MAX_LIGHT:g}, past any real light", file=ctx.file,
                         where=f"{where}.intensity",
                         fix="check the light's intensity (candela for point and spot lights, "
                             "lux for directional ones) and export it again")
    light_range = float("inf")
    if kind != "directional" and definition.get("range") is not None:
        light_range = float(finite(ctx, [definition["range"]], 1, f"{where}.range")[0])
        if light_range <= 0:
            raise invalid(f"range must be above 0, not {light_range}", ctx.file, f"{where}.range")
    inner, outer = 0.0, np.pi / 4
    if kind == "spot":
        spot = definition.get("spot") or {}
        inner = float(finite(ctx, [or_default(spot.get("innerConeAngle"), 0.0)], 1, f"{where}.spot")[0])
        outer = float(finite(ctx, [or_default(spot.get("outerConeAngle"), np.pi / 4)], 1, f"{where}.spot")[0])
        clamped_outer = min(max(outer, 1e-6), np.pi / 2)
        clamped_inner = min(max(inner, 0.0), clamped_outer)
        if (clamped_inner, clamped_outer) != (inner, outer):
            ctx.skip(f"{where}.spot", f"cone angles ({inner:.4g}, {outer:.4g}) rad clamped to "
                                      f"({clamped_inner:.4g}, {clamped_outer:.4g})")
        inner, outer = clamped_inner, clamped_outer
    extras = definition.get("extras") if isinstance(definition.get("extras"), dict) else {}
    radius = _light_size(ctx, extras, "radius", 1.0, where)
    angular = _light_size(ctx, extras, "angular_diameter", np.pi / 180, where)
    direction = world[:3, :3] @ np.array([0.0, 0.0, -1.0])
    length = np.linalg.norm(direction)
    if kind != "point" and not length > 0:
        ctx.skip(f"nodes[{node}]", "light's node scale is zero: the light has no direction, left out")
        return None
    return Light(index=index, node=node, name=str(definition.get("name") or ""), kind=kind,
                 colour=colour, intensity=float(intensity), position=np.array(world[:3, 3], np.float64),
                 direction=direction / length if length > 0 else np.array([0.0, 0.0, -1.0]),
                 range=light_range, inner_cone=inner, outer_cone=outer, radius=radius,
                 angular_diameter=angular)


def _light_size(ctx: Context, extras: dict, key: str, scale: float, where: str) -> float | None:
    """``extras[key] × scale`` when it is a finite number ≥ 0, else None (a bad value is recorded)."""
    value = extras.get(key)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value < 0:
        ctx.skip(f"{where}.extras.{key}", f"{key} {value!r} is not a number ≥ 0: the bake's setting applies")
        return None
    return float(value) * scale
