"""The fleet tables and the fleet report of ``roadpreview batch``, from hand-made drive
outcomes (no replay)."""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

import cv2
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from roadpreview.batch import report
from roadpreview.batch.outcome import MODES, DriveOutcome
from roadpreview.batch.report import fleet_figures, write_report
from roadpreview.batch.tables import (
    DRIVE_COLUMNS,
    TABLE_FILES,
    alert_columns,
    alerts_table,
    drives_table,
    write_tables,
)
from roadpreview.sinks.files import alert_record
from roadpreview.types import Alert, Confirmation, ConfirmationResult, FusionMode, Side


def _alert_row(alert_id: int, t_s: float, *, felt: bool = False) -> dict[str, Any]:
    """One alerts.jsonl line, made as the replay makes it."""
    alert = Alert(
        t_s=t_s,
        t_emit_s=t_s + 0.2,
        distance_m=18.0,
        time_to_arrival_s=1.5,
        severity_px=3.0,
        height_mm=None,  # null in every row: the column must stay numeric
        side=Side.UNKNOWN,
        confidence=0.8,
        mode=FusionMode.FUSED,
        alert_id=alert_id,
    )
    confirmation = (
        ConfirmationResult(alert_id, Confirmation.CONFIRMED, t_s + 2.0, t_s + 1.6, 4.0, 0.5)
        if felt
        else None
    )
    return alert_record(alert, confirmation)


BAD_VIDEO = "ValueError: video.mp4 has no decodable frame"
BAD_CAN = "unusable input: can.log | no message of the mapping"


def _fleet() -> list[DriveOutcome]:
    """A: 2 alerts in 4 km and 120 s, truth 2 of 3 hit and 1 false alarm in 2 min;
    B: no speed (no distance), 1 alert in 60 s, truth 1 of 1; C: skipped, 2 km, 180 s,
    no truth; D and E failed."""
    return [
        DriveOutcome(
            "B",
            "done",
            frames=600,
            duration_s=60.0,
            replay_s=6.0,
            fps=100.0,
            alerts=1,
            modes={"FUSED": 1.0},
            truth={"expected": 1.0, "hits": 1.0, "false_alarms": 0.0, "minutes": 1.0},
            alert_rows=[_alert_row(0, 30.0)],
        ),
        DriveOutcome(
            "A",
            "done",
            folder="out/A",
            frames=1200,
            duration_s=120.0,
            distance_km=4.0,
            replay_s=12.0,
            fps=100.0,
            alerts=2,
            modes={"FUSED": 0.5, "VISUAL_ONLY": 0.5, "IMU_ONLY": 0.0, "DEGRADED": 0.0},
            road_class="B",
            decode_failures=2,
            truth={"expected": 3.0, "hits": 2.0, "false_alarms": 1.0, "minutes": 2.0},
            worker="tcp://127.0.0.1:1",
            alert_rows=[_alert_row(0, 10.0, felt=True), _alert_row(1, 50.0)],
        ),
        DriveOutcome(
            "C",
            "skipped",
            frames=1800,
            duration_s=180.0,
            distance_km=2.0,
            modes={"IMU_ONLY": 1.0},
        ),
        DriveOutcome("D", "failed", BAD_VIDEO),
        DriveOutcome("E", "failed", BAD_CAN),
    ]


# -- (a) the alerts table -------------------------------------------------------------------
def test_alerts_parquet_round_trips_and_csv_has_the_same_rows(tmp_path: Path) -> None:
    fleet = _fleet()
    written = write_tables(fleet, tmp_path)
    assert list(written) == list(TABLE_FILES)
    assert all(p.is_file() and p.parent == tmp_path for p in written.values())
    assert not list(tmp_path.glob(".*tmp"))  # no temporary file left

    table = alerts_table(fleet)
    back = pq.read_table(written["alerts.parquet"])
    assert back.equals(table)
    assert back.column_names[0] == "drive"
    assert back.column("drive").to_pylist() == ["A", "A", "B"]  # by drive, then in order
    assert back.column("alert_id").to_pylist() == [0, 1, 0]
    assert back.column("confirmation").to_pylist() == ["CONFIRMED", None, None]
    # the first row's key order, every alert field
    assert back.column_names[1:] == list(fleet[1].alert_rows[0])
    assert back.schema.field("height_mm").type == pa.float64()  # null throughout

    with written["alerts.csv"].open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == back.num_rows
    assert list(rows[0]) == back.column_names
    assert [r["drive"] for r in rows] == ["A", "A", "B"]
    assert [float(r["t_s"]) for r in rows] == back.column("t_s").to_pylist()


