"""A device program under test (the simulated board wmsim, the native stand-in wmdev): started as a
process, its output lines collected, its TCP port read from its "listening on 127.0.0.1:PORT" line.
"""

from __future__ import annotations

import re
import subprocess
import threading
import time

START_TIMEOUT = 10.0  # s for a device to say it is listening
EXIT_TIMEOUT = 30.0  # s for it to finish after its client left or it was asked to stop


class DeviceProcess:
    """A running device: its URL (when it listens) and everything it printed."""

    name = "device"

    def __init__(self, cmd: list[str], listen: bool = True, start_timeout: float = START_TIMEOUT):
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.lines: list[str] = []
        self._listening = threading.Event()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self.port = None
        if listen:
            if not self._listening.wait(start_timeout):
                self.stop()
                raise AssertionError(f"{self.name} did not start listening:\n" + "\n".join(self.lines))
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

    def alive(self) -> bool:
        return self.proc.poll() is None

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

    def wait_for_line(self, text: str, timeout: float = EXIT_TIMEOUT) -> None:
        deadline = time.monotonic() + timeout
        while not any(text in ln for ln in self.lines):
            if time.monotonic() > deadline:
                raise AssertionError(f"no '{text}' from {self.name}:\n" + "\n".join(self.lines))
            time.sleep(0.01)
