"""The generated parts of docs/ are what `make docs` writes today (no stale numbers in the docs)."""

import importlib.util
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
