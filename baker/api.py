"""The bake a user asks for: check the paths, load, bake or rebake, write, report."""

from __future__ import annotations

import json
import os
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from contextlib import closing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import baker.jit as jit
from baker.errors import BakerError, InputError, OutputError
from baker.gltf.container import read_document
from baker.gltf.load import load
from baker.gltf.scene import Scene
from baker.image.carriers import emissive_lightmaps, viewer_notes
from baker.image.compose import Lightmaps
from baker.image.encode import EncodedPage, encode
from baker.image.errormap import write_error_maps
from baker.image.hdr import check_format, page_file
from baker.light.gi import MAX_BOUNCES
from baker.output.write import (DIRECTIONAL_EXTENSION, WriteInfo, WriteOptions, image_file_name,
                                write)
from baker.pipeline import cluster
from baker.pipeline.full import Computed, compute, writes_occlusion
from baker.pipeline.input_warnings import input_warnings
from baker.pipeline.plan import Plan
from baker.rays import native
from baker.rebake.asked import asked_settings
from baker.rebake.diff import code_fingerprint
from baker.rebake.fallback import FullBake
from baker.rebake.incremental import rebake
from baker.rebake.report import details, record_full_bake, summary
from baker.rebake.staging import StateStaging
from baker.rebake.state import default_path as default_state_path
from baker.rebake.state import timing_path
from baker.run.atomic import Outputs, destination, write_atomically
from baker.run.compile_clock import CompileClock
from baker.run.progress import StageLines
from baker.run.stages import timed
from baker.settings import Resolved, Settings


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
    rebake: dict | None = field(default=None, repr=False)  # rebake.report.summary: what changed


def check_output(input_path: Path, output: Path, overwrite: bool = False,
                 report_path: Path | None = None, state_path: Path | None = None,
                 folders: tuple[Path | None, ...] = ()) -> None:
    """Refuse, before any work, an output that cannot be written or would replace the input.

    The output ends in .glb or .gltf; it, the report, the bake state and its timing record are
    regular files or missing (``run.atomic.destination``: never a folder, a device or a link to
    one; a FIFO is written into) in folders that can be written to, or are missing below a
    folder that can (the bake makes them, ``Outputs.folder``, as for ``-o out/level.gltf``);
    ``folders`` (``--lightmaps``, ``--error-map``) are not files; the output is the input
    itself only with ``overwrite`` (the input is then replaced atomically).
    """
    if output.suffix.lower() not in (".glb", ".gltf"):
        raise OutputError(f"the output must end in .glb or .gltf, not {output.suffix or '(none)'}",
                          file=str(output), fix="name the output e.g. scene_baked.glb")
    if not overwrite and output.exists() and input_path.exists() and os.path.samefile(input_path, output):
        raise OutputError("the output is the input file: baker replaces its input only when asked",
                          file=str(output), fix="give another output path with -o, or add --overwrite "
                                                "to replace the input with its bake")
    timing = None if state_path is None else timing_path(state_path)
    for path in (output, report_path, state_path, timing):
        if path is not None and destination(path) == "replace":
            _check_writable(path, _existing_folder(path))
    for folder in folders:
        if folder is not None and folder.exists() and not folder.is_dir():
            raise OutputError("is a file, not a folder", file=str(folder),
                              fix="give a folder (it is made if missing), or remove the file")


def _existing_folder(path: Path) -> Path:
    """The deepest folder above ``path`` that exists: its own folder, or the one below which
    the bake makes the missing ones. A file in the way is an OutputError."""
    folder = path.parent
    while not folder.exists():
        folder = folder.parent
    if not folder.is_dir():
        raise OutputError(f"{folder} is a file, not a folder", file=str(path),
                          fix=f"choose a path that is not below the file {folder}")
    return folder


