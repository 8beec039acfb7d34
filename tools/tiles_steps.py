#!/usr/bin/env python3
"""Where a tiled run spends its time: `wavemesh mesh --tile` with every task's CPU counted in its worker.

    .venv/bin/python tools/tiles_steps.py INPUT --workers N [wavemesh mesh options ...] [--runner NAME=VALUE]

Runs `wavemesh mesh INPUT -o /tmp/... --quiet` with the options given (e.g. `--tile 1025 --metric
vertical --zeta 10`) in this process, each task of the tiles.Runner wrapped so that the worker that runs
it measures it (getrusage: user + system CPU, system CPU, minor page faults; the tile windows it read and
quantised, tile_heightfield's misses, and the samples of the windows it read, bands of seams included;
the tiles it holds after).  Prints the run's wall time and CPU (the workers' counted to their end, after
the run's for those still exiting as it ended, which it does not wait for) and its end (from the last
task's end to the command's return: the parent's last writing, the files moved into place), and its
writes to the workers' pipes (wall against CPU: a woken worker that preempts it mid-send; the bytes
both ways), and the
times no task runs (the command's start to the first task, between the parts, the end); then, for
the quantisation's strips and for the task graph: the wall time, the tasks and the parent's round trips
to the pool for them (runner.CHAIN, BATCH_READY, AHEAD), each worker's CPU and busy time, the time it waited
(the span less its tasks: at a barrier, for the parent, for a task's inputs), the most tiles it held and
how often it found no task in its pipe (it waited for the parent: a count that holds on a loaded machine),
how far apart the workers' first tasks started (the parent's first chains written one after the other),
then each step's CPU summed over the workers; what the tasks' page faults cost at this machine's price
of a fresh page (page_cost: the CPU of a page's first write, measured after the run); and the model
of the speed-up over one worker, the CPU
outside the workers (this process's) plus the busiest worker's CPU in each part.  CPU seconds, page
faults and reads hold on a loaded machine where wall times do not; run it with --workers 1 and 2 to
compare (docs/tiles.md, "Running the tiles").  ``--runner NAME=VALUE`` sets one of tiles.runner's
settings for the run (CHAIN=2, AHEAD=0, PIN=0, ...).
"""

from __future__ import annotations

import os

# as the command (wavemesh/__init__.py): numpy's OpenBLAS without its threads, which spin in this process
# when a task that runs here (a pool's thread) calls it
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import functools  # noqa: E402
import gc  # noqa: E402
import resource  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from multiprocessing import connection  # noqa: E402

from wavemesh import cli  # noqa: E402
from wavemesh.tiles import jobs, runner, source  # noqa: E402


class _Counts(threading.local):
    """A thread's counts (a pool's workers that are threads of this process count apart): the reads
    tile_heightfield's cache missed, the samples of every window read; a pool worker's receives that found
    nothing in its pipe (it waited for the parent) and their seconds."""

    reads, samples, stalls, stall_s = 0, 0, 0, 0.0


COUNTS = _Counts()
_recv = connection.Connection.recv


# this process's writes to its workers' pipes: count, wall and CPU seconds, bytes; and the bytes it read
SENDS = [0, 0.0, 0.0, 0, 0]
_send, _recv_bytes = connection.Connection._send, connection.Connection._recv_bytes


def _send_timed(conn, buf, *args):
    t0, c0 = time.perf_counter(), time.thread_time()
    try:
        return _send(conn, buf, *args)
    finally:
        SENDS[0] += 1
        SENDS[1] += time.perf_counter() - t0
        SENDS[2] += time.thread_time() - c0
        SENDS[3] += len(buf)


def _recv_bytes_counted(conn, *args):
    buf = _recv_bytes(conn, *args)
    SENDS[4] += buf.getbuffer().nbytes
    return buf


def _recv_counted(conn):
    if conn.poll(0):
        return _recv(conn)
    t0 = time.perf_counter()
    try:
        return _recv(conn)
    finally:
        COUNTS.stalls += 1
        COUNTS.stall_s += time.perf_counter() - t0
_read, _window = jobs._tile_heightfield, source.Source.read


def _counted(*args):
    COUNTS.reads += 1
    return _read(*args)


def _window_counted(src, x, y, w, h):
    COUNTS.samples += w * h
    return _window(src, x, y, w, h)


jobs._tile_heightfield = _counted  # before the pool forks: the workers count their own
source.Source.read = _window_counted


# the thread that runs the task (a pool's last worker is a thread of this process, beside the pool's loop)
WHO = getattr(resource, "RUSAGE_THREAD", resource.RUSAGE_SELF)


