"""Bake settings: what the user may set, their checks, and the defaults derived from the scene.

``Settings`` holds what the user asked for (None = "derive it from the scene"); ``resolve`` turns it
into ``Resolved`` with every value fixed, which is what the report prints and what the bake uses.
"""

from __future__ import annotations

import importlib.util
import math
import numbers
from dataclasses import asdict, dataclass, fields

from baker.errors import SettingsError

RHO_FUNCTIONS = ("sqrt", "step", "linear")
ENCODINGS = ("linear", "srgb")
OCCLUSION_MODES = ("none", "also")
CARRIERS = ("moz", "emissive", "occlusion")
BAKED_LIGHTS = ("remove", "keep", "indirect")
METHODS = ("obscurance", "gi")
SPECULAR_STRATEGIES = ("b", "a", "c")
ESCAPES = ("auto", "scene", "white")
"""``Settings.escape``: chosen from the scene, R_ave, or a neutral white environment."""
TECHNIQUES = ("sobol", "stratified", "random")  # how ray directions are drawn: rays.sampling
LIGHTMAP_FORMATS = ("png", "hdr", "exr")  # files of --lightmaps DIR: image.hdr
PREVIEW_MODES = ("lit", "lightmap", "checker", "unlit")  # what baker.preview shows
DEFAULT_RAYS = 64  # obscurance and sky rays per texel when not given
FIRST_ROUND_RAYS = 16  # the same with ``target_error``: its first round. With 64 the penumbra
# of benchmarks/bench_target_error.py took 4.05× the rays of the best uniform count, with 16 1.23×
STUDY_RAYS = (4, 8, 16, 32, 64, 128, 256, 512, 1024)  # rays per texel a study tries: baker.study
FOLIAGE_MODES = ("none", "approx")  # how leaves' obscurance is found: light.foliage
ANIMATED = ("bake", "occlude", "skip")
"""``Settings.animated``: what becomes of node-animated instances (``gltf.load.load``)."""
INSTALL_FIX = ('pip install "baker[denoise]" (or pip install ".[denoise]" from a checkout of '
               'baker), or leave out --denoise')


CALLER_ONLY = ("threads", "chunk_texels", "cluster", "max_total_rays", "allow_hard_links")
"""Settings that never change a bake's result, only where and how it runs and what it may take
or read: its threads, the size of its work units (memory), the cluster it runs on (where the
scene is sent), its ray budget and whether it reads files with several names. They come only
from whoever runs the bake (the command line, the API), never from a file that travels with the
scene: ``rebake.asked.asked_settings`` drops them from a bake state, which is as
untrusted as the scene it sits beside."""

MAX_LIGHT = 1e30
"""The largest emission (emissiveFactor × emissiveStrength), light colour × intensity or sky
radiance baker bakes, and the brightest lightmap page it writes (``image.encode.encode``, so
that baker reads its own outputs back): far past any real light (the sun's luminance is 1.6·10⁹
cd/m²), yet its squares and products with areas stay far from float64's range (10³⁰⁰'s do
not)."""

MAX_LENGTH = 1e30
"""The longest ``d_max`` baker takes: Embree's rays are float32 (at most 3.4·10³⁸), and a scene
is at most 10¹² units across (``gltf.read_nodes``), so a longer reach is the same bake."""

MAX_RAYS_PER_TEXEL = 1 << 16
"""The most rays of one kind a texel may be asked for (``--rays``, ``--max-rays``,
``--shadow-rays``, ``--emissive-rays``, ``--sky-rays``): 65,536, 16× the 4,096 of a converged
reference; 10¹¹ once ended in an allocation no memory holds before the ray budget was checked."""

MAX_SEED = (1 << 63) - 1
"""The largest ``--seed``: the samplers take it as a 64-bit integer."""

_WHOLE = frozenset({"page_size", "rays", "max_rays", "chunk_texels", "padding", "threads",
                    "seed", "shadow_rays", "emissive_rays", "sky_rays", "supersample",
                    "max_total_rays", "max_depth"})
