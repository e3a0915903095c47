"""The in-vehicle daemon (``roadpreview run``): a live camera and a CAN bus into the
pipeline, alerts and the periodic status out on CAN. A composition of the run loop:

* sources: the camera (`open_camera`: a device index or node, a stream URL, or a video
  file / image folder played at its recorded pace) and the input bus (`CanBusSource`,
  decoded through the DBC and the mapping as frames arrive);
* sinks: the output bus (`CanBusSink`: RP_ALERT + RP_ALERT_DETAIL per alert, RP_CONFIRM,
  RP_STATUS + RP_ROAD_STATUS every status period; send errors logged and counted), the
  sent frames optionally recorded to a CAN log, and structured log lines;
* watchdogs: the camera (no frame for ``daemon.camera_timeout_s``: image-less frames
  every status period, a vision failure for the fusion, so the status keeps going out)
  and the IMU (no gyro sample for ``can.imu_timeout_s``: logged and counted; the
  fusion's own gyro timeout turns the mode to VISUAL_ONLY);
* signals: SIGINT/SIGTERM set `Daemon.stop_event` (`install_signal_handlers`).

The clock: frame and CAN time stamps must be on one clock. A device or stream frame is
stamped ``time.time()`` when read, as python-can stamps received frames on
``socketcan`` and ``virtual``. A file camera is stamped by the video's clock rule
(`roadpreview.sources.video`) from ``camera_start_s`` (default: when it is opened) and
released at that wall time (``pace``), so it behaves like a live camera; a CAN log
replayed on the bus on the same clock lines up. The loop processes a frame
``daemon.can_latency_s`` after its stamp, so CAN frames stamped before it are pushed
first, as in a replay; when it falls behind, only the newest frame is processed.
Logging is structured: ``event=... key=value ...``.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from roadpreview.camera import CameraModel
from roadpreview.canbus.live import open_bus
from roadpreview.errors import OperationError
from roadpreview.loop import FrameTimes, Pace, RunSummary, install_signal_handlers, run
from roadpreview.pipeline.config import PipelineConfig
from roadpreview.pipeline.pipeline import FrameResult, Pipeline
from roadpreview.sinks import Sink
from roadpreview.sinks.can import CanBusSink, repetition_config
from roadpreview.sinks.files import FrameTableSink
from roadpreview.sources.can import CanBusSource, make_decoder
from roadpreview.sources.video import CameraDeviceSource, camera_kind, open_camera
from roadpreview.types import Alert, CameraFrame, FusionMode, ImuSample, Sample, Status

log = logging.getLogger(__name__)


def kv(event: str, **fields: Any) -> str:
    """A structured log line: ``event=<event> key=value ...`` (floats to 6 digits)."""
    parts = [f"event={event}"]
    for k, v in fields.items():
        if isinstance(v, float):
            v = f"{v:.3f}" if abs(v) >= 1e5 else f"{v:.6g}"  # Unix times to the ms
        elif isinstance(v, str) and (not v or " " in v):
            v = repr(v)
        parts.append(f"{k}={v}")
    return " ".join(parts)


# -- watchdogs ----------------------------------------------------------------------------
class CameraWatchdog:
    """No camera frame for ``timeout_s``: the camera is lost (logged once); an image-less
    frame every ``period_s`` while it is (index -1: a vision failure for the fusion)."""

    def __init__(
        self, source: str, timeout_s: float, period_s: float, *, start_s: float = -math.inf
    ) -> None:
        self.source = source
        self.start_s = start_s  #: when the first frame is due (the grace period's start)
        self.timeout_s = timeout_s
        self.period_s = period_s
        self.timeouts = 0  #: times the camera was declared lost
        self.gap_frames = 0  #: image-less frames injected
        self.lost = False
        self._last_t = math.nan  # the newest real frame (NaN: none yet)
        self._since = math.nan  # the first check: the camera's grace period starts there
        self._last_gap_t = -math.inf

    def observe(self, sample: Sample) -> None:
        if isinstance(sample, CameraFrame) and sample.index >= 0:
            self._last_t = sample.t_s
            if self.lost:
                self.lost = False
                log.warning(kv("camera_recovered", source=self.source, t=sample.t_s))

    def check(self, now_s: float) -> list[Sample]:
        if not math.isfinite(now_s):
            return []
        if math.isnan(self._since):
            self._since = max(now_s, self.start_s)
        last = self._last_t if math.isfinite(self._last_t) else self._since
        if now_s - last <= self.timeout_s:
            return []
        if not self.lost:
            self.lost = True
            self.timeouts += 1
            log.error(kv("camera_timeout", source=self.source, silent_s=now_s - last, t=now_s))
        if now_s - self._last_gap_t < self.period_s:
            return []
        self._last_gap_t = now_s
        self.gap_frames += 1
        return [CameraFrame(now_s, None, -1)]


class ImuWatchdog:
    """No gyro sample for ``timeout_s`` at a frame: the IMU is lost (logged once, counted);
    logged again when a gyro sample comes back."""

    def __init__(self, timeout_s: float) -> None:
        self.timeout_s = timeout_s
        self.timeouts = 0
        self.lost = False
        self._last_gyro_t = -math.inf
        self._first_t = math.inf

    def observe(self, sample: Sample) -> None:
        if isinstance(sample, ImuSample):
            if math.isfinite(sample.pitch_rate_rad_s):
                self._last_gyro_t = sample.t_s
            return
        if not isinstance(sample, CameraFrame):
            return
        t = sample.t_s
        self._first_t = min(self._first_t, t)
        lost = t - max(self._last_gyro_t, self._first_t) > self.timeout_s
        if lost and not self.lost:
            self.timeouts += 1
            silent = t - self._last_gyro_t if math.isfinite(self._last_gyro_t) else "never"
            log.warning(kv("imu_timeout", t=t, silent_s=silent))
        elif not lost and self.lost:
            log.warning(kv("imu_recovered", t=t))
        self.lost = lost

    def check(self, now_s: float) -> list[Sample]:
        return []


class LogSink(Sink):
    """Structured log lines: one per alert and per confirmation."""

    def on_frame(self, frame: CameraFrame, result: FrameResult, status: Status) -> None:
        self._alerts(result.alerts)
        for c in result.confirmations:
            log.info(
                kv(
                    "confirmation",
                    t=result.t,
                    alert_id=c.alert_id,
                    outcome=c.outcome.name,
                    peak_mps2=c.peak_mps2,
                    background_mps2=c.background_mps2,
                )
            )

    def on_flush(self, t_s: float, alerts: Sequence[Alert], status: Status) -> None:
        self._alerts(alerts)

    def _alerts(self, alerts: Sequence[Alert]) -> None:
        for a in alerts:
            log.warning(
                kv(
                    "alert",
                    id=a.alert_id,
                    t=a.t_s,
                    distance_m=a.distance_m if a.distance_m is not None else "na",
                    height_mm=a.height_mm if a.height_mm is not None else "na",
                    side=a.side.name,
                    mode=a.mode.name,
                )
            )


# -- the daemon ---------------------------------------------------------------------------
@dataclass(frozen=True)
class DaemonOptions:
    """Run-time options that are not part of the configuration file."""

    camera_source: str | None = None  #: overrides ``[daemon] camera_source``
    #: a file camera: time stamp of frame 0 on the pipeline's clock (default: when opened)
    camera_start_s: float | None = None
    #: a file camera: its frame time stamps (``frame,t_s``; default: index / fps)
    frames_csv: Path | None = None
    #: a file camera: the clock that releases its frames (default: the pipeline's clock is
    #: the wall clock, frame 0 due at ``camera_start_s``)
    pace: Pace | None = None
    alerts_log: Path | None = None  #: the output frames as sent (any python-can log format)
    frame_table: Path | None = None  #: the per-frame table (CSV), as a replay writes it
    stop_at_end: bool = True  #: a file camera: stop when it ends (else the camera is lost)


@dataclass
class DaemonSummary:
    """What the daemon did, printed and logged at exit."""

    frames_processed: int = 0  #: camera frames pushed into the pipeline
    frames_dropped: int = 0  #: camera frames skipped because a newer one was due
    frames_out_of_order: int = 0  #: camera frames not after the previous one (skipped)
    camera_read_failures: int = 0
    camera_timeouts: int = 0  #: times the camera watchdog fired
    camera_gap_frames: int = 0  #: image-less frames pushed while the camera was lost
    imu_timeouts: int = 0  #: times the IMU watchdog fired
    alerts: list[Alert] = field(default_factory=list)
    alert_send_errors: int = 0  #: output frames the bus refused
    can_frames: int = 0  #: CAN frames received
    can_input_errors: int = 0  #: CAN frames the decoder skipped for a problem
    can_queue_drops: int = 0  #: CAN frames lost because the receive queue was full
    can_receive_errors: int = 0
    mode_changes: list[tuple[float, FusionMode, str]] = field(default_factory=list)
    seconds: float = 0.0
    interrupted: bool = False
    #: time to process one camera frame (pipeline and sinks)
    frame_ms: FrameTimes = field(default_factory=FrameTimes)

    def fields(self) -> dict[str, Any]:
        """The counters (for the log line and the CLI)."""
        return {
            "frames_processed": self.frames_processed,
            "frames_dropped": self.frames_dropped,
            "frames_out_of_order": self.frames_out_of_order,
            "camera_read_failures": self.camera_read_failures,
            "camera_timeouts": self.camera_timeouts,
            "camera_gap_frames": self.camera_gap_frames,
            "imu_timeouts": self.imu_timeouts,
            "alerts": len(self.alerts),
            "alert_send_errors": self.alert_send_errors,
            "can_frames": self.can_frames,
            "can_input_errors": self.can_input_errors,
            "can_queue_drops": self.can_queue_drops,
            "can_receive_errors": self.can_receive_errors,
            "frame_ms_median": round(self.frame_ms.quantile(0.5), 2),
            "frame_ms_p99": round(self.frame_ms.quantile(0.99), 2),
            "frame_ms_max": round(self.frame_ms.max, 2),
            "seconds": round(self.seconds, 3),
        }


class Daemon:
    """Camera + CAN bus -> `Pipeline` -> alerts and status on CAN (module docstring).

    The constructor builds the pipeline, the sources and the sinks and opens the buses;
    `run` runs the loop until `stop_event` is set (or a file camera ends) and always
    cleans up. One run per object.
    """

    def __init__(
        self,
        camera: CameraModel,
        config: PipelineConfig | None = None,
        options: DaemonOptions | None = None,
    ) -> None:
        self.config = cfg = config or PipelineConfig()
        self.options = opts = options or DaemonOptions()
        self.stop_event = threading.Event()
        self.pipeline = Pipeline(camera, cfg)
        self.summary = DaemonSummary()
        self.camera_source = opts.camera_source or cfg.daemon.camera_source
        self.camera_kind = camera_kind(self.camera_source)
        self.camera = open_camera(
            self.camera_source,
            start_s=opts.camera_start_s,
            frames_csv=opts.frames_csv,
            reopen_s=cfg.daemon.camera_reopen_s,
        )
        source = self.camera
        first_due = -math.inf if isinstance(source, CameraDeviceSource) else source.start_s
        self.camera_watchdog = CameraWatchdog(
            self.camera_source,
            cfg.daemon.camera_timeout_s,
            cfg.can.status_period_s,
            start_s=first_due,
        )
        self.imu_watchdog = ImuWatchdog(cfg.can.imu_timeout_s)
        c = cfg.can
        self.input_bus = open_bus(c.input_interface, c.input_channel)
        self.output_bus = self.input_bus
        try:
            if c.output_interface or c.output_channel:
                self.output_bus = open_bus(
                    c.output_interface or c.input_interface, c.output_channel or c.input_channel
                )
            decoder = make_decoder(c.dbc, c.mapping)
            self.can_in = CanBusSource(
                self.input_bus, decoder, queue_size=cfg.daemon.can_queue_size
            )
            self.output = CanBusSink(
                self.output_bus,
                detector=cfg.anomaly.detector,
                record=opts.alerts_log,
                repetition=repetition_config(cfg),
            )
        except BaseException:
            self._shutdown_buses()
            raise
        self._ran = False

    def _pace(self) -> Pace | None:
        """A file camera is released at its own time: the wall clock, unless set."""
        if isinstance(self.camera, CameraDeviceSource) or self.options.pace is not None:
            return self.options.pace
        start = self.camera.start_s
        return Pace(1.0, t0=start, wall0=start)

    def run(self) -> DaemonSummary:
        """Process until stopped; return the summary (also logged)."""
        if self._ran:
            raise OperationError("a Daemon runs once; build a new one")
        self._ran = True
        cfg = self.config
        log.info(
            kv(
                "daemon_start",
                camera=self.camera_source,
                camera_kind=self.camera_kind,
                can_in=f"{cfg.can.input_interface}:{cfg.can.input_channel}",
                can_out=f"{self.output_bus.channel_info}",
                finder=cfg.vision.finder,
                estimator=cfg.pitch.estimator,
                fusion=cfg.fusion.backend,
            )
        )
        sinks: list[Sink] = [self.output, LogSink()]
        if self.options.frame_table is not None:
            sinks.append(FrameTableSink(self.options.frame_table))
        result: RunSummary | None = None
        try:
            result = run(
                [self.camera, self.can_in],
                self.pipeline,
                sinks,
                pace=self._pace(),
                watchdogs=[self.camera_watchdog, self.imu_watchdog],
                stop=self.stop_event,
                status_period_s=cfg.can.status_period_s,
                latency_s=cfg.daemon.can_latency_s,
                keep_running=not (self.options.stop_at_end and not self.camera.live),
            )
        finally:
            self._shutdown_buses()
            self._summarise(result)
            log.info(kv("daemon_stop", **self.summary.fields()))
        return self.summary

    def _summarise(self, r: RunSummary | None) -> None:
        s = self.summary
        if r is not None:
            s.frames_processed = r.frames
            s.frames_dropped = r.frames_dropped
            s.frames_out_of_order = r.frames_out_of_order
            s.alerts = r.alerts
            s.mode_changes = r.mode_changes
            s.seconds = r.seconds
            s.interrupted = r.interrupted
            s.frame_ms = r.frame_ms
            s.can_queue_drops = r.queue_drops
        s.camera_read_failures = self.camera.errors
        s.camera_timeouts = self.camera_watchdog.timeouts
        s.camera_gap_frames = self.camera_watchdog.gap_frames
        s.imu_timeouts = self.imu_watchdog.timeouts
        s.alert_send_errors = self.output.send_errors
        s.can_frames = self.can_in.frames
        s.can_input_errors = self.can_in.decoder.stats.skipped
        s.can_queue_drops += self.can_in.dropped
        s.can_receive_errors = self.can_in.receive_errors

    def _shutdown_buses(self) -> None:
        buses = {id(self.input_bus): self.input_bus, id(self.output_bus): self.output_bus}
        for bus in buses.values():
            try:
                bus.shutdown()
            except Exception:
                log.exception(kv("bus_shutdown_failed", channel=str(bus.channel_info)))


def iter_summary_lines(summary: DaemonSummary) -> Iterator[str]:
    """The exit summary for humans."""
    s = summary
    yield (
        f"{s.frames_processed} frames processed, {s.frames_dropped} dropped, "
        f"{s.frames_out_of_order} out of order, {s.camera_read_failures} unreadable"
    )
    yield (
        f"{len(s.alerts)} alert(s) ({s.alert_send_errors} send errors); "
        f"CAN: {s.can_frames} frames in, {s.can_input_errors} input errors, "
        f"{s.can_queue_drops} queue drops, {s.can_receive_errors} receive errors"
    )
    yield (
        f"watchdogs: camera {s.camera_timeouts} timeout(s) ({s.camera_gap_frames} image-less "
        f"frames), IMU {s.imu_timeouts} timeout(s); {s.seconds:.1f} s"
    )
    yield (
        f"processing per frame: median {s.frame_ms.quantile(0.5):.1f} ms, "
        f"99 % {s.frame_ms.quantile(0.99):.1f} ms, max {s.frame_ms.max:.1f} ms"
    )


__all__ = [
    "CameraWatchdog",
    "Daemon",
    "DaemonOptions",
    "DaemonSummary",
    "ImuWatchdog",
    "install_signal_handlers",
    "iter_summary_lines",
    "kv",
]
