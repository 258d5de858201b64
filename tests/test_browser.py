"""The bake as real browsers show it (issue 20), each picture against ``baker preview`` from the
same camera at the same exposure, in headless Chromium:
- three.js 0.187 through the page ``baker view`` serves (our MOZ_lightmap plugin);
- Babylon.js 9.28 with its own glTF loader and no code of ours (tests/babylon);
- ``<model-viewer>`` 4.4 with no code of ours (tests/modelviewer), its camera set through its own
  attributes, no image based lighting (a black environment image) but for the occlusion carrier,
  shown under a uniform white sky;
- Hubs: three.js r141 and Hubs' MOZ_lightmap loader extension (tests/hubs).

For every carrier a viewer reads, over the pixels that show a lightmapped surface (one pixel in
from every silhouette, where a rasteriser and a ray caster may see different triangles):
- the log luminances correlate (≥ 0.98) and their median ratio is within 5 % of 1;
- no pixel the preview shows lit (luminance above 1 % of white) is black in the browser.
A carrier a viewer does not read shows nothing of the bake there: every pixel the preview shows
lit is black. Transmissive surfaces are left out of every comparison (viewers draw them with the
scene behind them, the preview with nothing). The moz carrier of the shared scenes (MultiUVTest,
LightsPunctualLamp) lies on metals, whose pictures are mostly their emission: there what the
lightmap adds alone (the viewer's picture less its picture without the lightmap) is compared with
the preview's lightmap term, by the same measures. The Khronos validator finds no error in any
file shown.

Chromium is Debian's package: installed with apt-get when missing and running as root (CI); the
pinned npm packages of each page are installed with ``npm ci`` when missing. The tests are
skipped only where Chromium or npm cannot be had, and say so.
"""

from __future__ import annotations

import dataclasses
import io
import json
import shutil
import threading
from functools import partial
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import baker
from assets.make_scenes import cornell_box
from assets.material_scenes import metal_glass_room
from baker.geometry.surface import LUMINANCE, SRGB_TO_LINEAR
from baker.geometry.world import build_world
from baker.gltf.load import load
from baker.preview import default_view, render, scene_camera
from baker.view import start
from tests.bakehelp import REAL_SCENES, saved

import gltf_validator
from chromium import Browser, find_chromium
from npm_packages import installed

SIZE = (200, 150)
PAGES = Path(__file__).resolve().parent  # tests/<viewer>/page.html and its pinned npm packages
# (scene, carrier) shown through baker view's three.js page. BY_TERM: compared by what the
# lightmap adds alone (``_assert_same_lightmap_term``): the shared scenes' moz carrier lies on
# metals (MultiUVTest's cube; LightsPunctualLamp's stand, metal but where its texture says not),
# whose pictures are mostly their emission, which viewers sample through mipmaps.
# The default carrier (emissive) on the demo, the shared scenes and a room of metals and glass of
# our own (metal_glass: its clear pane keeps the lamp in the file, whose highlights the preview
# draws as three.js does). Not GlassVaseFlowers: at 200 × 150 it has 478 lightmapped pixels
# that no glass covers (too few to compare); with those behind its blended and transmissive
# vases the median ratio is 0.42 (three.js draws a double-sided blended vase's back faces over
# its front, sorted per object, where the preview composites per pixel).
DEFAULT_SCENES = ["cornell", "metal_glass", "MultiUVTest", "LightsPunctualLamp",
                  "NegativeScaleTest"]
CASES = [*((name, "emissive") for name in DEFAULT_SCENES), ("cornell", "moz"),
         ("cornell", "occlusion"), ("MultiUVTest", "moz"),
         pytest.param("LightsPunctualLamp", "moz", marks=pytest.mark.long)]
BY_TERM = {("MultiUVTest", "moz"), ("LightsPunctualLamp", "moz")}


