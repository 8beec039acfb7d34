"""`wavemesh devices`: the serial ports this machine has, and which of them a wavemesh device answers on.

Every port pyserial's ``list_ports`` finds (plus any URL given with ``--port``, e.g. the simulated
board's ``socket://127.0.0.1:7720``) is opened and sent HELLO, as ``wavemesh stream`` does before a job
(:meth:`wavemesh.device.stream.Device.sync`), with a short timeout; a port that answers is listed with the
capabilities its HELLO_REPLY states (the iCEBreaker's FPGA stage answers HELLO too: FEATURE_STAGE).  A
port that cannot be opened (busy, no permission) is listed with the reason.  HELLO ends whatever session
the device had, so nothing is lost on a wavemesh device; on another kind of device the probe writes two
short messages, as esptool's sync does (``--no-probe`` only lists).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from serial.tools import list_ports as lp

from wavemesh.device import stream
from wavemesh.device.stream import Device
from wavemesh.errors import WavemeshError

# one HELLO, answered within half a second, twice: a board answers in a few milliseconds
PROBE_SYNC_S = 0.5
PROBE_ATTEMPTS = 2


@dataclass
class PortReport:
    """One port: what pyserial says of it, and what (if anything) answered HELLO there."""

    url: str
    description: str = ""
    hwid: str = ""
    answer: str = ""  # the device's summary (DeviceInfo.summary) when it answered
    info: dict | None = None  # its HELLO_REPLY (DeviceInfo.to_report)
    problem: str = ""  # why it could not be asked, or that nothing answered

    @property
    def answered(self) -> bool:
        return self.info is not None

    def line(self) -> str:
        shown = self.description and self.description != "n/a"
        head = self.url + (f"  ({self.description})" if shown else "")
        if self.answered:
            return f"{head}: wavemesh device: {self.answer}"
        return f"{head}: {self.problem or 'not probed'}"


def list_ports() -> list[PortReport]:
    """The serial ports pyserial finds, sorted by name (none on a machine without any)."""
    return [PortReport(p.device, p.description or "", p.hwid or "") for p in sorted(lp.comports())]


def probe(report: PortReport, baud: int = 115200) -> PortReport:
    """Send HELLO on `report.url`; fill in the answer or the problem."""
    timeouts = replace(stream.DEFAULT_TIMEOUTS, sync=PROBE_SYNC_S, sync_attempts=PROBE_ATTEMPTS)
    try:
        with Device(report.url, baud, timeouts=timeouts) as dev:
            info = dev.sync()
    except WavemeshError as e:
        msg = e.message
        report.problem = "no HELLO answer" if msg.startswith("no device answers") else msg
        return report
    report.info = info.to_report()
    report.answer = info.summary()
    return report


def scan(extra: list[str] = (), baud: int = 115200, do_probe: bool = True) -> list[PortReport]:
    """Every port (pyserial's and `extra`), each probed with HELLO unless `do_probe` is false."""
    reports = list_ports()
    known = {r.url for r in reports}
    reports += [PortReport(url, "given with --port") for url in extra if url not in known]
    if do_probe:
        reports = [probe(r, baud) for r in reports]
    return reports

