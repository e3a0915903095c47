"""The README's commands work as written, and the example configuration documents every
field of `PipelineConfig` (and is what the generator writes)."""

from __future__ import annotations

import dataclasses
import json
import re
import shlex
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from roadpreview.cli._example_config import example_config_text
from roadpreview.cli.main import build_parser, main
from roadpreview.pipeline.config import PipelineConfig

if TYPE_CHECKING:
    from roadpreview.sim.recording import Recording

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
EXAMPLE = ROOT / "data" / "roadpreview.example.toml"
PREFIXES = (".venv/bin/roadpreview", "roadpreview", "python -m roadpreview")


def readme_commands() -> list[list[str]]:
    """The argument lists of the ``roadpreview`` commands in the README's ``sh`` blocks."""
    blocks = re.findall(r"```sh\n(.*?)```", README.read_text(), flags=re.DOTALL)
    commands = []
    for line in "\n".join(blocks).splitlines():
        for prefix in PREFIXES:
            if line.startswith(prefix + " ") or line == prefix:
                words = shlex.split(line[len(prefix) :], comments=True)
                commands.append(words)
                break
    return commands


def test_the_readme_has_commands() -> None:
    commands = readme_commands()
    assert len(commands) >= 10
    names = {c[0] for c in commands if c and not c[0].startswith("-")}
    assert {"simulate", "replay", "run", "evaluate", "bench"} <= names


@pytest.mark.parametrize("argv", readme_commands(), ids=lambda a: " ".join(a)[:60])
def test_readme_command_parses_and_its_help_works(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    """Every option in the README exists and takes the value it is given there."""
    parser = build_parser()
    if "--help" in argv:
        with pytest.raises(SystemExit) as exc:
            parser.parse_args(argv)
        assert exc.value.code == 0
        return
    args = parser.parse_args(argv)
    assert callable(args.func)
    with pytest.raises(SystemExit) as exc:
        main([argv[0], "--help"])
    assert exc.value.code == 0
    assert "exit codes:" in capsys.readouterr().out


def test_readme_replay_runs_as_written_on_a_tiny_recording(
    tiny: Recording, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``replay runs/wild3 --out runs/wild3-replay --truth`` and the ``--start/--end`` line,
    with runs/wild3 a short simulated drive."""
    (tmp_path / "runs").mkdir()
    (tmp_path / "runs" / "wild3").symlink_to(tiny.folder, target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    replays = [c for c in readme_commands() if c[:2] == ["replay", "runs/wild3"]]
    full = next(c for c in replays if "--truth" in c)
    assert main(full) == 0
    summary = json.loads((tmp_path / full[full.index("--out") + 1] / "summary.json").read_text())
    assert summary["frames"] == tiny.info["n_frames"]
    assert "truth" in summary
    cut = next(c for c in replays if "--start" in c)
    cut = [*cut[: cut.index("--start")], "--start", "1", "--end", "2"]  # 20-40 s: past 8 s
    assert main(cut) == 0


def _fields(cls: type, where: str = "") -> list[tuple[str, str, Any]]:
    """(table, key, default) of every leaf field of a config dataclass."""
    out = []
    obj = cls()
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):
            out += _fields(type(value), f"{where}.{f.name}" if where else f.name)
        else:
            out.append((where, f.name, value))
    return out


def test_example_config_comments_every_field() -> None:
    text = EXAMPLE.read_text()
    table = ""
    documented: dict[tuple[str, str], bool] = {}
    previous = ""
    for line in text.splitlines():
        if m := re.fullmatch(r"\[([\w.]+)\]", line):
            table = m.group(1)
        elif m := re.fullmatch(r"#? ?(\w+) = .*", line):
            documented[(table, m.group(1))] = previous.startswith("# ") and len(previous) > 4
        previous = line
    for where, name, value in _fields(PipelineConfig):
        if isinstance(value, dict):  # an options table: the table itself is commented
            assert f"[{where}.{name}]" in text, f"{where}.{name}"
            continue
        assert (where, name) in documented, f"{where}.{name} is not in {EXAMPLE.name}"
        assert documented[(where, name)], f"{where}.{name} has no comment above it"


def test_example_config_is_generated_and_loads_to_the_defaults() -> None:
    assert EXAMPLE.read_text() == example_config_text(), (
        "data/roadpreview.example.toml is stale; regenerate it with: PYTHONPATH=src "
        "python -m roadpreview.cli._example_config > data/roadpreview.example.toml"
    )
    assert PipelineConfig.load(EXAMPLE) == PipelineConfig()
