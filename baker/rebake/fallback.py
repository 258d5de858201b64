"""Why a rebake gives way to a full bake (``FullBake``): raised wherever the rebake finds it
cannot follow (an unusable state, a change that needs a new atlas or new rays for every texel,
a cost above a full bake's), caught by the caller that chooses (``api.bake_or_rebake``)."""

from __future__ import annotations

from baker.geometry.world import World
from baker.pipeline.full import Lighting
from baker.settings import Settings


class FullBake(Exception):
    """An incremental rebake cannot follow; ``str(error)`` says why in one line. ``settings``:
    the settings the full bake should take instead of the ones asked (a derived value kept
    from the last bake, ``asked.kept_d_max``), None to take them as asked; ``prepared``: what the
    rebake made that the full bake would make again (``pipeline.full.compute``)."""

    def __init__(self, reason: str, settings: Settings | None = None,
                 prepared: tuple[World, Lighting] | None = None):
        super().__init__(reason)
        self.settings = settings
        self.prepared = prepared  # the scene's world and Lighting, if made: the full bake's
