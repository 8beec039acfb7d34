#!/usr/bin/env python3
"""Where a tiled `wavemesh mesh` process's wall time goes: the parent's steps on one clock with every task of
its workers, and the time that not every worker runs a task.

    .venv/bin/python tools/tiles_timeline.py INPUT [--workers 1,2] [--runs 3] [wavemesh mesh options ...]

Runs `wavemesh mesh INPUT -o OUT --quiet --workers W [options]` (default options `--tile 1025 --metric
vertical --zeta 10`) as whole processes, each W of --workers in turn, --runs times (one of each first, not
counted), through a launcher named wavemesh (the package then sets itself up as the console script does)
with compiled modules from a cache of the tool's own, as bench/bench_tiles.py pair runs them.  The launcher
notes the time (time.perf_counter: CLOCK_MONOTONIC, one clock for every process) and the parent's CPU at
its first line (the interpreter started), after the imports (wavemesh.cli, then wavemesh.tiles), at the
input opened, around the plan (the quantisation's strips on the workers), the task graph (run_tiles) and
the files' end, and at the command's return; the tool notes the process's start and its exit (os.wait4;
as a subreaper it then reaps the pool's workers still exiting, their CPU counted).  Every task is timed
in the worker that runs it (start, end, its thread's CPU).

Each run: its wall time; "not every worker busy": the integral of (W - tasks running) / W over the run,
the seconds of the wall time in which W workers did not each run a task; the time with 0, 1, .. W tasks
running; the CPU of the process tree, of the parent process, and of the parent outside the tasks it ran
(a pool's thread worker's, a 1-worker run's); then each phase of the parent: its wall ms and its idle ms
(the same integral over the phase).  The medians of each W close, and whether every W wrote the same bytes.
W:NAME=VALUE+NAME=VALUE runs W workers with tiles.runner's settings (2:SWITCH_US=200).  Wall times on a
shared machine are noisy: `uptime`'s load is printed with each run (docs/tiles.md, "On 2 cores").
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DEFAULT = ["--tile", "1025", "--metric", "vertical", "--zeta", "10"]
PYCACHE = Path(tempfile.gettempdir()) / "wavemesh-tiles-timeline" / "pycache"  # compiled once, kept

# the child: the console script's name (the package then sets itself up as the command: wavemesh/__init__.py)
LAUNCHER = r'''import time
_T0, _C0 = time.perf_counter(), time.process_time()
import os, sys, threading, functools, atexit
_FD = os.open(os.environ["WAVEMESH_TIMELINE"], os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)


def _put(*rec):
    os.write(_FD, (repr(rec) + "\n").encode())


def mark(name, t=None, c=None):
    _put("mark", os.getpid(), name, time.perf_counter() if t is None else t,
         time.process_time() if c is None else c)


mark("interpreter", _T0, _C0)
atexit.register(mark, "atexit")  # the first registered: run last
import wavemesh.cli as cli
mark("imports wavemesh.cli")
from wavemesh import tiles
from wavemesh.tiles import runner, files
mark("imports wavemesh.tiles")
for kv in filter(None, os.environ.get("WAVEMESH_BENCH_RUNNER", "").split(",")):  # --runner NAME=VALUE
    k, v = kv.split("=")
    setattr(runner, k, type(getattr(runner, k))(int(v)))


def _task(fn, *args):
    t0, c0 = time.perf_counter(), time.thread_time()
    try:
        return fn(*args)
    finally:
        _put("task", os.getpid(), threading.get_native_id(), getattr(fn, "__name__", "?"), t0,
             time.perf_counter(), time.thread_time() - c0)


def _around(obj, attr, name, after=False):
    orig = getattr(obj, attr)

    @functools.wraps(orig)
    def f(*a, **k):
        if not after:
            mark(name + " <")
        try:
            return orig(*a, **k)
        finally:
            mark(name + (" >" if not after else ""))

    setattr(obj, attr, f)


_graph = runner.Runner.graph


def _graph_marked(self, nodes, *a, **k):
    nodes = [runner.Node(functools.partial(_task, n.fn), n.args, n.rank, n.tiles) for n in nodes]
    return _graph(self, nodes, *a, **k)


runner.Runner.graph = _graph_marked
_around(tiles, "open_source", "open")
_around(tiles, "plan_tiles", "plan")
_around(tiles, "run_tiles", "graph")
_around(runner.Runner, "_start_pool", "fork")
_around(runner, "_worker_start", "worker ready", after=True)
_around(runner._Local, "start", "thread start", after=True)
_around(files.TiledFiles, "add", "tile written", after=True)
_around(files.TiledFiles, "finish", "finish")
_around(files.TiledFiles, "__exit__", "files in place")
_around(cli, "_tiled_command", "command")
_PID, _EXIT = os.getpid(), os._exit


def _leave(code):  # the command leaves by os._exit once its files are in place (cli.main): its marks first
    if os.getpid() == _PID:
        mark("main returned")
        mark("atexit")
    _EXIT(code)


os._exit = _leave
rc = cli.main()
mark("main returned")
sys.exit(rc)
'''

# the parent steps, in order: (the phase's name, the mark that ends it)
PHASES = [
    ("interpreter start", "interpreter"),
    ("import wavemesh.cli", "imports wavemesh.cli"),
    ("import wavemesh.tiles", "imports wavemesh.tiles"),
    ("arguments, outputs checked", "open <"),
    ("input opened", "open >"),
    ("to the plan", "plan <"),
    ("plan (the strips)", "plan >"),
    ("to the graph", "graph <"),
    ("graph: to its first task", "first task"),
    ("graph: to the last free tile's end", "last free tile"),
    ("graph: its other tasks", "last task"),
    ("graph: after its last task", "graph >"),
    ("files finished", "finish >"),
    ("files in place, the end", "main returned"),
    ("interpreter's exit", "exit"),
]


def run_once(src: str, workers: int, opts: list[str], work: Path, settings: tuple = (), name: str = ""
             ) -> dict:
    """One process (``settings``: tiles.runner's, "NAME=VALUE"; its mesh written to ``work``/``name``.obj):
    its marks and tasks, its wall time and its tree's CPU."""
    marks = work / "marks.txt"
    marks.unlink(missing_ok=True)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env |= {"PYTHONPYCACHEPREFIX": str(PYCACHE), "WAVEMESH_TIMELINE": str(marks),
            "WAVEMESH_BENCH_RUNNER": ",".join(settings)}
    cmd = [sys.executable, str(work / "launch" / "wavemesh"), "mesh", src, "-o",
           str(work / f"{name or workers}.obj"), "--quiet", "--workers", str(workers), *opts]
    r0 = os.times()
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env)
    _, status, _ = os.wait4(proc.pid, 0)
    t1 = time.perf_counter()
    proc.returncode = os.waitstatus_to_exitcode(status)
    while True:  # the workers still exiting, reparented to this subreaper
        try:
            os.wait4(-1, 0)
        except ChildProcessError:
            break
    r1 = os.times()
    if proc.returncode:
        raise SystemExit(f"{' '.join(cmd)}: exit status {proc.returncode}")
    recs = [eval(line) for line in marks.read_text().splitlines()]  # noqa: S307 - our own repr lines
    pid = proc.pid
    at = {}
    for rec in recs:
        if rec[0] == "mark" and rec[1] == pid:
            at.setdefault(rec[2], rec[3])  # the first of each (a tile written: the first)
    tasks = [rec[1:] for rec in recs if rec[0] == "task"]  # pid, tid, name, start, end, cpu
    graph = [t for t in tasks if at.get("graph <", 0) <= t[3]]
    at["spawn"], at["exit"] = t0, t1
    at["first task"] = min(t[3] for t in graph)
    at["last task"] = max(t[4] for t in graph)
    at["last free tile"] = max(t[4] for t in graph if t[2] == "free_tile")
    return {"workers": workers, "pid": pid, "at": at, "tasks": tasks, "wall": t1 - t0,
            "cpu": r1.children_user + r1.children_system - r0.children_user - r0.children_system,
            "parent_cpu": next(rec[4] for rec in recs if rec[0] == "mark" and rec[2] == "atexit"),
            "uptime": os.getloadavg()}


