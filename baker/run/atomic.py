"""Every file a bake writes, staged beside its place and put in place together, or not at all.

A bake writes several files: the output (``.glb``, or ``.gltf`` with its ``.bin`` and copied
images), the bake state and its ``.json``, the report, the page files of ``--lightmaps`` and
``--error-map``. Written one after the other, a failure half-way (a full disk while the state is
written, a report path naming a folder) would leave a new output beside an old state. So each
file is first written whole to a hidden temporary beside its place (``Outputs.stage``), and only
when all are written are they renamed into place (``Outputs.commit``); an error or Ctrl-C before
that removes the temporaries (``Outputs.discard``), and one during the renames puts back what
they replaced (each replaced file is first given a second name, a hard link, ``spill.set_aside``),
so that every previous file is as it was.

``write_atomically`` is the one-file case. Errors writing are ``OutputError`` naming the file.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import BinaryIO, Callable

from baker.errors import OutputError
from baker.run.spill import remove_later, set_aside

Data = bytes | Callable[[BinaryIO], None]
"""A file's contents: its bytes, or a function that writes them to the open file (to stream)."""


class Outputs:
    """Files staged for one commit: ``stage`` each, then ``commit`` (or ``discard``)."""

    def __init__(self) -> None:
        self._staged: list[tuple[str, Path]] = []  # (temporary, destination), in commit order
        self._made: list[Path] = []  # folders made for the files, removed again on discard

    def folder(self, path: Path) -> Path:
        """Make the folder ``path`` (and its missing parents) for files staged into it; the
        folders made are removed on ``discard``. An existing file there is an ``OutputError``."""
        path = Path(path)
        missing = [p for p in (path, *path.parents) if not p.exists()]
        if path.exists() and not path.is_dir():
            raise OutputError("is a file, not a folder", file=str(path),
                              fix="give a folder (it is made if missing), or remove the file")
        for folder in reversed(missing):
            try:
                folder.mkdir()
            except OSError as error:
                raise _error(error, folder) from None
            self._made.append(folder)
        return path

    def stage(self, path: Path, data: Data, durable: bool = False) -> None:
        """Write ``data`` to a temporary beside ``path`` (``durable``: flushed to the disk),
        for ``commit`` to put in place."""
        self.adopt(stage_atomically(Path(path), data, durable), path)

    def adopt(self, temporary: str, path: Path) -> None:
        """Add a temporary staged elsewhere (``stage_atomically``) to put in place at ``path``."""
        self._staged.append((temporary, Path(path)))

    def commit(self) -> None:
        """Rename every staged file into place, in the order staged. If one rename fails (or
        Ctrl-C comes), the files already renamed get back what they replaced."""
        done: list[tuple[Path, str | None]] = []
        try:
            for temporary, path in self._staged:
                _check_destination(path)
                old = set_aside(path)
                done.append((path, old))
                try:
                    os.replace(temporary, path)
                except OSError as error:
                    raise _error(error, path) from None
        except BaseException:
            _put_back(done)
            self.discard()
            raise
        self._staged = []
        for _, old in done:
            if old is not None:
                remove_later(old)

    def discard(self) -> None:
        """Remove every staged temporary, and the folders ``folder`` made if they are empty."""
        for temporary, _ in self._staged:
            remove_temporary(temporary)
        self._staged = []
        for folder in reversed(self._made):
            try:
                folder.rmdir()
            except OSError:
                pass
        self._made = []


def _put_back(done: list[tuple[Path, str | None]]) -> None:
    """Undo the renames ``done`` (path, its previous file's second name or None), last first."""
    for path, old in reversed(done):
        try:
            if old is None:
                os.unlink(path)
            elif os.path.samefile(old, path):  # not replaced yet (a rename of a file onto
                os.unlink(old)                 # another name of itself would do nothing)
            else:
                os.replace(old, path)
        except OSError:
            pass


def _check_destination(path: Path) -> None:
    """Refuse a destination that is a folder (a rename would fail there, or replace it)."""
    if path.is_dir() and not path.is_symlink():
        raise OutputError("is a folder, not a file", file=str(path),
                          fix="give a file name, or move the folder away")


def _error(error: OSError, path: Path) -> OutputError:
    """The ``OutputError`` for ``error`` while writing ``path``."""
    if isinstance(error, PermissionError):
        return OutputError(f"no permission to write {path}", file=str(path),
                           fix=f"choose a folder you can write to, or change the permissions of "
                               f"{path.parent}")
    return OutputError(f"cannot write {path}: {error.strerror or error}", file=str(path),
                       fix="check the disk space and the output folder")


def _umask() -> int:
    """The process's file-creation mask (read by setting it and setting it back)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def stage_atomically(path: Path, data: Data, durable: bool = False) -> str:
    """Write ``data`` to a temporary file beside ``path`` with the permissions a new file gets
    (0666 less the umask, not the temporary's 0600) and return the temporary's path, for a
    rename to put in place; nothing is left behind if writing fails. ``durable``: flushed to
    the disk (``fsync``) before returning."""
    path = Path(path)
    if not path.parent.is_dir():
        raise OutputError(f"the folder {path.parent} does not exist", file=str(path),
                          fix=f"create {path.parent} first, or choose another path")
    _check_destination(path)
    try:
        handle, temp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as error:
        raise _error(error, path) from None
    try:
        with os.fdopen(handle, "wb") as f:
            if callable(data):
                data(f)
            else:
                f.write(data)
            if durable:
                f.flush()
                os.fsync(f.fileno())
        os.chmod(temp, 0o666 & ~_umask())
    except OSError as error:
        remove_temporary(temp)
        raise _error(error, path) from None
    except BaseException:
        remove_temporary(temp)
        raise
    return temp


def remove_temporary(temp: str) -> None:
    """Delete the temporary file ``temp`` if it is there."""
    try:
        os.unlink(temp)
    except FileNotFoundError:
        pass


def write_atomically(path: Path, data: Data) -> None:
    """Write ``data`` to ``path`` through a temporary file and a rename (``Outputs`` of one)."""
    outputs = Outputs()
    outputs.stage(path, data)
    outputs.commit()
