"""Fixtures of the firmware tests: the native library, and the C test programs in two builds."""

from pathlib import Path

import pytest
from wavemesh.refine import native

ROOT = Path(__file__).resolve().parents[2]
# Debug (WM_CHECK: asserts and the invariant check after every operator) with AddressSanitizer and
# UndefinedBehaviorSanitizer, and 16-bit indices as on the board: the tests that compare its meshes with
# the release library's (32-bit indices) also prove the two index widths give the same mesh, and the
# legalisation's path past its list of slots (a list of 4 in checked builds, mesh_state.c) the same as
# the list's.
CHECK_BUILD = ROOT / "build" / "firmware-check16"


@pytest.fixture(scope="session")
def lib():
    return native.load()


@pytest.fixture(scope="session")
def release_build():
    """build/firmware-native with the C test programs (the library the host loads lives there too)."""
    return native.build(targets=("wavemesh_shared", "wm_unit", "wm_run"))


@pytest.fixture(scope="session")
def check_build():
    """build/firmware-check16: Debug + WM_CHECK + ASan + UBSan + 16-bit indices."""
    return native.build(CHECK_BUILD, "Debug", ("-DWM_SANITIZE=ON", "-DWM_INDEX_BITS=16"),
                        targets=("wm_unit", "wm_run"))
