"""The pinned npm packages of a test folder (``tests/<tool>/package-lock.json``), installed on
first use with ``npm ci``, once however many test workers (``pytest -n``) ask at the same time.

``npm ci`` removes ``node_modules`` before it installs, so two of them at once in one folder
would pull the files from under each other, and a worker that checked for a package while
another was installing could find it half written. Every worker takes the folder's lock file (in
the system's temporary folder, named after the folder's path) before it looks: the first
installs, the others wait and find the packages there.
"""

from __future__ import annotations

import hashlib
import shutil
import subprocess
from pathlib import Path

from machine_lock import machine_lock


def installed(folder: Path, wanted: list[Path]) -> bool:
    """Whether the files or folders ``wanted`` (paths under ``folder``/node_modules) are
    there, after ``npm ci --prefix folder`` when one was missing; False where they are not and
    there is no npm."""
    npm = shutil.which("npm")
    with machine_lock("npm-" + hashlib.sha256(str(folder.resolve()).encode()).hexdigest()[:16]):
        if all((folder / "node_modules" / path).exists() for path in wanted):
            return True
        if npm is None:
            return False
        subprocess.run([npm, "ci", "--prefix", str(folder), "--no-audit", "--no-fund"],
                       check=True, capture_output=True, timeout=600)
    return True
