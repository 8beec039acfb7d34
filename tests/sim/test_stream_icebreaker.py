"""`wavemesh stream` through the simulated iCEBreaker: sim/icebreaker_sim.v is the bitstream's top,
rtl/boards/icebreaker_top.v, with its own parameters (12 MHz, 115200 baud, the power-on reset), driven
bit by bit on its UART pins by wmsim-icebreaker (sim/icebreaker_main.cpp).

HELLO finds the FPGA stage (FEATURE_STAGE), `wavemesh devices` lists it, the stage labels the blocks of
the job it is sent (wavemesh.device.stage), and the host refines: the mesh file equals `wavemesh mesh`'s byte
for byte, and the stage's labelling is the model's block for block.  A job beyond the stage's HELLO
(more levels than it makes) is refused on the host with one error line, and the next job is exact.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from wavemesh.cli import main
from wavemesh.device import protocol as P
from wavemesh.device import stage
from wavemesh.device.stream import Device
from wavemesh.harness.devproc import DeviceProcess
from wavemesh.harness.simboard import SIM_TIMEOUTS, build
from wavemesh.io import synth
from wavemesh.io.heightfield import from_array
from wavemesh.model.haar import decompose
from wavemesh.model.label import label_blocks, tau_counts

pytestmark = pytest.mark.sim


@pytest.fixture(scope="module")
def icebreaker(verilator):
    try:
        exe = build.build_icebreaker_sim()
    except RuntimeError as e:
        pytest.fail(str(e))
    dev = DeviceProcess([str(exe), "--port", "0"])
    dev.name = "the simulated iCEBreaker"
    yield dev
    dev.stop()


def test_devices_finds_the_stage(icebreaker, capsys):
    assert main(["devices", "--port", icebreaker.url, "--json"]) == 0
    [r] = [r for r in json.loads(capsys.readouterr().out) if r["url"] == icebreaker.url]
    info = r["info"]
    assert info["name"] == "wm-stage" and info["features"] == P.FEATURE_STAGE
    assert (info["max_width"], info["max_height"], info["max_levels"]) == (256, 4096, 3)
    assert (info["clk_hz"], info["baud"], info["tri_capacity"]) == (12_000_000, 115_200, 0)


def test_stage_labels_as_the_model(icebreaker):
    """The stage's entries for a 41 x 23 terrain at M = 3 make the model's labelling (labels, split
    masks, templates)."""
    samples = from_array(synth.f3(41)[:23]).samples
    tau_q = tau_counts(5.0, 1.0)
    with Device(icebreaker.url, timeouts=SIM_TIMEOUTS) as dev:
        info = dev.sync()
        assert info.features & P.FEATURE_STAGE
        got = stage.labelling(dev.link, samples, 3, tau_q, silence=15.0)
    want = label_blocks(decompose(samples, 3)[-1], tau_q, 41, 23)
    for name in ("xs", "ys", "label", "mask", "template"):
        assert np.array_equal(getattr(got, name), getattr(want, name)), name


# the last case asks for a faster line: the stage cannot change its rate (its divisor is the bitstream's
# BAUD parameter), so one warning line and the job at 115200 baud
@pytest.mark.parametrize("shape,opts,link", [((33, 33), [], []),
                                             ((37, 29), ["--levels", "3", "--zeta", "0.002"], []),
                                             ((20, 40), ["--stage", "initial", "--levels", "1"],
                                              ["--link-baud", "921600"])],
                         ids=["33x33-default", "37x29-M3", "20x40-initial-link-baud"])
def test_stream_equals_mesh(icebreaker, tmp_path, capsys, shape, opts, link):
    w, h = shape
    src = tmp_path / "in.npy"
    np.save(src, synth.f1(max(w, h))[:h, :w])
    assert main(["mesh", str(src), "-o", str(tmp_path / "mesh.obj"), "-q", *opts]) == 0
    capsys.readouterr()
    assert main(["stream", str(src), "-o", str(tmp_path / "stream.obj"), "--port", icebreaker.url, "-q",
                 "--timeout", "60", *opts, *link]) == 0
    assert (tmp_path / "stream.obj").read_bytes() == (tmp_path / "mesh.obj").read_bytes()
    warnings = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("warning:")]
    if link:
        assert len(warnings) == 1 and "cannot change its rate: staying at 115200" in warnings[0], warnings
    else:
        assert warnings == []


def test_job_beyond_the_stage_is_refused_on_the_host(icebreaker, tmp_path, capsys):
    src = tmp_path / "in.npy"
    np.save(src, synth.f1(33))
    assert main(["stream", str(src), "-o", str(tmp_path / "x.obj"), "--port", icebreaker.url, "-q",
                 "--levels", "4"]) != 0
    err = capsys.readouterr().err
    assert "error: --levels 4: the device makes at most 3" in err
    assert not (tmp_path / "x.obj").exists()
