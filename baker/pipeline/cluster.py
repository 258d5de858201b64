"""A bake's parts, or a rebake's traced texels, run as Ray tasks on a running cluster
(``baker bake --cluster ADDRESS``, ``baker rebake --cluster ADDRESS``).

A bake is cut into parts whose results depend only on their texels' keys (``parts.py``), about
four for each worker of the cluster (``part_texels``): that is the unit sent to the cluster. ``run_parts`` is the
one dispatcher: it puts a ``Work`` (what every part needs) into Ray's object store once, asks
for the parts as tasks, each carrying only its own input, and gives their results back in
order, whatever order they finish in, counting which worker made what (``Session``). Each node
may make something of the shipped work once, shared by its worker processes through its object
store (``Work.node``); a worker process makes it ready once (``_ready``: Embree's scene) and
runs the part function on each part it is given.

A full bake (``parts``): the driver (the process that runs ``baker``) loads the scene, has the
workers chart its distinct meshes (``chart_on_workers``), packs their charts and rasterises as a
local bake does, ships what every part needs (``_shipped``: the scene
as the file has it, resolved settings, light sources, I_A, atlas, which triangles own texels;
each node builds the world and what derives from it once, ``_node_bake``) and sends each part
only its texels' coverage rows; the worker runs the same part function as a local bake
(``full._bake_part``) and sends back the part's results less what the driver can make itself
(``_BakedRemotely``), so that the driver composes, spills and writes exactly as a local bake
does: the same bytes whatever the workers and their threads. A rebake's parts are its dirty
texels (``rebake.retrace``), through the same dispatcher.

Faults: a part whose worker process dies (SIGKILL, a machine lost) is asked for again, and runs
on whichever worker is free (``_RETRIES``; the report lists such parts and what Ray said was
lost); Ctrl-C on the driver cancels the parts not done and leaves the cluster
running, with nothing of the bake on it. Before any part, every node that has CPUs runs an
identity function (``baker.api.cluster_identity``) and must report the driver's: the same code
of baker, Python and libraries.

Ray is an optional extra (``pip install "baker[cluster]"``), imported only here and only when a
bake asks for a cluster.
"""

from __future__ import annotations

import logging
import os
import platform
import socket
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from typing import Callable, Iterator

import numpy as np
from isal import isal_zlib

from baker.atlas.charts import balanced, chart_list
from baker.atlas.rasterise import Coverage, owners_of, owning_triangles, texels_of
from baker.atlas.validity import Faces
from baker.errors import SettingsError
from baker.geometry.world import build_world
from baker.light.hemisphere import surfaces_of
from baker.pipeline import parts as parts_module
from baker.pipeline.parts import TexelPoints
from baker.rays.trace import Tracer

INSTALL = 'pip install "baker[cluster]"'
_RETRIES = 4  # times a part is asked for again whose worker process or node was lost
_PARTS_A_WORKER = 4  # parts of a bake for each worker of the cluster (``part_texels``)
_LEAST_PART = 4096  # texels: the least a part of a bake holds on a cluster
_AHEAD = 4  # parts ended and not taken, at most, for each part running (``run_parts``)
_REACH_SECONDS = 5.0  # how long to wait for the head's port to answer
_IDENTITY_SECONDS = 120.0  # how long each node may take to start a worker and answer
_WAIT_SECONDS = 0.1  # how often the driver looks at the parts (progress, Ctrl-C)
_ASKS = 8  # times Ray asks a head for its cluster's identity, a second apart (``_ray``)
_CONNECT_SECONDS = 15.0  # how long Ray may take to connect to a head that answers
_LIBRARIES = ("ray", "numpy", "numba", "embreex", "xatlas")


def _ray():
    """The ``ray`` module, or a SettingsError saying how to install it. Ray asks an address for
    its cluster's identity ``_ASKS`` times, a second apart (its default: 20), before it gives
    up: set before Ray is first imported (it reads it then), unless the user set it."""
    os.environ.setdefault("RAY_NUM_REDIS_GET_RETRIES", str(_ASKS))
    try:
        import ray
    except ImportError:
        raise SettingsError("--cluster needs Ray, which is not installed",
                            fix=f"{INSTALL} on this machine and on every machine of the "
                                "cluster") from None
    return ray


