"""A real Ray cluster on 127.0.0.1 for the tests and benchmarks: a head that bakes nothing
(no CPUs) and worker nodes of one CPU each, every one a ``ray start --block`` process of its
own (so that stopping one stops what it started, and nothing else on the machine is touched).

    with LocalCluster(workers=2) as cluster:
        baker.bake(..., baker.Settings(cluster=cluster.address))
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RAY = Path(sys.executable).with_name("ray")


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class LocalCluster:
    """A head on a free port of 127.0.0.1 and ``workers`` nodes of ``cpus`` CPUs each, whose
    Python finds baker at ``code`` (the worktree by default); stopped on exit."""

    def __init__(self, workers: int = 2, cpus: int = 1, code: Path = ROOT):
        self.port = free_port()
        self.address = f"127.0.0.1:{self.port}"
        self.temp = tempfile.mkdtemp(prefix="baker-ray-")  # the cluster's logs and sockets
        self.code = code
        self._head: subprocess.Popen | None = None
        self.workers: list[subprocess.Popen] = []
        self._count, self._cpus = workers, cpus

    def __enter__(self) -> "LocalCluster":
        try:
            self._head = self._start("--head", "--port", str(self.port), "--num-cpus", "0",
                                     "--temp-dir", self.temp, "--include-dashboard", "false")
            self._wait_for_nodes(1)
            for _ in range(self._count):
                self.add_worker(self._cpus)
        except BaseException:
            self.stop()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def add_worker(self, cpus: int = 1, code: Path | None = None) -> subprocess.Popen:
        """Start one more worker node of ``cpus`` CPUs (its baker at ``code``), wait until the
        head counts it, and return its ``ray start`` process."""
        process = self._start("--address", self.address, "--num-cpus", str(cpus),
                              code=code or self.code)
        self.workers.append(process)
        self._wait_for_nodes(1 + len(self.workers))
        return process

    def stop_worker(self, process: subprocess.Popen) -> None:
        """Stop one worker node (and what its ``ray start`` started)."""
        _stop(process)
        self.workers.remove(process)

    def sessions(self) -> set[int]:
        """The session ids of the cluster's processes: each node's ``ray start`` leads its own,
        which its raylet and worker processes belong to."""
        return {p.pid for p in [self._head, *self.workers] if p is not None}

    def stop(self) -> None:
        """Stop the workers, then the head, and remove the cluster's folder."""
        for process in list(self.workers):
            self.stop_worker(process)
        if self._head is not None:
            _stop(self._head)
            self._head = None
        shutil.rmtree(self.temp, ignore_errors=True)

    def _start(self, *args: str, code: Path | None = None) -> subprocess.Popen:
        env = dict(os.environ, PYTHONPATH=str(code or self.code), RAY_USAGE_STATS_ENABLED="0")
        return subprocess.Popen([str(RAY), "start", "--block", "--node-ip-address", "127.0.0.1",
                                 "--disable-usage-stats", *args], env=env, cwd=self.temp,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                start_new_session=True)

    def _wait_for_nodes(self, count: int, seconds: float = 60.0) -> None:
        """Wait until the head lists ``count`` live nodes (asked in a child process, so that
        this one is not connected to the cluster)."""
        script = ("import ray, sys, time; ray.init(address=sys.argv[1], logging_level='ERROR', "
                  "log_to_driver=False)\n"
                  "while sum(n['Alive'] for n in ray.nodes()) < int(sys.argv[2]): time.sleep(0.2)")
        subprocess.run([sys.executable, "-c", script, self.address, str(count)], check=True,
                       timeout=seconds, capture_output=True, cwd=self.temp)


def _stop(process: subprocess.Popen) -> None:
    """End a ``ray start --block`` process: SIGTERM makes it stop the node it started; its
    session (process group) is killed after 20 s if anything of it is still there."""
    if process.poll() is None:
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            pass
    try:
        os.killpg(process.pid, signal.SIGKILL)  # its own session: what it started, nothing else
    except ProcessLookupError:
        pass
    process.wait()
