"""A lock every test worker on this machine (``pytest -n``) shares: a lock file in the system's
temporary folder, held with ``flock`` for the ``with`` block. For what the machine has once and
one worker must make for all (Chromium's install, a folder's npm packages)."""

from __future__ import annotations

import fcntl
import os
import tempfile
from contextlib import contextmanager


@contextmanager
def machine_lock(name: str):
    """Hold the lock ``name`` (a file name's stem) until the block ends; wait for it first."""
    with open(os.path.join(tempfile.gettempdir(), f"baker-tests-{name}.lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield
