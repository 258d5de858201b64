"""``baker hook``: bake every glTF file given (a pre-commit hook), each into ``<stem>_baked``.

Used by ``.pre-commit-hooks.yaml``: pre-commit passes the staged .glb/.gltf files; each is baked
incrementally from its output's bake state (``<stem>_baked.glb.bake``) when there is one. Files
that are themselves bake outputs (``*_baked.*``) are skipped. Exit code 0 when every file baked,
1 when any failed (each failure printed as one line).

The bake states beside the outputs (``<stem>_baked.glb.bake`` and its ``.json``: tens of MB, and
rebuilt by any full bake) do not belong in the asset repository: the hook adds the line
``IGNORE`` to the ``.gitignore`` of each folder it baked into, once, and says so.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import baker
from baker.cli.state import print_rebake, settings_for

SUFFIX = "_baked"
IGNORE = "*_baked.gl*.bake*"  # every bake state the hook writes, and its timing record


def add_parser(commands) -> None:
    """Register ``hook`` on the ``baker`` command's subparsers."""
    parser = commands.add_parser(
        "hook", help="bake each given glTF file into <stem>_baked (for pre-commit)",
        description="Bake every given .glb/.gltf into <stem>_baked.<ext> beside it, "
                    "incrementally when its bake state is there. For .pre-commit-hooks.yaml.")
    parser.set_defaults(run=run)
    parser.add_argument("scenes", type=Path, nargs="*", help="the scenes to bake")
    parser.add_argument("--rays", type=int, default=baker.Settings().rays,
                        help="obscurance rays per texel for a scene baked the first time (then: "
                             "the settings of the bake that wrote its state)")
    parser.add_argument("--page-size", type=int, default=baker.Settings().page_size,
                        metavar="TEXELS", help="largest lightmap page side, likewise")
    parser.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                        help="show the traceback of an error")


def output_for(scene: Path) -> Path:
    """Where ``baker hook`` writes the bake of ``scene``: ``<stem>_baked<suffix>``."""
    return scene.with_name(scene.stem + SUFFIX + scene.suffix)


def run(args: argparse.Namespace) -> int:
    """Bake each scene; exit code 0 when all baked, 1 otherwise."""
    failed, folders = 0, set()
    for scene in args.scenes:
        if scene.stem.endswith(SUFFIX) or scene.suffix.lower() not in (".glb", ".gltf"):
            continue
        try:
            settings = settings_for(output_for(scene), rays=args.rays, page_size=args.page_size)
            result = baker.bake(scene, output_for(scene), settings, incremental=True)
            print_rebake(result)
            print(f"baked {result.output}")
            folders.add(result.output.parent)
        except baker.BakerError as error:
            print(f"baker: error: {error}", file=sys.stderr)
            failed += 1
    for folder in sorted(folders):
        if ignore_states(folder):
            print(f"baker hook: added {IGNORE} to {folder / '.gitignore'} (the bake states "
                  "beside the outputs: large, and rebuilt by any full bake)")
    return 1 if failed else 0


def ignore_states(folder: Path) -> bool:
    """Add ``IGNORE`` to ``folder``'s .gitignore (made if missing) unless a line says it
    already; whether it was added."""
    from baker.run.atomic import write_atomically

    path = folder / ".gitignore"
    text = path.read_text(encoding="utf-8") if path.is_file() else ""
    if IGNORE in (line.strip() for line in text.splitlines()):
        return False
    head = text + ("\n" if text and not text.endswith("\n") else "")
    write_atomically(path, (head + f"# baker's bake states: large, rebuilt by any bake\n"
                            f"{IGNORE}\n").encode("utf-8"))
    return True