@pytest.fixture(scope="module")
def browser():
    executable = find_chromium()
    if executable is None:
        pytest.skip("no Chromium: Debian's chromium package could not be installed here "
                    "(not root, or no apt-get); CI installs it")
    with Browser(executable) as running:
        yield running


@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    """(scene, carrier) → the baked file, each baked once for the module (about 1 s each)."""
    folder = tmp_path_factory.mktemp("browser")
    sources = {"cornell": saved(cornell_box(), folder, "cornell.glb"),
               "metal_glass": saved(metal_glass_room(), folder, "metal_glass.glb"), **REAL_SCENES}
    done = {}

    def get(name: str, carrier: str):
        if (name, carrier) not in done:
            out = folder / f"{name}_{carrier}.glb"
            density = 8.0 if name in ("cornell", "metal_glass") else 4.0
            baker.bake(sources[name], out, baker.Settings(texel_density=density, rays=16,
                                                          carrier=carrier), state=False)
            report = gltf_validator.validate(out)  # every file shown is valid glTF
            assert not gltf_validator.issue_codes(report, gltf_validator.ERROR), \
                gltf_validator.describe(report, gltf_validator.ERROR)
            done[name, carrier] = out
        return done[name, carrier]

    return get


def _camera_parameter(view) -> str:
    right, up, back = view.axes
    target = view.origin - back
    values = [*view.origin, *target, *up, np.degrees(view.yfov)]
    return ",".join(f"{v:.9g}" for v in values)


def _luminance(rgb: np.ndarray) -> np.ndarray:
    return SRGB_TO_LINEAR[rgb[..., :3]] @ LUMINANCE


def _interior(mask: np.ndarray) -> np.ndarray:
    """``mask`` less every pixel with a 4-neighbour outside it."""
    inner = mask.copy()
    inner[1:] &= mask[:-1]
    inner[:-1] &= mask[1:]
    inner[:, 1:] &= mask[:, :-1]
    inner[:, :-1] &= mask[:, 1:]
    inner[[0, -1]] = False
    inner[:, [0, -1]] = False
    return inner


def _view_and_preview(out: Path):
    """The camera the preview takes of ``out``, and its picture, whose ``lightmapped`` mask
    leaves out transmissive and blended surfaces: both draw the scene behind them, the preview
    composited front to back, viewers by their own means (three.js's transmission pass blurs
    it; blended triangles are sorted per object, not per pixel), so they agree only roughly
    there.
    Its exposure is the preview's automatic one over the pixels left (the 99th percentile of
    their luminance at 0.85), not over the glass left out."""
    scene = load(out)
    world = build_world(scene)
    view = scene_camera(scene) or default_view(world)
    preview = render(scene, "lit", SIZE, view=view, exposure=1.0)
    clear = np.array([m.transmission > 0 or m.diffuse_transmission > 0 or m.alpha_mode == "BLEND"
                      for m in scene.materials])
    seen = preview.triangle >= 0
    see_through = np.zeros_like(seen)
    see_through[seen] = clear[world.tri_material[preview.triangle[seen]]]
    if not see_through.any():
        return view, render(scene, "lit", SIZE, view=view)
    shown = preview.radiance[preview.lightmapped & ~see_through] @ LUMINANCE
    exposure = 0.85 / np.percentile(shown[shown > 0], 99)
    preview = render(scene, "lit", SIZE, view=view, exposure=exposure)
    return view, dataclasses.replace(preview, lightmapped=preview.lightmapped & ~see_through)


def _query(view, exposure: float) -> str:
    return f"size={SIZE[0]}x{SIZE[1]}&exposure={exposure:.9g}&camera={_camera_parameter(view)}"


def _png(data: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))


