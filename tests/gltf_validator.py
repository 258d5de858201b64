"""The Khronos glTF Validator (npm ``gltf-validator``, pinned in ``tests/validator``) for tests.

``validate(path)`` runs ``node tests/validator/validate.js <path>`` and returns the validator's
JSON report as a dict; ``issue_codes(report, severity)`` counts its issue codes of one severity.
Install the validator once with ``npm ci --prefix tests/validator``.
"""

from __future__ import annotations

import collections
import json
import shutil
import subprocess
from pathlib import Path

VALIDATOR_DIR = Path(__file__).resolve().parent / "validator"
SCRIPT = VALIDATOR_DIR / "validate.js"

ERROR = 0
WARNING = 1
INFO = 2
HINT = 3


class ValidatorUnavailable(RuntimeError):
    """node or the pinned gltf-validator package is not installed."""


def _node() -> str:
    node = shutil.which("node")
    if node is None:
        raise ValidatorUnavailable(
            "node is not on PATH: install Node.js (v18 or later), then run "
            "`npm ci --prefix tests/validator`"
        )
    if not (VALIDATOR_DIR / "node_modules" / "gltf-validator").is_dir():
        raise ValidatorUnavailable(
            f"the glTF validator is not installed in {VALIDATOR_DIR / 'node_modules'}: "
            "run `npm ci --prefix tests/validator` from the repository root"
        )
    return node


def validate(path: str | Path, timeout: float = 120.0) -> dict:
    """Validate a ``.gltf`` or ``.glb`` file; return the validator's report (parsed JSON).

    Relative URIs (``.bin`` buffers, image files) are read from the file's folder. The report's
    ``issues.messages`` lists every issue (no cap), each with ``code``, ``severity``, ``pointer``
    and ``message``.
    """
    node = _node()
    path = Path(path).resolve()
    run = subprocess.run(
        [node, str(SCRIPT), str(path)],
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )
    if run.returncode != 0:
        raise RuntimeError(
            f"glTF validator failed on {path} (exit {run.returncode}): {run.stderr.strip()}"
        )
    return json.loads(run.stdout)


def issue_codes(report: dict, severity: int) -> collections.Counter:
    """Count the report's issue codes of one severity (0 error, 1 warning, 2 info, 3 hint)."""
    return collections.Counter(
        message["code"]
        for message in report["issues"]["messages"]
        if message["severity"] == severity
    )


def describe(report: dict, severity: int) -> str:
    """One line per issue of ``severity``: code, JSON pointer and message (for assert messages)."""
    return "\n".join(
        f"{m['code']} at {m.get('pointer', '')}: {m['message']}"
        for m in report["issues"]["messages"]
        if m["severity"] == severity
    )
