#!/usr/bin/env python3
"""Build and run the fuzz harnesses (fuzz/README.md): `make fuzz`, the smoke run of `make test`, and the
CPU-hour campaign of `make bench-fuzz`.

    python fuzz/run.py build                          the C harnesses: clang, ASan + UBSan, into build/fuzz/
    python fuzz/run.py run [--seconds S | --cpu S] [TARGET ...] [--json FILE]
    python fuzz/run.py merge [TARGET ...]             what build/fuzz/corpus/ found that adds coverage,
                                                      into fuzz/corpus/ (libFuzzer -merge=1)

TARGETs: refine, proto (libFuzzer, build/fuzz/fuzz_*), readers (atheris, fuzz/readers_fuzz.py); default
all.  --seconds: wall-clock time per target (libFuzzer's -max_total_time); --cpu: CPU seconds per
target, measured on the process (the campaign runs at nice 19 on a shared machine, where wall time
says little).  The targets run side by side.  Each starts from the corpus in the repository
(fuzz/corpus/TARGET, read only) and writes what it finds to build/fuzz/corpus/TARGET; a crash, a
sanitizer report or a failed check leaves its input in build/fuzz/findings/ and counts as a crash.
Prints one line per target (execs, coverage, corpus, crashes); --json writes them too.  Exit status 1
when any target crashed.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

FUZZ = Path(__file__).resolve().parent
ROOT = FUZZ.parent
BUILD = ROOT / "build" / "fuzz"
GEN = ROOT / "build" / "gen"
TARGETS = ("refine", "proto", "readers")
CLANG = os.environ.get("CLANG", "clang")
# libFuzzer options for every target: inputs up to 4 KiB, 2 GiB, the final statistics on stderr; an
# input may take 300 s of wall-clock time before it counts as a hang: the campaign runs at nice 19 on a
# shared machine, where the refiner's worst inputs (40 x 40 at zeta 0, the invariant check after every
# operator) take a few CPU seconds and many times that in wall-clock time.
COMMON = ["-max_len=4096", "-timeout=300", "-rss_limit_mb=2048", "-print_final_stats=1"]


def build() -> None:
    """Configure and build build/fuzz with clang (cmake); the generated headers first."""
    if shutil.which(CLANG) is None:
        raise SystemExit(f"error: {CLANG} not found\nhint: `make setup` installs clang and libclang-rt-dev")
    py = ROOT / ".venv" / "bin" / "python"
    subprocess.run([str(py if py.exists() else sys.executable), "-m", "wavemesh.device.gen", str(GEN)],
                   check=True, stdout=subprocess.DEVNULL, cwd=ROOT)
    env = dict(os.environ, CC=CLANG)
    subprocess.run(["cmake", "-S", str(FUZZ), "-B", str(BUILD), f"-DWM_GEN_DIR={GEN}"], check=True, env=env,
                   stdout=subprocess.DEVNULL)
    subprocess.run(["cmake", "--build", str(BUILD), "-j2"], check=True, stdout=subprocess.DEVNULL)


def command(target: str) -> list[str]:
    if target == "readers":
        # build/fuzz/fuzz_readers runs readers_fuzz.py with the venv's Python: libFuzzer starts its own
        # program again for -merge and -fork, which an atheris script as argv[0] would not survive.
        py = ROOT / ".venv" / "bin" / "python"
        wrapper = BUILD / "fuzz_readers"
        BUILD.mkdir(parents=True, exist_ok=True)
        wrapper.write_text(f'#!/bin/sh\nWM_FUZZ_SELF="$0" exec "{py if py.exists() else sys.executable}" '
                           f'"{FUZZ / "readers_fuzz.py"}" "$@"\n')
        wrapper.chmod(0o755)
        return [str(wrapper)]
    return [str(BUILD / f"fuzz_{target}")]


def _cpu_seconds(pid: int) -> float:
    """utime + stime of a running process (Linux /proc)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _stats(log: str) -> dict:
    """execs, coverage (cov: edges, ft: features), corpus size from libFuzzer's output."""
    out = {"execs": 0, "cov": 0, "ft": 0, "corpus": 0}
    m = re.search(r"stat::number_of_executed_units:\s*(\d+)", log)
    if m:
        out["execs"] = int(m.group(1))
    else:
        runs = re.findall(r"^#(\d+)\s", log, re.M)
        out["execs"] = int(runs[-1]) if runs else 0
    lines = re.findall(r"cov: (\d+) ft: (\d+) corp: (\d+)", log)
    if lines:
        out["cov"], out["ft"], out["corpus"] = (int(v) for v in lines[-1])
    return out