def _compare(shown: np.ndarray, preview, label: str, folder: Path) -> dict:
    """How the browser's picture ``shown`` compares with the preview's over the lightmapped
    pixels (see the module notes): ``lit`` pixels the preview shows lit, ``black`` of those
    black in the browser, and over the others their median luminance ``ratio`` and log
    ``correlation`` (None when there are none)."""
    Image.fromarray(np.concatenate([shown, preview.rgb], axis=1)).save(
        folder / f"{label}.png")  # browser | preview, to look at
    assert shown.shape == preview.rgb.shape
    pixels = _interior(preview.lightmapped)
    pixels &= (shown.max(axis=-1) < 254) & (preview.rgb.max(axis=-1) < 254)  # not clipped
    assert pixels.sum() >= 500, "too few lightmapped pixels to compare"
    browser_lum, preview_lum = _luminance(shown)[pixels], _luminance(preview.rgb)[pixels]
    lit = preview_lum > 0.01
    both = lit & (browser_lum > 0.002)
    found = {"lit": int(lit.sum()), "black": int(np.count_nonzero(lit & ~both)), "ratio": None,
             "correlation": None, "brightest": float(browser_lum.max())}
    if both.any():
        found["ratio"] = float(np.median(browser_lum[both] / preview_lum[both]))
        found["correlation"] = float(np.corrcoef(np.log(browser_lum[both]),
                                                 np.log(preview_lum[both]))[0, 1])
    print(f"{label}: {found}")
    return found


def _assert_same(shown: np.ndarray, preview, label: str, folder: Path) -> None:
    found = _compare(shown, preview, label, folder)
    assert found["black"] == 0, f"{found['black']} lit pixels black in the browser"
    if found["ratio"] is None:  # nothing the viewer shows lit (metal under moz): black in both
        assert found["brightest"] < 0.01
        return
    assert abs(found["ratio"] - 1) <= 0.05, found
    assert found["correlation"] >= 0.98, found


def _assert_shows_nothing(shown: np.ndarray, preview, label: str, folder: Path) -> None:
    """A carrier the viewer does not read: every pixel the preview shows lit is black."""
    found = _compare(shown, preview, label, folder)
    assert found["lit"] > 1000 and found["black"] == found["lit"], found


def _assert_same_lightmap_term(with_map: np.ndarray, without_map: np.ndarray, preview,
                               label: str, folder: Path) -> None:
    """What the lightmap adds, alone: the viewer's picture less its picture without the
    lightmap (linear luminance, both unclipped) against the preview's ``from_lightmap`` at its
    exposure, over the lightmapped pixels. Emission cancels out of the viewer's difference,
    and with it how a viewer samples an emissive texture (through mipmaps: MultiUVTest's logos
    and LightsPunctualLamp's stand, whose emission is most of what shows). Where the preview's
    term is lit (above 1 % of white) the viewer's must be too, within 5 % (median ratio) and
    correlated (≥ 0.98 in log). Where no term is lit (a metal), the viewer's is dark too but on
    at most 10 % of the pixels: LightsPunctualLamp's stand is metal but for some texels of its
    metallic texture, which three.js samples through mipmaps (measured: 28 of its 1,443 pixels
    lit, by up to 9 % of white, with xatlas's atlas; 82 with this round's charts, whose
    lightmap texels on the stand are more), where the preview's term is dark everywhere)."""
    _compare(with_map, preview, label, folder)  # printed: what the whole pictures do
    pixels = _interior(preview.lightmapped)
    pixels &= (with_map.max(axis=-1) < 254) & (without_map.max(axis=-1) < 254)
    assert pixels.sum() >= 500, "too few lightmapped pixels to compare"
    viewer = (_luminance(with_map) - _luminance(without_map))[pixels]
    expected = np.minimum((preview.from_lightmap @ LUMINANCE)[pixels] * preview.exposure, 1.0)
    lit = expected > 0.01
    both = lit & (viewer > 0.002)
    found = {"pixels": int(pixels.sum()), "lit": int(lit.sum()),
             "black": int(np.count_nonzero(lit & ~both)), "viewer lit": int((viewer > 0.01).sum()),
             "viewer median": float(np.median(viewer)), "viewer brightest": float(viewer.max())}
    if both.any():
        found["ratio"] = float(np.median(viewer[both] / expected[both]))
        found["correlation"] = float(np.corrcoef(np.log(viewer[both]),
                                                 np.log(expected[both]))[0, 1])
    print(f"{label}, the lightmap's term: {found}")
    if not lit.any():
        assert found["viewer lit"] <= 0.10 * found["pixels"], found
        return
    assert found["black"] == 0, found
    assert abs(found["ratio"] - 1) <= 0.05 and found["correlation"] >= 0.98, found


