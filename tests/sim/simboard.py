"""The simulated board for tests: building it (sim/build.py) and running wmsim processes.

``build`` is sim/build.py as a module (``build_sim()``, ``build_firmware()``); ``SimBoard`` runs one
simulator and collects its log lines.
"""

from __future__ import annotations

import importlib.util
import re
import subprocess
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
START_TIMEOUT = 10.0  # s for the simulator to say it is listening
EXIT_TIMEOUT = 30.0  # s for it to finish after its client left or it was asked to stop


def _load_sim_build():
    spec = importlib.util.spec_from_file_location("wm_sim_build", ROOT / "sim" / "build.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


build = _load_sim_build()


class SimBoard:
    """A running wmsim process: its URL and everything it printed."""

    def __init__(self, exe: Path, firmware: Path, *args: str):
        self.proc = subprocess.Popen([str(exe), "--firmware", str(firmware), *args], stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True)
        self.lines: list[str] = []
        self._listening = threading.Event()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self.port = None
        if "--no-socket" not in args:
            if not self._listening.wait(START_TIMEOUT):
                self.stop()
                raise AssertionError("the simulator did not start listening:\n" + "\n".join(self.lines))
            m = re.search(r"listening on 127\.0\.0\.1:(\d+)", "\n".join(self.lines))
            self.port = int(m.group(1))

    def _read(self):
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))
            if "listening on" in line:
                self._listening.set()

    @property
    def url(self) -> str:
        return f"socket://127.0.0.1:{self.port}"

    def wait(self, timeout: float = EXIT_TIMEOUT) -> int:
        rc = self.proc.wait(timeout)
        self._reader.join(5)
        return rc

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(EXIT_TIMEOUT)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._reader.join(5)

    def events(self, kind: str) -> list[tuple[int, int]]:
        """(value, cycle) of every `wmsim: KIND 0xVALUE cycle N` line (stage, leds, halt)."""
        out = []
        for line in self.lines:
            m = re.match(rf"wmsim: {kind} 0x([0-9a-f]+) cycle (\d+)", line)
            if m:
                out.append((int(m.group(1), 16), int(m.group(2))))
        return out

    def wait_for_line(self, text: str, timeout: float = EXIT_TIMEOUT) -> None:
        deadline = time.monotonic() + timeout
        while not any(text in ln for ln in self.lines):
            if time.monotonic() > deadline:
                raise AssertionError(f"no '{text}' from the simulator:\n" + "\n".join(self.lines))
            time.sleep(0.02)
