"""`wavemesh stream` through the simulated board: the FPGA stage and the refiner on the soft CPU.

The board (sim/, Verilator model of soc_top with the real firmware) runs the protocol engine, the filter
bank and template stage in RTL (rtl/soc_accel.v) and the refiner cross-compiled for the soft CPU (the
VexRiscv; tests/sim/test_cpu_other.py runs the PicoRV32).  Its meshes must be byte for byte those of
`wavemesh mesh` (the native software path) and pass wavemesh.check, on inputs of several sizes, one of
them real data (a decimated crop of matplotlib's Jacksboro DEM).  The device's cycle counts of the stages
(filter, template, refine, emit) and of every level must depend on nothing but the job: the same on a
second identical job after other jobs, in the pin-accurate and the fast UART mode, and while CPU hogs
load the machine (the host then answers at other moments of the simulated clock); link I/O is counted
apart (DONE's cycles_link), and in pin-accurate mode it holds at least the line time of the mesh bytes.
Garbage must never keep the board from serving the next request (the fault proxy between host and
board, at 3 Mbaud on the pins: tests/sim/test_stream_board_3mbaud.py).

The simulated CPU runs about 1 million cycles per second, and the refiner's whole default pipeline
(reduction, error bound, final decimation) takes the soft CPU some 100 million cycles on a few
hundred triangles, so the inputs are small and only the smallest runs the whole pipeline (CASES).
"""

from __future__ import annotations

import json
import random
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from wavemesh.device import memmap
from wavemesh.device import protocol as P
from wavemesh.device import stream as S
from wavemesh.harness import jacksboro, run_cli
from wavemesh.harness.simboard import SIM_TIMEOUTS, SimBoard, fastest_rate
from wavemesh.io.synth import make

pytestmark = pytest.mark.sim

STAGES = ("filter", "template", "refine", "emit")  # the device's stages: their cycles depend only on the job


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("board_inputs")
    np.save(d / "ball.npy", make("ball", 32)[8:25, 6:26])  # 20 x 17
    np.save(d / "box.npy", make("box", 32)[:24, 4:32])  # 28 x 24
    np.save(d / "tiny.npy", make("ball", 16)[3:12, 2:12])  # 10 x 9
    return d


def jacksboro_holes(folder: Path) -> Path:
    """An 18 x 16 crop of the Jacksboro DEM with a hole of 3 x 3 samples and one of a sample (NaN), for
    `--nodata hole`: the error engine scans against the validity mask."""
    z = np.load(jacksboro())["elevation"].astype(np.float64)[120:136, 200:218]
    z[6:9, 4:7] = np.nan
    z[12, 14] = np.nan
    np.save(folder / "jacksboro-holes.npy", z)
    return folder / "jacksboro-holes.npy"


# name -> (input, options of both commands).  The soft CPU runs the reduction (64-bit eigen
# arithmetic) and the final decimation at some 100 million cycles per job on these inputs, minutes
# of simulation each: the three larger inputs run without them (the levels and the error bound, as
# the first board did), and the 10 x 9 one with the whole default pipeline.
LEAN = ["--reduce", "off", "--simplify", "off"]
CASES = {
    "ball-20x17": ("ball.npy", LEAN),
    "box-28x24": ("box.npy", ["--metric", "vertical", "--zeta", "2", *LEAN]),
    # a real DEM on the board at 13 x 11 (/16, 26 x 22, took ~55 s of make test; make bench-soc runs it)
    "jacksboro-13x11": ("JACKSBORO", ["--key", "elevation", "--decimate", "32", "--zeta", "15", *LEAN]),
    "tiny-default": ("tiny.npy", []),
    "tiny-levels-alone": ("tiny.npy", ["--levels", "2", "--bound", "off", "-k", "3"]),  # the levels alone
}


def source(inputs: Path, name: str) -> str:
    return jacksboro() if name == "JACKSBORO" else str(inputs / name)


