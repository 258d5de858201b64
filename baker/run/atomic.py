"""Files written whole or not at all: through a temporary file beside them and a rename."""

from __future__ import annotations

import os
import tempfile
from concurrent.futures import Future
from pathlib import Path
from typing import BinaryIO, Callable

from baker.errors import OutputError


def _umask() -> int:
    """The process's file-creation mask (read by setting it and setting it back)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask
def stage_atomically(path: Path, data: bytes | Callable[[BinaryIO], None]) -> str:
    """The first half of ``write_atomically``: write ``data`` to a temporary file beside
    ``path`` with the permissions a new file gets, and return the temporary's path, for
    ``rename_staged`` to put in place (nothing is left behind if writing fails)."""
    if not path.parent.exists():
        raise OutputError("the folder does not exist", file=str(path),
                          fix=f"create {path.parent} first")
    handle, temp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(handle, "wb") as f:
            if callable(data):
                data(f)
            else:
                f.write(data)
        os.chmod(temp, 0o666 & ~_umask())
    except BaseException:
        _remove(temp)
        raise
    return temp
def rename_staged(temp: str, path: Path) -> None:
    """Put the staged file ``temp`` in place at ``path`` (an atomic rename)."""
    try:
        os.replace(temp, path)
    except BaseException:
        _remove(temp)
        raise
def _remove(temp: str) -> None:
    """Delete the temporary file ``temp`` if it is there."""
    if os.path.exists(temp):
        os.unlink(temp)
def discard_staged(staging: Future | None) -> None:
    """Wait for a file being staged beside a write that failed, and remove it."""
    if staging is None:
        return
    try:
        _remove(staging.result())
    except Exception:
        pass  # it failed too; the write's own error is the one to report
def write_atomically(path: Path, data: bytes | Callable[[BinaryIO], None]) -> None:
    """Write ``data`` to ``path`` through a temporary file and a rename; ``data`` is the bytes,
    or a function that writes them to the open file (to stream large files). The file gets the
    permissions a newly created file gets (0666 less the umask), not the temporary's 0600."""
    rename_staged(stage_atomically(path, data), path)
