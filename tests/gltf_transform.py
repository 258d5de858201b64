"""glTF Transform (npm ``@gltf-transform/*``, pinned in ``tests/transform``) for tests: compressed
and quantized variants of a scene, made by the tools studios use.

``variant(kind, source, target)`` runs ``node tests/transform/transform.js KIND SOURCE TARGET``
(kind: ``draco``, ``meshopt`` or ``quantize``). The packages are installed on first use with
``npm ci --prefix tests/transform`` (the README's test command installs only the validator).
"""

from __future__ import annotations

import shutil
import subprocess
import threading
from pathlib import Path

TRANSFORM_DIR = Path(__file__).resolve().parent / "transform"
SCRIPT = TRANSFORM_DIR / "transform.js"
KINDS = ("draco", "meshopt", "quantize")
_install = threading.Lock()


def _node() -> str:
    """node, with the pinned packages installed (``npm ci`` once, when they are missing)."""
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None or npm is None:
        raise RuntimeError("node and npm are not on PATH: install Node.js (v18 or later)")
    with _install:
        if not (TRANSFORM_DIR / "node_modules" / "@gltf-transform" / "functions").is_dir():
            subprocess.run([npm, "ci", "--prefix", str(TRANSFORM_DIR), "--no-audit", "--no-fund"],
                           check=True, capture_output=True, timeout=600)
    return node


def variant(kind: str, source: Path, target: Path) -> Path:
    """Write ``source`` as ``target`` compressed (``draco``, ``meshopt``) or quantized."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, not {kind!r}")
    run = subprocess.run([_node(), str(SCRIPT), kind, str(source), str(target)],
                         capture_output=True, text=True, timeout=300, check=False)
    if run.returncode != 0:
        raise RuntimeError(f"gltf-transform {kind} failed on {source}: {run.stderr.strip()}")
    return target