def timed(fn, *args):
    """fn(*args) and what it cost this worker: (the worker, CPU s, start, end, system s, minor faults, reads,
    the tiles this process holds after it, the samples read, and the worker's waits for the parent so far:
    count, seconds).  The worker is (pid, thread id): a pool's workers that are threads of this process
    (runner.THREADS) are apart."""
    u0, t0, r0, n0 = resource.getrusage(WHO), time.perf_counter(), COUNTS.reads, COUNTS.samples
    c0 = time.thread_time()
    out = fn(*args)
    cpu = time.thread_time() - c0
    u1 = resource.getrusage(WHO)
    c = COUNTS
    return out, ((os.getpid(), threading.get_native_id()), cpu, t0, time.perf_counter(),
                 u1.ru_stime - u0.ru_stime, u1.ru_minflt - u0.ru_minflt, c.reads - r0, len(jobs._TILE_CACHE),
                 c.samples - n0, c.stalls, c.stall_s)


def _result(r):
    return r[0]


def _picked(pick, r):
    """pick of a timed result (as functools.partial(_picked, pick): it pickles, for the pool and Dask)."""
    return pick(r[0])


LOG: list = []  # (part, start, end, the pool's round trips, [(step, info)])
_map, _graph, _reply = runner.Runner.map, runner.Runner.graph, runner._reply
TRIPS = [0]  # the parent's round trips to a pool worker (runner._reply: one for each task or chain sent)


def _counted_reply(proc, pipe):
    TRIPS[0] += 1
    return _reply(proc, pipe)


def _timed_map(self, fn, tasks, done=None):
    t0, n0 = time.perf_counter(), TRIPS[0]
    out = _map(self, timed, [(fn, *t) for t in tasks], (lambda r: done(r[0])) if done else None)
    LOG.append((f"map {fn.__name__}", t0, time.perf_counter(), TRIPS[0] - n0,
                [(fn.__name__, o[1]) for o in out]))
    return [o[0] for o in out]


def _timed_graph(self, nodes, done=None, homes=None, shared=(), keep=None, last=False, seen=None):
    """Runner.graph with every node timed; every result kept until the end (each carries its timing), the
    ones outside ``keep`` None in what it returns, as Runner.graph's; every result comes back (``seen``
    not passed on: done is given each one)."""
    if nodes and nodes[0].fn is timed:  # a map's tasks (Runner.map makes a graph of them), timed there
        return _graph(self, nodes, done, homes, shared, keep, last, seen)
    def wrap(a):
        if isinstance(a, runner.Ref):
            return runner.Ref(a.node, functools.partial(_picked, a.pick) if a.pick else _result)
        return a

    wrapped = [runner.Node(timed, (n.fn, *map(wrap, n.args)), n.rank, n.tiles) for n in nodes]
    t0, n0 = time.perf_counter(), TRIPS[0]
    out = _graph(self, wrapped, (lambda i, r: done(i, r[0])) if done else None, homes, shared, last=last)
    steps = [f"{n.rank[1]} {n.fn.__name__.strip('_')}" for n in nodes]
    LOG.append(("graph", t0, time.perf_counter(), TRIPS[0] - n0,
                [(s, o[1]) for s, o in zip(steps, out, strict=True)]))
    GRAPH.append((nodes, homes or {}, [o[1][1] for o in out], self.workers))
    kept = set(range(len(nodes)) if keep is None else keep)
    return [o[0] if i in kept else None for i, o in enumerate(out)]


GRAPH: list = []  # (nodes, homes, each node's CPU seconds, workers)


def simulate(nodes, homes: dict, cost: list, workers: int) -> float:
    """The graph's makespan on ``workers`` workers that answer at once, each node taking its measured
    CPU time, scheduled as the pool schedules (runner._Schedule: rank, the worker that read the tile)."""
    import heapq

    sched = runner._Schedule(nodes, {t: int(h * workers) for t, h in homes.items()})
    running: list = []
    idle, now = list(range(workers)), 0.0
    while True:
        for w in list(idle):
            i = sched.take(w if workers > 1 else None)
            if i is not None:
                heapq.heappush(running, (now + cost[i], w, i))
                idle.remove(w)
        if not running:
            return now
        now, w, i = heapq.heappop(running)
        sched.finished(i)
        idle.insert(0, w)


