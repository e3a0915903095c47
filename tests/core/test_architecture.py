"""The package structure the architecture document draws: no import cycle between
packages nor between modules, the estimation packages never reach for I/O, the simulator
or the apps, and no source file grows past `MAX_LINES`.

The import checks walk the source (every import statement, also inside functions and
under TYPE_CHECKING), so an import added anywhere shows up here."""

from __future__ import annotations

import ast
import itertools
import subprocess
import sys
from collections import defaultdict, deque
from pathlib import Path
from typing import NamedTuple

import pytest

import roadpreview

SRC = Path(roadpreview.__file__).parent
#: longest source file: past it a module holds more than one thing (STYLE.md, "Files")
MAX_LINES = 800
#: the packages that estimate: they take typed samples and arrays, never files or buses
CORE = ("vision", "pitch", "fusion", "compensation", "anomaly")
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


# --- module cycles ------------------------------------------------------------------------
#
# The graph has one node per roadpreview module; a package is the node of its __init__.py.
# Every import statement adds edges (also inside functions and under TYPE_CHECKING):
#
# * ``import roadpreview.a.b`` and ``from roadpreview.a.b import f`` -> ``roadpreview.a.b``;
# * ``from roadpreview.a import b`` where ``b`` is a submodule -> ``roadpreview.a.b`` (only
#   the submodule: the package's re-exports are not used), otherwise -> ``roadpreview.a``;
# * importing ``roadpreview.a.b`` runs the ``__init__`` of ``roadpreview.a`` first, so the
#   importer also gets an (implied) edge to every enclosing package of what it imports ...
# * ... except the packages that enclose the importer itself: Python has entered those
#   before the importer runs, so an implied edge there says nothing about order. Without
#   that rule every package whose __init__ re-exports a submodule would be a cycle with
#   each of its submodules. An import that names the enclosing package for its
#   re-exports (``from roadpreview.a import f`` inside ``roadpreview/a/b.py``) is explicit
#   and stays: that is a real cycle when ``a/__init__.py`` imports ``b``.


class Edge(NamedTuple):
    """One import: where it is, and whether the target is only an enclosing package."""

    where: str  # file:line
    via: str | None  # the module actually named when the edge is implied, else None


def _module_of(path: Path) -> str:
    return ".".join(path.relative_to(SRC.parent).with_suffix("").parts).removesuffix(".__init__")


def _ancestors(module: str) -> list[str]:
    """The enclosing packages of ``module``, outermost first (not the module itself)."""
    parts = module.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts))]


def _module_graph(
    extra: dict[str, str] | None = None,
) -> dict[str, dict[str, list[Edge]]]:
    """module -> {imported module: [edges]} over every roadpreview module in ``SRC``;
    ``extra`` maps further module names to source text (planted modules for the tests of
    the check)."""
    sources = {_module_of(p): (p, p.read_text(encoding="utf-8")) for p in SRC.rglob("*.py")}
    for name, text in (extra or {}).items():
        sources[name] = (SRC.parent / (name.replace(".", "/") + ".py"), text)
    known = set(sources)
    packages = {m for m, (p, _) in sources.items() if p.name == "__init__.py"}
    graph: dict[str, dict[str, list[Edge]]] = {m: {} for m in sources}
    for me, (path, text) in sorted(sources.items()):
        package = me if me in packages else me.rpartition(".")[0]
        mine = set(_ancestors(me))
        found: list[tuple[str, int, str | None]] = []  # (imported module, line, via)
        for node in ast.walk(ast.parse(text, str(path))):
            named: list[str] = []
            if isinstance(node, ast.Import):
                named = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - node.level + 1]
                    module = ".".join([*base, node.module] if node.module else base)
                else:
                    module = node.module or ""
                subs = [f"{module}.{a.name}" for a in node.names]
                named = [s for s in subs if s in known]
                if len(named) < len(subs):  # a name that is not a submodule: the module itself
                    named.append(module)
            else:
                continue
            for target in named:
                found.append((target, node.lineno, None))
                found += [(up, node.lineno, target) for up in _ancestors(target) if up not in mine]
        for target, line, via in found:
            if target in known and target != me:
                where = f"{path.relative_to(SRC.parent)}:{line}"
                graph[me].setdefault(target, []).append(Edge(where, via))
    return graph


