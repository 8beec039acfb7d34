"""Where a tiled run's tasks run: in this process, a local pool of forked processes, or a Dask cluster."""

from __future__ import annotations

import bisect
import ctypes
import gc
import importlib
import os
import pickle
import select
import signal
import struct
import sys
import time
from collections.abc import Callable, Iterable

from wavemesh.errors import WavemeshError
from wavemesh.record import record
from wavemesh.refine import native
from wavemesh.tiles.plan import default_workers

DASK_CONNECT_S = 10  # how long --scheduler ADDRESS may take to answer
# The modules of the tiled run's task functions, which each Dask worker imports before its first task
# (_dask_start), by name: wavemesh.tiles.jobs imports this module
DASK_TASK_MODULES = ("wavemesh.tiles.jobs",)
# a node sent to a pool worker takes with it the next node that waits for it alone and whose tiles are that
# worker's (its result goes on to it in the worker), and so on, up to CHAIN nodes: one round trip of the
# parent for them all (1: none)
CHAIN = 4
# and, while more nodes are ready than BATCH_READY per worker, the next ready node of its own after a chain
# that has no follower (and that node's followers), up to CHAIN in all
BATCH_READY = 2
# and a worker running a chain is given its next one too, when one of its own is ready (sent while it fits in
# the pipe's buffer, else as the first one's result comes), so that it goes on without waiting for the parent
AHEAD = True
# a pool of one worker a CPU (of those this process may use, the default --workers): each worker kept on a CPU
# of its own (sched_setaffinity; the parent moves between them), its tiles in that core's caches
PIN = True
# a pool worker keeps each result it made that other nodes read, until the parent has given out every one of
# them: a node given to that worker names it (_Held) instead of carrying it down the pipe again
HOLD = True
# of a pool's K workers, the last THREADS (at most K) are threads of this process (_Local), the others forked
# processes: with 1, K - 1 forks; the thread's tasks and results pass no pipe, its tiles are in this process's
# heap (8192^2, tile 1025, 2 workers: 0.09-0.14 s of CPU less than 2 forked, docs/tiles.md)
THREADS = 1
# while a pool with a thread runs, the interpreter's switch interval (microseconds; 0: Python's 5 ms): how
# long the loop, woken by a forked worker's result, may wait for the interpreter's lock while the thread runs
# Python (8192^2, tile 1025, 4 workers on 2 CPUs: the graph 2.41 s against 2.82-3.03 s with 5 ms)
SWITCH_US = 500
# on Dask, the nodes given out as the pool gives them (_Schedule: chains, ahead; each worker thread a pool
# worker, its own tiles a block of them), a chain a task of up to DASK_CHAIN nodes (CHAIN's rules): a Dask
# task costs the scheduler and the worker some milliseconds of CPU more than a pool's round trip
DASK_CHAIN = 16
_WORKER_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)  # blocked from a fork to _worker_start
# glibc malloc for a process that runs tiles (tune_malloc): buffers up to 32 MiB from the heap, the heap's top
# kept up to 1 GiB
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
MALLOC_MMAP_BYTES, MALLOC_TRIM_BYTES = 32 << 20, 1 << 30
_TUNED: list = []


def tune_malloc() -> None:
    """The memory of a process that runs tiles, once: glibc's malloc gives a tile's arrays (1025^2 float64:
    8 MiB, and the refiner's storage) from the heap and keeps the heap between tasks, rather than mapping
    and unmapping them for every tile (glibc raises its mmap threshold itself only after it has freed
    such a mapping, which a forked worker may never do); and numpy asks for no transparent huge pages for
    its arrays (each fresh one zeroed, or compacted for, at its first touch).  8192^2 in tiles of 1025, 2
    pool workers: the mallopt took the free and conformed steps from 464,000 page faults and 1.2 s of
    system time to 5,600 and 0.3 s; the huge pages cost the free step 0.7 s of system time in 2.4 s of CPU,
    0.15 in 1.75 without them (numbers: docs/tiles.md).  mallopt only where there is one (glibc)."""
    if _TUNED:
        return
    _TUNED.append(True)
    from numpy._core import multiarray  # private to numpy (2, pinned): read only where tiles run

    getattr(multiarray, "_set_madvise_hugepage", lambda _: None)(False)
    if not sys.platform.startswith("linux"):
        return
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return
    mallopt(_M_MMAP_THRESHOLD, MALLOC_MMAP_BYTES)
    mallopt(_M_TRIM_THRESHOLD, MALLOC_TRIM_BYTES)

def connect(address: str):
    """A distributed.Client of the Dask scheduler at ``address``, or WavemeshError."""
    try:
        from distributed import Client  # an optional package (wavemesh[dask]), only for --scheduler
    except ImportError:
        raise WavemeshError("--scheduler needs Dask's distributed package",
                            hint="pip install 'wavemesh[dask]' (or: pip install dask distributed)") from None
    try:
        return Client(address, timeout=f"{DASK_CONNECT_S}s")
    except (OSError, TimeoutError, ValueError) as e:
        raise WavemeshError(f"--scheduler {address}: no Dask scheduler answers ({e})",
                            hint="start one (dask scheduler; dask worker ADDRESS), or check the address") \
            from None


# The scheduler's words (distributed.Scheduler.update_graph) for a graph it cannot unpickle: a task's
# function or argument named by a module or class its Python does not have as this process has it
GRAPH_UNREAD = "Error during deserialization of the task graph"


def _cluster_said(client, detail: str) -> tuple[str, str]:
    """For a Dask error line: the scheduler's address ("?" when unknown) and ``detail`` cut to 200
    characters."""
    address = getattr(getattr(client, "scheduler", None), "address", None) or "?"
    return address, detail if len(detail) <= 200 else detail[:197] + "..."


def foreign_cluster(client, who: str, e: BaseException) -> WavemeshError:
    """The error of a Dask cluster whose scheduler or workers (``who``) could not load this wavemesh's tasks
    (the task functions are sent by name: another wavemesh version or package tree there, or none): its
    address, what failed there, and the fix."""
    import wavemesh  # start-up: only for this error (the package is loaded: its path for the hint)

    detail = " ".join(str(e).split())
    if detail.startswith(GRAPH_UNREAD):
        detail = GRAPH_UNREAD.lower()  # the rest is Dask's advice, which the hint gives
    address, detail = _cluster_said(client, detail)
    here = os.path.dirname(os.path.dirname(wavemesh.__file__))
    return WavemeshError(f"the Dask {who} at {address} cannot load this wavemesh's tasks ({detail})",
                         hint=f"run the same wavemesh as here (version {wavemesh.__version__}, from {here}) "
                              "on the scheduler and every worker, then start them again")


