"""File sinks: the alerts as JSON lines, the per-frame table, the plots and the annotated
video (the CAN log is `roadpreview.sinks.can.CanLogSink`)."""

from __future__ import annotations

import csv
import json
import math
import os
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import cv2
import numpy as np

from roadpreview.pipeline.pipeline import FrameResult
from roadpreview.sinks import Sink
from roadpreview.types import Alert, CameraFrame, ConfirmationResult, FusionMode, Image, Status

if TYPE_CHECKING:
    from roadpreview.pipeline.run_summary import RunSummary


def alert_json(alert: Alert) -> dict[str, Any]:
    d = asdict(alert)
    d["side"] = alert.side.name
    d["mode"] = alert.mode.name
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in d.items()}


#: `FrameResult.COLUMNS` -> the frame table's column: every name says its unit (``_px``,
#: ``_rad``, ``_m``, ``_s``, ...); counts, flags, codes and classes have none
FRAME_TABLE_NAMES: dict[str, str] = {
    "t": "t_unix_s",
    "index": "frame_index",
    "y": "y_px",
    "y_left": "y_left_px",
    "y_right": "y_right_px",
    "y_c": "y_c_px",
    "phi": "phi_rad",
    "phi_std": "phi_std_rad",
    "mode": "mode",
    "bias": "gyro_bias_rad_s",
    "time_offset": "imu_time_offset_s",
    "s": "s_px",
    "s_left": "s_left_px",
    "s_right": "s_right_px",
    "threshold_px": "threshold_px",
    "suppressed": "suppressed_code",
    "lead_found": "lead_found",
    "lead_distance_m": "lead_distance_m",
    "n_lead_points": "n_lead_points",
    "n_background": "n_background_points",
    "textured": "textured",
    "n_events": "n_events",
    "heave_m": "heave_m",
    "heave_px": "heave_px",
    "score": "score",
    "score_threshold": "score_threshold",
    "score_t": "score_t_unix_s",
    "road_input_mm": "road_input_mm",
    "background_mm": "background_mm",
    "ego_accel_peak_mps2": "ego_accel_peak_mps2",
    "road_class": "road_class",
}


def frame_table_columns() -> tuple[str, ...]:
    """The header of ``frames.csv``: `FrameResult.COLUMNS` with their units, ``t_rel_s``
    (seconds since the first frame) after ``t_unix_s``, and the ego's and lead's speed
    terms at the end."""
    names = [FRAME_TABLE_NAMES.get(c, c) for c in FrameResult.COLUMNS]
    names.insert(1, "t_rel_s")
    return (*names, "ego_speed_mps", "lead_accel_mps2")


class FrameTableWriter:
    """The per-frame table as CSV (`frame_table_columns`), written as frames come (bounded
    memory). ``t_unix_s`` is the pipeline's clock (Unix time when the inputs carry it, as
    recordings and CAN logs do); ``t_rel_s`` is measured from ``t0`` (default: the first
    frame written)."""

    def __init__(self, path: Path, *, t0: float | None = None) -> None:
        self._fh: TextIO = path.open("w", newline="")
        self._w = csv.writer(self._fh)
        self.columns = frame_table_columns()
        self._w.writerow(self.columns)
        self.t0 = t0

    #: columns that are times: they keep microseconds whatever their epoch
    TIME_COLUMNS = frozenset({"t_unix_s", "t_rel_s", "score_t_unix_s"})

    def write(self, r: FrameResult) -> None:
        if self.t0 is None:
            self.t0 = r.t
        values = r.row()
        values.insert(1, r.t - self.t0)
        values += [
            math.nan if r.ego_speed_mps is None else r.ego_speed_mps,
            math.nan if r.lead_accel_mps2 is None else r.lead_accel_mps2,
        ]
        # times with microseconds, the rest with 6 significant digits
        self._w.writerow(
            [
                (f"{v:.6f}" if name in self.TIME_COLUMNS else f"{v:.6g}")
                if isinstance(v, float)
                else v
                for name, v in zip(self.columns, values, strict=True)
            ]
        )

    def flush(self) -> None:
        self._fh.flush()

    def close(self) -> None:
        self._fh.close()


class SeriesRecorder:
    """The few per-frame series the plots need, as arrays."""

    def __init__(self) -> None:
        self.cols: dict[str, list[float]] = {
            k: [] for k in ("t", "y", "y_c", "phi", "s", "thr", "mode")
        }

    def add(self, r: FrameResult) -> None:
        c = self.cols
        c["t"].append(r.t)
        c["y"].append(r.y)
        c["y_c"].append(r.y_c)
        c["phi"].append(r.phi)
        c["s"].append(r.s)
        c["thr"].append(r.threshold_px)
        c["mode"].append(float(r.mode))