def simulate_pool(nodes, homes: dict, cost: list, workers: int, latency: float, ahead: bool = True
                  ) -> float:
    """The graph's makespan on ``workers`` pool workers given chains as Runner.graph gives them
    (runner._Schedule.chain: CHAIN, BATCH_READY and, with ``ahead``, AHEAD), each node taking its measured
    CPU time, the parent answering each chain's results at once but its next chain reaching a worker
    that has none ``latency`` seconds later (a worker with a chain sent ahead goes straight on)."""
    import heapq

    sched = runner._Schedule(nodes, {t: int(h * workers) for t, h in homes.items()})
    saved, runner.AHEAD = runner.AHEAD, ahead
    try:
        given: list[list] = [[] for _ in range(workers)]  # each worker's chains, the first running
        ends: list = []  # (the running chain's end, worker)

        def give(now: float) -> None:
            for w in range(workers):  # the workers with none first, then the chains ahead
                if not given[w] and (chain := sched.chain(w, workers)):
                    given[w].append(chain)
                    heapq.heappush(ends, (now + latency + sum(cost[i] for i in chain), w))
            for w in range(workers):
                if len(given[w]) == 1 and (chain := sched.chain(w, workers, ahead=True)):
                    given[w].append(chain)

        give(0.0)
        now = 0.0
        while ends:
            now, w = heapq.heappop(ends)
            for i in given[w].pop(0):
                sched.finished(i)
            if given[w]:
                heapq.heappush(ends, (now + sum(cost[i] for i in given[w][0]), w))
            give(now)
        return now
    finally:
        runner.AHEAD = saved


