"""The C unit tests (tests/firmware/wm_unit.c): tiny hand-built meshes for every operator, the exact
helpers, E(T), the filter bank, small refinements; in the release build and in the checking build
(asserts, the invariant check after every operator, AddressSanitizer, UndefinedBehaviorSanitizer)."""

import re
import subprocess

import pytest


@pytest.mark.parametrize("build", ["release_build", "check_build"])
def test_c_unit_tests(build, request):
    exe = request.getfixturevalue(build) / "wm_unit"
    r = subprocess.run([str(exe)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    m = re.search(r"^(\d+) passed, 0 failed$", r.stdout, re.M)
    assert m and int(m.group(1)) > 100, r.stdout
    assert "runtime error" not in r.stderr and "Sanitizer" not in r.stderr, r.stderr
