"""``baker view``: open a baked glTF in a browser page served from this machine (three.js)."""

from __future__ import annotations

import argparse
import webbrowser
from pathlib import Path

from baker.cli.common import add_debug

EPILOG = """examples:
  baker view level_baked.glb                 (prints the address; open it in a browser)
  baker view level_baked.glb --open --port 8123

The page (three.js and baker's MOZ_lightmap plugin, shipped with baker; nothing is fetched from
the internet) shows the file as three.js shows it, with orbit controls (drag, wheel) and
toggles: lightmap on/off, lightmap only, texel checker, exposure. Ctrl-C stops the server.
"""


def add_parser(commands) -> None:
    """Register ``view`` and its options on the ``baker`` command's subparsers."""
    parser = commands.add_parser(
        "view", help="show a baked scene in a local browser page", epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Serve a baked glTF and a three.js page that shows it from 127.0.0.1.")
    parser.set_defaults(run=run)
    parser.add_argument("scene", type=Path, help="the baked scene, .glb or .gltf")
    parser.add_argument("--port", type=int, default=0,
                        help="the port on 127.0.0.1 (default: a free one)")
    parser.add_argument("--open", action="store_true",
                        help="also open the page in the default browser")
    add_debug(parser)


def run(args: argparse.Namespace) -> int:
    """Serve until Ctrl-C (which main turns into exit code 130)."""
    from baker.view import serve, url_of

    server = serve(args.scene, args.port)
    url = url_of(server)
    print(f"baker view: {args.scene} at {url} (Ctrl-C stops)", flush=True)
    if args.open:
        webbrowser.open(url)
    with server:
        server.serve_forever()
    return 0
