"""The in-vehicle daemon (``roadpreview run``): a live camera and a CAN bus into the
pipeline, alerts and the periodic status out on CAN. A composition of the run loop:

* sources: the camera (`open_camera`: a device index or node, a stream URL, a GStreamer
  pipeline where OpenCV has GStreamer, or a video file / image folder played at its
  recorded pace; ``[daemon] camera_width/height/fps`` requested, the calibration's size
  required) and the input bus (`CanBusSource`, decoded through the DBC and the mapping as
  frames arrive), optionally fed from a CAN log by a `CanLogPlayer` (``can_log``);
* sinks: the output bus (`CanBusSink`: RP_ALERT + RP_ALERT_DETAIL per alert, RP_CONFIRM
  from the loop's thread; RP_STATUS + RP_ROAD_STATUS (+ RP_INPUT_STATUS) every status
  period from a cyclic sender thread of its own, `StatusCycle`, fed with the loop's
  newest status; send errors logged and counted; Python's thread switch interval is
  ``daemon.switch_interval_s`` while the daemon runs, so that thread waits little for
  the interpreter), the sent frames optionally recorded to a CAN log, and structured log
  lines;
* watchdogs: the camera (no frame for ``daemon.camera_timeout_s``: image-less frames
  every status period, a vision failure for the fusion, so the status keeps going out)
  and the IMU (no gyro sample for ``can.imu_timeout_s``: logged and counted; the
  fusion's own gyro timeout turns the mode to VISUAL_ONLY);
* supervision: the loop reads the camera and the bus in threads of their own and restarts
  a source whose iterator raises (logged ``event=thread_died``, counted, with backoff;
  `roadpreview.loop.Supervision`); a source that keeps failing ends the run with
  `SourceFailed`, which `Daemon.run` raises after cleaning up, so ``roadpreview run``
  exits non-zero and systemd's ``Restart=on-failure`` starts it again. The status
  sender is supervised the same way (``thread_deaths`` ``can-status``; giving up stops
  the daemon with `ThreadFailed`). A send error on the output bus costs that frame only
  (`CanBusSink`); the status sender goes on, so the next period's RP_STATUS is sent;
* signals: SIGINT/SIGTERM set `Daemon.stop_event` (`install_signal_handlers`);
* operations: a status line every ``daemon.status_log_period_s`` (`StatusMonitor`) and
  systemd ``Type=notify`` (`SystemdNotifier`): READY at the first frame, WATCHDOG pings
  while frames go through (`WatchdogPinger`), STATUS, STOPPING (docs/daemon.md).

The clock: frame and CAN time stamps must be on one clock. A device or stream frame is
stamped ``time.time()`` when read, as python-can stamps received frames on
``socketcan`` and ``virtual``. A file camera is stamped by the video's clock rule
(`roadpreview.sources.video`) from ``camera_start_s`` (default: when it is opened) and
released at that wall time (``pace``), so it behaves like a live camera; a CAN log
replayed on the bus on the same clock lines up. Every wait and every reading of the time
goes through `DaemonOptions.clock` (the system's clock by default; a
`roadpreview.clock.VirtualClock` in tests, which then run on virtual time). The loop
processes a frame
``daemon.can_latency_s`` after its stamp, so CAN frames stamped before it are pushed
first, as in a replay; when it falls behind, only the newest frame is processed.
Logging is structured: ``event=... key=value ...``.
"""

from __future__ import annotations

import gc
import logging
import math
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import can