def versions() -> dict[str, str]:
    """Python's and the libraries' versions here: with baker's own code (``api``'s
    ``cluster_identity``), what must be the same on the driver and every worker for their
    texels to be the same bits. (importlib.metadata is imported here, for a cluster's bake
    only: 0.02 s of every command's start else.)"""
    from importlib import metadata

    out = {"python": platform.python_version()}
    for name in _LIBRARIES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "(not installed)"
    return out


def _node_identity(identity: Callable[[], dict[str, str]]) -> dict:
    """``identity()`` of the node this runs on, with its host name (run as a Ray task)."""
    return {"host": socket.gethostname(), "identity": identity()}


@dataclass
class Session:
    """A connection to a Ray cluster at ``address``, whose nodes run the driver's baker, and
    the account of the parts run on it (``report``).

    threads: the CPUs each part takes on a worker; workers: per worker ("host ip pid"), texels
    and parts it baked; worker_seconds: the stages' seconds summed over the workers (the part
    functions' stages, "receive": fetching the shipped work and building Embree's scene);
    sent/received: array bytes to and from the workers per part (the shipped work once:
    ``shipped_bytes``); parts_run: parts the driver took; lost: each part lost with its worker
    (process or node) and asked for again: the part and Ray's word on what was lost;
    charted: distinct meshes the workers charted (``chart_on_workers``)."""

    address: str
    cpus: int
    nodes: int
    connected_here: bool
    threads: int
    workers: dict[str, dict[str, int]] = field(default_factory=dict)
    worker_seconds: dict[str, float] = field(default_factory=dict)
    shipped_bytes: int = 0
    sent: int = 0
    received: int = 0
    parts_run: int = 0
    lost: list[dict] = field(default_factory=list)
    charted: int = 0

    def report(self) -> dict:
        """The JSON-able ``cluster`` entry of the bake's report."""
        return {"address": self.address, "nodes": self.nodes, "cpus": self.cpus,
                "parts": self.parts_run, "workers": self.workers,
                "worker_stage_seconds": self.worker_seconds,
                "shipped_bytes": self.shipped_bytes, "bytes_to_workers": self.sent,
                "bytes_from_workers": self.received, "parts_run_again": self.lost,
                "meshes_charted": self.charted}

    def took(self, returned: "_Returned", texels: int) -> None:
        """Count a part of ``texels`` texels the driver took: its worker's texels and parts,
        its stages' seconds there, and the bytes it sent back."""
        worker = self.workers.setdefault(returned.worker, {"texels": 0, "parts": 0})
        worker["texels"] += texels
        worker["parts"] += 1
        for name, seconds in returned.seconds.items():
            self.worker_seconds[name] = self.worker_seconds.get(name, 0.0) + seconds
        self.received += _array_bytes(returned.value)
        self.parts_run += 1


_current: Session | None = None


@contextmanager
def session(address: str | None, threads: int, identity: Callable[[], dict[str, str]]
            ) -> Iterator[Session | None]:
    """Connect to the cluster at ``address`` ("host:port" of its head) and check its nodes
    (``connect``: parts of ``threads`` CPUs, ``Settings.threads``, 0 for 1; ``identity``) for
    the block, in which a bake's parts find it (``current``); None for no address."""
    global _current
    if address is None:
        yield None
        return
    opened = connect(address, max(1, threads), identity)
    _current = opened
    try:
        yield opened
    finally:
        _current = None
        if opened.connected_here:
            _ray().shutdown()


