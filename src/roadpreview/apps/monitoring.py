"""The daemon's supervision parts: structured log lines (`kv`), the camera and IMU
watchdogs, the log and status sinks (`LogSink`, `StatusMonitor`: the periodic one-line
status, also sent to systemd), `SystemdNotifier` (``sd_notify``: READY, STATUS,
WATCHDOG, STOPPING) and `WatchdogPinger` (WATCHDOG=1 while the loop is healthy).
`roadpreview.apps.daemon` composes them with the run loop. The health times are on an
injected clock (the monotonic clock in the product, virtual time in tests)."""

from __future__ import annotations

import logging
import math
import os
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import sdnotify

from roadpreview.clock import Clock
from roadpreview.pipeline.pipeline import FrameResult
from roadpreview.sinks import Sink
from roadpreview.types import Alert, CameraFrame, ImuSample, Sample, Status

log = logging.getLogger("roadpreview.apps.daemon")  # one logger for the daemon's lines


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


class StatusMonitor(Sink):
    """The daemon's health as the loop sees it, and the periodic status line.

    Every ``period_s`` on the frames' clock (hooked on the loop's status schedule) one
    line ``event=status t=... mode=... fps=... frames=... drops=... alerts=...`` followed
    by the daemon's own ``fields()`` (bus errors, CAN, IMU and camera state), logged and
    handed to ``on_line``. ``fps`` counts the camera frames processed per second of the
    frames' clock since the previous line; ``drops`` the camera frames read but not
    processed (the gaps in their indices: the loop fell behind, or a frame came out of
    order). ``on_ready`` is called once, at the first frame processed (a real one, or the
    camera watchdog's image-less one when the camera is silent from the start).
    `unhealthy` says why the watchdog pings should stop, if they should; the frames'
    arrival is timed on ``clock`` (default ``time.monotonic``).
    """

    def __init__(
        self,
        period_s: float,
        fields: Callable[[], dict[str, Any]] = dict,
        *,
        on_ready: Callable[[CameraFrame], None] | None = None,
        on_line: Callable[[str], None] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.period_s = period_s
        self.fields = fields
        self.on_ready = on_ready
        self.on_line = on_line
        self.clock = clock
        self.frames = 0  #: camera frames processed (image-less injected ones not counted)
        self.drops = 0  #: camera frames read but not processed
        self.alerts = 0  #: alerts raised (flushed ones included)
        self.lines = 0  #: status lines logged
        self.ready = False
        self.last_frame_mono = math.nan  #: ``clock()`` at the last frame processed
        self.last_camera_mono = math.nan  #: ... at the last real camera frame processed
        self._t0 = math.nan  # the previous line's frame time and frame count
        self._frames0 = 0
        self._next = -math.inf

    def on_frame(self, frame: CameraFrame, result: FrameResult, status: Status) -> None:
        now = self.clock()
        self.last_frame_mono = now
        if frame.index >= 0:
            self.frames += 1
            self.last_camera_mono = now
            self.drops = max(self.drops, frame.index + 1 - self.frames)
        self.alerts += len(result.alerts)
        if not self.ready:
            if math.isnan(self.last_camera_mono):
                self.last_camera_mono = now  # silent since the start: lost from here
            if self.on_ready is not None:
                self.on_ready(frame)
            self.ready = True  # after READY=1 went out: no WATCHDOG=1 before it

    def on_flush(self, t_s: float, alerts: Sequence[Alert], status: Status) -> None:
        self.alerts += len(alerts)

    def on_status(self, t_s: float, status: Status) -> None:
        if self.period_s <= 0:
            return
        if math.isnan(self._t0):
            self._t0, self._frames0, self._next = t_s, self.frames, t_s + self.period_s
            return
        if t_s < self._next:
            return
        fps = (self.frames - self._frames0) / (t_s - self._t0) if t_s > self._t0 else 0.0
        self._t0, self._frames0, self._next = t_s, self.frames, t_s + self.period_s
        line = kv(
            "status",
            t=t_s,
            mode=status.mode.name,
            fps=round(fps, 1),
            frames=self.frames,
            drops=self.drops,
            alerts=self.alerts,
            **self.fields(),
        )
        log.info(line)
        self.lines += 1
        if self.on_line is not None:
            self.on_line(line)

    def unhealthy(self, now_mono: float, stall_s: float, camera_lost_s: float = 0.0) -> str:
        """Why the daemon is unhealthy at ``now_mono`` (on ``clock``), or "": no
        frame processed for ``stall_s`` (the loop hangs; a lost camera still gives an
        image-less frame every status period), or no camera frame for ``camera_lost_s``
        (0: never a reason)."""
        if not self.ready:
            return ""
        silent = now_mono - self.last_frame_mono
        if silent > stall_s:
            return f"loop stalled: no frame processed for {silent:.1f} s"
        lost = now_mono - self.last_camera_mono
        if camera_lost_s > 0 and lost > camera_lost_s:
            return f"camera lost for {lost:.1f} s"
        return ""


class SystemdNotifier:
    """``sd_notify`` through sdnotify: READY, STATUS, WATCHDOG, STOPPING. Does nothing
    when ``NOTIFY_SOCKET`` is unset (not started by systemd with ``Type=notify``)."""

    def __init__(self) -> None:
        self.enabled = bool(os.environ.get("NOTIFY_SOCKET"))
        self._notifier = sdnotify.SystemdNotifier() if self.enabled else None
        self.sent = 0  #: notifications sent

    def notify(self, state: str) -> None:
        if self._notifier is not None:
            self._notifier.notify(state)
            self.sent += 1

    def close(self) -> None:
        """Close the socket (sdnotify leaves it open)."""
        if self._notifier is not None and self._notifier.socket is not None:
            self._notifier.socket.close()
        self._notifier = None

    @staticmethod
    def watchdog_period_s(configured_s: float = 0.0) -> float:
        """The ping period: ``configured_s`` if set, else half of ``WATCHDOG_USEC`` (the
        unit's ``WatchdogSec=``, when ``WATCHDOG_PID`` is unset or this process); 0: no
        watchdog."""
        if configured_s > 0:
            return configured_s
        pid = os.environ.get("WATCHDOG_PID", "")
        if pid and pid != str(os.getpid()):
            return 0.0
        try:
            usec = int(os.environ.get("WATCHDOG_USEC", "0"))
        except ValueError:
            log.warning(kv("watchdog_usec_invalid", value=os.environ.get("WATCHDOG_USEC", "")))
            return 0.0
        return usec / 2e6 if usec > 0 else 0.0


class WatchdogPinger:
    """systemd's watchdog: ``WATCHDOG=1`` every ``period_s`` of ``clock`` while the loop is
    healthy (`StatusMonitor.unhealthy` with ``stall_s`` and ``camera_lost_s``); the pings
    are withheld (logged once, counted in ``withheld``, ``STATUS=unhealthy: ...``) while it
    is not, so that systemd restarts a stalled daemon (``Restart=on-failure``), and resume
    (logged) when it is healthy again. No ping before READY=1 (``monitor.ready``: systemd
    starts its watchdog then). `run` until ``done`` is set (a thread of its own)."""

    def __init__(
        self,
        notifier: SystemdNotifier,
        monitor: StatusMonitor,
        period_s: float,
        *,
        stall_s: float,
        camera_lost_s: float = 0.0,
        clock: Clock,
    ) -> None:
        self.notifier = notifier
        self.monitor = monitor
        self.period_s = period_s
        self.stall_s = stall_s
        self.camera_lost_s = camera_lost_s
        self.clock = clock
        self.withheld = 0  #: times the pings were withheld
        self.pings = 0  #: WATCHDOG=1 sent

    def run(self, done: threading.Event) -> None:
        withheld = ""
        while not self.clock.wait(done, self.period_s):
            if not self.monitor.ready:
                continue  # systemd starts the watchdog at READY=1
            why = self.monitor.unhealthy(self.clock.now(), self.stall_s, self.camera_lost_s)
            if not why:
                self.notifier.notify("WATCHDOG=1")
                self.pings += 1
                if withheld:
                    log.warning(kv("watchdog_resumed", after=withheld))
                    withheld = ""
            elif not withheld:
                withheld = why
                self.withheld += 1
                log.error(kv("watchdog_withheld", reason=why))
                self.notifier.notify(f"STATUS=unhealthy: {why}")
