"""requirements.lock agrees with pyproject.toml: every direct dependency (runtime, the
extras, the build group) is locked at a version its range admits, for every supported
Python on Linux x86_64 and aarch64, with sha256 hashes; nothing is locked as a direct
dependency that pyproject.toml does not ask for; and `make` installs from it.

The checks are functions of the two texts, so the tests below also show that they fail
when one file is edited alone."""

from __future__ import annotations

import re
import sys
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from packaging.markers import Marker
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised only on 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[2]
LOCK = ROOT / "requirements.lock"
PYPROJECT = ROOT / "pyproject.toml"
MAKEFILE = ROOT / "Makefile"

#: the Pythons the project supports (requires-python >= 3.10) and the lock must cover
PYTHONS = ("3.10.16", "3.11.7", "3.12.9", "3.13.2")
MACHINES = ("x86_64", "aarch64")
_ENTRY = re.compile(r"^([A-Za-z0-9][A-Za-z0-9._-]*)==([^\s;\\]+)\s*(?:;\s*([^\\]+?))?\s*\\?$")
_HASH = re.compile(r"--hash=sha256:[0-9a-f]{64}")
_OURS = re.compile(r"roadpreview \(pyproject\.toml(?::[\w-]+)?\)")


@dataclass
class Pin:
    """One line ``name==version ; marker`` of the lock, with its hashes and origins."""

    name: str
    version: Version
    marker: Marker | None
    hashes: int = 0
    via: list[str] = field(default_factory=list)


def parse_lock(text: str) -> list[Pin]:
    """The pins of a lock written by ``uv pip compile --generate-hashes`` (annotated)."""
    pins: list[Pin] = []
    in_via = False
    for line in text.splitlines():
        m = _ENTRY.match(line)
        if m:
            marker = Marker(m.group(3)) if m.group(3) else None
            pins.append(Pin(canonicalize_name(m.group(1)), Version(m.group(2)), marker))
            in_via = False
            continue
        stripped = line.strip()
        if not pins or not stripped:
            continue
        pins[-1].hashes += len(_HASH.findall(stripped))
        if stripped.startswith("# via"):
            rest = stripped.removeprefix("# via").strip()
            in_via = not rest
            if rest:
                pins[-1].via.append(rest)
        elif in_via and stripped.startswith("#"):
            pins[-1].via.append(stripped.lstrip("#").strip())
    return pins


def direct_requirements(pyproject: dict[str, object]) -> list[Requirement]:
    """What pyproject.toml asks for: dependencies, every extra and every dependency group."""
    project = pyproject["project"]
    assert isinstance(project, dict)
    specs: list[str] = list(project.get("dependencies", []))
    for extra in project.get("optional-dependencies", {}).values():
        specs += extra
    groups = pyproject.get("dependency-groups", {})
    assert isinstance(groups, dict)
    for group in groups.values():
        specs += [s for s in group if isinstance(s, str)]
    return [Requirement(s.split("#")[0].strip()) for s in specs]


def _env(python: str, machine: str) -> dict[str, str]:
    return {
        "python_version": ".".join(python.split(".")[:2]),
        "python_full_version": python,
        "platform_machine": machine,
        "sys_platform": "linux",
        "platform_system": "Linux",
        "os_name": "posix",
        "implementation_name": "cpython",
        "platform_python_implementation": "CPython",
        "extra": "",
    }


