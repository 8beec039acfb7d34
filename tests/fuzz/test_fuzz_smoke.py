"""The fuzz harnesses in `make test` (fuzz/README.md): built with clang under ASan + UBSan, the hand-made
seeds and the inputs of past findings (fuzz/corpus/*/seed-*, regress-*) run once, then a few seconds of
fuzzing each from them (the whole corpus, grown by campaigns, is `make fuzz`'s: minutes to replay).
Any crash, sanitizer report or broken check fails the test and names the input that did it; the long
campaign is `make bench-fuzz`."""

import importlib.util
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SMOKE_SECONDS = 4

_spec = importlib.util.spec_from_file_location("wm_fuzz_run", ROOT / "fuzz" / "run.py")
fuzz_run = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fuzz_run)


@pytest.fixture(scope="module")
def built():
    if shutil.which(fuzz_run.CLANG) is None:
        pytest.fail("clang is missing: run `make setup` (tools/debian-packages.txt: clang, libclang-rt-dev)")
    fuzz_run.build()


def _report(results) -> str:
    return "; ".join(f"{r['target']}: {r['crashes']} crashes {r['findings']} (log {r['log']})"
                     for r in results)


def test_corpus_replays_clean(built):
    """Every seed and past finding once (libFuzzer -runs=0): no finding comes back."""
    results = fuzz_run.run(list(fuzz_run.TARGETS), None, None, ["-runs=0"], seeds_only=True)
    assert all(r["crashes"] == 0 and r["exit"] == 0 for r in results), _report(results)
    for r in results:
        stored = len(list((ROOT / "fuzz" / "corpus" / r["target"]).iterdir()))
        assert stored > 0, f"no corpus for {r['target']}"
        assert r["execs"] >= 1, f"{r['target']} ran nothing"


def test_fuzz_seconds(built):
    """A few seconds of fuzzing per harness, side by side: executions happen, nothing crashes."""
    results = fuzz_run.run(list(fuzz_run.TARGETS), SMOKE_SECONDS, None, [], seeds_only=True)
    assert all(r["crashes"] == 0 for r in results), _report(results)
    assert all(r["execs"] > 0 and r["cov"] > 0 for r in results), results
