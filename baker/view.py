"""``baker view OUT.glb``: the baked file in a browser, served from this machine.

A small HTTP server bound to 127.0.0.1 serves a page (``view_static/``: three.js 0.187 from its
npm package, minified, with its licence; our MOZ_lightmap GLTFLoader plugin; the viewer) and the
file itself; nothing is fetched from the internet. The page shows the file as three.js shows it
to anyone who opens it (diffuse colour × lightmap / π + emission), with orbit controls and
toggles: lightmap on/off, lightmap only, texel checker, exposure.

Routes: ``/`` the page, ``/<static file>``, ``/model/<name>`` the file and, beside it, the files
it names by relative URI (``.bin``, images; nothing outside its folder), and ``/info.json``: the
file's name and address, its carrier (``asset.extras.baker.carrier``) and the exposure ``baker
preview`` picks for it, the page's starting exposure.
"""

from __future__ import annotations

import json
import threading
from functools import partial
from http import HTTPStatus
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import quote, unquote

from baker.errors import InputError, OutputError
from baker.gltf.load import load
from baker.run.atomic import write_atomically

STATIC = Path(__file__).resolve().parent / "view_static"
PLUGIN = "moz_lightmap.js"  # the GLTFLoader plugin: MOZ_lightmap and directional pages
_PREVIEW_SIZE = (160, 120)  # pixels of the preview that sets the starting exposure
_TYPES = {".js": "text/javascript", ".html": "text/html; charset=utf-8",
          ".json": "application/json", ".glb": "model/gltf-binary", ".gltf": "model/gltf+json"}


def page_info(path: Path) -> dict:
    """What ``/info.json`` says of the baked file at ``path``.

    Raises InputError (naming the file) when it cannot be read as glTF or holds no bake.
    """
    from baker.preview import render  # late: preview builds an Embree scene

    scene = load(path)
    picture = render(scene, "lit", _PREVIEW_SIZE)  # InputError when nothing is baked
    return {"name": path.name, "model": "model/" + quote(path.name),
            "carrier": (scene.recorded_bake() or {}).get("carrier") or "moz",
            "exposure": picture.exposure}


class _Handler(SimpleHTTPRequestHandler):
    """Static files from ``STATIC``, the model's folder under ``/model/``, and ``/info.json``;
    quiet."""

    def __init__(self, *args, folder: Path, info: bytes, **kwargs):
        self.folder, self.info = folder, info
        super().__init__(*args, directory=str(STATIC), **kwargs)

    def do_GET(self) -> None:  # noqa: N802 (http.server's name)
        route = unquote(self.path.split("?", 1)[0])
        if route == "/info.json":
            return self._send(self.info, _TYPES[".json"])
        if route.startswith("/model/"):
            file = (self.folder / route[len("/model/"):]).resolve()
            if not file.is_file() or not file.is_relative_to(self.folder):
                return self.send_error(HTTPStatus.NOT_FOUND)
            return self._send(file.read_bytes(), self.guess_type(str(file)))
        if route.startswith("/bundle") or route.endswith(".md"):
            return self.send_error(HTTPStatus.NOT_FOUND)
        return super().do_GET()

    def guess_type(self, path) -> str:
        return _TYPES.get(Path(str(path)).suffix, super().guess_type(path))

    def _send(self, body: bytes, kind: str) -> None:
        self.send_response(HTTPStatus.OK)
        self.send_header("Content-Type", kind)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, format, *args) -> None:
        pass


def serve(path: str | Path, port: int = 0) -> ThreadingHTTPServer:
    """A server for the baked file at ``path`` on 127.0.0.1:``port`` (0: a free port), not yet
    serving: call ``serve_forever`` (or use ``start``). Its address is ``server_address``."""
    path = Path(path)
    if not path.is_file():
        raise InputError("the file does not exist", file=str(path),
                         fix="give the baked .glb or .gltf that baker bake wrote")
    info = page_info(path)
    handler = partial(_Handler, folder=path.resolve().parent, info=json.dumps(info).encode())
    return ThreadingHTTPServer(("127.0.0.1", port), handler)


def start(path: str | Path, port: int = 0) -> tuple[ThreadingHTTPServer, str]:
    """``serve`` in a daemon thread; returns the server (``shutdown()`` stops it) and its URL."""
    server = serve(path, port)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, url_of(server)


def url_of(server: ThreadingHTTPServer) -> str:
    """The page's address."""
    host, port = server.server_address[:2]
    return f"http://{host}:{port}/"


def write_plugin(folder: str | Path) -> Path:
    """Write baker's three.js GLTFLoader plugin (``PLUGIN``: the moz carrier's MOZ_lightmap and
    the directional pages; it imports "three") into ``folder``, made if missing, for an app
    of the user's own (docs/viewers.md); returns the file's path."""
    target = Path(folder) / PLUGIN
    if Path(folder).exists() and not Path(folder).is_dir():
        raise OutputError("is a file, not a folder", file=str(folder),
                          fix="give a folder (it is made if missing)")
    Path(folder).mkdir(parents=True, exist_ok=True)
    write_atomically(target, (STATIC / PLUGIN).read_bytes())
    return target
