"""Fixtures of the firmware tests: the native library, and the C test programs in two builds."""

from pathlib import Path

import pytest
from wavemesh import native

ROOT = Path(__file__).resolve().parents[2]
# Debug (WM_CHECK: asserts and the invariant check after every operator) with AddressSanitizer and
# UndefinedBehaviorSanitizer.
CHECK_BUILD = ROOT / "build" / "firmware-check"


@pytest.fixture(scope="session")
def lib():
    return native.load()


@pytest.fixture(scope="session")
def release_build():
    """build/firmware-native with the C test programs (the library the host loads lives there too)."""
    return native.build(targets=("wavemesh_shared", "wm_unit", "wm_run"))


@pytest.fixture(scope="session")
def check_build():
    """build/firmware-check: Debug + WM_CHECK + ASan + UBSan."""
    return native.build(CHECK_BUILD, "Debug", ("-DWM_SANITIZE=ON",), targets=("wm_unit", "wm_run"))