"""The settings that count something (``Settings._check_types``)."""
_REAL = frozenset({"texel_density", "d_max", "d_max_fraction", "target_error", "foliage_density",
                   "ambient", "clip_percentile", "light_radius", "light_angle", "sky_rotation",
                   "sky_intensity", "mirror_roughness", "translucent"})
"""The settings that measure something (``Settings._check_types``)."""
_OPTIONAL = frozenset({"texel_density", "d_max", "target_error", "ambient", "rays", "sky_rays",
                       "foliage_density", "uv"})
"""The settings None leaves to be derived (or off)."""
_EXAMPLES = {"page_size": 1024, "rays": 64, "threads": 0, "seed": 0, "padding": 2}

MAX_TOTAL_RAYS = 10 ** 10
"""``Settings.max_total_rays`` by default: 10¹⁰ rays, about half an hour at the 5 M rays/s of
Embree on 2 cores (an 8192² page at 64 rays a texel is 4.3·10⁹); a scene of 3 KB can otherwise
ask for years (100,000 lights × 16 shadow rays on each texel)."""


@dataclass(frozen=True)
class Settings:
    """What the user asks for. Lengths in scene units (metres for glTF).

    texel_density: texels per world unit along a surface; None derives it from ``page_size``
        (about half a page of texels, lowered until the charts fit one page when they
        can: ``atlas.unwrap``).
    page_size: the largest lightmap page, in texels per side.
    uv: bake into the UV set TEXCOORD_<uv> every baked primitive already has (lightmap UVs
        the artist authored: one ``page_size``² page, checked by ``atlas.authored``) instead
        of unwrapping with xatlas; None: unwrap.
    padding: texels kept free around every chart (dilation fills them).
    rays: obscurance rays per texel (GI paths with ``method`` "gi"); None: ``ray_default``.
    sampling: how each texel's ray directions are drawn: "sobol" (Owen-scrambled Sobol, the
        default), "stratified" (jittered grid) or "random" (independent), see sampling.py.
    target_error: adaptive sampling: give each texel rays in rounds (``rays``, even, then
        doubling; the direct light's noisy sources doubled likewise, and GI paths) until its
        predicted lightmap luminance error is at most half this (so that about 95 % of texels
        are within it), or it has ``max_rays``; None: every texel gets ``rays``
        (``hemisphere.hemisphere_terms``, ``direct.adaptive_direct_light``,
        ``gi.indirect_light``, ``light/adaptive.py``).
    max_rays: the most rays of a kind (obscurance, towards one source, or GI paths) a texel
        gets with ``target_error``.
    method: "obscurance" (L = D + I_A·W, the product) or "gi": a full diffuse global
        illumination reference, L = D + path-traced indirect light with ``rays`` paths per
        texel (gi.py; slower, for judging the obscurance approximation).
    d_max: the obscurance distance; None takes ``d_max_fraction`` of the baked bounds' diagonal
    (rounded to a quarter octave, ``quarter_octave``).
    rho: the obscurance function ρ(d): "sqrt" (the paper's sqrt(d/d_max)), "step" (classic
        ambient occlusion: a hit closer than d_max counts 0, R(Q) = 1) or "linear" (d/d_max).
    ambient: the ambient intensity I_A; None computes it from the scene's emission (eq. 3).
    seed: the sampler's seed; the same seed gives the same bytes.
    threads: worker threads for ray casting (0: one per core; with ``cluster``, the CPUs each
        part takes on a worker, 0 counting as 1).
    cluster: the address ("host:port") of a running Ray cluster's head to run the bake's parts
        on, or an incremental rebake's traced texels (cluster.py, rebake/retrace.py; needs
        ``pip install "baker[cluster]"``); None: on this machine. The bytes are the same
        either way.
    chunk_texels: texels per work unit; bounds memory, never changes the result.
    carrier: how the bake reaches a viewer (docs/viewers.md): "emissive" (the diffuse light a
        lit surface sends out, as the emission of a copy of each material that keeps its
        specular response: every glTF viewer, no plugin), "moz" (MOZ_lightmap, the irradiance:
        three.js with our plugin, Hubs, ``baker view``) or "occlusion" (visibility, 1 =
        unoccluded, as the core occlusionTexture: every viewer, their own lights kept). None
        (the default): "emissive", or "moz" with ``directional`` (``chosen_carrier``).
    baked_lights: what becomes of the KHR_lights_punctual lights baked into the lightmap:
        "remove" them from the output (so viewers do not light the baked surfaces again),
        "keep" them, or "indirect": keep them and bake only the indirect light, for viewers
        that light with them (moz). None: "keep" for the occlusion carrier, and for the
        emissive carrier where a surface without a lightmap needs them
        (``Scene.lights_needed``: its copies have no diffuse response, so the lights then give
        the baked surfaces only their highlights), else "remove".
    encoding: how lightmap PNG texels map to light, named for what reads them: "linear"
        (texel/255: the three.js MOZ_lightmap plugin, Hubs, ``baker view``) or "srgb" (the
        MOZ_lightmap extension text; the emissive carrier's texture, which glTF says is sRGB);
        None: "srgb" for the emissive carrier, else "linear".
    occlusion: also write the visibility (1 = unoccluded) as the core occlusionTexture next to
        the bake ("also": with the emissive carrier, viewers then dim their environment's
        reflections where the bake found the surface occluded), or not ("none"); the occlusion
        carrier writes it alone.
    clip_percentile: each page's MOZ_lightmap intensity is this percentile (in (50, 100]) of its
        texels' brightest channel; brighter texels clip to it (encode.py). 100: the page's peak.
    shadow_rays: shadow rays per texel towards each light that has a size (radius or angular
        diameter: soft shadows); a light without size casts exactly 1.
    light_radius: sphere radius (scene units) of point and spot lights whose ``extras.radius``
        is not set; 0 makes them hard points.
    light_angle: angular diameter (degrees) of directional lights whose
        ``extras.angular_diameter`` is not set (the sun's is about 0.53); 0: hard shadows.
    emissive_rays: shadow rays per texel towards emissive surfaces (area lights).
    sky: linear RGB radiance of the sky at the zenith (+Y), None for no sky. An open upward
        surface under a uniform sky of radiance L receives irradiance π·L.
    sky_horizon: linear RGB radiance at and below the horizon, blended linearly in the sine of
        the elevation up to ``sky`` at the zenith; None: a uniform sky.
    sky_rays: rays per texel that look for the sky (escaping the scene entirely); None:
        ``ray_default``.
    sky_image: an equirectangular panorama (``.hdr`` or ``.exr``, linear radiance, +Y up,
        three.js's layout) to light the scene with instead of ``sky``, importance-sampled by
        its brightness (light/sky.py); None: none.
    sky_rotation: degrees ``sky_image`` is turned about +Y (right-handed: +Z towards +X).
    sky_intensity: factor on ``sky_image``'s radiance.
    directional: directional lightmaps for normal-mapped materials: per texel also the
        irradiance's dominant direction (from every estimator), an extra page per lightmap
        page that viewers decode with the material's normal map (light/directional.py,
        docs/directional.md); only with the moz carrier, and only when a baked material has a
        normal map (``Resolved.directional_pages``).
    mirror_roughness: metals with roughness below this are perfect mirrors (materials.py).
    specular: what an obscurance ray does at a mirror or glass (paper §3.1–3.2): "b" follows
        the reflected/refracted path and applies ρ to its summed length, stopping past d_max
        (default); "a" follows it for the colour but applies ρ to the first distance; "c"
        casts nothing more and counts R_ave with ρ = 1.
    translucent: R(Q) of a translucent neighbour as a fraction of R_ave, with ρ = 1 (§3.3):
        0 black, 1 R_ave.
    max_depth: hard cap on the mirror/glass bounces of one obscurance ray (after Russian
        roulette); the report counts the rays that reach it.
    supersample: sub-positions per texel (1–64) that its shadow, emissive, sky and obscurance
        rays start from, ray s from sub-position s mod N: anti-aliased shadow edges and
        obscurance details (supersample.py). A hard light casts N rays per texel then. 1: every
        ray from the texel's sample point.
    denoise: run Intel Open Image Denoise's lightmap filter on each chart of the composed
        pages before dilation (denoise.py; needs ``pip install "baker[denoise]"``).
    smooth: average each texel's light with the texels near it in the world — across charts
        and objects, never across a crease, a wall or a gap — as wide as Stein's estimate of
        the result's error says pays, and report that error (image/world_filter.py).
    foliage: "none" (every texel traced) or "approx": leaves and grass get their obscurance
        from a closed form fitted per crown, the rest is traced without the crowns' leaves
        and shaded by them in closed form (light/foliage.py).
    foliage_density: αρ (per cubic world unit) of every crown in ``foliage`` "approx" whose
        node's extras give none; None fits it to a few traced texels.
    allow_hard_links: read files a ``.gltf`` names that have other names too (hard links); by
        default they are refused, as a link to a file outside the scene's folder would be
        read (gltf/files.py). Like the rest of ``CALLER_ONLY``, never taken from a bake state.
    max_total_rays: the most rays one bake may cast: its texels × their rays (obscurance,
        direct light, GI paths, validity probes), checked once the texels are known and before
        any ray is cast; a bake that would need more is refused with its figures
        (``pipeline.full.check_ray_budget``). Raise it for a larger bake.
    escape: what obscurance rays that meet nothing within d_max count: "scene" (R_ave, the
        scene's mean albedo: the rest of a closed level), "white" (a neutral environment; with
        no punctual light or sky, I_A = 1), or "auto" (white for an open scene without lights,
        a prop; R_ave otherwise: light/environment.py).
    animated: what becomes of an instance whose node (or an ancestor) an animation moves:
        "bake" it in its rest pose, with a warning (its lightmap does not follow the
        animation: the default, as a still pose is what most such files show), "occlude":
        no lightmap, but it casts its rest pose's shadows and obscurance on the rest, or
        "skip": left out entirely (no lightmap, no shadow), for parts that move far.
    """

    texel_density: float | None = None
    page_size: int = 1024
    padding: int = 2
    rays: int | None = None
    sampling: str = "sobol"
    target_error: float | None = None
    max_rays: int = 1024
    method: str = "obscurance"
    d_max: float | None = None
    d_max_fraction: float = 0.2
    rho: str = "sqrt"
    ambient: float | None = None
    seed: int = 0
    threads: int = 0
    chunk_texels: int = 4096
    carrier: str | None = None
    baked_lights: str | None = None
    encoding: str | None = None
    occlusion: str = "none"
    clip_percentile: float = 99.9
    shadow_rays: int = 16
    light_radius: float = 0.0
    light_angle: float = 0.0
    emissive_rays: int = 16
    sky: tuple[float, float, float] | None = None
    sky_horizon: tuple[float, float, float] | None = None
    sky_rays: int | None = None
    sky_image: str | None = None
    sky_rotation: float = 0.0
    sky_intensity: float = 1.0
    directional: bool = False
    mirror_roughness: float = 0.1
    specular: str = "b"
    translucent: float = 0.5
    max_depth: int = 16
    supersample: int = 1
    denoise: bool = False
    smooth: bool = False
    foliage: str = "none"
    foliage_density: float | None = None
    cluster: str | None = None
    escape: str = "auto"
    animated: str = "bake"
    uv: int | None = None
    max_total_rays: int = MAX_TOTAL_RAYS
    allow_hard_links: bool = False

    def ray_default(self) -> int:
        """The rays a texel gets of a kind whose count is not given (``rays``, ``sky_rays``):
        ``DEFAULT_RAYS``, or ``FIRST_ROUND_RAYS`` with ``target_error``, where the count is the
        first round, the least a texel gets: the quiet texels stop there."""
        return DEFAULT_RAYS if self.target_error is None else FIRST_ROUND_RAYS

    def ray_count(self, given: int | None) -> int:
        """A ray count as given, or ``ray_default`` when it is None."""
        return self.ray_default() if given is None else given

    def check(self) -> None:
        """Raise SettingsError for a value that cannot work, saying which values can."""
        self._check_types()
        positive = {
            "texel_density": self.texel_density,
            "d_max": self.d_max,
            "d_max_fraction": self.d_max_fraction,
            "target_error": self.target_error,
            "foliage_density": self.foliage_density,
            "ambient": self.ambient if self.ambient is None else self.ambient + 1.0,
        }
        for name, value in positive.items():
            if value is not None and not (math.isfinite(value) and value > 0):
                raise SettingsError(f"{name} must be a finite number above 0, not {value}",
                                    fix=f"give --{name.replace('_', '-')} a positive value")
        for name, value, top in (("d_max", self.d_max, MAX_LENGTH),
                                 ("ambient", self.ambient, MAX_LIGHT)):
            if value is not None and value > top:
                raise SettingsError(f"{name} must be at most {top:g}, not {value:g}",
                                    fix=f"give --{name.replace('_', '-')} a value up to {top:g}")
        if self.ambient is not None and self.ambient < 0:
            raise SettingsError(f"ambient must be 0 or more, not {self.ambient}",
                                fix="give --ambient a value of 0 or more")
        rays, sky_rays = self.ray_count(self.rays), self.ray_count(self.sky_rays)
        most = MAX_RAYS_PER_TEXEL
        integers = {"page_size": (self.page_size, 16, None), "rays": (rays, 1, most),
                    "max_rays": (self.max_rays, 1, most),
                    "chunk_texels": (self.chunk_texels, 1, None),
                    "padding": (self.padding, 0, None), "threads": (self.threads, 0, None),
                    "seed": (self.seed, 0, MAX_SEED),
                    "shadow_rays": (self.shadow_rays, 1, most),
                    "emissive_rays": (self.emissive_rays, 1, most),
                    "sky_rays": (sky_rays, 1, most), "supersample": (self.supersample, 1, None),
                    "max_total_rays": (self.max_total_rays, 1, None)}
        for name, (value, low, high) in integers.items():
            option = f"--{name.replace('_', '-')}"
            if value < low:  # a whole number already (``_check_types``)
                raise SettingsError(f"{name} must be a whole number of at least {low}, not {value}",
                                    fix=f"give {option} a whole number ≥ {low}")
            if high is not None and value > high:
                raise SettingsError(f"{name} must be at most {high:,}, not {value:,}",
                                    fix=f"give {option} a whole number up to {high:,}")
        if self.page_size - 2 * self.padding - 2 < 1:  # ``unwrap``'s room for a chart
            raise SettingsError(f"padding {self.padding} leaves no room for a chart on a page of "
                                f"{self.page_size} texels (2 × padding + 3 at least)",
                                fix=f"give --padding {(self.page_size - 3) // 2} or less, or a "
                                    "larger --page-size")
        if self.target_error is not None and rays % 2:
            raise SettingsError(f"--target-error needs an even number of rays, not {rays}: "
                                f"its rounds grow each texel's two nets of rays/2 points",
                                fix=f"use --rays {rays + 1}")
        self._check_uv()
        self._check_lights()
        self._check_materials()
        if self.denoise and self.smooth:
            raise SettingsError("--smooth and --denoise are two ways to remove the same noise; "
                                "the second would see the first's output, and the error "
                                "estimate neither", fix="give one of --smooth and --denoise")
        if self.denoise:  # pyoidn is optional: say how to install it before any work
            require_oidn()
        if not (isinstance(self.clip_percentile, (int, float)) and 50 < self.clip_percentile <= 100):
            raise SettingsError(f"clip_percentile must be above 50 and at most 100, not "
                                f"{self.clip_percentile}", fix="use --clip-percentile 99.9 (or 100: "
                                                               "scale each page to its peak)")
        if self.supersample > 64:
            raise SettingsError(f"supersample must be at most 64, not {self.supersample}",
                                fix="use --supersample 4 to 16 (shadow edges gain little beyond)")
        if self.page_size > 16384:
            raise SettingsError(f"page_size {self.page_size} is larger than 16384 texels",
                                fix="use --page-size 16384 or less; large scenes get several pages")
        self._check_output()
        for name, value, allowed in (("rho", self.rho, RHO_FUNCTIONS),
                                     ("sampling", self.sampling, TECHNIQUES),
                                     ("method", self.method, METHODS),
                                     ("foliage", self.foliage, FOLIAGE_MODES),
                                     ("animated", self.animated, ANIMATED)):
            if value not in allowed:
                raise SettingsError(f"{name} must be one of {', '.join(allowed)}, not {value!r}",
                                    fix=f"use --{name} {allowed[0]}")
        if self.cluster is not None and self.foliage != "none":
            raise SettingsError("--foliage approx does not run on a cluster: the workers would "
                                "need its Embree scene without the crowns' leaves, which is "
                                "not shipped to them", fix="bake without --cluster or without "
                                                           "--foliage")

    def chosen_carrier(self) -> str:
        """``carrier``, or when it is not given the default: "moz" for directional lightmaps
        (their pages ride beside the MOZ_lightmap), else "emissive"."""
        return self.carrier or ("moz" if self.directional else "emissive")

    def _check_output(self) -> None:
        """Carrier, baked lights, encoding and occlusion: known values that fit together."""
        if self.occlusion == "only":
            raise SettingsError("occlusion 'only' is now the occlusion carrier",
                                fix="use --carrier occlusion")
        carrier = self.chosen_carrier()
        for name, value, allowed in (("carrier", carrier, CARRIERS),
                                     ("baked_lights", self.baked_lights, BAKED_LIGHTS),
                                     ("encoding", self.encoding, ENCODINGS),
                                     ("occlusion", self.occlusion, OCCLUSION_MODES)):
            if value not in allowed and not (value is None and name in ("baked_lights",
                                                                          "encoding")):
                raise SettingsError(f"{name} must be one of {', '.join(allowed)}, not {value!r}",
                                    fix=f"use --{name.replace('_', '-')} {allowed[0]}")
        if carrier == "emissive" and self.encoding == "linear":
            raise SettingsError("the emissive carrier's texture is an emissiveTexture, which glTF "
                                "defines as sRGB: it cannot be linear",
                                fix="leave out --encoding (srgb), or use --carrier moz")
        if carrier == "occlusion" and self.occlusion == "also":
            raise SettingsError("occlusion 'also' adds the visibility as an occlusionTexture "
                                "beside the bake; the occlusion carrier is that texture alone",
                                fix="leave out --occlusion")
        if carrier == "emissive" and self.baked_lights == "indirect":
            raise SettingsError("the emissive carrier's copies have no diffuse response: the "
                                "lights' direct light must be in the bake, or nothing shows it",
                                fix="leave out --baked-lights (keep), or use --carrier moz")
        if self.directional and self.carrier not in (None, "moz"):
            raise SettingsError(f"directional pages ride beside the MOZ_lightmap (the "
                                f"BAKER_lightmap_directional extension); the {self.carrier} "
                                f"carrier has none", fix="leave out --carrier (moz with "
                                                         "--directional), or --directional")
        if carrier == "occlusion" and self.baked_lights == "indirect":
            raise SettingsError("the occlusion carrier holds no light, so it has no indirect "
                                "light to bake", fix="leave out --baked-lights (keep)")


    def _check_uv(self) -> None:
        """An authored UV set: a set index, and no texel density (the set fixes the layout)."""
        if self.uv is None:
            return
        if isinstance(self.uv, bool) or int(self.uv) != self.uv or self.uv < 0:
            raise SettingsError(f"uv must be a UV set index (0, 1, 2, …), not {self.uv!r}",
                                fix="give --uv the N of the TEXCOORD_N to bake into, e.g. 1")
        if self.texel_density is not None:
            raise SettingsError("--texel-density has no effect with --uv: the authored UVs "
                                "fix where every texel lies",
                                fix="leave out --texel-density (--page-size sets the "
                                    "resolution), or leave out --uv")

    def _check_types(self) -> None:
        """Every number a number: a whole one (an int, numpy's too, not a bool or a float such
        as 64.0) where a count is asked, a real one where a quantity is; None only where it
        means "derive it" (``_OPTIONAL``). A string or a float count from a pipeline's code once
        ended in a TypeError deep in the bake."""
        for f in fields(Settings):
            value = getattr(self, f.name)
            if value is None and f.name in _OPTIONAL:
                continue
            if f.name in _WHOLE and not (isinstance(value, numbers.Integral)
                                         and not isinstance(value, bool)):
                raise SettingsError(f"{f.name} must be a whole number (an int), not {value!r}",
                                    fix=f"give {f.name} as an int, e.g. "
                                        f"{_EXAMPLES.get(f.name, 1)}")
            if f.name in _REAL and not (isinstance(value, numbers.Real)
                                        and not isinstance(value, bool)):
                raise SettingsError(f"{f.name} must be a number, not {value!r}",
                                    fix=f"give {f.name} as a number (int or float)")

    def _check_materials(self) -> None:
        """Material settings (materials.py, integrate.py) within their ranges."""
        for name, value in (("mirror_roughness", self.mirror_roughness),
                            ("translucent", self.translucent)):
            if not (isinstance(value, (int, float)) and 0 <= value <= 1):
                raise SettingsError(f"{name} must be a number from 0 to 1, not {value!r}",
                                    fix=f"give --{name.replace('_', '-')} a value such as 0.1")
        if self.specular not in SPECULAR_STRATEGIES:
            raise SettingsError(f"specular must be one of {', '.join(SPECULAR_STRATEGIES)}, not "
                                f"{self.specular!r}", fix="use --specular b")
        if self.escape not in ESCAPES:
            raise SettingsError(f"escape must be one of {', '.join(ESCAPES)}, not "
                                f"{self.escape!r}", fix="use --escape auto")
        if int(self.max_depth) != self.max_depth or self.max_depth < 1:
            raise SettingsError(f"max_depth must be a whole number of at least 1, not "
                                f"{self.max_depth}", fix="use --max-depth 16")

    def _check_lights(self) -> None:
        """Light sizes finite and ≥ 0 (angle below 180°); sky colours three finite numbers ≥ 0."""
        for name, value, top in (("light_radius", self.light_radius, math.inf),
                                 ("light_angle", self.light_angle, 180.0)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and 0 <= value < top):
                below = "" if top == math.inf else f" and below {top:g}"
                raise SettingsError(f"{name} must be a finite number ≥ 0{below}, not {value}",
                                    fix=f"give --{name.replace('_', '-')} a value such as 0")
        for name, value in (("sky", self.sky), ("sky_horizon", self.sky_horizon)):
            if value is None:
                continue
            try:
                ok = len(value) == 3 and all(0 <= float(v) <= MAX_LIGHT for v in value)
            except (TypeError, ValueError):
                ok = False
            if not ok:
                raise SettingsError(f"{name} must be three numbers from 0 to {MAX_LIGHT:g} "
                                    f"(linear RGB), not {value!r}",
                                    fix=f"give --{name.replace('_', '-')} R,G,B, e.g. 0.5,0.6,0.8")
        if self.sky_horizon is not None and self.sky is None:
            raise SettingsError("sky_horizon needs sky (the zenith colour) too",
                                fix="add --sky R,G,B, or leave out --sky-horizon")
        self._check_sky_image()

    def _check_sky_image(self) -> None:
        """A sky image alone (no colour sky beside it), its rotation finite and its intensity
        finite and ≥ 0 (both at most ``MAX_LIGHT`` in size)."""
        for name, value, least in (("sky_rotation", self.sky_rotation, -math.inf),
                                   ("sky_intensity", self.sky_intensity, 0.0)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= least
                    and abs(value) <= MAX_LIGHT):
                low = "" if least == -math.inf else " ≥ 0"
                raise SettingsError(f"{name} must be a finite number{low} up to {MAX_LIGHT:g}, "
                                    f"not {value!r}",
                                    fix=f"give --{name.replace('_', '-')} a value such as "
                                        f"{'90' if name == 'sky_rotation' else '1'}")
        if self.sky_image is not None and self.sky is not None:
            raise SettingsError("a sky image and a sky colour were both given: the image is "
                                "the sky", fix="leave out --sky (and --sky-horizon), or "
                                               "--sky-image")


