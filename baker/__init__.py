"""baker: lightmaps for glTF 2.0 scenes, with obscurances and colour bleeding.

    import baker
    result = baker.bake("level.glb", "level_baked.glb", baker.Settings(rays=128))

or in memory, stage by stage (the same bytes, without the bake state and report):

    scene = baker.load("level.glb")
    done = baker.compute(scene, baker.Settings(rays=128))
    baker.write(done, baker.encode(done), "level_baked.glb")

The pipeline, stage by stage (docs/design.md §3); each stage hands a frozen dataclass on:

    gltf.load.load               glTF file → Scene (instances with float64 world matrices)
    geometry.world.build_world   Scene → World (every triangle in world space)
    pipeline.plan.make_plan      Scene + lights → Plan (what runs, what is left out, why)
    atlas.unwrap.unwrap          World → Atlas (lightmap pages)
    atlas.rasterise.cover        Atlas → Coverage (which triangle owns each texel)
    atlas.rasterise.texels_of    Coverage → Texels (world sample point of every texel of a part)
    atlas.validity.check_texels  Texels → Texels + Validity (points inside geometry moved/flagged)
    light.integrate.integrate    Texels → Terms (obscurance terms, rays cast with rays.trace)
    light.direct.direct_light    Texels → Direct (lights, emitters, sky per texel, shadow rays)
    light.gi.indirect_light      Texels → GI irradiance (``--method gi``, the reference)
    image.compose.compose_into   Terms + Direct → Lightmaps (L = D + I_A · W per page)
    image.denoise.denoise        optional (--denoise): Open Image Denoise per chart
    image.postprocess            invalid texels filled, seams stitched, dilation into the padding
    image.encode.encode          Lightmaps → 8-bit PNG pages, each scaled by a percentile
    image.carriers               optional (--carrier emissive): pages of outgoing radiance
    output.write.write           Scene + Atlas + pages → glTF file carrying the bake

``pipeline.full.compute`` runs them from the scene to the lightmaps, as its named ``STAGES``
(the lines a bake prints), from ``texels_of`` to ``compose`` a part of the texels at a time
(``pipeline.parts``, ``run.spill``), so a large page needs little more memory than its pages. ``rebake.incremental.rebake`` recomputes only what an
edit changed, from the bake state (``rebake.state``). ``api.bake`` chooses between the two,
writes the files and the report; ``baker.cli`` is the command line over it.
"""

from __future__ import annotations

import importlib

__all__ = ["bake", "BakeResult", "Settings", "BakerError", "InputError", "OutputError",
           "SettingsError", "load", "compute", "encode", "write"]
__version__ = "0.1.0"

_LIGHT = {"Settings": "baker.settings", "BakerError": "baker.errors",
          "InputError": "baker.errors", "OutputError": "baker.errors",
          "SettingsError": "baker.errors"}
"""Public names of modules that import no more than the standard library's small modules."""

_IN_MEMORY = {"load": ("baker.gltf.load", "load"), "compute": ("baker.pipeline.full", "compute"),
              "encode": ("baker.api", "encode_pages"), "write": ("baker.api", "write_output")}
"""The bake in memory, stage by stage: ``load`` a file into a Scene, ``compute`` its lightmaps,
``encode`` them into 8-bit pages, ``write`` the scene with them (what ``bake`` does, less its
bake state and report)."""


def __getattr__(name: str):
    """The public names and the subpackages, imported on first use: ``import baker`` runs
    nothing, so that the command line sets its Ctrl-C handler (``baker.cli``) before anything
    else of baker loads. ``Settings`` and the errors come from their small modules; ``bake``,
    ``BakeResult`` and any subpackage (after ``import baker``,
    ``baker.preview.render(baker.gltf.load.load(...))`` works) load the whole pipeline first,
    as ``import baker`` once did (numpy, numba, Embree: most of a second)."""
    if name in _LIGHT:
        return getattr(importlib.import_module(_LIGHT[name]), name)
    if name.startswith("__"):  # dunder lookups (copy, pickle, pydoc): none of ours
        raise AttributeError(f"module 'baker' has no attribute {name!r}")
    api = importlib.import_module("baker.api")  # the whole pipeline, as ``import baker`` was
    if name in ("bake", "BakeResult"):
        return getattr(api, name)
    if name in _IN_MEMORY:
        return getattr(importlib.import_module(_IN_MEMORY[name][0]), _IN_MEMORY[name][1])
    try:
        return importlib.import_module(f"baker.{name}")
    except ModuleNotFoundError:
        raise AttributeError(f"module 'baker' has no attribute {name!r}") from None
