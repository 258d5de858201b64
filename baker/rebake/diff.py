"""What changed between the scene a bake state was made from and the scene baked now.

``fingerprints`` hashes everything a bake's result depends on, grouped so that a change can be
classified (docs/design.md §5); ``diff`` compares two sets and says whether an incremental rebake can
follow, and what it must redo:

- a node moved or turned rigidly (its instances' unwrap input unchanged): re-integrate the
  texels its old and new place can reach, and its own;
- a material's base colour (factor or texture) changed: re-integrate the texels whose
  obscurance rays meet its triangles;
- a light's colour or intensity changed: recompose only; its position, direction, cone, range
  or size changed: that light's shadow rays only;
- settings that only the composition or the encoding read (ambient override, encoding,
  occlusion, carrier, baked lights): recompose only;
- anything that changes the atlas (a node added or removed, a mesh edited, a node scaled, the
  texel density or page size), the rays (rays, seed, d_max, ρ, …), the tracer's float32 frame
  (the scene's bounds), lights added or removed, or a material beyond its base colour: a full
  bake, with the reason;
- a state written by another build of baker (its code, or the libraries whose arithmetic the
  terms depend on): a full bake, since its terms need not be this build's.
"""

from __future__ import annotations

import functools
from dataclasses import asdict, dataclass, field, fields
from importlib import metadata
from pathlib import Path

import numpy as np

from baker.atlas.unwrap import baked_instances, frame_positions
from baker.geometry.world import World
from baker.gltf.scene import Scene, TextureRef
from baker.jit import package_digest
from baker.rebake.state import digest
from baker.settings import CALLER_ONLY, Resolved

# Settings that only the composition, post-processing or encoding read: a recomposition.
RECOMPOSE_SETTINGS = ("ambient", "encoding", "occlusion", "carrier", "baked_lights", "smooth")
# Settings that change the atlas.
ATLAS_SETTINGS = ("texel_density", "page_size", "padding", "uv")


def instance_key(scene: Scene, i: int) -> str:
    """A name for instance ``i`` that survives edits elsewhere: node/mesh/primitive/GPU instance."""
    inst = scene.instances[i]
    prim = scene.primitives[inst.primitive]
    return f"{inst.node}/{prim.mesh}/{prim.index}/{inst.gpu_instance}"


def _image_digest(scene: Scene, ref) -> str | None:
    if ref is None:
        return None
    return digest(scene.images[ref.image].pixels, ref.texcoord, ref.wrap_s, ref.wrap_t,
                  ref.transform)


_NOT_IN_REST = ("index", "name", "base_color", "base_color_texture",  # names; the colour
                "occlusion_texture", "specular", "specular_color")  # the writer's alone
"""Material fields outside the fingerprint's rest: every other field is in it, so that a term
the bake comes to read is in it too (a change of an ior once went unseen when the rest was a
hand-made list: the rebake kept a glass's old refraction where a full bake bent its rays anew)."""


def _material(scene: Scene, m) -> dict:
    """A material's colour fingerprint (what the obscurance rays read) and the rest: every
    field but ``_NOT_IN_REST``, each texture by its pixels and how it is read."""
    colour = digest(np.asarray(m.base_color, np.float64), _image_digest(scene, m.base_color_texture))
    rest = digest(*(_image_digest(scene, value) if isinstance(value, TextureRef) else value
                    for value in (getattr(m, f.name) for f in fields(m)
                                  if f.name not in _NOT_IN_REST)))
    return {"colour": colour, "rest": rest}


def _light(light) -> dict:
    """A light's colour × intensity fingerprint and its placement/shape fingerprint."""
    return {"colour": digest(np.asarray(light.colour, np.float64), float(light.intensity)),
            "place": digest(light.kind, np.asarray(light.position, np.float64),
                            np.asarray(light.direction, np.float64), light.range, light.inner_cone,
                            light.outer_cone, light.radius, light.angular_diameter),
            "node": light.node, "index": light.index}


def _primitive(prim) -> str:
    return digest(prim.positions, prim.normals if prim.normals is not None else "no normals",
                  *prim.texcoords, prim.colors if prim.colors is not None else "no colours",
                  prim.triangles, prim.material, prim.has_morph_targets)


def _node_name(scene: Scene, node: int) -> str:
    nodes = scene.document.nodes or []
    name = nodes[node].name if 0 <= node < len(nodes) else None
    return name or f"nodes[{node}]"