def test_alert_columns_follow_alert_record_and_keep_their_types() -> None:
    known = alert_columns()
    assert list(known)[:2] == ["t_s", "t_emit_s"]
    assert {"alert_id", "height_std_mm", "confirmation", "ego_peak_mps2"} <= set(known)
    assert known["t_s"] == pa.float64()
    assert known["side"] == pa.string()
    assert known["alert_id"] == pa.int64()

    # an extra key in a later row: after the first row's keys; null-only columns typed
    row = _alert_row(0, 1.0)
    extra = dict(row, zeta="x", extra_gap_m=None)
    table = alerts_table([DriveOutcome("A", "done", alert_rows=[row, extra])])
    assert table.column_names == ["drive", *row, "extra_gap_m", "zeta"]
    assert table.schema.field("extra_gap_m").type == pa.float64()  # a unit: a number
    assert table.schema.field("zeta").type == pa.string()


# -- (b) the drives table -------------------------------------------------------------------
def test_drives_table_columns_units_and_values() -> None:
    table = drives_table(_fleet())
    names = table.column_names
    assert names == list(DRIVE_COLUMNS)
    for name in ("duration_s", "distance_km", "replay_s", "alerts_per_km", "alerts_per_hour"):
        assert name in names
    assert [f"mode_{m}_share" for m in MODES] == [n for n in names if n.startswith("mode_")]
    assert {"truth_expected", "truth_hits", "truth_false_alarms"} <= set(names)

    rows = {r["drive"]: r for r in table.to_pylist()}
    assert list(rows) == ["A", "B", "C", "D", "E"]
    a, b, c, d = rows["A"], rows["B"], rows["C"], rows["D"]
    assert a["alerts_per_km"] == pytest.approx(2 / 4.0, abs=1e-9)
    assert a["alerts_per_hour"] == pytest.approx(2 / (120 / 3600), abs=1e-9)
    assert b["alerts_per_km"] is None  # no speed input: no distance
    assert b["distance_km"] is None
    assert b["alerts_per_hour"] == pytest.approx(60.0, abs=1e-9)
    assert c["alerts_per_km"] == 0.0
    assert a["mode_VISUAL_ONLY_share"] == 0.5
    assert b["mode_IMU_ONLY_share"] == 0.0  # absent from a drive's modes: none of its time
    assert d["mode_FUSED_share"] is None  # failed before it ran: unknown
    assert (a["truth_expected"], a["truth_hits"], a["truth_false_alarms"]) == (3.0, 2.0, 1.0)
    assert c["truth_hits"] is None
    assert (a["decode_failures"], a["road_class"], a["worker"]) == (2, "B", "tcp://127.0.0.1:1")
    assert (d["status"], d["message"]) == ("failed", BAD_VIDEO)
    # the same types whatever the data
    assert drives_table([DriveOutcome("D", "failed", "x")]).schema == table.schema
    assert drives_table([]).schema == table.schema


# -- (c) the pooled figures -----------------------------------------------------------------
def test_fleet_figures_pool_by_hand() -> None:
    f = fleet_figures(_fleet())
    assert (f.drives, f.done, f.skipped, f.failed) == (5, 2, 1, 2)
    assert f.duration_h == pytest.approx(360 / 3600, abs=1e-12)
    assert f.distance_km == 6.0
    assert f.drives_with_distance == 2
    assert f.alerts == 3
    assert f.alerts_per_km == pytest.approx(2 / 6, abs=1e-12)  # B has no distance
    assert f.alerts_per_hour == pytest.approx(3 / 0.1, abs=1e-9)
    # time-weighted: 120 s half FUSED half VISUAL_ONLY, 60 s FUSED, 180 s IMU_ONLY
    assert f.mode_shares["FUSED"] == pytest.approx(120 / 360, abs=1e-12)
    assert f.mode_shares["VISUAL_ONLY"] == pytest.approx(60 / 360, abs=1e-12)
    assert f.mode_shares["IMU_ONLY"] == pytest.approx(180 / 360, abs=1e-12)
    assert f.mode_shares["DEGRADED"] == 0.0
    # truth: A 2 of 3 and 1 false alarm in 2 min, B 1 of 1 in 1 min, C none
    assert f.truth_drives == 2
    assert (f.truth_expected, f.truth_hits, f.false_alarms) == (4.0, 3.0, 1.0)
    assert f.recall == pytest.approx(3 / 4, abs=1e-12)
    assert f.truth_minutes == 3.0
    assert f.false_alarms_per_min == pytest.approx(1 / 3, abs=1e-12)


