"""bench/bench_soc.py's full cases (`make bench-soc-full`) without the simulator: the case names, the
results file the runs merge into, the table written from it."""

from __future__ import annotations

import json

import bench_soc as B  # bench/ is on pytest's path (pytest.ini)


def _case(name: str, work: int, samples: int = 65_536, tris: int = 424, **extra) -> dict:
    budget = B.PER_SAMPLE * samples + B.PER_TRIANGLE * tris
    cycles = {"receive": 5, "filter": 1_000_000, "template": 2_000_000, "refine": work - 3_500_000,
              "emit": 500_000, "link": 7}
    return {"name": name, "options": ["--zeta", "10"] if "Jacksboro" in name else [], "width": 256,
            "height": samples // 256, "samples": samples, "initial_triangles": 124, "output_triangles": tris,
            "cycles": cycles, "work_cycles": work, "budget_cycles": budget, "work_vs_budget": work / budget,
            "work_cycles_per_sample": work / samples, "work_cycles_per_triangle": work / tris,
            "board_seconds": 1.25, "same_as_mesh": True, "held_out": name in B.FULL_HELD_OUT,
            "simulator": {"cycles": 1, "wall_seconds": 150.0, "rate_khz": 554, "cpu_seconds": 1.0},
            "code": {"commit": "abc1234", "measured": "abc1234", "uncommitted": []}, "cpu": "vexriscv",
            "date": "2026-11-29", **extra}


def test_full_cases_by_name_or_first_word():
    assert B.full_case("ball") == "Ball 256 x 256"
    assert B.full_case("Jacksboro") == "Jacksboro, whole"
    assert B.full_case("lidar_dem") == "lidar_dem, whole (held out)"
    assert B.full_case("Box 256 x 256") == "Box 256 x 256"
    assert B.full_case("ball 256") is None and B.full_case("nosuch") is None
    # every held-out case is a case, and the budget's five inputs are there, each of >= 5,000 samples' kind
    assert set(B.FULL_HELD_OUT) < set(B.FULL) and len(B.FULL) == 5
    assert B.FULL_HELD_OUT == ("lidar_dem, whole (held out)", "motorcycle, whole (held out)")
    assert B.HELD_OUT == ("lidar_dem / 8 (held out)",)


def test_merge_keeps_every_case_once_in_full_order(tmp_path):
    path, lock = tmp_path / "soc-full.json", tmp_path / "lock"
    B._merge(path, _case("lidar_dem, whole (held out)", 40_000_000, samples=160_000), lock)
    B._merge(path, _case("Ball 256 x 256", 50_000_000), lock)
    B._merge(path, _case("Ball 256 x 256", 45_667_489), lock)  # a second run replaces the first
    data = json.loads(path.read_text())
    assert [c["name"] for c in data["cases"]] == ["Ball 256 x 256", "lidar_dem, whole (held out)"]
    assert data["cases"][0]["work_cycles"] == 45_667_489
    assert data["budget"] == {"per_sample": 200, "per_output_triangle": 3_000}


def test_full_markdown_tables_held_out_apart_failures_and_missing():
    data = {"cases": [_case("Ball 256 x 256", 45_667_489),
                      _case("lidar_dem, whole (held out)", 40_000_000, samples=160_000, tris=550),
                      {"name": "Box 256 x 256", "options": [], "error": "error: timed out\nerror: the job"}]}
    text = "\n".join(B.full_markdown(data))
    tuned, held = text.split("Held out:")
    # Ball: work 45.7 M against 200 x 65,536 + 3,000 x 424 = 14.4 M
    assert "| Ball 256 x 256 | 256 x 256 | 65,536 | defaults | 124 -> 424 |" in tuned
    assert "| 45.7 M | 14.4 M | 3.18 x | 697 | 107,706 | 1.2 | 2.5 min (554 kHz) | yes |" in tuned
    assert "lidar_dem" not in tuned.split("|", 1)[1] and "| lidar_dem, whole (held out) | 256 x 625 |" in held
    assert "Box 256 x 256: the run failed: `error: the job`" in held
    assert "Not run yet: Jacksboro, whole; motorcycle, whole (held out)." in held
    assert "code measured: commit abc1234" in tuned
    # nothing run yet: the description and the list of what is missing, no table
    empty = "\n".join(B.full_markdown(None))
    assert "| input |" not in empty and "Not run yet: Ball 256 x 256; Box 256 x 256;" in empty


