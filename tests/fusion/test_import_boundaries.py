"""The math packages keep the arrows pointing down: fusion/ and pitch/ never import the CAN
stack, video capture, the simulator, the evaluation, the pipeline or the CLI."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

import roadpreview

SRC = Path(roadpreview.__file__).parent
PACKAGES = ("fusion", "pitch")
FORBIDDEN = ("can", "roadpreview.sim", "roadpreview.eval", "roadpreview.pipeline")
FORBIDDEN += ("roadpreview.cli", "roadpreview.canbus")


def _forbidden(module: str) -> bool:
    return any(module == f or module.startswith(f + ".") for f in FORBIDDEN)


def _modules() -> list[Path]:
    return sorted(p for pkg in PACKAGES for p in (SRC / pkg).glob("*.py"))


@pytest.mark.parametrize("path", _modules(), ids=lambda p: f"{p.parent.name}/{p.name}")
def test_no_forbidden_import_in_the_source(path: Path) -> None:
    """Every import statement (also inside functions), and no use of cv2.VideoCapture."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    found: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [a.name for a in node.names if _forbidden(a.name)]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            if _forbidden(node.module):
                found.append(node.module)
            if node.module == "cv2" and any(a.name == "VideoCapture" for a in node.names):
                found.append("cv2.VideoCapture")
        elif (
            isinstance(node, ast.Attribute)
            and node.attr == "VideoCapture"
            and isinstance(node.value, ast.Name)
            and node.value.id == "cv2"
        ):
            found.append("cv2.VideoCapture")
    assert not found, f"{path.name} imports {sorted(set(found))}"


def test_importing_every_module_loads_nothing_forbidden() -> None:
    """Transitively too: a fresh interpreter that imports every module of fusion/ and pitch/
    has none of the forbidden modules loaded."""
    names = [f"roadpreview.{p.parent.name}.{p.stem}" for p in _modules()]
    code = (
        "import importlib, sys\n"
        f"for name in {names!r}:\n"
        "    importlib.import_module(name.removesuffix('.__init__'))\n"
        "print('\\n'.join(sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    loaded = sorted(m for m in out.split() if _forbidden(m))
    assert not loaded
