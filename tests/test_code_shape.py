"""The shape of the code a newcomer reads: no import cycles, every module of evo in a
layer, no very long functions.

The layers themselves are import-linter's contracts in ``pyproject.toml``
(``lint-imports``, run by ``make test``); here, that every module of evo is in one.

Imports are read from the source (``ast``), at any depth (an import inside a function
is still a dependency), leaving out ``if TYPE_CHECKING:`` blocks, which never run.
``from package import name`` depends on ``package.name`` when that is a module, else on
``package``.
"""

from __future__ import annotations

import ast
import tomllib
from pathlib import Path

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("evo", "analysis")
LONGEST = 60
"""Lines of the longest function allowed (docstring included)."""


def modules() -> dict[str, Path]:
    """Every module of the packages, by dotted name."""
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


def _type_checking_only(node: ast.AST) -> bool:
    return (isinstance(node, ast.If) and isinstance(node.test, ast.Name)
            and node.test.id == "TYPE_CHECKING")


def imports(path: Path, name: str, known: dict[str, Path]) -> set[str]:
    """The modules of ``known`` that module ``name`` (at ``path``) imports."""
    tree = ast.parse(path.read_text())
    skipped = {id(n) for block in ast.walk(tree) if _type_checking_only(block)
               for n in ast.walk(block)}
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    targets = set()
    for node in ast.walk(tree):
        if id(node) in skipped:
            continue
        if isinstance(node, ast.Import):
            targets |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                base = f"{anchor}.{base}" if base else anchor
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                targets.add(sub if sub in known else base)
    return {t for t in targets if t in known and t != name}


def import_cycles() -> list[list[str]]:
    """Groups of modules that import each other, directly or through others."""
    known = modules()
    names = list(known)
    index = {n: i for i, n in enumerate(names)}
    edges = [(index[a], index[b]) for a in names for b in imports(known[a], a, known)]
    rows, cols = zip(*edges, strict=True) if edges else ((), ())
    graph = csr_matrix((np.ones(len(edges)), (rows, cols)), shape=(len(names),) * 2)
    _, labels = connected_components(graph, directed=True, connection="strong")
    groups = [[names[i] for i in np.flatnonzero(labels == label)] for label in set(labels)]
    return sorted(sorted(g) for g in groups if len(g) > 1)


def layers() -> list[str]:
    """The modules and packages named by the layers contract of ``pyproject.toml``."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    (contract,) = [c for c in config["contracts"] if c.get("id") == "layers"]
    return [name.strip() for layer in contract["layers"] for name in layer.split("|")]


def outside_layers() -> list[str]:
    """The modules of evo that no layer holds (a package whose ``__init__`` imports
    nothing, like ``evo.components``, is only a folder: its modules are placed one by one)."""
    named, known = layers(), modules()
    return [m for m, path in known.items() if m.startswith("evo.")
            and not any(m == n or m.startswith(f"{n}.") for n in named)
            and not (path.name == "__init__.py" and not imports(path, m, known))]


def long_functions(limit: int = LONGEST) -> list[tuple[int, str]]:
    """(lines, module:function) of every function longer than ``limit`` lines."""
    found = []
    for name, path in modules().items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                lines = (node.end_lineno or node.lineno) - node.lineno + 1
                if lines > limit:
                    found.append((lines, f"{name}:{node.name}"))
    return sorted(found, reverse=True)


def test_the_import_graph_finds_a_cycle_it_is_shown(tmp_path: Path) -> None:
    a, b = tmp_path / "a.py", tmp_path / "b.py"
    a.write_text("from pkg import b\n")
    b.write_text("def f():\n    import pkg.a\n")
    known = {"pkg.a": a, "pkg.b": b}
    assert imports(a, "pkg.a", known) == {"pkg.b"} and imports(b, "pkg.b", known) == {"pkg.a"}
    b.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import pkg.a\n")
    assert imports(b, "pkg.b", known) == set()


def test_no_module_imports_itself_through_others() -> None:
    assert import_cycles() == []


def test_every_module_of_evo_is_in_a_layer() -> None:
    assert "evo.robot" in layers() and "evo.robot.gallery" not in outside_layers()
    assert outside_layers() == [], "place them in pyproject.toml's [tool.importlinter] layers"


def test_no_function_is_longer_than_a_screen() -> None:
    assert long_functions() == []
