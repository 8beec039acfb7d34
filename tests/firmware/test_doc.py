"""docs/refiner.md is what firmware/tools/make_refiner_doc.py writes today (run times aside)."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_refiner_doc_is_current():
    r = subprocess.run([sys.executable, str(ROOT / "firmware" / "tools" / "make_refiner_doc.py"), "--check"],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
