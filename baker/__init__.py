"""baker: lightmaps for glTF 2.0 scenes, with obscurances and colour bleeding.

    import baker
    result = baker.bake("level.glb", "level_baked.glb", baker.Settings(rays=128))

The pipeline, one module per stage (DESIGN.md §3):

    load.load            glTF file → Scene (instances with float64 world matrices)
    geometry.build_world Scene → World (every triangle in world space)
    unwrap.unwrap        World → Atlas (xatlas lightmap pages)
    rasterise.cover      Atlas → Coverage (which triangle owns each texel)
    rasterise.texels_of  Coverage → Texels (world sample point of every texel of a part)
    integrate.integrate  Texels → Terms (obscurance terms, rays cast with trace.Tracer)
    direct.direct_light  Texels → Direct (lights, emitters, sky per texel, with shadow rays)
    compose.compose_into Terms + Direct → Lightmaps (L = D + I_A · W per page)
    denoise.denoise      optional (--denoise): Open Image Denoise per chart, before dilation
    postprocess          dilation into the padding
    encode.encode        Lightmaps → 8-bit PNG pages, each scaled by a percentile of its texels
    hdr.page_file        float pages as .hdr / .exr files (``--lightmaps DIR --format``)
    write.write          Scene + Atlas + pages → glTF file with MOZ_lightmap

``bake.bake`` runs them in order; from ``texels_of`` to ``compose`` a part of the texels at a
time, each part's results kept on disk for the bake state (``parts.py``, ``spill.py``), so a
large page needs little more memory than its pages.
"""

from .bake import BakeResult, bake
from .errors import BakerError, InputError, OutputError, SettingsError
from .settings import Settings

__all__ = ["bake", "BakeResult", "Settings", "BakerError", "InputError", "OutputError",
           "SettingsError"]
__version__ = "0.1.0"