@pytest.mark.parametrize("name, carrier", CASES)
def test_three_js_shows_what_the_preview_shows(browser, baked, name, carrier, tmp_path):
    out = baked(name, carrier)
    view, preview = _view_and_preview(out)
    server, url = start(out)
    page = f"{url}?bare=1&{_query(view, preview.exposure)}"
    try:
        shown = _png(browser.canvas_png(page))
        without = _png(browser.canvas_png(page, _click("lightmap"))) \
            if (name, carrier) in BY_TERM else None
    finally:
        server.shutdown()
        server.server_close()
    label = f"three.js {name} {carrier}"
    if without is None:
        _assert_same(shown, preview, label, tmp_path)
    else:
        _assert_same_lightmap_term(shown, without, preview, label, tmp_path)


def _write_skies(folder: Path) -> None:
    """black.hdr and white.hdr in ``folder``: uniform equirectangular Radiance images of
    radiance 0 and 1 (flat RGBE pixels; 256 × 128, as smaller ones filter to black in three.js's
    PMREM) for tests/modelviewer/page.html."""
    header = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 128 +X 256\n"
    for name, rgbe in (("black", (0, 0, 0, 0)), ("white", (128, 128, 128, 129))):
        (folder / f"{name}.hdr").write_bytes(header + bytes(rgbe) * (256 * 128))


def _served_page(tmp_path_factory, viewer: str, skies: bool = False):
    """The address of tests/<viewer>/page.html served on 127.0.0.1 from a folder holding a copy
    of the page and its scripts and a link to its pinned npm packages (``npm ci --prefix
    tests/<viewer>`` when one of them is missing), and the folder, where ``model`` links to the
    folder of the file to show (``_viewer_picture``), and the ``skies`` when asked for. A
    generator: the fixture's body."""
    source = PAGES / viewer
    wanted = json.loads((source / "package.json").read_text())["dependencies"]
    if not installed(source, [Path(name) for name in wanted]):
        pytest.skip(f"no npm: {', '.join(wanted)} cannot be installed (the README's test "
                    "command needs Node.js and npm)")
    folder = tmp_path_factory.mktemp(viewer)
    for script in [source / "page.html", *source.glob("*.js")]:
        shutil.copy(script, folder)
    (folder / "node_modules").symlink_to(source / "node_modules", target_is_directory=True)
    if skies:
        _write_skies(folder)
    server = ThreadingHTTPServer(("127.0.0.1", 0), partial(_QuietFiles, directory=str(folder)))
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield f"http://127.0.0.1:{server.server_address[1]}/page.html", folder
    server.shutdown()
    server.server_close()


@pytest.fixture(scope="module")
def babylon(tmp_path_factory):
    yield from _served_page(tmp_path_factory, "babylon")


@pytest.fixture(scope="module")
def model_viewer(tmp_path_factory):
    yield from _served_page(tmp_path_factory, "modelviewer", skies=True)


@pytest.fixture(scope="module")
def hubs(tmp_path_factory):
    yield from _served_page(tmp_path_factory, "hubs")


class _QuietFiles(SimpleHTTPRequestHandler):
    def log_message(self, format, *args) -> None:
        pass


def _viewer_picture(browser, page, out: Path, view, exposure: float,
                    extra: str = "") -> np.ndarray:
    """A served page's picture of ``out``, served from its own folder (with the images beside
    it); ``extra`` adds URL parameters."""
    url, folder = page
    served = folder / "model"
    if served.is_symlink():
        served.unlink()
    served.symlink_to(out.parent, target_is_directory=True)
    return _png(browser.canvas_png(
        f"{url}?model=model/{out.name}&{_query(view, exposure)}{extra}", timeout=60.0))


