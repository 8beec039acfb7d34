"""The simulated board for tests, the demo and the benchmarks: building it (sim/build.py) and running
wmsim processes.

``build`` is sim/build.py as a module (``build_sim()``, ``build_firmware()``); ``SimBoard`` runs one
simulator and collects its log lines; ``SIM_TIMEOUTS`` are the host's timeouts for it, and
``host_timeouts`` makes them (or longer ones) the host's default for a block.
"""

from __future__ import annotations

import contextlib
import importlib.util
import re
from collections.abc import Iterator
from pathlib import Path

from wavemesh.device import memmap, stream
from wavemesh.device.stream import Timeouts, auto_rate, reachable
from wavemesh.harness.devproc import DeviceProcess

ROOT = Path(__file__).resolve().parents[3]


def _load_sim_build():
    spec = importlib.util.spec_from_file_location("wm_sim_build", ROOT / "sim" / "build.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


build = _load_sim_build()

# Host timeouts for the simulated board: it runs at a tenth of the board's speed, far less on a loaded
# machine, and a level of the refiner takes it minutes then (job: the longest silence, not a bound on
# the job).  sync: in pin-accurate mode a HELLO and its answer are some 92 bytes on the line, 320 k
# cycles at 40 MHz and 115200 baud (3470 cycles a byte; 312 k at 39 MHz), two seconds of a simulator
# slowed to 170 kHz
# by a loaded machine (measured), more with a CPU hog beside it (4 s each was not enough at a load of
# 15 on two cores): 8 s each; reply likewise (RUN's answer did not come in 12 tries of 5 s there).
# keepalive: the device repeats a LEVEL_END or DONE whose ACK was lost only after ACK_TIMEOUT_MS of its
# own clock without any frame (19.5 million cycles at 39 MHz: one to several minutes of simulation, longer
# than any keepalive here on a loaded machine); every KEEPALIVE postpones that, so after a silence of
# keepalive with a level under way (or DONE due) the host sends RESUME instead (stream.Device.run).  The
# host here stays silent about as long in real seconds as the board's KEEPALIVE_MS takes in simulated
# ones (its link timeout, 30 s of the board's clock, is hours of simulation).
SIM_TIMEOUTS = Timeouts(sync=8.0, sync_attempts=5, reply=10.0, attempts=3, ack=5.0, job=900.0,
                        keepalive=120.0)


@contextlib.contextmanager
def host_timeouts(base: Timeouts = SIM_TIMEOUTS, **changes: float) -> Iterator[Timeouts]:
    """Inside the block, ``base`` with ``changes`` (fields of Timeouts) is the host's default
    (wavemesh.device.stream.DEFAULT_TIMEOUTS: what `wavemesh stream` and api.stream run with when given
    none, read when they open the device); after it, on an exception too, the default it replaced."""
    saved = stream.DEFAULT_TIMEOUTS
    stream.DEFAULT_TIMEOUTS = stream.with_timeouts(base, **changes)
    try:
        yield stream.DEFAULT_TIMEOUTS
    finally:
        stream.DEFAULT_TIMEOUTS = saved


def fastest_rate() -> int:
    """The rate `--link-baud auto` takes on the simulated board (and the ULX3S it models): the first of
    protocol.COMMON_BAUDS that the divisors its HELLO_REPLY states reach (memmap: CLK_HZ, UART_DIV_MIN up
    to the largest the UART's DIV field holds; firmware/board/app/main.c); 3,000,000 at 39 MHz."""
    div = next(f for r in memmap.UART.registers if r.name == "DIV" for f in r.fields if f.name == "DIV")
    div_max = div.mask >> div.lsb
    return reachable(memmap.CLK_HZ, memmap.UART_DIV_MIN, div_max,
                     auto_rate(memmap.CLK_HZ, memmap.UART_DIV_MIN, div_max))[1]


class SimBoard(DeviceProcess):
    """A running wmsim process: its URL and everything it printed."""

    name = "the simulator"

    def __init__(self, exe: Path, firmware: Path, *args: str):
        super().__init__([str(exe), "--firmware", str(firmware), *args], listen="--no-socket" not in args)

    def summary(self) -> dict:
        """The simulator's summary line as it stopped (`wmsim: summary cycles N wall S s rate K kHz ...
        cpu C s`): cycles, wall_seconds, rate_khz, cpu_seconds; {} without one."""
        m = re.search(r"summary cycles (\d+) wall ([\d.]+) s rate (\d+) kHz .* cpu ([\d.]+) s",
                      "\n".join(self.lines))
        if not m:
            return {}
        return {"cycles": int(m.group(1)), "wall_seconds": float(m.group(2)), "rate_khz": int(m.group(3)),
                "cpu_seconds": float(m.group(4))}

    def events(self, kind: str) -> list[tuple[int, int]]:
        """(value, cycle) of every `wmsim: KIND 0xVALUE cycle N` line (stage, leds, halt)."""
        out = []
        for line in self.lines:
            m = re.match(rf"wmsim: {kind} 0x([0-9a-f]+) cycle (\d+)", line)
            if m:
                out.append((int(m.group(1), 16), int(m.group(2))))
        return out