@pytest.fixture(scope="module")
def fast_board(sim_exe, firmware_hex):
    b = SimBoard(sim_exe, firmware_hex, "--port", "0", "--fast", "--quiet")
    yield b
    b.stop()


@pytest.fixture
def sim_timeouts(monkeypatch):
    monkeypatch.setattr(S, "DEFAULT_TIMEOUTS", SIM_TIMEOUTS)


def stream_and_mesh(src: str, opts: list[str], url: str, tmp: Path, link: tuple[str, ...] = ()) -> dict:
    """`wavemesh stream` on the board and `wavemesh mesh` with the same options: the same files, a
    proper mesh, the same initial triangulation in both reports; returns the stream's report.  ``link``:
    options of the stream alone (--link-baud)."""
    rc, _, err = run_cli("stream", src, *opts, *link, "--port", url, "-o", str(tmp / "board.obj"),
                         "--report", str(tmp / "board.json"), "--quiet")
    assert rc == 0, err
    rc, _, err = run_cli("mesh", src, *opts, "-o", str(tmp / "soft.obj"), "--report", str(tmp / "soft.json"),
                         "-q")
    assert rc == 0, err
    assert (tmp / "board.obj").read_bytes() == (tmp / "soft.obj").read_bytes()
    report, soft = (json.loads((tmp / f"{n}.json").read_text()) for n in ("board", "soft"))
    # the initial triangulation is the templates' (DONE's initial_*), not the first level the board sent
    assert report["initial"] == {k: soft["initial"][k] for k in report["initial"]}
    check_args = ["check", str(tmp / "board.obj"), "--against", src]
    check_args += [o for o in opts if o in ("--key", "elevation")]
    for o in ("--decimate", "--nodata"):  # the input's options that check takes
        if o in opts:
            check_args += [o, opts[opts.index(o) + 1]]
    rc, out, err = run_cli(*check_args)
    assert rc == 0, out + err
    return report


def job_cycles(report: dict) -> dict:
    """What must depend only on the job: the stages' cycles and every level's (LEVEL_HEADER.cycles)."""
    return {k: report["device_cycles"][k] for k in STAGES} | {
        "levels": [(lv["level"], lv["device_cycles"]) for lv in report["refiner"]["levels"]]}


def assert_same_work(a: dict, b: dict) -> None:
    """job_cycles of two runs: the same stages and levels, each with exactly the same cycles (every
    SYS.STAGE marker is a stage sync: the SDRAM, its refresh clock and the CPU's cache start each
    stretch in one state, docs/soc.md, "Cycle accounting")."""
    assert a == b, (a, b)


def assert_same_trace(a: list, b: list) -> None:
    """clock_trace of two runs: the same switches of the engine's clocks, each stage's stretch of
    exactly the same cycles."""
    assert len(a) > 10 and a == b, (a, b)


CYCLES: dict[str, dict] = {}


@pytest.mark.parametrize("case", list(CASES))
def test_stream_on_the_board_equals_mesh(case, fast_board, inputs, tmp_path, sim_timeouts):
    name, opts = CASES[case]
    report = stream_and_mesh(source(inputs, name), opts, fast_board.url, tmp_path)
    assert report["device"]["name"] == "wm-board"
    cycles = {k: v for k, v in report["device_cycles"].items() if k != "seconds"}
    assert all(cycles[k] > 0 for k in (*STAGES, "receive", "link")), cycles
    # the FPGA stage alone (no frame is counted in it any more): about 1.4 cycles per sample, and the
    # fixed cost of its marker and the data cache's flush after it (the stage sync, the VexRiscv's two
    # caches swept a line a cycle, 1,024 lines each, docs/soc.md "Cycle accounting")
    samples = report["input"]["width"] * report["input"]["height"]
    assert cycles["filter"] < 10 * samples + 6_000
    # the levels' cycles are the stages' that made them, to the cycle: after the last level no stage's
    # clock runs (the job only returns)
    levels = [lv["device_cycles"] for lv in report["refiner"]["levels"]]
    assert sum(levels) == cycles["filter"] + cycles["template"] + cycles["refine"], (levels, cycles)
    CYCLES[case] = job_cycles(report)


