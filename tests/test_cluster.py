"""A bake whose parts run on a real Ray cluster (cluster.py) gives the bytes of a local bake:
the output and the bake state, whatever the workers, their threads, the order the parts end in,
and a worker killed in the middle of a part; so does a rebake whose dirty texels run there
(rebake/retrace.py), which is also a full bake's bytes. A cluster that cannot bake (unreachable, another
baker on a node, no Ray) is a clear error before any work, and Ctrl-C leaves it as it was.

One cluster for the module (``tests/ray_cluster.py``: a head with no CPUs and two one-CPU
workers on 127.0.0.1, about 13-20 s to start on this machine) and small bakes cut into many
parts (``parts.PART_TEXELS``), so that both workers get several.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

import baker
from assets.make_scenes import cornell_box
from baker.pipeline import parts
from baker.rebake.state import default_path
from tests.bakehelp import REAL_SCENES
from tests.ray_cluster import ROOT, LocalCluster, free_port

PART = 1500  # texels a part: the Cornell box's 9,181 at a 128² page make 7 parts


@pytest.fixture(scope="module")
def ray_cluster():
    with LocalCluster(workers=2, cpus=1) as running:
        yield running


@pytest.fixture
def small_parts(monkeypatch):
    monkeypatch.setattr(parts, "PART_TEXELS", PART)


def _outputs(folder: Path) -> tuple[Path, Path]:
    """Where a local and a cluster bake write, under one name (the output's images beside it
    are named after it)."""
    for kind in ("local", "cluster"):
        (folder / kind).mkdir()
    return folder / "local" / "baked.glb", folder / "cluster" / "baked.glb"


def _same_bake(local: Path, remote: Path) -> None:
    assert remote.read_bytes() == local.read_bytes()
    assert Path(f"{remote}.bake").read_bytes() == Path(f"{local}.bake").read_bytes()
    assert sorted(p.name for p in remote.parent.iterdir()) == \
        sorted(p.name for p in local.parent.iterdir())


def _bake_both(source: Path, folder: Path, address: str, local_threads: int = 0, **settings):
    """Bake ``source`` here (on ``local_threads``) and on the cluster (one thread a part);
    return the cluster bake's result."""
    local, remote = _outputs(folder)
    baker.bake(source, local, baker.Settings(threads=local_threads, **settings))
    result = baker.bake(source, remote, baker.Settings(cluster=address, **settings))
    _same_bake(local, remote)
    return result


def test_the_demo_scene_baked_on_the_cluster_is_the_local_bake(ray_cluster, small_parts, tmp_path):
    source = cornell_box().save(tmp_path / "cornell.glb")
    result = _bake_both(source, tmp_path, ray_cluster.address, rays=4, page_size=128)
    report = result.report["cluster"]
    assert result.texels > 4 * PART and report["parts"] == len(parts.part_slices(result.texels))
    assert report["nodes"] == 2 and report["cpus"] == 2
    workers = report["workers"].values()
    assert sum(w["texels"] for w in workers) == result.texels  # each part counted once
    assert sum(w["parts"] for w in workers) == report["parts"]
    assert {"receive", "validity", "trace", "direct"} <= set(report["worker_stage_seconds"])
    assert report["bytes_from_workers"] > report["bytes_to_workers"] > 0


@pytest.mark.long
def test_a_bake_is_cut_into_four_parts_a_worker_whatever_its_size(ray_cluster, tmp_path,
                                                                  monkeypatch):
    """At the parts' default size the demo at a 128² page is one part locally; on a cluster
    of two one-CPU workers it is cut into eight (``cluster.part_texels``), with the same
    bytes, and each worker takes parts as it ends its last (which of them takes how many
    depends on when each is ready: on a loaded machine one may take all eight). Its meshes are
    charted on the workers (no cache), and the atlas packed here from their charts is the
    local one."""
    from baker.pipeline import cluster

    monkeypatch.setattr(cluster, "_LEAST_PART", 100)
    monkeypatch.setenv("BAKER_CACHE_DIR", "off")
    source = cornell_box().save(tmp_path / "cornell.glb")
    result = _bake_both(source, tmp_path, ray_cluster.address, rays=4, page_size=128)
    assert len(parts.part_slices(result.texels)) == 1
    report = result.report["cluster"]
    assert report["parts"] == 8 and report["parts_run_again"] == []
    assert report["meshes_charted"] >= 3  # the room's walls, the blocks
    assert sum(worker["parts"] for worker in report["workers"].values()) == 8


