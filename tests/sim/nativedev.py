"""The native stand-in device for tests: building wmdev (firmware/board/native) and running it.

``build_wmdev()`` configures and builds it with CMake into build/native-device (or, with
``sanitize=True``, build/native-device-asan: AddressSanitizer and UndefinedBehaviorSanitizer);
``NativeDevice`` runs one wmdev process on a free port and collects its output lines.
"""

from __future__ import annotations

import fcntl
import re
import subprocess
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SOURCE = ROOT / "firmware" / "board" / "native"
START_TIMEOUT = 10.0  # s for wmdev to say it is listening


def build_wmdev(sanitize: bool = False) -> Path:
    """Build wmdev (once per tree; cmake --build is a no-op when nothing changed); returns its path."""
    from wavemesh.gen import write_all

    gen = ROOT / "build" / "gen"
    write_all(gen)
    out = ROOT / "build" / ("native-device-asan" if sanitize else "native-device")
    out.mkdir(parents=True, exist_ok=True)
    with open(out / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            steps = []
            if not (out / "CMakeCache.txt").exists():
                steps.append(["cmake", "-S", str(SOURCE), "-B", str(out), f"-DWM_GEN_DIR={gen}",
                              f"-DCMAKE_BUILD_TYPE={'Debug' if sanitize else 'Release'}",
                              f"-DWM_SANITIZE={'ON' if sanitize else 'OFF'}"])
            steps.append(["cmake", "--build", str(out), "-j2", "--target", "wmdev"])
            for cmd in steps:
                r = subprocess.run(cmd, capture_output=True, text=True)
                if r.returncode != 0:
                    tail = r.stdout[-3000:] + r.stderr[-3000:]
                    raise RuntimeError(f"building wmdev failed: {' '.join(cmd)}\n{tail}")
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)
    return out / "wmdev"


class NativeDevice:
    """A running wmdev: its URL and everything it printed."""

    def __init__(self, exe: Path, *args: str):
        self.proc = subprocess.Popen([str(exe), "--port", "0", *args], stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True)
        self.lines: list[str] = []
        self._listening = threading.Event()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        if not self._listening.wait(START_TIMEOUT):
            self.stop()
            raise AssertionError("wmdev did not start listening:\n" + "\n".join(self.lines))
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

    def wait_for_line(self, text: str, timeout: float = 10.0) -> None:
        deadline = time.monotonic() + timeout
        while not any(text in ln for ln in self.lines):
            if time.monotonic() > deadline:
                raise AssertionError(f"no '{text}' from wmdev:\n" + "\n".join(self.lines))
            time.sleep(0.01)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._reader.join(5)
