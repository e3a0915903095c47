"""Replay a recording through the pipeline and write its outputs (``roadpreview replay``).

Inputs: a simulator recording folder in one argument, or a video (with an
optional ``frames.csv`` of time stamps), CAN logs and/or an IMU CSV, a camera
calibration and a configuration. Streams are merged by time stamp lazily
(bounded memory). Outputs go to one folder: ``alerts.blf`` (RP_ALERT and
RP_STATUS), ``alerts.jsonl``, ``frames.csv``, ``plots.png``, ``summary.json``
and optionally ``annotated.mp4``.
"""

from __future__ import annotations

import json
import logging
import math
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from roadpreview.camera import CameraModel
from roadpreview.canbus.imu_csv import imu_samples, read_imu_csv
from roadpreview.errors import InputDataError
from roadpreview.pipeline.config import PipelineConfig
from roadpreview.pipeline.core import FrameResult, Pipeline
from roadpreview.pipeline.outputs import (
    AnnotatedVideoWriter,
    CanOutputLog,
    FrameTableWriter,
    SeriesRecorder,
    plot_run,
    write_jsonl,
)
from roadpreview.pipeline.sources import (
    CAN,
    CanSource,
    Item,
    VideoSource,
    first_timestamp,
    merge_streams,
)
from roadpreview.pipeline.truthmatch import MatchReport, match_alerts
from roadpreview.types import Alert, Confirmation, ConfirmationResult, FusionMode, RoadState

log = logging.getLogger(__name__)


@dataclass
class ReplayInputs:
    """What to replay. Times of the video are ``video_start_s`` + frame time (log clock)."""

    video: Path
    camera: CameraModel
    can_logs: list[Path] = field(default_factory=list)
    imu_csv: Path | None = None
    frames_csv: Path | None = None
    video_start_s: float | None = None
    truth_events: list[dict[str, Any]] | None = None
    duration_s: float | None = None

    @classmethod
    def from_recording(cls, folder: str | Path) -> ReplayInputs:
        """A simulator recording folder: video, CAN log, calibration, clocks, truth."""
        from roadpreview.sim.recording import Recording

        rec = Recording.open(folder)
        return cls(
            video=rec.video,
            camera=rec.camera,
            can_logs=[rec.can_log()],
            frames_csv=rec.folder / "frames.csv",
            video_start_s=float(rec.info["can_t0_unix_s"]),
            truth_events=rec.events,
            duration_s=float(rec.info["duration_s"]),
        )


@dataclass
class ReplayResult:
    frames: int
    alerts: list[Alert]
    mode_changes: list[tuple[float, FusionMode, str]]
    seconds: float
    video_start_s: float
    out: Path | None
    match: MatchReport | None = None
    decode_failures: int = 0
    input_errors: int = 0
    results: list[FrameResult] | None = None
    #: the ego's check of each alerted spot it passed
    confirmations: list[ConfirmationResult] = field(default_factory=list)
    road: RoadState = field(default_factory=RoadState)  #: the road class at the end

    @property
    def fps(self) -> float:
        return self.frames / self.seconds if self.seconds > 0 else math.nan


def _imu_csv_items(path: Path, offset_s: float) -> Iterator[Item]:
    for s in imu_samples(read_imu_csv(path), source=str(path)):
        yield (s.t_s + offset_s, CAN, s)