def busy(tasks: list, a: float, b: float, workers: int) -> tuple[float, list[float]]:
    """Over [a, b]: the integral of (workers - tasks running) / workers (s), and the time at each count."""
    ev = sorted([(max(a, s), 1) for *_, s, e, _ in tasks if e > a and s < b]
                + [(min(b, e), -1) for *_, s, e, _ in tasks if e > a and s < b])
    level, t, idle = 0, a, 0.0
    at = [0.0] * (workers + 2)
    for x, d in ev:
        at[min(level, workers + 1)] += x - t
        idle += max(0, workers - level) * (x - t)
        t, level = x, level + d
    at[min(level, workers + 1)] += b - t
    idle += max(0, workers - level) * (b - t)
    return idle / workers, at


def report(r: dict) -> dict:
    """A run's phases (wall s, idle s), its idle s and the time at each count of tasks running, its tasks'
    CPU and wall s (each worker's wall apart), its tree's CPU, the parent process's (at its last atexit)
    and the parent's outside tasks (a thread worker's and a 1-worker run's tasks apart)."""
    at, w = r["at"], r["workers"]
    t = at["spawn"]
    rows = {}
    for name, end in PHASES:
        e = at.get(end, t)
        rows[name] = (e - t, busy(r["tasks"], t, e, w)[0])
        t = e
    idle, levels = busy(r["tasks"], at["spawn"], at["exit"], w)
    task_cpu = sum(x[5] for x in r["tasks"])
    task_wall = sum(x[4] - x[3] for x in r["tasks"])
    per = {}
    for x in r["tasks"]:
        per[(x[0], x[1])] = per.get((x[0], x[1]), 0.0) + x[4] - x[3]
    return {"rows": rows, "idle": idle, "levels": levels, "task_cpu": task_cpu, "task_wall": task_wall,
            "per_worker": sorted(per.values(), reverse=True), "wall": r["wall"], "cpu": r["cpu"],
            "parent_cpu": r["parent_cpu"], "tasks": len(r["tasks"]), "load": r["uptime"][0],
            "parent_own": r["parent_cpu"] - sum(x[5] for x in r["tasks"] if x[0] == r["pid"])}


