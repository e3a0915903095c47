"""``roadpreview replay`` on a tiny recording: outputs that explain themselves (units in
the column names, two clocks, a summary with inputs, config, versions, truth rows and
mode shares; mode reasons that fit their mode), ``--start/--end``, and the progress."""

from __future__ import annotations

import csv
import hashlib
import io
import itertools
import json
import math
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from roadpreview import configtools
from roadpreview.apps.progress import Progress
from roadpreview.apps.summary import truth_rows
from roadpreview.cli.main import main
from roadpreview.fusion.mode_machine import mode_reason
from roadpreview.pipeline.config import PipelineConfig
from roadpreview.pipeline.pipeline import FrameResult
from roadpreview.pipeline.truthmatch import match_alerts
from roadpreview.sinks.files import FRAME_TABLE_NAMES, frame_table_columns
from roadpreview.types import Alert, FusionMode, Side

if TYPE_CHECKING:
    from roadpreview.sim.recording import Recording

#: what a reason of each mode talks about
MODE_WORDS = {
    FusionMode.FUSED: "gyro and vision agree",
    FusionMode.VISUAL_ONLY: "vision only: ",
    FusionMode.IMU_ONLY: "gyro only: ",
    FusionMode.DEGRADED: "no pitch source: ",
}


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def replayed(
    tiny: Recording, tmp_path_factory: pytest.TempPathFactory
) -> tuple[Path, dict[str, Any]]:
    out = tmp_path_factory.mktemp("replayed") / "out"
    assert main(["replay", str(tiny.folder), "--out", str(out), "--truth", "-q"]) == 0
    return out, json.loads((out / "summary.json").read_text())


def test_every_frame_column_carries_its_unit() -> None:
    assert set(FRAME_TABLE_NAMES) == set(FrameResult.COLUMNS), "a column without its unit"
    cols = frame_table_columns()
    assert cols[:2] == ("t_unix_s", "t_rel_s")
    for name in ("phi_rad", "y_px", "y_c_px", "s_px", "lead_distance_m", "ego_speed_mps"):
        assert name in cols
    assert "phi" not in cols
    assert "t" not in cols
    assert len(set(cols)) == len(cols)


def test_frames_csv_has_a_unix_and_a_relative_clock(
    tiny: Recording, replayed: tuple[Path, dict[str, Any]]
) -> None:
    out, summary = replayed
    rows = _rows(out / "frames.csv")
    assert len(rows) == tiny.info["n_frames"]
    t0 = summary["clock"]["frame0_unix_s"]
    assert t0 == pytest.approx(float(tiny.info["can_t0_unix_s"]))
    assert float(rows[0]["t_rel_s"]) == 0.0
    for r in rows:
        assert float(r["t_unix_s"]) - t0 == pytest.approx(float(r["t_rel_s"]), abs=2e-6)
    # the recording's frame clock, and φ in radians (a degree-sized pitch would be ~57x)
    truth_t = tiny.truth["frame_t_s"]
    assert float(rows[-1]["t_rel_s"]) == pytest.approx(float(truth_t[-1]) - float(truth_t[0]))
    phi = [float(r["phi_rad"]) for r in rows if math.isfinite(float(r["phi_rad"]))]
    assert max(abs(p) for p in phi) < 0.05


def test_summary_holds_inputs_config_versions_and_mode_shares(
    tiny: Recording, replayed: tuple[Path, dict[str, Any]]
) -> None:
    _, summary = replayed
    inputs = {Path(i["path"]).name: i for i in summary["inputs"]}
    assert {"video.mp4", "can.blf", "frames.csv", "camera.toml", "truth.json"} <= set(inputs)
    video = tiny.folder / "video.mp4"
    assert inputs["video.mp4"]["sha256"] == hashlib.sha256(video.read_bytes()).hexdigest()
    assert inputs["video.mp4"]["size_bytes"] == video.stat().st_size
    assert configtools.from_mapping(PipelineConfig, summary["config"]) == PipelineConfig()
    versions = summary["versions"]
    for name in ("roadpreview", "python", "numpy", "scipy", "opencv", "cantools", "python-can"):
        assert versions[name], name
    shares = summary["modes"]
    assert set(shares) == {m.name for m in FusionMode}
    assert sum(s["share"] for s in shares.values()) == pytest.approx(1.0, abs=1e-3)
    span = summary["clock"]["last_frame_rel_s"] - summary["clock"]["first_frame_rel_s"]
    assert sum(s["seconds"] for s in shares.values()) == pytest.approx(span, abs=1e-3)
    assert summary["interrupted"] is False


def test_summary_has_one_row_per_true_event(
    tiny: Recording, replayed: tuple[Path, dict[str, Any]]
) -> None:
    _, summary = replayed
    events = [e for e in tiny.events if e.get("lead_front_t_s") is not None]
    assert events, "the drive has no event the lead crosses"
    rows = summary["truth"]["events"]
    assert [r["event"] for r in rows] == [e["index"] for e in events]
    for r, e in zip(rows, events, strict=True):
        assert r["kind"] == e["kind"]
        assert r["height_mm"] == pytest.approx(1000 * e["height_m"], abs=0.1)
        assert r["outcome"] in ("hit", "miss", "-")
        assert (r["alert_id"] is None) == (r["outcome"] != "hit")
    assert summary["truth"]["hits"] == sum(r["outcome"] == "hit" for r in rows)