def _strongly_connected(graph: dict[str, dict[str, list[Edge]]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan, iterative),
    each sorted, in sorted order."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return sorted(found)


def _a_cycle(graph: dict[str, dict[str, list[Edge]]], component: list[str]) -> list[str]:
    """A shortest cycle through the first module of ``component`` (breadth first)."""
    start, inside = component[0], set(component)
    came: dict[str, str] = {}
    queue = deque([start])
    while queue:
        node = queue.popleft()
        for child in sorted(graph[node]):
            if child not in inside:
                continue
            if child == start:
                path = [node]
                while path[-1] != start:
                    path.append(came[path[-1]])
                return [*reversed(path), start]
            if child not in came:
                came[child] = node
                queue.append(child)
    raise AssertionError(f"{component} is not strongly connected")


def _describe(graph: dict[str, dict[str, list[Edge]]], component: list[str]) -> str:
    lines = [f"cycle {' -> '.join(_a_cycle(graph, component))}; every import among them:"]
    for a in component:
        for b in sorted(set(graph[a]) & set(component)):
            for edge in graph[a][b]:
                via = f" (imports {edge.via}: runs this __init__)" if edge.via else ""
                lines.append(f"    {a} -> {b}  at {edge.where}{via}")
    return "\n".join(lines)


def test_no_import_cycle_between_modules() -> None:
    graph = _module_graph()
    cycles = [_describe(graph, c) for c in _strongly_connected(graph)]
    assert not cycles, f"{len(cycles)} import cycle(s) between modules:\n" + "\n".join(cycles)


def test_the_module_cycle_check_finds_planted_cycles() -> None:
    planted = {
        # a direct cycle, one import inside a function
        "roadpreview.eval.zz_a": "from roadpreview.eval.zz_b import f\n",
        "roadpreview.eval.zz_b": "def f():\n    from roadpreview.eval import zz_a\n",
        # through a package __init__ that imports its own submodule: explicit use of
        # the package's re-exports from inside it closes the cycle
        "roadpreview.zz_pkg": "from roadpreview.zz_pkg.inner import g\n",
        "roadpreview.zz_pkg.inner": (
            "from typing import TYPE_CHECKING\n"
            "if TYPE_CHECKING:\n    from roadpreview.zz_pkg import g\n"
        ),
    }
    graph = _module_graph(planted)
    found = _strongly_connected(graph)
    assert ["roadpreview.eval.zz_a", "roadpreview.eval.zz_b"] in found
    assert ["roadpreview.zz_pkg", "roadpreview.zz_pkg.inner"] in found
    text = _describe(graph, ["roadpreview.eval.zz_a", "roadpreview.eval.zz_b"])
    assert "roadpreview/eval/zz_a.py:1" in text
    assert "roadpreview/eval/zz_b.py:2" in text


def test_the_module_graph_follows_package_inits() -> None:
    """Importing a submodule of another package runs that package's __init__; importing
    from one's own enclosing package only does when it names the package's re-exports."""
    planted = {
        "roadpreview.zz_pkg": "from roadpreview.zz_pkg.inner import g\n",
        "roadpreview.zz_pkg.inner": "from roadpreview.zz_pkg import sibling\n",
        "roadpreview.zz_pkg.sibling": "",
        "roadpreview.zz_user": "from roadpreview.zz_pkg.sibling import h\n",
    }
    graph = _module_graph(planted)
    assert set(graph["roadpreview.zz_pkg.inner"]) == {"roadpreview.zz_pkg.sibling"}
    assert set(graph["roadpreview.zz_user"]) == {"roadpreview.zz_pkg", "roadpreview.zz_pkg.sibling"}
    assert graph["roadpreview.zz_user"]["roadpreview.zz_pkg"][0].via == "roadpreview.zz_pkg.sibling"
    assert not [c for c in _strongly_connected(graph) if "roadpreview.zz_pkg" in c]


# --- file length --------------------------------------------------------------------------


def test_no_source_file_is_longer_than_max_lines() -> None:
    long = {
        str(p.relative_to(SRC.parent)): n
        for p in sorted(SRC.rglob("*.py"))
        if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_LINES
    }
    assert not long, f"longer than {MAX_LINES} lines (split along a seam): {long}"
