"""The kernels compiled at install (setup.py → assets/warm_kernels.py) are those a first bake
needs: after the warm-up, the README's first bake runs them compiled ahead of time, and with
numba's JIT (``BAKER_JIT=1``, or where the module could not be built) compiles nothing.

Slow (every kernel compiled cold, about a minute of CPU): it runs in the long mode,
``BAKER_LONG=1 python -m pytest tests/test_warm_kernels.py``. It warms a copy of the package:
warming the checkout's would remove its compiled module for the minutes the build takes, under
the feet of the bakes other test workers run at the same time (``pytest -n``).
"""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from assets.make_scenes import cornell_box

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.long
def test_after_the_warm_up_the_first_bake_compiles_nothing(tmp_path):
    code = tmp_path / "code"  # the package and the warm-up, without the checkout's kernels
    for folder in ("baker", "assets"):
        shutil.copytree(ROOT / folder, code / folder,
                        ignore=shutil.ignore_patterns("__pycache__", "_kernels*", "scenes"))
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), NUMBA_DEBUG_CACHE="1",
               PYTHONPATH=str(code))  # the copy before the checkout's editable install
    before = sorted((p.name, p.stat().st_mtime_ns) for p in (ROOT / "baker").glob("_kernels*"))
    warm = subprocess.run([sys.executable, str(code / "assets" / "warm_kernels.py")], env=env,
                          capture_output=True, text=True, cwd=code)
    assert warm.returncode == 0, warm.stderr[-2000:]
    assert "data saved" in warm.stdout  # it did compile, into that cache
    assert list((code / "baker").glob("_kernels*.so")), "the copy's module was not built"
    assert sorted((p.name, p.stat().st_mtime_ns)
                  for p in (ROOT / "baker").glob("_kernels*")) == before
    scene = cornell_box().save(tmp_path / "cornell_box.glb")
    report = tmp_path / "report.json"
    ahead = subprocess.run([sys.executable, "-m", "baker.cli.main", "bake", str(scene), "-o",
                            str(tmp_path / "ahead.glb"), "--quiet", "--report", str(report)],
                           env=env, capture_output=True, text=True, cwd=code)
    assert ahead.returncode == 0, ahead.stderr[-2000:]
    assert json.loads(report.read_text())["kernels"] == "compiled ahead of time"
    assert "data loaded" not in ahead.stdout  # numba not even imported
    first = subprocess.run([sys.executable, "-m", "baker.cli.main", "bake", str(scene), "-o",
                            str(tmp_path / "baked.glb"), "--quiet"], env=dict(env, BAKER_JIT="1"),
                           capture_output=True, text=True, cwd=code)
    assert first.returncode == 0, first.stderr[-2000:]
    assert "data loaded" in first.stdout
    saved = [line for line in first.stdout.splitlines() if "data saved" in line]
    assert not saved, f"compiled on the first bake: {saved}"