def _check_writable(path: Path, folder: Path) -> None:
    """Create and remove a file in ``folder`` (``path``'s, or the existing one above it): the
    one true test that it can be written."""
    try:
        handle, probe = tempfile.mkstemp(dir=folder, prefix=".baker-probe-", suffix=".tmp")
    except PermissionError:
        raise OutputError(f"no permission to write in the folder {folder}", file=str(path),
                          fix=f"choose a folder you can write to, or change the permissions of "
                              f"{folder}") from None
    except OSError as error:
        raise OutputError(f"cannot write in the folder {folder} ({error.strerror or error})",
                          file=str(path), fix="choose a folder on a writable disk with free space") from None
    os.close(handle)
    os.unlink(probe)


def output_files(scene: Scene, output: Path) -> list[Path]:
    """The files of the output itself: ``output``, and for a ``.gltf`` output the ``<stem>.bin``
    it writes beside it and, in another folder than the input's, the copies of the images the
    input names by URI (``write.image_file_name``; a ``.glb`` holds them): those
    ``--overwrite`` lets replace files the input uses."""
    gltf = output.suffix.lower() == ".gltf"
    written = [output] + ([output.with_name(output.stem + ".bin")] if gltf else [])
    if gltf and output.parent.resolve() != scene.path.parent.resolve():
        written += [output.with_name(image_file_name(output, i, image.uri))
                    for i, image in enumerate(scene.document.images)
                    if isinstance(image.uri, str) and not image.uri.startswith("data:")]
    return written


def bake(input: str | os.PathLike, output: str | os.PathLike, settings: Settings = Settings(), *,
         report_path: str | os.PathLike | None = None,
         lightmaps_dir: str | os.PathLike | None = None, lightmaps_format: str = "png",
         error_map_dir: str | os.PathLike | None = None,
         quiet: bool = True, overwrite: bool = False, incremental: bool | str = False,
         state: str | os.PathLike | bool | None = None, relight: bool = False,
         contained: bool = False) -> BakeResult:
    """Bake the glTF scene at ``input`` into ``output`` (.glb or .gltf) with lightmaps.

    ``report_path`` writes the JSON report; ``lightmaps_dir`` also writes each page as a file,
    ``lightmaps_format`` "png" (the embedded image), "hdr" or "exr" (the float page, hdr.py);
    ``error_map_dir`` writes each page's per-texel standard error (errormap.py);
    ``quiet=False`` prints a line per stage with its time to stderr, and draws a progress
    bar of the rays on a terminal (``run.progress``). ``overwrite`` lets
    ``output`` be the input itself (or replace a file the input uses); it is replaced
    atomically, only once the bake has succeeded.

    ``state``: the bake state (docs/bake_state.md) written after the bake, ``<output>.bake`` by
    default (None/True), another path, or False for none. ``incremental=True`` starts from that
    state: only the texels the edit can reach are recomputed, bit-identical to a full bake; a
    missing, damaged or mismatched state, an edit that changes the atlas, or one whose rebake
    the last bakes' measured times say would cost more than a full bake, falls back to a full
    bake; ``incremental="always"`` leaves out the last (a rebake whenever it can follow: to
    measure it, or test it). ``BakeResult.rebake`` says which (``full_bake_reason``), what changed, and names
    the recomputed texels (``dirty_keys``, ``dirty_reasons``). ``relight=True``: only light
    colours and intensities may have changed; the lightmaps are recomposed from the state with
    no ray cast, and anything else is an InputError (nothing written). ``contained``: the scene
    file itself is opened as the files it names are (inside its folder, no link out, one
    name: ``gltf.load.load``), for scenes as untrusted as their contents (``baker hook``).

    No file the bake writes ever replaces one the scene is read from, whatever its name; with
    ``overwrite``, the output's own files may (``output_files``).
    """
    input_path, output = Path(input), Path(output)
    files = _Files.asked(output, report_path, lightmaps_dir, lightmaps_format, error_map_dir,
                         state)
    check_output(input_path, output, overwrite, files.report, files.state,
                 (files.lightmaps, files.error_maps))
    settings.check()
    check_format(lightmaps_format)
    started = time.perf_counter()
    log = StageLines(not quiet)
    scene, load_seconds = _loaded(input_path, settings, contained, log)
    outputs = _claimed(scene, output, overwrite, files)
    with ThreadPoolExecutor(1) as beside, CompileClock() as compiling, \
            cluster.session(settings.cluster, settings.threads, cluster_identity) as on_cluster:
        staging = None if files.state is None else StateStaging(beside, files.state, settings)
        try:
            for path in (output, files.report, files.state):  # made if missing, like mkdir -p
                if path is not None:
                    outputs.folder(path.parent)
            done, rebaked = _computed(scene, settings, files.state, incremental, quiet, relight,
                                      (files.state or output).parent, staging)
            times = dict(done.stage_seconds)
            times["load"] += load_seconds
            # closing(): the rows the state is written from (parts.py), if on disk, are
            # removed once the state is written.
            clock = timed(times, "write")
            with closing(done.per_texel), log.stage("write", "steps", clock) as steps, clock:
                pages, info = _written(done, output, files, outputs, steps)
                if staging is not None:
                    staging.stage_into(outputs)
                    record_full_bake(files.state, rebaked, time.perf_counter() - started
                                     - compiling.seconds, outputs.stage, times)
            seconds = time.perf_counter() - started
            report = _report(input_path, output, done, info, pages, times, seconds,
                             summary(rebaked, files.state, incremental, seconds,
                                     compiling.seconds))
            if on_cluster is not None:  # which worker baked what, the stages' time on them
                report["cluster"] = on_cluster.report()
            if files.report is not None:
                outputs.stage(files.report, json.dumps(report, indent=2).encode())
            outputs.commit()
        except BaseException:
            outputs.discard()
            if staging is not None:
                staging.discard()
            raise
    return BakeResult(output=output, settings=done.settings, plan=done.plan,
                      texels=done.tally.texels, rays=done.tally.rays,
                      pages=done.atlas.page_count, seconds=seconds,
                      rmse_estimate=report["rmse_estimate"], report=report,
                      rebake=details(report["rebake"], rebaked))


