"""``baker hook``: bake every glTF file given (a pre-commit hook), each into ``<stem>_baked``.

Used by ``.pre-commit-hooks.yaml``: pre-commit passes the staged .glb/.gltf files; each is baked
incrementally from its output's bake state (``<stem>_baked.glb.bake``) when there is one. Files
that are themselves bake outputs (``*_baked.*``) are skipped. Exit code 0 when every file baked
to the bytes its output already held; ``OUTPUTS_CHANGED`` when an output (or its ``.bin``, or
the ``.gitignore``) was written anew or changed: the commit must stop so that they are added
(pre-commit itself stops a commit only when a hook changes a file git tracks, and a scene's
first bake makes new ones); 1 when any failed (each failure printed as one line).

The bake states beside the outputs (``<stem>_baked.glb.bake`` and its ``.json``: tens of MB, and
rebuilt by any full bake) do not belong in the asset repository: the hook adds the line
``IGNORE`` to the ``.gitignore`` of each folder it baked into, once, and says so.

A repository is as untrusted as the scenes in it: the hook opens every file as the files a
scene names are opened (``gltf.files.SceneFolder``: inside the folder, no link out, one name),
the staged scenes themselves included (``baker.bake(contained=True)``), and the ``.gitignore``
once, to read and append to: one that is a link, not a regular file, has other names or more
than ``MAX_GITIGNORE_BYTES`` is left as it is, with a line saying so. The settings it takes
from a bake state never include a guard (``settings.CALLER_ONLY``).
"""

from __future__ import annotations

import argparse
import os
import stat
import sys
from pathlib import Path

import baker
from baker.cli.common import OUTPUTS_CHANGED
from baker.cli.state import print_rebake, settings_for

SUFFIX = "_baked"
IGNORE = "*_baked.gl*.bake*"  # every bake state the hook writes, and its timing record
MAX_GITIGNORE_BYTES = 1 << 20
"""Largest ``.gitignore`` the hook reads to add its line to (a sparse 3 GB one was read whole)."""


def add_parser(commands) -> None:
    """Register ``hook`` on the ``baker`` command's subparsers."""
    parser = commands.add_parser(
        "hook", help="bake each given glTF file into <stem>_baked (for pre-commit)",
        description="Bake every given .glb/.gltf into <stem>_baked.<ext> beside it, "
                    "incrementally when its bake state is there. For .pre-commit-hooks.yaml: "
                    f"exits {OUTPUTS_CHANGED} when it wrote an output (or .gitignore) anew or "
                    "changed, so that the commit stops until they are added; 0 when every "
                    "output was already as baked.")
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
    """Bake each scene; exit code 0 when all baked and no file changed, ``OUTPUTS_CHANGED``
    when one did (the module's docstring), 1 when any failed."""
    failed, folders, changed = 0, set(), []
    for scene in args.scenes:
        if scene.stem.endswith(SUFFIX) or scene.suffix.lower() not in (".glb", ".gltf"):
            continue
        written = _written_files(output_for(scene))
        before = {path: _opened(path) for path in written}  # the bytes as they were
        try:
            settings = settings_for(output_for(scene), rays=args.rays, page_size=args.page_size)
            result = baker.bake(scene, output_for(scene), settings, incremental=True,
                                contained=True)
            print_rebake(result)
            print(f"baked {result.output}")
            folders.add(result.output.parent)
            changed += [path for path in written if path.exists() and not _same(before[path], path)]
        except baker.BakerError as error:
            print(f"baker: error: {error}", file=sys.stderr)
            failed += 1
        finally:
            for descriptor in before.values():
                if descriptor is not None:
                    os.close(descriptor)
    changed += _ignored_states(folders)
    if failed:
        return 1
    if changed:
        print(f"baker hook: wrote {', '.join(map(str, changed))}: add "
              f"{'it' if len(changed) == 1 else 'them'} and commit again", file=sys.stderr)
        return OUTPUTS_CHANGED
    return 0


def _written_files(output: Path) -> list[Path]:
    """The files a bake of the hook writes for ``output`` that belong in the repository: the
    output, and beside a .gltf its .bin (the hook bakes into the scene's own folder, so the
    images stay the scene's own)."""
    return [output, *([output.with_suffix(".bin")] if output.suffix.lower() == ".gltf" else [])]


def _opened(path: Path) -> int | None:
    """A descriptor of the regular file ``path`` as it is before the bake (which renames a new
    file into its place: this one keeps reading the old bytes), or None when there is none
    (missing, a link, a FIFO, anything else: never followed, never read)."""
    try:
        descriptor = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:
        return None
    if not stat.S_ISREG(os.fstat(descriptor).st_mode):
        os.close(descriptor)
        return None
    return descriptor


def _same(descriptor: int | None, path: Path) -> bool:
    """Whether the file at ``path`` (just written by the bake) holds what ``descriptor``
    (``_opened`` before it) held; no more of the old file is read than the new one's size."""
    if descriptor is None:
        return False
    new = path.read_bytes()
    if os.fstat(descriptor).st_size != len(new):
        return False
    old, offset = bytearray(), 0
    while offset < len(new):
        chunk = os.pread(descriptor, min(len(new) - offset, 1 << 24), offset)
        if not chunk:
            return False
        old += chunk
        offset += len(chunk)
    return old == new


def _ignored_states(folders: set[Path]) -> list[Path]:
    """``ignore_states`` for each folder baked into, said; the .gitignore files it changed."""
    changed = []
    for folder in sorted(folders):
        try:
            added = ignore_states(folder)
        except baker.BakerError as error:
            print(f"baker hook: {error.file} not changed: {error.message}", file=sys.stderr)
            continue
        if added is None:
            print(f"baker hook: {folder / '.gitignore'} not changed: more than "
                  f"{MAX_GITIGNORE_BYTES:,} bytes; add the line {IGNORE} yourself",
                  file=sys.stderr)
        elif added:
            print(f"baker hook: added {IGNORE} to {folder / '.gitignore'} (the bake states "
                  "beside the outputs: large, and rebuilt by any full bake)")
            changed.append(folder / ".gitignore")
    return changed


def ignore_states(folder: Path) -> bool | None:
    """Add ``IGNORE`` to ``folder``'s .gitignore (made if missing) unless a line says it
    already: whether it was added (None: the file is too large to read). The file is opened
    once (``SceneFolder.append_to``); a link, or a file that is no regular file of one name, is
    an InputError and left as it is."""
    from baker.gltf.files import SceneFolder

    with SceneFolder(folder, str(folder / ".gitignore")) as opened:
        found = opened.append_to(".gitignore", MAX_GITIGNORE_BYTES)
    if found is None:
        return None
    descriptor, data = found
    try:
        text = data.decode("utf-8", errors="replace")
        if IGNORE in (line.strip() for line in text.splitlines()):
            return False
        head = "\n" if text and not text.endswith("\n") else ""
        os.write(descriptor, (head + "# baker's bake states: large, rebuilt by any bake\n"
                              f"{IGNORE}\n").encode("utf-8"))
        return True
    finally:
        os.close(descriptor)
