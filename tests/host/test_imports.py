"""The import graph of host/wavemesh stays readable: no import cycle, and no import inside a function
without a reason beside it (a comment on its line: the measured start-up cost it saves, or the optional
dependency it waits for).  Read from the source with ast, so a hidden import cannot slip past."""

from __future__ import annotations

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parents[2] / "host" / "wavemesh"


def module_name(path: Path) -> str:
    parts = path.relative_to(PKG.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def sources() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(PKG.rglob("*.py"))}


def type_checking_nodes(tree: ast.AST) -> set[int]:
    """ids of the import nodes under ``if TYPE_CHECKING:`` (for the type checker only, never run)."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            out |= {id(n) for stmt in node.body for n in ast.walk(stmt)}
    return out


def imports(name: str, path: Path, known: set[str]) -> list[tuple[ast.stmt, set[str]]]:
    """Each import statement of the module and the wavemesh modules it names."""
    tree = ast.parse(path.read_text())
    skip = type_checking_nodes(tree)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = []
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        targets = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in known else mod for a in node.names]
        else:
            continue
        # the module named (a package's own __init__ that a submodule's import runs first is not counted:
        # a package that gathers its submodules' names is no cycle)
        out.append((node, set(targets) & known))
    return out


def graph() -> dict[str, set[str]]:
    src = sources()
    known = set(src)
    return {name: set().union(*(m for _, m in imports(name, path, known))) - {name}
            for name, path in src.items()}


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycle():
    edges = graph()
    assert "wavemesh.api" in edges and "wavemesh.refine.native" in edges["wavemesh.api"]  # the graph is read
    assert cycles(edges) == []


def test_the_cycle_finder_finds_one():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def function_level(path: Path) -> list[tuple[int, str]]:
    """(line, text) of each import inside a function with no reason beside it (a comment that is more
    than a linter's noqa)."""
    text = path.read_text()
    lines = text.split("\n")
    tree = ast.parse(text)
    out = []
    for fn in ast.walk(tree):
        if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        for node in ast.walk(fn):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                span = lines[node.lineno - 1:node.end_lineno]
                comments = [s.split("#", 1)[1].strip() for s in span if "#" in s]
                if not any(c and not c.startswith("noqa") for c in comments):
                    out.append((node.lineno, " ".join(s.strip() for s in span)))
    return out


def test_function_level_imports_say_why():
    bare = {str(p.relative_to(PKG)): found for p in sorted(PKG.rglob("*.py")) if (found := function_level(p))}
    assert bare == {}


def test_the_import_reader_sees_a_bare_function_import(tmp_path):
    p = tmp_path / "m.py"
    p.write_text("import os\n\ndef f():\n    import json\n    from x import y  # x is slow (12 ms)\n"
                 "    import z  # noqa: F401\n")
    assert [line for line, _ in function_level(p)] == [4, 6]


def test_the_command_collects_after_its_imports(tmp_path):
    """Run as the `wavemesh` command (a __main__ file of that name, as the console script), the package
    holds the collector while the command's imports are made and wavemesh.cli freezes them and turns it
    back on; imported by any other program it leaves the collector alone."""
    import subprocess
    import sys

    probe = "import gc\nfrom wavemesh.cli import main\nprint(gc.isenabled(), gc.get_freeze_count() > 10000)\n"
    for name, want in (("wavemesh", "True True"), ("other.py", "True False")):
        (tmp_path / name).write_text(probe)
        out = subprocess.run([sys.executable, str(tmp_path / name)], capture_output=True, text=True)
        assert out.stdout.split() == want.split(), (name, out.stderr[-500:])



def test_python_m_is_the_command(tmp_path):
    """`python -m wavemesh` and `python -m wavemesh.cli` are the command too (their __main__ is not set
    while the package is imported, so the interpreter's arguments, sys.orig_argv, say it):
    OPENBLAS_NUM_THREADS=1 unless the user set it; another `-m` module that imports the package, or a
    program that does, is left alone."""
    import os
    import subprocess
    import sys

    (tmp_path / "probe_m").mkdir()
    (tmp_path / "probe_m" / "__init__.py").write_text("")
    main = "import os, wavemesh\nprint(os.environ.get('OPENBLAS_NUM_THREADS'))\n"
    (tmp_path / "probe_m" / "__main__.py").write_text(main)
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    env["PYTHONPATH"] = os.pathsep.join([str(tmp_path), *sys.path])

    def blas(argv: list[str], as_m: str | None = None, **extra: str) -> str:
        """OPENBLAS_NUM_THREADS after the package's import; as_m: run as `python -m as_m` would set it."""
        fake = f"import sys; sys.orig_argv = [sys.executable, '-m', {as_m!r}]; " if as_m else ""
        probe = fake + "import os, wavemesh; print(os.environ.get('OPENBLAS_NUM_THREADS'))"
        cmd = argv or ["-c", probe]
        out = subprocess.run([sys.executable, *cmd], capture_output=True, text=True, env={**env, **extra})
        return out.stdout.strip() or out.stderr[-300:]

    assert blas([], as_m="wavemesh") == "1"
    assert blas([], as_m="wavemesh.cli") == "1"
    assert blas([], as_m="wavemesh", OPENBLAS_NUM_THREADS="4") == "4"  # the user's value kept
    assert blas([], as_m="wavemesh.io") == "None"
    assert blas(["-m", "probe_m"]) == "None"  # another module's run that imports the package
    assert blas([]) == "None"  # a program that imports it