def connect(address: str, threads: int, identity: Callable[[], dict[str, str]]) -> Session:
    """Connect this process to the Ray cluster whose head is at ``address`` and check, before
    any work, that it can bake parts of ``threads`` CPUs each: the head answers, some node has
    that many CPUs, and every node with CPUs gives the driver's ``identity()`` (a module-level
    function, which Ray sends by name: the workers run their own baker's). A SettingsError
    names what is wrong."""
    ray = _ray()
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise SettingsError(f"--cluster {address!r} is not HOST:PORT",
                            fix="give the address `ray start --head` printed, e.g. "
                                "10.0.0.1:6379")
    try:
        answer = _first_frame(host, int(port))
    except OSError as error:
        raise SettingsError(f"no Ray cluster answers at {address} ({error.strerror or error})",
                            fix=f"start one with `ray start --head --port {port}` on {host}, "
                                "or give the address of a running head") from None
    if len(answer) < 9 or answer[3] != _SETTINGS_FRAME:
        raise SettingsError(f"no Ray cluster answers at {address}: something listens there, "
                            f"but not a Ray head (it does not speak gRPC)",
                            fix=f"give the address `ray start --head` printed on the head (its "
                                f"GCS port, 6379 by default), or start one with `ray start "
                                f"--head --port {port}` on {host}")
    connected_here = not ray.is_initialized()
    if connected_here:
        try:
            with _stderr_kept(dropped := []):
                _within(_CONNECT_SECONDS, lambda: ray.init(
                    address=address, logging_level=logging.WARNING, log_to_driver=False,
                    configure_logging=True))
        except (ConnectionError, RuntimeError, TimeoutError) as error:
            said = f" ({dropped[0]})" if dropped else ""
            raise SettingsError(
                f"no Ray cluster answers at {address}: something listens there, but no Ray "
                f"head ({error or type(error).__name__}){said}",
                fix=f"give the address `ray start --head` printed on the head (its GCS port, "
                    f"6379 by default), or start one with `ray start --head --port {port}` on "
                    f"{host}") from None
    try:
        nodes = _baking_nodes(ray)
        if not nodes:
            raise SettingsError(f"the Ray cluster at {address} has no node with CPUs to bake on",
                                fix=f"start workers with `ray start --address {address}` on the "
                                    "machines that should bake")
        _check_nodes(ray, address, nodes, identity)
        largest = max(int(n["Resources"]["CPU"]) for n in nodes)
        if threads > largest:
            raise SettingsError(f"each part asks for {threads} CPUs of one worker (--threads), "
                                f"and the largest node of the cluster has {largest}",
                                fix=f"give --threads {largest} or less, or start workers with "
                                    f"`ray start --address {address} --num-cpus {threads}`")
    except BaseException:
        if connected_here:
            ray.shutdown()
        raise
    return Session(address, sum(int(n["Resources"]["CPU"]) for n in nodes), len(nodes),
                   connected_here, threads)


def _baking_nodes(ray) -> list[dict]:
    """The cluster's live nodes that have CPUs (``ray.nodes()``'s entries)."""
    return [n for n in ray.nodes() if n["Alive"] and n["Resources"].get("CPU", 0) > 0]


def _within(seconds: float, call: Callable[[], object]) -> object:
    """``call()``'s value, or its error, if it ends within ``seconds``; else TimeoutError
    (the call goes on in a daemon thread: Ray's connection to a server that speaks gRPC but
    is no Ray head retries for minutes, past any timeout it takes)."""
    import threading

    outcome: list = []

    def run() -> None:
        try:
            outcome.append((True, call()))
        except BaseException as error:  # handed to the caller's thread
            outcome.append((False, error))

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(seconds)
    if not outcome:
        raise TimeoutError(f"no answer in {seconds:.0f} s")
    ok, value = outcome[0]
    if not ok:
        raise value
    return value


_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])
_SETTINGS_FRAME = 4  # an HTTP/2 frame's type, its header's fourth byte


def _first_frame(host: str, port: int) -> bytes:
    """The first bytes (up to an HTTP/2 frame header's 9) that ``host:port`` answers to an
    HTTP/2 client's preface and empty SETTINGS frame within ``_REACH_SECONDS``: a Ray head's
    GCS (gRPC) answers with its own SETTINGS frame at once; anything else (another server, or
    none that answers) would keep Ray's connection retrying for minutes. OSError when nothing
    accepts the connection."""
    with socket.create_connection((host, port), timeout=_REACH_SECONDS) as connection:
        connection.sendall(_PREFACE)
        answer = b""
        try:
            while len(answer) < 9:
                part = connection.recv(9 - len(answer))
                if not part:
                    break
                answer += part
        except (socket.timeout, ConnectionError):
            pass
        return answer