@pytest.mark.long
def test_a_shared_scene_with_lights_is_the_local_bake_on_one_thread(ray_cluster, small_parts,
                                                                     tmp_path):
    """Punctual lights (direct light per texel) and glass-free leaves of a real scene, against
    a local bake on one thread (the demo's test: on every core)."""
    result = _bake_both(REAL_SCENES["LightsPunctualLamp"], tmp_path, ray_cluster.address,
                        local_threads=1, rays=8, page_size=256)  # 128: 4,493 texels, fitted
    assert result.report["shadow_rays"] > 0 and result.texels > 4 * PART


@pytest.mark.long
def test_the_command_line_says_which_worker_baked_what(ray_cluster, small_parts, tmp_path,
                                                       capsys):
    from baker.cli.main import main

    source = cornell_box().save(tmp_path / "cornell.glb")
    assert main(["bake", str(source), "-o", str(tmp_path / "baked.glb"), "--rays", "4",
                 "--page-size", "128", "--cluster", ray_cluster.address,
                 "--report", str(tmp_path / "report.json")]) == 0
    report = json.loads((tmp_path / "report.json").read_text())
    line = next(line for line in capsys.readouterr().out.splitlines() if "on the cluster" in line)
    assert f"at {ray_cluster.address}: {report['cluster']['parts']} parts" in line
    for name, worker in report["cluster"]["workers"].items():
        assert f"{name} {worker['texels']:,} texels" in line


def _short_block_moved():
    """The demo scene with its short block moved 0.3 m towards the middle of the room."""
    scene = cornell_box()
    node = scene._nodes[scene.info["nodes"]["short_block"]]
    node.translation = [node.translation[0] - 0.3, *node.translation[1:]]
    return scene


def _rebakes(folder: Path, settings: dict) -> tuple[Path, Path, Path]:
    """The demo scene baked here into ``folder``/local, its bake copied to ``folder``/cluster,
    and the edited scene (``_short_block_moved``): (its path, the local and the cluster
    outputs, each with the state of the first bake beside it, without its timing record: the
    move reaches most texels, and by the record's stage times a rebake may cost about what a
    full bake does (``cost.rebake_cost``), which these tests do not weigh)."""
    local, remote = _outputs(folder)
    baker.bake(cornell_box().save(folder / "cornell.glb"), local, baker.Settings(**settings))
    Path(f"{default_path(local)}.json").unlink()
    for made in local.parent.iterdir():
        shutil.copyfile(made, remote.parent / made.name)
    return _short_block_moved().save(folder / "moved.glb"), local, remote


def test_a_rebake_on_the_cluster_is_the_local_rebake_and_a_full_bake(ray_cluster, monkeypatch,
                                                                      tmp_path, capsys):
    """``baker rebake --cluster`` after a move: the local rebake's bytes and a full bake's of
    the edited scene, its dirty texels traced in parts by the workers and counted once."""
    from baker.cli.main import main

    monkeypatch.setattr(parts, "PART_TEXELS", 500)  # the 2,566 dirty texels make 6 parts
    settings = dict(rays=16, page_size=128)
    edited, local, remote = _rebakes(tmp_path, settings)
    here = baker.bake(edited, local, baker.Settings(**settings), incremental="always")
    assert main(["rebake", str(edited), "-o", str(remote), "--cluster", ray_cluster.address,
                 "--report", str(tmp_path / "report.json")]) == 0
    _same_bake(local, remote)
    full = tmp_path / "full" / "baked.glb"
    baker.bake(edited, full, baker.Settings(**settings))
    assert full.read_bytes() == remote.read_bytes()
    assert Path(f"{full}.bake").read_bytes() == Path(f"{remote}.bake").read_bytes()
    report = json.loads((tmp_path / "report.json").read_text())
    dirty = report["rebake"]["dirty_texels"]
    assert report["rebake"]["incremental"] and dirty == here.rebake["dirty_texels"] > 4 * 500
    assert report["rebake"]["rays"] == here.rebake["rays"]
    on = report["cluster"]
    assert on["parts"] == len(parts.part_slices(dirty))  # no light placed anew: the dirty rows
    assert sum(w["texels"] for w in on["workers"].values()) == dirty
    assert {"receive", "trace", "direct"} <= set(on["worker_stage_seconds"])
    line = next(line for line in capsys.readouterr().out.splitlines() if "on the cluster" in line)
    for name, worker in on["workers"].items():
        assert f"{name} {worker['texels']:,} texels" in line


