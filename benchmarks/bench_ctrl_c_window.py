"""Benchmark: how long after a ``baker`` process starts a Ctrl-C still prints a traceback.

Starts the command as the console script does (a file named ``baker`` holding the script pip
writes for ``[project.scripts]``: ``from baker.cli.main import entry; sys.exit(entry())``, with
this checkout on PYTHONPATH) on a small bake, sends
SIGINT after each delay from 0 to ``--last`` ms in steps of ``--step`` ms, and prints, per delay,
the exit code and whether stderr held a traceback (and the file the traceback's last frame was
in: Python's own start-up, or baker's imports), then how many runs printed one and the latest
delay that did. A Ctrl-C that arrives before Python has installed its own handler ends the
process silently (exit −2, no traceback); one after ``entry`` has started exits 130 with one line.

    python benchmarks/bench_ctrl_c_window.py [--last 300] [--step 10] [--repeat 1]
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from assets.make_scenes import cornell_box  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ("import re\nimport sys\nfrom baker.cli.main import entry\nif __name__ == '__main__':\n"
          "    sys.argv[0] = re.sub(r'(-script\\.pyw|\\.exe)?$', '', sys.argv[0])\n"
          "    sys.exit(entry())\n")  # what pip writes for baker = "baker.cli.main:entry"


def interrupted(command: Path, scene: Path, out: Path, delay: float) -> tuple[int, str]:
    """Exit code and stderr of the console script ``command`` baking ``scene``, sent SIGINT
    ``delay`` seconds after it starts."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    child = subprocess.Popen([sys.executable, str(command), "bake", str(scene), "-o", str(out),
                              "--quiet", "--rays", "4", "--page-size", "64"], cwd=ROOT, env=env,
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    time.sleep(delay)
    child.send_signal(signal.SIGINT)
    _, err = child.communicate(timeout=120)
    return child.returncode, err


def where(err: str) -> str:
    """Where a traceback in ``err`` was raised: "Python's start-up" when a frame is in ``site``
    (the interpreter importing site-packages' .pth files, before any of the command runs), else
    the file of its last frame."""
    frames = [line.split('"')[1] for line in err.splitlines() if line.strip().startswith('File "')]
    if any(f.endswith(("site.py", "<frozen site>")) for f in frames):
        return "Python's start-up (site)"
    return os.path.relpath(frames[-1], ROOT) if frames and frames[-1].startswith(str(ROOT)) else (
        frames[-1] if frames else "?")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--last", type=int, default=300, help="largest delay, ms")
    parser.add_argument("--step", type=int, default=10, help="delay step, ms")
    parser.add_argument("--repeat", type=int, default=1, help="runs per delay")
    args = parser.parse_args()
    tracebacks, latest, runs, ours = 0, None, 0, 0
    with tempfile.TemporaryDirectory() as folder:
        scene = cornell_box().save(Path(folder) / "cornell.glb")
        command = Path(folder) / "baker"
        command.write_text(SCRIPT)
        for delay in range(0, args.last + 1, args.step):
            for _ in range(args.repeat):
                code, err = interrupted(command, scene, Path(folder) / "out.glb", delay / 1000)
                runs += 1
                shown = "Traceback" in err
                tracebacks += shown
                latest = delay if shown else latest
                ours += shown and not where(err).startswith("Python's")
                print(f"  {delay:4d} ms  exit {code:4d}  "
                      f"{'traceback in ' + where(err) if shown else err.strip()[:60]}")
    print(f"{tracebacks} of {runs} runs printed a traceback ({ours} outside Python's start-up); "
          f"the latest at {latest if latest is not None else '-'} ms")


if __name__ == "__main__":
    main()