def dask_stopped(client, e: BaseException) -> WavemeshError:
    """The error of a Dask run that stopped on an OSError or a timeout: the connection to the cluster
    lost, or a task's own (a worker that cannot read the input: its path not on a file system it shares
    with this machine): the scheduler's address, what failed, and the fix."""
    address, detail = _cluster_said(client, " ".join(f"{type(e).__name__}: {e}".split()))
    return WavemeshError(f"the Dask run at {address} stopped ({detail})",
                         hint="check that the scheduler and its workers are running and that every worker "
                              "reads the input at the same path (a shared file system), then run again")


_TREE: list = []  # this process's tree_fingerprint, once made


def tree_fingerprint() -> str:
    """This wavemesh's version and the text of its Python files (their sha256, 16 hex digits), which each
    Dask worker's _dask_start compares with the client's: the tasks are sent by name, and a worker with
    another wavemesh would run other functions, or find none (its process then ends, and the run waited
    for a worker for ever).  About 2 ms, once, and only for --scheduler."""
    if not _TREE:
        import hashlib  # start-up: only for --scheduler (see above)

        import wavemesh  # the same: the package's folder

        root = os.path.dirname(wavemesh.__file__)
        h = hashlib.sha256(wavemesh.__version__.encode() + b"\0")
        for folder, dirs, files in os.walk(root):
            dirs[:] = sorted(d for d in dirs if d != "__pycache__")
            for name in sorted(f for f in files if f.endswith(".py")):
                path = os.path.join(folder, name)
                with open(path, "rb") as f:
                    h.update(os.path.relpath(path, root).encode() + b"\0" + f.read() + b"\0")
        _TREE.append(h.hexdigest()[:16])
    return _TREE[0]


@record(frozen=True)
class Ref:
    """In a Node's args: node ``node``'s result (``pick`` of it when given: a module-level function)."""

    node: int
    pick: Callable | None = None


@record(frozen=True, eq=False)
class Here:
    """In a Node's args: fn(*args) computed in this process when the node is given out (a tile's window of
    an input in memory); on Dask once for every node that names it, and scattered."""

    fn: Callable
    args: tuple


@record(frozen=True)
class Node:
    """A task of Runner.graph: fn(*args), each Ref in args (at the top level) replaced by that node's result;
    ``rank``: the order among the ready nodes (least first); ``tiles``: the tiles whose data it reads (the
    pool gives it to the worker that read them first, whose cache holds them)."""

    fn: Callable
    args: tuple
    rank: tuple = ()
    tiles: tuple = ()

    def deps(self) -> set[int]:
        return {a.node for a in self.args if isinstance(a, Ref)}


@record(frozen=True)
class _Prev:
    """In a chained node's args sent to a pool worker: the chain's previous node's result (``pick`` of it)."""

    pick: Callable | None = None


@record(frozen=True)
class _Held:
    """In a node's args sent to a pool worker: the result of node ``node`` that worker made and holds
    (``pick`` of it)."""

    node: int
    pick: Callable | None = None


def _resolve(node: Node, results: list, prev: int | None = None, held: set | frozenset = frozenset()
             ) -> tuple:
    """The node's args, each Ref replaced by its result (a Ref to ``prev``: _Prev, the worker's; to a node in
    ``held``: _Held, the worker's)."""

    def one(a):
        if isinstance(a, Ref) and a.node == prev:
            return _Prev(a.pick)
        if isinstance(a, Ref) and a.node in held:
            return _Held(a.node, a.pick)
        if isinstance(a, Ref):
            return a.pick(results[a.node]) if a.pick else results[a.node]
        return a.fn(*a.args) if isinstance(a, Here) else a

    return tuple(one(a) for a in node.args)


