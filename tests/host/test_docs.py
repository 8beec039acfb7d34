"""The generated parts of docs/ are what `make docs` writes today (no stale numbers in the docs)."""

import importlib.util
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def load_make_docs():
    spec = importlib.util.spec_from_file_location("make_docs", ROOT / "tools" / "make_docs.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("name", ["templates.md", "initial-results.md"])
def test_generated_docs_are_current(name):
    mod = load_make_docs()
    committed = (ROOT / "docs" / name).read_text()
    assert committed == mod.GENERATED[name](), f"docs/{name} is stale: run `make docs`"
    for picture in ("templates.png", "forms.png"):
        assert (ROOT / "docs" / picture).exists(), "run `make docs`"


# --- The docs are manuals: no commit hashes, no issue numbers, a README that is a front door ---------------
#
# A commit hash, as these docs would write one, is a lower-case hex word of 7 to 40 characters with at least
# one letter a-f and at least one digit ("4f604f2", "00da38b-dirty"), standing alone: not after "0x" or "#"
# (register values, CRC constants such as 0xedb88320, colours such as #1f77b4), not inside a longer word or
# a path or file name (the neighbouring characters are not letters, digits, "_", ".", "/" or "-" before
# it).  Numbers (all digits), words of a-f alone ("deadbeef", "faded"), hex runs longer than 40 (a sha256
# digest) and upper-case hex ("CAFE1234") are not hashes.  docs/benchmarks.md may name the commit it
# measured; nothing else may.  "issue N" (issue 12, issues 10, Issue #3) names a tracker the reader does
# not have: nowhere.
COMMIT_HASH = re.compile(r"(?<![0-9A-Za-z_#./-])(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}"
                         r"(?![0-9A-Za-z_])")
ISSUE_NUMBER = re.compile(r"\bissues?\s+#?\d+", re.IGNORECASE)
README_LIMIT = 12_000  # bytes: a front door; the details live in docs/*.md


def manuals():
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), *sorted(ROOT.glob("*/README.md"))]


def test_the_rules_catch_what_they_mean():
    hashes = "built on 57e3c63 (then 00da38b-dirty, 0b9bdb3): a1f40e1d2c3b4a5f6e7d8c9b0a1f2e3d4c5b6a7f"
    assert COMMIT_HASH.findall(hashes) == ["57e3c63", "00da38b", "0b9bdb3",
                                           "a1f40e1d2c3b4a5f6e7d8c9b0a1f2e3d4c5b6a7f"]
    for fine in ("0xedb88320", "#1f77b4", "1048576", "deadbeef", "build/1a2b3c4d/x", "wm_3a4b5c6d",
                 "abc1234x", "decade", "a1b2c3", "CAFE1234", "9f86d081884c7d659a2feaa0c55ad015"
                 "a3bf4f1b2b0b822cd15d6c15b0f00a08"):  # the last: a sha256 digest, longer than 40
        assert not COMMIT_HASH.search(fine), fine
    found = ISSUE_NUMBER.findall("issue 14's bar; (issues 10, 11); Issue #3")
    assert found == ["issue 14", "issues 10", "Issue #3"]
    assert not ISSUE_NUMBER.search("an issue with 3 parts; the tissue 4")


@pytest.mark.parametrize("path", manuals(), ids=lambda p: str(p.relative_to(ROOT)))
def test_manuals_name_no_commits_or_issues(path):
    text = path.read_text()

    def where(m):
        return f"{path.relative_to(ROOT)}:{text.count(chr(10), 0, m.start()) + 1}: {m.group()!r}"

    issues = [where(m) for m in ISSUE_NUMBER.finditer(text)]
    assert not issues, "say what the requirement is, not which issue asked for it:\n" + "\n".join(issues)
    if path.name != "benchmarks.md":
        commits = [where(m) for m in COMMIT_HASH.finditer(text)]
        assert not commits, ("a manual states what is true now; git log has the history (only "
                             "docs/benchmarks.md names the commit it measured):\n" + "\n".join(commits))


def test_readme_is_a_front_door():
    size = len((ROOT / "README.md").read_bytes())
    assert size < README_LIMIT, f"README.md is {size} bytes (limit {README_LIMIT}): move details to docs/*.md"
