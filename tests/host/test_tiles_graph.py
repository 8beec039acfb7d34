"""A tiled run's task graph (tiles.Runner.graph, tiles.tile_graph): every node after the nodes it reads,
the same results in this process and on a pool of 2 workers, the ready nodes in rank order and a tile's
nodes on the worker that read it first; the free meshes given (stream) or made give the same tiles; a
process's kept tiles are read-only, forgotten after their last step, and read anew from a replaced file;
a worker told to end lowers its priority, one still exiting as its run ends is reaped by a later Runner."""

from __future__ import annotations

import os

import numpy as np
import pytest
from wavemesh import api, tiles
from wavemesh.refine.native import RefineParams
from wavemesh.tiles import jobs
from wavemesh.tiles.runner import Node, Ref, _Schedule


def _add(*xs):
    return sum(xs)


def _first(pair):
    return pair[0]


def _pair(a, b):
    return (a, b)


def _pid_after(_):
    return os.getpid()


@pytest.mark.parametrize("threads", [0, 1, 2])
def test_graph_results_in_order_any_runner(threads, monkeypatch):
    """The same results in this process and on a pool of 2 whose workers are forked processes, threads of
    this process (runner.THREADS), or one of each; the interpreter's switch interval (runner.SWITCH_US while
    a thread runs) as it was after."""
    import sys

    from wavemesh.tiles import runner

    monkeypatch.setattr(runner, "THREADS", threads)
    switch = sys.getswitchinterval()
    # a diamond and a chain: each node sums its inputs; Ref with pick takes a part of a result
    nodes = [Node(_add, (1,)), Node(_add, (Ref(0), 10)), Node(_add, (Ref(0), 100)),
             Node(_pair, (Ref(1), Ref(2))), Node(_add, (Ref(3, _first), Ref(2), 1000))]
    want = [1, 11, 101, (11, 101), 1112]
    for workers in (1, 2):
        seen: list = []
        with tiles.Runner(workers) as run:
            assert run.graph(nodes, lambda i, r, seen=seen: seen.append(i)) == want
            # an arg sent once to each worker and kept there: the same results, a second graph too
            ten = 10
            kept = [Node(_add, (1,)), Node(_add, (Ref(0), ten)), Node(_add, (Ref(0), ten, ten))]
            assert run.graph(kept, shared=(ten,)) == [1, 11, 21]
            assert run.graph(kept[:2], shared=(ten,)) == [1, 11]
        assert sorted(seen) == list(range(len(nodes)))
        assert seen.index(0) < min(seen.index(1), seen.index(2)) and seen.index(3) < seen.index(4)
        assert sys.getswitchinterval() == switch
    with pytest.raises(ValueError, match="only earlier nodes"):
        _Schedule([Node(_add, (Ref(1),)), Node(_add, (1,))])


def test_last_graph_lets_its_workers_go():
    """``last``: the same results; the pool's workers told to end once nothing is left to give out (they
    end without the Runner's exit), and a later graph still runs (on a new pool)."""
    from wavemesh.tiles import runner

    nodes = [Node(_add, (1,)), Node(_add, (Ref(0), 10)), Node(_add, (Ref(0), 100)),
             Node(_pair, (Ref(1), Ref(2))), Node(_add, (Ref(3, _first), Ref(2), 1000))]
    forked = 3 - runner.THREADS  # the pool's forked workers (the others threads of this process)
    with tiles.Runner(3) as run:
        assert run.graph(nodes[:3]) == [1, 11, 101] and len(run.pool) == forked and not run.ended
        first = [p for p, _ in run.pool]
        assert run.graph(nodes, last=True) == [1, 11, 101, (11, 101), 1112]
        assert run.pool == [] and [p for p, _ in run.ended] == first
        for p in first:
            p.join(10)
            assert p.exitcode == 0  # ended by itself, before the Runner's exit
        assert run.graph(nodes[:2]) == [1, 11] and len(run.pool) == forked
    assert run.pool == [] == run.ended


def _in_runner() -> None:
    with tiles.Runner(1):
        pass


def test_ended_workers_reaped_by_a_later_runner():
    """A worker let go gently and still running is not waited for: kept for a later Runner to reap, off
    multiprocessing's children (whose exit handler would wait for it); reaped once it has ended, no zombie
    left; a child forked meanwhile runs its own Runner without it (not its child to join)."""
    import multiprocessing

    from wavemesh.tiles import runner

    ctx = multiprocessing.get_context("fork")
    here, there = ctx.Pipe()
    gate, opened = ctx.Pipe(duplex=False)
    # deaf to its pipe: running until the gate opens (a minute at most, whatever happens here)
    slow = ctx.Process(target=gate.poll, args=(60,), daemon=True)
    slow.start()
    there.close()
    try:
        runner._end_workers([(slow, here)], gently=True)
        assert slow in runner._EXITING and slow.exitcode is None
        assert slow not in multiprocessing.active_children()
        child = ctx.Process(target=_in_runner)
        child.start()
        child.join(30)
        assert child.exitcode == 0
    finally:
        opened.send(None)
    os.waitid(os.P_PID, slow.pid, os.WEXITED | os.WNOWAIT)  # ended, not reaped yet
    with tiles.Runner(1):
        pass
    assert slow.exitcode == 0 and slow not in runner._EXITING
    with pytest.raises(ChildProcessError):
        os.waitpid(slow.pid, os.WNOHANG)


