"""Helpers the tests share: save an assets scene, load it, run the bake's stages on it."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from baker.atlas.rasterise import Texels, cover, texels_of
from baker.image.compose import Lightmaps, blank, compose_into
from baker.pipeline.full import Computed, compute
from baker.gltf import document as gltf_document
from baker.gltf.load import load
from baker.gltf.scene import Scene
from baker.settings import Settings

SHARED_SCENES = Path(__file__).resolve().parent / "scenes"  # third-party, with licences: scenes/README.md
REAL_SCENES = {
    "GlassVaseFlowers": SHARED_SCENES / "GlassVaseFlowers" / "GlassVaseFlowers.glb",
    "NegativeScaleTest": SHARED_SCENES / "NegativeScaleTest" / "NegativeScaleTest.glb",
    "SimpleInstancing": SHARED_SCENES / "SimpleInstancing" / "SimpleInstancing.glb",
    "MultiUVTest": SHARED_SCENES / "MultiUVTest" / "MultiUVTest.glb",
    "LightsPunctualLamp": SHARED_SCENES / "LightsPunctualLamp" / "LightsPunctualLamp.gltf",
}


def saved(builder, folder: Path, name: str = "scene.glb") -> Path:
    """Save an assets ``GltfBuilder`` into ``folder`` and return the file's path."""
    return builder.save(folder / name)


def loaded(builder, folder: Path) -> Scene:
    """The ``Scene`` the loader makes of an assets scene."""
    return load(saved(builder, folder))


def computed(builder, folder: Path, only_nodes=None, **settings) -> Computed:
    """Run the bake's stages (no writing) on an assets scene with ``Settings(**settings)``.

    ``only_nodes``: bake only the instances of these node indices (the rest still occlude).
    """
    scene = loaded(builder, folder)
    if only_nodes is not None:
        scene = replace(scene, instances=tuple(
            replace(inst, baked=inst.baked and inst.node in only_nodes, reason="not under test")
            for inst in scene.instances))
    return compute(scene, Settings(**settings))


def rasterised(atlas, world) -> Texels:
    """Every texel a baked triangle touches, with its world sample point and normals, in one
    part: the bake's own ``rasterise.cover`` and ``texels_of``."""
    return texels_of(atlas, world, cover(atlas, world))


def composed(done: Computed, direct=None, visibility: bool = True) -> Lightmaps:
    """The pages of ``done``'s texels composed as a bake composes them (``compose.blank``,
    ``compose_into``), before any post-processing: L = D + I_A·W with ``direct`` (None: no
    direct light), and the visibility's pages with ``visibility``."""
    lightmaps = blank(done.atlas, visibility)
    compose_into(lightmaps, done.texels, done.terms, done.ambient, done.settings.rho, direct)
    return lightmaps


def carried(material) -> dict | None:
    """What carries the bake on a material of a baked file (a pygltflib or baker Material, or
    its JSON dict), whichever the carrier: {"index": texture, "texCoord": n, "transform": its
    KHR_texture_transform or None}, from its MOZ_lightmap or, for a lightmap copy of the
    emissive carrier ("… (lightmap page p)"), its emissiveTexture; None for a material that
    carries none. ``page_uv`` maps the UVs it reads to the page's."""
    data = (material if isinstance(material, dict) else material.to_dict()
            if hasattr(material, "to_dict") else gltf_document.data(material))
    extension = (data.get("extensions") or {}).get("MOZ_lightmap")
    if extension is not None:
        return {"index": extension["index"], "texCoord": extension.get("texCoord", 0),
                "transform": None}
    emissive = data.get("emissiveTexture")
    if emissive is not None and "(lightmap page" in (data.get("name") or ""):
        return {"index": emissive["index"], "texCoord": emissive.get("texCoord", 0),
                "transform": (emissive.get("extensions") or {}).get("KHR_texture_transform")}
    return None


def page_uv(uv, info: dict):
    """UVs (k, 2) as the carrier ``info`` (``carried``) reads them on its page: through its
    KHR_texture_transform's scale and offset (baker writes no rotation), or as they are."""
    transform = info["transform"]
    if not transform:
        return uv
    return uv * transform.get("scale", [1.0, 1.0]) + transform.get("offset", [0.0, 0.0])