def _name(v: str) -> str:
    w, _, settings = v.partition(":")
    with_ = f" ({settings.replace('+', ', ')})" if settings else ""
    return f"{w} worker{'s' if int(w) > 1 else ''}{with_}"


def show(rep: dict, v: str) -> None:
    print(f"  {_name(v)}: wall {rep['wall']:.3f} s, not every worker busy {rep['idle']:.3f} s; CPU "
          f"{rep['cpu']:.2f} s (the parent process {rep['parent_cpu']:.2f} s, {rep['parent_own']:.2f} s "
          f"outside tasks); {rep['tasks']} tasks {rep['task_cpu']:.2f} s CPU, {rep['task_wall']:.2f} s wall "
          f"(per worker {', '.join(f'{x:.2f}' for x in rep['per_worker'])}); load {rep['load']:.2f}")
    print("    time with " + ", ".join(f"{k} tasks running {1000 * v:.0f} ms"
                                       for k, v in enumerate(rep["levels"]) if v))
    print("    " + _phases(rep["rows"]))


def _phases(rows: dict) -> str:
    return "; ".join(f"{name} {1000 * d:.0f} ({1000 * i:.0f} idle)" for name, (d, i) in rows.items())


def main(argv: list[str]) -> int:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
                                 allow_abbrev=False)
    ap.add_argument("input")
    ap.add_argument("--workers", default="1,2",
                    help="the runs' worker counts, in turn (default 1,2); W:NAME=VALUE+NAME=VALUE with "
                         "tiles.runner's settings (2:SWITCH_US=200)")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--json", help="also each run's figures as JSON here")
    a, opts = ap.parse_known_args(argv)
    opts = opts or DEFAULT
    if sys.platform.startswith("linux"):
        import ctypes

        ctypes.CDLL(None).prctl(36, 1, 0, 0, 0)  # PR_SET_CHILD_SUBREAPER: the exiting workers are ours
    variants = a.workers.split(",")
    got: dict = {v: [] for v in variants}
    with tempfile.TemporaryDirectory(prefix="wavemesh-timeline-") as tmp:
        work = Path(tmp)
        (work / "launch").mkdir()
        (work / "launch" / "wavemesh").write_text(LAUNCHER)

        def once(v: str) -> dict:
            w, _, settings = v.partition(":")
            return run_once(a.input, int(w), opts, work, tuple(filter(None, settings.split("+"))), v)

        for v in variants:  # the modules compiled into the cache, not counted
            once(v)
        for k in range(a.runs):
            print(f"run {k + 1}:")
            for v in variants:
                rep = report(once(v))
                got[v].append(rep)
                show(rep, v)
        same = len({(work / f"{v}.obj").read_bytes() for v in variants}) == 1
    print(f"medians of {a.runs} runs (the same bytes: {'yes' if same else 'NO'}):")
    for v, reps in got.items():
        med = {name: (statistics.median(r["rows"][name][0] for r in reps),
                      statistics.median(r["rows"][name][1] for r in reps)) for name, _ in PHASES}
        print(f"  {_name(v)}: wall {statistics.median(r['wall'] for r in reps):.3f} s, "
              f"not every worker busy {statistics.median(r['idle'] for r in reps):.3f} s, tasks' CPU "
              f"{statistics.median(r['task_cpu'] for r in reps):.2f} s, all CPU "
              f"{statistics.median(r['cpu'] for r in reps):.2f} s, the parent's outside tasks "
              f"{statistics.median(r['parent_own'] for r in reps):.3f} s")
        print("    " + _phases(med))
    if a.json:
        Path(a.json).write_text(json.dumps({"same": same, "runs": got}, indent=1))
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