def plot_run(
    rec: SeriesRecorder,
    alerts: Sequence[Alert],
    path: Path,
    *,
    t0: float = 0.0,
    truth_times: Sequence[float] = (),
) -> None:
    """y and y_c, pitch, s(t) with threshold and alerts, and the mode band, as one PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = {k: np.asarray(v, float) for k, v in rec.cols.items()}
    t = c["t"] - t0
    fig, ax = plt.subplots(
        4, 1, figsize=(12, 9), sharex=True, gridspec_kw={"height_ratios": [3, 2, 3, 0.6]}
    )
    ax[0].plot(t, c["y"] - np.nanmedian(c["y"]), lw=0.8, label="y (lead, raw)")
    ax[0].plot(t, c["y_c"] - np.nanmedian(c["y_c"]), lw=0.8, label="y_c (compensated)")
    ax[0].set_ylabel("px (median removed)")
    ax[0].invert_yaxis()
    ax[0].legend(loc="upper right")
    ax[1].plot(t, np.degrees(c["phi"]), lw=0.8, color="tab:green")
    ax[1].set_ylabel("pitch φ (deg)")
    ax[2].plot(t, c["s"], lw=0.9, label="s(t)")
    ax[2].plot(t, c["thr"], lw=0.8, ls="--", color="k", label="threshold")
    for i, a in enumerate(alerts):
        ax[2].axvline(a.t_s - t0, color="tab:red", lw=1.0, label="alert" if i == 0 else None)
    for i, tt in enumerate(truth_times):
        ax[2].axvline(
            tt - t0,
            color="tab:gray",
            lw=0.8,
            ls=":",
            label="lead crosses (truth)" if i == 0 else None,
        )
    ax[2].set_ylabel("s (px)")
    ax[2].legend(loc="upper right")
    colours = {
        FusionMode.FUSED: "tab:green",
        FusionMode.VISUAL_ONLY: "tab:blue",
        FusionMode.IMU_ONLY: "tab:orange",
        FusionMode.DEGRADED: "tab:red",
    }
    for mode, colour in colours.items():
        ax[3].fill_between(
            t,
            0,
            1,
            where=c["mode"] == int(mode),
            color=colour,
            step="mid",
            label=mode.name,
            linewidth=0,
        )
    ax[3].set_yticks([])
    ax[3].set_ylabel("mode")
    ax[3].legend(loc="upper right", ncol=4, fontsize=7)
    clock = f"; frame 0 at Unix {t0:.3f} s" if t0 > 1e8 else ""
    ax[3].set_xlabel(f"time since frame 0 (s){clock}")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


class AnnotatedVideoWriter:
    """The input video with tracked box, y(t), the s(t) gauge and the mode drawn on it."""

    def __init__(self, path: Path, fps: float, size: tuple[int, int]) -> None:
        self._w = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"mp4v"), fps, size)
        self.size = size

    def write(self, frame: Image | None, r: FrameResult) -> None:
        if frame is None:
            frame = np.zeros((self.size[1], self.size[0], 3), np.uint8)
        img = frame.copy()
        if r.lead_box is not None:
            x0, y0, x1, y1 = (round(v) for v in r.lead_box)
            cv2.rectangle(img, (x0, y0), (x1, y1), (0, 255, 0), 2)
            if math.isfinite(r.y):
                cv2.line(img, (x0, int(r.y)), (x1, int(r.y)), (0, 255, 255), 1)
        h = img.shape[0]
        level = 0.0 if not math.isfinite(r.s) else min(1.0, r.s / max(2 * r.threshold_px, 1e-6))
        cv2.rectangle(
            img,
            (10, h - 20),
            (10 + int(200 * level), h - 10),
            (0, 0, 255) if r.s > r.threshold_px else (0, 200, 0),
            -1,
        )
        cv2.rectangle(img, (10, h - 20), (210, h - 10), (255, 255, 255), 1)
        phi_deg = math.degrees(r.phi) if math.isfinite(r.phi) else 0.0
        text = f"{r.mode.name}  phi {phi_deg:+.2f} deg  s {r.s:.2f} px"
        cv2.putText(img, text, (10, h - 28), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1)
        if r.alerts:
            cv2.putText(img, "ALERT", (10, 30), cv2.FONT_HERSHEY_SIMPLEX, 1.0, (0, 0, 255), 2)
        self._w.write(img)

    def close(self) -> None:
        self._w.release()


def write_jsonl(
    path: Path, alerts: Sequence[Alert], confirmations: Sequence[ConfirmationResult] = ()
) -> None:
    """One JSON object per alert; an alert whose spot the ego passed carries what it felt
    there (``confirmation``: CONFIRMED / NOT_FELT / UNKNOWN, ``confirmation_t_s``,
    ``ego_peak_mps2``, ``ego_background_mps2``, ``ego_arrival_t_s``); null while pending."""
    by_id = {c.alert_id: c for c in confirmations}
    with path.open("w") as fh:
        for a in alerts:
            fh.write(json.dumps(alert_record(a, by_id.get(a.alert_id))) + "\n")


def alert_record(alert: Alert, c: ConfirmationResult | None) -> dict[str, Any]:
    """One line of ``alerts.jsonl``: the alert and its confirmation (None: pending)."""
    d = alert_json(alert)
    d["confirmation"] = None if c is None else c.outcome.name
    for key, value in (
        ("confirmation_t_s", None if c is None else c.t_s),
        ("ego_arrival_t_s", None if c is None else c.t_arrival_s),
        ("ego_peak_mps2", None if c is None else c.peak_mps2),
        ("ego_background_mps2", None if c is None else c.background_mps2),
    ):
        d[key] = value if value is None or math.isfinite(value) else None
    return d


# -- the sinks ------------------------------------------------------------------------------
class FrameTableSink(Sink):
    """``frames.csv``: one row per frame (`frame_table_columns`; ``t_rel_s`` from ``t0``,
    default the first frame), flushed every ``flush_every`` frames so that an interrupt
    keeps what was processed."""

    def __init__(self, path: str | Path, *, flush_every: int = 30, t0: float | None = None) -> None:
        self.writer = FrameTableWriter(Path(path), t0=t0)
        self.flush_every = flush_every
        self._n = 0

    def on_frame(self, frame: CameraFrame, result: FrameResult, status: Status) -> None:
        self.writer.write(result)
        self._n += 1
        if self._n % self.flush_every == 0:
            self.writer.flush()

    def close(self, summary: RunSummary) -> None:
        self.writer.close()


class AlertsJsonlSink(Sink):
    """``alerts.jsonl``: one JSON object per alert, appended (and flushed) as the alert is
    emitted; at close the file is rewritten (atomically) with what the ego felt at each
    alerted spot it passed (`write_jsonl`)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._fh: TextIO | None = self.path.open("w")
        self.alerts: list[Alert] = []
        self.confirmations: list[ConfirmationResult] = []

    def _append(self, alerts: Sequence[Alert]) -> None:
        for a in alerts:
            self.alerts.append(a)
            if self._fh is not None:
                self._fh.write(json.dumps(alert_record(a, None)) + "\n")
        if alerts and self._fh is not None:
            self._fh.flush()

    def on_frame(self, frame: CameraFrame, result: FrameResult, status: Status) -> None:
        self._append(result.alerts)
        self.confirmations.extend(result.confirmations)

    def on_flush(self, t_s: float, alerts: Sequence[Alert], status: Status) -> None:
        self._append(alerts)

    def close(self, summary: RunSummary) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None
        tmp = self.path.with_name(self.path.name + ".tmp")
        write_jsonl(tmp, self.alerts, self.confirmations)
        os.replace(tmp, self.path)