@dataclass(frozen=True)
class _Files:
    """The files a bake writes besides its output, as paths (None: not written): the JSON
    report, the folders of page files (``lightmaps_format``) and error maps, the bake state."""

    report: Path | None
    lightmaps: Path | None
    lightmaps_format: str
    error_maps: Path | None
    state: Path | None

    @staticmethod
    def asked(output: Path, report, lightmaps, lightmaps_format: str, error_maps,
              state) -> "_Files":
        """``bake``'s arguments as paths; ``state`` None or True: ``<output>.bake``, False:
        none."""
        def path(value) -> Path | None:
            return None if value is None else Path(value)
        state_path = None if state is False else (
            default_state_path(output) if state is None or state is True else Path(state))
        return _Files(path(report), path(lightmaps), lightmaps_format, path(error_maps),
                      state_path)


def _loaded(input_path: Path, settings: Settings, contained: bool, log: StageLines
            ) -> tuple[Scene, float]:
    """The scene at ``input_path`` (``gltf.load.load``) and the seconds its loading took."""
    loading: dict[str, float] = {}
    with timed(loading, "load"), log.stage("load"):
        scene = load(input_path, settings.mirror_roughness, settings.animated,
                     settings.allow_hard_links, contained)
    return scene, loading["load"]


def _claimed(scene: Scene, output: Path, overwrite: bool, files: _Files) -> Outputs:
    """The ``Outputs`` every file of the bake is staged in and put in place together
    (run/atomic.py), none over a file the scene reads: checked here before any work, and
    again before the first rename."""
    own = output_files(scene, output)
    outputs = Outputs(scene.inputs, own, overwrite)
    state_files = [] if files.state is None else [files.state, timing_path(files.state)]
    for path in own + state_files + ([] if files.report is None else [files.report]):
        outputs.check(path)
    return outputs


