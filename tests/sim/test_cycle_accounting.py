"""The protocol engine's cycle accounting, exactly: wm_clocktest (firmware/board/native/clocktest.c).

The engine (firmware/board/src/proto_*.c) runs a fake job against a scripted host on a virtual clock
that nothing advances but the job's stages (by amounts the program prints first) and the transport
(writing costs ticks per byte, the host waits before each ACK, may ask for half a level again).  So
every count DONE reports has an exact expected value: each stage exactly its work, emit nothing (the
engine's own work takes no virtual time), each level header the stage work since the previous level,
and link all the rest of the time from RUN's OK to the last ACK (the host's own clock).  Several jobs
in one session give the engine different frame numbers, so different CRCs and SLIP escapes; a cycle
of link I/O (a PROGRESS frame, a write, a wait, a resend) counted in a stage shows up as a difference.
This runs in milliseconds; tests/sim/test_stream_board.py checks the same on the simulated board.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest
from wavemesh.device import protocol as P
from wavemesh.device.coding import encode_level_body
from wavemesh.harness.nativedev import build_wmdev

JOB = re.compile(r"job (\d+) filter (\d+) template (\d+) refine (\d+) emit (\d+) link (\d+) span (\d+) "
                 r"levels (\d+),(\d+) resent (\d+) status (\d+)")


@pytest.fixture(scope="module")
def clocktest() -> Path:
    return build_wmdev(target="wm_clocktest")


def run(exe: Path, *args: str) -> tuple[dict, list[dict]]:
    r = subprocess.run([str(exe), *args], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr
    lines = r.stdout.splitlines()
    w = dict(zip(*[iter(lines[0].split()[1:])] * 2, strict=True))
    work = {k: int(v) for k, v in w.items()}
    jobs = []
    for ln in lines[1:]:
        m = JOB.fullmatch(ln)
        assert m, ln
        v = [int(x) for x in m.groups()]
        names = ("job", "filter", "template", "refine", "emit", "link", "span", "level1", "level0", "resent",
                 "status")
        jobs.append(dict(zip(names, v, strict=True)))
    return work, jobs


# (tx ticks per byte, host delays before each ACK (per job, cycled; below ACK_TIMEOUT_MS = 500000
# ticks, so no LEVEL_END is repeated), half-level first ACKs)
SCENARIOS = {
    "instant": ("0", "0", False),
    "uart": ("217", "0", False),
    "slow-host": ("217", "0,777,123457,399999", False),
    "resends": ("217", "1,5000,250001", True),
}


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_stage_counts_are_the_jobs_work_and_link_is_the_rest(name, clocktest):
    tx, delays, short = SCENARIOS[name]
    work, jobs = run(clocktest, "--jobs", "4", "--tx-cost", tx, "--ack-delay", delays,
                     *(["--short-ack"] if short else []))
    assert [j["job"] for j in jobs] == [0, 1, 2, 3]
    delay = [int(d) for d in delays.split(",")]
    for j in jobs:
        assert j["status"] == 0
        assert (j["filter"], j["template"], j["refine"], j["emit"]) == (
            work["filter"], work["template"], work["refine1"] + work["refine0"], 0), j
        first = work["filter"] + work["template"] + work["refine1"]  # filter, template, refiner set-up
        assert (j["level1"], j["level0"]) == (first, work["refine0"])
        # link: everything else between RUN's OK and the last ACK, by the host's clock
        assert j["link"] == j["span"] - (j["filter"] + j["template"] + j["refine"] + j["emit"]), j
        waits = (4 if short else 2) * delay[j["job"] % len(delay)]  # one (two) ACK waits per level
        assert j["link"] >= waits
        assert (j["link"] > 0) == (tx != "0" or waits > 0)
        # the fake job's level (clocktest.c: 4 vertices, 2 triangles), delta-coded: shorter than raw
        total = P.LEVEL_HEADER.size + len(encode_level_body([(0, 0), (3, 0), (0, 3), (3, 3)],
                                                            [(0, 1, 3), (0, 3, 2)]))
        assert total < P.level_stream_size(4, 2, 2)
        assert j["resent"] == (2 * (total - total // 2) if short else 0)  # the second half of both levels
