"""The bake state read and compared with the scene (``compared``), and its texels remade on the
scene's world (``stored_texels``): the world, settings, lights and plan made again exactly as a
full bake makes them, the change since the state (``diff``), and a FullBake where the change or
the settings need every texel anew."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from baker.atlas.layout import Atlas
from baker.atlas.rasterise import Coverage, Texels, texels_of
from baker.atlas.validity import Validity
from baker.geometry.world import World, build_world
from baker.gltf.materials import has_normal_maps
from baker.gltf.scene import Scene
from baker.light.direct import Direct
from baker.light.hemisphere import Terms
from baker.pipeline.full import Lighting, bounds_of_baked, lighting
from baker.pipeline.parts import TexelPoints
from baker.rebake import state as state_file
from baker.rebake.asked import kept_d_max
from baker.rebake.diff import Diff, diff, fingerprints
from baker.rebake.fallback import FullBake
from baker.rebake.state_check import (
    check_fingerprints,
    check_for_scene,
    check_state,
    stored_density,
)
from baker.run.stages import timed
from baker.settings import Resolved, Settings, resolve


@dataclass(frozen=True)
class Compared:
    """The bake state read and compared with the scene (``compared``): the state, the world,
    the settings resolved as the last bake resolved them, the scene's fingerprints and the
    change since the state."""

    stored: state_file.BakeState
    world: World
    resolved: Resolved
    fingerprint: dict
    change: Diff
    lit: Lighting
    full_bake: dict | None = None  # the last full bake's times (``state.last_full_bake``)
    asked: Settings | None = None  # the settings with a kept d_max (``kept_d_max``), if any
    kept: str = ""  # the line that says so

    @property
    def moved(self) -> np.ndarray:
        """(m,) int64 the instances that moved."""
        return np.asarray(self.change.moved, np.int64)


def compared(scene: Scene, settings: Settings, path, relight: bool, times: dict[str, float]
             ) -> Compared:
    """Read the state at ``path`` and compare it with ``scene``; FullBake where the change or
    the settings need every texel anew."""
    with timed(times, "load"):
        try:
            stored = state_file.load(path, state_file.state_classes())
            check_state(stored, settings.max_depth)
            density = stored_density(stored.fingerprints)
        except state_file.StateUnusable as error:
            raise FullBake(str(error)) from None
        world = build_world(scene)
    area, diagonal = bounds_of_baked(world, scene)
    resolved = resolve(settings, area, diagonal, normal_maps=has_normal_maps(scene),
                       lights_needed=scene.lights_needed())
    kept, note = kept_d_max(stored.fingerprints, settings, resolved.d_max)
    asked = None
    if kept is not None:  # the user's from now on: the state records it as asked
        asked = settings = replace(settings, d_max=kept)
        resolved = replace(resolved, d_max=kept)
    if settings.texel_density is None and density is not None and (
            density < resolved.texel_density):
        # The full bake lowered its derived density until the charts fit a page
        # (``pipeline.full.compute``); the same scene derives the same density, so take the
        # value it ended with. Were the geometry different, the unwrap fingerprint below
        # would still call for a full bake.
        resolved = replace(resolved, texel_density=density)
    lit = lighting(scene, world, resolved, times)  # also a full bake's, if it comes to one
    fingerprint = fingerprints(scene, world, resolved, settings)

    def full_bake(reason: str) -> FullBake:
        return FullBake(reason + (f"; {note}" if note else ""), asked, (world, lit))

    try:
        check_fingerprints(stored.fingerprints, fingerprint)
        change = diff(stored.fingerprints, fingerprint)
        if change.full is None:
            check_for_scene(stored, scene, world)
    except state_file.StateUnusable as error:
        raise full_bake(str(error)) from None
    if change.full is not None:
        raise full_bake(change.full)
    if relight and (change.moved or change.recoloured or change.lights_placed):
        raise full_bake("more than light colours and intensities changed: "
                        + "; ".join(change.changes))
    if resolved.method != "obscurance":
        raise full_bake(f"method {resolved.method!r} traces paths through the whole scene "
                        "from every texel")
    if getattr(resolved, "supersample", 1) > 1:
        raise full_bake("supersampled shadow and obscurance rays start from sub-texel points "
                        "the rebake does not track yet")
    if note:
        change.changes.append(note)
    return Compared(stored, world, resolved, fingerprint, change, lit,
                    state_file.last_full_bake(path), asked, note)


@dataclass(frozen=True)
class Stored:
    """The last bake's texels as the state keeps them, checked against the scene
    (``stored_texels``): ``raw`` the texels remade from the stored coverage (sample points
    before the validity probes), ``texels`` what the state keeps of their points, and their
    validity, terms and direct light."""

    atlas: Atlas
    raw: Texels
    texels: TexelPoints
    validity: Validity
    terms: Terms
    direct: Direct


def stored_texels(scene: Scene, start: Compared, lit: Lighting, times: dict[str, float]
                  ) -> Stored:
    """The state's texels and results, remade on the scene's world; FullBake where they do not
    belong to it (other triangles, other lights) or every texel must sample anew (an emitter
    moved)."""
    world, groups = start.world, start.stored.groups
    old_texels, old_validity = groups["texels"], groups["validity"]
    old_terms, old_direct = groups["terms"], groups["direct"]
    if old_texels is None or old_validity is None or old_terms is None:
        raise FullBake("the bake state lacks the texels' terms")
    with timed(times, "rasterise"):  # the stored coverage: no rasterising again
        raw = texels_of(start.stored.atlas, world, Coverage(old_texels.key, old_texels.triangle,
                                                            old_texels.triangle_texels))
    sources = lit.sources
    if old_direct is None or len(old_direct.punctual) != len(raw) or (
            old_direct.punctual.shape[1] != len(sources.lights)):
        raise FullBake("the bake state's direct light does not match the scene's lights")
    if sources.emitters is not None and len(start.moved) and np.isin(
            world.tri_instance[sources.emitters.triangles], start.moved).any():
        raise FullBake("an emissive node moved: every texel samples the emitters anew")
    return Stored(start.stored.atlas, raw, old_texels, old_validity, old_terms, old_direct)