from roadpreview.apps.monitoring import (
    CameraWatchdog,
    ImuWatchdog,
    LogSink,
    StatusMonitor,
    SystemdNotifier,
    WatchdogPinger,
    kv,
)
from roadpreview.camera import CameraModel
from roadpreview.canbus.live import CanLogPlayer, open_bus
from roadpreview.clock import Clock, SystemClock
from roadpreview.errors import ConfigError, InputDataError, OperationError
from roadpreview.loop import (
    FrameTimes,
    Pace,
    RunSummary,
    SourceFailed,
    Supervision,
    install_signal_handlers,
    run,
)
from roadpreview.pipeline.config import PipelineConfig
from roadpreview.pipeline.pipeline import Pipeline
from roadpreview.sinks import Sink
from roadpreview.sinks.can import CanBusSink, StatusCycle, repetition_config
from roadpreview.sinks.files import FrameTableSink
from roadpreview.sources.can import CanBusSource, make_decoder
from roadpreview.sources.clockguard import ClockGuard
from roadpreview.sources.video import (
    CameraDeviceSource,
    ImageSequenceSource,
    VideoFileSource,
    camera_kind,
    open_camera,
)
from roadpreview.supervision import ThreadFailed
from roadpreview.types import Alert, CameraFrame, FusionMode

log = logging.getLogger(__name__)