def test_simboard_summary_parses_the_simulators_line():
    """SimBoard.summary reads the line sim/sim_main.h prints as it stops (the benches' one parser of it)."""
    from types import SimpleNamespace

    from wavemesh.harness.simboard import SimBoard

    line = "wmsim: summary cycles 45667489 wall 115.900 s rate 394 kHz bytes-in 12 bytes-out 34 cpu 110.250 s"
    got = SimBoard.summary(SimpleNamespace(lines=["wmsim: stage 0x1 cycle 5", line]))
    assert got == {"cycles": 45667489, "wall_seconds": 115.9, "rate_khz": 394, "cpu_seconds": 110.25}
    assert SimBoard.summary(SimpleNamespace(lines=["wmsim: stage 0x1 cycle 5"])) == {}


def test_host_timeouts_set_for_the_block_and_restored_on_exception_too():
    """harness.simboard.host_timeouts, the benches' one way to give `wavemesh stream` the simulated
    board's timeouts: inside the block stream.DEFAULT_TIMEOUTS is SIM_TIMEOUTS (with the changes asked
    for, over another base too, nested), after it what it was, also when the block raises."""
    import pytest
    from wavemesh.device import stream as S
    from wavemesh.harness.simboard import SIM_TIMEOUTS, host_timeouts

    before = S.DEFAULT_TIMEOUTS
    assert before != SIM_TIMEOUTS
    with host_timeouts() as t:
        assert S.DEFAULT_TIMEOUTS is t and t == SIM_TIMEOUTS
    assert S.DEFAULT_TIMEOUTS is before
    with pytest.raises(KeyError), host_timeouts(job=3600.0, sync=20.0):
        assert S.DEFAULT_TIMEOUTS.job == 3600.0 and S.DEFAULT_TIMEOUTS.sync == 20.0
        assert S.DEFAULT_TIMEOUTS.reply == SIM_TIMEOUTS.reply
        with host_timeouts(S.DEFAULT_TIMEOUTS, sync_attempts=250):
            assert S.DEFAULT_TIMEOUTS.sync_attempts == 250 and S.DEFAULT_TIMEOUTS.job == 3600.0
        assert S.DEFAULT_TIMEOUTS.sync_attempts == SIM_TIMEOUTS.sync_attempts
        raise KeyError("the block fails")
    assert S.DEFAULT_TIMEOUTS is before


def test_devices_opened_in_the_block_take_its_timeouts(monkeypatch):
    """Device() without timeouts and `wavemesh devices`' probe read DEFAULT_TIMEOUTS when they open the
    port, not when their module was imported: host_timeouts reaches them."""
    from wavemesh.device import devices
    from wavemesh.device import stream as S
    from wavemesh.errors import WavemeshError
    from wavemesh.harness.simboard import host_timeouts

    seen = []

    class Probe:  # stands in for Device in the probe: records its timeouts, answers nothing
        def __init__(self, url, baud, timeouts):
            seen.append(timeouts)
            raise WavemeshError("no device answers")

    monkeypatch.setattr(devices, "Device", Probe)
    with host_timeouts(job=1234.0, reply=7.5):
        with S.Device("loop://") as dev:
            assert dev.t == S.DEFAULT_TIMEOUTS and dev.t.job == 1234.0
        devices.probe(devices.PortReport("loop://"))
    assert seen and seen[0].reply == 7.5 and seen[0].sync == devices.PROBE_SYNC_S
    with S.Device("loop://") as dev:
        assert dev.t is S.DEFAULT_TIMEOUTS and dev.t.job != 1234.0
