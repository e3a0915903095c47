"""The package structure the architecture document draws: no import cycle between
packages, and the estimation packages never reach for I/O, the simulator or the apps.

Both walk the source (every import statement, also inside functions and under
TYPE_CHECKING), so an import added anywhere shows up here."""

from __future__ import annotations

import ast
import itertools
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import pytest

import roadpreview

SRC = Path(roadpreview.__file__).parent
#: the packages that estimate: they take typed samples and arrays, never files or buses
CORE = ("vision", "pitch", "fusion", "anomaly")
FORBIDDEN = (
    "can",
    "roadpreview.sim",
    "roadpreview.eval",
    "roadpreview.pipeline",
    "roadpreview.cli",
    "roadpreview.canbus",
    "roadpreview.sources",
    "roadpreview.sinks",
    "roadpreview.apps",
    "roadpreview.loop",
)


def _unit(module: str) -> str | None:
    """The top-level unit of a roadpreview module: a sub-package or a top-level module."""
    parts = module.split(".")
    if parts[0] != "roadpreview" or len(parts) < 2:
        return None
    return parts[1]


def _imports(path: Path) -> list[tuple[str, int]]:
    """Absolute module names imported by ``path`` (relative imports resolved), with lines."""
    rel = path.relative_to(SRC.parent).with_suffix("")
    package = list(rel.parts[:-1])  # the package a relative import starts from
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    out: list[tuple[str, int]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                module = ".".join([*base, node.module] if node.module else base)
            else:
                module = node.module or ""
            out.append((module, node.lineno))
            # `from roadpreview import pipeline` imports the sub-package
            out += [(f"{module}.{a.name}", node.lineno) for a in node.names]
    return out


def _unit_graph() -> dict[str, dict[str, str]]:
    """unit -> {imported unit: where (file:line)}."""
    graph: dict[str, dict[str, str]] = defaultdict(dict)
    for path in sorted(SRC.rglob("*.py")):
        me = _unit(".".join(path.relative_to(SRC.parent).with_suffix("").parts))
        assert me is not None
        me = me.removesuffix("__init__") or "__init__"
        for module, line in _imports(path):
            other = _unit(module)
            if other is None or other == me or (not (SRC / other).exists() and not (
                SRC / f"{other}.py"
            ).exists()):
                continue
            graph[me].setdefault(other, f"{path.relative_to(SRC)}:{line}")
    return graph


def _cycle(graph: dict[str, dict[str, str]]) -> list[str] | None:
    """One import cycle between units (as a path), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(u: str) -> list[str] | None:
        state[u] = 1
        stack.append(u)
        for v in graph.get(u, {}):
            if state.get(v) == 1:
                return [*stack[stack.index(v) :], v]
            if v not in state and (found := visit(v)):
                return found
        stack.pop()
        state[u] = 2
        return None

    for u in sorted(graph):
        if u not in state and (found := visit(u)):
            return found
    return None


def test_no_import_cycle_between_packages() -> None:
    graph = _unit_graph()
    cycle = _cycle(graph) or []
    where = [graph[a][b] for a, b in itertools.pairwise(cycle)]
    assert not cycle, "import cycle " + " -> ".join(cycle) + f" (at {', '.join(where)})"


def test_the_cycle_check_finds_a_planted_cycle() -> None:
    graph = _unit_graph()
    graph["types"] = {"fusion": "planted"}  # the vocabulary importing upward
    assert _cycle(graph) is not None


def test_types_is_at_the_bottom() -> None:
    assert _unit_graph().get("types", {}) == {}


def _forbidden(module: str) -> bool:
    return any(module == f or module.startswith(f + ".") for f in FORBIDDEN)


def _core_modules() -> list[Path]:
    return sorted(p for pkg in CORE for p in (SRC / pkg).rglob("*.py"))


@pytest.mark.parametrize("path", _core_modules(), ids=lambda p: str(p.relative_to(SRC)))
def test_estimation_packages_import_no_io(path: Path) -> None:
    """No CAN, no video capture, no simulator, evaluation, pipeline, apps or CLI."""
    found = sorted({m for m, _ in _imports(path) if _forbidden(m)})
    tree = ast.parse(path.read_text(encoding="utf-8"))
    if any(isinstance(n, ast.Attribute) and n.attr == "VideoCapture" for n in ast.walk(tree)):
        found.append("cv2.VideoCapture")
    assert not found, f"{path.relative_to(SRC)} imports {found}"


def test_importing_the_estimation_packages_loads_nothing_forbidden() -> None:
    """Transitively too, in a fresh interpreter."""
    names = [
        ".".join(p.relative_to(SRC.parent).with_suffix("").parts).removesuffix(".__init__")
        for p in _core_modules()
    ]
    code = (
        "import importlib, sys\n"
        f"for name in {names!r}:\n"
        "    importlib.import_module(name)\n"
        "print('\\n'.join(sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert sorted(m for m in out.split() if _forbidden(m)) == []
