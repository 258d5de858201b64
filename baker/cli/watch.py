"""``baker watch``: rebake a scene whenever its file, or a file it uses, changes, until Ctrl-C."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import baker
from baker.cli.state import print_rebake, settings_for


def add_parser(commands) -> None:
    """Register ``watch`` on the ``baker`` command's subparsers (the bake's settings options
    are those of ``baker bake``: the defaults, or the ones given here)."""
    parser = commands.add_parser(
        "watch", help="rebake a scene each time its file changes (Ctrl-C stops)",
        description="Bake SCENE into OUTPUT, then watch the modification times of SCENE and "
                    "of the files it uses (.bin, images) and rebake incrementally (from "
                    "OUTPUT.bake) each time one changes. Ctrl-C ends it.")
    parser.set_defaults(run=run)
    parser.add_argument("scene", type=Path, help="the scene to watch, .glb or .gltf")
    parser.add_argument("-o", "--output", type=Path, required=True, help="the baked scene")
    parser.add_argument("--interval", type=float, default=1.0, metavar="SECONDS",
                        help="how often to look at the file (default 1 s)")
    parser.add_argument("--rays", type=int, default=baker.Settings().rays,
                        help="obscurance rays per texel (when OUTPUT has no bake state; with "
                             "one, the settings of the bake that wrote it)")
    parser.add_argument("--page-size", type=int, default=baker.Settings().page_size,
                        metavar="TEXELS", help="largest lightmap page side")
    parser.add_argument("--threads", type=int, default=0, help="ray-casting threads")
    parser.add_argument("--max-bakes", type=int, default=0, help=argparse.SUPPRESS)  # tests
    parser.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                        help="show the traceback of an error")


class _Watched:
    """The files a bake of ``scene`` reads (the scene, its .bin, its images:
    ``gltf.container.used_uris``), listed again whenever the scene file itself changes; ``stamp()``
    changes when any of them does (its modification time or size), or is None while the scene
    file is missing."""

    def __init__(self, scene: Path):
        self._scene, self._seen, self._uris = scene, None, []

    def stamp(self) -> tuple | None:
        from baker.gltf.container import file_stamps, used_uris

        stamps = file_stamps(self._scene, self._uris)
        if stamps[0] is None:
            return None
        if stamps[0] != self._seen:
            self._seen, self._uris = stamps[0], used_uris(self._scene)
            stamps = file_stamps(self._scene, self._uris)
        return stamps


def run(args: argparse.Namespace) -> int:
    """Watch and rebake until Ctrl-C, which exits 130 (interrupted), as every subcommand does;
    a bake that fails prints its error and the watch goes on (``--max-bakes``, for tests,
    returns 1 when the last bake failed)."""
    settings = settings_for(args.output, rays=args.rays, page_size=args.page_size,
                            threads=args.threads)
    seen, bakes, failed, watched = None, 0, False, _Watched(args.scene)
    print(f"watching {args.scene} and the files it uses (Ctrl-C to stop)", flush=True)
    try:
        while True:
            stamp = watched.stamp()
            if stamp is not None and stamp != seen:
                seen = stamp
                started = time.perf_counter()
                try:
                    result = baker.bake(args.scene, args.output, settings, incremental=True)
                    print_rebake(result)
                    print(f"baked {args.output} in {time.perf_counter() - started:.2f} s",
                          flush=True)
                    failed = False
                except baker.BakerError as error:
                    print(f"baker: error: {error}", file=sys.stderr, flush=True)
                    failed = True
                bakes += 1
                if args.max_bakes and bakes >= args.max_bakes:
                    return 1 if failed else 0
            time.sleep(args.interval)
    except KeyboardInterrupt:
        print("stopped watching", flush=True)
        return 130
