"""The package layout's rules, read from the source: estimators never imports twin, no import circle, modules short
enough to read."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("estimators", "twin")
MAX_LINES = 400
DECLARATIVE = {"estimators/io/logformat.py"}
"""Tables that are longer by nature: the log schema, one Column per line."""


def modules() -> dict[str, Path]:
    found = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


def _walk_runtime(node: ast.AST):
    """Every node of the tree except what sits under `if TYPE_CHECKING:` (annotations only, never imported)."""
    for child in ast.iter_child_nodes(node):
        if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
            continue
        yield child
        yield from _walk_runtime(child)


def imports(path: Path, known: dict[str, Path], top_level_only: bool) -> set[str]:
    """Project modules `path` imports (at module level only, or anywhere)."""
    tree = ast.parse(path.read_text())
    nodes = tree.body if top_level_only else _walk_runtime(tree)
    out = set()
    for node in nodes:
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [f"{node.module}.{a.name}" for a in node.names] + [node.module]
        else:
            continue
        out |= {n for n in names if n in known}
    return out


def test_estimators_never_imports_twin():
    known = modules()
    offenders = {name: sorted(m for m in imports(path, known, top_level_only=False) if m.startswith("twin"))
                 for name, path in known.items() if name.startswith("estimators")}
    assert not {k: v for k, v in offenders.items() if v}


def test_no_import_circle():
    """Module-level imports between the project's modules form no cycle (a function-level import is how a
    module reaches a heavy or optional dependency late, not a way around a cycle, so those count too)."""
    known = modules()
    graph = {name: imports(path, known, top_level_only=False) - {name} for name, path in known.items()}
    graph = {name: {m for m in deps if not name.startswith(m + ".")} for name, deps in graph.items()}  # a package's own __init__
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for dep in sorted(graph[node]):
            if state.get(dep) == 1:
                return stack[stack.index(dep):] + [dep]
            if dep not in state and (cycle := visit(dep)):
                return cycle
        stack.pop()
        state[node] = 2
        return None

    for name in sorted(graph):
        if name not in state:
            cycle = visit(name)
            assert cycle is None, " -> ".join(cycle)


@pytest.mark.parametrize("name", sorted(modules()))
def test_module_is_short_enough_to_read(name):
    path = modules()[name]
    rel = str(path.relative_to(ROOT))
    lines = len(path.read_text().splitlines())
    assert rel in DECLARATIVE or lines <= MAX_LINES, f"{rel}: {lines} lines (split it by what it holds)"
