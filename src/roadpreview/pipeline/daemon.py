"""The in-vehicle daemon (``roadpreview run``): a live camera and a CAN bus into the pipeline,
alerts and the periodic status out on CAN.

Threads (no asyncio):

* the **camera reader** (`CameraReader`) reads ``cv2.VideoCapture`` (a device
  index, a video file or a stream URL) and puts only the newest frame into a
  one-slot `FrameMailbox`; a frame the processing loop did not take before the
  next one arrived is dropped and counted, never queued;
* python-can's **notifier** thread (`CanReceiver`) only queues received frames
  (bounded; drops are counted);
* python-can's **periodic send** task re-encodes ``RP_STATUS`` every period;
* the **processing loop** (`Daemon.run`, the caller's thread): per frame it
  waits ``can_latency_s`` past the frame's time stamp, pushes every queued CAN
  frame stamped at or before it (in arrival order), then the frame, sends the
  alerts and updates the status. A slow frame delays only the next frames
  (they are dropped), never the CAN receive. Frame k+1 waits in the mailbox
  while frame k is processed and is dropped when frame k+2 arrives first: with
  the ``can_latency_s`` wait L and frame period T, a frame taken on time may
  take up to 2T - L (47 ms at 30 fps) without a drop, and frames must take
  less than T on average. `DaemonSummary.frame_ms` holds the processing times.

The clock: frame time stamps and CAN time stamps must be on one clock, the
Unix time of ``time.time()`` (python-can stamps received frames with it on
``socketcan`` and ``virtual``). A device or stream frame is stamped
``time.time()`` when it is read; a video file played as a camera is stamped
``start + k / fps`` (``start``: `DaemonOptions.camera_start_s`, default the
moment the file is opened) and released at that wall-clock time, so it
behaves like a live camera and a CAN log replayed with the same start lines up.

Watchdogs: no camera frame for ``daemon.camera_timeout_s`` -> frames without
an image are pushed every status period (a vision failure for the fusion: the
mode becomes IMU_ONLY, or DEGRADED without IMU); no gyro sample for
``can.imu_timeout_s`` -> logged and counted; the fusion's own gyro timeout
(``fusion.gyro.timeout_s``) already turns the mode to VISUAL_ONLY.

Shutdown: `Daemon.stop_event` (set by SIGINT/SIGTERM through
`install_signal_handlers`, or by the end of a video file) ends the loop; the
camera thread is joined, held-back events are flushed as alerts, the periodic
status, the notifier and the buses are stopped and the alerts log is closed.
Logging is structured: ``event=... key=value ...``.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import signal
import threading
import time
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import FrameType
from typing import Any

import can
import cv2

from roadpreview.camera import CameraModel
from roadpreview.canbus.live import CanOutput, CanReceiver, open_bus
from roadpreview.errors import InputDataError, OperationError
from roadpreview.pipeline.config import PipelineConfig
from roadpreview.pipeline.core import FrameResult, Pipeline
from roadpreview.types import Alert, FusionMode, Status

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


# -- the camera ---------------------------------------------------------------------------


@dataclass(frozen=True)
class CameraFrame:
    """One frame read by the camera thread."""

    t: float  #: time stamp on the daemon's clock (module docstring), s
    image: Any  #: BGR uint8 array
    index: int  #: frame counter of the camera thread
    wall_s: float  #: time.time() when it was put into the mailbox


class FrameMailbox:
    """A one-slot mailbox: ``put`` replaces a frame nobody took (and counts it dropped)."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._slot: CameraFrame | None = None
        self._closed = False
        self.dropped = 0  #: frames replaced before the processing loop took them
        self.delivered = 0  #: frames put
        self.last_put_wall_s = -math.inf  #: time.time() of the newest put

    def put(self, frame: CameraFrame) -> None:
        with self._cond:
            if self._slot is not None:
                self.dropped += 1
            self._slot = frame
            self.delivered += 1
            self.last_put_wall_s = frame.wall_s
            self._cond.notify()

    def take(self, timeout: float) -> CameraFrame | None:
        """The newest frame, or None after ``timeout`` s."""
        with self._cond:
            if self._slot is None:
                self._cond.wait(timeout)
            frame, self._slot = self._slot, None
            return frame

    def close(self) -> None:
        """The camera ended (a video file): ``take`` no longer waits."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    @property
    def closed(self) -> bool:
        with self._cond:
            return self._closed and self._slot is None


def camera_kind(source: str) -> str:
    """``device`` (digits or a device node), ``stream`` (an URL) or ``file``."""
    if source.isdigit():
        return "device"
    if "://" in source:
        return "stream"
    path = Path(source)
    if path.is_file():
        return "file"
    if path.exists():
        return "device"  # /dev/video0
    raise InputDataError(f"camera {source!r}: no such file or device")


class CameraReader(threading.Thread):
    """The camera thread (module docstring). Never raises: failures are logged and counted."""

    def __init__(
        self,
        source: str,
        mailbox: FrameMailbox,
        stop: threading.Event,
        *,
        start_s: float | None = None,
        reopen_s: float = 1.0,
    ) -> None:
        super().__init__(name="roadpreview-camera", daemon=True)
        self.source = source
        self.kind = camera_kind(source)
        self.mailbox = mailbox
        self.stop_event = stop
        self.start_s = start_s
        self.reopen_s = reopen_s
        self.read_failures = 0  #: frames that could not be read or decoded
        self.opens = 0  #: successful opens
        self.fps = math.nan  #: frame rate of a file
        self.first_due_s = time.time() if start_s is None else start_s

    def _open(self) -> cv2.VideoCapture | None:
        target: int | str = int(self.source) if self.source.isdigit() else self.source
        cap = cv2.VideoCapture(target)
        if not cap.isOpened():
            cap.release()
            log.error(kv("camera_open_failed", source=self.source, kind=self.kind))
            return None
        self.opens += 1
        log.info(kv("camera_opened", source=self.source, kind=self.kind))
        return cap

    def run(self) -> None:
        try:
            if self.kind == "file":
                self._run_file()
            else:
                self._run_live()
        except Exception:  # the thread must not die silently: log, and the watchdog reports
            log.exception(kv("camera_thread_failed", source=self.source))
        finally:
            self.mailbox.close()

    def _run_file(self) -> None:
        cap = self._open()
        if cap is None:
            return
        try:
            self.fps = float(cap.get(cv2.CAP_PROP_FPS)) or 30.0
            n_frames = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
            start = self.start_s if self.start_s is not None else time.time()
            self.first_due_s = start
            i = 0
            misses = 0
            while not self.stop_event.is_set():
                ok, image = cap.read()
                if not ok:
                    if i >= n_frames - 1 or misses > 10:
                        log.info(kv("camera_end_of_file", source=self.source, frames=i))
                        return
                    misses += 1
                    self.read_failures += 1
                    log.warning(kv("camera_frame_undecodable", source=self.source, frame=i))
                    i += 1
                    continue
                misses = 0
                t = start + i / self.fps
                # released at its own time: the file behaves like a live camera
                if self.stop_event.wait(max(0.0, t - time.time())):
                    return
                self.mailbox.put(CameraFrame(t, image, i, time.time()))
                i += 1
        finally:
            cap.release()

    def _run_live(self) -> None:
        i = 0
        while not self.stop_event.is_set():
            cap = self._open()
            if cap is None:
                self.stop_event.wait(self.reopen_s)
                continue
            try:
                while not self.stop_event.is_set():
                    ok, image = cap.read()
                    now = time.time()
                    if not ok or image is None:
                        self.read_failures += 1
                        log.error(kv("camera_read_failed", source=self.source, frame=i))
                        break
                    self.mailbox.put(CameraFrame(now, image, i, now))
                    i += 1
            finally:
                cap.release()
            self.stop_event.wait(self.reopen_s)


# -- the daemon ---------------------------------------------------------------------------


@dataclass(frozen=True)
class DaemonOptions:
    """Run-time options that are not part of the configuration file."""

    camera_source: str | None = None  #: overrides ``[daemon] camera_source``
    camera_start_s: float | None = None  #: a file camera: time stamp of frame 0 (Unix s)
    alerts_log: Path | None = None  #: RP_ALERT frames as sent (any python-can log format)
    stop_at_end: bool = True  #: a file camera: stop when it ends (else the camera is lost)


class FrameTimes:
    """Distribution of the per-frame processing time in constant memory (0.25 ms bins up
    to 250 ms, the exact maximum): the daemon keeps up at 30 fps while frames take less
    than a frame period, single frames up to about 45 ms (module docstring)."""

    BIN_MS = 0.25
    BINS = 1000

    def __init__(self) -> None:
        self.counts = [0] * (self.BINS + 1)  # the last bin: beyond 250 ms
        self.n = 0
        self.max = math.nan

    def add(self, ms: float) -> None:
        self.counts[min(int(ms / self.BIN_MS), self.BINS)] += 1
        self.n += 1
        if self.n == 1 or ms > self.max:
            self.max = ms

    def quantile(self, q: float) -> float:
        """Upper edge of the bin holding the ``q`` quantile, ms (NaN without frames)."""
        if self.n == 0:
            return math.nan
        rank = q * self.n
        total = 0
        for i, c in enumerate(self.counts):  # 1001 bins, once at exit
            total += c
            if total >= rank and c:
                return min((i + 1) * self.BIN_MS, self.max)
        return self.max


@dataclass
class DaemonSummary:
    """What the daemon did, printed and logged at exit."""

    frames_processed: int = 0  #: camera frames pushed into the pipeline
    frames_dropped: int = 0  #: camera frames replaced in the mailbox before processing
    frames_out_of_order: int = 0  #: camera frames not after the previous one (skipped)
    camera_read_failures: int = 0
    camera_timeouts: int = 0  #: times the camera watchdog fired
    camera_gap_frames: int = 0  #: image-less frames pushed while the camera was lost
    imu_timeouts: int = 0  #: times the IMU watchdog fired
    alerts: list[Alert] = field(default_factory=list)
    alert_send_errors: int = 0
    can_frames: int = 0  #: CAN frames pushed into the pipeline
    can_input_errors: int = 0  #: CAN frames the decoder skipped for a problem
    can_queue_drops: int = 0  #: CAN frames lost because the receive queue was full
    can_receive_errors: int = 0
    mode_changes: list[tuple[float, FusionMode, str]] = field(default_factory=list)
    seconds: float = 0.0
    #: time to process one camera frame (CAN + pipeline + alerts, not the CAN wait)
    frame_ms: FrameTimes = field(default_factory=lambda: FrameTimes())

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

    The constructor builds the pipeline and opens the buses; `run` starts the
    threads, processes until `stop_event` is set (or a file camera ends) and
    always cleans up. One run per object.
    """

    def __init__(
        self,
        camera: CameraModel,
        config: PipelineConfig | None = None,
        options: DaemonOptions | None = None,
    ) -> None:
        self.config = config or PipelineConfig()
        self.options = options or DaemonOptions()
        self.stop_event = threading.Event()
        self.pipeline = Pipeline(camera, self.config)
        self.summary = DaemonSummary()
        self.mailbox = FrameMailbox()
        source = self.options.camera_source or self.config.daemon.camera_source
        self.camera = CameraReader(
            source,
            self.mailbox,
            self.stop_event,
            start_s=self.options.camera_start_s,
            reopen_s=self.config.daemon.camera_reopen_s,
        )
        c = self.config.can
        self.input_bus = open_bus(c.input_interface, c.input_channel)
        self.output_bus = self.input_bus
        try:
            if c.output_interface or c.output_channel:
                self.output_bus = open_bus(
                    c.output_interface or c.input_interface, c.output_channel or c.input_channel
                )
            self.output = CanOutput(self.output_bus, detector=self.config.anomaly.detector)
            self.alerts_log: can.Listener | None = None
            if self.options.alerts_log is not None:
                self.alerts_log = can.Logger(str(self.options.alerts_log))
        except BaseException:
            self._shutdown_buses()
            raise
        self.receiver: CanReceiver | None = None
        self._pending: deque[can.Message] = deque()
        self._last_t = -math.inf
        self._first_t = math.inf
        self._camera_lost = False
        self._imu_lost = False
        self._last_gap_t = -math.inf
        self._ran = False

    # -- the loop ----------------------------------------------------------------------
    def run(self) -> DaemonSummary:
        """Process until stopped; return the summary (also logged)."""
        if self._ran:
            raise OperationError("a Daemon runs once; build a new one")
        self._ran = True
        cfg = self.config
        t_wall = time.perf_counter()
        log.info(
            kv(
                "daemon_start",
                camera=self.camera.source,
                camera_kind=self.camera.kind,
                can_in=f"{cfg.can.input_interface}:{cfg.can.input_channel}",
                can_out=f"{self.output_bus.channel_info}",
                finder=cfg.vision.finder,
                estimator=cfg.pitch.estimator,
                fusion=cfg.fusion.backend,
            )
        )
        try:
            self.receiver = CanReceiver(self.input_bus, maxsize=cfg.daemon.can_queue_size)
            self.output.start_status(self._status(), cfg.can.status_period_s)
            self.camera.start()
            self._loop()
        finally:
            self._shutdown()
            self.summary.seconds = time.perf_counter() - t_wall
            log.info(kv("daemon_stop", **self.summary.fields()))
        return self.summary

    def _loop(self) -> None:
        period = self.config.can.status_period_s
        while not self.stop_event.is_set():
            item = self.mailbox.take(timeout=min(period, 0.05))
            if item is not None:
                self._camera_ok()
                self._process(item.t, item.image)
                continue
            if self.mailbox.closed and self.options.stop_at_end and self.camera.kind == "file":
                log.info(kv("camera_ended_stopping", source=self.camera.source))
                return
            self._camera_watchdog()

    def _camera_ok(self) -> None:
        if self._camera_lost:
            self._camera_lost = False
            log.warning(kv("camera_recovered", source=self.camera.source))

    def _camera_watchdog(self) -> None:
        """No frame for ``camera_timeout_s``: push image-less frames (vision failure)."""
        now = time.time()
        last = max(self.mailbox.last_put_wall_s, self.camera.first_due_s)
        if now - last <= self.config.daemon.camera_timeout_s:
            return
        if not self._camera_lost:
            self._camera_lost = True
            self.summary.camera_timeouts += 1
            log.error(kv("camera_timeout", source=self.camera.source, silent_s=now - last, t=now))
        if now - self._last_gap_t >= self.config.can.status_period_s:
            self._last_gap_t = now
            self.summary.camera_gap_frames += 1
            self._process(now, None, real=False)

    def _feed_can(self, t: float) -> None:
        """Push every received CAN frame stamped at or before ``t`` (later ones wait)."""
        assert self.receiver is not None
        self._pending.extend(self.receiver.listener.drain())
        limit = self.config.daemon.can_queue_size
        while self._pending and (self._pending[0].timestamp <= t or len(self._pending) > limit):
            msg = self._pending.popleft()
            if msg.timestamp > t:  # a clock far ahead of the frames': keep memory bounded
                self.summary.can_queue_drops += 1
                log.warning(kv("can_frame_ahead_of_camera_clock", ts=msg.timestamp, t=t))
                continue
            self.pipeline.push_can(msg)
            self.summary.can_frames += 1

    def _process(self, t: float, image: Any, *, real: bool = True) -> None:
        if t <= self._last_t:
            if not real:
                t = self._last_t + 1e-3
            else:
                self.summary.frames_out_of_order += 1
                log.warning(kv("frame_out_of_order", t=t, previous=self._last_t))
                return
        # CAN frames stamped just before the frame may still be on their way
        wait = t + self.config.daemon.can_latency_s - time.time()
        if wait > 0 and self.stop_event.wait(wait):
            return
        self._last_t = t
        t0 = time.perf_counter()  # only measured and reported, never acted upon
        self._feed_can(t)
        r = self.pipeline.push_frame(t, image)
        if real:
            self.summary.frames_processed += 1
        self._track_mode(r)
        self._send_alerts(r.alerts)
        self._imu_watchdog(t)
        status = self._status()
        self._send_confirmations(r, status)
        self.output.update_status(status)
        if real:
            self.summary.frame_ms.add((time.perf_counter() - t0) * 1e3)

    def _track_mode(self, r: FrameResult) -> None:
        modes = self.summary.mode_changes
        if not modes or modes[-1][1] != r.mode:
            why = r.pitch_reason or r.vision_reason
            modes.append((r.t, r.mode, why))
            log.info(kv("mode_change", t=r.t, mode=r.mode.name, reason=why))

    def _imu_watchdog(self, t: float) -> None:
        # the pipeline's time of the newest gyro sample (no public accessor yet)
        last_gyro = self.pipeline.last_gyro_t
        if not math.isfinite(self._first_t):
            self._first_t = t
        lost = t - max(last_gyro, self._first_t) > self.config.can.imu_timeout_s
        if lost and not self._imu_lost:
            self.summary.imu_timeouts += 1
            mode = self.pipeline.last.mode.name if self.pipeline.last else "none"
            log.warning(
                kv(
                    "imu_timeout",
                    t=t,
                    silent_s=t - last_gyro if math.isfinite(last_gyro) else "never",
                    mode=mode,
                )
            )
        elif not lost and self._imu_lost:
            log.warning(kv("imu_recovered", t=t))
        self._imu_lost = lost

    def _send_alerts(self, alerts: tuple[Alert, ...] | list[Alert]) -> None:
        for a in alerts:
            self.summary.alerts.append(a)
            log.warning(
                kv(
                    "alert",
                    t=a.t_s,
                    distance_m=a.distance_m if a.distance_m is not None else "na",
                    severity_px=a.severity_px,
                    side=a.side.name,
                    mode=a.mode.name,
                )
            )
            try:
                msgs = self.output.send_alert(a)  # RP_ALERT, RP_ALERT_DETAIL
            except OperationError as exc:
                self.summary.alert_send_errors += 1
                log.error(kv("alert_send_failed", error=str(exc)))
                continue
            if self.alerts_log is not None:
                for msg in msgs:
                    self.alerts_log.on_message_received(msg)

    def _send_confirmations(self, r: FrameResult, status: Status) -> None:
        """RP_CONFIRM for each alert whose spot the ego passed at frame ``r`` (the running
        precision from ``status``, the pipeline's after this frame)."""
        for c in r.confirmations:
            log.info(
                kv(
                    "confirmation",
                    t=r.t,
                    alert_id=c.alert_id,
                    outcome=c.outcome.name,
                    peak_mps2=c.peak_mps2,
                    background_mps2=c.background_mps2,
                )
            )
            try:
                msg = self.output.send_confirmation(c, status.precision, timestamp=r.t)
            except OperationError as exc:
                log.error(kv("confirmation_send_failed", error=str(exc)))
                continue
            if self.alerts_log is not None:
                self.alerts_log.on_message_received(msg)

    def _status(self) -> Status:
        """The pipeline's status, with the real camera frames (not the image-less ones)."""
        return dataclasses.replace(
            self.pipeline.status(), frames_processed=self.summary.frames_processed
        )

    # -- shutdown ----------------------------------------------------------------------
    def _shutdown(self) -> None:
        self.stop_event.set()
        if self.camera.is_alive():
            self.camera.join(timeout=5.0)
            if self.camera.is_alive():
                log.error(kv("camera_thread_hangs", source=self.camera.source))
        try:
            if self.receiver is not None and self._last_t > -math.inf:
                self._feed_can(self._last_t)
            self._send_alerts(self.pipeline.finish())  # events held by the suppression
            self.output.update_status(self._status())
        except Exception:
            log.exception(kv("flush_failed"))
        s = self.summary
        s.frames_dropped = self.mailbox.dropped
        s.camera_read_failures = self.camera.read_failures
        s.can_input_errors = self.pipeline.can_decoder.stats.skipped
        if self.receiver is not None:
            s.can_queue_drops += self.receiver.dropped
            s.can_receive_errors = self.receiver.listener.errors
        self.output.stop()
        try:  # the last word: the counts after the flush
            status, now = self._status(), time.time()
            self.output.send_status(status, timestamp=now)
            self.output.send_road_status(status, timestamp=now)
        except OperationError as exc:
            log.error(kv("status_send_failed", error=str(exc)))
        if self.receiver is not None:
            self.receiver.stop()
        if self.alerts_log is not None:
            self.alerts_log.stop()  # flushes and closes the file
        self._shutdown_buses()

    def _shutdown_buses(self) -> None:
        for bus in {
            id(self.input_bus): self.input_bus,
            id(self.output_bus): self.output_bus,
        }.values():
            try:
                bus.shutdown()
            except Exception:
                log.exception(kv("bus_shutdown_failed", channel=str(bus.channel_info)))


@dataclass
class SignalHandlers:
    """SIGINT/SIGTERM set an event; `restore` puts the previous handlers back."""

    event: threading.Event
    previous: dict[int, Any] = field(default_factory=dict)

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        log.warning(kv("signal", name=signal.Signals(signum).name))
        self.event.set()

    def install(self) -> SignalHandlers:
        for sig in (signal.SIGINT, signal.SIGTERM):
            self.previous[sig] = signal.signal(sig, self._handle)
        return self

    def restore(self) -> None:
        for sig, handler in self.previous.items():
            signal.signal(sig, handler)
        self.previous.clear()


def install_signal_handlers(event: threading.Event) -> SignalHandlers:
    """SIGINT and SIGTERM set ``event`` (call from the main thread)."""
    return SignalHandlers(event).install()


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
