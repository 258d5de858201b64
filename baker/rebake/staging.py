"""The bake state written beside the rest of a bake, and put in place with the bake's other files."""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import BinaryIO, Callable

import numpy as np

from baker.atlas.layout import Atlas
from baker.geometry.world import World
from baker.gltf.scene import Scene
from baker.pipeline.full import Baking
from baker.pipeline.parts import PerTexel
from baker.rebake import state as state_file
from baker.rebake.diff import fingerprints
from baker.run.atomic import Outputs, remove_temporary, stage_atomically
from baker.run.interruptible import deferred
from baker.settings import Resolved, Settings


class StateStaging:
    """The bake state (docs/bake_state.md), written on a thread of its own into a temporary file
    beside ``path`` from the moment the texels' results are final (``start``), so that it is
    written while the pages are denoised, post-processed and encoded and the output written
    (its CRCs and file writes release the GIL, as numba's kernels and zlib do); put in place
    only with the output and every other file of the bake (``stage_into``, ``run.atomic.Outputs``),
    removed if anything fails (``discard``)."""

    def __init__(self, executor: ThreadPoolExecutor, path: Path, settings: Settings):
        self._executor, self._path = executor, path
        self.asked = settings  # what the state records as asked (``api.bake_or_rebake`` may
        # give it a d_max a rebake kept when it falls back to a full bake)
        self._future: Future | None = None

    def start(self, baking: "Baking", per_texel: PerTexel, fingerprint: dict | None = None
              ) -> None:
        """Begin writing the state of ``baking``'s texels ``per_texel`` (``fingerprint``: the
        scene's, if made already)."""
        writer = bake_state_writer(baking.scene, baking.world, baking.settings, baking.atlas,
                                   per_texel, self.asked, fingerprint)
        with deferred():  # submitted and recorded, for discard to wait for: not parted
            self._future = self._executor.submit(stage_atomically, self._path, writer)

    def stage_into(self, outputs: Outputs) -> None:
        """Wait for the state to be written and add it to the files ``outputs`` puts in place."""
        outputs.adopt(self._future.result(), self._path)

    def discard(self) -> None:
        """Wait for the state being written, if any, and remove it."""
        if self._future is None:
            return
        try:
            remove_temporary(self._future.result())
        except Exception:
            pass  # it failed too; the bake's own error is the one to report


def bake_state_writer(scene: Scene, world: World, resolved: Resolved, atlas: Atlas,
                      per_texel: PerTexel, settings: Settings | None = None,
                      fingerprint: dict | None = None) -> Callable[[BinaryIO], None]:
    """What writes the bake state to an open file (``state.write_state``): the texels'
    results ``per_texel`` (``parts.PerTexel``) on ``atlas``, with the ``fingerprint`` of the
    scene baked (by default that of ``scene`` and ``world`` baked with ``resolved``, asked as
    ``settings``; a rebake has made it already). ``StateStaging`` runs it beside
    post-processing and the output's encoding, and the file is renamed into place only once
    the output is written."""
    if fingerprint is None:
        fingerprint = fingerprints(scene, world, resolved, settings)
    state = state_file.BakeState(
        fingerprints=fingerprint, atlas=atlas, groups=per_texel.state_groups(),
        instance_world=np.array([inst.world for inst in scene.instances], np.float64
                                ).reshape(-1, 4, 4))
    return lambda file: state_file.write_state(file, state)
