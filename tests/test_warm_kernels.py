"""The kernels compiled at install (setup.py → assets/warm_kernels.py) are those a first bake
needs: after the warm-up, the README's first bake runs them compiled ahead of time, and with
numba's JIT (``BAKER_JIT=1``, or where the module could not be built) compiles nothing.

Slow (every kernel compiled cold, about a minute of CPU): it runs in the long mode,
``BAKER_LONG=1 python -m pytest tests/test_warm_kernels.py``.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from assets.make_scenes import cornell_box

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.long
def test_after_the_warm_up_the_first_bake_compiles_nothing(tmp_path):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), NUMBA_DEBUG_CACHE="1")
    warm = subprocess.run([sys.executable, str(ROOT / "assets" / "warm_kernels.py")], env=env,
                          capture_output=True, text=True, cwd=ROOT)
    assert warm.returncode == 0, warm.stderr[-2000:]
    assert "data saved" in warm.stdout  # it did compile, into that cache
    scene = cornell_box().save(tmp_path / "cornell_box.glb")
    report = tmp_path / "report.json"
    ahead = subprocess.run([sys.executable, "-m", "baker.cli.main", "bake", str(scene), "-o",
                            str(tmp_path / "ahead.glb"), "--quiet", "--report", str(report)],
                           env=env, capture_output=True, text=True, cwd=ROOT)
    assert ahead.returncode == 0, ahead.stderr[-2000:]
    assert json.loads(report.read_text())["kernels"] == "compiled ahead of time"
    assert "data loaded" not in ahead.stdout  # numba not even imported
    first = subprocess.run([sys.executable, "-m", "baker.cli.main", "bake", str(scene), "-o",
                            str(tmp_path / "baked.glb"), "--quiet"], env=dict(env, BAKER_JIT="1"),
                           capture_output=True, text=True, cwd=ROOT)
    assert first.returncode == 0, first.stderr[-2000:]
    assert "data loaded" in first.stdout
    saved = [line for line in first.stdout.splitlines() if "data saved" in line]
    assert not saved, f"compiled on the first bake: {saved}"
