"""The native stand-in device for the tests, the demo and the benchmarks: building wmdev
(firmware/board/native) and running it.

``build_wmdev()`` configures and builds it with CMake into build/native-device (or, with
``sanitize=True``, build/native-device-asan: AddressSanitizer and UndefinedBehaviorSanitizer);
``build_wmdev(target="wm_clocktest")`` builds the engine's accounting test program there too;
``NativeDevice`` runs one wmdev process on a free port and collects its output lines.
"""

from __future__ import annotations

import fcntl
import subprocess
from pathlib import Path

from wavemesh.device.gen import write_all
from wavemesh.harness.devproc import DeviceProcess

ROOT = Path(__file__).resolve().parents[3]
SOURCE = ROOT / "firmware" / "board" / "native"


def build_wmdev(sanitize: bool = False, target: str = "wmdev") -> Path:
    """Build wmdev, or another target of firmware/board/native (wm_clocktest), once per tree (cmake
    --build is a no-op when nothing changed); returns its path."""
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
            steps.append(["cmake", "--build", str(out), "-j2", "--target", target])
            for cmd in steps:
                r = subprocess.run(cmd, capture_output=True, text=True)
                if r.returncode != 0:
                    tail = r.stdout[-3000:] + r.stderr[-3000:]
                    raise RuntimeError(f"building {target} failed: {' '.join(cmd)}\n{tail}")
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)
    return out / target


class NativeDevice(DeviceProcess):
    """A running wmdev: its URL and everything it printed."""

    name = "wmdev"

    def __init__(self, exe: Path, *args: str):
        super().__init__([str(exe), "--port", "0", *args])
