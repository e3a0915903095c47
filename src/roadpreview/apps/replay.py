"""Replay a recording through the pipeline and write its outputs (``roadpreview replay``).

A thin composition of the run loop: file sources (a recording folder in one argument,
or a video with an optional ``frames.csv``, CAN logs and/or an IMU CSV) -> `Pipeline`
-> file sinks, all in one output folder: ``alerts.blf`` (RP_ALERT, RP_ALERT_DETAIL,
RP_ALERT_END, RP_CONFIRM, RP_STATUS, RP_ROAD_STATUS, RP_INPUT_STATUS), ``alerts.jsonl``,
``frames.csv``,
``plots.png``, ``summary.json`` and optionally ``annotated.mp4``. The sinks stream, so
an interrupt (``stop``, set by SIGINT/SIGTERM in the CLI) keeps every alert emitted so
far; the summary then says ``"interrupted": true``.

An input that gives nothing (a CAN log without a frame, or none of whose frames maps to
an IMU or speed sample; an IMU CSV without a valid row) does not stop the replay: the
drive runs without it, a one-line error names it, and ``ReplayResult.unusable_inputs``
and summary.json's ``unusable_inputs`` say so (``roadpreview replay`` then exits 1
unless ``--allow-missing``). A source that keeps failing (`SourceFailed`) ends the run;
the outputs and the summary are written up to it, then the error is raised.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from roadpreview.apps.progress import Progress
from roadpreview.apps.result import ReplayResult
from roadpreview.apps.summary import write_summary
from roadpreview.camera import CameraModel
from roadpreview.canbus.imu_csv import read_imu_csv
from roadpreview.canbus.mapping import load_mapping
from roadpreview.errors import ConfigError, InputDataError
from roadpreview.loop import Pace, RunSummary, SourceFailed, run
from roadpreview.pipeline.config import PipelineConfig
from roadpreview.pipeline.pipeline import Pipeline
from roadpreview.pipeline.truthmatch import match_alerts
from roadpreview.sinks import Sink
from roadpreview.sinks.can import CanLogSink, CanMemorySink, repetition_config
from roadpreview.sinks.files import (
    AlertsJsonlSink,
    AnnotatedVideoSink,
    FrameTableSink,
    PlotSink,
    ResultsSink,
)
from roadpreview.sources import Source
from roadpreview.sources.can import CanLogSource, first_timestamp, make_decoder
from roadpreview.sources.clockguard import ClockGuard
from roadpreview.sources.clocks import (
    CameraClock,
    ClockPlan,
    LogClock,
    VideoTime,
    is_unix_time,
    plan_clocks,
    video_file_time,
)
from roadpreview.sources.imu_csv import ImuCsvSource
from roadpreview.sources.recording import RecordingFolder
from roadpreview.sources.rosbag import (
    IMU_TYPES,
    BagCameraSource,
    BagSampleSource,
    RosBag,
    choose_topics,
    is_bag,
)
from roadpreview.sources.video import VideoFileSource, frame_times
from roadpreview.sources.window import WindowedSource
from roadpreview.types import Alert, ConfirmationResult, FusionMode

log = logging.getLogger(__name__)


@dataclass
class ReplayInputs:
    """What to replay. ``video`` is the camera input: a video file, or a ROS bag (a
    rosbag2 folder, ``.mcap``, ``.db3`` or ROS 1 ``.bag``: `is_bag`) whose image topic is
    the camera and whose IMU and speed topics are read too; with CAN logs and/or an IMU
    CSV. `sources` puts every input on one clock before anything is read
    (`roadpreview.sources.clocks`): ``video_start_s`` pins the camera's time 0,
    ``can_offset_s`` / ``imu_offset_s`` are added to the logs' stamps; None: by the rules
    there (mixed clocks are refused)."""

    video: Path
    camera: CameraModel
    can_logs: list[Path] = field(default_factory=list)
    imu_csv: Path | None = None
    frames_csv: Path | None = None
    video_start_s: float | None = None
    truth_events: list[dict[str, Any]] | None = None
    duration_s: float | None = None
    image_topic: str | None = None  #: the bag's camera topic; None: the only image topic
    imu_topic: str | None = None  #: the bag's IMU topic; None: the only Imu topic, if any
    speed_topic: str | None = None  #: the bag's speed topic; None: the only twist/odometry
    can_offset_s: float | None = None
    imu_offset_s: float | None = None
    #: how `sources` put each input on the drive's clock (filled by `sources`)
    clock_notes: list[str] = field(default_factory=list, compare=False)
    #: the calibration file ``camera`` was read from (an input of the replay: summary.json)
    camera_file: Path | None = None

    @classmethod
    def from_recording(cls, folder: str | Path) -> ReplayInputs:
        """A recording folder: video, CAN log, calibration, clocks, truth."""
        rec = RecordingFolder.open(folder)
        return cls(
            video=rec.video,
            camera=rec.camera,
            can_logs=[rec.can_log()],
            frames_csv=rec.frames_csv,
            video_start_s=rec.t0_unix_s,
            truth_events=rec.events,
            duration_s=rec.duration_s,
            camera_file=rec.folder / "camera.toml",
        )

    @property
    def start_s(self) -> float:
        """The time of the camera's own time 0 on the drive's clock (`sources`)."""
        return self._clock_plan()[2].camera_start_s

    def _camera(
        self,
    ) -> tuple[VideoFileSource | BagCameraSource, CameraClock, list[BagSampleSource]]:
        """The camera source (not yet on the drive's clock), its clock, and the bag's IMU
        and speed topics (on the camera's clock)."""
        if is_bag(self.video):
            bag = RosBag(self.video)
            topics = choose_topics(
                bag.topics,
                image=self.image_topic,
                imu=self.imu_topic,
                speed=self.speed_topic,
                where=str(self.video),
            )
            others = [BagSampleSource(bag, t) for t in (topics.imu, topics.speed) if t]
            own_t = bag.path.stat().st_mtime - bag.duration_s
            clock = CameraClock(
                f"bag {bag.path} ({topics.image})",
                bag.first_stamp(topics.image),
                0.0 if self.video_start_s is None else self.video_start_s,
                VideoTime(own_t, "the bag's modification time minus its duration"),
            )
            return BagCameraSource(bag, topics.image), clock, others
        if any(t is not None for t in (self.image_topic, self.imu_topic, self.speed_topic)):
            raise ConfigError(f"{self.video}: topics are for a ROS bag input, not a video")
        video = VideoFileSource(self.video, frames_csv=self.frames_csv)
        first_rel = 0.0
        if video.frames_csv is not None:
            first_rel = next(frame_times(video.frames_csv), 0.0)
        pinned = self.video_start_s
        if pinned is None and is_unix_time(first_rel):
            pinned = 0.0  # frames.csv holds Unix times: the frames carry their own clock
        duration = video.n_frames / video.fps if video.fps > 0 else 0.0
        clock = CameraClock(
            f"video {video.path}", first_rel, pinned, video_file_time(video.path, duration)
        )
        return video, clock, []

    def _clock_plan(
        self, config: PipelineConfig | None = None
    ) -> tuple[VideoFileSource | BagCameraSource, list[Source], ClockPlan]:
        """Every source, on the drive's clock (`plan_clocks`), and the plan."""
        camera, clock, others = self._camera()
        logs: list[tuple[CanLogSource | ImuCsvSource, LogClock]] = []
        if self.can_logs:
            cfg = config or PipelineConfig()
            for path in self.can_logs:  # a decoder per log: its own E2E state and counts
                decoder = make_decoder(cfg.can.dbc, cfg.can.mapping, cfg.plausibility)
                first = first_timestamp(path)
                clock_of = LogClock(f"CAN log {path}", first, self.can_offset_s, "--can-offset")
                logs.append((CanLogSource(path, decoder), clock_of))
        if self.imu_csv is not None:
            mapping = (config or PipelineConfig()).can.mapping  # a calibrated [mount], if any
            mount = load_mapping(mapping).mount if mapping else None
            gate = (config or PipelineConfig()).plausibility
            imu = ImuCsvSource(self.imu_csv, mount=mount, plausibility=gate)
            clock_of = LogClock(
                f"IMU CSV {self.imu_csv}", imu.first_s, self.imu_offset_s, "--imu-offset"
            )
            logs.append((imu, clock_of))
        plan = plan_clocks(clock, [c for _, c in logs])
        camera.start_s = plan.camera_start_s
        for topic in others:
            topic.offset_s = plan.camera_start_s
        for src, c in logs:
            src.offset_s = plan.offsets_s[c.name]
        return camera, [camera, *others, *(src for src, _ in logs)], plan

    def sources(
        self, config: PipelineConfig
    ) -> tuple[VideoFileSource | BagCameraSource, list[Source]]:
        """The camera source (size checked against the calibration) and all sources, every
        one on the drive's clock (class docstring); the clock rules used are logged."""
        camera, sources, plan = self._clock_plan(config)
        camera.check_size(self.camera.size)
        self.clock_notes = [*plan.notes, *plan.warnings]  # for summary.json
        for note in plan.notes:
            log.info("clock: %s", note)
        for warning in plan.warnings:
            log.warning("clock: %s", warning)
        if not any(isinstance(s, ImuCsvSource | CanLogSource) for s in sources) and not any(
            isinstance(s, BagSampleSource) and s.msgtype in IMU_TYPES for s in sources
        ):
            log.warning("%s: no IMU input: vision-only fusion (VISUAL_ONLY)", self.video)
            self.clock_notes.append("no IMU input: vision-only fusion (VISUAL_ONLY)")
        # every other input's clock checked against its own stamps: lone stray stamps
        # dropped, clock steps taken off (the camera is the time base; the loop skips a
        # frame stamped before its predecessor)
        return camera, [s if s is camera else ClockGuard(s) for s in sources]


def drive_inputs(
    path: Path,
    *,
    camera: Path | None = None,
    can_logs: Sequence[Path] = (),
    imu_csv: Path | None = None,
    frames_csv: Path | None = None,
    video_start_s: float | None = None,
    can_offset_s: float | None = None,
    imu_offset_s: float | None = None,
    image_topic: str | None = None,
    imu_topic: str | None = None,
    speed_topic: str | None = None,
    truth: bool = False,
) -> ReplayInputs:
    """The drive at ``path`` (a recording folder, a video or a ROS bag) with its companion
    inputs, as ``roadpreview replay`` and ``roadpreview batch`` take them; truth events
    are kept only with ``truth`` (a recording folder's)."""
    path = Path(path)
    if not path.exists():
        raise InputDataError(f"{path}: no such recording folder, video or bag")
    if path.is_dir() and not is_bag(path):
        inputs = ReplayInputs.from_recording(path)
        if not truth:
            inputs.truth_events = None
        return inputs
    if camera is None:
        raise ConfigError(f"--camera: a camera calibration is needed for {path}")
    if truth:
        raise ConfigError(f"{path}: --truth needs a simulator recording folder")
    return ReplayInputs(
        video=path,
        camera=CameraModel.load(camera),
        can_logs=list(can_logs),
        imu_csv=imu_csv,
        frames_csv=frames_csv,
        video_start_s=video_start_s,
        image_topic=image_topic,
        imu_topic=imu_topic,
        speed_topic=speed_topic,
        can_offset_s=can_offset_s,
        imu_offset_s=imu_offset_s,
        camera_file=Path(camera),
    )


#: the files `replay` writes into its output folder
OUTPUT_FILES = (
    "alerts.blf",
    "alerts.jsonl",
    "alerts.jsonl.tmp",
    "frames.csv",
    "plots.png",
    "summary.json",
    "summary.json.tmp",
    "annotated.mp4",
)


def replay(
    inputs: ReplayInputs,
    config: PipelineConfig | None = None,
    out: str | Path | None = None,
    *,
    annotated_video: bool = False,
    keep_results: bool = False,
    progress: Progress | Callable[[int, float], None] | None = None,
    max_frames: int | None = None,
    pace: Pace | None = None,
    stop: threading.Event | None = None,
    start_s: float | None = None,
    end_s: float | None = None,
    more_inputs: Sequence[Path] = (),
) -> ReplayResult:
    """Run the pipeline over the inputs; write the outputs into ``out`` (if given).

    ``start_s`` / ``end_s``: only the part of the drive between these times, in seconds
    from the video's frame 0 (`WindowedSource`). ``progress``: called with (frames, wall
    seconds) as the run goes; a `Progress` is also told the number of frames to expect."""
    config = config or PipelineConfig()
    inputs, unusable = _usable_inputs(inputs)
    video, sources = inputs.sources(config)
    start = video.start_s
    if start_s is not None or end_s is not None:
        lo = -math.inf if start_s is None else start + start_s
        hi = math.inf if end_s is None else start + end_s
        if not lo < hi:
            raise ConfigError(f"--start {start_s} s must be before --end {end_s} s")
        sources = [WindowedSource(s, lo, hi) for s in sources]
    pipeline = Pipeline(inputs.camera, config)
    out_dir = Path(out) if out is not None else None
    sinks: list[Sink] = []
    collected = ResultsSink() if keep_results else None
    if collected is not None:
        sinks.append(collected)
    if out_dir is None:  # the CAN output is encoded anyway (what an ECU would get), kept here
        sinks.append(
            CanMemorySink(detector=config.anomaly.detector, repetition=repetition_config(config))
        )
    else:
        out_dir.mkdir(parents=True, exist_ok=True)
        truth_times = [
            start + float(e["lead_front_t_s"])
            for e in inputs.truth_events or []
            if e.get("lead_front_t_s") is not None and e.get("lead_hits")
        ]
        sinks += [
            FrameTableSink(out_dir / "frames.csv", t0=start),
            CanLogSink(
                out_dir / "alerts.blf",
                detector=config.anomaly.detector,
                repetition=repetition_config(config),
            ),
            AlertsJsonlSink(out_dir / "alerts.jsonl"),
            PlotSink(out_dir / "plots.png", t0=start, truth_times=truth_times),
        ]
        if annotated_video:
            sinks.append(AnnotatedVideoSink(out_dir / "annotated.mp4", video.fps, video.size))
    if isinstance(progress, Progress):
        progress.start(expected_frames(video, start_s, end_s, max_frames))
    failure: SourceFailed | None = None
    try:
        summary = run(
            sources,
            pipeline,
            sinks,
            pace=pace,
            stop=stop,
            status_period_s=config.can.status_period_s,
            frame_hold_s=pipeline.frame_hold_s,
            max_frames=max_frames,
            progress=progress,
        )
    except SourceFailed as exc:  # the outputs up to it are closed: summarise them too
        if isinstance(progress, Progress):
            progress.close()
        if exc.summary is None:
            raise
        summary, failure = exc.summary, exc
    except BaseException:
        if isinstance(progress, Progress):
            progress.close()
        raise
    if isinstance(progress, Progress) and failure is None:
        progress.close(summary.frames)
    if not summary.interrupted:
        unusable += _unmapped_logs(sources)
    if summary.frames == 0:
        if failure is not None:
            raise failure
        window = "" if start_s is None and end_s is None else " in the --start/--end window"
        raise InputDataError(f"{inputs.video}: no frame could be read{window}")
    match = None
    if inputs.truth_events is not None:
        events = inputs.truth_events
        duration = inputs.duration_s or (summary.last_t - start)
        if start_s is not None or end_s is not None:  # the events of the window only
            duration = summary.last_t - summary.first_t
            events = [e for e in events if _in_window(e, start, summary)]
        match = match_alerts(
            summary.alerts,
            events,
            t0=start,
            duration_s=duration,
            provisional=summary.provisional,
            cancelled=summary.cancelled,
        )
    result = ReplayResult(
        run=summary,
        video_start_s=start,
        out=out_dir,
        match=match,
        results=collected.results if collected is not None else None,
        video_name=video.name,
        clock_notes=list(inputs.clock_notes),
        unusable_inputs=unusable,
    )
    if out_dir is not None:
        dropped = [Path(u["path"]) for u in unusable if Path(u["path"]).is_file()]
        files = [*input_files(inputs, sources), *dropped, *more_inputs]
        write_summary(out_dir / "summary.json", result, config, files=files)
    if failure is not None:
        raise failure
    return result


def _usable_inputs(inputs: ReplayInputs) -> tuple[ReplayInputs, list[dict[str, str]]]:
    """``inputs`` without the CAN logs that hold no frame and the IMU CSV without a valid
    row (each logged as an error), and what was left out: ``{"path", "reason"}``. A file
    that does not exist is left in (the sources say so, and the replay stops)."""
    unusable: list[dict[str, str]] = []
    logs = []
    for path in inputs.can_logs:
        try:
            if Path(path).is_file():
                first_timestamp(path)
        except InputDataError as exc:
            unusable.append({"path": str(path), "reason": str(exc)})
            log.error("%s; the drive is replayed without it", exc)
            continue
        logs.append(path)
    imu_csv = inputs.imu_csv
    if imu_csv is not None and Path(imu_csv).is_file():
        try:
            read_imu_csv(imu_csv)
        except InputDataError as exc:
            unusable.append({"path": str(imu_csv), "reason": str(exc)})
            log.error("%s; the drive is replayed without it", exc)
            imu_csv = None
    if not unusable:
        return inputs, []
    return replace(inputs, can_logs=logs, imu_csv=imu_csv), unusable


def _unmapped_logs(sources: Sequence[Source]) -> list[dict[str, str]]:
    """The CAN logs read to their end of which no frame gave an IMU or speed sample."""
    out = []
    for s in sources:
        inner = getattr(s, "source", s)  # a WindowedSource's
        if isinstance(inner, CanLogSource) and inner.samples == 0:
            why = (
                f"{inner.path}: none of its {inner.frames} frames maps to an IMU or speed "
                f"sample (DBC {inner.decoder.db_name}, mapping {inner.decoder.mapping.source})"
            )
            log.error("%s; the drive ran without it", why)
            out.append({"path": str(inner.path), "reason": why})
    return out


def _in_window(event: dict[str, Any], start: float, summary: RunSummary) -> bool:
    """Whether the lead crosses the true ``event`` within the frames the replay saw."""
    t = event.get("lead_front_t_s")
    if t is None or math.isnan(summary.first_t):
        return True
    return bool(summary.first_t <= start + float(t) <= summary.last_t)


def expected_frames(
    video: VideoFileSource | BagCameraSource,
    start_s: float | None,
    end_s: float | None,
    max_frames: int | None,
) -> int | None:
    """About how many frames a replay of ``video`` (cut to the window) will process."""
    n = video.n_frames
    if n <= 0:
        return max_frames
    first = 0 if start_s is None else max(0, math.ceil(start_s * video.fps - 1e-6))
    last = n if end_s is None else min(n, math.floor(end_s * video.fps + 1e-6) + 1)
    total = max(0, last - first)
    return total if max_frames is None else min(total, max_frames)


def input_files(inputs: ReplayInputs, sources: Sequence[Source]) -> list[Path]:
    """The files a replay reads: every file source, the frame time stamps, and the
    recording's calibration and truth when the video sits in a recording folder."""
    paths: list[Path] = []
    for s in sources:
        inner = getattr(s, "source", s)  # a WindowedSource's
        path = getattr(inner, "path", None) or Path(s.name)
        if isinstance(path, Path) and path.is_file():
            paths.append(path)
    for extra in (getattr(inputs, "frames_csv", None), getattr(inputs, "camera_file", None)):
        if extra is not None and Path(extra).is_file():
            paths.append(Path(extra))
    folder = Path(inputs.video).parent
    for name in ("scenario.toml", "truth.json"):
        if (folder / name).is_file() and inputs.truth_events is not None:
            paths.append(folder / name)
    return paths


def format_alerts(
    alerts: Sequence[Alert],
    confirmations: Sequence[ConfirmationResult],
    t0: float,
    cancelled: Sequence[Alert] = (),
) -> str:
    """The alerts as a table (times from ``t0``), with when each was first sent (its
    provisional alert, if any) and confirmed, and the ego's confirmation of each; then the
    provisional alerts that were cancelled."""
    felt = {c.alert_id: c for c in confirmations}
    lines = [
        "   id  crossing  first sent  confirmed  distance  arrives in   height            side"
        "   confidence  ego felt"
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
            f"{a.alert_id:5d}  {a.t_s - t0:7.2f} s  {a.t_first_sent_s - t0:8.2f} s"
            f"  {a.t_emit_s - t0:7.2f} s  {dist}  {tta}    {height:16s}  "
            f"{a.side.name:5s}  {100 * a.confidence:8.0f} %  {outcome}"
        )
    for a in cancelled:
        lines.append(
            f"{a.alert_id:5d}  {a.t_s - t0:7.2f} s  provisional, cancelled at"
            f" {a.t_emit_s - t0:.2f} s (the rear axle did not match)"
        )
    return "\n".join(lines) if alerts or cancelled else "   (none)"


def format_modes(modes: Sequence[tuple[float, FusionMode, str]], start: float) -> str:
    """The mode changes, one a line, times in seconds from ``start`` (the video's frame 0)."""
    return "\n".join(f"  {t - start:8.2f} s  {m.name:11s} {why}" for t, m, why in modes)