@dataclass(frozen=True)
class Resolved(Settings):
    """Settings with every derived value filled in (no None left but ``ambient``).

    directional_pages: ``directional`` was asked and a baked material has a normal map: the
    estimators keep the light's directions and the output gets directional pages."""

    texel_density: float = 0.0
    d_max: float = 0.0
    directional_pages: bool = False

    def as_dict(self) -> dict:
        """The settings as plain JSON-able values, for the report."""
        return asdict(self)


MAX_TEXELS = 1 << 26
"""Most lightmap texels (surface area × texel density²) one bake may ask for: 67 M, a full 8192²
page, which already takes several GiB of memory on the way (texels, rays, float page images)."""


def _round_down(value: float, digits: int = 3) -> float:
    """``value`` cut (never rounded up) to ``digits`` significant digits, for a limit to quote."""
    step = 10.0 ** (math.floor(math.log10(value)) - digits + 1)
    return math.floor(value / step) * step


def default_texel_density(surface_area: float, page_size: int, fill: float = 0.5) -> float:
    """Texels per world unit that fill about ``fill`` of one page of ``page_size``² texels.

    ``surface_area`` is the world-space area of every baked triangle; xatlas packs charts to
    roughly 50–70 % of a page once padding is counted, hence the default fill.
    """
    if surface_area <= 0:
        return 1.0
    return math.sqrt(fill * page_size * page_size / surface_area)


