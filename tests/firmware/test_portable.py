"""The firmware core is C99, freestanding, integer-only, and builds for the soft CPU (rv32im).

- Every source compiles with the RISC-V cross compiler for rv32im/ilp32 (no FPU), -ffreestanding,
  -std=c99 and the warnings as errors; the objects call no soft-float helper (__adddf3, __floatsidf, ...).
- No source includes a header beyond <stdint.h>, <stddef.h> and the firmware's own (the generated wm_angle.h
  among them; assert.h only in the checking build), and none names float or double.
"""

import re
import shutil
import subprocess
from pathlib import Path

import pytest
from wavemesh.device import gen

ROOT = Path(__file__).resolve().parents[2]
SRC = ROOT / "firmware" / "src"
CROSS = "riscv64-unknown-elf-gcc"
WARN = ["-Wall", "-Wextra", "-Wpedantic", "-Wshadow", "-Wstrict-prototypes", "-Wmissing-prototypes",
        "-Wdouble-promotion", "-Wvla", "-Werror"]
SOFT_FLOAT = re.compile(r"__\w*(sf|df|tf)\d?$|__(fix|float)\w+")


def sources():
    return sorted(SRC.glob("*.c"))


def test_only_freestanding_headers():
    allowed = {"wavemesh.h", "wm_internal.h", "wm_inline.h", "wm_angle.h", "stdint.h", "stddef.h", "assert.h"}
    include = ROOT / "firmware" / "include"
    for path in sources() + sorted(SRC.glob("*.h")) + [include / "wavemesh.h", include / "wm_inline.h"]:
        text = path.read_text()
        for inc in re.findall(r'#\s*include\s*[<"]([^>"]+)[>"]', text):
            assert inc in allowed, f"{path.name} includes {inc}"
        code = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
        assert not re.search(r"\b(float|double)\b", code), f"{path.name} names a floating-point type"


@pytest.mark.skipif(shutil.which(CROSS) is None,
                    reason=f"{CROSS} is not installed (Debian gcc-riscv64-unknown-elf)")
@pytest.mark.parametrize("opt", ["-O2", "-Os"])
def test_builds_for_rv32im_without_float(tmp_path, opt):
    objs = []
    gen.write_all(tmp_path / "gen")  # fixed.c's wm_angle.h
    for src in sources():
        obj = tmp_path / (src.stem + ".o")
        r = subprocess.run([CROSS, "-march=rv32im", "-mabi=ilp32", "-ffreestanding", "-std=c99", opt, *WARN,
                            "-I", str(ROOT / "firmware" / "include"), "-I", str(tmp_path / "gen"),
                            "-c", str(src), "-o", str(obj)],
                           capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        objs.append(obj)
    nm = shutil.which("riscv64-unknown-elf-nm")
    if nm is None:
        pytest.skip("riscv64-unknown-elf-nm is not installed")
    core = tmp_path / "core.o"  # one relocatable object: what the core needs from outside
    subprocess.run([CROSS, "-march=rv32im", "-mabi=ilp32", "-nostdlib", "-r", "-o", str(core), *map(str,
                                                                                                    objs)],
                   check=True)
    r = subprocess.run([nm, "-u", str(core)], capture_output=True, text=True, check=True)
    undefined = {line.split()[-1] for line in r.stdout.splitlines()
                 if line.strip() and not line.endswith(":")}
    floats = sorted(s for s in undefined if SOFT_FLOAT.search(s))
    assert not floats, f"soft-float helpers called: {floats}"
    # what the core may need: libgcc's 64-bit integer helpers, and memcpy / memset (GCC emits them
    # for struct copies; every freestanding environment provides them)
    int_helpers = re.compile(r"^__(u?(div|mod)|mul|ashl|ashr|lshr|clz|ctz|popcount|bswap|cmp|ucmp)[sd]i\d$")
    other = {s for s in undefined if not int_helpers.match(s)}
    assert other <= {"memcpy", "memset"}, other