def _loop_then_nice(pipe, out) -> None:
    from wavemesh.tiles import runner

    runner._worker_loop(pipe, os.getppid())
    out.send(os.nice(0))  # its priority as it would exit


def test_worker_told_to_end_lowers_its_priority():
    """A pool worker told to end (None down its pipe) lowers its priority to the lowest before it exits,
    so that its exit takes a CPU only where the parent and the other workers leave one."""
    import multiprocessing

    ctx = multiprocessing.get_context("fork")
    here, there = ctx.Pipe()
    out_r, out_w = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_loop_then_nice, args=(there, out_w))
    proc.start()
    there.close()
    out_w.close()
    here.send(("chain", [(_add, (1, 2))], 1, (-1,), ()))
    assert here.recv() == ("ok", [3], None)
    here.send(None)
    assert out_r.poll(30) and out_r.recv() == 19
    proc.join(30)
    assert proc.exitcode == 0


def _frozen(_):
    import gc

    return os.getpid(), gc.get_freeze_count(), gc.isenabled()


def test_pool_worker_freezes_what_it_was_forked_with(monkeypatch):
    """A forked pool worker starts with the objects it was forked with frozen for its collector (its
    collections never walk them, never write into the parent's pages), and its collector on; this
    process's is left as it was (nothing frozen here by the pool, whose thread workers run here)."""
    import gc

    from wavemesh.tiles import runner

    monkeypatch.setattr(runner, "THREADS", 1)
    before = gc.get_freeze_count()
    with tiles.Runner(3) as run:
        got = run.map(_frozen, [(i,) for i in range(12)])
    there = [(count, on) for pid, count, on in got if pid != os.getpid()]
    assert there and all(count > before and on for count, on in there)  # more than a fork inherits frozen
    assert all(count == before for pid, count, _ in got if pid == os.getpid())
    assert gc.get_freeze_count() == before


def _big(n, *_):
    return np.full(n, 7, dtype=np.int64)


def test_graph_large_messages_both_ways():
    """Tasks and results larger than a socket's buffer (4 MiB each way): the pool never has the parent and
    a worker both blocked sending (a second task sent while the worker sends its result)."""
    import signal

    n = 1 << 19
    nodes = [Node(_big, (n,)) for _ in range(4)]
    nodes += [Node(_big, (n, Ref(k % 4), Ref((k + 1) % 4)), (k,)) for k in range(12)]
    old = signal.signal(signal.SIGALRM, lambda *_: (_ for _ in ()).throw(TimeoutError("deadlock")))
    signal.alarm(60)
    try:
        with tiles.Runner(2) as run:
            out = run.graph(nodes)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    assert len(out) == 16 and all(len(x) == n and x[0] == 7 for x in out)


def _pid(*_):
    return os.getpid()


def test_graph_ahead_large_and_small_messages():
    """Many ready nodes: a worker is sent its next chain while it runs one (runner.AHEAD) when both fit in
    its pipe's buffer, else it is held and written as the first one's result comes: the same results with
    and without, large args and results (4 MiB, more than the buffer) in the mix never block both ends."""
    import signal

    from wavemesh.tiles import runner

    n = 1 << 19
    nodes = [Node(_big, (n if k % 5 == 0 else 3,), (k, 0), (k % 4,)) for k in range(40)]
    nodes += [Node(_big, (n if k % 3 == 0 else 5, Ref(k), Ref(k + 1)), (k + 1, 1), (k % 4,))
              for k in range(39)]
    nodes += [Node(_pid, (k,), (0, 2), (k % 4,)) for k in range(8)]
    homes = {t: t / 4 for t in range(4)}
    saved = runner.AHEAD  # put back after, whatever the default is
    old = signal.signal(signal.SIGALRM, lambda *_: (_ for _ in ()).throw(TimeoutError("deadlock")))
    signal.alarm(60)
    try:
        outs = []
        for ahead in (False, True):
            runner.AHEAD = ahead
            with tiles.Runner(2) as run:
                outs.append(run.graph(nodes, homes=homes))
    finally:
        runner.AHEAD = saved
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    for out in outs:
        assert [len(x) for x in out[:79]] == [n if k % 5 == 0 else 3 for k in range(40)] + \
            [n if k % 3 == 0 else 5 for k in range(39)]
        assert all(x[0] == 7 for x in out[:79])
        pids = set(out[79:])  # run in the workers (a thread of this process, runner.THREADS)
        assert len(pids) <= 2