def test_cycle_counts_are_deterministic(fast_board, inputs, tmp_path, sim_timeouts):
    """The first job again on the same board, after the other jobs (other samples, coefficients,
    heap contents and frame numbers left behind): the same cycles in every stage and level."""
    case = "ball-20x17"
    if case not in CYCLES:
        pytest.skip("needs test_stream_on_the_board_equals_mesh[ball-20x17]")
    name, opts = CASES[case]
    report = stream_and_mesh(source(inputs, name), opts, fast_board.url, tmp_path)
    assert_same_work(job_cycles(report), CYCLES[case])


TINY = ["--levels", "2", *LEAN]
CLOCK_MARK = 0x00020000  # SYS.STAGE marker | the clock that starts to run (firmware/board/app/main.c)


def clock_trace(board: SimBoard) -> list[tuple[int, int | None]]:
    """(clock, cycles until the next switch) of every switch of the engine's clocks that the board
    logged; the cycles of the job's stages only (filter .. emit), None for link I/O, the upload
    (receive) and the time outside jobs, which depend on the host."""
    ev = [(v & 0xFFFF, c) for v, c in board.events("stage") if v & 0xFFFF0000 == CLOCK_MARK]
    stages = range(P.Stage.FILTER, P.Stage.EMIT + 1)
    return [(k, c2 - c1 if k in stages else None) for (k, c1), (_, c2) in zip(ev, ev[1:], strict=False)]


def stream_tiny(sim_exe, firmware_hex, inputs, tmp: Path, mode: str, jobs: int = 1) -> tuple[list, list]:
    """The tiny input `jobs` times on a fresh board in pin-accurate or fast mode: the reports and the
    board's clock trace."""
    args = ["--port", "0", "--exit-on-close"] + (["--fast"] if mode == "fast" else [])
    b = SimBoard(sim_exe, firmware_hex, *args)
    reports = []
    try:
        for k in range(jobs):
            (tmp / f"{mode}{k}").mkdir(parents=True)
            reports.append(stream_and_mesh(str(inputs / "tiny.npy"), TINY, b.url, tmp / f"{mode}{k}"))
    finally:
        b.stop()
    return reports, clock_trace(b)


TINY_CYCLES: dict[str, dict] = {}
TINY_TRACE: list = []


def test_pin_accurate_mode_gives_the_same_mesh_and_cycles(sim_exe, firmware_hex, inputs, tmp_path,
                                                          sim_timeouts):
    """A tiny input bit by bit over the UART pins at 115200 baud, then in fast mode: the same mesh,
    the same cycles in every stage and level; the link's cycles hold the line time (10 bit times of
    the UART per byte, for at least the mesh bytes) in pin-accurate mode only."""
    (pin,), pin_trace = stream_tiny(sim_exe, firmware_hex, inputs, tmp_path, "pin")
    (fast,), fast_trace = stream_tiny(sim_exe, firmware_hex, inputs, tmp_path, "fast")
    assert_same_work(job_cycles(pin), job_cycles(fast))
    # interval by interval: every stretch of a stage's clock between two switches is the same
    assert_same_trace(pin_trace, fast_trace)
    dev = pin["device"]
    # the start rate as the board states it: its divisor's, rounded as after a switch (115,385 at 39 MHz)
    assert dev["baud"] == P.divisor_baud(memmap.CLK_HZ, memmap.UART_DIV_RESET)
    byte_cycles = 10 * P.baud_divisor(dev["clk_hz"], dev["baud"])  # 3380 at 39 MHz and 115200 baud
    mesh_bytes = pin["transfer"]["mesh_bytes"]
    assert pin["device_cycles"]["link"] >= byte_cycles * mesh_bytes
    assert fast["device_cycles"]["link"] < byte_cycles * mesh_bytes
    TINY_CYCLES.update(job_cycles(fast))
    TINY_TRACE[:] = fast_trace