def _computed(scene: Scene, settings: Settings, state_path: Path | None,
              incremental: bool | str, quiet: bool, relight: bool, spill_folder: Path,
              staging: StateStaging | None):
    """``bake_or_rebake``, its errors of settings the scene cannot meet naming the scene."""
    try:
        return bake_or_rebake(scene, settings, state_path, incremental, quiet, relight,
                              spill_folder, staging)
    except BakerError as error:
        error.file = error.file or str(scene.path)
        raise


def _written(done: Computed, output: Path, files: _Files, outputs: Outputs, steps
             ) -> tuple[list[EncodedPage], WriteInfo]:
    """Encode ``done``'s pages and stage the output, the page files and the error maps in
    ``outputs``, counting the encoded texels and the written ones on ``steps``."""
    texels = done.lightmaps.covered.size  # the pages' texels encoded: as many steps
    steps.expect(texels)
    pages = encode_pages(done)
    steps.advance(texels)
    info = write_output(done, pages, output, outputs, steps)
    if files.lightmaps is not None:
        write_page_files(outputs.folder(files.lightmaps), output.stem, pages,
                         done.lightmaps.light, files.lightmaps_format, outputs.stage)
    if files.error_maps is not None:  # per-texel standard error pages (errormap.py)
        write_error_maps(outputs.folder(files.error_maps), output.stem, done, outputs.stage)
    return pages, info


def last_settings(output: str | os.PathLike, state: str | os.PathLike | None = None,
                  **overrides) -> Settings:
    """The ``Settings`` the last bake of ``output`` was given, read from its bake state
    (``state``; default ``<output>.bake``), with ``overrides``: what ``baker rebake`` and
    ``relight`` bake with. The settings a state never gives (``settings.CALLER_ONLY``) are the
    defaults unless ``overrides`` give them; SettingsError when there is no usable state."""
    return asked_settings(Path(state) if state else default_state_path(Path(output)),
                          **overrides)


def scene_node_names(scene: str | os.PathLike) -> dict[int, str]:
    """Node index → name (or ``nodes[i]``) of the glTF file ``scene``, for messages."""
    document = read_document(scene)
    return {i: node.name or f"nodes[{i}]" for i, node in enumerate(document.nodes or [])}


def encode_pages(done: Computed) -> list[EncodedPage]:
    """``done``'s pages as the output carries them (``carried``), encoded as its settings say
    (8-bit PNG: ``image.encode.encode``)."""
    s = done.settings
    return encode(carried(done), s.encoding, writes_occlusion(s), s.clip_percentile)


def write_output(done: Computed, pages: list[EncodedPage], output: str | os.PathLike,
                 outputs: Outputs | None = None, steps=None) -> WriteInfo:
    """Write ``done``'s scene with its lightmap ``pages`` (``encode_pages``) to ``output`` (.glb
    or .gltf) as its settings say (``output.write.write``); ``outputs``: stage the files there
    for the caller to put in place with its others (None: in place now, atomically)."""
    s = done.settings
    options = WriteOptions(encoding=s.encoding, occlusion=s.occlusion,
                           clip_percentile=s.clip_percentile, carrier=s.carrier,
                           baked_lights=s.baked_lights, authored_uv=s.uv)
    return write(done.scene, done.atlas, pages, Path(output), options, outputs, steps)


def build_status() -> dict[str, str]:
    """How this install runs bakes (``baker --version``, the report): its kernels, compiled
    ahead of time or by numba (``jit.status``), and what casts its rays (``native.engine``)."""
    return {"kernels": jit.status(), "rays": native.engine()}


def cluster_identity() -> dict[str, str]:
    """What the driver and every worker of a cluster must share (``pipeline.cluster``): baker's
    code (``rebake.diff.code_fingerprint``), Python's and the libraries' versions. Run on each
    node by name, so that a node answers with its own baker's."""
    return {"baker code": code_fingerprint(), **cluster.versions()}