def test_pipe_room_of_a_socket_and_of_a_plain_pipe():
    """runner._pipe_room: half a socket pipe's send buffer; 0 for a pipe that is no socket (no chain sent
    ahead there), its duplicate descriptor closed again."""
    import multiprocessing

    from wavemesh.tiles import runner

    here, there = multiprocessing.Pipe()
    r, w = multiprocessing.Pipe(duplex=False)  # os.pipe: no socket
    with here, there, r, w:
        assert runner._pipe_room(here) > 0
        before = len(os.listdir("/proc/self/fd")) if os.path.isdir("/proc/self/fd") else None
        assert runner._pipe_room(w) == 0
        if before is not None:
            assert len(os.listdir("/proc/self/fd")) == before


def _threads(*_):
    from wavemesh.refine import native

    return native.threads(), frozenset(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None


def test_pool_workers_share_the_cpus_host_threads():
    """A pool worker's host stages (native.threads) run on its share of the CPUs, the CPUs this process may
    use over the workers (at least 1), not on every one; a count the run set (--threads) is kept.  A pool
    of one worker a CPU (runner.PIN) keeps each worker on a CPU of its own, another pool where the kernel
    puts it."""
    from wavemesh.refine import native

    cpus = native.cores()
    mine = frozenset(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
    for workers in (cpus, cpus + 1):
        nodes = [Node(_threads, (k,), (0, k), (k % workers,)) for k in range(2 * workers)]
        homes = {t: t / workers for t in range(workers)}
        with tiles.Runner(workers) as run:
            out = run.graph(nodes, homes=homes)
        assert {t for t, _ in out} == {max(1, cpus // workers)}
        if mine is not None and workers == len(mine):
            pinned = {a for _, a in out}
            assert pinned <= {frozenset({c}) for c in mine} and len(pinned) == workers
            assert {frozenset({c}) for c in run.pinned} == pinned  # what the pool writes to first knows
        elif mine is not None:
            assert {a for _, a in out} == {mine}
            assert run.pinned == [None] * workers
    native.set_threads(3)
    try:
        with tiles.Runner(2) as run:
            assert {t for t, _ in run.graph(nodes[:4], homes={0: 0.0, 1: 0.5})} == {3}
    finally:
        native.set_threads(None)


def test_this_cpu_is_one_this_process_may_use():
    """runner._this_cpu: the CPU this process runs on (the pool writes an idle worker kept on it last); on
    Linux (glibc's sched_getcpu) always known."""
    import sys

    from wavemesh.tiles import runner

    cpu = runner._this_cpu()
    if sys.platform.startswith("linux"):
        assert cpu in os.sched_getaffinity(0)
    else:
        assert cpu is None or cpu >= 0


@pytest.mark.parametrize("threads", [0, 1, 2])
def test_graph_failure_raises_and_pool_ends(threads, monkeypatch):
    """A task's error, in a forked worker or a thread (runner.THREADS), raised by the graph; the forked
    workers ended."""
    from wavemesh.tiles import runner

    monkeypatch.setattr(runner, "THREADS", threads)
    procs: list = []
    nodes = [Node(_add, (1,)), *(Node(divmod, (1, k % 2), (0, k)) for k in range(6)), Node(_add, (Ref(0), 1))]
    with pytest.raises(ZeroDivisionError), tiles.Runner(2) as run:
        try:
            run.graph(nodes)
        finally:
            procs = [p for p, _ in run.pool]  # the runner forgets its pool as it ends it
    assert len(procs) == 2 - threads and not any(p.is_alive() for p in procs)


def test_schedule_rank_and_homes():
    # one worker: the ready node of least rank first, whatever the node order
    nodes = [Node(_add, (1,), (2, 0), (0,)), Node(_add, (1,), (0, 0), (1,)),
             Node(_add, (Ref(1),), (0, 1), (1,))]
    s = _Schedule(nodes)
    order = []
    while (i := s.take(None)) is not None:
        order.append(i)
        s.finished(i)
    assert order == [1, 2, 0]
    # two workers: a tile nobody read goes to its home, a tile read once to the worker that read it
    nodes = [Node(_add, (1,), (0, 0), (0,)), Node(_add, (1,), (1, 0), (1,)),
             Node(_add, (Ref(0),), (2, 1), (0,)), Node(_add, (Ref(1),), (2, 1), (1,))]
    s = _Schedule(nodes, {0: 1, 1: 0})
    assert s.take(0) == 1 and s.take(1) == 0
    s.finished(0)
    s.finished(1)
    assert s.take(1) == 2 and s.take(0) == 3
    # nothing of its own ready: a worker takes another's rather than wait
    s = _Schedule(nodes[:2], {0: 1, 1: 1})
    assert s.take(0, own=True) is None and s.take(0) == 0  # own: only its own
    # a node on two workers' tiles: its first tile's worker's in rank order, before that worker's later
    # nodes; the other worker takes its own
    nodes = [Node(_add, (1,), (0, 0), (0,)), Node(_add, (1,), (0, 0), (1,)),
             Node(_add, (Ref(0), Ref(1)), (1, 2), (0, 1)), Node(_add, (Ref(0),), (2, 0), (0,)),
             Node(_add, (Ref(1),), (2, 0), (1,))]
    s = _Schedule(nodes, {0: 0, 1: 1})
    assert s.take(0) == 0 and s.take(1) == 1
    s.finished(0)
    s.finished(1)
    assert s.take(1) == 4 and s.take(0) == 2 and s.take(0) == 3


@pytest.fixture(scope="module")
def plan(tmp_path_factory):
    rng = np.random.default_rng(4)
    y, x = np.mgrid[0:150, 0:190].astype(np.float64)
    z = 300 * np.sin(x / 17) * np.cos(y / 23) + 40 * np.sin((x + 2 * y) / 5) + rng.normal(0, 2, x.shape)
    path = tmp_path_factory.mktemp("graph") / "z.npy"
    np.save(path, z.astype(np.float32))
    return tiles.plan_tiles(tiles.open_source(str(path)), api.MeshParams(refine=RefineParams(zeta=4.0)), 64)


def test_given_free_meshes_equal_made_ones(plan):
    """stream's path (the free meshes made elsewhere, given) and mesh's: the same tiles."""
    made = tiles.run_tiles(plan, workers=1)
    frees = [tiles.free_tile(plan, i) for i in range(len(plan.tiles))]
    given = tiles.run_tiles(plan, workers=2, frees=frees)
    for a, b in zip(made, given, strict=True):
        assert np.array_equal(a.xy, b.xy) and np.array_equal(a.tris, b.tris)
        assert {k: v for k, v in a.report.items() if k != "seconds"} == \
            {k: v for k, v in b.report.items() if k != "seconds"}
    assert len(plan.tiles) == 9 and sum(r.report["seam_removed"] for r in made) > 0


def test_graph_steps_and_last_nodes(plan):
    nodes, roles = tiles.tile_graph(plan)
    n = len(plan.tiles)
    assert len(roles["free"]) == len(roles["finish"]) == len(roles["last"]) == n
    assert {nodes[k].fn for k in roles["last"]} == {jobs._thin_node}
    for k, node in enumerate(nodes):  # a node waits for the tiles its rank names, never a later tile
        assert all(a.node < k and nodes[a.node].rank <= node.rank for a in node.args
                   if isinstance(a, Ref))


def test_kept_tiles(plan, tmp_path):
    jobs.clear_tile_cache()
    t = plan.tiles[5]
    hf = tiles.tile_heightfield(plan, t)
    assert tiles.tile_heightfield(plan, t) is hf and not hf.values.flags.writeable
    jobs.forget_tile(plan, 5)
    assert tiles.tile_heightfield(plan, t) is not hf
    # keep=False (a seam's other tile): a kept tile as it is, one not kept read and not kept
    assert tiles.tile_heightfield(plan, t, keep=False) is tiles.tile_heightfield(plan, t)
    other = tiles.tile_heightfield(plan, plan.tiles[6], keep=False)
    assert other is not tiles.tile_heightfield(plan, plan.tiles[6], keep=False)
    assert np.array_equal(other.samples, tiles.tile_heightfield(plan, plan.tiles[6]).samples)
    assert len(jobs._TILE_CACHE) == 2
    # the file replaced under its name: read anew
    path = tmp_path / "r.npy"
    np.save(path, np.arange(64 * 64, dtype=np.float32).reshape(64, 64))
    p = tiles.plan_tiles(tiles.open_source(str(path)), api.MeshParams(refine=RefineParams(zeta=4.0)), 64)
    before = tiles.tile_heightfield(p, p.tiles[0]).values.copy()
    np.save(path, np.arange(64 * 64, dtype=np.float32).reshape(64, 64)[::-1].copy())
    os.utime(path, ns=(1, 1))
    after = tiles.tile_heightfield(p, p.tiles[0]).values
    assert not np.array_equal(before, after) and np.array_equal(after, before[::-1])
    jobs.clear_tile_cache()


def test_graph_finds_the_quantisation_error(plan):
    """A plan without its largest quantisation error (plan_tiles' defer_error): the graph's strips find it
    beside the free meshes (which do not read it), every later step reads it, and the plan has it after:
    the same q, zeta and tiles as a plan that found it first."""
    from dataclasses import replace

    from wavemesh.tiles.source import strip_error

    deferred = replace(plan, quant=replace(plan.quant, q=None), zeta_used=None)
    nodes, roles = tiles.tile_graph(deferred)
    q = roles["q"]
    assert nodes[q].fn is jobs._largest and nodes[q].args
    assert all(nodes[a.node].fn is strip_error for a in nodes[q].args)
    assert not any(Ref(q) in nodes[k].args for k in roles["free"])
    steps = (jobs._finish_node, jobs._seam_node, jobs._thin_node)
    later = [k for k in range(len(nodes)) if nodes[k].fn in steps]
    assert later and all(Ref(q) in nodes[k].args for k in later)
    assert nodes[q].rank < min(nodes[k].rank for k in roles["finish"])  # before the first tile conformed
    assert nodes[q].rank > nodes[roles["free"][0]].rank  # after the first free meshes
    made = tiles.run_tiles(deferred, workers=2)
    assert plan.quant.q > 0 and (deferred.quant, deferred.zeta_used) == (plan.quant, plan.zeta_used)
    for a, b in zip(tiles.run_tiles(plan, workers=1), made, strict=True):
        assert np.array_equal(a.xy, b.xy) and np.array_equal(a.tris, b.tris) and np.array_equal(a.z, b.z)


def test_schedule_chains_a_node_with_its_follower():
    """A node given out takes with it the node that waits for it alone, if its tiles are the worker's: that
    node is not made ready again; a node that waits for another too, or reads another worker's tile, is
    not taken.  The pool runs a chain in one round trip, a picked result passed on in the worker."""
    nodes = [Node(_add, (1,), (0, 0), (0,)), Node(_add, (Ref(0), 1), (0, 1), (0,)),
             Node(_add, (Ref(0), Ref(1)), (0, 2), (0,)), Node(_add, (Ref(0),), (0, 3), (1,))]
    s = _Schedule(nodes, {0: 0, 1: 1})
    assert s.take(0) == 0 and s.follower(0, 0) == 1
    assert s.follower(0, 0) is None  # 2 waits for 1 too, 3 reads worker 1's tile
    s.finished(0)
    assert [i for _, i in s.ready] == [3]
    s.finished(1)
    assert [i for _, i in s.ready] == [2, 3]
    chain = [Node(_pair, (1, 2)), Node(_add, (Ref(0, _first), 10)), Node(_add, (Ref(1), Ref(0, _first)))]
    line = [Node(_add, (1,))] + [Node(_add, (Ref(k), k)) for k in range(6)]  # longer than runner.CHAIN
    # many ready nodes of its own: a worker is given the next ones with a chain that has no follower
    # (runner.BATCH_READY), each its own args; the same results
    wide = [Node(_add, (k, 1), (k, 0), (k % 2,)) for k in range(24)]
    wide += [Node(_add, (Ref(k), Ref(k + 1)), (k + 1, 1), (k % 2,)) for k in range(23)]
    for workers in (1, 2):
        with tiles.Runner(workers) as run:
            assert run.graph(chain) == [(1, 2), 11, 12]
            assert run.graph(line) == [1, 1, 2, 4, 7, 11, 16]
            assert run.graph(wide, homes={0: 0.0, 1: 0.5}) == \
                [k + 1 for k in range(24)] + [2 * k + 3 for k in range(23)]


def test_schedule_takes_only_its_own_when_asked():
    """take(w, own=True) (Runner.graph's batches: BATCH_READY): the first ready node of w's own (its first
    tile w's: a side between two workers' tiles is its first tile's worker's), or None when only other
    workers' are ready, which it leaves as they were; take without it gives another's rather than wait.
    ``left``: the nodes not yet taken (a last graph lets its idle workers go at 0)."""
    nodes = [Node(_add, (k,), (0, k), tiles) for k, tiles in enumerate(((1,), (1, 0), (0,), (1,)))]
    s = _Schedule(nodes, {0: 0, 1: 1})
    assert s.left == 4
    assert s.take(0, own=True) == 2 and s.left == 3
    assert s.take(0, own=True) is None and [i for _, i in s.ready] == [0, 1, 3] and s.left == 3  # (1, 0) not
    assert s.take(1, own=True) == 0
    assert s.take(1, own=True) == 1  # (1, 0): its first tile worker 1's
    assert s.take(0, own=True) is None
    assert s.take(0) == 3 and s.left == 0 and s.ready == []  # another's rather than wait
    assert s.take(0) is None and s.left == 0
    # held (a chain sent ahead, Runner.graph's AHEAD): only a node whose tiles the worker has read already
    # (taken before; a home tile nobody read yet is not), or one without tiles
    nodes = [Node(_add, (k,), (0, k), tiles) for k, tiles in enumerate(((0,), (), (1,), (0,), (0, 1)))]
    s = _Schedule(nodes, {0: 0, 1: 0})
    assert s.take(0, own=True, held=True) == 1  # no tiles; (0,) is its home's, not read yet
    assert s.take(0, own=True, held=True) is None and len(s.ready) == 4
    assert s.take(0, own=True) == 0  # read now
    assert s.take(0, own=True, held=True) == 3  # (0,) again; not (1,), nor (0, 1)
    assert s.take(1, own=True) is None and s.take(0, own=True, held=True) is None
    assert s.take(0) == 2 and s.take(0, own=True, held=True) == 4  # (1,) read by worker 0: both its now


class _Box:
    """A result a weak reference can follow."""

    def __init__(self, v):
        self.v = v


def _boxed(*xs):
    return _Box(sum(x.v if isinstance(x, _Box) else x for x in xs))


def test_graph_keeps_only_what_it_returns():
    """``keep``: the other nodes' results are let go once their readers have them (in this process: before
    the next node runs), the kept ones returned, every one still given to ``done``; the same on a pool."""
    import weakref

    nodes = [Node(_boxed, (1,)), Node(_boxed, (Ref(0), 10)), Node(_boxed, (Ref(1), 100)),
             Node(_boxed, (Ref(0), Ref(2), 1000))]
    for workers in (1, 2):
        alive: dict = {}
        seen: dict = {}

        def done(i, r, alive=alive, seen=seen, workers=workers):
            seen[i] = r.v
            alive[i] = weakref.ref(r)
            if i == 3 and workers == 1:  # node 1 read by node 2 alone, node 2 by node 3: both let go
                assert alive[1]() is None and alive[2]() is None and alive[0]() is not None

        with tiles.Runner(workers) as run:
            out = run.graph(nodes, done, keep=[0, 3])
        assert [None if r is None else r.v for r in out] == [1, None, None, 1112]
        assert seen == {0: 1, 1: 11, 2: 111, 3: 1112}


class _Made:
    """A result that says which process made it and how many times it was unpickled on its way."""

    def __init__(self, value, pid=None, copies=0):
        self.value, self.pid, self.copies = value, os.getpid() if pid is None else pid, copies

    def __reduce__(self):
        rest = {k: v for k, v in self.__dict__.items() if k not in ("value", "pid", "copies")}
        return (_Made, (self.value, self.pid, self.copies + 1), rest)


def _made(*xs):
    """A _Made of the sum of the values; ``seen``: for each arg, whether this process made it and how many
    times it was unpickled; ``held``: the results this worker keeps (runner._HELD) as it runs."""
    from wavemesh.tiles import runner

    out = _Made(sum(x.value for x in xs) + 1)
    out.seen = [(x.pid == os.getpid(), x.copies) for x in xs]
    out.held = len(runner._HELD)
    return out


def test_pool_worker_keeps_the_results_it_made():
    """runner.HOLD: a node given to the worker that made a result it reads gets that object itself (never
    pickled), not the parent's copy sent down the pipe again; the same values as in this process and
    without HOLD (where such an arg comes as a copy); a new graph starts with nothing kept."""
    from wavemesh.tiles import runner

    nodes = [Node(_made, (), (0, k), (k % 2,)) for k in range(8)]
    nodes += [Node(_made, (Ref(k), Ref((k + 2) % 8)), (1, k), (k % 2,)) for k in range(8)]
    nodes += [Node(_made, (Ref(8 + k), Ref(k), Ref(8 + (k + 2) % 8)), (2, k), (k % 2,)) for k in range(8)]
    homes = {0: 0.0, 1: 0.5}
    want = [r.value for r in tiles.Runner(1).graph(nodes)]
    saved = runner.HOLD
    copied = {}
    try:
        for hold in (True, False):
            runner.HOLD = hold
            with tiles.Runner(2) as run:
                out = run.graph(nodes, homes=homes)
                assert [r.value for r in out] == want
                own = [c for r in out[8:] for mine, c in r.seen if mine]  # args this worker made
                assert own  # the homes put most readers with their inputs
                copied[hold] = sum(c > 1 for c in own)  # unpickled in the parent and again here
                if hold:
                    assert copied[hold] == 0
                    assert max(r.held for r in out) > 0
                    assert run.graph([Node(_made, ()), Node(_made, ())])[0].held == 0  # a new graph
    finally:
        runner.HOLD = saved
    assert copied[False] > 0


def _held_counts(nodes: list) -> list[int]:
    """The results each node's worker held as it ran (_made's ``held``), ``nodes`` run by a pool of 2 with
    runner.HOLD on, tiles 0 and 1 homed apart; the values checked against one worker's."""
    from wavemesh.tiles import runner

    want = [r.value for r in tiles.Runner(1).graph(nodes)]
    saved = runner.HOLD
    try:
        runner.HOLD = True
        with tiles.Runner(2) as run:
            out = run.graph(nodes, homes={0: 0.0, 1: 0.5})
    finally:
        runner.HOLD = saved
    assert [r.value for r in out] == want
    return [r.held for r in out]


def test_pool_worker_lets_go_of_held_results():
    """runner.HOLD: a held result is let go once every node that reads it has been given out, so a worker
    holds about a level's results of a deep graph, not every result it ever made (fifteen levels of four
    nodes, each reading two of the level before, both made by the same worker)."""
    width, depth = 4, 15
    nodes = [Node(_made, (), (0, k), (k % 2,)) for k in range(width)]
    for d in range(1, depth):
        base = (d - 1) * width
        nodes += [Node(_made, (Ref(base + k), Ref(base + (k + 2) % width)), (d, k), (k % 2,))
                  for k in range(width)]
    held = _held_counts(nodes)
    assert max(held) > 0  # results were held at all
    assert max(held) <= 2 * width  # two levels' at most: without letting go, up to depth * width / 2


def test_pool_worker_keeps_no_result_only_its_chain_reads():
    """runner.HOLD: a result whose one reader runs next in the same chain (given it as _Prev) is not held:
    two lines of 30 nodes, each reading the one before on its tile (the chains' followers), leave a worker
    at most the last chain's end held (22 when such results were kept to the graph's end)."""
    nodes = [Node(_made, (), (0, k), (k,)) for k in range(2)]
    nodes += [Node(_made, (Ref(k - 2),), (0, k), (k % 2,)) for k in range(2, 60)]
    assert max(_held_counts(nodes)) <= 1


@pytest.mark.parametrize("threads", [1, 2])
def test_tiles_steps_tool_counts_every_task(threads, tmp_path):
    """tools/tiles_steps.py (where a tiled run's time goes) runs `wavemesh mesh --tile` with every task
    of the graph counted once in its worker: the steps it lists add up to tile_graph's nodes, and each of
    the 2 workers has its line, threads of the command's process too (runner.THREADS, one or both)."""
    import re
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    v = np.random.default_rng(8).normal(0, 30, (150, 170)).cumsum(axis=0).cumsum(axis=1)
    np.save(tmp_path / "h.npy", v.astype(np.float32))
    out = subprocess.run([sys.executable, str(root / "tools" / "tiles_steps.py"), str(tmp_path / "h.npy"),
                          "--workers", "2", "--tile", "65", "--metric", "vertical", "--zeta", "5",
                          "--runner", f"THREADS={threads}"],
                         capture_output=True, text=True, cwd=root, timeout=120)
    assert out.returncode == 0, out.stderr
    graph = re.search(r"^graph: wall [\d.]+ s; (\d+) tasks", out.stdout, re.M)
    counts = [(m[0], int(m[1])) for m in re.findall(r"^  (?:-?\d+ )?(\w+) +(\d+) tasks", out.stdout, re.M)]
    src = tiles.open_source(str(tmp_path / "h.npy"))
    plan = tiles.plan_tiles(src, api.MeshParams(refine=RefineParams(metric="vertical", zeta=5.0)), 65,
                            defer_error=True, runner=tiles.Runner(1))
    nodes, _ = tiles.tile_graph(plan)
    assert graph and int(graph[1]) == len(nodes)
    line = out.stdout[graph.start():].split("\n", 1)[0]  # each worker's CPU / busy / waiting (tasks, ...)
    tasks = [int(n) for n in re.findall(r"[\d.]+ / [\d.]+ / -?[\d.]+ \((\d+), ", line)]
    assert len(tasks) == 2 and sum(tasks) == len(nodes), line
    assert sum(n for k, n in counts if k != "_strip_stats") == len(nodes), counts
    assert dict(counts)["free_tile"] == len(plan.tiles)


def test_tiles_timeline_tool_accounts_for_the_whole_run(tmp_path):
    """tools/tiles_timeline.py (where a tiled process's wall time goes) runs whole `wavemesh mesh --tile`
    processes with 1 and 2 workers: every task of the strips and of tile_graph timed once, in both runs;
    the parent's phases add up to the process's wall time; the time not every worker is busy within it; two
    workers' tasks on two workers; the same bytes."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    from wavemesh.tiles import source

    root = Path(__file__).resolve().parents[2]
    v = np.random.default_rng(8).normal(0, 30, (150, 170)).cumsum(axis=0).cumsum(axis=1)
    np.save(tmp_path / "h.npy", v.astype(np.float32))
    out = subprocess.run([sys.executable, str(root / "tools" / "tiles_timeline.py"), str(tmp_path / "h.npy"),
                          "--workers", "1,2", "--runs", "1", "--json", str(tmp_path / "t.json"),
                          "--tile", "65", "--metric", "vertical", "--zeta", "5"],
                         capture_output=True, text=True, cwd=root, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    got = json.loads((tmp_path / "t.json").read_text())
    src = tiles.open_source(str(tmp_path / "h.npy"))
    plan = tiles.plan_tiles(src, api.MeshParams(refine=RefineParams(metric="vertical", zeta=5.0)), 65,
                            defer_error=True, runner=tiles.Runner(1))
    nodes, _ = tiles.tile_graph(plan)
    strips = len(source.strip_tasks(src))
    assert got["same"]
    for w, (run,) in got["runs"].items():
        assert run["tasks"] == len(nodes) + strips, w
        assert sum(d for d, _ in run["rows"].values()) == pytest.approx(run["wall"], abs=1e-6)
        assert all(0 <= i <= d + 1e-9 for d, i in run["rows"].values()), run["rows"]
        assert 0 < run["idle"] < run["wall"]
        assert run["rows"]["import wavemesh.cli"][0] > 0
        assert run["rows"]["graph: to the last free tile's end"][0] > 0
        assert len(run["levels"]) == int(w) + 2
        assert (len(run["per_worker"]) > 1) == (w == "2")  # a thread of each graph apart: the same one


def _switch(_):
    import sys

    return sys.getswitchinterval()


@pytest.mark.parametrize("switch_us", [500, 0])
def test_pool_with_a_thread_sets_the_switch_interval(switch_us, monkeypatch):
    """While a pool with a thread worker runs a graph, the interpreter's switch interval is SWITCH_US (0:
    the one it had), as the thread's tasks see it; the one it had again after."""
    import sys

    from wavemesh.tiles import runner

    monkeypatch.setattr(runner, "THREADS", 2)  # both workers threads: every task runs in this process
    monkeypatch.setattr(runner, "SWITCH_US", switch_us)
    before = sys.getswitchinterval()
    with tiles.Runner(2) as run:
        got = run.graph([Node(_switch, (k,)) for k in range(4)])
    assert got == [switch_us / 1e6 if switch_us else before] * 4
    assert sys.getswitchinterval() == before


_RUNNER: list = []  # the Runner _pool_seen's tasks look at


def _pool_seen(_):
    import time

    seen = len(_RUNNER[0].pool)  # as the task starts
    time.sleep(0.005)
    return os.getpid(), seen


def test_thread_worker_starts_after_the_forks(monkeypatch):
    """A new pool of 3 (2 forked, a thread): the thread runs no task before every worker is forked (a fork
    while a thread of this process runs copies whatever lock it holds into the child)."""
    from wavemesh.tiles import runner

    monkeypatch.setattr(runner, "THREADS", 1)
    with tiles.Runner(3) as run:
        _RUNNER[:] = [run]
        got = run.graph([Node(_pool_seen, (k,)) for k in range(9)])
    _RUNNER.clear()
    here = [n for pid, n in got if pid == os.getpid()]
    assert here and set(here) == {2}, got


def test_pool_pipe_frames_as_multiprocessing_and_its_process_ends():
    """runner._Pipe frames messages as multiprocessing's Connection does (either end may be one: small and
    large messages, bytes and objects), EOFError once the other end is closed; runner._Forked runs its
    target in a fork: its exit status, a raise's 1, join with a timeout, terminate."""
    import multiprocessing.connection
    import signal
    import socket
    import time

    from wavemesh.tiles import runner

    a, b = socket.socketpair()
    ours, theirs = runner._Pipe(a.detach()), multiprocessing.connection.Connection(b.detach())
    big = np.arange(4_000, dtype=np.float64)  # over the 16 KiB of a header sent apart, within the buffer
    for msg in (None, ("ok", [1, 2.5], None), ("chain", big, "x" * 20_000)):
        ours.send(msg)
        got = theirs.recv()
        theirs.send(msg)
        back = ours.recv()
        for m in (got, back):
            if msg is not None and msg[0] == "chain":
                assert m[0] == "chain" and np.array_equal(m[1], big) and m[2] == msg[2]
            else:
                assert m == msg
    theirs.send_bytes(b"abc")
    assert ours.poll(1) and ours.recv_bytes() == b"abc" and not ours.poll()
    theirs.close()
    with pytest.raises(EOFError):
        ours.recv()
    ours.close()
    ours.close()  # twice: nothing

    here, there = runner._pipe()
    with here, there:
        ok = runner._Forked(there.send, ("hello",))
        ok.start()
        assert here.recv() == "hello"
        ok.join()
        assert ok.exitcode == 0 and not ok.is_alive()
    bad = runner._Forked(lambda: 1 / 0)
    bad.start()
    bad.join(30)
    assert bad.exitcode == 1
    slow = runner._Forked(time.sleep, (60,))
    slow.start()
    slow.join(0.05)
    assert slow.exitcode is None and slow.is_alive()
    slow.terminate()
    slow.join(30)
    assert slow.exitcode == -signal.SIGTERM


def test_a_tiled_command_imports_no_multiprocessing(tmp_path):
    """`wavemesh mesh --tile` with a pool of a forked worker and a thread imports neither multiprocessing nor
    socket (the pool's own fork and pipes: 45 M instructions of the start, docs/tiles.md)."""
    import subprocess
    import sys

    np.save(tmp_path / "h.npy", np.random.default_rng(3).normal(0, 9, (150, 170)).cumsum(axis=0))
    code = ("import sys; sys.argv = ['wavemesh']; from wavemesh import cli; "
            f"rc = cli.main(['mesh', {str(tmp_path / 'h.npy')!r}, '-o', {str(tmp_path / 'm.obj')!r}, '-q', "
            "'--tile', '65', '--workers', '2', '--zeta', '5']); "
            "print(rc, [m for m in ('multiprocessing', 'socket', 'tempfile') if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["0", "[]"]
    assert (tmp_path / "m.obj").stat().st_size > 0
