"""Where a tiled run's tasks run: in this process, a local pool of forked processes, or a Dask cluster."""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import sys
import time
from collections.abc import Callable, Iterable
from multiprocessing.connection import wait

from wavemesh.errors import WavemeshError
from wavemesh.refine import native
from wavemesh.tiles.plan import default_workers

DASK_CONNECT_S = 10  # how long --scheduler ADDRESS may take to answer
_WORKER_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)  # blocked from a fork to _worker_start
# glibc malloc for a process that runs tiles (tune_malloc): buffers up to 32 MiB from the heap, the heap's top
# kept up to 1 GiB
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
MALLOC_MMAP_BYTES, MALLOC_TRIM_BYTES = 32 << 20, 1 << 30
_TUNED: list = []


def tune_malloc() -> None:
    """glibc's malloc, once in a process that runs tiles: a tile's arrays (1025^2 float64: 8 MiB, and the
    refiner's storage) from the heap and the heap kept between tasks, not mapped and unmapped for every
    tile.  glibc raises its mmap threshold itself only after it has freed such a mapping, which a forked
    worker may never do: 8192^2 in tiles of 1025, 2 pool workers, measured 464,000 page faults and 1.2 s
    of system time in the free and conformed phases without this, 5,600 and 0.3 s with it (and 5.4 s of
    the workers' CPU in all, not 6.7).  No-op elsewhere (no mallopt: musl, macOS)."""
    if _TUNED:
        return
    _TUNED.append(True)
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


class Runner:
    """Where a tiled run's tasks run, as a context manager: ``scheduler`` (a Dask scheduler's address or
    a distributed.Client: one task per job, the workers read their own windows), else ``workers`` forked
    local processes (default: the CPUs this process may use; 1: in this process), started at the first
    task and kept for every phase.  Leaving it early (an error, Ctrl-C, SIGTERM) kills the workers."""

    def __init__(self, workers: int | None = None, scheduler=None):
        workers = default_workers() if workers is None else workers
        if workers < 1:
            raise WavemeshError(f"--workers {workers} is out of range", hint="use 1 or more")
        self.workers, self.scheduler = workers, scheduler
        self.client = None
        self.own_client = scheduler is not None and not hasattr(scheduler, "submit")
        self.pool: list[tuple] = []  # (process, pipe)
        self.run_id = f"{time.time_ns()}-{os.getpid()}"
        self.n_maps = 0

    def __enter__(self) -> Runner:
        if self.scheduler is not None:
            self.client = connect(self.scheduler) if self.own_client else self.scheduler
        return self

    def __exit__(self, kind, *exc) -> None:
        _end_workers(self.pool, gently=kind is None)
        self.pool = []
        if self.own_client and self.client is not None:
            self.client.close()

    def map(self, fn: Callable, tasks: Iterable[tuple], done: Callable | None = None) -> list:
        """fn(*task) of every task, in task order; ``done(result)`` called as each finishes (any order)."""
        tasks = list(tasks)
        results: list = [None] * len(tasks)

        def got(i: int, r) -> None:
            results[i] = r
            if done:
                done(r)

        self.n_maps += 1
        if self.client is not None:
            from distributed import as_completed  # with connect's package

            key = f"wavemesh-{self.run_id}-{self.n_maps}"  # this run's tasks alone
            futures = {self.client.submit(fn, *task, pure=False, key=f"{key}-{i}"): i
                       for i, task in enumerate(tasks)}
            for fut in as_completed(futures):
                got(futures[fut], fut.result())
        elif self.workers == 1 or len(tasks) == 1:
            tune_malloc()
            for i, task in enumerate(tasks):
                got(i, fn(*task))
        else:
            self._pool_map(fn, tasks, got)
        return results

    def _pool_map(self, fn, tasks: list, got) -> None:
        """The tasks on the forked workers, one each at a time, each result through the worker's own pipe.
        The parent has no threads of its own for them: a run that ends early kills its workers and returns
        at once (concurrent.futures' pool could wait forever at exit for a result a killed worker had half
        sent)."""
        if not self.pool:
            native.load()  # built once here, not by every worker at once
            # fork: the workers start from this process as it is (the library loaded; a script that calls
            # this needs no `if __name__ == "__main__"` guard, which spawn and forkserver would ask of it)
            ctx = multiprocessing.get_context("fork")
            # the signals held back over the forks: a worker starts with them blocked and unblocks them
            # once its own handlers are set (_worker_start), so a Ctrl-C just after the fork is not a
            # KeyboardInterrupt traceback in the worker; here they are raised after the last fork, every
            # worker in the pool by then (ended by __exit__)
            held = signal.pthread_sigmask(signal.SIG_BLOCK, _WORKER_SIGNALS)
            try:
                for _ in range(self.workers):
                    here, there = ctx.Pipe()
                    proc = ctx.Process(target=_worker_loop, args=(there, os.getpid()), daemon=True)
                    proc.start()
                    there.close()
                    self.pool.append((proc, here))
            finally:
                signal.pthread_sigmask(signal.SIG_SETMASK, held)
        todo = iter(enumerate(tasks))
        busy: dict = {}  # pipe -> (process, task number)

        def give(proc, pipe) -> None:
            nxt = next(todo, None)
            if nxt is not None:
                pipe.send((fn, nxt[1]))
                busy[pipe] = (proc, nxt[0])

        for proc, pipe in self.pool:
            give(proc, pipe)
        while busy:
            ready = wait([*busy, *(p.sentinel for p, _ in busy.values())])
            for pipe in [c for c in busy if c in ready]:
                proc, i = busy.pop(pipe)
                try:
                    kind, value, hint = pipe.recv()
                except (EOFError, OSError):
                    _lost(proc)
                if kind == "error":
                    if isinstance(value, WavemeshError) and hint is not None:
                        value.hint = hint
                    raise value
                got(i, value)
                give(proc, pipe)
            for pipe, (proc, _) in list(busy.items()):
                if proc.sentinel in ready and pipe not in ready and not pipe.poll():
                    _lost(proc)