class Runner:
    """Where a tiled run's tasks run, as a context manager: ``scheduler`` (a Dask scheduler's address or
    a distributed.Client: a Dask task a chain of nodes, given out as the pool gives them; the workers read
    their own windows), else ``workers`` local workers (default: the CPUs this process may use; 1: in this
    process), the last THREADS of them threads of this process, the others forked processes, started at the
    first task and kept for every phase.  Leaving it early (an error, Ctrl-C, SIGTERM) kills the workers."""

    def __init__(self, workers: int | None = None, scheduler=None):
        workers = default_workers() if workers is None else workers
        if workers < 1:
            raise WavemeshError(f"--workers {workers} is out of range", hint="use 1 or more")
        self.workers, self.scheduler = workers, scheduler
        self.client = None
        self.own_client = scheduler is not None and not hasattr(scheduler, "submit")
        self.pool: list[tuple] = []  # (process, pipe) of each forked worker
        self.pinned: list[int | None] = []  # the CPU each worker of the pool is kept on (PIN), or None
        self.ended: list[tuple] = []  # workers let go by the last graph, reaped by __exit__
        self.run_id = f"{time.time_ns()}-{os.getpid()}"
        self.n_maps = 0
        self.dask_started = False  # _dask_start run on the cluster's workers
        self.threads_cpu = 0.0  # the CPU seconds of the pool's workers that were threads of this process

    def __enter__(self) -> Runner:
        if self.scheduler is not None:
            self.client = connect(self.scheduler) if self.own_client else self.scheduler
        return self

    def __exit__(self, kind, *exc) -> None:
        _end_workers(self.ended + self.pool, gently=kind is None)
        self.pool, self.ended = [], []
        if self.own_client and self.client is not None:
            self.client.close()

    def map(self, fn: Callable, tasks: Iterable[tuple], done: Callable | None = None) -> list:
        """fn(*task) of every task, in task order; ``done(result)`` called as each finishes (any order): a
        graph of nodes that wait for none."""
        return self.graph([Node(fn, tuple(task)) for task in tasks], (lambda _, r: done(r)) if done else None)

    def graph(self, nodes: list[Node], done: Callable | None = None, homes: dict | None = None,
              shared: tuple = (), keep: Iterable[int] | None = None, last: bool = False,
              seen: Iterable[int] | None = None) -> list:
        """Every node's result, in node order; a node runs once the nodes its Refs name are done (no
        barrier between phases); ``done(i, result)`` as each finishes.  ``keep``: the nodes whose results
        are returned (None: all); another's is let go once every node that reads it has been given it
        (None in the list), so that the parent holds a tiled run's meshes a step at a time, not every
        step's of every tile.  Refs name earlier nodes only.  The
        same results however it runs: each node depends only on its args.  ``homes``: tile -> a number in
        [0, 1), the pool worker (of the workers in order) that should read it first (neighbouring tiles on
        one worker: fewer tiles read twice).  ``shared``: args (by identity) a pool worker is sent once and
        keeps (the plan every task reads), not with every task.  A pool worker given a node takes with it the
        node that waits for it alone, if its tiles are the worker's, and so on (CHAIN; _Schedule.follower),
        and while many nodes are ready the next ready nodes of its own (BATCH_READY); while it runs a chain,
        its next one (AHEAD; _Schedule.chain).  ``last``: the
        Runner's last graph: a pool worker is let go as soon as no node is left to give out (its exit,
        which frees its memory, then runs beside the other's last nodes and the parent's handling of the
        last results, not after them; a later graph starts a new pool).  ``seen``: the nodes whose results
        ``done`` reads (None: every node's); on a Dask cluster another's stays on the workers (done is
        given None for it)."""
        results: list = [None] * len(nodes)
        kept_nodes = None if keep is None else set(keep)
        deps = [node.deps() for node in nodes]  # once (given, _Schedule)
        readers = [0] * len(nodes)  # the nodes not yet given each node's result (a local run's)
        for ds in deps:
            for d in ds:
                readers[d] += 1

        def got(i: int, r, report: bool = True) -> None:
            if kept_nodes is None or i in kept_nodes or (self.client is None and readers[i]):
                results[i] = r
            if done and report:
                done(i, r)

        holds: list[set] = []  # a pool's: the results each worker holds (HOLD)
        drops: list[list] = []  # and those it may let go, told with its next chain

        def given(k: int) -> None:
            """Node ``k``'s args are out (resolved): a result nobody else reads and graph does not return
            goes (here, and from the worker that holds it)."""
            for d in deps[k]:
                readers[d] -= 1
                if readers[d]:
                    continue
                if kept_nodes is not None and d not in kept_nodes:
                    results[d] = None
                for w, has in enumerate(holds):
                    if d in has:
                        has.discard(d)
                        drops[w].append(d)

        self.n_maps += 1
        if self.client is not None:
            try:
                self._dask_graph(nodes, got, shared, kept_nodes, seen, homes)
            except (OSError, TimeoutError) as e:  # the connection, or a task's own (the input unread there)
                raise dask_stopped(self.client, e) from None
        elif self.workers == 1 or len(nodes) == 1:
            tune_malloc()
            sched = _Schedule(nodes, deps=deps)
            while (i := sched.take(None)) is not None:
                args = _resolve(nodes[i], results)
                given(i)
                r = nodes[i].fn(*args)
                del args  # the inputs let go before done sees the result
                got(i, r)
                del r
                sched.finished(i)
        else:  # a pool: forked workers, each through its own pipe, and the last THREADS workers threads of
            # this process; the loop here (this thread) hands out and answers: a run that ends early kills its
            # workers and returns at once (concurrent.futures' pool could wait forever at exit for a result
            # a killed worker had half sent)
            size = self.workers
            forked = size - min(size, THREADS)  # the workers from forked on are threads of this process
            # a new pool's first worker is given its first chain before the others are forked: it starts its
            # tasks while they fork and start
            self._start_pool(1)
            sched = _Schedule(nodes, {t: int(h * size) for t, h in (homes or {}).items()}, deps)
            # each worker's chains, in the order sent: the first written to its pipe, a second one (decided
            # while the worker runs the first, so that it starts it without waiting for the parent) written
            # only while both fit in the pipe's buffer, else held here and written as the first one's result
            # comes (a message that could block the parent's send while the worker sends its result back
            # would block both ends: one of any size goes only to a worker that waits for it)
            sent: list[list] = [[] for _ in range(size)]  # [chain, its bytes (the thread's: steps), written]
            room = [_pipe_room(pipe) for _, pipe in self.pool] + [0] * (forked - len(self.pool))
            keys = {id(obj): _Kept(self.n_maps, k) for k, obj in enumerate(shared)}
            holds[:] = [set() for _ in range(forked)]
            drops[:] = [[] for _ in range(forked)]
            kept: list[set] = [set() for _ in range(forked)]  # the shared args each worker has
            local = {w: _Local(self.pinned[w]) for w in range(forked, size)}

            def give(w: int, now: bool = True) -> None:
                """Worker ``w``'s next chain (_Schedule.chain) when it has none, or its second while it runs
                the first (AHEAD; a chain sent ahead takes at most one tile more than the worker would
                otherwise hold: its batch only of tiles it has read already); ``now``: written at once."""
                if len(sent[w]) > 1 or not (chain := sched.chain(w, size, bool(sent[w]))):
                    return
                if w >= forked:  # a thread: the args themselves, nothing pickled, nothing held for it
                    steps = []
                    for n, k in enumerate(chain):
                        steps.append((nodes[k].fn, _resolve(nodes[k], results, chain[n - 1] if n else None)))
                        given(k)
                    sent[w].append([chain, steps, False])
                    if now:
                        write(w)
                    return
                out = []
                steps = []
                for n, k in enumerate(chain):
                    args = _resolve(nodes[k], results, chain[n - 1] if n else None, holds[w])
                    given(k)
                    for a in args:
                        key = keys.get(id(a))
                        if key is not None and key not in kept[w]:
                            out.append(_DUMPS(("keep", key, a)))  # no answer: the worker keeps it
                            kept[w].add(key)
                    steps.append((nodes[k].fn, tuple(keys.get(id(a), a) for a in args)))
                # a result a node not yet given reads: kept by the worker that makes it (one only its chain
                # reads comes to the next step as _Prev and is not kept; no node given later reads it)
                store = tuple(k if HOLD and readers[k] else -1 for k in chain)
                out.append(_DUMPS(("chain", steps, self.n_maps, store, tuple(drops[w]))))
                drops[w].clear()
                sent[w].append([chain, out, False])
                if now:
                    write(w)

            def write(w: int) -> None:
                """Worker ``w``'s chains not yet written that may be: the first, or a second that fits (the
                thread's: both, to its queue)."""
                for n, item in enumerate(sent[w]):
                    if item[2]:
                        continue
                    if w >= forked:
                        local[w].put(item[1])
                        item[2] = True
                        continue
                    size = sum(map(len, item[1]))
                    if n and size + sum(sum(map(len, x[1])) for x in sent[w][:n]) > room[w]:
                        return
                    for buf in item[1]:
                        self.pool[w][1].send_bytes(buf)
                    item[2] = True

            gone: set[int] = set()

            def let_go() -> None:
                """The idle workers let go once nothing is left to give out (``last``)."""
                if last and not sched.left:
                    for w in range(len(self.pool)):
                        if not sent[w] and w not in gone:
                            _let_go(self.pool[w][1])
                            gone.add(w)

            def hand_out(idle: Iterable[int], busy: Iterable[int] = ()) -> None:
                """The ``idle`` workers' next chains, every one made before the first is written (a worker
                its chain wakes may take the CPU this process makes the next one on: the other idle worker
                would wait for it; the thread, or a worker kept on this process's CPU, written last), then
                the second chains of ``busy`` ones."""
                idle = [w for w in dict.fromkeys(idle) if not sent[w]]
                if len(idle) > 1:
                    cpu = _this_cpu()
                    idle.sort(key=lambda w: self.pinned[w] == cpu)
                for w in idle:
                    give(w, False)
                for w in idle:
                    write(w)
                for w in busy:
                    give(w)

            ready = _Ready()
            back = self._own_cpu() if local else None
            try:
                hand_out((*range(len(self.pool)), *local))
                if len(self.pool) < forked:  # the rest of a new pool, then their first chains
                    started = len(self.pool)
                    self._start_pool()
                    room[started:] = [_pipe_room(pipe) for _, pipe in self.pool[started:]]
                    hand_out(range(started, forked))
                # the threads started once every fork is made: a fork while a thread of this process runs
                # copies whatever lock that thread holds into the child (their first chains wait in their
                # queues meanwhile; with 2 workers the one fork came before this graph's hand-out)
                for t in local.values():
                    t.start()
                workers = [*range(len(self.pool)), *local]
                while any(sent):
                    live = [w for w in workers if sent[w]]
                    fds = ready.wait([self.pool[w][1] if w < forked else local[w].wake for w in live]
                                     + [self.pool[w][0].sentinel for w in live if w < forked])
                    came = []
                    for w in live:
                        if w >= forked:
                            if local[w].wake not in fds:
                                continue
                            chain = sent[w].pop(0)[0]
                            reply = local[w].reply()
                        else:
                            proc, pipe = self.pool[w]
                            if pipe.fileno() not in fds:
                                if proc.sentinel in fds and not pipe.poll():
                                    _lost(proc)
                                continue
                            chain = sent[w].pop(0)[0]
                            reply = _reply(proc, pipe)
                            write(w)  # a second chain held back: the worker waits for it
                        let_go()  # before its results are handled
                        for i, r in zip(chain, reply, strict=True):
                            if HOLD and w < forked and readers[i]:  # as store said (only its chain gave a
                                holds[w].add(i)  # reader since)
                            got(i, r, False)
                            sched.finished(i)
                            came.append((i, r))
                    idle = [w for w in (*live, *workers) if not sent[w]]  # answered first
                    hand_out(idle, (*idle, *live))  # a worker with nothing first, then the second chains
                    let_go()
                    if done:  # the results handled (a finished tile written) once the workers have their next
                        for i, r in came:
                            done(i, r)
            finally:
                for t in local.values():
                    t.stop(not any(sent))
                    self.threads_cpu += t.cpu_s
                if back is not None:
                    back()
            if gone:  # reaped when the Runner ends; a later graph forks a new pool
                self.ended += self.pool
                self.pool = []
        return results

    def _dask_graph(self, nodes: list[Node], got: Callable, shared: tuple, keep: set | None,
                    seen: Iterable[int] | None, homes: dict | None) -> None:
        """Runner.graph on a Dask cluster: as the pool, chains of nodes (_dask_chains); ``shared`` args and
        each Here scattered once (the plan every task reads: sent to every worker, not with each task); only
        the results the caller reads (``keep``, ``seen``) come back to this process.  A cluster without
        workers yet: the run waits for the first (the workers the graph starts with are given its chains;
        one that joins later may take them by Dask's work stealing)."""
        client = self.client
        if not _dask_threads(client):
            client.wait_for_workers(1)
        if not self.dask_started:  # each worker set up once, before its first task (_dask_start)
            self.dask_started = True
            hosts: dict = {}
            for addr, w in client.scheduler_info().get("workers", {}).items():
                host = _host(addr)
                hosts[host] = hosts.get(host, 0) + (w.get("nthreads") or 1)
            try:
                client.run(_dask_start, hosts, native.threads_set(), DASK_TASK_MODULES, tree_fingerprint())
            except (OSError, TimeoutError):  # the connection (distributed's CommClosedError is an OSError)
                raise
            except Exception as e:  # a worker that cannot load _dask_start (or the tasks' modules)
                raise foreign_cluster(client, "workers", e) from None
        scattered: dict = {}  # id of a shared arg or a Here (the nodes share one per tile) -> its future
        for obj in shared:
            scattered[id(obj)] = client.scatter(obj, broadcast=True, hash=False)
        wanted = None if keep is None or seen is None else keep | set(seen)
        workers = _dask_threads(client)
        try:
            self._dask_chains(nodes, got, scattered, wanted, homes, workers)
        except RuntimeError as e:  # the scheduler could not read the graph: every task erred with it
            if not str(e).startswith(GRAPH_UNREAD):
                raise
            raise foreign_cluster(client, "scheduler", e) from None

    def _dask_chains(self, nodes: list[Node], got: Callable, scattered: dict, wanted: set | None,
                     homes: dict | None, workers: list[str]) -> None:
        """_dask_graph as the pool gives out its nodes: the Dask worker thread ``w`` (of ``workers``) is given
        _Schedule.chain's nodes as one task (its first node's tiles its own: _blocks of ``homes``), asked of
        that worker (Dask's loose restrictions: another may still take it, by work stealing or when that
        one leaves), with the futures of the chains whose results it reads; while it runs one, its next
        chain (ahead).  A chain's results stay on its worker until every node that reads them has been
        given out, and come back here only for the nodes the caller reads (``wanted``)."""
        from distributed import as_completed  # with connect's package

        client, size = self.client, len(workers)
        key = f"wavemesh-{self.run_id}-{self.n_maps}"
        deps = [n.deps() for n in nodes]
        readers = [0] * len(nodes)
        for ds in deps:
            for d in ds:
                readers[d] += 1
        sched = _Schedule(nodes, _blocks(homes or {}, size), deps)
        made: dict = {}  # node -> (the future of the chain that made it, its place in the chain)
        flight: list[list] = [[] for _ in range(size)]  # each worker's chains given out, not yet done
        chains: dict = {}  # a chain's key -> (worker, its nodes)
        pending = as_completed()

        def give(w: int) -> None:
            if len(flight[w]) > 1 or not (chain := sched.chain(w, size, bool(flight[w]), DASK_CHAIN)):
                return
            ext: dict = {}  # key of a future the chain reads -> (its place in the task's args, the future)
            steps = []
            for n, k in enumerate(chain):
                args = []
                for a in nodes[k].args:
                    if isinstance(a, Ref) and a.node in chain[:n]:
                        args.append(_Made(None, chain.index(a.node), a.pick))
                    elif isinstance(a, Ref):
                        f, at = made[a.node]
                        args.append(_Made(ext.setdefault(f.key, (len(ext), f))[0], at, a.pick))
                    elif isinstance(a, Here) or id(a) in scattered:
                        if id(a) not in scattered:
                            scattered[id(a)] = client.scatter(a.fn(*a.args), hash=False)
                        f = scattered[id(a)]
                        args.append(_Made(ext.setdefault(f.key, (len(ext), f))[0], None, None))
                    else:
                        args.append(a)
                steps.append((nodes[k].fn, tuple(args)))
                for d in deps[k]:  # given out: a result nobody reads any more is let go (its future)
                    readers[d] -= 1
                    if not readers[d] and d not in chain:
                        made.pop(d, None)
            fut = client.submit(_dask_chain, steps, *(f for _, f in ext.values()), pure=False,
                                key=f"{key}-{chain[0]}", workers=[workers[w]], allow_other_workers=True)
            for at, k in enumerate(chain):
                if readers[k]:
                    made[k] = (fut, at)
            flight[w].append(fut)
            chains[fut.key] = (w, chain)
            pending.add(fut)

        def hand_out() -> None:
            for w in range(size):  # a worker with nothing first, then the second chains
                if not flight[w]:
                    give(w)
            for w in range(size):
                give(w)

        hand_out()
        for fut in pending:
            w, chain = chains.pop(fut.key)
            flight[w].remove(fut)
            if fut.status == "error" or wanted is None or any(k in wanted for k in chain):
                out = fut.result()  # its error raised here
            else:
                out = [None] * len(chain)
            for k in chain:
                sched.finished(k)
            hand_out()
            for k, r in zip(chain, out, strict=True):
                got(k, r if wanted is None or k in wanted else None)
            del fut, out

    def _own_cpu(self) -> Callable:
        """This process set up for a graph whose workers include its threads, as _worker_start sets up a
        forked one: its memory (tune_malloc) and its host stages on the workers' share of the CPUs (unless the
        run gave --threads); and the interpreter's switch interval SWITCH_US; returns what puts them back."""
        tune_malloc()
        threads = native.threads_set() is None
        if threads:
            native.set_threads(max(1, native.cores() // self.workers))
        switch = sys.getswitchinterval()
        if SWITCH_US:
            sys.setswitchinterval(SWITCH_US / 1e6)

        def back() -> None:
            if threads:
                native.set_threads(None)
            sys.setswitchinterval(switch)

        return back

    def _pins(self) -> None:
        """The CPU each worker of the pool is kept on (PIN: one worker a CPU), else None each."""
        cpus = sorted(os.sched_getaffinity(0)) if PIN and hasattr(os, "sched_getaffinity") else []
        # one worker a CPU: each its own (PIN), kept there by the worker itself as it starts
        # (_worker_start): set from here, the call waited while the new process, running on the
        # other CPU, was moved (1.4-1.5 ms for the first worker, before any worker had its first task)
        if len(cpus) == self.workers:
            now = _this_cpu()
            # this process's CPU last: the first forked worker starts at once, a thread stays where it is
            cpus.sort(key=lambda c: c == now)
            self.pinned = cpus
        else:
            self.pinned = [None] * self.workers

    def _start_pool(self, upto: int | None = None) -> None:
        """The pool's forked workers (all but the last THREADS), up to ``upto`` of them (None: all)."""
        forked = self.workers - min(self.workers, THREADS)
        upto = forked if upto is None else min(upto, forked)
        if not self.pool:
            self._pins()
        if len(self.pool) >= upto:
            return
        native.load()  # built once here, not by every worker at once
        # fork: the workers start from this process as it is (the library loaded; a script that calls
        # this needs no `if __name__ == "__main__"` guard, which spawn and forkserver would ask of it)
        # the signals held back over the forks: a worker starts with them blocked and unblocks them
        # once its own handlers are set (_worker_start), so a Ctrl-C just after the fork is not a
        # KeyboardInterrupt traceback in the worker; here they are raised after this call's last fork,
        # every worker forked in the pool by then (ended by __exit__)
        held = signal.pthread_sigmask(signal.SIG_BLOCK, _WORKER_SIGNALS)
        try:
            # each worker's host stages (quantisation, error measure, checks) on its share of the CPUs, not
            # on every one as a process of its own would: one thread each with one worker a CPU
            share = max(1, native.cores() // self.workers)
            for k in range(len(self.pool), upto):
                here, there = _pipe()
                proc = _Forked(_worker_loop, (there, os.getpid(), share, self.pinned[k]))
                proc.start()
                there.close()
                self.pool.append((proc, here))
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, held)


class _Schedule:
    """Which node a worker runs next, of the ready ones (every Ref's node done), in rank order: the first
    whose tiles are all the worker's (a tile is the worker's that first read it, whose cache holds it; one
    nobody read yet, its home's) or whose first tile is (a node on two workers' tiles, a side between
    their blocks, is its first tile's worker's in its turn: left to whichever worker had nothing of its
    own it came last, both tiles and the steps after them held till then), else the first with one of its
    tiles, else the first (another worker's tiles, read again here rather than wait).  ``take(None)``: the
    first (one worker)."""

    def __init__(self, nodes: list[Node], homes: dict | None = None, deps: list | None = None):
        self.nodes = nodes
        self.homes = homes or {}
        deps = [n.deps() for n in nodes] if deps is None else deps  # each node's (Node.deps)
        self.waiting = [len(ds) for ds in deps]
        self.users: list[list[int]] = [[] for _ in nodes]
        for i, ds in enumerate(deps):
            for d in ds:
                if d >= i:
                    raise ValueError(f"node {i} refers to node {d}: only earlier nodes")
                self.users[d].append(i)
        self.ready = sorted((n.rank, i) for i, n in enumerate(nodes) if not self.waiting[i])
        self.owner: dict = {}  # tile -> the worker that first read it
        self.chained = [False] * len(nodes)  # taken with the node it waits for (follower)
        self.left = len(nodes)  # not taken yet (by take or follower)

    def take(self, worker: int | None, own: bool = False, held: bool = False) -> int | None:
        """The node ``worker`` runs next (None: none ready); ``own``: only one of its own (None if none);
        ``held``: only one of its own whose tiles it has read already (none read anew)."""
        if not self.ready:
            return None
        k = 0
        if worker is not None:  # the first its own (the scan stops there), else the first with one
            some = None
            for j, (_, i) in enumerate(self.ready):
                tiles = self.nodes[i].tiles
                if held:
                    if not tiles or self.owner.get(tiles[0]) == worker and all(
                            self.owner.get(t) == worker for t in tiles[1:]):
                        k = j
                        break
                    continue
                if not tiles or self._mine(tiles[0], worker):  # its first tile the worker's: its own
                    k = j
                    break
                if some is None and any(self._mine(t, worker) for t in tiles[1:]):
                    some = j
            else:
                if own:
                    return None
                k = 0 if some is None else some
            self._claim(self.ready[k][1], worker)
        self.left -= 1
        return self.ready.pop(k)[1]

    def chain(self, worker: int, workers: int, ahead: bool = False, most: int | None = None) -> list[int]:
        """The nodes ``worker`` (of ``workers``) is given next, in order (Runner.graph): the node take gives
        it, the node that waits for it alone (follower), and so on, up to CHAIN (``most``); while more than
        BATCH_READY nodes a worker are ready, after a node without a follower the next ready node of its
        own.  ``ahead``: the worker is running a chain: none unless AHEAD, its first node one of its own,
        the batch only of tiles it has read already.  Empty: nothing to give."""
        if ahead and not AHEAD:
            return []
        if (i := self.take(worker, own=ahead)) is None:
            return []
        chain = [i]
        while len(chain) < (CHAIN if most is None else most):
            j = self.follower(chain[-1], worker)
            if j is None and len(self.ready) > BATCH_READY * workers:
                j = self.take(worker, own=True, held=ahead)  # another of its own, while there are plenty
            if j is None:
                break
            chain.append(j)
        return chain

    def follower(self, i: int, worker: int) -> int | None:
        """Of the nodes that wait for node ``i`` (just taken by ``worker``) alone, the first by rank whose
        tiles are all the worker's (as take counts them), taken with it; None if none."""
        best = None
        for u in self.users[i]:
            if self.waiting[u] == 1 and not self.chained[u] and all(
                    self._mine(t, worker) for t in self.nodes[u].tiles):
                if best is None or (self.nodes[u].rank, u) < (self.nodes[best].rank, best):
                    best = u
        if best is not None:
            self.chained[best] = True
            self._claim(best, worker)
            self.left -= 1
        return best

    def _mine(self, tile, worker: int) -> bool:
        """Whether ``tile`` is the worker's: it read it first, or nobody did and it is the tile's home."""
        return self.owner.get(tile, self.homes.get(tile, worker)) == worker

    def _claim(self, i: int, worker: int) -> None:
        """Node ``i``'s tiles that nobody read yet: the worker's from now on (it reads them)."""
        for t in self.nodes[i].tiles:
            self.owner.setdefault(t, worker)

    def finished(self, i: int) -> None:
        for u in self.users[i]:
            self.waiting[u] -= 1
            if not self.waiting[u] and not self.chained[u]:
                bisect.insort(self.ready, (self.nodes[u].rank, u))


def _host(address: str) -> str:
    """The host of a Dask worker's address (tcp://10.0.0.5:40123 -> 10.0.0.5)."""
    return address.rsplit("://", 1)[-1].rsplit(":", 1)[0]


def _dask_threads(client) -> list[str]:
    """The Dask workers' addresses, one a thread (a worker of n threads named n times: each thread is
    given chains as a pool worker is), a host's together."""
    info = client.scheduler_info().get("workers", {})
    return [a for a in sorted(info, key=lambda a: (_host(a), a)) for _ in range(info[a].get("nthreads") or 1)]


def _blocks(homes: dict, workers: int) -> dict:
    """Tile -> the Dask worker (of ``workers``) whose tasks its nodes are: the tiles in the order of their
    ``homes`` (Runner.graph's; columns of tiles), an equal block of them a worker (with more workers than
    columns of tiles, parts of columns: every worker has tiles of its own)."""
    tiles = sorted(homes, key=lambda t: (homes[t], t))
    return {t: p * workers // len(tiles) for p, t in enumerate(tiles)}


def _dask_start(hosts: dict, threads: int | None, modules: tuple[str, ...] = (), tree: str | None = None,
                dask_worker=None) -> None:
    """A Dask worker set up for a tiled run's tasks, as a pool worker is (_worker_start): its memory
    (tune_malloc: Dask's MALLOC_TRIM_THRESHOLD_ maps and unmaps every tile's arrays again), its host
    stages' threads (the run's --threads, else its share of the host's CPUs: ``hosts``, each host's
    worker threads), and the tasks' ``modules`` imported before its first task; RuntimeError when its
    wavemesh is not the client's (``tree``: the client's tree_fingerprint)."""
    if tree is not None and tree != tree_fingerprint():
        import wavemesh  # start-up: only for this error (the package is loaded: its path)

        raise RuntimeError(f"another wavemesh there: version {wavemesh.__version__} from "
                           f"{os.path.dirname(os.path.dirname(wavemesh.__file__))}, whose files differ from "
                           "this one's")
    for name in modules:
        importlib.import_module(name)

    tune_malloc()
    here = hosts.get(_host(dask_worker.address), 1) if dask_worker is not None else 1
    native.set_threads(threads if threads is not None else max(1, native.cores() // here))


@record(frozen=True)
class _Made:
    """In a chain's args sent to a Dask worker (_dask_chain): the future at ``arg`` of the task's args (None:
    this chain's results), its result ``at`` (None: the whole), ``pick`` of it when given."""

    arg: int | None
    at: int | None
    pick: Callable | None = None


def _dask_chain(steps: list, *made):
    """A chain of nodes on a Dask worker (Runner._dask_chains): each (fn, args) in turn, a _Made in args
    one of ``made`` (the futures' results) or of this chain's results; their results as a list."""
    out: list = []
    for fn, args in steps:
        vals = []
        for a in args:
            if isinstance(a, _Made):
                v = out if a.arg is None else made[a.arg]
                v = v if a.at is None else v[a.at]
                a = a.pick(v) if a.pick else v
            vals.append(a)
        out.append(fn(*vals))
    return out


def _this_cpu() -> int | None:
    """The CPU this thread runs on now (glibc's sched_getcpu), None where that is not known."""
    if not _GETCPU:
        try:
            _GETCPU.append(ctypes.CDLL(None, use_errno=True).sched_getcpu)
        except (OSError, AttributeError):
            _GETCPU.append(None)
    cpu = _GETCPU[0]() if _GETCPU[0] is not None else -1
    return cpu if cpu >= 0 else None


_GETCPU: list = []


class _Local:
    """A pool worker that is a thread of this process (THREADS): chains from a queue, run as a forked worker
    runs them (_run_chain), each result put on a list and a byte written to ``wake``'s pipe, which the
    pool's loop polls with the workers' pipes; kept on ``cpu`` (PIN).  Its nodes' args and results are the
    objects themselves (nothing pickled, nothing forked); the loop, answering the forked workers, takes the
    interpreter's lock from it only for that."""

    def __init__(self, cpu: int | None = None):
        import queue  # start-up: only for a pool
        import threading  # the same

        self.inbox: queue.SimpleQueue = queue.SimpleQueue()
        self.out: list = []
        self.wake, self._wake_w = os.pipe()
        self.cpu = cpu
        self.cpu_s = 0.0  # the thread's CPU seconds, once it has ended
        self.thread = threading.Thread(target=self._loop, name="wavemesh-tiles", daemon=True)

    def start(self) -> None:
        self.thread.start()

    def put(self, steps: list) -> None:
        self.inbox.put(steps)

    def _loop(self) -> None:
        if self.cpu is not None:  # this thread alone (PIN)
            try:
                os.sched_setaffinity(0, {self.cpu})
            except OSError:
                pass
        while (steps := self.inbox.get()) is not None:
            try:
                reply = ("ok", _run_chain(steps), None)
            except Exception as e:  # raised in the loop (WavemeshError with its hint)
                reply = ("error", e, getattr(e, "hint", None))
            self.out.append(reply)
            os.write(self._wake_w, b"x")
        self.cpu_s = time.thread_time()
        os.close(self.wake)
        os.close(self._wake_w)

    def reply(self) -> list:
        """The next chain's results (a byte read from ``wake``), or its error raised here."""
        os.read(self.wake, 1)
        kind, value, _ = self.out.pop(0)
        if kind == "error":
            raise value
        return value

    def stop(self, wait: bool) -> None:
        """No more chains: the thread ends after the one it runs, if any (``wait``: waited for, the graph
        done; else not: a run that failed returns at once), and closes its pipe."""
        if not self.thread.is_alive() and self.thread.ident is None:  # never started (the forks failed)
            os.close(self.wake)
            os.close(self._wake_w)
            return
        self.inbox.put(None)
        if wait:
            self.thread.join()


def _run_chain(steps: list, kept: dict | None = None, held: dict | None = None) -> list:
    """A chain's steps run in turn: a _Prev in args the previous step's result, a _Kept an arg in
    ``kept``, a _Held a result in ``held``; the results as a list."""
    out: list = []
    for fn, args in steps:
        args = tuple(kept[a] if isinstance(a, _Kept) else
                     (a.pick(out[-1]) if a.pick else out[-1]) if isinstance(a, _Prev) else
                     (a.pick(held[a.node]) if a.pick else held[a.node]) if isinstance(a, _Held) else a
                     for a in args)
        out.append(fn(*args))
    return out


class _Ready:
    """What multiprocessing.connection.wait does for the pool's loop, with one poll object kept for the graph
    and only the changes registered (wait makes a selector and registers every pipe and sentinel anew at
    each call: a few per cent of the parent's CPU over a run's round trips)."""

    def __init__(self):
        self.poller = select.poll() if hasattr(select, "poll") else None
        self.fds: set[int] = set()

    def wait(self, objs: list, timeout: float | None = None) -> set[int]:
        """The file descriptors of ``objs`` (connections, sentinels) ready to read (or ended), once one is
        (``timeout``: at most that many seconds, 0: those ready now)."""
        if self.poller is None:
            from multiprocessing.connection import wait  # start-up: only where there is no poll

            return {o if isinstance(o, int) else o.fileno() for o in wait(objs, timeout)}
        fds = {o if isinstance(o, int) else o.fileno() for o in objs}
        for fd in self.fds - fds:
            self.poller.unregister(fd)
        for fd in fds - self.fds:
            self.poller.register(fd, select.POLLIN)
        self.fds = fds
        return {fd for fd, _ in self.poller.poll(None if timeout is None else 1000 * timeout)}


_DUMPS = pickle.dumps  # a message's bytes, as _Pipe.send pickles it (_Pipe.recv, or a Connection, reads it)


# The pool's processes and pipes are its own, not multiprocessing's: a fork and a Unix socket pair each, the
# messages framed as multiprocessing.connection.Connection frames them (either end may be one).  Importing
# multiprocessing.connection and .reduction (socket's enums, tempfile, subprocess) cost every tiled run
# 45 M instructions of its serial start, a tenth of the interpreter's start and imports (docs/tiles.md,
# "On 2 cores").
def _pipe() -> tuple[_Pipe, _Pipe]:
    """Both ends of a duplex pipe (a Unix stream socket pair, as multiprocessing.Pipe() makes)."""
    import _socket  # the C module alone: socket.py's enum tables cost the tiled start (docs/tiles.md)

    a, b = _socket.socketpair()
    return _Pipe(a.detach()), _Pipe(b.detach())


class _Pipe:
    """One end of a pool worker's pipe: byte messages (send_bytes, recv_bytes) framed as multiprocessing's
    Connection frames them (a 4-byte big-endian length, or -1 and an 8-byte one), objects pickled (send,
    recv), poll, fileno, close."""

    def __init__(self, fd: int):
        self._fd: int | None = fd

    def fileno(self) -> int:
        if self._fd is None:
            raise OSError("handle is closed")
        return self._fd

    def close(self) -> None:
        if self._fd is not None:
            fd, self._fd = self._fd, None
            os.close(fd)

    def __enter__(self) -> _Pipe:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self) -> None:
        self.close()

    def send_bytes(self, buf) -> None:
        view = memoryview(buf).cast("B")
        n = len(view)
        head = struct.pack("!i", n) if n <= 0x7FFFFFFF else struct.pack("!iQ", -1, n)
        if n > 16384:  # as Connection: a large message after its header, a small one with it
            self._write(head)
            self._write(view)
        else:
            self._write(head + view.tobytes())

    def _write(self, buf) -> None:
        fd, view = self.fileno(), memoryview(buf)
        while view:
            view = view[os.write(fd, view):]

    def recv_bytes(self) -> bytearray:
        (n,) = struct.unpack("!i", self._read(4, True))
        if n == -1:
            (n,) = struct.unpack("!Q", self._read(8))
        return self._read(n)

    def _read(self, n: int, first: bool = False) -> bytearray:
        fd, buf = self.fileno(), bytearray(n)
        view, got = memoryview(buf), 0
        while got < n:
            k = os.readv(fd, [view[got:]])
            if not k:
                if first and not got:
                    raise EOFError
                raise OSError("got end of file during message")
            got += k
        return buf

    def send(self, obj) -> None:
        self.send_bytes(_DUMPS(obj))

    def recv(self):
        return pickle.loads(self.recv_bytes())

    def poll(self, timeout: float = 0.0) -> bool:
        p = select.poll()
        p.register(self.fileno(), select.POLLIN)
        return bool(p.poll(None if timeout is None else 1000 * timeout))


class _Forked:
    """A pool worker process: ``target(*args)`` in a fork of this process, its exit status then, as
    multiprocessing's fork context runs a Process (start, pid, sentinel: readable once it has ended, join,
    exitcode, is_alive, terminate, kill); a traceback on stderr and status 1 if ``target`` raises."""

    def __init__(self, target: Callable, args: tuple = ()):
        self._target, self._args = target, args
        self.pid: int | None = None
        self.sentinel: int | None = None
        self.exitcode: int | None = None

    def start(self) -> None:
        r, w = os.pipe()  # the child holds w: r reads its end once the child has ended
        pid = os.fork()
        if pid == 0:  # the child: never returns
            code = 1
            try:
                os.close(r)
                self._target(*self._args)
                code = 0
            except SystemExit as e:
                code = e.code if isinstance(e.code, int) else 0 if e.code is None else 1
            except BaseException:
                import traceback  # only a worker that failed prints one

                traceback.print_exc()
            finally:
                for f in (sys.stdout, sys.stderr):
                    try:
                        f.flush()
                    except Exception:  # noqa: S110 - its end comes anyway
                        pass
                os._exit(code)
        os.close(w)
        self.pid, self.sentinel = pid, r

    def _reap(self, block: bool) -> None:
        if self.exitcode is None:
            try:
                pid, status = os.waitpid(self.pid, 0 if block else os.WNOHANG)
            except ChildProcessError:  # reaped elsewhere
                return
            if pid:
                self.exitcode = os.waitstatus_to_exitcode(status)

    def join(self, timeout: float | None = None) -> None:
        if self.exitcode is None and timeout is not None:
            p = select.poll()
            p.register(self.sentinel, select.POLLIN)
            if not p.poll(1000 * max(0.0, timeout)):
                return
        self._reap(True)

    def is_alive(self) -> bool:
        self._reap(False)
        return self.exitcode is None

    def terminate(self) -> None:
        self._signal(signal.SIGTERM)

    def kill(self) -> None:
        self._signal(signal.SIGKILL)

    def _signal(self, sig: int) -> None:
        if self.exitcode is None:
            try:
                os.kill(self.pid, sig)
            except ProcessLookupError:
                pass

    def __del__(self) -> None:
        if self.sentinel is not None:
            os.close(self.sentinel)
            self.sentinel = None


def _pipe_room(pipe) -> int:
    """The bytes a second chain's messages may take in a worker's pipe with the first's: half its socket's
    send buffer (the parent's send never waits on them: the other half is for the kernel's own cost of each
    message, some 770 bytes, and two chains are a few messages), 0 where that is not known."""
    import _socket  # the C module alone, as _pipe

    fd = os.dup(pipe.fileno())
    try:
        sock = _socket.socket(fileno=fd)
    except OSError:  # not a socket: the duplicate closed here
        os.close(fd)
        return 0
    try:
        return sock.getsockopt(_socket.SOL_SOCKET, _socket.SO_SNDBUF) // 2
    except OSError:
        return 0
    finally:
        sock.close()


def _let_go(pipe) -> None:
    """A pool worker told to end (its loop returns at the None), not waited for here."""
    try:
        pipe.send(None)
    except OSError:
        pass


def _reply(proc, pipe):
    """A worker's result from its pipe, or its error raised here."""
    try:
        kind, value, hint = pipe.recv()
    except (EOFError, OSError):
        _lost(proc)
    if kind == "error":
        if isinstance(value, WavemeshError) and hint is not None:
            value.hint = hint
        raise value
    return value


def _lost(proc) -> None:
    proc.join(1.0)
    raise WavemeshError(f"a tile worker ended without its result (exit status {proc.exitcode})",
                        hint="out of memory? try a smaller --tile or fewer --workers") from None


@record(frozen=True)
class _Kept:
    """In a task's args sent to a pool worker: an arg it was sent before (Runner.graph's ``shared``)."""

    graph: int
    index: int


_HELD: dict = {}  # a pool worker's results kept for a _Held (_worker_loop)


def _worker_loop(pipe, parent: int, threads: int | None = None, cpu: int | None = None) -> None:
    """A pool worker: tasks from its pipe until it closes (None); ("keep", key, value): an arg its next tasks
    name by the key; ("chain", [(fn, args), ...], graph, store, drops): each step in turn, a _Prev in args
    the one before's result, the results (or the error) back as a list, each step's result kept under its
    node in ``store`` (-1: not kept) for a _Held in a later task's args, and the results named in ``drops``
    let go (a new graph: every one)."""
    _worker_start(parent, threads, cpu)
    kept: dict = {}
    held = _HELD  # node -> the result this worker made, of the graph held_graph
    held.clear()
    held_graph = None
    while True:
        try:
            task = pipe.recv()
        except (EOFError, OSError):
            task = None
        if task is None:
            _worker_end()
            return
        if task[0] == "keep":  # ("keep", key, value)
            kept[task[1]] = task[2]
            continue
        _, steps, graph, store, drops = task  # ("chain", steps, graph, store, drops)
        if graph != held_graph:
            held.clear()
            held_graph = graph
        try:
            out = _run_chain(steps, kept, held)
            for k, r in zip(store, out, strict=True):
                if k >= 0:
                    held[k] = r
            for k in drops:
                held.pop(k, None)
            reply = ("ok", out, None)
        except Exception as e:  # the parent raises it (WavemeshError with its hint)
            reply = ("error", e, getattr(e, "hint", None))
        try:
            pipe.send(reply)
        except Exception as e:  # an error that does not pickle: its text
            pipe.send(("error", RuntimeError(f"{type(e).__name__}: {e}"), None))


def _worker_start(parent: int, threads: int | None = None, cpu: int | None = None) -> None:
    """A pool worker's start: Ctrl-C is the parent's to handle (it ends the workers, _end_workers), SIGTERM
    ends the worker at once (SIGHUP too, unless the run ignores it: nohup), and the worker ends when its
    parent does, even one killed outright (Linux's PR_SET_PDEATHSIG).  The signals, blocked since the fork
    (_start_pool), are let through once these are set.  ``threads``: the host stages' threads in this
    worker (native.set_threads), unless the run gave its own (--threads); ``cpu``: the CPU it is kept on
    (PIN), first (a CPU taken away meanwhile: it goes where the kernel puts it).  The objects it was forked
    with are frozen for its collector (gc.freeze: a list splice, no object touched), which then never walks
    them: its collections wrote into their headers, the parent's pages copied for it as it did."""
    gc.freeze()
    if cpu is not None:
        try:
            os.sched_setaffinity(0, {cpu})
        except OSError:
            pass
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if signal.getsignal(signal.SIGHUP) is not signal.SIG_IGN:
        signal.signal(signal.SIGHUP, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _WORKER_SIGNALS)
    tune_malloc()
    if threads is not None and native.threads_set() is None:  # the host stages' threads (--threads: as given)
        native.set_threads(threads)
    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM, 0, 0, 0)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent:  # the parent ended before the line above
        os._exit(1)


# the pool workers a run let go that were still exiting (freeing their memory) when it ended: reaped by a
# later Runner, or by init once this process has ended (_end_workers); a forked child starts without them
# (they are not its children: joining one there fails)
_EXITING: list = []
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_EXITING.clear)


def _worker_end() -> None:
    """A pool worker's end: its exit (the kernel freeing its heap, tens of milliseconds of system time) at
    the lowest priority, so that it takes a CPU only when the parent and the other workers leave one (the
    run's last tasks, the parent's writing and its own end): not waited for (_end_workers), it need not be
    early."""
    try:
        os.nice(19)
    except OSError:
        pass


def _end_workers(pool: list, gently: bool) -> None:
    """End the workers: ``gently`` (the run is done) by closing their pipes, not waited for: a worker still
    exiting (the kernel freeing its memory, tens of milliseconds for a tile worker's heap, after its last
    result) is left to end beside this process's own end, and reaped by a later Runner or, once this
    process has ended, by init (multiprocessing's exit handler would wait for it: it is taken off its list
    of children); else at once (SIGTERM, then SIGKILL after a second), reaped here."""
    for proc in list(_EXITING):  # a past run's, ended by now: reaped
        proc.join(0)
        if proc.exitcode is not None:
            _EXITING.remove(proc)
    for proc, pipe in pool:
        if gently:
            try:
                pipe.send(None)
            except OSError:
                pass
        elif proc.is_alive():
            proc.terminate()
    if gently:
        for proc, pipe in pool:
            pipe.close()
            proc.join(0)
            if proc.exitcode is None:
                _EXITING.append(proc)
                # multiprocessing's exit handler waits for its own (a caller's Process given here)
                getattr(sys.modules.get("multiprocessing.process"), "_children", set()).discard(proc)
        return
    deadline = time.monotonic() + 1.0
    for proc, pipe in pool:
        proc.join(max(0.0, deadline - time.monotonic()))
        if proc.is_alive():
            proc.kill()
            proc.join(1.0)
        pipe.close()
