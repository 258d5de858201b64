"""The pinned npm packages of a test folder (``tests/<tool>/package-lock.json``), installed on
first use with ``npm ci``, once however many test workers (``pytest -n``) ask at the same time.

``npm ci`` removes ``node_modules`` before it installs, so two of them at once in one folder
would pull the files from under each other, and a worker that checked for a package while
another was installing could find it half written. Every worker takes the folder's lock file (in
the system's temporary folder, named after the folder's path) before it looks: the first
installs, the others wait and find the packages there.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
import subprocess
import tempfile
from pathlib import Path


def installed(folder: Path, wanted: list[Path]) -> bool:
    """Whether the files or folders ``wanted`` (paths under ``folder``/node_modules) are
    there, after ``npm ci --prefix folder`` when one was missing; False where there is no npm."""
    if all((folder / "node_modules" / path).exists() for path in wanted):
        return True
    npm = shutil.which("npm")
    if npm is None:
        return False
    name = hashlib.sha256(str(folder.resolve()).encode()).hexdigest()[:16]
    with open(os.path.join(tempfile.gettempdir(), f"baker-tests-npm-{name}.lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not all((folder / "node_modules" / path).exists() for path in wanted):
            subprocess.run([npm, "ci", "--prefix", str(folder), "--no-audit", "--no-fund"],
                           check=True, capture_output=True, timeout=600)
    return True