@pytest.mark.parametrize("name", DEFAULT_SCENES)
def test_babylon_shows_the_emissive_carrier(browser, baked, babylon, name, tmp_path):
    """Babylon.js 9.28 with its own glTF loader and no code of ours shows the emissive carrier
    as the preview does."""
    out = baked(name, "emissive")
    view, preview = _view_and_preview(out)
    _assert_same(_viewer_picture(browser, babylon, out, view, preview.exposure), preview,
                 f"Babylon {name} emissive", tmp_path)


@pytest.mark.parametrize("carrier", ["emissive", "occlusion"])
def test_model_viewer_shows_what_the_preview_shows(browser, baked, model_viewer, carrier,
                                                   tmp_path):
    """<model-viewer> 4.4 with no code of ours shows the emissive carrier with no environment,
    and the occlusion carrier under a uniform sky of radiance 1: there a diffuse surface sends
    albedo × visibility, π times what the preview shades (visibility as a lightmap of
    intensity 1, diffuse colour × V / π), so it is shown at the preview's exposure / π. (Its
    loader is three.js's GLTFLoader, which the three.js cases measure on the shared scenes.)"""
    out = baked("cornell", carrier)
    view, preview = _view_and_preview(out)
    sky = "white" if carrier == "occlusion" else "black"
    exposure = preview.exposure / (np.pi if carrier == "occlusion" else 1.0)
    shown = _viewer_picture(browser, model_viewer, out, view, exposure, f"&environment={sky}")
    _assert_same(shown, preview, f"model-viewer cornell {carrier}", tmp_path)


@pytest.mark.parametrize("name", [pytest.param("cornell", marks=pytest.mark.long),
                                  "metal_glass"])
def test_model_viewer_s_own_lighting_adds_reflections_to_the_default(browser, baked,
                                                                      model_viewer, name,
                                                                      tmp_path):
    """<model-viewer>'s own default lighting ("neutral", a studio environment) on the default
    carrier: the bake shows whole (no lit pixel black) and the environment only adds its
    reflections to it (the copies keep their specular response, not their diffuse one): the
    median ratio to the preview is at least 1 (measured 1.34 on the Cornell room, whose light
    is dim beside the studio's at this exposure; 1.09 on the room of metals and glass), the
    log correlation ≥ 0.97 (0.979, 0.984)."""
    out = baked(name, "emissive")
    view, preview = _view_and_preview(out)
    shown = _viewer_picture(browser, model_viewer, out, view, preview.exposure,
                            "&environment=neutral")
    found = _compare(shown, preview, f"model-viewer {name} neutral", tmp_path)
    assert found["black"] == 0 and found["ratio"] >= 0.99, found
    assert found["correlation"] >= 0.97, found


@pytest.mark.parametrize("viewer", ["babylon", "model_viewer"])
def test_viewers_without_moz_lightmap_show_nothing_of_it(browser, baked, viewer, request,
                                                         tmp_path):
    """Babylon's loader and model-viewer's read no lightmap extension: every surface the
    preview shows lit by the moz carrier is black there, with no environment (docs/output.md
    says so; this test notices if that changes)."""
    out = baked("cornell", "moz")
    view, preview = _view_and_preview(out)
    shown = _viewer_picture(browser, request.getfixturevalue(viewer), out, view,
                            preview.exposure, "&environment=black")
    _assert_shows_nothing(shown, preview, f"{viewer} cornell moz", tmp_path)


@pytest.mark.parametrize("name", ["cornell", "MultiUVTest",
                                  pytest.param("LightsPunctualLamp", marks=pytest.mark.long)])
