"""``baker view``'s server (issue 20): 127.0.0.1 only, the page and everything it imports shipped
with baker, the file and its neighbours and nothing else, clean errors for bad input.
What the page draws is tests/test_browser.py's."""

from __future__ import annotations

import json
import re
import urllib.error
import urllib.request

import pytest

import baker
from assets.make_scenes import cornell_box, open_plane
from baker.cli.main import main
from baker.errors import InputError
from baker.gltf.load import load
from baker.preview import render
from baker.view import STATIC, page_info, start
from tests.bakehelp import saved


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    folder = tmp_path_factory.mktemp("view")
    out = folder / "room baked.glb"
    baker.bake(saved(cornell_box(), folder), out, baker.Settings(texel_density=6, rays=8),
               state=False)
    (folder / "secret.txt").write_text("not for the page")
    server, url = start(out)
    yield out, url
    server.shutdown()
    server.server_close()


def _get(url: str) -> tuple[int, bytes, str]:
    try:
        with urllib.request.urlopen(url, timeout=10) as response:
            return response.status, response.read(), response.headers["Content-Type"]
    except urllib.error.HTTPError as error:
        return error.code, b"", ""


def test_serves_the_page_the_file_and_its_exposure_on_localhost(served):
    out, url = served
    assert url.startswith("http://127.0.0.1:")
    status, page, kind = _get(url)
    assert status == 200 and b'src="viewer.js"' in page and kind.startswith("text/html")
    info = json.loads(_get(url + "info.json")[1])
    assert info["carrier"] == "emissive" and info["name"] == out.name  # the default
    assert info["exposure"] == render(load(out), "lit", (160, 120)).exposure
    status, body, kind = _get(url + info["model"])
    assert status == 200 and body == out.read_bytes() and kind == "model/gltf-binary"


def test_nothing_outside_the_package_and_the_files_folder(served):
    out, url = served
    for path in ("model/secret.txt", "model/../view.py", "model/%2e%2e/view.py"):
        status, body, _ = _get(url + path)
        assert status == 200 if path == "model/secret.txt" else status == 404, path
    assert _get(url + "bundle/package.json")[0] == 404  # the recipe is not served


def test_the_page_imports_only_shipped_files():
    """Every import of the page's modules is a relative path to a file in view_static or
    "three", which the page's import map makes the shipped bundle (nothing is fetched from
    the internet; the plugin imports "three" so that it works in a user's own app too), and
    three.js's licence ships beside it."""
    page = (STATIC / "index.html").read_text()
    (mapped,) = re.findall(r'"three":\s*"\./([^"]+)"', page)
    assert (STATIC / mapped).is_file()
    for script in ("viewer.js", "moz_lightmap.js"):
        text = (STATIC / script).read_text()
        for target in re.findall(r"^import\b[^;]*?\bfrom\s+'([^']+)'", text, flags=re.M):
            assert target == "three" or (target.startswith("./")
                                         and (STATIC / target[2:]).is_file()), target
    bundle = (STATIC / "three.min.js").read_text()
    assert not re.search(r"\bimport\s*[\w{}*,\s]*from\s*[\"']", bundle)  # self-contained
    assert "MIT License" in (STATIC / "three.LICENSE").read_text()


def test_bad_input_is_a_clean_error(tmp_path, capsys):
    assert main(["view", str(tmp_path / "missing.glb")]) == 1
    assert "does not exist" in capsys.readouterr().err
    unbaked = saved(open_plane(), tmp_path)
    with pytest.raises(InputError, match="no lightmap"):
        page_info(unbaked)
    assert main(["view", str(unbaked)]) == 1
    assert "bake it first" in capsys.readouterr().err


def test_a_gltf_is_served_with_its_buffer(tmp_path):
    """A .gltf output names its .bin by relative URI: the page's loader finds it beside it."""
    out = tmp_path / "room.gltf"
    baker.bake(saved(cornell_box(), tmp_path), out, baker.Settings(texel_density=4, rays=4),
               state=False)
    server, url = start(out)
    try:
        info = json.loads(_get(url + "info.json")[1])
        status, body, kind = _get(url + info["model"])
        assert status == 200 and kind == "model/gltf+json"
        uri = json.loads(body)["buffers"][0]["uri"]
        status, blob, _ = _get(url + "model/" + uri)
        assert status == 200 and blob == (tmp_path / uri).read_bytes()
    finally:
        server.shutdown()
        server.server_close()