def test_more_threads_a_part_than_a_worker_has_is_a_clear_error(ray_cluster, tmp_path):
    source = cornell_box().save(tmp_path / "cornell.glb")
    with pytest.raises(baker.SettingsError, match="largest node of the cluster has 1"):
        baker.bake(source, tmp_path / "baked.glb",
                   baker.Settings(cluster=ray_cluster.address, threads=2, page_size=128))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cornell.glb"]


def _kill_first_part(cluster: LocalCluster, killed: list, stop: threading.Event) -> None:
    """SIGKILL the first worker process of ``cluster`` seen running a part
    (``_part_processes``), at once: a part of a node whose world is built takes well under a
    second, and a kill after it ended would lose nothing."""
    while not stop.is_set():
        running = _part_processes(cluster)
        if running:
            os.kill(running[0], signal.SIGKILL)
            killed.append(running[0])
            return
        time.sleep(0.02)


def _with_a_worker_killed(cluster: LocalCluster, bake) -> "baker.BakeResult":
    """``bake()``'s result, the first worker process of ``cluster`` seen running a part
    SIGKILLed meanwhile (``_kill_first_part``); asserts that one was, that the part it lost was
    run again, and that every texel is counted once: the killed worker only for the parts it
    had finished (how many depends on the machine's pace)."""
    killed, stop = [], threading.Event()
    killer = threading.Thread(target=_kill_first_part, args=(cluster, killed, stop))
    killer.start()
    try:
        result = bake()
    finally:
        stop.set()
        killer.join()
    assert killed, "no worker was seen running a part"
    rebaked = result.rebake or {}
    texels = rebaked["dirty_texels"] if rebaked.get("incremental") else result.texels
    assert sum(w["texels"] for w in result.report["cluster"]["workers"].values()) == texels
    again = result.report["cluster"]["parts_run_again"]  # the part lost, and its worker
    assert again and all("Worker" in lost["error"] or "Node" in lost["error"] for lost in again)
    return result


@pytest.mark.long
def test_a_worker_killed_in_a_part_leaves_the_bytes_as_they_were(ray_cluster, small_parts,
                                                                   tmp_path):
    source = cornell_box().save(tmp_path / "cornell.glb")
    settings = dict(rays=256, page_size=128)
    local, remote = _outputs(tmp_path)
    baker.bake(source, local, baker.Settings(**settings))
    _with_a_worker_killed(ray_cluster, lambda: baker.bake(source, remote, baker.Settings(
        cluster=ray_cluster.address, **settings)))
    _same_bake(local, remote)


@pytest.mark.long
def test_a_worker_killed_in_a_rebake_leaves_the_bytes_as_they_were(ray_cluster, small_parts,
                                                                     tmp_path):
    settings = dict(rays=256, page_size=128)
    edited, local, remote = _rebakes(tmp_path, settings)
    baker.bake(edited, local, baker.Settings(**settings), incremental="always")
    result = _with_a_worker_killed(ray_cluster, lambda: baker.bake(edited, remote, baker.Settings(
        cluster=ray_cluster.address, **settings), incremental="always"))
    assert result.rebake["incremental"], result.rebake.get("full_bake_reason")
    _same_bake(local, remote)
    on = result.report["cluster"]
    assert sum(w["texels"] for w in on["workers"].values()) == result.rebake["dirty_texels"]


@pytest.mark.long
def test_ctrl_c_leaves_no_output_and_the_cluster_as_it_was(ray_cluster, tmp_path):
    source = cornell_box().save(tmp_path / "cornell.glb")
    deadline = time.monotonic() + 60  # an earlier test's worker may still be named for its part:
    while _part_processes(ray_cluster):  # the signal would then reach a driver still starting
        assert time.monotonic() < deadline, _part_processes(ray_cluster)
        time.sleep(0.2)
    script = ("import signal, sys\n"  # Ctrl-C as a terminal sends it
              "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
              "from baker.cli.main import main\n"
              "sys.exit(main(sys.argv[1:]))\n")
    process = subprocess.Popen(
        [sys.executable, "-c", script, "bake", str(source), "-o", str(tmp_path / "baked.glb"),
         "--rays", "4096", "--page-size", "128", "--cluster", ray_cluster.address],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not _part_processes(ray_cluster):
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.05)
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=60)
    assert process.returncode == 130, err
    assert err.strip().endswith("baker: interrupted; no output was changed")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cornell.glb"]
    deadline = time.monotonic() + 30  # the cluster: both workers there, their CPUs free again
    while _free_cpus(ray_cluster.address) != (2, 2.0):
        assert time.monotonic() < deadline, _free_cpus(ray_cluster.address)
        time.sleep(0.5)
    assert not _part_processes(ray_cluster)


