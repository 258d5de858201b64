"""What every estimator needs of a bake, made once and handed on whole (``Context``).

The estimators (``light/``) trace rays through the world, shade what the rays meet and light it
from the scene's sources; they read all of that from one frozen ``Context`` rather than from the
glTF scene, whose format they never see. The pipeline makes it once, in its stage "lights and
plan" (``pipeline.full.lighting``), and the rebake in its own (``rebake.compared``), with
``context_of``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from baker.geometry.world import World
from baker.materials import MaterialTable
from baker.punctual import Light
from baker.rays.trace import Tracer
from baker.settings import Resolved

if TYPE_CHECKING:  # the loaded scene, only ever handed on to the surface lookups
    from baker.gltf.scene import Scene


@dataclass(frozen=True)
class Node:
    """A node of the scene as the estimators may ask after it: its name ("" without one) and
    its custom properties (a glTF node's ``extras``, {} without them: foliage hints)."""

    name: str
    extras: dict


@dataclass(frozen=True)
class Context:
    """What every estimator needs of a bake.

    world: every triangle in world space (``geometry.world``), with its materials as the
    estimators see them (``materials``). tracer: Embree's scene of the world (None while the
    context travels to another process: ``without_tracer``). lights: the punctual lights, in
    the scene's order. settings: the bake's, resolved for the scene. surfaces: the loaded scene,
    read only by the surface lookups (``geometry.surface``: textures, images) and the validity
    probes. instance_scale: (I,) float64 each instance's linear scale, |det|^(1/3) of its world
    matrix (mesh → world units). instance_node: (I,) int64 the node of each instance. nodes:
    every node's ``Node``. source: the scene's file, for messages.
    """

    world: World
    tracer: Tracer | None
    lights: tuple[Light, ...]
    settings: Resolved
    surfaces: Scene
    instance_scale: np.ndarray
    instance_node: np.ndarray
    nodes: tuple[Node, ...]
    source: str

    @property
    def materials(self) -> MaterialTable:
        """Every material as the estimators see them (``World.materials``)."""
        return self.world.materials

    def with_settings(self, settings: Resolved) -> Context:
        """This context with other settings (an estimator's own rays, a fit's)."""
        return replace(self, settings=settings)

    def with_tracer(self, tracer: Tracer | None) -> Context:
        """This context tracing with ``tracer`` (a recording one, the foliage's, one made
        anew in another process; None before the context is sent to one)."""
        return replace(self, tracer=tracer)


def context_of(scene: Scene, world: World, tracer: Tracer, settings: Resolved) -> Context:
    """The ``Context`` of the loaded ``scene`` with its ``world`` and ``tracer``, baked with
    ``settings``."""
    nodes = scene.document.nodes or []
    return Context(
        world=world, tracer=tracer, lights=tuple(scene.lights), settings=settings,
        surfaces=scene,
        instance_scale=np.array([abs(np.linalg.det(i.world[:3, :3])) ** (1.0 / 3.0)
                                 for i in scene.instances], np.float64),
        instance_node=np.array([i.node for i in scene.instances], np.int64),
        nodes=tuple(Node(node.name or "", node.extras if isinstance(node.extras, dict) else {})
                    for node in nodes),
        source=str(scene.path))