def start(target: str, seconds: float | None, extra: list[str], seeds_only: bool = False
          ) -> tuple[subprocess.Popen, Path]:
    work = BUILD / "corpus" / target
    seeds = FUZZ / "corpus" / target
    if seeds_only:  # the hand-made seeds and past findings alone, into a fresh folder (make test's smoke run)
        work, picked = BUILD / "smoke" / target / "work", BUILD / "smoke" / target / "seeds"
        shutil.rmtree(BUILD / "smoke" / target, ignore_errors=True)
        picked.mkdir(parents=True)
        for f in seeds.iterdir():
            if f.name.startswith(("seed-", "regress-")):
                shutil.copy(f, picked / f.name)
        seeds = picked
    findings = BUILD / "findings"
    for d in (work, seeds, findings):
        d.mkdir(parents=True, exist_ok=True)
    log = BUILD / f"{target}-{os.getpid()}.log"  # per run: a `make test` beside a campaign keeps its own
    args = command(target) + COMMON + [f"-artifact_prefix={findings}/{target}-"]
    if seconds is not None:
        args.append(f"-max_total_time={int(max(1, seconds))}")
    args += extra + [str(work), str(seeds)]
    f = log.open("w")
    return subprocess.Popen(args, stdout=f, stderr=subprocess.STDOUT, cwd=ROOT), log


def run(targets: list[str], seconds: float | None, cpu: float | None, extra: list[str],
        seeds_only: bool = False) -> list[dict]:
    began = time.time()  # findings of this run only: build/fuzz/findings keeps earlier runs' too
    procs = {t: start(t, seconds, extra, seeds_only) for t in targets}
    used = {t: 0.0 for t in targets}
    t0 = time.monotonic()
    while any(p.poll() is None for p, _ in procs.values()):
        for t, (p, _) in procs.items():
            if p.poll() is None:
                used[t] = max(used[t], _cpu_seconds(p.pid))
                if cpu is not None and used[t] >= cpu:
                    p.send_signal(signal.SIGINT)  # libFuzzer prints its final statistics and exits
        time.sleep(0.5)
    results = []
    findings = BUILD / "findings"
    for t, (p, log) in procs.items():
        text = log.read_text(errors="replace")
        found = sorted(str(f.relative_to(ROOT)) for f in findings.glob(f"{t}-*")
                       if not f.name.startswith(f"{t}-slow-unit-")  # slow, not wrong: libFuzzer's note
                       and f.stat().st_mtime >= began)
        crashed = bool(re.search(r"ERROR: (AddressSanitizer|UndefinedBehaviorSanitizer|libFuzzer)|"
                                 r"runtime error:|deadly signal|Uncaught Python exception", text))
        results.append({"target": t, "cpu_seconds": round(used[t], 1),
                        "wall_seconds": round(time.monotonic() - t0, 1), **_stats(text),
                        "crashes": max(len(found), int(crashed)), "findings": found, "exit": p.returncode,
                        "log": str(log.relative_to(ROOT))})
    return results


def merge(targets: list[str]) -> None:
    """Add the inputs of build/fuzz/corpus/TARGET that reach new coverage to fuzz/corpus/TARGET."""
    for t in targets:
        seeds, work = FUZZ / "corpus" / t, BUILD / "corpus" / t
        before = len(list(seeds.iterdir()))
        subprocess.run(command(t) + ["-merge=1", str(seeds), str(work)], check=True, cwd=ROOT,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        print(f"fuzz {t}: corpus {before} -> {len(list(seeds.iterdir()))} inputs")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="fuzz/run.py", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    sub.add_parser("build", help="build the C harnesses into build/fuzz/")
    m = sub.add_parser("merge", help="add what the runs found to the corpus in the repository")
    m.add_argument("targets", nargs="*", metavar="TARGET")
    r = sub.add_parser("run", help="run harnesses")
    r.add_argument("targets", nargs="*", metavar="TARGET", help=", ".join(TARGETS) + " (default: all)")
    g = r.add_mutually_exclusive_group()
    g.add_argument("--seconds", type=float, help="wall-clock seconds per target")
    g.add_argument("--cpu", type=float, help="CPU seconds per target")
    r.add_argument("--json", type=Path, help="write the results here")
    r.add_argument("--no-build", action="store_true", help="do not build first")
    args = ap.parse_args(argv)
    if args.cmd == "build":
        build()
        return 0
    targets = args.targets or list(TARGETS)
    unknown = sorted(set(targets) - set(TARGETS))
    if unknown:
        ap.error(f"unknown target {', '.join(unknown)}; have: {', '.join(TARGETS)}")
    if args.cmd == "merge":
        merge(targets)
        return 0
    if not args.no_build and any(t != "readers" for t in targets):
        build()
    results = run(targets, args.seconds if args.cpu is None else None, args.cpu, [])
    for res in results:
        print(f"fuzz {res['target']}: {res['execs']} execs in {res['cpu_seconds']} CPU s, cov {res['cov']} "
              f"ft {res['ft']}, corpus {res['corpus']}, crashes {res['crashes']}"
              + (f" ({', '.join(res['findings'])}; {res['log']})" if res["crashes"] else ""))
    if args.json:
        args.json.write_text(json.dumps(results, indent=1) + "\n")
    return 1 if any(res["crashes"] for res in results) else 0


if __name__ == "__main__":
    sys.exit(main())