def _report(input_path: Path, output: Path, done, info, pages, times: dict[str, float],
            seconds: float, rebake: dict) -> dict:
    """The JSON-able report of a bake (``--report``): settings, plan, atlas, texels, rays, times,
    warnings and notes, each page's intensity, and the rebake's ``summary``."""
    ambient, atlas, status = done.ambient, done.atlas, build_status()
    return {
        "input": str(input_path), "output": str(output),
        "settings": done.settings.as_dict(),
        "plan": done.plan.as_dict(),
        "ambient": {"r_ave": ambient.r_ave.tolist(), "intensity": ambient.intensity.tolist(),
                    "source": ambient.source, "series_truncated": ambient.truncated},
        "atlas": {"pages": atlas.page_count, "width": atlas.width, "height": atlas.height,
                  "texel_density": atlas.texel_density},
        "texels": done.tally.texels, "rays": done.tally.rays,
        "shadow_rays": done.tally.shadow_rays,
        "rays_per_second": done.tally.rays / times["trace"] if times["trace"] > 0 else 0.0,
        "stage_seconds": times, "seconds": seconds, "kernels": status["kernels"],
        "rays_engine": status["rays"],
        "rmse_estimate": done.rmse_estimate(),
        "rmse_estimate_leaves_out": [] if done.sources is None else done.sources.unmeasured(),
        "validity": done.tally.states,
        "denoise": done.denoised.as_dict() if done.denoised is not None else {"denoised": False},
        "smooth": done.smoothed.as_dict() if done.smoothed is not None else {"smoothed": False},
        "carrier": done.settings.carrier, "baked_lights": done.settings.baked_lights,
        "notes": list(info.notes) + clipping_notes(pages) + viewer_notes(
            done.scene, done.world, [u.instance for u in done.atlas.instances],
            done.settings.carrier) + gi_notes(done) + target_notes(done, pages),
        "warnings": input_warnings(done.scene, done.world),  # dropped or changed, counted
        "lightmap_pages": [{"intensity": page.intensity, "peak": page.peak,
                            "clipped_fraction": page.clipped} for page in pages],
        "rebake": rebake,
        **({"foliage": done.foliage.report()} if done.foliage is not None else {}),
        **({"gi": gi_report(done.tally)} if done.settings.method == "gi" else {}),
        **({"directional": directional_report(done, pages)}
           if done.settings.directional else {}),
        **({"sky": done.sources.sky.report()}
           if done.sources is not None and done.sources.sky is not None else {}),
    }


def directional_report(done, pages) -> dict:
    """What ``--directional`` gave: whether pages were written (a baked material has a normal
    map), the extension, the RMS standard error of the texels' first moment U
    (``light.directional``, lightmap luminance units) and the pages' PNG bytes against the
    irradiance pages'."""
    written = done.settings.directional_pages
    out = {"pages": written, "extension": DIRECTIONAL_EXTENSION if written else None,
           "reason": done.plan.stages.get("directional", "")}
    if written:
        out.update({"aim_rmse_estimate": done.tally.aim_rmse(),
                    "png_bytes": sum(len(p.direction_png or b"") for p in pages),
                    "lightmap_png_bytes": sum(len(p.png) for p in pages)})
    return out


def gi_report(tally) -> dict:
    """What ``--method gi``'s paths did: how many were traced, their rays, and how many were
    cut at ``MAX_BOUNCES`` (their share of the light is lost: at most a_max^(B−1) of what each
    would still gather)."""
    return {"paths": tally.gi_paths, "rays": tally.gi_rays, "max_bounces": MAX_BOUNCES,
            "paths_capped": tally.gi_capped}


def carried(done) -> Lightmaps:
    """The pages the carrier stores: the irradiance (moz, occlusion), or the radiance the lit
    surfaces send out (emissive, ``image/carriers.py``)."""
    if done.settings.carrier != "emissive":
        return done.lightmaps
    return emissive_lightmaps(done.scene, done.world, done.atlas, done.coverage, done.lightmaps,
                              done.settings.padding,
                              done.direct if done.settings.baked_lights == "keep" else None)