def replay(
    inputs: ReplayInputs,
    config: PipelineConfig | None = None,
    out: str | Path | None = None,
    *,
    annotated_video: bool = False,
    keep_results: bool = False,
    progress: Callable[[int, float], None] | None = None,
    max_frames: int | None = None,
) -> ReplayResult:
    """Run the pipeline over the inputs; write the outputs into ``out`` (if given)."""
    config = config or PipelineConfig()
    pipeline = Pipeline(inputs.camera, config)
    if inputs.video_start_s is not None:
        start = inputs.video_start_s
    elif inputs.can_logs:
        start = first_timestamp(inputs.can_logs[0])
    else:
        start = 0.0
    video = VideoSource(inputs.video, start_s=start, frames_csv=inputs.frames_csv)
    if video.size != inputs.camera.size:
        raise InputDataError(
            f"{inputs.video}: frames are {video.size[0]}x{video.size[1]} but the camera "
            f"calibration is for {inputs.camera.width}x{inputs.camera.height}"
        )
    sources: list[Any] = [video, *(CanSource(p) for p in inputs.can_logs)]
    if inputs.imu_csv is not None:
        sources.append(_imu_csv_items(inputs.imu_csv, start))
    out_dir = Path(out) if out is not None else None
    table = None
    annot = None
    can_out = CanOutputLog(config.can.status_period_s, detector=config.anomaly.detector)
    series = SeriesRecorder()
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        table = FrameTableWriter(out_dir / "frames.csv")
        if annotated_video:
            annot = AnnotatedVideoWriter(out_dir / "annotated.mp4", video.fps, video.size)
    alerts: list[Alert] = []
    confirmations: list[ConfirmationResult] = []
    modes: list[tuple[float, FusionMode, str]] = []
    results: list[FrameResult] = []
    frames = 0
    t_wall = time.perf_counter()
    last_t = -math.inf
    try:
        for t, kind, payload in merge_streams(sources):
            if kind == CAN:
                if hasattr(payload, "arbitration_id"):
                    pipeline.push_can(payload)
                else:
                    pipeline.push_imu(payload)
                continue
            if t <= last_t:
                log.warning("frame at %.6f s is not after the previous one; skipped", t)
                continue
            last_t = t
            r = pipeline.push_frame(t, payload)
            frames += 1
            if not modes or modes[-1][1] != r.mode:
                modes.append((t, r.mode, r.pitch_reason or r.vision_reason))
            alerts.extend(r.alerts)
            confirmations.extend(r.confirmations)
            can_out.frame(t, pipeline.status(), r.alerts, r.confirmations)
            series.add(r)
            if table is not None:
                table.write(r)
            if annot is not None:
                annot.write(payload, r)
            if keep_results:
                results.append(r)
            if progress is not None and frames % 30 == 0:
                progress(frames, time.perf_counter() - t_wall)
            if max_frames is not None and frames >= max_frames:
                break
    finally:
        if table is not None:
            table.close()
        if annot is not None:
            annot.close()
    tail = pipeline.finish()
    alerts.extend(tail)
    if tail:
        can_out.frame(last_t, pipeline.status(), tail)
    seconds = time.perf_counter() - t_wall
    if frames == 0:
        raise InputDataError(f"{inputs.video}: no frame could be read")
    match = None
    if inputs.truth_events is not None:
        duration = inputs.duration_s or (last_t - start)
        match = match_alerts(alerts, inputs.truth_events, t0=start, duration_s=duration)
    result = ReplayResult(
        frames=frames,
        alerts=alerts,
        mode_changes=modes,
        seconds=seconds,
        video_start_s=start,
        out=out_dir,
        match=match,
        decode_failures=video.decode_failures,
        input_errors=pipeline.can_decoder.stats.skipped,
        results=results if keep_results else None,
        confirmations=confirmations,
        road=pipeline.last.road if pipeline.last is not None else RoadState(),
    )
    if out_dir is not None:
        can_out.write(out_dir / "alerts.blf")
        write_jsonl(out_dir / "alerts.jsonl", alerts, confirmations)
        truth_times = [
            start + float(e["lead_front_t_s"])
            for e in inputs.truth_events or []
            if e.get("lead_front_t_s") is not None and e.get("lead_hits")
        ]
        plot_run(series, alerts, out_dir / "plots.png", t0=start, truth_times=truth_times)
        summary = {
            "frames": frames,
            "seconds": round(seconds, 3),
            "fps": round(result.fps, 2),
            "alerts": len(alerts),
            "video_decode_failures": video.decode_failures,
            "can_input_errors": pipeline.can_decoder.stats.skipped,
            "mode_changes": [
                {"t_s": round(t - start, 3), "mode": m.name, "reason": why} for t, m, why in modes
            ],
            "detector": config.anomaly.detector,
            "road_class": result.road.iso_class,
            "road_class_ego": result.road.ego_class,
            "road_class_lead": result.road.lead_class,
            "confirmations": {
                c.name: sum(x.outcome is c for x in confirmations) for c in Confirmation
            },
            "pending_confirmations": len(alerts) - len(confirmations),
        }
        if match is not None:
            summary["truth"] = {
                "expected": match.expected,
                "hits": match.hits,
                "false_alarms": len(match.false_alarms),
                "false_alarms_per_min": match.false_alarms_per_min,
            }
        (out_dir / "summary.json").write_text(json.dumps(summary, indent=2))
    return result


def format_alerts(
    alerts: Sequence[Alert], confirmations: Sequence[ConfirmationResult], t0: float
) -> str:
    """The alerts as a table (times from ``t0``), with the ego's confirmation of each."""
    felt = {c.alert_id: c for c in confirmations}
    lines = [
        "   id  crossing  distance  arrives in   height            side   confidence  ego felt"
    ]
    for a in alerts:
        c = felt.get(a.alert_id)
        height = "      -       " if a.height_mm is None else f"{a.height_mm:+5.0f} mm"
        if a.height_mm is not None and a.height_std_mm is not None:
            height += f" ± {a.height_std_mm:3.0f}"
        dist = "   -   " if a.distance_m is None else f"{a.distance_m:5.1f} m"
        tta = "   -   " if a.time_to_arrival_s is None else f"{a.time_to_arrival_s:5.2f} s"
        outcome = "pending" if c is None else c.outcome.name
        if c is not None and math.isfinite(c.peak_mps2):
            outcome += f" ({c.peak_mps2:.1f} m/s²)"
        lines.append(
            f"{a.alert_id:5d}  {a.t_s - t0:7.2f} s  {dist}  {tta}    {height:16s}  "
            f"{a.side.name:5s}  {100 * a.confidence:8.0f} %  {outcome}"
        )
    return "\n".join(lines) if alerts else "   (none)"


def print_progress(frames: int, seconds: float) -> None:
    """A one-line progress display on stderr (frames and frames per second)."""
    if sys.stderr.isatty():
        print(
            f"\r  {frames} frames, {frames / max(seconds, 1e-9):5.1f} fps", end="", file=sys.stderr
        )


def format_modes(modes: Sequence[tuple[float, FusionMode, str]], start: float) -> str:
    return "\n".join(f"  {t - start:7.2f} s  {m.name:11s} {why}" for t, m, why in modes)