def test_mode_reasons_describe_their_mode(replayed: tuple[Path, dict[str, Any]]) -> None:
    _, summary = replayed
    changes = summary["mode_changes"]
    assert changes, "no mode at all"
    for c in changes:
        assert c["reason"].startswith(MODE_WORDS[FusionMode[c["mode"]]]), c
        assert "lead" not in c["reason"]  # the lead is not why the pitch mode is what it is
    # the recording has an IMU at 100 Hz: "no IMU input" holds only until its first sample,
    # and a reason is replaced when it stops being true, even if the mode stays
    for c, nxt in itertools.pairwise(changes):
        if "no IMU input" in c["reason"]:
            assert nxt["t_rel_s"] - c["t_rel_s"] <= 0.1, changes
    assert "no IMU input" not in changes[-1]["reason"]


@pytest.mark.parametrize(
    ("mode", "kwargs", "expected"),
    [
        (FusionMode.FUSED, {"gyro_age_s": 0.01}, "gyro and vision agree"),
        (FusionMode.FUSED, {}, "vision trusted; no gyro sample yet"),
        (FusionMode.VISUAL_ONLY, {}, "vision only: no IMU input"),
        (FusionMode.VISUAL_ONLY, {"gyro_age_s": 0.8}, "vision only: gyro timed out"),
        (FusionMode.IMU_ONLY, {"vision_failure": "low texture: fog"}, "gyro only: vision failed"),
        (FusionMode.IMU_ONLY, {"gyro_age_s": 0.01}, "gyro only: vision not trusted"),
        (FusionMode.DEGRADED, {"vision_failure": "x"}, "no pitch source: no IMU input"),
    ],
)
def test_mode_reason_fits_the_mode(mode: FusionMode, kwargs: Any, expected: str) -> None:
    assert mode_reason(mode, **kwargs).startswith(expected)


def test_start_and_end_cut_the_drive(tiny: Recording, tmp_path: Path) -> None:
    out = tmp_path / "cut"
    argv = ["replay", str(tiny.folder), "--out", str(out), "--start", "1.0", "--end", "2.5"]
    assert main([*argv, "-q"]) == 0
    rows = _rows(out / "frames.csv")
    t_rel = [float(r["t_rel_s"]) for r in rows]
    assert t_rel[0] == pytest.approx(1.0, abs=1 / 30)
    assert 2.5 - 1 / 30 <= t_rel[-1] <= 2.5
    assert len(rows) == pytest.approx(1.5 * 30, abs=2)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["frames"] == len(rows)
    assert summary["clock"]["first_frame_rel_s"] == pytest.approx(t_rel[0], abs=1e-3)
    assert summary["interrupted"] is False  # a window is no interruption


def test_start_after_end_is_a_usage_error(
    tiny: Recording, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["replay", str(tiny.folder), "--out", str(tmp_path / "o"), "--start", "3", "--end", "2"]
    assert main(argv) == 1
    assert "--start 3.0 s must be before --end 2.0 s" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_progress_bar_on_a_terminal_shows_total_rate_and_eta() -> None:
    stream = io.StringIO()
    p = Progress("replay", stream=stream, tty=True)
    p.start(300)
    for frames in range(30, 301, 30):
        p(frames, frames / 60.0)
    p.close(300)
    text = stream.getvalue()
    assert "300/300" in text
    assert "frame/s" in text  # the rate
    assert "<" in text  # elapsed<remaining


def test_progress_off_a_terminal_logs_lines_with_total_and_time_left(
    caplog: pytest.LogCaptureFixture,
) -> None:
    p = Progress("replay", stream=io.StringIO(), tty=False, every_s=0.0)
    p.start(300)
    with caplog.at_level("INFO", logger="roadpreview.progress"):
        p(150, 5.0)
        p.close(300)
    lines = [r.getMessage() for r in caplog.records]
    assert lines[0] == "replay: 150/300 frames (50.0 %), 30.0 fps, 0:05 elapsed, 0:05 left"
    assert lines[-1].startswith("replay: 300/300 frames (100.0 %)")
    assert lines[-1].endswith("(done)")
    silent = Progress("replay", enabled=False, stream=io.StringIO(), tty=False, every_s=0.0)
    silent.start(10)
    silent(5, 1.0)
    silent.close(10)
    assert len(caplog.records) == len(lines)


def test_truth_rows_give_the_matching_alert_and_its_timing_errors() -> None:
    t0 = 1.7e9
    event = {
        "index": 3,
        "kind": "pothole",
        "height_m": -0.05,
        "lead_side": "left",
        "lead_front_t_s": 10.0,
        "ego_front_t_s": 11.5,
        "lead_distance_m": 14.0,
        "lead_hits": True,
    }
    alert = Alert(
        t_s=t0 + 10.1,
        t_emit_s=t0 + 10.9,
        distance_m=15.0,
        time_to_arrival_s=1.3,
        severity_px=4.0,
        height_mm=-45.0,
        side=Side.LEFT,
        confidence=0.9,
        mode=FusionMode.FUSED,
        alert_id=7,
    )
    stray = replace(alert, t_s=t0 + 30.0, t_emit_s=t0 + 31.0, alert_id=8)
    report = match_alerts([alert, stray], [event], t0=t0, duration_s=60.0)
    (row,) = truth_rows(report)
    assert row["event"] == 3
    assert row["outcome"] == "hit"
    assert row["alert_id"] == 7
    assert row["t_lead_rel_s"] == 10.0
    assert row["crossing_error_s"] == pytest.approx(0.1)  # the alert's crossing is late
    assert row["tta_true_s"] == pytest.approx(1.4)  # ego there 1.4 s after the alert's t_s
    assert row["tta_error_s"] == pytest.approx(-0.1)  # predicted 1.3 s
    assert row["lead_time_s"] == pytest.approx(0.6)  # warned 0.6 s before the ego got there
    assert [a.alert_id for a in report.false_alarms] == [8]