def main(argv: list[str]) -> int:
    while "--runner" in argv:  # --runner NAME=VALUE: a setting of tiles.runner (CHAIN=2, AHEAD=0, ...)
        k = argv.index("--runner")
        name, value = argv[k + 1].split("=")
        if not name.isupper() or not hasattr(runner, name):
            raise SystemExit(f"--runner {argv[k + 1]}: tiles.runner has no setting {name}")
        setattr(runner, name, type(getattr(runner, name))(int(value)))
        del argv[k : k + 2]
    runner.Runner.map = _timed_map
    runner.Runner.graph = _timed_graph
    runner._reply = _counted_reply
    connection.Connection.recv = _recv_counted  # in the pool's workers (forked after this)
    connection.Connection._send = _send_timed
    connection.Connection._recv_bytes = _recv_bytes_counted
    out = os.path.join(tempfile.mkdtemp(prefix="tiles-steps-"), "m.obj")
    gc.freeze()  # as the console script does (cli.main): the workers' collector leaves the imports' objects
    t0, c0, m0 = time.perf_counter(), os.times(), time.thread_time()
    rc = cli.main(["mesh", *argv[:1], "-o", out, "--quiet", *argv[1:]])
    end = time.perf_counter()  # CLOCK_MONOTONIC, as the workers' task times (timed)
    main = time.thread_time() - m0  # this thread's: the loop (a pool's last worker is another thread)
    wall, exiting = end - t0, list(runner._EXITING)
    for proc in exiting:  # the pool's workers still exiting as the run ended (not waited for by it)
        proc.join()
    after, c1 = time.perf_counter() - t0 - wall, os.times()
    here = c1.user + c1.system - c0.user - c0.system
    there = c1.children_user + c1.children_system - c0.children_user - c0.children_system
    tasks_here = sum(i[1] for *_, infos in LOG for _, i in infos if i[0][0] == os.getpid())
    last = max((i[3] for *_, infos in LOG for _, i in infos), default=None)  # None: no task (untiled, failed)
    print(f"wall {wall:.2f} s; CPU: this process {here:.2f} s (its own, outside the tasks: "
          f"{here - tasks_here:.2f}; its main thread {main:.2f}), the workers {there:.2f} s"
          + (f" ({len(exiting)} still exiting as the run ended, for {1000 * after:.0f} ms more)" if exiting
             else "")
          + (f"; the run's end, from its last task's to the command's return: {1000 * (end - last):.0f} ms"
             if last is not None else "; no tile task ran"))
    spans = [(min(i[2] for _, i in infos), max(i[3] for _, i in infos)) for *_, infos in LOG if infos]
    if spans:  # the serial parts: the parent's own work (and the pool's start) while no task runs
        gaps = [1000 * (b[0] - a[1]) for a, b in zip(spans, spans[1:], strict=False)]
        print(f"no task running: from the command's start to the first task {1000 * (spans[0][0] - t0):.1f} "
              "ms" + "".join(f", between part {k + 1}'s last and part {k + 2}'s first {g:.1f} ms"
                             for k, g in enumerate(gaps))
              + f", the end {1000 * (end - spans[-1][1]):.1f} ms")
    model = here - tasks_here
    for part, a, b, trips, infos in LOG:
        per: dict = {}
        steps: dict = {}
        for step, (who, cpu, s, e, sys_, flt, reads, held, samples, *stalls) in infos:
            # its waits at its first and last task; its page faults
            w = per.setdefault(who, [0.0, 0.0, 0, 0, stalls, stalls, 0])
            w[0], w[1], w[2], w[3], w[6] = w[0] + cpu, w[1] + e - s, w[2] + 1, max(w[3], held), w[6] + flt
            w[4], w[5] = min(w[4], stalls), max(w[5], stalls)
            x = steps.setdefault(step, [0, 0.0, 0.0, 0, 0, 0])
            x[0], x[1], x[2], x[3], x[4] = x[0] + 1, x[1] + cpu, x[2] + sys_, x[3] + flt, x[4] + reads
            x[5] += samples
        model += max(w[0] for w in per.values())
        firsts = [min(i[2] for _, i in infos if i[0] == who) for who in per]  # each worker's first start
        print(f"{part}: wall {b - a:.3f} s; {len(infos)} tasks in {trips} round trips to the pool (0: none); "
              "per worker CPU / busy / waiting s (tasks, the most tiles held, page faults; the times it "
              "found no task in its pipe between its first and last, and their ms): "
              + ", ".join(f"{w[0]:.2f} / {w[1]:.2f} / {b - a - w[1]:.2f} ({w[2]}, {w[3]}, {w[6]}; "
                          f"{w[5][0] - w[4][0]}, {1000 * (w[5][1] - w[4][1]):.0f})" for w in per.values())
              + (f"; the workers' first tasks started within {1000 * (max(firsts) - min(firsts)):.1f} ms"
                 if len(firsts) > 1 else ""))
        for step, x in steps.items():
            print(f"  {step:<16} {x[0]:4d} tasks  CPU {x[1]:6.2f} s  system {x[2]:5.2f} s  "
                  f"page faults {x[3]:8d}  tiles read {x[4]:3d}  samples read {x[5] / 1e6:6.2f} M")
    if SENDS[0]:  # a woken worker that takes this process's CPU in the middle of a send: wall above CPU
        print(f"this process's writes to the pool's pipes: {SENDS[0]}, {1000 * SENDS[1]:.1f} ms wall, "
              f"{1000 * SENDS[2]:.1f} ms CPU, {SENDS[3] / 1e6:.2f} MB; read from them "
              f"{SENDS[4] / 1e6:.2f} MB")
    print(f"model: this process's own CPU + the busiest worker's CPU in each part = {model:.2f} s")
    for nodes, homes, cost, workers in GRAPH:
        span = {w: simulate(nodes, homes, cost, w) for w in sorted({1, workers})}
        print("the graph's makespan with these tasks' CPU times, workers that answer at once (its waits "
              "for inputs and at the end included): "
              + ", ".join(f"{w} worker{'s' if w > 1 else ''} {t:.2f} s" for w, t in span.items())
              + (f" ({span[1] / span[workers]:.2f}x)" if workers > 1 else ""))
        if workers > 1:  # the round trips' cost: the pool's chains, the parent answering in 0.5 ms
            pool = {a: simulate_pool(nodes, homes, cost, workers, 0.0005, a) for a in (False, True)}
            print(f"  as the pool gives chains, the parent's answer reaching a worker without one in 0.5 ms: "
                  f"{pool[True]:.3f} s with chains sent ahead (AHEAD), {pool[False]:.3f} s without")
    faults = sum(i[5] for *_, infos in LOG for _, i in infos)
    if faults:  # what the tasks' page faults cost, at this machine's price of a fresh page
        each = page_cost()
        print(f"a fresh page here: {1e6 * each:.2f} us of CPU (written one by one, {PAGE_TEST >> 20} MiB): "
              f"the tasks' {faults} page faults about {faults * each:.2f} s of their CPU at that price")
    return rc


PAGE_TEST = 64 << 20


def page_cost() -> float:
    """CPU seconds a fresh page of anonymous memory costs this process at its first write (the fault, the
    kernel's zeroing and accounting): PAGE_TEST bytes mapped and written a byte a page, the best of 3."""
    import mmap

    import numpy as np

    best = float("inf")
    for _ in range(3):
        with mmap.mmap(-1, PAGE_TEST) as m:
            a = np.frombuffer(m, dtype=np.uint8)
            u0 = resource.getrusage(resource.RUSAGE_SELF)
            a[:: mmap.PAGESIZE] = 1
            u1 = resource.getrusage(resource.RUSAGE_SELF)
            del a
        pages = max(1, u1.ru_minflt - u0.ru_minflt)
        best = min(best, (u1.ru_utime - u0.ru_utime + u1.ru_stime - u0.ru_stime) / pages)
    return best


if __name__ == "__main__":
    if len(sys.argv) < 2 or sys.argv[1] in ("-h", "--help"):
        print(__doc__)
        sys.exit(0 if len(sys.argv) >= 2 else 2)
    sys.exit(main(sys.argv[1:]))