def _lost(proc) -> None:
    proc.join(1.0)
    raise WavemeshError(f"a tile worker ended without its result (exit status {proc.exitcode})",
                        hint="out of memory? try a smaller --tile or fewer --workers") from None


def _worker_loop(pipe, parent: int) -> None:
    """A pool worker: tasks (fn, args) from its pipe until it closes; each result, or the error, back."""
    _worker_start(parent)
    while True:
        try:
            task = pipe.recv()
        except (EOFError, OSError):
            return
        if task is None:
            return
        try:
            reply = ("ok", task[0](*task[1]), None)
        except Exception as e:  # the parent raises it (WavemeshError with its hint)
            reply = ("error", e, getattr(e, "hint", None))
        try:
            pipe.send(reply)
        except Exception as e:  # an error that does not pickle: its text
            pipe.send(("error", RuntimeError(f"{type(e).__name__}: {e}"), None))


def _worker_start(parent: int) -> None:
    """A pool worker's start: Ctrl-C is the parent's to handle (it ends the workers, _end_workers), SIGTERM
    ends the worker at once (SIGHUP too, unless the run ignores it: nohup), and the worker ends when its
    parent does, even one killed outright (Linux's PR_SET_PDEATHSIG).  The signals, blocked since the fork
    (_pool_map), are let through once these are set."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if signal.getsignal(signal.SIGHUP) is not signal.SIG_IGN:
        signal.signal(signal.SIGHUP, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _WORKER_SIGNALS)
    tune_malloc()
    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM, 0, 0, 0)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent:  # the parent ended before the line above
        os._exit(1)


def _end_workers(pool: list, gently: bool) -> None:
    """End the workers: ``gently`` (the run is done) by closing their pipes; else at once (SIGTERM, then
    SIGKILL after a second).  Reaped either way."""
    for proc, pipe in pool:
        if gently:
            try:
                pipe.send(None)
            except OSError:
                pass
        elif proc.is_alive():
            proc.terminate()
    deadline = time.monotonic() + (10.0 if gently else 1.0)
    for proc, pipe in pool:
        proc.join(max(0.0, deadline - time.monotonic()))
        if proc.is_alive():
            proc.kill()
            proc.join(1.0)
        pipe.close()