@contextmanager
def _stderr_kept(dropped: list[str]) -> Iterator[None]:
    """Send what is written to this process's standard error (file descriptor 2: Ray's C++
    core logs there, a line a second while it waits for a head that does not answer) to a
    file for the block, and put its last line in ``dropped`` instead of on the terminal."""
    import tempfile

    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as kept:
        os.dup2(kept.fileno(), 2)
        try:
            yield
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            kept.seek(0)
            lines = kept.read().decode(errors="replace").strip().splitlines()
            dropped.extend(lines[-1:])


def _check_nodes(ray, address: str, nodes: list[dict], identity: Callable) -> None:
    """Run ``_node_identity(identity)`` on each of ``nodes`` and raise a SettingsError naming
    the first node whose baker cannot run, or differs from the driver's, and what differs."""
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    task = ray.remote(num_cpus=0, max_retries=0)(_node_identity)
    asks = [task.options(scheduling_strategy=NodeAffinitySchedulingStrategy(
        n["NodeID"], soft=False)).remote(identity) for n in nodes]
    mine = identity()
    fix = (f"install the driver's baker ({INSTALL} from the same source, the same Python and "
           "libraries) on every machine of the cluster, then restart its workers")
    for node, ask in zip(nodes, asks):
        where = f"node {node['NodeManagerAddress']}"
        try:
            theirs = ray.get(ask, timeout=_IDENTITY_SECONDS)
        except Exception as error:
            raise SettingsError(f"baker cannot run on {where} of the cluster at {address}: "
                                f"{type(error).__name__}: {str(error).splitlines()[0]}",
                                fix=fix) from None
        differs = [f"{name} {theirs['identity'].get(name, '(none)')} there, {value} here"
                   for name, value in mine.items() if theirs["identity"].get(name) != value]
        if differs:
            raise SettingsError(f"{where} ({theirs['host']}) of the cluster at {address} runs "
                                f"another baker than this one: {'; '.join(differs)}", fix=fix)


def current() -> Session:
    """The session a bake runs in (``session``, which ``baker.bake`` opens)."""
    if _current is None:
        raise SettingsError("a bake on a cluster runs through baker.bake, which checks the "
                            "cluster's workers first",
                            fix="call baker.bake with Settings(cluster=...), or leave cluster "
                                "None to compute on this machine")
    return _current


@dataclass(frozen=True)
class Work:
    """What a cluster runs, part by part, for a bake or a rebake: ``shipped`` goes into the
    object store once; with a ``node`` function, each node makes ``node(shipped)`` once, into
    its own object store, which its worker processes share read-only (``_made_on_nodes``);
    each worker process makes it ready once (``ready(made)``, ``made`` the node's value, or
    ``shipped`` without a ``node``: what cannot be shared, such as Embree's scene, built there);
    then each part is ``run(ready, item, seconds)``, ``item`` the part's own input, ``seconds``
    the worker's stages. ``node``, ``ready`` and ``run`` are module-level functions, which Ray
    sends by name."""

    shipped: object
    ready: Callable[[object], object]
    run: Callable[[object, object, dict[str, float]], object]
    node: Callable[[object], object] | None = None


@dataclass(frozen=True)
class _Returned:
    """A part's result as a worker sends it back: ``Work.run``'s ``value``, with the worker
    that made it ("host ip pid") and the part's stages there (seconds)."""

    value: object
    worker: str
    seconds: dict[str, float]