def _part_processes(cluster: LocalCluster) -> list[int]:
    """The worker processes of ``cluster`` running a part (Ray names them ``ray::_run_part``
    while they do; other clusters on this machine, of other test runs, are left out)."""
    pids = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            running = Path(f"/proc/{pid}/cmdline").read_bytes().startswith(b"ray::_run_part")
            if running and os.getsid(int(pid)) in cluster.sessions():
                pids.append(int(pid))
        except OSError:
            pass
    return pids


def _free_cpus(address: str) -> tuple[int, float]:
    """(live nodes with CPUs, CPUs free) of the cluster, asked from a child process."""
    script = ("import ray, sys; ray.init(address=sys.argv[1], logging_level='ERROR', "
              "log_to_driver=False); print(sum(n['Alive'] and n['Resources'].get('CPU', 0) > 0 "
              "for n in ray.nodes()), ray.available_resources().get('CPU', 0.0))")
    run = subprocess.run([sys.executable, "-c", script, address], capture_output=True,
                         text=True, check=True, cwd="/")
    nodes, cpus = run.stdout.split()[-2:]
    return int(nodes), float(cpus)


def test_an_unreachable_cluster_is_a_clear_error_before_any_work(tmp_path):
    address = f"127.0.0.1:{free_port()}"
    source = cornell_box().save(tmp_path / "cornell.glb")
    with pytest.raises(baker.SettingsError, match=f"no Ray cluster answers at {address}"):
        baker.bake(source, tmp_path / "baked.glb", baker.Settings(cluster=address))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cornell.glb"]


def test_an_unreachable_cluster_stops_a_rebake_before_any_work(tmp_path, capsys):
    from baker.cli.main import main

    edited, local, _ = _rebakes(tmp_path, dict(rays=4, page_size=128))
    before = {p.name: p.read_bytes() for p in local.parent.iterdir()}
    address = f"127.0.0.1:{free_port()}"
    assert main(["rebake", str(edited), "-o", str(local), "--cluster", address]) == 1
    assert f"no Ray cluster answers at {address}" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in local.parent.iterdir()} == before


class _NotAHead:
    """A server on loopback that is not a Ray head: it answers every connection once with
    ``reply`` (an HTTP/1 error page, or an HTTP/2 SETTINGS frame and nothing after), then
    hangs up; stops with the block."""

    def __init__(self, reply: bytes):
        import socket

        self.reply = reply
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.listener.settimeout(0.2)
        self.address = f"127.0.0.1:{self.listener.getsockname()[1]}"
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._serve, daemon=True)

    def _serve(self) -> None:
        import socket

        while not self.stop.is_set():
            try:
                connection, _ = self.listener.accept()
            except socket.timeout:
                continue
            with connection:
                try:
                    connection.settimeout(2.0)
                    connection.recv(1 << 16)
                    connection.sendall(self.reply)
                except OSError:
                    pass

    def __enter__(self) -> "_NotAHead":
        self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop.set()
        self.thread.join()
        self.listener.close()


