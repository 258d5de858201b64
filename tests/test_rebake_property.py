"""Rebake = full bake, as a property over generated rooms and edits.

Each case draws a room (``assets.random_rooms``: props of every material kind, punctual lights,
maybe sky, open or closed) and an edit of it (a prop moved, turned, scaled or recoloured, a
light changed, or several at once), bakes the room, rebakes the edited room from that bake's
state and bakes the edited room from scratch: the two outputs and the two bake states must be
the same bytes. ``CASES`` rooms (3 edits each) run in the normal suite, about 55 s on the shared
2 cores; ``BAKER_LONG=1`` runs ``LONG_CASES``. A case that fails is added to ``REGRESSIONS``
(room seed, edit seed) once fixed, and runs in both modes. Rooms 0–59 (180 edits) and 30 rooms
of ``rebake_scenes.grid_boxes`` with one box moved (16 or 64 rays, default d_max) found none.
The same check runs with ``--foliage approx`` on the first ``FOLIAGE_CASES`` rooms that have an
alpha-cut panel (a crown of one leaf: fitted, shading the room in closed form), or
``LONG_FOLIAGE_CASES`` with ``BAKER_LONG=1``.
"""

from __future__ import annotations

import os
import shutil

import pytest

import baker
from assets.random_rooms import build, random_edit, random_room
from baker.rebake.state import default_path

CASES, LONG_CASES, EDITS_PER_ROOM = 8, 200, 3
FOLIAGE_CASES, LONG_FOLIAGE_CASES = 2, 30
REGRESSIONS: list[tuple[int, int]] = []


def _settings(spec, foliage: str = "none") -> baker.Settings:
    return baker.Settings(rays=spec["rays"], page_size=256, shadow_rays=4, threads=1,
                          texel_density=spec["density"], supersample=spec["supersample"],
                          sky=(0.2, 0.25, 0.3) if spec["sky"] else None, foliage=foliage)


def _cases() -> list[tuple[int, list[int]]]:
    """(room seed, edit seeds): the generated rooms, then each regression on its own."""
    rooms = range(LONG_CASES if os.environ.get("BAKER_LONG") else CASES)
    return ([(room, [1000 * room + e for e in range(EDITS_PER_ROOM)]) for room in rooms]
            + [(room, [edit]) for room, edit in REGRESSIONS])


def _foliage_cases() -> list[tuple[int, list[int]]]:
    """(room seed, edit seeds) of the first rooms with an alpha-cut panel (a crown)."""
    wanted = LONG_FOLIAGE_CASES if os.environ.get("BAKER_LONG") else FOLIAGE_CASES
    rooms = (room for room in range(10 * wanted)
             if any(p["kind"] == "alpha" for p in random_room(room)["props"]))
    return [(room, [1000 * room + e for e in range(EDITS_PER_ROOM)])
            for room, _ in zip(rooms, range(wanted))]


def check_case(folder, room_seed: int, edit_seeds, foliage: str = "none") -> list[str]:
    """Bake room ``room_seed``, then for each edit seed rebake and fully bake the edited room
    (``foliage``: the --foliage mode); return a line per edit whose bytes differ."""
    spec = random_room(room_seed)
    build(spec).save(folder / "room.glb")
    baker.bake(folder / "room.glb", folder / "base.glb", _settings(spec, foliage))
    failures = []
    for edit_seed in edit_seeds:
        what, edited = random_edit(spec, edit_seed)
        scene = build(edited).save(folder / "edited.glb")
        shutil.copy(default_path(folder / "base.glb"), default_path(folder / "incremental.glb"))
        result = baker.bake(scene, folder / "incremental.glb", _settings(edited, foliage),
                            incremental=True)
        baker.bake(scene, folder / "full.glb", _settings(edited, foliage))
        same_output = (folder / "incremental.glb").read_bytes() == (folder / "full.glb").read_bytes()
        same_state = (default_path(folder / "incremental.glb").read_bytes()
                      == default_path(folder / "full.glb").read_bytes())
        if "foliage" in str(result.rebake.get("full_bake_reason", "")):
            failures.append(f"room {room_seed}, edit {edit_seed} ({what}): a full bake for "
                            f"foliage: {result.rebake['full_bake_reason']}")
        if not (same_output and same_state):
            failures.append(f"room {room_seed}, edit {edit_seed} ({what}, incremental "
                            f"{result.rebake['incremental']}): output same {same_output}, "
                            f"state same {same_state}")
    return failures


@pytest.mark.parametrize("room_seed, edit_seeds", _cases())
def test_rebake_equals_a_full_bake_on_generated_rooms(tmp_path, room_seed, edit_seeds):
    assert check_case(tmp_path, room_seed, edit_seeds) == []


@pytest.mark.parametrize("room_seed, edit_seeds", _foliage_cases())
def test_foliage_rebake_equals_a_full_bake_on_generated_rooms(tmp_path, room_seed, edit_seeds):
    assert check_case(tmp_path, room_seed, edit_seeds, "approx") == []