def test_hubs_shows_the_moz_carrier(browser, baked, hubs, name, tmp_path):
    """three.js r141 with Hubs' MOZ_lightmap loader extension (TEXCOORD_1, linear texels) shows
    the moz carrier as the preview does (on the shared scenes: what the lightmap adds alone)."""
    out = baked(name, "moz")
    view, preview = _view_and_preview(out)
    shown = _viewer_picture(browser, hubs, out, view, preview.exposure)
    label = f"Hubs {name} moz"
    if (name, "moz") not in BY_TERM:
        _assert_same(shown, preview, label, tmp_path)
        return
    without = _viewer_picture(browser, hubs, out, view, preview.exposure, "&lightmap=off")
    _assert_same_lightmap_term(shown, without, preview, label, tmp_path)


def _click(element: str) -> str:
    """JavaScript that toggles the page's checkbox ``element`` as a click does."""
    return (f"(() => {{ const box = document.getElementById('{element}'); box.checked = "
            "!box.checked; box.dispatchEvent(new Event('change')); })()")


def test_the_page_toggles_change_what_three_js_draws(browser, baked):
    """Lightmap off: only the lamp's emission is left (the baked surfaces go black); lightmap
    only: the red wall turns grey (the lightmap on white); checker: the floor is a checker of
    two shades whose squares are texels."""
    out = baked("cornell", "moz")
    scene = load(out)
    view = default_view(build_world(scene))
    preview = render(scene, "lit", SIZE, view=view)
    server, url = start(out)
    page = (f"{url}?bare=1&size={SIZE[0]}x{SIZE[1]}&exposure={preview.exposure:.9g}"
            f"&camera={_camera_parameter(view)}")
    try:
        pictures = {name: np.asarray(Image.open(io.BytesIO(browser.canvas_png(
            page, "" if name == "lit" else _click(name)))).convert("RGB")).astype(float)
            for name in ("lit", "lightmap", "only", "checker")}
    finally:
        server.shutdown()
        server.server_close()
    pixels = _interior(preview.lightmapped)
    emitting = (preview.radiance @ LUMINANCE) > 1.0  # the lamp's own pixels, if seen
    dark = pixels & ~emitting
    assert pictures["lit"][dark].mean() > 40
    assert pictures["lightmap"][dark].max() < 8  # nothing but the bake lit them
    lit, only = pictures["lit"][pixels], pictures["only"][pixels]
    red = lit[:, 0] > 1.5 * lit[:, 1]  # the red wall, lit
    assert red.sum() > 100
    assert np.all(np.abs(only[red, 0] - only[red, 1]) < 0.35 * only[red, 0])  # grey now
    shades = np.unique(pictures["checker"][dark].round(-1), axis=0)
    assert len(shades) >= 2 and not np.array_equal(pictures["checker"], pictures["lit"])


@pytest.mark.parametrize("release, reads_texcoord", [("three-r150", False), ("three-r151", True)])
def test_three_js_shows_the_default_carrier_from_r151_on(browser, baked, hubs, release,
                                                         reads_texcoord, tmp_path):
    """The default carrier binds its page to the lightmap UVs (TEXCOORD_1) through the
    emissiveTexture's texCoord. three.js's GLTFLoader reads a texture's texCoord from r151 on
    (``texture.channel``); r150 and before (Hubs' r141 among them) read every map but the
    occlusion and light maps on TEXCOORD_0, so the bake lands on the wrong UVs there
    (docs/viewers.md says which to use: the moz carrier for Hubs)."""
    out = baked("cornell", "emissive")
    view, preview = _view_and_preview(out)
    shown = _viewer_picture(browser, hubs, out, view, preview.exposure,
                            f"&three={release}&lightmap=off")
    label = f"three.js {release} cornell emissive"
    if reads_texcoord:
        _assert_same(shown, preview, label, tmp_path)
        return
    found = _compare(shown, preview, label, tmp_path)
    assert found["correlation"] is None or found["correlation"] < 0.9, found


