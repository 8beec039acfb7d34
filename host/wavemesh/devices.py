"""`wavemesh devices`: the serial ports this machine has, and which of them a wavemesh device answers on.

Every port pyserial's ``list_ports`` finds (plus any URL given with ``--port``, e.g. the simulated
board's ``socket://127.0.0.1:7720``) is opened and sent HELLO, as ``wavemesh stream`` does before a job
(:meth:`wavemesh.stream.Device.sync`), with a short timeout; a port that answers is listed with the
capabilities its HELLO_REPLY states.  A port that cannot be opened (busy, no permission) is listed with
the reason.  A port that does not answer HELLO is asked once more in the byte stream of the
iCEBreaker's FPGA stage (docs/boards.md, "The iCEBreaker's stream": a header with W = 0, which the
stage refuses with "EW" and forgets).  HELLO ends whatever session the device had, so nothing is lost on
a wavemesh device; on another kind of device the probe writes two short messages, as esptool's sync
does (``--no-probe`` only lists).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from wavemesh.errors import WavemeshError

# one HELLO, answered within half a second, twice: a board answers in a few milliseconds
PROBE_SYNC_S = 0.5
PROBE_ATTEMPTS = 2
# the FPGA stage's refusal of a header with W = H = M = 0 (rtl/boards/stage_uart.v)
STAGE_PROBE = b"WM" + bytes(8)
STAGE_REFUSAL = b"EW"
STAGE_SILENCE_S = 0.8  # past the stage's silence timeout (0.7 s): a header it was in the middle of is gone


@dataclass
class PortReport:
    """One port: what pyserial says of it, and what (if anything) answered HELLO there."""

    url: str
    description: str = ""
    hwid: str = ""
    answer: str = ""  # the device's summary (DeviceInfo.summary) when it answered
    info: dict | None = None  # its HELLO_REPLY (DeviceInfo.to_report)
    stage: bool = False  # the iCEBreaker's FPGA stage answered its byte stream (no HELLO)
    problem: str = ""  # why it could not be asked, or that nothing answered

    @property
    def answered(self) -> bool:
        return self.info is not None

    def line(self) -> str:
        shown = self.description and self.description != "n/a"
        head = self.url + (f"  ({self.description})" if shown else "")
        if self.answered:
            return f"{head}: wavemesh device: {self.answer}"
        if self.stage:
            return f"{head}: wavemesh FPGA stage (no HELLO: the iCEBreaker's byte stream, docs/boards.md)"
        return f"{head}: {self.problem or 'not probed'}"


def list_ports() -> list[PortReport]:
    """The serial ports pyserial finds, sorted by name (none on a machine without any)."""
    from serial.tools import list_ports as lp

    return [PortReport(p.device, p.description or "", p.hwid or "") for p in sorted(lp.comports())]


def probe(report: PortReport, baud: int = 115200) -> PortReport:
    """Send HELLO on `report.url`; fill in the answer or the problem."""
    from wavemesh.stream import DEFAULT_TIMEOUTS, Device

    timeouts = replace(DEFAULT_TIMEOUTS, sync=PROBE_SYNC_S, sync_attempts=PROBE_ATTEMPTS)
    try:
        with Device(report.url, baud, timeouts=timeouts) as dev:
            info = dev.sync()
    except WavemeshError as e:
        msg = e.message
        if not msg.startswith("no device answers"):
            report.problem = msg
            return report
        report.problem = "no HELLO answer"
        report.stage = probe_stage(report.url, baud)
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


def probe_stage(url: str, baud: int = 115200, attempts: int = 2) -> bool:
    """True when the iCEBreaker's FPGA stage answers on `url`: it refuses a header of zeros with "EW"."""
    import time

    from wavemesh.link import open_port

    try:
        port = open_port(url, baud)
    except WavemeshError:
        return False
    try:
        for k in range(attempts):
            if k:
                time.sleep(STAGE_SILENCE_S)
            port.reset_input_buffer()
            port.write(STAGE_PROBE)
            got, deadline = b"", time.monotonic() + PROBE_SYNC_S
            while time.monotonic() < deadline and STAGE_REFUSAL not in got:
                got += port.read(64)
                time.sleep(0.01)
            if STAGE_REFUSAL in got:
                return True
        return False
    except OSError:
        return False
    finally:
        port.close()
