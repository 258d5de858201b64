"""The bake plan: which stages run for this scene, what gets texels, and what is left out, why.

Built before any ray is cast, shown to the user and written to the report, so a technical artist
can see at a glance what the bake will and will not account for.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from baker.geometry.surface import luminance
from baker.gltf.materials import normal_mapped
from baker.gltf.scene import Scene
from baker.light.ambient import Ambient
from baker.light.sources import Sources
from baker.light.environment import Environment
from baker.materials import MaterialTable


@dataclass(frozen=True)
class Plan:
    """stages: stage name → what it does here (or why it is off). baked: instances that get
    texels, as "nodes[i] (name) meshes[m].primitives[p]". left_out: (glTF path, reason) pairs."""

    stages: dict[str, str]
    baked: tuple[str, ...]
    left_out: tuple[tuple[str, str], ...]

    def lines(self) -> list[str]:
        """The plan as short lines for a terminal."""
        out = [f"  {name}: {what}" for name, what in self.stages.items()]
        out.append(f"  baked: {len(self.baked)} primitive instance(s)")
        out += [f"  left out: {count} × {reason}"
                for reason, count in self.left_out_counts().items()]
        return out

    def left_out_counts(self) -> dict[str, int]:
        """How many primitive instances were left out for each reason, by reason."""
        reasons: dict[str, int] = {}
        for _where, reason in self.left_out:
            reasons[reason] = reasons.get(reason, 0) + 1
        return dict(sorted(reasons.items()))

    def as_dict(self) -> dict:
        """The plan for the report: each place left out once, with how many of its primitive
        instances were left out there for that reason (the GPU instances of one node share
        their place: 100,000 of them made a 12 MB report, one entry each)."""
        counts: dict[tuple[str, str], int] = {}
        for pair in self.left_out:
            counts[pair] = counts.get(pair, 0) + 1
        return {"stages": self.stages, "baked": list(self.baked),
                "left_out": [{"where": w, "reason": r, "count": n}
                             for (w, r), n in counts.items()]}


def _node_label(scene: Scene, node: int) -> str:
    name = scene.document.nodes[node].name
    return f"nodes[{node}]" + (f" ({name})" if name else "")


def make_plan(scene: Scene, materials: MaterialTable, ambient: Ambient, rho: str,
              sources: Sources | None = None, surround: Environment | None = None, directional: bool = False) -> Plan:
    """What this bake does with ``scene``, whose materials are ``materials``; ``sources``: its direct light (sources.light_sources);
    ``surround``: what rays that meet nothing count, and why (environment.environment);
    ``directional``: whether directional lightmaps were asked for."""
    baked, left_out = [], [(s.where, s.reason) for s in scene.skipped]
    for inst in scene.instances:
        prim = scene.primitives[inst.primitive]
        where = f"{_node_label(scene, inst.node)} meshes[{prim.mesh}].primitives[{prim.index}]"
        if inst.baked:
            baked.append(where)
        else:
            left_out.append((where, inst.reason))
    ambient_text = {
        "emission": f"I_A = {_rgb(ambient.intensity)} from emissive surfaces (eq. 3)",
        "user": f"I_A = {_rgb(ambient.intensity)} set by the user",
        "none": "no light source in the scene: I_A = 1, the lightmap is the obscurance W itself",
        "environment": "I_A = 1 in a neutral environment: the lightmap is the obscurance W "
                       "itself plus any emission's direct light",
    }.get(ambient.source, f"I_A = {_rgb(ambient.intensity)}: the power of "
                          f"{ambient.source.replace('+', ', ')} after its first bounce "
                          "(docs/direct_light.md)")
    if ambient.source == "none" and sources is not None and sources.any():
        ambient_text = ("the scene's light sources lay no light on its surfaces (measured at "
                        "their power points, power.delivered_power): I_A = 1, as with no source")
    if ambient.source == "emission" and sources is not None:
        ambient_text = ambient_text.replace("(eq. 3)", "after their first bounce (docs/direct_light.md)")
    if ambient.source == "emission":
        ambient_text += _emitter_warning(sources, ambient)
    if ambient.truncated:
        ambient_text += (f"; R_ave = {_rgb(ambient.r_ave)} is close to 1, so 1/(1 - R_ave) "
                         "was summed as a bounded series (docs/model.md)")
    stages = {
        "obscurance": ("classic ambient occlusion (step ρ, R(Q) = 1)" if rho == "step"
                       else f"obscurance with colour bleeding, ρ = {rho}, R_ave = {_rgb(ambient.r_ave)}"),
        "ambient": ambient_text,
    }
    if surround is not None and rho not in ("step",):
        stages["escaping rays"] = f"rays that meet nothing within d_max count {surround.reason}"
    stages.update(material_stages(scene, materials))
    stages.update(_direct_stages(scene, sources))
    stages["directional"] = _directional_stage(scene, directional)
    return Plan(stages=stages, baked=tuple(baked), left_out=tuple(left_out))


EMITTER_SHARE = 0.01
"""Share of the surface area below which emissive surfaces setting I_A may be decals."""
FAINT_AMBIENT = 0.05
"""Luminance of I_A below which the ambient term those surfaces give leaves the lightmap near
black wherever their direct light does not reach (the decals of a prop: 6e-3 and less)."""


def _emitter_warning(sources: Sources | None, ambient: Ambient) -> str:
    """A warning when I_A comes from emissive surfaces covering little of the scene and is
    faint (decals): their light then sets the whole scene's ambient term near zero. A lamp
    that covers little but lights the room (the demo Cornell box's: 0.69 % of the area,
    I_A 0.25) gets none."""
    if sources is None or sources.emitters is None:
        return ""
    share = sources.emitters.area_share
    if share >= EMITTER_SHARE or float(luminance(ambient.intensity)) >= FAINT_AMBIENT:
        return ""
    return (f"; warning: set by emissive surfaces covering {share:.2%} of the surface area "
            "alone (decals?): --ambient 1 or --escape white gives the scene a neutral ambient")


def material_stages(scene: Scene, table: MaterialTable) -> dict[str, str]:
    """What the material stages do here (materials.py, integrate.py), or why they are off: a
    scene of opaque diffuse surfaces runs none of them (the diffuse kernel alone). ``table``:
    the scene's materials as the estimators see them (``World.materials``)."""
    used = sorted({scene.primitives[i.primitive].material for i in scene.instances})

    def names(stage: str) -> tuple[str, int]:
        hit = [scene.materials[m].name or f"materials[{m}]" for m in used
               if stage in table.classes[m].stages()]
        return ", ".join(hit[:4]) + (f" and {len(hit) - 4} more" if len(hit) > 4 else ""), len(hit)

    out = {}
    for stage, on, off in (
            ("specular chains", "obscurance rays follow mirror reflections ({})",
             "off: no mirror (metal smoother than mirror_roughness)"),
            ("refraction", "obscurance rays refract through glass, Fresnel by importance ({})",
             "off: no clear transmissive material"),
            ("translucency", "translucent neighbours count a share of R_ave with ρ = 1 ({})",
             "off: no translucent material"),
            ("alpha testing", "rays pass alpha-cut and blended texels ({})",
             "off: no MASK/BLEND material with alpha below opaque"),
            ("inner obscurances", "rays into closed translucent objects, γ(d) = 1 − sqrt(d/d_in) "
             "× absorption, t·R_ave·I_A added (§4, eq. 5; {})",
             "off: no closed translucent material (translucency with KHR_materials_volume "
             "thickness)"),
            ("leaves", "the back face's obscurance × translucency is added to the front's "
             "(§4; {})", "off: no thin double-sided translucent material")):
        text, count = names(stage)
        out[stage] = on.format(text) if count else off
    return out