def test_baker_s_plugin_in_an_app_of_one_s_own_shows_the_moz_carrier(browser, baked, hubs,
                                                                     tmp_path):
    """The steps docs/viewers.md gives a three.js developer: ``baker plugin DIR`` writes
    moz_lightmap.js, which an app on three.js from npm (0.187 here) registers on its
    GLTFLoader; the moz carrier then shows as the preview shows it."""
    from baker.cli.main import main

    url, folder = hubs
    assert main(["plugin", str(folder)]) == 0 and (folder / "moz_lightmap.js").is_file()
    out = baked("cornell", "moz")
    view, preview = _view_and_preview(out)
    shown = _viewer_picture(browser, hubs, out, view, preview.exposure,
                            "&three=three-r187&plugin=baker")
    _assert_same(shown, preview, "three.js 0.187 app + baker plugin cornell moz", tmp_path)


def test_hubs_reads_the_moz_texels_as_linear(browser, baked, hubs, tmp_path):
    """Which encoding each MOZ_lightmap reader expects, side by side: Hubs' loader reads a texel
    as texel/255 (linear: ``_assert_same`` on the default, test_hubs_shows_the_moz_carrier), so
    a bake encoded as the extension text says (``--encoding srgb``) shows too bright there
    (measured 2.8× by issue 43), while baker's plugin reads the encoding the file records and
    shows both right (baker view's page: test_three_js_shows_what_the_preview_shows)."""
    source = tmp_path / "cornell.glb"
    cornell_box().save(source)
    out = tmp_path / "srgb.glb"
    baker.bake(source, out, baker.Settings(texel_density=8.0, rays=16, carrier="moz",
                                           encoding="srgb"), state=False)
    view, preview = _view_and_preview(out)
    found = _compare(_viewer_picture(browser, hubs, out, view, preview.exposure), preview,
                     "Hubs cornell moz srgb", tmp_path)
    assert found["ratio"] > 1.5, found
    server, url = start(out)
    try:
        shown = _png(browser.canvas_png(f"{url}?bare=1&{_query(view, preview.exposure)}"))
    finally:
        server.shutdown()
        server.server_close()
    _assert_same(shown, preview, "three.js + plugin cornell moz srgb", tmp_path)


def test_babylon_shows_a_specular_glossiness_scene_as_the_preview(browser, babylon, tmp_path):
    """The demo room with every material in KHR_materials_pbrSpecularGlossiness, which
    Babylon.js reads in place of the core terms: its emissive copies (the diffuse black in the
    extension too, KHR_materials_emissive_strength beside it) show as the preview shows them;
    lit by an app's own light as well (white, from every side), they gain only its specular
    reflection (F0 0.04, rough: 6 % measured), not a second diffuse. With the copies' diffuse
    left in the extension, Babylon's picture was off the preview by more than 5 % unlit and
    clipped white lit."""
    b = cornell_box()
    for material in b._materials:
        material.extensions = {**(material.extensions or {}),
                               "KHR_materials_pbrSpecularGlossiness": {
                                   "diffuseFactor": list(material.pbrMetallicRoughness
                                                         .baseColorFactor),
                                   "specularFactor": [0.04] * 3, "glossinessFactor": 0.0}}
    b._extensions_used.add("KHR_materials_pbrSpecularGlossiness")
    out = tmp_path / "spec_gloss_emissive.glb"
    baker.bake(saved(b, tmp_path, "spec_gloss.glb"), out,
               baker.Settings(texel_density=8.0, rays=16), state=False)
    view, preview = _view_and_preview(out)
    shown = _viewer_picture(browser, babylon, out, view, preview.exposure)
    _assert_same(shown, preview, "Babylon specular-glossiness emissive", tmp_path)
    lit = _viewer_picture(browser, babylon, out, view, preview.exposure, "&light=1")
    found = _compare(lit, dataclasses.replace(preview, rgb=shown), "Babylon specular-glossiness"
                     " emissive, lit by the app", tmp_path)
    assert found["black"] == 0 and 1.0 <= found["ratio"] <= 1.15, found
    assert found["correlation"] >= 0.98, found
