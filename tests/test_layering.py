"""The package's layering: the dependency order written in the README is the real one.

Every module under ``simulator/`` (outside ``commands/``, ``cli`` and ``__main__``) may
import only modules of earlier layers or of its own stage package, at module level (no
in-package imports inside functions), opens with a one-sentence docstring, and stays
near 500 lines.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PKG = REPO / "simulator"
FRONT = {"cli", "commands", "__main__"}  # the CLI: may import anything, lazily
FACES = {"headpath", "grf"}  # thin faces of traces/ and mitigation/ for the design's names
MAX_LINES = 520


def _readme_layers() -> list[str]:
    """The layer chain as the README's Development section writes it (`a` -> `b` -> ...)."""
    text = (REPO / "README.md").read_text()
    m = re.search(r"Dependency order[^\n]*\n+((?:.+\n)+?)\n", text)
    assert m, "README: no 'Dependency order' paragraph"
    return re.findall(r"`([a-z_]+)`", m.group(1))


def _modules():
    for p in sorted(PKG.rglob("*.py")):
        rel = p.relative_to(PKG)
        if rel.parts[0] in FRONT or rel.parts[0].removesuffix(".py") in FRONT | FACES:
            continue
        if rel == Path("__init__.py"):
            continue
        yield p, rel.parts[0].removesuffix(".py")


def _simulator_imports(tree: ast.AST):
    """``(node, top-level simulator module)`` of every in-package import."""
    for n in ast.walk(tree):
        if isinstance(n, ast.ImportFrom) and n.module and n.module.startswith("simulator"):
            parts = n.module.split(".")
            if len(parts) == 1:  # from simulator import x: a module, or the root's __version__
                for a in n.names:
                    if (PKG / a.name).is_dir() or (PKG / f"{a.name}.py").is_file():
                        yield n, a.name
                    else:
                        yield n, "core"  # the root package imports core only
            else:
                yield n, parts[1]
        elif isinstance(n, ast.Import):
            for a in n.names:
                if a.name.startswith("simulator."):
                    yield n, a.name.split(".")[1]


def test_readme_chain_names_every_module():
    layers = _readme_layers()
    tops = {top for _, top in _modules()}
    assert sorted(tops - set(layers)) == []
    assert sorted(set(layers) - tops - FRONT) == []


def test_every_module_sits_in_a_layer_folder():
    """Only the root, the CLI, the demo and the two thin faces sit at the top of the package."""
    flat = sorted(p.stem for p in PKG.glob("*.py"))
    assert flat == sorted({"__init__", "__main__", "cli", "demo"} | FACES)


def test_the_library_never_imports_a_face():
    bad = []
    for p, _top in _modules():
        for node, dep in _simulator_imports(ast.parse(p.read_text())):
            if dep in FACES:
                bad.append(f"{p.relative_to(REPO)}:{node.lineno} imports {dep}")
    assert bad == []


def test_imports_follow_the_dependency_order():
    layers = _readme_layers()
    rank = {name: i for i, name in enumerate(layers)}
    bad = []
    for p, top in _modules():
        for node, dep in _simulator_imports(ast.parse(p.read_text())):
            if dep == top:
                continue
            if dep not in rank or rank[dep] >= rank[top]:
                bad.append(f"{p.relative_to(REPO)}:{node.lineno} imports {dep}")
    assert bad == []


def test_no_function_level_package_imports_outside_the_cli():
    bad = []
    for p, _top in _modules():
        tree = ast.parse(p.read_text())
        top_level = set(map(id, tree.body))
        for node, dep in _simulator_imports(tree):
            if id(node) not in top_level:
                bad.append(f"{p.relative_to(REPO)}:{node.lineno} imports {dep} inside a function")
    assert bad == []


@pytest.mark.parametrize("path", [p for p, _ in _modules()], ids=lambda p: str(p.relative_to(PKG)))
def test_module_opens_with_one_sentence_and_stays_small(path):
    text = path.read_text()
    doc = ast.get_docstring(ast.parse(text))
    assert doc, f"{path.name}: no module docstring"
    first = doc.split("\n\n")[0].replace("\n", " ")
    assert first.rstrip().endswith("."), (
        f"{path.name}: first paragraph is not a sentence: {first!r}"
    )
    n = text.count("\n")
    assert n <= MAX_LINES, f"{path.relative_to(REPO)} has {n} lines (limit {MAX_LINES})"


def test_library_is_quiet():
    """Only the CLI writes to the terminal: no print, sys.stderr or progress bar in the library."""
    bad = []
    for p, _top in _modules():
        tree = ast.parse(p.read_text())
        for n in ast.walk(tree):
            if isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id == "print":
                bad.append(f"{p.relative_to(REPO)}:{n.lineno} print()")
            if (
                isinstance(n, ast.Attribute)
                and n.attr in ("stderr", "stdout")
                and isinstance(n.value, ast.Name)
                and n.value.id == "sys"
            ):
                bad.append(f"{p.relative_to(REPO)}:{n.lineno} sys.{n.attr}")
            if isinstance(n, (ast.Import, ast.ImportFrom)):
                mods = [n.module] if isinstance(n, ast.ImportFrom) else [a.name for a in n.names]
                if any(m and m.split(".")[0] == "tqdm" for m in mods):
                    bad.append(f"{p.relative_to(REPO)}:{n.lineno} imports tqdm")
    assert bad == []


MAX_FUNCTION_LINES = 100
#: Library functions allowed over MAX_FUNCTION_LINES (none).
LONG_FUNCTIONS_ALLOWED: set[str] = set()


def _long_functions() -> dict[str, int]:
    """``{"folder/module.py:function": lines}`` of every library function (methods and
    nested functions included; ``commands/`` and ``cli`` excluded) over the limit."""
    out = {}
    for p in sorted(PKG.rglob("*.py")):
        rel = p.relative_to(PKG)
        if rel.parts[0] in FRONT or rel.parts[0].removesuffix(".py") in FRONT:
            continue
        for n in ast.walk(ast.parse(p.read_text())):
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = n.end_lineno - n.lineno + 1
                if lines > MAX_FUNCTION_LINES:
                    out[f"{rel.as_posix()}:{n.name}"] = lines
    return out


def test_no_library_function_over_100_lines():
    """Functions stay readable: none over 100 lines (docstring included) outside the CLI."""
    long = _long_functions()
    over = {k: v for k, v in long.items() if k not in LONG_FUNCTIONS_ALLOWED}
    assert not over, f"library functions over {MAX_FUNCTION_LINES} lines: {over}"