def quarter_octave(length: float) -> float:
    """``length`` rounded to the nearest 2^(k/4): derived settings (d_max) that a small move of
    a node leaves bit-identical, so that an incremental rebake can follow (steps of 19 %)."""
    return 2.0 ** (round(4.0 * math.log2(length)) / 4.0)


def resolve(settings: Settings, surface_area: float, diagonal: float,
            normal_maps: bool = False, lights_needed: bool = False) -> Resolved:
    """Fill in the defaults that depend on the scene.

    ``surface_area``: world area of the baked surfaces; ``diagonal``: length of the diagonal of
    their world bounds. Both in scene units. ``normal_maps``: some baked material has a normal
    map (what ``directional`` pages are for). ``lights_needed``: the punctual lights light a
    surface that gets no lightmap (``Scene.lights_needed``), so a carrier that could drop them
    keeps them.
    """
    settings.check()
    values = {f.name: getattr(settings, f.name) for f in fields(Settings)}
    most = math.sqrt(MAX_TEXELS / surface_area) if surface_area > 0 else math.inf
    if values["texel_density"] is None:
        values["texel_density"] = min(default_texel_density(surface_area, settings.page_size), most)
    elif values["texel_density"] > most:
        texels = surface_area * values["texel_density"] * values["texel_density"]  # may be inf
        raise SettingsError(
            f"texel density {values['texel_density']:g} needs about {texels:.3g} lightmap texels "
            f"for {surface_area:.4g} square units of surface; one bake holds at most "
            f"{MAX_TEXELS:,} texels", fix=f"use --texel-density {_round_down(most):g} or less")
    values["texel_density"] = float(values["texel_density"])  # one type, one fingerprint
    if values["d_max"] is None:
        values["d_max"] = settings.d_max_fraction * quarter_octave(diagonal) if diagonal > 0 else 1.0
    values["rays"], values["sky_rays"] = (settings.ray_count(settings.rays),
                                          settings.ray_count(settings.sky_rays))
    values["directional_pages"] = bool(settings.directional and normal_maps)
    if values["sky_image"] is not None:  # a path given as a Path: one type, one fingerprint
        values["sky_image"] = str(values["sky_image"])
    carrier = values["carrier"] = settings.chosen_carrier()
    if values["baked_lights"] is None:
        kept = carrier == "occlusion" or (carrier == "emissive" and lights_needed)
        values["baked_lights"] = "keep" if kept else "remove"
    if values["encoding"] is None:
        values["encoding"] = "srgb" if carrier == "emissive" else "linear"
    return Resolved(**values)


def require_oidn() -> None:
    """Raise SettingsError naming the fix when pyoidn is missing or has no CPU device."""
    if importlib.util.find_spec("pyoidn") is None:
        raise SettingsError("denoising needs Intel Open Image Denoise's Python binding pyoidn, "
                            "which is not installed", fix=INSTALL_FIX)
    import pyoidn

    if not pyoidn.Device.is_cpu_available():
        raise SettingsError("pyoidn is installed but Open Image Denoise has no CPU device on this "
                            "machine (it needs a 64-bit x86 CPU with SSE4.1, or Apple silicon)",
                            fix="bake without --denoise")