def test_fleet_figures_undefined_are_nan() -> None:
    f = fleet_figures([DriveOutcome("A", "done", frames=10, alerts=1)])
    assert f.alerts == 1
    assert not f.has_truth
    for x in (f.duration_h, f.distance_km, f.alerts_per_km, f.alerts_per_hour, f.recall):
        assert math.isnan(x)
    assert all(math.isnan(s) for s in f.mode_shares.values())
    empty = fleet_figures([])
    assert (empty.drives, empty.alerts) == (0, 0)
    assert math.isnan(empty.false_alarms_per_min)


# -- (d) the report -------------------------------------------------------------------------
def _check_png(path: Path) -> None:
    image = cv2.imread(str(path))
    assert image is not None
    assert image.size > 0


def test_report_lists_failed_drives_and_writes_a_png(tmp_path: Path) -> None:
    md, png = write_report(_fleet(), tmp_path, title="Test fleet", notes=["engine: local"])
    assert (md, png) == (tmp_path / "report.md", tmp_path / "report.png")
    text = md.read_text()
    assert text.startswith("# Test fleet\n")
    failed = text.split("## Failed drives")[1].split("##")[0]
    assert BAD_VIDEO in failed
    assert BAD_CAN.replace("|", "\\|") in failed  # a pipe would break nothing
    assert "**D**" in failed
    assert "**E**" in failed
    assert "## Detection against truth (pooled)" in text
    assert "| recall | 75 % |" in text
    assert "| false alarms per minute | 0.333 |" in text
    assert "- engine: local" in text
    for name in ("report.png", "alerts.parquet", "drives.csv"):
        assert f"({name})" in text
    assert "| A | done | 1200 | 2.0 | 4.00 | 2 | 0.50 | 60.0 | 50 % | B | 2 decode |" in text
    _check_png(png)


# -- (e) fleets with nothing to show --------------------------------------------------------
def test_all_failed_fleet_writes(tmp_path: Path) -> None:
    fleet = [DriveOutcome(f"d{i}", "failed", f"error {i}") for i in range(3)]
    written = write_tables(fleet, tmp_path)
    alerts = pq.read_table(written["alerts.parquet"])
    assert alerts.num_rows == 0
    assert alerts.column_names == ["drive", *alert_columns()]
    assert pq.read_table(written["drives.parquet"]).num_rows == 3
    md, png = write_report(fleet, tmp_path)
    text = md.read_text()
    assert all(f"**d{i}**: error {i}" in text for i in range(3))
    assert "Detection against truth" not in text
    _check_png(png)


def test_empty_alert_fleet_and_empty_fleet_write(tmp_path: Path) -> None:
    fleet = [
        DriveOutcome("quiet", "done", frames=100, duration_s=10.0, modes={"FUSED": 1.0}),
        DriveOutcome("still", "done", frames=100, duration_s=10.0, distance_km=0.0),
    ]
    written = write_tables(fleet, tmp_path)
    assert pq.read_table(written["alerts.parquet"]).num_rows == 0
    with written["alerts.csv"].open(newline="") as fh:
        assert next(csv.reader(fh)) == ["drive", *alert_columns()]
    md, png = write_report(fleet, tmp_path)
    assert "## Failed drives\n\nnone\n" in md.read_text()
    _check_png(png)

    empty = tmp_path / "empty"
    write_tables([], empty)
    _check_png(write_report([], empty)[1])


def test_hundreds_of_drives_are_capped_in_the_figure(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # a small cap keeps the test fast; what is checked is that the cap holds
    monkeypatch.setattr(report, "MAX_BARS", 8)
    fleet = [
        DriveOutcome(
            f"drive-{i:03d}",
            "done",
            duration_s=60.0,
            distance_km=1.0 if i % 2 else math.nan,
            alerts=i % 7,
            modes={"FUSED": 0.9, "DEGRADED": 0.1},
            truth={"expected": 2.0, "hits": float(i % 3), "false_alarms": 1.0, "minutes": 1.0},
        )
        for i in range(300)
    ]
    md, png = write_report(fleet, tmp_path)
    assert md.read_text().count("| drive-") == len(fleet)  # the Markdown lists them all
    image = cv2.imread(str(png))
    assert image is not None
    assert image.shape[0] < 600  # the panels hold 8 rows, not 300
