"""The conventions every sub-command shares: -v/-q anywhere, --help with defaults and exit
codes, ``python -m roadpreview``, one-line errors with exit code 1, and an ``--out`` that
is never a file nor silently mixed with an earlier run's files."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from roadpreview.cli.main import COMMANDS, build_parser, main, verbosity

if TYPE_CHECKING:
    from roadpreview.sim.recording import Recording

SRC = Path(__file__).resolve().parents[2] / "src"


def _help(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    with pytest.raises(SystemExit) as exc:
        main([*argv, "--help"])
    assert exc.value.code == 0
    return capsys.readouterr().out


@pytest.mark.parametrize("command", list(COMMANDS))
def test_every_command_takes_v_and_q_after_its_name_and_documents_exit_codes(
    command: str, capsys: pytest.CaptureFixture[str]
) -> None:
    text = _help(capsys, command)
    assert "-q, --quiet" in text
    assert "-v, --verbose" in text
    for code in ("0 ", "1 ", "2 ", "130 "):
        assert f"\n  {code}" in text, f"exit code {code} not documented"


def test_v_and_q_count_before_and_after_the_command() -> None:
    parser = build_parser()
    assert verbosity(parser.parse_args(["bench", "pitch"])) == 0
    assert verbosity(parser.parse_args(["-v", "bench", "pitch", "-v"])) == 2
    assert verbosity(parser.parse_args(["bench", "pitch", "-vv"])) == 2
    assert verbosity(parser.parse_args(["bench", "-q", "pitch"])) == -1
    assert verbosity(parser.parse_args(["-q", "bench", "pitch", "-v"])) == -1  # -q wins


def test_help_shows_defaults_and_units(capsys: pytest.CaptureFixture[str]) -> None:
    simulate = _help(capsys, "simulate")
    assert "(default: demo)" in simulate  # --preset
    assert "--duration S" in simulate
    assert "seconds" in simulate
    replay = _help(capsys, "replay")
    assert "--start S" in replay
    assert "--end S" in replay
    assert "t_unix_s" in replay  # the clocks of the outputs
    bench = _help(capsys, "bench")
    assert "(default: 0)" in bench  # --seed
    assert "None" not in bench  # no meaningless default shown


def test_python_dash_m_roadpreview_runs_the_cli() -> None:
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    out = subprocess.run(
        [sys.executable, "-m", "roadpreview", "--version"],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
        check=False,
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("roadpreview ")
    usage = subprocess.run(
        [sys.executable, "-m", "roadpreview", "replay"],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
        check=False,
    )
    assert usage.returncode == 2  # usage error: the input and --out are missing
    assert "Traceback" not in usage.stderr


def _one_line_error(err: str, *needles: str) -> None:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("roadpreview replay: error: ")
    assert "Traceback" not in err
    for n in needles:
        assert n in lines[0]


def test_out_that_is_a_file_is_a_one_line_error(
    tiny: Recording, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    target = tmp_path / "notes.txt"
    target.write_text("mine")
    assert main(["replay", str(tiny.folder), "--out", str(target)]) == 1
    _one_line_error(capsys.readouterr().err, str(target), "is a file")
    assert target.read_text() == "mine"


def test_out_below_a_file_is_a_one_line_error(
    tiny: Recording, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A file-system error (here NotADirectoryError from mkdir) is no traceback."""
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["replay", str(tiny.folder), "--out", str(blocker / "sub" / "out")]) == 1
    _one_line_error(capsys.readouterr().err, str(blocker))


def test_non_empty_out_is_refused_and_force_replaces_only_our_files(
    tiny: Recording, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "summary.json").write_text('{"stale": true}')
    (out / "annotated.mp4").write_text("stale video of an earlier --annotate run")
    (out / "notes.txt").write_text("the user's")
    assert main(["replay", str(tiny.folder), "--out", str(out), "-q"]) == 1
    _one_line_error(capsys.readouterr().err, "not empty", "--force")
    assert json.loads((out / "summary.json").read_text()) == {"stale": True}  # untouched

    argv = ["replay", str(tiny.folder), "--out", str(out), "--force", "--end", "1", "-q"]
    assert main(argv) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["frames"] == 31  # frames 0..30 at 30 fps: the new run's
    assert not (out / "annotated.mp4").exists()  # stale output of ours: deleted
    assert (out / "notes.txt").read_text() == "the user's"  # not ours: kept


def test_quiet_silences_the_progress_and_default_logs_it_off_a_terminal(
    tiny: Recording, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    argv = ["replay", str(tiny.folder), "--end", "1", "--out"]
    assert main([*argv, str(tmp_path / "a"), "-q"]) == 0
    assert not [r for r in caplog.records if r.name == "roadpreview.progress"]
    caplog.clear()
    assert main([*argv, str(tmp_path / "b")]) == 0
    lines = [r.getMessage() for r in caplog.records if r.name == "roadpreview.progress"]
    n = json.loads((tmp_path / "b" / "summary.json").read_text())["frames"]
    assert lines, "no progress line when stderr is not a terminal"
    assert f"{n}/{n} frames (100.0 %)" in lines[-1]
    assert "fps" in lines[-1]


def test_simulate_refuses_a_non_empty_out_unless_force(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "rec"
    out.mkdir()
    (out / "video.mp4").write_text("an earlier drive")
    assert main(["simulate", "--out", str(out), "--write-scenario"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("roadpreview simulate: error: --out ")
    assert "not empty" in err
    assert (out / "video.mp4").read_text() == "an earlier drive"
    assert main(["simulate", "--out", str(out), "--write-scenario", "--force", "-q"]) == 0
    assert not (out / "video.mp4").exists()  # the stale recording file: deleted
    assert (out / "scenario.toml").is_file()