#: a file camera fed by a CAN log player starts this long after it is opened (unless its
#: start is given): the loop's threads and the player run before frame 0 is due, so the
#: first frames cannot overtake the CAN frames stamped before them
PLAYER_START_DELAY_S = 1.0


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
    #: a CAN log played onto the input bus at recorded pace (`CanLogPlayer`), re-stamped
    #: onto the daemon's clock: the bench without a car
    can_log: Path | None = None
    can_log_loop: bool = False  #: start the log over when it ends
    #: the log's time stamp of the camera file's frame 0 (as ``replay --video-start``);
    #: default: the log's first frame. A live camera: the log starts when the daemon does
    video_start_s: float | None = None
    #: a file camera (and its CAN log): play at this multiple of the recorded speed; the
    #: time stamps stay on the recording's clock (``pace`` overrides it)
    rate: float = 1.0
    #: how a failing camera or bus reader (and the status sender) is restarted before
    #: the daemon gives up
    supervision: Supervision = field(default_factory=Supervision)
    #: the clock the daemon reads and waits on (None: the system's, Unix time, with the
    #: timeouts and the watchdog on the monotonic clock); a test's `VirtualClock`
    clock: Clock | None = None


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
    can_log_sent: int = 0  #: frames the CAN log player sent (``can_log``)
    can_log_errors: int = 0  #: its garbled, out-of-order and refused frames
    status_lines: int = 0  #: periodic status lines logged
    watchdog_withheld: int = 0  #: times the systemd watchdog pings were withheld (unhealthy)
    #: exceptions out of a source's reader thread (the loop restarted it), per source
    thread_deaths: dict[str, int] = field(default_factory=dict)
    #: per source: reason -> count (`RunSummary.source_problems`)
    source_problems: dict[str, dict[str, int]] = field(default_factory=dict)
    #: per arbitration id: output frames the bus refused (e.g. ``{0x201: 1}``: RP_STATUS)
    send_failures: dict[int, int] = field(default_factory=dict)
    error: str = ""  #: why the daemon gave up ('' if it stopped normally)
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
            "can_log_sent": self.can_log_sent,
            "can_log_errors": self.can_log_errors,
            "thread_deaths": sum(self.thread_deaths.values()),
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
        #: the frames' clock (Unix time) and the one timeouts and pings are measured on
        self.clock: Clock = opts.clock or SystemClock()
        self.timer: Clock = opts.clock or SystemClock(time.monotonic)
        self.stop_event = self.clock.event()
        self.pipeline = Pipeline(camera, cfg)
        self.summary = DaemonSummary()
        self.camera_source = opts.camera_source or cfg.daemon.camera_source
        d = cfg.daemon
        if d.watchdog_stall_s <= d.camera_timeout_s:
            raise ConfigError(
                f"[daemon] watchdog_stall_s = {d.watchdog_stall_s} s must exceed "
                f"camera_timeout_s = {d.camera_timeout_s} s (a lost camera gives the loop "
                "image-less frames only after that)"
            )
        if not opts.rate > 0:
            raise ConfigError(f"rate {opts.rate}: must be positive")
        start_s = opts.camera_start_s
        if start_s is None:  # a file camera starts now (a device ignores it)
            start_s = self.clock.now() + (PLAYER_START_DELAY_S if opts.can_log else 0.0)
        self.camera = open_camera(
            self.camera_source,
            start_s=start_s,
            frames_csv=opts.frames_csv,
            reopen_s=d.camera_reopen_s,
            device_width=d.camera_width,
            device_height=d.camera_height,
            device_fps=d.camera_fps,
            expected_size=camera.size,
        )
        source = self.camera
        if isinstance(source, CameraDeviceSource):
            self.camera_kind = source.kind
        else:
            self.camera_kind = camera_kind(self.camera_source)
        self._check_camera(camera)
        first_due = -math.inf if isinstance(source, CameraDeviceSource) else source.start_s
        self.camera_watchdog = CameraWatchdog(
            self.camera_source,
            d.camera_timeout_s,
            cfg.can.status_period_s,
            start_s=first_due,
        )
        self.imu_watchdog = ImuWatchdog(cfg.can.imu_timeout_s)
        self.pace = self._pace()
        c = cfg.can
        self.player: CanLogPlayer | None = None
        self.player_bus: Any = None
        self.input_bus = _open_bus(c.input_interface, c.input_channel)
        self.output_bus = self.input_bus
        self._thread_failure = ""  # why a supervised thread of the daemon gave up
        try:
            if c.output_interface or c.output_channel:
                self.output_bus = _open_bus(
                    c.output_interface or c.input_interface, c.output_channel or c.input_channel
                )
            decoder = make_decoder(c.dbc, c.mapping, self.config.plausibility)
            self.can_in = CanBusSource(
                self.input_bus, decoder, queue_size=d.can_queue_size, clock=self.timer
            )
            # the status on the frames' clock: a file camera's pace, else the monotonic
            # clock with the time stamps on the system's
            pace = self.pace
            self.output = CanBusSink(
                self.output_bus,
                detector=cfg.anomaly.detector,
                record=opts.alerts_log,
                repetition=repetition_config(cfg),
                cycle=StatusCycle(
                    clock=pace if pace is not None else self.timer,
                    period_s=c.status_period_s,
                    stamp=None if pace is not None else self.clock.now,
                    supervision=opts.supervision,
                    on_failed=self._thread_failed,
                ),
            )
            if opts.can_log is not None:
                self.player = self._player(opts.can_log)
        except BaseException:
            self._shutdown_buses()
            self.camera.close()
            raise
        self.monitor: StatusMonitor | None = None  #: the running daemon's health (`run`)
        self.pinger: WatchdogPinger | None = None  #: systemd's watchdog pings (`run`)
        self._ran = False

    def _check_camera(self, camera: CameraModel) -> None:
        """The camera settings apply to a device or stream, whose size must be the
        calibration's: opened now to say so at once (if it is there: else it is retried
        while running, a frame of another size then arriving without image)."""
        d = self.config.daemon
        cam = self.camera
        cal = f"{camera.width}x{camera.height}"
        if not isinstance(cam, CameraDeviceSource):
            if d.camera_width or d.camera_height or d.camera_fps:
                log.warning(
                    kv("camera_settings_ignored", source=self.camera_source, kind=self.camera_kind)
                )
            if isinstance(cam, VideoFileSource):
                cam.check_size(camera.size)
            elif isinstance(cam, ImageSequenceSource) and cam.size not in ((0, 0), camera.size):
                raise InputDataError(
                    f"{cam.folder}: images are {cam.size[0]}x{cam.size[1]} but the camera "
                    f"calibration is for {cal}"
                )
            return
        if not cam.open():
            log.error(
                kv("camera_unavailable", source=self.camera_source, retry_s=d.camera_reopen_s)
            )
            return
        if cam.size[0] > 0 and cam.size != camera.size:
            cam.close()
            raise ConfigError(
                f"camera {self.camera_source!r} gives {cam.size[0]}x{cam.size[1]} frames but "
                f"the calibration is for {cal}: set [daemon] camera_width/camera_height to "
                "the calibration's size, or calibrate the camera at this size"
            )

    def _player(self, path: Path) -> CanLogPlayer:
        """The CAN log player on its own bus object on the input channel, on the camera's
        clock: a file camera's frame 0 is the log's ``video_start_s`` (default: its first
        frame); with a live camera the log starts when the daemon does."""
        c = self.config.can
        virtual = c.input_interface == "virtual"
        if self.pace is not None and self.pace.rate != 1.0 and not virtual:
            raise ConfigError(
                f"a pace of {self.pace.rate} x recorded speed needs the virtual CAN "
                f"interface: {c.input_interface} stamps frames on arrival, on the wall clock"
            )
        self.player_bus = _open_bus(c.input_interface, c.input_channel)
        return CanLogPlayer(
            path,
            self.player_bus,
            anchor_s=None if isinstance(self.camera, CameraDeviceSource) else self.camera.start_s,
            anchor_log_s=self.options.video_start_s,
            schedule=self.pace,
            loop=self.options.can_log_loop,
            clock=self.clock,
        )

    def _pace(self) -> Pace | None:
        """A file camera is released at its own time: the wall clock, unless set."""
        if isinstance(self.camera, CameraDeviceSource) or self.options.pace is not None:
            return self.options.pace
        start = self.camera.start_s
        return Pace(self.options.rate, t0=start, wall0=start, clock=self.clock)

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
        d = cfg.daemon
        notifier = SystemdNotifier()
        self.monitor = monitor = StatusMonitor(
            d.status_log_period_s,
            self._status_fields,
            on_ready=lambda frame: self._ready(notifier, frame),
            on_line=lambda line: notifier.notify("STATUS=" + line.removeprefix("event=status ")),
            clock=self.timer.now,
        )
        sinks: list[Sink] = [self.output, LogSink(), monitor]
        if self.options.frame_table is not None:
            sinks.append(FrameTableSink(self.options.frame_table))
        result: RunSummary | None = None
        pinger_done = self.timer.event()
        pinger_thread: threading.Thread | None = None
        ping_s = SystemdNotifier.watchdog_period_s(d.watchdog_ping_s) if notifier.enabled else 0.0
        self.pinger = WatchdogPinger(
            notifier,
            monitor,
            ping_s,
            stall_s=d.watchdog_stall_s,
            camera_lost_s=d.watchdog_camera_lost_s,
            clock=self.timer,
        )
        # a shorter thread switch interval: the status sender waits less for the interpreter;
        # what exists now (modules, the pipeline, the DBC: ~140,000 objects) frozen out of
        # the garbage collector, whose full collections then walk only what the run
        # allocates (~1 ms instead of ~100 ms with the interpreter held, RP_STATUS too)
        switch_interval = sys.getswitchinterval()
        sys.setswitchinterval(d.switch_interval_s)
        gc.collect()
        gc.freeze()
        try:
            if ping_s > 0:
                pinger_thread = threading.Thread(
                    target=self.pinger.run,
                    args=(pinger_done,),
                    name="systemd-watchdog",
                    daemon=True,
                )
                pinger_thread.start()
            if self.player is not None:
                self.player.start()
            # the bus's stamps against the loop's clock as frames arrive: stray stamps
            # dropped alone, clock steps taken off (`ClockGuard`)
            pace = self.pace
            clock = (
                self.clock.now
                if pace is None
                else (lambda: pace.now() if pace.started else math.nan)
            )
            result = run(
                [self.camera, ClockGuard(self.can_in, clock=clock)],
                self.pipeline,
                sinks,
                pace=self.pace,
                watchdogs=[self.camera_watchdog, self.imu_watchdog],
                stop=self.stop_event,
                status_period_s=cfg.can.status_period_s,
                frame_hold_s=self.pipeline.frame_hold_s,
                latency_s=d.can_latency_s,
                keep_running=not (self.options.stop_at_end and not self.camera.live),
                supervision=self.options.supervision,
                clock=self.options.clock,
            )
        except SourceFailed as exc:  # a source kept failing: summarised, then raised
            result = exc.summary
            self.summary.error = str(exc)
            raise
        finally:
            notifier.notify("STOPPING=1")
            pinger_done.set()
            if pinger_thread is not None:
                pinger_thread.join(timeout=5.0)
            notifier.close()
            if self.player is not None:
                self.player.stop()
            self._shutdown_buses()
            sys.setswitchinterval(switch_interval)
            gc.unfreeze()
            self._summarise(result)
            log.info(kv("daemon_stop", **self.summary.fields()))
        if self._thread_failure:  # the status sender kept dying: stopped, then raised
            raise ThreadFailed(self._thread_failure)
        return self.summary

    def _thread_failed(self, message: str) -> None:
        """A supervised thread of the daemon gave up: the daemon stops and `run` raises."""
        self._thread_failure = message
        self.stop_event.set()

    def _ready(self, notifier: SystemdNotifier, frame: CameraFrame) -> None:
        """The first frame went through: systemd's READY=1 (the camera and the buses are
        open, or the camera stayed silent for its timeout: then it says so)."""
        camera = "ok" if frame.index >= 0 else "lost"
        log.info(kv("ready", t=frame.t_s, camera=camera))
        notifier.notify(f"READY=1\nSTATUS=running, first frame processed, camera {camera}")

    def _status_fields(self) -> dict[str, Any]:
        """The daemon's part of the periodic status line (`StatusMonitor`)."""
        fields: dict[str, Any] = {
            "bus_errors": self.output.send_errors + self.can_in.receive_errors,
            "can_in": self.can_in.frames,
            "can_errors": self.can_in.decoder.stats.skipped + self.can_in.dropped,
            "imu": "lost" if self.imu_watchdog.lost else "ok",
            "camera": "lost" if self.camera_watchdog.lost else "ok",
        }
        if self.player is not None:
            fields["can_log_sent"] = self.player.sent
            fields["can_log_errors"] = self.player.errors
        return fields

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
            s.thread_deaths = dict(r.thread_deaths)
            s.source_problems = {name: dict(p) for name, p in r.source_problems.items()}
        sender = self.output.status_sender
        if sender is not None and sender.deaths:
            s.thread_deaths[sender.name] = sender.deaths
        if self._thread_failure:
            s.error = self._thread_failure
        if self.pinger is not None:
            s.watchdog_withheld = self.pinger.withheld
        s.camera_read_failures = self.camera.errors
        s.status_lines = self.monitor.lines if self.monitor is not None else 0
        if self.player is not None:
            s.can_log_sent = self.player.sent
            s.can_log_errors = self.player.errors
        s.camera_timeouts = self.camera_watchdog.timeouts
        s.camera_gap_frames = self.camera_watchdog.gap_frames
        s.imu_timeouts = self.imu_watchdog.timeouts
        s.alert_send_errors = self.output.send_errors
        s.send_failures = dict(self.output.send_failures)
        s.can_frames = self.can_in.frames
        s.can_input_errors = self.can_in.decoder.stats.skipped
        s.can_queue_drops += self.can_in.dropped
        s.can_receive_errors = self.can_in.receive_errors

    def _shutdown_buses(self) -> None:
        buses = {id(self.input_bus): self.input_bus, id(self.output_bus): self.output_bus}
        if self.player_bus is not None:
            buses[id(self.player_bus)] = self.player_bus
        for bus in buses.values():
            try:
                bus.shutdown()
            except Exception:
                log.exception(kv("bus_shutdown_failed", channel=str(bus.channel_info)))


def _open_bus(interface: str, channel: str | int | None) -> can.BusABC:
    """A bus of the daemon; python-can's ``virtual`` one keeps the time stamps the daemon
    gives its frames (the frames' clock), as a real bus stamps them on the wire."""
    keep = {"preserve_timestamps": True} if interface == "virtual" else {}
    return open_bus(interface, channel, **keep)


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
    if s.thread_deaths:
        deaths = ", ".join(f"{name} {n}" for name, n in s.thread_deaths.items())
        yield f"reader threads died and were restarted: {deaths}"
    if s.can_log_sent or s.can_log_errors:
        yield f"CAN log player: {s.can_log_sent} frames sent, {s.can_log_errors} errors"
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
    "StatusMonitor",
    "SystemdNotifier",
    "install_signal_handlers",
    "iter_summary_lines",
    "kv",
]