def part_texels(count: int) -> int:
    """Texels a part of a bake of ``count`` texels holds on the current session: about
    ``_PARTS_A_WORKER`` parts for each worker (its CPUs over the CPUs a part takes), so that a
    slow part or a lost worker holds up little of the bake, and the workers that end first
    take the rest; at least ``_LEAST_PART`` texels (a part's own costs) and at most
    ``parts.PART_TEXELS``."""
    account = current()
    workers = max(1, account.cpus // account.threads)
    return int(min(parts_module.PART_TEXELS,
                   max(_LEAST_PART, -(-count // (_PARTS_A_WORKER * workers)))))


def chart_on_workers(meshes: list, steps) -> list:
    """Each mesh's charts (``atlas.charts.chart_many``: ``Charts``), made by tasks on the current
    session's workers, in order: the meshes dealt by triangles into about
    ``_PARTS_A_WORKER`` groups a worker, each group a task of one CPU, run again where its
    worker is lost (Ray's retries). Charting is a pure function of a mesh, so the atlas the
    driver packs from them has the same bits as one charted here. ``steps`` (``Steps``): the
    triangles charted, as the groups end."""
    ray, account = _ray(), current()
    task = ray.remote(num_cpus=1, max_retries=_RETRIES)(chart_list)
    counts = [len(triangles) for _positions, triangles in meshes]
    order = sorted(range(len(meshes)), key=lambda m: (-counts[m], m))
    groups = balanced(order, [counts[m] for m in order], _PARTS_A_WORKER * account.cpus)
    steps.expect(sum(counts))
    refs = {task.remote([meshes[m] for m in group]): group for group in groups}
    out: list = [None] * len(meshes)
    pending = list(refs)
    while pending:
        done, pending = ray.wait(pending, num_returns=1)
        for ref in done:
            for m, charts in zip(refs[ref], ray.get(ref)):
                out[m] = charts
            steps.advance(sum(counts[m] for m in refs[ref]))
    account.charted += len(meshes)
    return out


def run_parts(work: Work, sizes: list[int], item: Callable[[int], object],
              times: dict[str, float], advance: Callable[[int], None]) -> Iterator:
    """``work.run``'s results for the parts ``item(k)`` of ``sizes[k]`` texels, in order, each
    made on a worker of the current session with ``Settings.threads`` CPUs (the ``threads``
    the session was opened with). ``advance(texels)`` as each part ends, in any order (the
    progress bar). As many parts run as the cluster has workers, twice over, each asked for
    as one ends, whichever it is: a slow part does not hold the others up; results wait on
    the workers' nodes until the driver takes them, in order, one at a time. ``times`` gets
    the driver's "trace", the time it waited for parts (so rays/s are the cluster's), and
    "ship", putting ``work.shipped`` in the object store. A part whose worker is lost (its
    process killed, its machine gone) is asked for again, up to ``_RETRIES`` times, and the
    session notes it (``Session.lost``); an error or Ctrl-C cancels the parts not taken."""
    ray, account = _ray(), current()
    task = ray.remote(num_cpus=account.threads, max_retries=0)(_run_part)
    start = time.perf_counter()
    shipped = ray.put(work.shipped)
    made = {} if work.node is None else _made_on_nodes(ray, work.node, shipped)
    box = [replace(work, shipped=shipped), made]  # in a list: Ray hands references over
    account.shipped_bytes += _array_bytes(work.shipped)
    _add_seconds(times, "ship", start)
    running = max(2, 2 * account.cpus // account.threads)
    asked: dict[int, object] = {}  # part → its task's reference, until the driver takes it
    pending: dict[object, int] = {}  # a reference not yet ended → its part
    tries = [0] * len(sizes)

    def ask(k: int) -> None:
        given = item(k)
        account.sent += _array_bytes(given)
        asked[k] = task.remote(box, given)
        pending[asked[k]] = k

    following = [0]  # the next part to ask for

    def fill(taken: int) -> None:
        """Keep ``running`` parts going, the next ones in order, at most ``_AHEAD`` times as
        many beyond part ``taken`` (the next the driver takes) waiting to be taken."""
        while (len(pending) < running and following[0] < len(sizes)
               and following[0] - taken < _AHEAD * running):
            ask(following[0])
            following[0] += 1

    try:
        for index in range(len(sizes)):
            fill(index)
            waited = time.perf_counter()
            while True:
                _wait_for(ray, asked[index], pending, sizes, advance, lambda: fill(index))
                try:
                    returned = ray.get(asked[index])
                    break
                except _lost_errors(ray) as error:
                    tries[index] += 1
                    account.lost.append({"part": index, "error": _first_line(error)})
                    if tries[index] > _RETRIES:
                        raise
                    ask(index)
            del asked[index]
            _add_seconds(times, "trace", waited)
            account.took(returned, sizes[index])
            yield returned.value
    except BaseException:  # an error or Ctrl-C: no part of this run goes on running
        for ref in asked.values():
            ray.cancel(ref, force=True)
        raise


def _lost_errors(ray) -> tuple[type, ...]:
    """The errors of a part whose worker process or node was lost (not of the part itself)."""
    from ray import exceptions

    return tuple(getattr(exceptions, name) for name in (
        "WorkerCrashedError", "NodeDiedError", "OwnerDiedError", "ObjectLostError",
        "TaskUnschedulableError") if hasattr(exceptions, name))


def _first_line(error: BaseException) -> str:
    """The first line of ``error``'s message, with its type (what the report says of it)."""
    text = str(error).strip().splitlines()
    return f"{type(error).__name__}: {text[0] if text else ''}"


def _wait_for(ray, wanted, pending: dict, sizes: list[int], advance: Callable[[int], None],
              ended: Callable[[], None]) -> None:
    """Wait for the part ``wanted`` to end, advancing the progress by the texels of every part
    that ends meanwhile (``pending``: reference → its part, not yet ended; ``sizes``: each
    part's texels) and calling ``ended()`` (to ask for more). The results stay on the nodes
    that made them until the driver takes them (``ray.get``)."""
    while wanted in pending:
        done, _ = ray.wait(list(pending), num_returns=1, timeout=_WAIT_SECONDS,
                           fetch_local=False)
        for ref in done:
            advance(sizes[pending.pop(ref)])
        if done:
            ended()


def _made_on_nodes(ray, node: Callable[[object], object], shipped) -> dict:
    """``node(shipped)`` made once on each node with CPUs, by a task of no CPU pinned to it:
    node id → the reference of its value, which stays in that node's object store, where the
    node's worker processes read its arrays without a copy (``_ready``)."""
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    task = ray.remote(num_cpus=0, max_retries=_RETRIES)(node)
    return {n["NodeID"]: task.options(scheduling_strategy=NodeAffinitySchedulingStrategy(
        n["NodeID"], soft=False)).remote(shipped) for n in _baking_nodes(ray)}


_READY: dict = {}  # in a worker process: the shipped work's reference → (work, its ready value)


def _ready(box: list, seconds: dict[str, float]) -> tuple[Work, object]:
    """In a worker, the ``Work`` ``box[0]`` (its ``shipped`` a reference) and its ready value,
    made once per process and kept for the next parts; a new run's replaces the last one's (a
    worker holds one scene). With a ``node`` function, what this node made of the shipped work
    (``box[1]``: node id → reference), or, on a node that joined after the run began, made
    here."""
    work, made = box
    key = work.shipped.hex()
    if key not in _READY:
        started = time.perf_counter()
        _READY.clear()
        ray = _ray()
        here = ray.get_runtime_context().get_node_id()
        if work.node is None:
            value = ray.get(work.shipped)
        else:
            value = ray.get(made[here]) if here in made else work.node(ray.get(work.shipped))
        _READY[key] = work, work.ready(value)
        seconds["receive"] = time.perf_counter() - started
    return _READY[key]


def _run_part(box: list, item) -> _Returned:
    """A Ray task: one part, ``item``, of the work ``box[0]`` (``run_parts``, ``_ready``)."""
    seconds: dict[str, float] = {}
    work, ready = _ready(box, seconds)
    value = work.run(ready, item, seconds)
    worker = f"{socket.gethostname()} {_ray().util.get_node_ip_address()} pid {os.getpid()}"
    return _Returned(value, worker, seconds)


def parts(part: Callable, baking, slices: list[slice], times: dict[str, float],
          advance: Callable[[int], None]) -> Iterator:
    """A full bake's parts: ``part``'s results (``full.BakedPart``) for the texels ``slices``
    of ``baking`` (``full.Baking``), in order, each made on a worker (``run_parts``); each
    part sends only its texels' coverage rows and gets back the part less its texels, which
    the driver makes again (``_received``: "rasterise" in ``times``)."""
    coverage = baking.coverage
    work = Work(_shipped(part, baking), _ready_bake, _bake_part, _node_bake)
    made = run_parts(work, [s.stop - s.start for s in slices],
                     lambda k: (coverage.key[slices[k]], coverage.triangle[slices[k]]),
                     times, advance)
    for rows, returned in zip(slices, made):
        yield _received(baking, rows, returned, times)


@dataclass(frozen=True)
class _BakedRemotely:
    """What a worker sends back of a full bake's part: the part function's ``BakedPart`` less
    its texels and points, which the driver makes again from the coverage (``texels_of``, as
    ``parts.PerTexel`` does), with the sample points the probes moved. moved: (m,) int64 rows
    within the part whose sample point moved, to ``moved_position`` (m, 3) world."""

    part: object
    moved: np.ndarray
    moved_position: np.ndarray


def _received(baking, rows: slice, returned: _BakedRemotely, times: dict[str, float]):
    """A worker's part as ``full._bake_part`` gives it locally: the texels made again from
    their coverage and their moved points put back, with what the state keeps of them
    (``TexelPoints``)."""
    start = time.perf_counter()
    made = texels_of(baking.atlas, baking.world, baking.coverage, rows, baking.owned)
    position = made.position.copy()
    position[returned.moved] = returned.moved_position
    texels = replace(made, position=position)
    points = TexelPoints.of(texels, made.position)
    _add_seconds(times, "rasterise", start)
    return replace(returned.part, texels=texels, points=points)


@dataclass(frozen=True)
class _ShippedBake:
    """What every node of a full bake's cluster receives once (``_shipped``): the part
    function; the bake (``full.Baking``) without its world (the scene as the file has it:
    distinct meshes and each instance's matrix, ``_read_scene``), what the texels take from their triangles,
    Embree's scene, the back faces, the surfaces and the texels' coverage rows; which world
    triangles own texels (``owns``: ``np.packbits`` of (T,) bool); and ``crc``, the CRC-32 of
    what a node makes from them (``_made_crc``) as the driver made it."""

    part: Callable
    baking: object
    owns: np.ndarray
    crc: int


def _shipped(part: Callable, baking) -> _ShippedBake:
    """What every node needs of ``baking`` (``full.Baking``), once (``_ShippedBake``): a node
    builds the rest (``_node_bake``); each part carries its own coverage rows (the
    per-triangle texel counts are shipped)."""
    coverage, lit = baking.coverage, baking.lit
    empty = Coverage(coverage.key[:0], coverage.triangle[:0], coverage.triangle_texels)
    scene = _read_scene(baking.scene)
    context = replace(lit.context, world=None, tracer=None, surfaces=scene)
    bare = replace(baking, scene=scene, world=None, owned=None, faces=None, surfaces=None,
                   coverage=empty, lit=replace(lit, context=context))
    return _ShippedBake(part, bare, np.packbits(owning_triangles(baking.world, coverage)),
                        _made_crc(baking))


def _read_scene(scene):
    """The loaded ``scene`` (``gltf.scene.Scene``) as a node reads it: without the file's own
    bytes (its glTF document, each buffer's bytes, each image file's), which only the
    driver's writer reads; the meshes, instances, materials and decoded images stay."""
    images = tuple(replace(image, data=None) for image in scene.images)
    return replace(scene, document=None, buffers=(), images=images)


def _node_bake(shipped: _ShippedBake) -> tuple:
    """On a node, once (``Work.node``): the part function and the bake its worker processes
    share, the world built from the shipped scene (``build_world``: the driver's bits, on any
    machine and thread count), what the texels take from their triangles, the back faces and
    the surfaces made from it, as the driver made them; a RuntimeError if their CRC-32 is not
    the driver's (another build of a library, a CPU that rounds otherwise), rather than a bake
    of other bytes."""
    baking = shipped.baking
    world = build_world(baking.scene)
    owns = np.unpackbits(shipped.owns, count=len(world.triangles)).astype(bool)
    context = replace(baking.lit.context, world=world)
    made = replace(baking, world=world, owned=owners_of(baking.atlas, world, owns),
                   lit=replace(baking.lit, context=context), faces=Faces(baking.scene, world),
                   surfaces=surfaces_of(context))
    crc = _made_crc(made)
    if crc != shipped.crc:
        raise RuntimeError(f"node {socket.gethostname()} built another world from the shipped "
                           f"scene than the driver's (CRC-32 {crc:08x}, the driver's "
                           f"{shipped.crc:08x}): its libraries or CPU round otherwise")
    return shipped.part, made


def _made_crc(baking) -> int:
    """CRC-32 of every array a node makes of a bake (``_node_bake``): the world's, the texels'
    per-triangle terms, the back faces and the surfaces' tables, with their dtypes and shapes,
    in a fixed order (not the scene's, which is shipped)."""
    crc = 0
    for array in _arrays(_made(baking), {id(baking.scene)}):
        crc = isal_zlib.crc32(f"{array.dtype.str}{array.shape}".encode(), crc)
        crc = isal_zlib.crc32(np.ascontiguousarray(array).reshape(-1).view(np.uint8), crc)
    return crc


def _made(baking) -> tuple:
    """What a node makes of a bake (``_node_bake``): its world, the texels' per-triangle terms,
    the back faces' arrays and the surfaces."""
    return baking.world, baking.owned, vars(baking.faces), baking.surfaces


def _ready_bake(made: tuple):
    """In a worker: the part function and the bake its node made (``_node_bake``) with
    Embree's scene built from its world, with the task's CPUs as threads."""
    part, baking = made
    threads = max(1, baking.settings.threads)
    return part, replace(baking, lit=baking.lit.with_tracer(Tracer(baking.world)),
                         settings=replace(baking.settings, threads=threads))


def _bake_part(ready: tuple, item: tuple[np.ndarray, np.ndarray], seconds: dict[str, float]
               ) -> _BakedRemotely:
    """In a worker: the full bake's part whose texels have the coverage rows ``item`` (keys
    (k,) uint64, owning triangles (k,) int64), made by the same part function as a local
    bake."""
    part, baking = ready
    baking = replace(baking, coverage=Coverage(item[0], item[1],
                                               baking.coverage.triangle_texels))
    baked = part(baking, slice(None), seconds, None)  # no progress bar on a worker
    moved = np.flatnonzero(baked.points.moved)
    return _BakedRemotely(replace(baked, texels=None, points=None), moved,
                          baked.texels.position[moved])


def _array_bytes(value) -> int:
    """Bytes of the numpy arrays in ``value`` (``_arrays``), each array counted once: what
    crosses the network beyond a few bytes of framing."""
    return sum(array.nbytes for array in _arrays(value))


def _arrays(value, seen: set | None = None) -> Iterator[np.ndarray]:
    """The numpy arrays in ``value`` (dataclasses, tuples, lists, dicts, nested), each once,
    in a fixed order; none within an object whose id is in ``seen``."""
    seen = set() if seen is None else seen
    if id(value) in seen:
        return
    seen.add(id(value))
    if isinstance(value, np.ndarray):
        yield value
    elif isinstance(value, (tuple, list)):
        for item in value:
            yield from _arrays(item, seen)
    elif isinstance(value, dict):
        for item in value.values():
            yield from _arrays(item, seen)
    elif hasattr(value, "__dataclass_fields__"):
        for name in value.__dataclass_fields__:
            yield from _arrays(getattr(value, name), seen)


def _add_seconds(times: dict[str, float], name: str, start: float) -> None:
    """Add the seconds since ``start`` (``time.perf_counter``) to ``times[name]``."""
    times[name] = times.get(name, 0.0) + time.perf_counter() - start