def test_pin_accurate_after_the_switch_to_3_mbaud(sim_exe, firmware_hex, inputs, tmp_path, sim_timeouts):
    """The tiny job bit by bit after `--link-baud` to the board's nearest rate to 3 Mbaud (divisor 13 at
    39 MHz: 3 Mbaud exactly): the same mesh as
    `wavemesh mesh`, the same stage cycles as the fast mode's, and the link's cycles hold the line time
    of the mesh bytes at the new rate, less than a 115200-baud byte each.  Then, at that rate (the board
    keeps it for BAUD_IDLE_MS, tens of seconds of simulation): garbage on the line and a clean job again.
    (Faults at that rate: tests/sim/test_stream_board_3mbaud.py and make bench-faults.)"""
    rate = fastest_rate()  # what --link-baud auto takes: 3,000,000 at 39 MHz
    link = ("--link-baud", str(rate))
    src = str(inputs / "tiny.npy")
    b = SimBoard(sim_exe, firmware_hex, "--port", "0")
    try:
        rep = stream_and_mesh(src, TINY, b.url, tmp_path, link)
        with socket.create_connection(("127.0.0.1", b.port), timeout=5) as s:
            s.sendall(bytes(random.Random(3).randrange(256) for _ in range(300)) + b"\xc0\x01\x02")
            time.sleep(0.5)
        time.sleep(0.5)  # the bridge has seen the close (a second client would get BUSY)
        (tmp_path / "clean").mkdir()
        stream_and_mesh(src, TINY, b.url, tmp_path / "clean", link)
    finally:
        b.stop()
    assert rep["device"]["baud"] == rate and rep["transfer"]["line_baud"] == rate
    assert rep["device"]["features"] & P.FEATURE_RICE  # the upload block decodes: coded samples at every rate
    if TINY_CYCLES:
        assert_same_work(job_cycles(rep), TINY_CYCLES)
    byte_cycles = 10 * P.baud_divisor(memmap.CLK_HZ, rate)
    mesh_bytes = rep["transfer"]["mesh_bytes"]
    assert byte_cycles * mesh_bytes <= rep["device_cycles"]["link"]


HOG = "import sys, time\nend = time.monotonic() + float(sys.argv[1])\nwhile time.monotonic() < end: pass"
HOG_SECONDS = 900  # the hog ends by itself after this, whatever happens to the test


@pytest.fixture
def cpu_hog():
    """start() -> a busy-looping process, bounded in time; killed at teardown."""
    hogs = []

    def start() -> subprocess.Popen:
        hogs.append(subprocess.Popen([sys.executable, "-c", HOG, str(HOG_SECONDS)]))
        return hogs[-1]

    yield start
    for h in hogs:
        h.kill()
        h.wait(10)


def test_cycle_counts_do_not_change_under_load(sim_exe, firmware_hex, inputs, tmp_path, sim_timeouts,
                                               cpu_hog):
    """The tiny input on a fresh pin-accurate board while a CPU hog runs (the host and the simulator
    get the CPU at other moments, so the host answers at other simulated cycles): the cycles of every
    stage and level, and of every stretch of a stage's clock, are those of the unloaded run."""
    if TINY_CYCLES:
        reference, trace = TINY_CYCLES, TINY_TRACE
    else:
        (fast,), trace = stream_tiny(sim_exe, firmware_hex, inputs, tmp_path / "unloaded", "fast")
        reference = job_cycles(fast)
    hog = cpu_hog()
    t0 = time.monotonic()
    (loaded,), loaded_trace = stream_tiny(sim_exe, firmware_hex, inputs, tmp_path, "pin")
    assert hog.poll() is None, "the hog ended before the job did"
    assert time.monotonic() - t0 < HOG_SECONDS
    assert_same_work(job_cycles(loaded), reference)
    assert_same_trace(loaded_trace, trace)


