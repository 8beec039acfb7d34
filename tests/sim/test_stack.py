"""The board's stack check: crt0 paints the free firmware RAM and the stack with memmap.STACK_PAINT, and
DONE states the stack's reserve and its high-water mark (the deepest word no longer painted), which the
host reports (the report's device_stack) and refuses when it came within protocol.STACK_GUARD_BYTES of the
reserve (docs/soc.md, "The stack's high-water mark").

The mark of a real job is checked against an independent figure, GCC's -fstack-usage frames of the
firmware build (its .su files): at least the frames that are on the stack together when the reduction
runs (main, the engine's serve loop, the board's job, the job library's refine loop, the refiner's step
and wm_reduce, whose frame is the image's largest), and below the reserve by more than the guard.  A
firmware linked with a smaller stack (sim/build.py's build_firmware(stack_bytes=...)) shows the other
side: its job runs past the reserve into the free RAM below it, and the host says so and writes nothing.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from wavemesh.device import memmap
from wavemesh.device import protocol as P
from wavemesh.device import stream as S
from wavemesh.harness import run_cli
from wavemesh.harness.simboard import SIM_TIMEOUTS, SimBoard, build
from wavemesh.io.synth import make

pytestmark = pytest.mark.sim

# the frames on the stack together while the reduction runs (tiny-default below runs it on every level)
CHAIN = ("main", "wm_proto_serve", "board_job", "wm_job_refine", "wm_refine_step", "wm_reduce")
LEAN = ["--levels", "2", "--reduce", "off", "--simplify", "off"]
SMALL_STACK = 1024  # bytes: below what any job needs (the LEAN job's mark is some 2 KB)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("stack") / "tiny.npy"
    np.save(p, make("ball", 16)[3:12, 2:12])  # 10 x 9, test_stream_board.py's tiny-default
    return p


@pytest.fixture
def sim_timeouts(monkeypatch):
    monkeypatch.setattr(S, "DEFAULT_TIMEOUTS", SIM_TIMEOUTS)


def frames(folder: Path) -> dict[str, int]:
    """-fstack-usage's frame of every function of the firmware build in `folder` (its .su files)."""
    out: dict[str, int] = {}
    for su in folder.rglob("*.su"):
        for line in su.read_text().splitlines():
            where, size, _ = line.split("\t")
            out[where.rsplit(":", 1)[1]] = int(size)
    return out


def stream(src: Path, opts: list[str], url: str, tmp: Path) -> tuple[int, str, dict | None]:
    rc, _, err = run_cli("stream", str(src), *opts, "--port", url, "-o", str(tmp / "board.obj"),
                         "--report", str(tmp / "board.json"), "--quiet")
    report = json.loads((tmp / "board.json").read_text()) if rc == 0 else None
    return rc, err, report


def test_the_mark_of_a_real_job(sim_exe, firmware_hex, tiny, tmp_path, sim_timeouts):
    """The whole default pipeline on the board: its mark lies above the chain's -fstack-usage frames and
    below the reserve less the guard; a lean job after it (no reduction) reports its own, smaller mark:
    each DONE's scan paints the stack again below it."""
    su = frames(build.build_firmware().parent)
    assert max(su, key=su.get) == "wm_reduce", sorted(su.items(), key=lambda kv: -kv[1])[:5]
    floor = sum(su[f] for f in CHAIN)
    board = SimBoard(sim_exe, firmware_hex, "--port", "0", "--fast", "--quiet")
    try:
        rc, err, full = stream(tiny, [], board.url, tmp_path)
        assert rc == 0, err
        rc, err, lean = stream(tiny, LEAN, board.url, tmp_path)
        assert rc == 0, err
    finally:
        board.stop()
    stack = full["device_stack"]
    assert stack["bytes"] == memmap.STACK_BYTES
    assert floor < stack["peak"] <= memmap.STACK_BYTES - P.STACK_GUARD_BYTES, (floor, stack)
    assert lean["device_stack"]["bytes"] == memmap.STACK_BYTES
    assert su["main"] < lean["device_stack"]["peak"] < floor, (lean["device_stack"], floor)


def test_a_stack_past_its_guard_is_an_error(sim_exe, tiny, tmp_path, sim_timeouts):
    """The firmware linked with a 1 KiB stack: the lean job runs past it into the free RAM below (which
    nothing else uses, so the board survives), DONE states the overflow and the host refuses the job,
    names the stack and writes no output."""
    image = build.build_firmware(stack_bytes=SMALL_STACK)
    board = SimBoard(sim_exe, image, "--port", "0", "--fast", "--quiet")
    try:
        rc, err, _ = stream(tiny, LEAN, board.url, tmp_path)
    finally:
        board.stop()
    assert rc != 0
    assert f"overflowed its {SMALL_STACK}-byte reserve" in err, err
    assert not (tmp_path / "board.obj").exists() and not (tmp_path / "board.json").exists()
