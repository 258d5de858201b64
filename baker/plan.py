"""The bake plan: which stages run for this scene, what gets texels, and what is left out, why.

Built before any ray is cast, shown to the user and written to the report, so a technical artist
can see at a glance what the bake will and will not account for.
"""

from __future__ import annotations

from dataclasses import dataclass

from .ambient import Ambient
from .scene import Scene


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
        reasons: dict[str, int] = {}
        for _where, reason in self.left_out:
            reasons[reason] = reasons.get(reason, 0) + 1
        out += [f"  left out: {count} × {reason}" for reason, count in sorted(reasons.items())]
        return out

    def as_dict(self) -> dict:
        return {"stages": self.stages, "baked": list(self.baked),
                "left_out": [{"where": w, "reason": r} for w, r in self.left_out]}


def _node_label(scene: Scene, node: int) -> str:
    name = scene.document.nodes[node].name
    return f"nodes[{node}]" + (f" ({name})" if name else "")


def make_plan(scene: Scene, ambient: Ambient, rho: str) -> Plan:
    """What this bake does with ``scene``."""
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
    }[ambient.source]
    if ambient.truncated:
        ambient_text += (f"; R_ave = {_rgb(ambient.r_ave)} is close to 1, so 1/(1 - R_ave) "
                         "was summed as a bounded series (docs/model.md)")
    stages = {
        "obscurance": ("classic ambient occlusion (step ρ, R(Q) = 1)" if rho == "step"
                       else f"obscurance with colour bleeding, ρ = {rho}, R_ave = {_rgb(ambient.r_ave)}"),
        "ambient": ambient_text,
    }
    lights = (scene.document.extensions or {}).get("KHR_lights_punctual", {}).get("lights", [])
    if lights:
        stages["punctual lights"] = (f"{len(lights)} KHR_lights_punctual light(s) not baked yet: "
                                     "direct light is not computed in this version")
    return Plan(stages=stages, baked=tuple(baked), left_out=tuple(left_out))


def _rgb(v) -> str:
    return "(" + ", ".join(f"{float(x):.3g}" for x in v) + ")"
