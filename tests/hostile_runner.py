"""Run ``baker`` commands as separate processes, fast: forked from a server that has imported baker.

``tests/test_hostile_generated.py`` runs hundreds of generated cases, each as a real ``baker``
process (its own exit code, signals, peak memory and clock), and a fresh Python importing
numpy, numba and Embree takes a second or more. So one server process (``Runner``) imports
baker's pipeline once and forks a child for each command: the child runs the command line's own
entry point (``baker.cli.main.entry``) on its arguments, its stdout and stderr in files, and
exits with its exit code; the server measures it with ``os.wait4`` (clock seconds, peak
resident KiB), sends it a signal at a given moment if asked, and kills it after a time limit.
A forked child's peak counts only the server's pages it touches: it was 54 to 56 MiB below a
fresh ``python -m baker.cli.main`` process's (``tests/test_hostile.py::run_measured``) on the
same cases (113 MiB against 57 for a refusal, 779 against 725 for the largest decode). Run as ``python tests/hostile_runner.py``, the server reads one JSON request a line
on stdin and answers one JSON line on stdout.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_POLL = 0.005  # seconds between looks at a running child


def serve() -> None:
    """The server's loop: a request ``{"argv", "cwd", "limit", "signal", "after"}`` a line,
    an answer ``{"code", "seconds", "kib", "after_signal"}`` a line."""
    import importlib

    for module in ("baker.api", "baker.cli.hook", "baker.cli.main", "baker.cli.rebake"):
        importlib.import_module(module)  # the pipeline, imported once for every child

    answers = os.fdopen(os.dup(1), "w")
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 1)  # nothing but the answers on the answer pipe
    for line in sys.stdin:
        request = json.loads(line)
        answers.write(json.dumps(_run(**request)) + "\n")
        answers.flush()


def _run(argv: list[str], cwd: str, out: str, err: str, limit: float,
         signal_number: int | None = None, after: float = 0.0) -> dict:
    """Fork, run ``baker ARGV`` in ``cwd`` (stdout to ``out``, stderr to ``err``), measure."""
    start = time.monotonic()
    pid = os.fork()
    if pid == 0:
        _child(argv, cwd, out, err)
    sent = None
    while True:
        done, status, usage = os.wait4(pid, os.WNOHANG)
        if done:
            break
        now = time.monotonic() - start
        if signal_number is not None and sent is None and now >= after:
            os.kill(pid, signal_number)
            sent = now
        if now > limit:
            os.kill(pid, signal.SIGKILL)
            done, status, usage = os.wait4(pid, 0)
            break
        time.sleep(_POLL)
    seconds = time.monotonic() - start
    return {"code": os.waitstatus_to_exitcode(status), "seconds": seconds,
            "kib": usage.ru_maxrss, "after_signal": None if sent is None else seconds - sent}


def _child(argv: list[str], cwd: str, out: str, err: str) -> None:
    """The forked child: the ``baker`` command on ``argv``, its exit code ``os._exit``'s."""
    import threading

    code = 3
    try:
        os.chdir(cwd)
        for fd, path in ((1, out), (2, err)):
            os.dup2(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644), fd)
        sys.argv = ["baker", *argv]
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        from baker.cli.main import entry

        code = entry()
        for thread in threading.enumerate():  # as the interpreter waits for them at exit
            if thread is not threading.main_thread() and not thread.daemon:
                thread.join()
    except BaseException as error:  # noqa: BLE001  a bug in the harness: say so
        print(f"hostile_runner: {type(error).__name__}: {error}", file=sys.stderr)
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)


class Runner:
    """A server (``serve``) in a process of its own; ``run`` a command through it."""

    def __init__(self) -> None:
        self._scratch = Path(tempfile.mkdtemp(prefix="baker-runner-"))  # the children's output
        self._server = subprocess.Popen(
            [sys.executable, str(Path(__file__).resolve())], cwd=ROOT, stdin=subprocess.PIPE,
            stdout=subprocess.PIPE, text=True, env=dict(os.environ, PYTHONPATH=str(ROOT)))

    def run(self, argv: list[str], cwd: Path, limit: float, signal_number: int | None = None,
            after: float = 0.0) -> dict:
        """``baker ARGV`` run in ``cwd``: ``{"code", "seconds", "kib", "after_signal", "out",
        "err"}`` (``after_signal``: seconds from the signal to the child's end)."""
        out, err = self._scratch / "stdout", self._scratch / "stderr"
        request = {"argv": argv, "cwd": str(cwd), "out": str(out), "err": str(err),
                   "limit": limit, "signal_number": signal_number, "after": after}
        self._server.stdin.write(json.dumps(request) + "\n")
        self._server.stdin.flush()
        answer = json.loads(self._server.stdout.readline())
        answer["out"], answer["err"] = out.read_text(), err.read_text()
        out.unlink()
        err.unlink()
        return answer

    def close(self) -> None:
        self._server.stdin.close()
        self._server.wait(timeout=30)
        shutil.rmtree(self._scratch, ignore_errors=True)


if __name__ == "__main__":
    serve()