def gi_notes(done) -> list[str]:
    """A report note when ``--method gi`` cut paths at its bounce cap (its light is then low)."""
    capped = done.tally.gi_capped
    return ([f"--method gi: {capped:,} paths were still going after {MAX_BOUNCES} bounces and were "
             "cut there, so the indirect light is low (albedos of 1 with nothing escaping?)"]
            if capped else [])


def target_notes(done, pages) -> list[str]:
    """A report note when ``--target-error`` E was not met: the bake's estimated RMSE is above
    E (a texel stops when twice its predicted error is within E, so a bake that meets E
    estimates about E/2 or less). Its rays stopped at ``--max-rays`` first; E is in lightmap
    units, which the pages' peaks put in scale."""
    target = done.settings.target_error
    rmse = done.rmse_estimate()
    if target is None or rmse <= target:
        return []
    peak = max((page.peak for page in pages), default=0.0)
    return [f"--target-error {target:g} was not met: the estimated RMSE is {rmse:.4g}, as "
            f"texels reached --max-rays {done.settings.max_rays} first; raise --max-rays, or "
            f"give a target in scale with the lightmap (its pages peak at {peak:.4g})"]


def clipping_notes(pages) -> list[str]:
    """One report note per page whose intensity (a percentile, encode.py) clips texels."""
    return [f"lightmap page {p}: {page.clipped:.2%} of its texels are brighter than its scale "
            f"{page.intensity:.4g} (the MOZ_lightmap intensity, the emissive strength; peak "
            f"{page.peak:.4g}) and clip to it; "
            "--clip-percentile 100 scales to the peak, --lightmaps DIR --format exr keeps floats"
            for p, page in enumerate(pages) if page.clipped > 0]


def write_page_files(folder: Path, stem: str, pages, light=None, format: str = "png",
                     write: Callable[[Path, bytes], None] = write_atomically) -> list[Path]:
    """Write each lightmap page as ``<stem>_lightmap_<p>.<format>`` in the existing ``folder``
    with ``write(path, bytes)``: the embedded PNG, or with ``light`` (P, H, W, 3) the float page
    as .hdr or .exr."""
    paths = []
    for p, page in enumerate(pages):
        path = folder / f"{stem}_lightmap_{p}.{format}"
        write(path, page_file(None if light is None else light[p], page.png, format))
        paths.append(path)
    return paths


def bake_or_rebake(scene: Scene, settings: Settings, state_path, incremental: bool | str,
                   quiet: bool = True, relight: bool = False, spill_folder=None, staging=None):
    """(``pipeline.full.Computed``, Rebaked | str | None): a rebake from the state at ``state_path`` when
    ``incremental`` and it can follow, else a full bake and the one-line reason (a str), or None
    when no rebake was asked for. ``relight``: only a recomposition (light colours and
    intensities) may follow; anything else raises InputError before any ray is cast. A
    relight casts no ray, so the last bakes' times never price it out (``rebake.cost``).
    ``spill_folder``: where a full bake keeps its texels' results until the state is written
    (``pipeline.full.compute``); ``staging``: where the bake state is written (``rebake.staging.StateStaging``)."""
    if not incremental and not relight:
        return compute(scene, settings, quiet, spill_folder, staging), None
    scene.check_not_a_bake()  # as compute does, before the state is read
    prepared = None
    if state_path is None:
        reason = "no bake state (state=False)"
    else:
        try:
            rebaked = rebake(scene, settings, state_path, quiet, relight, staging,
                             priced=incremental != "always" and not relight)
            return rebaked.computed, rebaked
        except FullBake as why:  # keeping what the rebake kept (a derived d_max) and made
            reason, settings, prepared = str(why), why.settings or settings, why.prepared
            if staging is not None:
                staging.asked = settings
    if relight:
        raise InputError(f"cannot relight without tracing: {reason}", file=str(scene.path),
                         fix="use `baker bake` (it rebakes only what changed)")
    return compute(scene, settings, quiet, spill_folder, staging, prepared), reason
