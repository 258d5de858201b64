"""``baker plugin DIR``: write the three.js loader plugin for the moz carrier into an app."""

from __future__ import annotations

import argparse
from pathlib import Path

from baker.cli.common import add_debug

EPILOG = """examples:
  baker plugin src/                          (writes src/moz_lightmap.js)

In your app (three.js r151 or later):
  import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
  import { MozLightmapPlugin } from './moz_lightmap.js';
  const loader = new GLTFLoader().register((parser) => new MozLightmapPlugin(parser));

It reads MOZ_lightmap (--carrier moz) and the directional pages (--directional); the default
carrier (emissive) needs no plugin. docs/viewers.md has the other engines.
"""


def add_parser(commands) -> None:
    """Register ``plugin`` on the ``baker`` command's subparsers."""
    parser = commands.add_parser(
        "plugin", help="write the three.js loader plugin for the moz carrier into a folder",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Write moz_lightmap.js, baker's three.js GLTFLoader plugin, into DIR.")
    parser.set_defaults(run=run)
    parser.add_argument("folder", type=Path, metavar="DIR", help="where to write it (made if "
                                                                 "missing)")
    add_debug(parser)


def run(args: argparse.Namespace) -> int:
    """Write the plugin; exit code 0."""
    from baker.view import write_plugin

    print(f"wrote {write_plugin(args.folder)}")
    return 0
