"""The whole bake, stage by stage (DESIGN.md §3):

    load → plan → unwrap → rasterise → trace/integrate → compose → post-process → write

Each stage is one module with one entry function; this module only runs them in order, times
them, and gathers the report.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import closing, contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import BinaryIO, Callable, Iterator

import numpy as np

from .ambient import Ambient, ambient_terms
from .atlas import Atlas
from .compose import Lightmaps, blank, compose_into, effective_r_ave
from .direct import Direct, Power, Sources, delivered_power, direct_light, light_sources
from .encode import encode
from .errormap import write_error_maps
from .denoise import DenoiseInfo, denoise
from .hdr import check_format, page_file
from .errors import BakerError, OutputError
from .geometry import World, build_world
from .gi import indirect_light
from .input_warnings import input_warnings
from .integrate import Surfaces, Terms, integrate, surfaces_of
from .load import load
from .plan import Plan, make_plan
from .postprocess import postprocess
from .progress import bar, wanted
from .parts import PerTexel, Tally, TexelPoints, part_slices
from .rasterise import Coverage, Owners, Texels, cover, owners, texels_of
from .spill import Spill, remove_later, set_aside
from .validity import Faces, Validity, check_texels
from .seams import find_seams
from .scene import Scene
from .scene_files import inside
from .settings import Resolved, Settings, resolve
from .surface import LUMINANCE
from .trace import Tracer
from .unwrap import PageTooSmall, baked_instances, frame_area, unwrap
from .write import WriteOptions, image_file_name, write
from .incremental import bake_or_rebake, bake_state_writer, details, record_full_bake, summary
from .state import default_path as default_state_path


@dataclass(frozen=True)
class BakeResult:
    """What a bake did. ``report`` is the JSON-able dict that ``--report`` writes."""

    output: Path
    settings: Resolved
    plan: Plan
    texels: int
    rays: int
    pages: int
    seconds: float
    rmse_estimate: float
    report: dict = field(repr=False)
    rebake: dict | None = field(default=None, repr=False)  # incremental.summary: what changed


@contextmanager
def _timed(times: dict[str, float], name: str) -> Iterator[None]:
    """Add the wall time of the block to ``times[name]``, in seconds."""
    start = time.perf_counter()
    yield
    times[name] = times.get(name, 0.0) + time.perf_counter() - start


def _bounds_of_baked(world, scene) -> tuple[float, float]:
    """Area and world bounds diagonal of the baked instances (for default settings).

    The area is summed in each instance's rigid-free frame (``unwrap.frame_area``), so a rigid
    move of a node leaves the derived texel density bit-identical (incremental rebake)."""
    tris = np.concatenate([world.instance_triangles(i) for i in baked_instances(scene)] or
                          [np.zeros(0, np.int64)])
    if len(tris) == 0:
        return 0.0, 0.0
    points = world.positions[world.triangles[tris].reshape(-1)]
    return frame_area(scene, world), float(np.linalg.norm(points.max(0) - points.min(0)))


def check_output(input_path: Path, output: Path, overwrite: bool = False,
                 report_path: Path | None = None) -> None:
    """Refuse, before any work, an output that cannot be written or would replace the input.

    The output ends in .glb or .gltf; its folder (and the report's) exists and can be written
    to; it is the input itself only with ``overwrite`` (the input is then replaced atomically).
    """
    if output.suffix.lower() not in (".glb", ".gltf"):
        raise OutputError(f"the output must end in .glb or .gltf, not {output.suffix or '(none)'}",
                          file=str(output), fix="name the output e.g. scene_baked.glb")
    if not overwrite and output.exists() and input_path.exists() and os.path.samefile(input_path, output):
        raise OutputError("the output is the input file: baker replaces its input only when asked",
                          file=str(output), fix="give another output path with -o, or add --overwrite "
                                                "to replace the input with its bake")
    if output.is_dir():
        raise OutputError("the output path is a folder", file=str(output),
                          fix="give a file name ending in .glb or .gltf")
    for path in (output, report_path):
        if path is not None and not path.parent.is_dir():
            raise OutputError(f"the folder {path.parent} does not exist", file=str(path),
                              fix=f"create {path.parent} first, or choose another path")
        if path is not None:
            _check_writable(path)


def _check_writable(path: Path) -> None:
    """Create and remove a file in ``path``'s folder: the one true test that it can be written."""
    try:
        handle, probe = tempfile.mkstemp(dir=path.parent, prefix=".baker-probe-", suffix=".tmp")
    except PermissionError:
        raise OutputError(f"no permission to write in the folder {path.parent}", file=str(path),
                          fix=f"choose a folder you can write to, or change the permissions of "
                              f"{path.parent}") from None
    except OSError as error:
        raise OutputError(f"cannot write in the folder {path.parent} ({error.strerror or error})",
                          file=str(path), fix="choose a folder on a writable disk with free space") from None
    os.close(handle)
    os.unlink(probe)


def check_input_kept(scene: Scene, output: Path, overwrite: bool = False) -> None:
    """Refuse an output whose files would replace a file the input uses (its .bin, its images),
    unless ``overwrite``.

    A ``.gltf`` output writes ``<stem>.bin`` beside it, and any output in another folder than
    the input's copies the images the input names by URI beside it (``write.image_file_name``).
    """
    if overwrite:
        return
    written = [output] + ([output.with_name(output.stem + ".bin")]
                          if output.suffix.lower() == ".gltf" else [])
    folder = scene.path.parent
    if output.parent.resolve() != folder.resolve():
        written += [output.with_name(image_file_name(output, i, image.uri))
                    for i, image in enumerate(scene.document.images)
                    if isinstance(image.uri, str) and not image.uri.startswith("data:")]
    fix = "choose another output name or folder, or add --overwrite to replace it"
    for kind, items in (("buffers", scene.document.buffers), ("images", scene.document.images)):
        for i, item in enumerate(items):
            uri = item.uri
            if not isinstance(uri, str) or not uri or uri.startswith("data:"):
                continue
            source = inside(uri, folder, str(scene.path), f"{kind}[{i}]")
            for target in written:
                if target.exists() and source.exists() and os.path.samefile(source, target):
                    raise OutputError(f"the output would replace {source}, which the input uses",
                                      file=str(output), where=f"{kind}[{i}].uri", fix=fix)


@dataclass(frozen=True)
class Computed:
    """Everything a bake computed before encoding, for the report, tests and benchmarks.

    ``per_texel`` holds the texels and their results, in memory or on disk (``parts.py``);
    ``texels``, ``validity``, ``terms`` and ``direct`` load them whole on first use. ``tally``
    has what the report needs of them without loading them.
    """

    scene: Scene
    world: World
    settings: Resolved
    ambient: Ambient
    plan: Plan
    atlas: Atlas
    per_texel: PerTexel
    tally: Tally
    lightmaps: Lightmaps
    stage_seconds: dict[str, float]
    sources: Sources | None = None  # what lights the scene directly (direct.py)
    power: Power | None = None  # what each source lays on the surfaces, for I_A
    denoised: DenoiseInfo | None = None  # what --denoise did (denoise.py); None: not denoised

    @property
    def texels(self) -> Texels:
        return self.per_texel.texels

    @property
    def validity(self) -> Validity:
        """Which sample points were moved or flagged (validity.py)."""
        return self.per_texel.validity

    @property
    def terms(self) -> Terms:
        return self.per_texel.terms

    @property
    def direct(self) -> Direct | None:
        """The texels' direct light, per source."""
        return self.per_texel.direct

    def obscurance_rmse(self) -> float:
        """RMSE of the luminance of I_A·W estimated from the rays (``Terms.rmse``)."""
        return self.tally.obscurance_rmse(self.settings.sampling) * float(
            self.ambient.intensity @ LUMINANCE)

    def rmse_estimate(self) -> float:
        """RMSE of the lightmap's luminance estimated from the rays: I_A·W's and D's."""
        if not self.tally.texels:
            return 0.0
        direct = self.tally.direct_variance / self.tally.texels
        return float(np.sqrt(self.obscurance_rmse() ** 2 + direct))


def lighting(scene: Scene, world: World, resolved: Resolved, times: dict[str, float]):
    """Embree's scene, the light sources, the power they deliver, I_A and R_ave, and the plan:
    what a bake and a rebake both need before any texel. Returns (tracer, sources, power,
    ambient, plan); adds the stages "lights" and "plan" to ``times``."""
    with _timed(times, "lights"):
        tracer = Tracer(world)
        sources = light_sources(scene, world, resolved)
        power = delivered_power(scene, world, tracer, sources, resolved)
    with _timed(times, "plan"):
        ambient = ambient_terms(scene, world, resolved.ambient, power)
        plan = make_plan(scene, ambient, resolved.rho, sources)
    return tracer, sources, power, ambient, plan


@dataclass(frozen=True)
class _Baking:
    """What every part of a bake needs (``compute``)."""

    scene: Scene
    world: World
    settings: Resolved
    tracer: Tracer
    sources: Sources
    ambient: Ambient
    atlas: Atlas
    coverage: Coverage | None = None  # which triangle owns each texel (rasterise.cover)
    owned: Owners | None = None  # what the texels take from their triangles (rasterise.owners)
    faces: Faces | None = None  # back faces, for the validity probes
    surfaces: Surfaces | None = None  # shading of obscurance hits (integrate.surfaces_of)


class _StateStaging:
    """The bake state (docs/bake_state.md), written on a thread of its own into a temporary file
    beside ``path`` from the moment the texels' results are final (``start``), so that it is
    written while the pages are denoised, post-processed and encoded and the output written
    (its CRCs and file writes release the GIL, as numba's kernels and zlib do); put in place
    only once the output is (``put_in_place``), removed if anything fails (``discard``)."""

    def __init__(self, executor: ThreadPoolExecutor, path: Path, settings: Settings):
        self._executor, self._path, self._settings = executor, path, settings
        self._future: Future | None = None

    def start(self, baking: "_Baking", per_texel: PerTexel, fingerprint: dict | None = None
              ) -> None:
        """Begin writing the state of ``baking``'s texels ``per_texel`` (``fingerprint``: the
        scene's, if made already)."""
        writer = bake_state_writer(baking.scene, baking.world, baking.settings, baking.atlas,
                                   per_texel, self._settings, fingerprint)
        self._future = self._executor.submit(stage_atomically, self._path, writer)

    def put_in_place(self) -> None:
        """Wait for the state to be written and rename it to its path. The state it replaces
        is freed on a thread of its own (``spill.set_aside``)."""
        temp = self._future.result()
        old = set_aside(self._path)
        try:
            _rename(temp, self._path)
        finally:
            if old is not None:
                remove_later(old)

    def discard(self) -> None:
        """Wait for the state being written, if any, and remove it."""
        _discard(self._future)


def compute(scene: Scene, settings: Settings, quiet: bool = True,
            spill_folder: str | os.PathLike | None = None,
            staging: _StateStaging | None = None) -> Computed:
    """Run every stage from the loaded scene up to the post-processed float lightmaps.

    The texels are made, traced and composed a part at a time (``parts.py``); when there are
    several parts, each part's results go to a temporary folder in ``spill_folder`` (None: the
    system's) until the bake state is written (``Computed.per_texel``). ``staging``: where the
    bake state starts to be written once the texels are done.
    """
    times: dict[str, float] = {}
    with _timed(times, "load"):
        world = build_world(scene)
    area, diagonal = _bounds_of_baked(world, scene)
    resolved = resolve(settings, area, diagonal)
    tracer, sources, power, ambient, plan = lighting(scene, world, resolved, times)
    with _timed(times, "unwrap"):
        try:
            atlas = unwrap(scene, world, resolved)
        except PageTooSmall as error:
            if settings.texel_density is not None:  # the user's density: say what fits
                raise
            resolved = replace(resolved, texel_density=error.texel_density)  # derived: shrink it
            atlas = unwrap(scene, world, resolved)
    with _timed(times, "rasterise"):
        coverage = cover(atlas, world)
        owned = owners(atlas, world, coverage)
    count = len(coverage.key)
    spill = Spill(spill_folder) if len(part_slices(count)) > 1 else None
    baking = _Baking(scene, world, resolved, tracer, sources, ambient, atlas, coverage, owned,
                     Faces(scene, world), surfaces_of(scene, world))
    try:
        pages, held = _bake_parts(baking, spill, times, quiet)
        per_texel = (PerTexel.spilled(spill, atlas, world) if spill is not None
                     else PerTexel.held(*held))
        return _finish_pages(baking, power, plan, per_texel, pages, times, staging)
    except BaseException:  # an error or Ctrl-C: no spilled rows left behind
        if spill is not None:
            spill.close()
        raise


def _bake_parts(baking: _Baking, spill: Spill | None, times: dict[str, float], quiet: bool):
    """Bake the texels a part at a time, each composed into the pages as it is done and, with
    a ``spill``, its rows appended to it. Returns the composed ``_Pages``, and the last part's
    (texels, validity, terms, direct) — all the texels' when there is one part."""
    count = len(baking.coverage.key)
    pages = _Pages.blank(baking)
    with bar(count * (1 + baking.sources.any()), "baking", wanted(quiet)) as advance:
        for rows in part_slices(count):
            texels, points, validity, terms, direct, indirect = _bake_part(baking, rows, times,
                                                                           advance)
            with _timed(times, "compose"):
                pages.add(baking, texels, validity, terms, direct, indirect)
            if spill is not None:
                with _timed(times, "spill"):
                    for name, group in (("texels", points), ("validity", validity),
                                        ("terms", terms), ("direct", direct)):
                        spill.append(name, group)
    return pages, (texels, points, validity, terms, direct)


def _bake_part(baking: _Baking, rows: slice, times: dict[str, float],
               advance: Callable[[int], None]):
    """Make, probe, trace and light the texels ``rows``: (texels with their sample points moved
    by the probes, what the state keeps of them (``TexelPoints``), validity, obscurance terms,
    direct light, and the full-GI indirect irradiance (k, 3) with ``--method gi``, else
    None)."""
    s, ambient, scene, world, tracer = (baking.settings, baking.ambient, baking.scene,
                                        baking.world, baking.tracer)
    with _timed(times, "rasterise"):
        made = texels_of(baking.atlas, world, baking.coverage, rows, baking.owned)
    with _timed(times, "validity"):  # sample points inside/behind geometry: moved or flagged
        texels, validity = check_texels(scene, world, tracer, made, s.d_max, faces=baking.faces)
        points = TexelPoints.of(texels, made.position)
    with _timed(times, "trace"):
        error_scale = (effective_r_ave(ambient, s.rho), float(ambient.intensity @ LUMINANCE))
        terms = integrate(scene, world, tracer, texels, s, advance, error_scale=error_scale,
                          surfaces=baking.surfaces)
    with _timed(times, "direct"):
        direct = direct_light(scene, world, tracer, texels, baking.sources, s, advance)
    indirect = None
    if s.method == "gi":  # the full-GI reference instead of I_A·W (gi.py)
        with _timed(times, "gi"):
            indirect = indirect_light(scene, world, tracer, baking.sources, texels, s,
                                      s.rays).irradiance
    return texels, points, validity, terms, direct, indirect


def finish(scene: Scene, world: World, resolved: Resolved, tracer: Tracer, sources: Sources,
           power: Power, ambient: Ambient, plan: Plan, atlas: Atlas, texels: Texels,
           points: TexelPoints, validity: Validity, terms: Terms, direct: Direct,
           times: dict[str, float], staging: _StateStaging | None = None,
           fingerprint: dict | None = None) -> Computed:
    """From the texels' terms, all held in memory, to the post-processed float lightmaps: an
    incremental rebake (incremental.py) ends as a full bake does, so both give the same bytes
    (``staging`` and the scene's ``fingerprint``: the bake state, as in ``compute``).
    """
    baking = _Baking(scene, world, resolved, tracer, sources, ambient, atlas)
    with _timed(times, "compose"):
        pages = _Pages.blank(baking)
        pages.add(baking, texels, validity, terms, direct)
    return _finish_pages(baking, power, plan,
                         PerTexel.held(texels, points, validity, terms, direct), pages, times,
                         staging, fingerprint)


@dataclass
class _Pages:
    """What the texels are composed into, part by part: the lightmaps, the validity's page
    masks (invalid, enclosed) and the report's ``Tally``."""

    lightmaps: Lightmaps
    masks: tuple[np.ndarray, np.ndarray]
    tally: Tally

    @classmethod
    def blank(cls, baking: _Baking) -> "_Pages":
        """Nothing composed yet (pages of W only for the occlusion texture)."""
        lightmaps = blank(baking.atlas, obscurance=baking.settings.occlusion != "none")
        return cls(lightmaps, (np.zeros_like(lightmaps.covered),
                               np.zeros_like(lightmaps.covered)), Tally())

    def add(self, baking: _Baking, texels: Texels, validity: Validity, terms: Terms,
            direct: Direct, indirect: np.ndarray | None = None) -> None:
        """Compose the texels' light, mark their validity and count them."""
        rho, ambient = baking.settings.rho, baking.ambient
        compose_into(self.lightmaps, texels, terms, ambient, rho, direct, indirect=indirect)
        validity.mark(texels, *self.masks)
        self.tally.add(terms, direct, validity, effective_r_ave(ambient, rho))


def _finish_pages(baking: _Baking, power: Power, plan: Plan, per_texel: PerTexel, pages: _Pages,
                  times: dict[str, float], staging: _StateStaging | None = None,
                  fingerprint: dict | None = None) -> Computed:
    """Start writing the bake state (``staging``, if any: the texels are final), then denoise
    (if asked) and post-process the composed pages."""
    if staging is not None:
        staging.start(baking, per_texel, fingerprint)
    resolved, lightmaps, masks = baking.settings, pages.lightmaps, pages.masks
    denoised = None
    if resolved.denoise:  # per chart, before the fill of invalid texels and dilation (denoise.py)
        with _timed(times, "denoise"):
            lightmaps, denoised = denoise(lightmaps, per_texel.texels, *masks,
                                          threads=resolved.threads,
                                          obscurance=resolved.occlusion != "none")
    with _timed(times, "compose"):
        lightmaps = postprocess(lightmaps, resolved.padding, *masks,
                                seams=find_seams(baking.atlas, baking.world))
    return Computed(scene=baking.scene, world=baking.world, settings=resolved,
                    ambient=baking.ambient, plan=plan, atlas=baking.atlas, per_texel=per_texel,
                    tally=pages.tally, lightmaps=lightmaps, stage_seconds=times,
                    sources=baking.sources, power=power, denoised=denoised)


def bake(input: str | os.PathLike, output: str | os.PathLike, settings: Settings = Settings(), *,
         report_path: str | os.PathLike | None = None,
         lightmaps_dir: str | os.PathLike | None = None, lightmaps_format: str = "png",
         error_map_dir: str | os.PathLike | None = None,
         quiet: bool = True, overwrite: bool = False, incremental: bool = False,
         state: str | os.PathLike | bool | None = None, relight: bool = False) -> BakeResult:
    """Bake the glTF scene at ``input`` into ``output`` (.glb or .gltf) with lightmaps.

    ``report_path`` writes the JSON report; ``lightmaps_dir`` also writes each page as a file,
    ``lightmaps_format`` "png" (the embedded image), "hdr" or "exr" (the float page, hdr.py);
    ``error_map_dir`` writes each page's per-texel standard error (errormap.py);
    ``quiet=False`` draws a progress bar when stderr is a terminal. ``overwrite`` lets
    ``output`` be the input itself (or replace a file the input uses); it is replaced
    atomically, only once the bake has succeeded.

    ``state``: the bake state (docs/bake_state.md) written after the bake, ``<output>.bake`` by
    default (None/True), another path, or False for none. ``incremental=True`` starts from that
    state: only the texels the edit can reach are recomputed, bit-identical to a full bake; a
    missing, damaged or mismatched state, or an edit that changes the atlas, falls back to a
    full bake. ``BakeResult.rebake`` says which (``full_bake_reason``), what changed, and names
    the recomputed texels (``dirty_keys``, ``dirty_reasons``). ``relight=True``: only light
    colours and intensities may have changed; the lightmaps are recomposed from the state with
    no ray cast, and anything else is an InputError (nothing written).
    """
    input_path, output = Path(input), Path(output)
    check_output(input_path, output, overwrite,
                 None if report_path is None else Path(report_path))
    settings.check()
    check_format(lightmaps_format)
    started = time.perf_counter()
    loading: dict[str, float] = {}
    with _timed(loading, "load"):
        scene = load(input_path, settings.mirror_roughness)
    check_input_kept(scene, output, overwrite)
    state_path = None if state is False else (
        default_state_path(output) if state is None or state is True else Path(state))
    with ThreadPoolExecutor(1) as beside:
        staging = None if state_path is None else _StateStaging(beside, state_path, settings)
        try:
            try:
                done, rebaked = bake_or_rebake(scene, settings, state_path, incremental, quiet,
                                               relight, (state_path or output).parent, staging)
            except BakerError as error:  # a setting this scene cannot meet: name the scene
                error.file = error.file or str(input_path)
                raise
            times = dict(done.stage_seconds)
            times["load"] += loading["load"]
            resolved = done.settings
            # closing(): the rows the state is written from (parts.py), if on disk, are
            # removed once the state is written.
            with closing(done.per_texel), _timed(times, "write"):
                pages = encode(done.lightmaps, resolved.encoding, resolved.occlusion != "none",
                               resolved.clip_percentile)
                info = write(scene, done.atlas, pages, output,
                             WriteOptions(encoding=resolved.encoding, occlusion=resolved.occlusion,
                                          clip_percentile=resolved.clip_percentile))
                if lightmaps_dir is not None:
                    write_page_files(Path(lightmaps_dir), output.stem, pages,
                                     done.lightmaps.light, lightmaps_format)
                if error_map_dir is not None:  # per-texel standard error pages (errormap.py)
                    write_error_maps(Path(error_map_dir), output.stem, done, write_atomically)
                if staging is not None:
                    staging.put_in_place()
                    record_full_bake(state_path, rebaked, time.perf_counter() - started)
        except BaseException:
            if staging is not None:
                staging.discard()
            raise
    seconds = time.perf_counter() - started
    rmse = done.rmse_estimate()
    ambient, atlas = done.ambient, done.atlas
    report = {
        "input": str(input_path), "output": str(output),
        "settings": resolved.as_dict(),
        "plan": done.plan.as_dict(),
        "ambient": {"r_ave": ambient.r_ave.tolist(), "intensity": ambient.intensity.tolist(),
                    "source": ambient.source, "series_truncated": ambient.truncated},
        "atlas": {"pages": atlas.page_count, "width": atlas.width, "height": atlas.height,
                  "texel_density": atlas.texel_density},
        "texels": done.tally.texels, "rays": done.tally.rays,
        "shadow_rays": done.tally.shadow_rays,
        "rays_per_second": done.tally.rays / times["trace"] if times["trace"] > 0 else 0.0,
        "stage_seconds": times, "seconds": seconds,
        "rmse_estimate": rmse,
        "validity": done.tally.states,
        "denoise": done.denoised.as_dict() if done.denoised is not None else {"denoised": False},
        "notes": list(info.notes) + clipping_notes(pages),
        "warnings": input_warnings(done.scene, done.world),  # dropped or changed, counted
        "lightmap_pages": [{"intensity": page.intensity, "peak": page.peak,
                            "clipped_fraction": page.clipped} for page in pages],
        "rebake": summary(rebaked, state_path, incremental, seconds),
    }
    if report_path is not None:
        write_atomically(Path(report_path), json.dumps(report, indent=2).encode())
    return BakeResult(output=output, settings=resolved, plan=done.plan, texels=done.tally.texels,
                      rays=done.tally.rays, pages=atlas.page_count, seconds=seconds,
                      rmse_estimate=rmse, report=report,
                      rebake=details(report["rebake"], rebaked))


def _umask() -> int:
    """The process's file-creation mask (read by setting it and setting it back)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def stage_atomically(path: Path, data: bytes | Callable[[BinaryIO], None]) -> str:
    """The first half of ``write_atomically``: write ``data`` to a temporary file beside
    ``path`` with the permissions a new file gets, and return the temporary's path, for
    ``_rename`` to put in place (nothing is left behind if writing fails)."""
    if not path.parent.exists():
        raise OutputError("the folder does not exist", file=str(path),
                          fix=f"create {path.parent} first")
    handle, temp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(handle, "wb") as f:
            if callable(data):
                data(f)
            else:
                f.write(data)
        os.chmod(temp, 0o666 & ~_umask())
    except BaseException:
        _remove(temp)
        raise
    return temp


def _rename(temp: str, path: Path) -> None:
    """Put the staged file ``temp`` in place at ``path`` (an atomic rename)."""
    try:
        os.replace(temp, path)
    except BaseException:
        _remove(temp)
        raise


def _remove(temp: str) -> None:
    """Delete the temporary file ``temp`` if it is there."""
    if os.path.exists(temp):
        os.unlink(temp)


def _discard(staging: Future | None) -> None:
    """Wait for a file being staged beside a write that failed, and remove it."""
    if staging is None:
        return
    try:
        _remove(staging.result())
    except Exception:
        pass  # it failed too; the write's own error is the one to report


def write_atomically(path: Path, data: bytes | Callable[[BinaryIO], None]) -> None:
    """Write ``data`` to ``path`` through a temporary file and a rename; ``data`` is the bytes,
    or a function that writes them to the open file (to stream large files). The file gets the
    permissions a newly created file gets (0666 less the umask), not the temporary's 0600."""
    _rename(stage_atomically(path, data), path)


def clipping_notes(pages) -> list[str]:
    """One report note per page whose intensity (a percentile, encode.py) clips texels."""
    return [f"lightmap page {p}: {page.clipped:.2%} of its texels are brighter than its "
            f"MOZ_lightmap intensity {page.intensity:.4g} (peak {page.peak:.4g}) and clip to it; "
            "--clip-percentile 100 scales to the peak, --lightmaps DIR --format exr keeps floats"
            for p, page in enumerate(pages) if page.clipped > 0]


def write_page_files(folder: Path, stem: str, pages, light=None, format: str = "png") -> list[Path]:
    """Write each lightmap page as ``<stem>_lightmap_<p>.<format>`` in ``folder`` (made if
    needed): the embedded PNG, or with ``light`` (P, H, W, 3) the float page as .hdr or .exr."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for p, page in enumerate(pages):
        path = folder / f"{stem}_lightmap_{p}.{format}"
        write_atomically(path, page_file(None if light is None else light[p], page.png, format))
        paths.append(path)
    return paths