# The libraries whose arithmetic the stored terms depend on (Embree's hits, numba's and numpy's
# floating point), besides baker's own code.
_LIBRARIES = ("embreex", "numba", "numpy")


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """A hash of baker's own source files and of the versions of ``_LIBRARIES``: a bake state
    keeps terms this code computed, and an incremental rebake is byte-identical to a full bake
    only if the terms it keeps are what this build would compute (an upgrade that changed the
    sampler or a library's hits would otherwise mix two builds' texels). About 2 ms, once."""
    versions = []
    for name in _LIBRARIES:
        try:
            versions.append(f"{name} {metadata.version(name)}")
        except metadata.PackageNotFoundError:
            versions.append(f"{name} (no metadata)")
    return digest(package_digest(), *versions)


def _foliage_hints(scene: Scene, node: int) -> str:
    """A digest of the node's ``extras.foliage`` and ``extras.foliage_density``, which say what
    ``--foliage approx`` makes of its triangles (``light.foliage``; without it they are not
    read): an edit of them once rebaked as "nothing changed"."""
    extras = scene.document.nodes[node].extras
    extras = extras if isinstance(extras, dict) else {}
    return digest(extras.get("foliage"), extras.get("foliage_density"))


def _authored_uv(scene: Scene, instance: int, uv: int | None) -> tuple[np.ndarray, ...]:
    """The instance's TEXCOORD_<uv> (the atlas with ``--uv``), as a one-array tuple; none
    without ``--uv`` or when the set is missing (the bake refuses that)."""
    sets = scene.primitives[scene.instances[instance].primitive].texcoords
    return () if uv is None or len(sets) <= uv else (sets[uv],)


def _as_json(value):
    """A setting's value as JSON reads it back (a tuple, such as the sky colour, as a list),
    so that the fingerprints of the scene compare with the stored ones member by member."""
    return list(value) if isinstance(value, tuple) else value


def fingerprints(scene: Scene, world: World, settings: Resolved, asked=None) -> dict:
    """Hashes of everything the bake's result depends on, JSON-able, grouped for ``diff``.

    ``asked``: the ``Settings`` the user gave (kept as "asked", not compared: ``baker rebake``
    bakes again with them)."""
    values = settings.as_dict()
    rays = {k: v for k, v in values.items()
            if k not in CALLER_ONLY + RECOMPOSE_SETTINGS + ATLAS_SETTINGS}
    if rays.get("sky_image") is not None:  # the image's bytes, wherever it is named from
        rays["sky_image"] = digest(np.frombuffer(Path(rays["sky_image"]).read_bytes(), np.uint8))
    baked = baked_instances(scene)
    unwrap_input = digest(settings.texel_density, settings.page_size, settings.padding,
                          settings.uv,
                          *[(instance_key(scene, i), digest(
                              frame_positions(scene, i).astype(np.float32),
                              world.triangles[world.instance_triangles(i)] - world.vertex_start[i],
                              *_authored_uv(scene, i, settings.uv)))
                            for i in baked])
    asked_values = None if asked is None else {
        k: _as_json(v) for k, v in asdict(asked).items() if k not in CALLER_ONLY}
    return {
        "code": code_fingerprint(),
        "asked": asked_values,
        "settings": {"rays": digest(sorted(rays.items())),
                     "atlas": digest(*[values[k] for k in ATLAS_SETTINGS]),
                     "recompose": digest(*[values[k] for k in RECOMPOSE_SETTINGS]),
                     "values": {k: _as_json(values[k]) for k in sorted(values)
                                if k not in CALLER_ONLY}},
        "unwrap": unwrap_input,
        "center": world.center.tolist() + [world.scale],
        "triangles": int(len(world.triangles)),
        "instances": [{"key": instance_key(scene, i), "world": digest(inst.world),
                       "node": int(inst.node), "name": _node_name(scene, inst.node),
                       "mesh": _primitive(scene.primitives[inst.primitive]),
                       "material": int(scene.primitives[inst.primitive].material),
                       "baked": bool(inst.baked),
                       "foliage": (_foliage_hints(scene, inst.node)
                                   if settings.foliage == "approx" else None)}
                      for i, inst in enumerate(scene.instances)],
        "materials": [_material(scene, m) for m in scene.materials],
        "lights": [_light(light) for light in scene.lights],
    }


@dataclass
class Diff:
    """The changes found, and what the rebake must do about them.

    full: why a full bake is needed, or None when an incremental rebake can follow.
    changes: one line per change found, for the user and the report.
    moved: instance indices (same in both scenes) whose node moved rigidly.
    recoloured: material indices whose base colour changed.
    lights_placed: light indices whose position, direction, cone, range or size changed.
    What changes only global terms (light colours, R_ave, I_A, encoding: no ray needed for
    them) is only said in ``changes``: the rebake recomposes every texel anyway.
    """

    full: str | None = None
    changes: list[str] = field(default_factory=list)
    moved: list[int] = field(default_factory=list)
    recoloured: list[int] = field(default_factory=list)
    lights_placed: list[int] = field(default_factory=list)