def test_garbage_then_a_valid_request(fast_board, inputs, tmp_path, sim_timeouts):
    """Random bytes, a half frame, then a normal session on a new connection: the board serves it."""
    rng = random.Random(7)
    with socket.create_connection(("127.0.0.1", fast_board.port), timeout=5) as s:
        s.sendall(bytes(rng.randrange(256) for _ in range(600)))
        s.sendall(b"\xc0\x01\x02\x03")  # a frame start and a few bytes, never finished
        time.sleep(0.5)
    time.sleep(0.2)
    src = str(inputs / "tiny.npy")
    stream_and_mesh(src, ["--levels", "2", *LEAN], fast_board.url, tmp_path)  # LEAN: the link is under test


@pytest.fixture(scope="module")
def ungated_exe(verilator, tmp_path_factory) -> Path:
    """The simulator without its clock gates of the FPGA stage and the error engine's units (sim/build.py,
    ungated: every unit clocked at every edge, as in the bitstream), copied as conftest.py's sim_exe is."""
    import shutil

    from wavemesh.harness.simboard import build

    try:
        exe = build.build_sim(ungated=True)
    except RuntimeError as e:
        pytest.fail(str(e))
    return Path(shutil.copy2(exe, tmp_path_factory.mktemp("ungated") / exe.name))


# The jobs of the clock gates' test, on one board in this order: the stage's frames (the second and later
# after idle), and every unit of the error engine: scans (PUSH), the slope unit (SLOPE_GO, mode 2 of
# POINT_GO, root commands), the divider, the angle unit (the swaps' angles with --alpha above 0, the
# reduction's ears) and the point-error unit (the reduction; not with holes), idle between commands.
GATE_JOBS = {
    "ball-20x17-reduce": ("ball.npy", ["--simplify", "off", "--alpha", "0.8"]),
    "jacksboro-13x11": CASES["jacksboro-13x11"],
    "jacksboro-holes": ("jacksboro-holes.npy", ["--nodata", "hole", "--simplify", "off", "--alpha", "0.8",
                                                "--zeta", "5"]),
}


def test_the_clock_gates_change_no_cycle(sim_exe, ungated_exe, firmware_hex, inputs, tmp_path, sim_timeouts):
    """The default simulator gates the FPGA stage's clock outside its frames (rtl/soc_accel.v,
    WM_SIM_STAGE_GATE) and the error engine's units' while none has work (rtl/soc_engine.v,
    WM_SIM_ENGINE_GATE); the ungated build clocks them at every edge, as the bitstream does.  The jobs of
    GATE_JOBS on a fresh board of each (the stage, the upload block, every unit of the error engine, the
    levels; each frame and command starts from what the units kept through the idle stretch before it):
    the same mesh bytes, the same cycles of every stage and level, of every stretch of a stage's clock,
    and the same counts in DONE."""
    jacksboro_holes(inputs)
    runs = {}
    for kind, exe in (("gated", sim_exe), ("ungated", ungated_exe)):
        b = SimBoard(exe, firmware_hex, "--port", "0", "--fast")
        out = []
        try:
            for case, (name, opts) in GATE_JOBS.items():
                d = tmp_path / kind / case
                d.mkdir(parents=True)
                report = stream_and_mesh(source(inputs, name), opts, b.url, d)
                # DONE's counts (the levels' vertices, triangles, E_max, splits, swaps), not when they arrived
                levels = report["refiner"]["levels"]
                done = [{k: v for k, v in lv.items() if k != "arrived_s"} for lv in levels]
                out.append((job_cycles(report), done, (d / "board.obj").read_bytes()))
        finally:
            b.stop()
        runs[kind] = (out, clock_trace(b))
    (gated, gated_trace), (ungated, ungated_trace) = runs["gated"], runs["ungated"]
    for (cyc_a, ref_a, obj_a), (cyc_b, ref_b, obj_b) in zip(gated, ungated, strict=True):
        assert obj_a == obj_b
        assert_same_work(cyc_a, cyc_b)
        assert ref_a == ref_b
    assert_same_trace(gated_trace, ungated_trace)