def _direct_stages(scene: Scene, sources: Sources | None) -> dict[str, str]:
    """What the direct-light stages do: punctual lights, emissive surfaces, sky (or why not)."""
    lights = scene.lights if sources is None else sources.lights
    if not lights:
        punctual = "none: no shadow rays"
    else:
        kinds: dict[str, int] = {}
        for light in lights:
            kinds[light.kind] = kinds.get(light.kind, 0) + 1
        punctual = (f"{len(lights)} light(s) ("
                    + ", ".join(f"{n} {kind}" for kind, n in sorted(kinds.items())) + ")")
        if sources is not None:
            soft = int((sources.spread > 0).sum())
            punctual += f", shadow rays: 1 per texel per hard light ({len(lights) - soft})"
            if soft:
                punctual += f", {int(sources.samples.max())} per soft light ({soft})"
    stages = {"punctual lights": punctual}
    if sources is None:
        return stages
    emitters = sources.emitters
    stages["emissive surfaces"] = (
        "none: no emissive sampling" if emitters is None else
        f"{len(emitters.triangles)} emissive triangle(s) as area lights, sampled by power, "
        f"{sources.emissive_rays} shadow rays per texel; their own texels hold only the light "
        "they receive (the material adds the emission)")
    sky = sources.sky
    if sky is None:
        stages["sky"] = "none: no escaping rays (--sky R,G,B or --sky-image FILE adds one)"
    elif sky.is_image:
        height, width = sky.image.shape[:2]
        stages["sky"] = (f"image {sky.source} ({width}×{height}, mean radiance "
                         f"{_rgb(sky.mean_radiance())}, turned {math.degrees(sky.rotation):g}° "
                         f"about +Y), {sources.sky_rays} rays per texel, half drawn by the "
                         "image's brightness and half by the cosine (one-sample MIS); it lights "
                         "D, I_A and GI's paths alike")
    else:
        zenith, horizon = sky.gradient
        shape = "uniform" if np.array_equal(zenith, horizon) else f"gradient to {_rgb(horizon)} at the horizon"
        stages["sky"] = f"radiance {_rgb(zenith)} at the zenith, {shape}, {sources.sky_rays} rays per texel"
    return stages


def _directional_stage(scene: Scene, asked: bool) -> str:
    """What ``--directional`` does here: which normal-mapped materials get directional pages,
    or why there are none."""
    if not asked:
        return "off: one irradiance per texel (--directional adds its dominant direction for " \
               "normal-mapped materials)"
    mapped = sorted({scene.primitives[inst.primitive].material for inst in scene.instances
                     if inst.baked and normal_mapped(scene, scene.primitives[inst.primitive]
                                                     .material)})
    if not mapped:
        return "left out: directional pages, the scene has no normal map"
    names = ", ".join(scene.materials[m].name or f"materials[{scene.materials[m].index}]"
                      for m in mapped)
    return (f"per texel the irradiance and its dominant direction from every estimator, one "
            f"more page per lightmap page (BAKER_lightmap_directional) for {len(mapped)} "
            f"normal-mapped material(s): {names}")


def _rgb(v) -> str:
    return "(" + ", ".join(f"{float(x):.3g}" for x in v) + ")"