@pytest.mark.parametrize("reply", [
    pytest.param(b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\n\r\n", id="http1"),
    pytest.param(bytes([0, 0, 0, 4, 0, 0, 0, 0, 0]), id="http2 but not ray",
                 marks=pytest.mark.long)])  # a gRPC server given up after 15 s
def test_something_else_at_the_address_is_a_clear_error_within_30_s(tmp_path, reply):
    """A server that is not a Ray head at the address (the README's example address often
    is one: a proxy): exit 1 within 30 s with a message naming the address, not Ray's log
    lines, nothing written."""
    source = cornell_box().save(tmp_path / "cornell.glb")
    with _NotAHead(reply) as server:
        started = time.monotonic()
        run = subprocess.run([sys.executable, "-m", "baker.cli.main", "bake", str(source), "-o",
                              str(tmp_path / "baked.glb"), "--cluster", server.address],
                             capture_output=True, text=True, cwd=ROOT, timeout=60)
        seconds = time.monotonic() - started
    assert run.returncode == 1 and seconds < 30, (run.returncode, seconds, run.stderr)
    assert f"no Ray cluster answers at {server.address}" in run.stderr
    assert not re.search(r"gcs_client|\.cc:\d+|Traceback", run.stderr), run.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cornell.glb"]


@pytest.mark.long
def test_the_head_lost_mid_bake_is_exit_1_with_a_word_and_no_rows_left(tmp_path):
    """The head of a cluster of its own killed mid-bake (its session: GCS and all): Ray ends
    the driver (exit 1); the spill's watcher removes the rows it left and says why; nothing is
    written. (Measured: exit 1.1–2.5 s after the kill.) The driver's standard error goes to a
    file, read at the end: a pipe nobody reads while the test waits would stop the driver
    once Ray's log lines filled it."""
    source = cornell_box().save(tmp_path / "cornell.glb")
    out = tmp_path / "out"
    out.mkdir()
    said = tmp_path / "stderr.txt"
    with LocalCluster(workers=1) as cluster, open(said, "wb") as stderr:
        bake = subprocess.Popen([sys.executable, "-m", "baker.cli.main", "bake", str(source),
                                 "-o", str(out / "baked.glb"), "--cluster", cluster.address,
                                 "--rays", "512", "--page-size", "256"],
                                stdout=subprocess.DEVNULL, stderr=stderr, cwd=ROOT)
        deadline = time.monotonic() + 120
        while (not list(out.glob(".baker-spill-*")) and bake.poll() is None
               and time.monotonic() < deadline):
            time.sleep(0.05)
        assert list(out.glob(".baker-spill-*")), f"the bake made no spill: {said.read_text()}"
        time.sleep(1.0)  # parts running
        os.killpg(cluster._head.pid, signal.SIGKILL)
        cluster._head.wait()
        cluster._head = None
        try:
            bake.wait(timeout=90)
        finally:
            bake.kill()
    said = said.read_text()
    assert bake.returncode == 1, said
    assert "the bake ended abruptly" in said and "cluster's head was lost" in said
    assert list(out.iterdir()) == []


def test_foliage_on_a_cluster_is_refused_before_any_work(tmp_path):
    source = cornell_box().save(tmp_path / "cornell.glb")
    with pytest.raises(baker.SettingsError, match="--foliage approx does not run on a cluster"):
        baker.bake(source, tmp_path / "baked.glb",
                   baker.Settings(cluster="127.0.0.1:1", foliage="approx"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cornell.glb"]


def test_without_ray_the_cluster_asks_for_the_extra(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray fails, as when not installed
    source = cornell_box().save(tmp_path / "cornell.glb")
    with pytest.raises(baker.SettingsError, match="needs Ray") as error:
        baker.bake(source, tmp_path / "baked.glb", baker.Settings(cluster="127.0.0.1:1"))
    assert 'pip install "baker[cluster]"' in str(error.value)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cornell.glb"]


@pytest.mark.long
def test_a_worker_with_another_baker_is_named_before_any_work(ray_cluster, tmp_path,
                                                                monkeypatch):
    """A third node whose Python finds a copy of baker with one line added: the bake stops
    before any part, naming the node and what differs. (Ray puts the driver's working folder
    first on its workers' paths, so the driver runs from one without baker in it.)"""
    code = tmp_path / "code"
    shutil.copytree(ROOT / "baker", code / "baker", ignore=shutil.ignore_patterns("__pycache__"))
    with open(code / "baker" / "image" / "compose.py", "a") as changed:
        changed.write("# another version\n")
    source = cornell_box().save(tmp_path / "cornell.glb")
    (tmp_path / "run").mkdir()
    monkeypatch.chdir(tmp_path / "run")
    other = ray_cluster.add_worker(1, code=code)
    try:
        with pytest.raises(baker.SettingsError, match="runs another baker than this one") as error:
            baker.bake(source, tmp_path / "baked.glb",
                       baker.Settings(cluster=ray_cluster.address, page_size=128))
    finally:
        ray_cluster.stop_worker(other)
    message = str(error.value)
    assert re.match(rf"node \S+ \(\S+\) of the cluster at {ray_cluster.address} runs", message)
    assert "baker code" in message
    assert "python" not in message.split("fix:")[0]  # only what differs is named
    assert not (tmp_path / "baked.glb").exists()