class PlotSink(Sink):
    """``plots.png`` at close (`plot_run`), times from ``t0``; ``truth_times``: when the
    lead crossed the true anomalies (pipeline clock)."""

    def __init__(
        self, path: str | Path, *, t0: float = 0.0, truth_times: Sequence[float] = ()
    ) -> None:
        self.path = Path(path)
        self.t0 = t0
        self.truth_times = list(truth_times)
        self.series = SeriesRecorder()
        self.alerts: list[Alert] = []

    def on_frame(self, frame: CameraFrame, result: FrameResult, status: Status) -> None:
        self.series.add(result)
        self.alerts.extend(result.alerts)

    def on_flush(self, t_s: float, alerts: Sequence[Alert], status: Status) -> None:
        self.alerts.extend(alerts)

    def close(self, summary: RunSummary) -> None:
        if self.series.cols["t"]:
            plot_run(self.series, self.alerts, self.path, t0=self.t0, truth_times=self.truth_times)


class AnnotatedVideoSink(Sink):
    """``annotated.mp4``: the input frames with the tracked box, y(t), the s(t) gauge and
    the mode drawn on them."""

    def __init__(self, path: str | Path, fps: float, size: tuple[int, int]) -> None:
        self.writer = AnnotatedVideoWriter(Path(path), fps, size)

    def on_frame(self, frame: CameraFrame, result: FrameResult, status: Status) -> None:
        self.writer.write(frame.image, result)

    def close(self, summary: RunSummary) -> None:
        self.writer.close()


class ResultsSink(Sink):
    """Every `FrameResult` kept in memory (tests, notebooks; a long drive is large)."""

    def __init__(self) -> None:
        self.results: list[FrameResult] = []

    def on_frame(self, frame: CameraFrame, result: FrameResult, status: Status) -> None:
        self.results.append(result)