def _named(instance: dict) -> str:
    """How a report names one of ``fingerprints``' instances: its node's name and the primitive
    (and GPU instance) its key holds — "node 'crate' (nodes[12]), mesh 3, primitive 0"."""
    node, mesh, primitive, gpu = instance["key"].split("/")
    name = instance["name"]
    said = f"node {name!r}" + (f" (nodes[{node}])" if name != f"nodes[{node}]" else "")
    return said + f", mesh {mesh}, primitive {primitive}" + (
        f", GPU instance {gpu}" if gpu != "None" else "")


def _listed(instances: list[dict], most: int = 3) -> str:
    """The first ``most`` of ``instances`` named (``_named``), then how many more there are."""
    said = "; ".join(_named(x) for x in instances[:most])
    return said + (f" and {len(instances) - most} more" if len(instances) > most else "")


def _setting_changes(old: dict, new: dict) -> list[str]:
    return [f"{k} {old.get(k)!r} → {new.get(k)!r}" for k in sorted(set(old) | set(new))
            if old.get(k) != new.get(k)]


def diff(old: dict, new: dict) -> Diff:
    """Compare the fingerprints of the last bake (``old``) with the scene's now (``new``)."""
    result = Diff()

    def full(reason: str) -> Diff:
        result.full = reason
        return result

    if old.get("code") != new["code"]:
        return full("the bake state was written by another build of baker (its code or the "
                    "libraries it computes with differ)")
    so, sn = old["settings"], new["settings"]
    if so["atlas"] != sn["atlas"] or so["rays"] != sn["rays"]:
        changed = _setting_changes(so["values"], sn["values"])
        return full("settings changed (" + ", ".join(changed or ["derived values"]) + ")")
    if sn["values"].get("target_error") is not None:
        return full("adaptive sampling (target_error) ties every texel's ray count to the "
                    "scene-wide R_ave and I_A")
    oi, ni = old["instances"], new["instances"]
    old_keys, new_keys = [x["key"] for x in oi], [x["key"] for x in ni]
    if old_keys != new_keys:
        added = [x for x in ni if x["key"] not in set(old_keys)]
        removed = [x for x in oi if x["key"] not in set(new_keys)]
        what = "; ".join(f"{verb} {_listed(group)}" for verb, group in
                         (("added", added), ("removed", removed)) if group)
        return full(f"instances {what or 'reordered'}: the atlas is packed anew")
    for i, (a, b) in enumerate(zip(oi, ni)):
        if any(a[k] != b[k] for k in ("mesh", "material", "baked", "foliage")):
            return full(f"the mesh, material slot, baking or foliage hints of {_named(b)} "
                        "changed")
    if old["unwrap"] != new["unwrap"]:
        return full("the unwrap input changed (a node was scaled, or the texel density moved): "
                    "the atlas is laid out anew")
    if old["triangles"] != new["triangles"]:
        return full("the number of triangles changed")
    if old["center"] != new["center"]:
        return full("the scene's bounds changed beyond the tracer's float32 frame grid (1/16 of "
                    "the scene's size): every ray's rounding changes")
    om, nm = old["materials"], new["materials"]
    if len(om) != len(nm):
        return full("materials were added or removed")
    for m, (a, b) in enumerate(zip(om, nm)):
        if a["rest"] != b["rest"]:
            return full(f"material {m} changed beyond its base colour (emission, metalness, "
                        "alpha, sides, transmission, ior or volume)")
        if a["colour"] != b["colour"]:
            result.recoloured.append(m)
            result.changes.append(f"material {m}: base colour changed")
    ol, nl = old["lights"], new["lights"]
    if len(ol) != len(nl) or any(a["index"] != b["index"] for a, b in zip(ol, nl)):
        return full("lights were added or removed")
    for l, (a, b) in enumerate(zip(ol, nl)):
        if a["place"] != b["place"]:
            result.lights_placed.append(l)
            result.changes.append(f"light {l} (node {b['node']}): moved or reshaped → its "
                                  "shadow rays")
        elif a["colour"] != b["colour"]:
            result.changes.append(f"light {l} (node {b['node']}): colour/intensity → recompose")
    for i, (a, b) in enumerate(zip(oi, ni)):
        if a["world"] != b["world"]:
            result.moved.append(i)
            line = f"node {b['name']} moved"
            if line not in result.changes:
                result.changes.append(line)
    if so["recompose"] != sn["recompose"]:
        result.changes.append("settings: " + ", ".join(_setting_changes(so["values"], sn["values"]))
                              + " → recompose")
    return result
