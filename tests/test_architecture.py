"""The layout of docs/architecture.md holds: imports run one way, and no module or function grows past its size.

The layers, bottom to top, are those of docs/architecture.md; a module may import its own layer
and those below it, never one above (an import only for type checking counts too: the house is
read from its imports).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).parents[1] / "egnc"

LAYERS = (
    ("errors", "_moved", "lie"),
    ("graph",),
    ("linalg",),
    ("nonlinear",),
    ("io",),
    ("metrics",),
    ("robust",),
    ("api",),
    ("interop",),
    ("online",),
    ("plot", "rerun", "datasets"),
    ("bench",),
    ("cli",),
    ("__init__", "__main__"),
)
"""docs/architecture.md's layers, bottom first: top-level modules and packages of `egnc`."""

MAX_MODULE_LINES = 620
MAX_FUNCTION_LINES = 85
"""docs/development.md: no module over about 600 lines, no function over about 80 (docstring included)."""


def _layer_of(dotted: str) -> int:
    """The layer index of `egnc.<dotted>` by its first component."""
    head = dotted.split(".")[0]
    for index, names in enumerate(LAYERS):
        if head in names:
            return index
    raise AssertionError(f"egnc.{head} is in no layer of docs/architecture.md")


def _modules() -> list[tuple[str, Path]]:
    """`(dotted name below egnc, path)` of every module of the package."""
    return [(".".join(path.relative_to(PACKAGE).with_suffix("").parts), path) for path in sorted(PACKAGE.rglob("*.py"))]


def _egnc_imports(path: Path) -> list[tuple[str, int]]:
    """`(dotted name below egnc, line)` of every `egnc.*` module a file imports."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("egnc.") and node.level == 0:
            found.append((node.module[len("egnc.") :], node.lineno))
        elif isinstance(node, ast.Import):
            names = [alias.name for alias in node.names if alias.name.startswith("egnc.")]
            found += [(name[len("egnc.") :], node.lineno) for name in names]
    return found


def test_every_import_points_to_its_own_layer_or_below():
    upward = []
    for name, path in _modules():
        own = _layer_of(name)
        upward += [
            f"egnc.{name}:{line} imports egnc.{target}"
            for target, line in _egnc_imports(path)
            if _layer_of(target) > own
        ]
    assert upward == []


def test_no_module_imports_itself_back_through_another():
    graph = {name: {target for target, _ in _egnc_imports(path)} for name, path in _modules()}
    modules = set(graph)

    def resolved(target: str) -> str | None:
        """The module an import names (a package's `__init__` for a package)."""
        if target in modules:
            return target
        return f"{target}.__init__" if f"{target}.__init__" in modules else None

    edges = {name: {t for t in map(resolved, targets) if t and t != name} for name, targets in graph.items()}
    state: dict[str, int] = {}
    cycle: list[str] = []

    def visit(node: str, trail: list[str]) -> bool:
        state[node] = 1
        for nxt in sorted(edges[node]):
            if state.get(nxt) == 1:
                cycle.extend(trail[trail.index(nxt) :] + [node, nxt] if nxt in trail else [node, nxt])
                return True
            if nxt not in state and visit(nxt, trail + [node]):
                return True
        state[node] = 2
        return False

    assert not any(visit(name, []) for name in sorted(edges) if name not in state), " -> ".join(cycle)


@pytest.mark.parametrize(("name", "path"), _modules(), ids=[name for name, _ in _modules()])
def test_modules_and_functions_stay_small(name, path):
    text = path.read_text()
    assert text.count("\n") <= MAX_MODULE_LINES, f"egnc.{name} has {text.count(chr(10))} lines"
    long = [
        f"{node.name} ({node.end_lineno - node.lineno + 1} lines)"
        for node in ast.walk(ast.parse(text))
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
        and node.end_lineno is not None
        and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES
    ]
    assert long == [], f"egnc.{name}: {', '.join(long)}"