def disagreements(pyproject_text: str, lock_text: str) -> list[str]:
    """Every way the lock and pyproject.toml disagree, one line each (empty: they agree)."""
    pins = parse_lock(lock_text)
    reqs = direct_requirements(tomllib.loads(pyproject_text))
    problems: list[str] = []
    by_name: dict[str, list[Pin]] = defaultdict(list)
    for pin in pins:
        by_name[pin.name].append(pin)
        if pin.hashes == 0:
            problems.append(f"{pin.name}=={pin.version}: no sha256 hash")
    wanted = {canonicalize_name(r.name) for r in reqs}
    ours = {p.name for p in pins if any(_OURS.fullmatch(v) for v in p.via)}
    problems += [f"{n}: in pyproject.toml, not a direct pin of the lock" for n in wanted - ours]
    problems += [f"{n}: a direct pin of the lock, not in pyproject.toml" for n in ours - wanted]
    for python in PYTHONS:
        for machine in MACHINES:
            env = _env(python, machine)
            for req in reqs:
                if req.marker is not None and not req.marker.evaluate(env):
                    continue
                name = canonicalize_name(req.name)
                live = [p for p in by_name[name] if p.marker is None or p.marker.evaluate(env)]
                where = f"{name} on Python {python} {machine}"
                if len(live) != 1:
                    problems.append(f"{where}: {len(live)} pins apply, want exactly 1")
                elif not req.specifier.contains(live[0].version, prereleases=True):
                    problems.append(f"{where}: {live[0].version} outside {req.specifier}")
    return sorted(set(problems))


def test_the_lock_agrees_with_pyproject() -> None:
    assert disagreements(PYPROJECT.read_text(), LOCK.read_text()) == []


def test_the_lock_pins_every_direct_dependency_with_hashes() -> None:
    pins = parse_lock(LOCK.read_text())
    names = {p.name for p in pins}
    # the design card's packages and the build group are all there, each hashed
    for name in ("numpy", "scipy", "opencv-python-headless", "filterpy", "gtsam",
                 "onnxruntime", "python-can", "setuptools", "wheel", "pytest-xdist"):
        assert name in names
    assert all(p.hashes >= 1 for p in pins)
    # a wheel per platform: numpy's pin for this Python has many (x86_64, aarch64, ...)
    assert max(p.hashes for p in pins if p.name == "numpy") >= 10


def test_a_dependency_added_to_pyproject_alone_is_caught() -> None:
    text = PYPROJECT.read_text()
    edited = text.replace('"numpy>=1.24",', '"numpy>=1.24",\n    "requests>=2.0",', 1)
    assert edited != text
    assert "requests: in pyproject.toml, not a direct pin of the lock" in disagreements(
        edited, LOCK.read_text()
    )


def test_a_range_raised_in_pyproject_alone_is_caught() -> None:
    text = PYPROJECT.read_text()
    edited = text.replace('"numpy>=1.24",', '"numpy>=99",', 1)
    assert edited != text
    found = disagreements(edited, LOCK.read_text())
    assert any(p.startswith("numpy on Python 3.11.7 x86_64:") and "outside >=99" in p
               for p in found)


def test_a_dependency_added_to_the_lock_alone_is_caught() -> None:
    extra = (
        "requests==2.32.3 \\\n"
        "    --hash=sha256:" + "0" * 64 + "\n"
        "    # via roadpreview (pyproject.toml)\n"
    )
    found = disagreements(PYPROJECT.read_text(), extra + LOCK.read_text())
    assert "requests: a direct pin of the lock, not in pyproject.toml" in found


def test_a_pin_without_hash_is_caught() -> None:
    lock = LOCK.read_text()
    edited = re.sub(r"(?m)^(tqdm==\S+) \\\n(    --hash=\S+( \\)?\n)+", r"\1\n", lock, count=1)
    assert edited != lock
    assert any(p.startswith("tqdm==") and "no sha256 hash" in p
               for p in disagreements(PYPROJECT.read_text(), edited))


@pytest.mark.parametrize("target", ["demo", "test"])
def test_make_installs_from_the_lock_with_hashes(target: str) -> None:
    text = MAKEFILE.read_text()
    # demo and test depend on the install stamp, which depends on the lock
    assert re.search(rf"(?m)^{target}:.*(\$\(STAMP\)|lint)", text)
    assert re.search(r"(?m)^\$\(STAMP\): \$\(LOCK\)", text)
    install = [ln for ln in text.splitlines() if "$(BIN)/python -m pip install" in ln]
    assert len(install) == 2
    assert any("--require-hashes" in ln and "-r $(LOCK)" in ln for ln in install)
    # the project itself goes in without pulling anything past the lock
    assert all("--no-deps" in ln for ln in install)
