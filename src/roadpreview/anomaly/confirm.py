"""Ego confirmation: when the ego reaches an alerted spot, did it feel the anomaly?

For each alert, the ego's odometry (its speed integrated over the frames
since the lead's crossing) says when the ego's front axle reaches the spot
(the alert's distance less the camera's offset behind the front axle) and
its rear axle a wheelbase later. The ego's band-passed vertical acceleration
(`roadpreview.ego`) over [front - ``before_s``, rear + ``after_s``] is then
compared with its own background, the running median of the per-frame peaks
over the last ``background_s`` outside such windows:

* CONFIRMED: the window's largest peak is at least ``felt_ratio`` times the
  background and at least ``min_felt_mps2``;
* NOT_FELT: it is not, and the alert was full-width (a one-sided anomaly may
  have passed between or beside the ego's wheels: UNKNOWN);
* UNKNOWN: no accelerometer or speed over the window, the ego stopped or
  turned away (the spot is not reached within ``max_wait_s``), or too
  little background yet.

The outcomes feed a running precision estimate, (confirmed + 1) / (confirmed +
not felt + 2) over the last ``precision_window`` resolved alerts (a uniform
prior keeps it away from 0 and 1 with few alerts), published on CAN.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from roadpreview.configtools import check_ranges, param
from roadpreview.types import Confirmation, ConfirmationResult, Side


@dataclass(frozen=True)
class ConfirmConfig:
    """``[anomaly.confirm]``: checking alerts against the ego's own IMU."""

    enabled: bool = param(True, help="check each alert when the ego reaches its spot")
    camera_to_front_axle_m: float = param(
        0.2,
        unit="m",
        ge=-5.0,
        le=10.0,
        help="how far the ego's front axle is ahead of the camera (the simulator's car: camera"
        " 1.0 m, front axle 1.2 m ahead of the CG); measure it on the car",
    )
    wheelbase_m: float = param(2.7, unit="m", gt=0.5, le=8.0, help="the ego's wheelbase")
    before_s: float = param(
        0.3, unit="s", ge=0.0, le=5.0, help="the window opens this long before the front axle"
    )
    after_s: float = param(
        0.7,
        unit="s",
        ge=0.0,
        le=5.0,
        help="and closes this long after the rear axle (the body's response and the odometry's"
        " error)",
    )
    felt_ratio: float = param(
        2.5,
        unit="",
        gt=1.0,
        le=100.0,
        help="felt: the window's peak acceleration is this many times the ego's background",
    )
    min_felt_mps2: float = param(
        1.0,
        unit="m/s^2",
        ge=0.0,
        le=50.0,
        help="and at least this (0.1 g: what a passenger notices as a jolt)",
    )
    background_s: float = param(
        30.0, unit="s", gt=1.0, le=600.0, help="the ego's background over this much driving"
    )
    min_background_s: float = param(
        5.0, unit="s", ge=0.0, le=600.0, help="less background than this: UNKNOWN"
    )
    max_wait_s: float = param(
        15.0, unit="s", gt=0.0, le=600.0, help="a spot not reached within this is UNKNOWN"
    )
    min_speed_mps: float = param(
        1.0, unit="m/s", ge=0.0, le=50.0, help="slower: the odometry is not trusted"
    )
    precision_window: int = param(
        20, ge=1, le=10_000, help="resolved alerts the online precision is taken over"
    )


@dataclass
class _Pending:
    alert_id: int
    t_s: float
    distance_m: float
    one_sided: bool
    travelled_m: float = 0.0
    t_front: float = math.nan
    t_rear: float = math.nan
    peak: float = math.nan
    missing: bool = False


class EgoConfirmer:
    """Alerts in, `ConfirmationResult` when the ego has passed their spots (module docstring)."""

    def __init__(self, config: ConfirmConfig | None = None) -> None:
        self.config = config or ConfirmConfig()
        check_ranges(self.config, "ConfirmConfig")
        self._pending: list[_Pending] = []
        self._bg: deque[tuple[float, float]] = deque()
        self._t = math.nan
        self._v = math.nan
        self._recent: deque[Confirmation] = deque(maxlen=self.config.precision_window)
        self._odo: deque[tuple[float, float]] = deque()  # (frame time, distance driven)
        self.counts = {c: 0 for c in Confirmation}

    @property
    def pending(self) -> int:
        """Alerts whose spot the ego has not passed yet."""
        return len(self._pending)

    def add(self, alert_id: int, t_s: float, distance_m: float | None, side: Side) -> None:
        """An alert about a spot ``distance_m`` ahead of the camera at ``t_s`` (its crossing,
        usually a second or more before the alert is made: the distance the ego drove since
        is taken from the odometry's history)."""
        if not self.config.enabled:
            return
        d = math.nan if distance_m is None else float(distance_m)
        p = _Pending(alert_id, t_s, d, one_sided=side in (Side.LEFT, Side.RIGHT))
        p.travelled_m = self._driven_since(t_s)
        self._pending.append(p)

    def _driven_since(self, t: float) -> float:
        """Distance the ego drove from ``t`` to the last frame (0 before the history)."""
        if not self._odo or t >= self._odo[-1][0]:
            return 0.0
        times = [r[0] for r in self._odo]
        dists = [r[1] for r in self._odo]
        return float(dists[-1] - np.interp(t, times, dists))

    def precision(self) -> float:
        """Running precision of the resolved alerts (None-free: 0.5 before any)."""
        c = sum(1 for r in self._recent if r == Confirmation.CONFIRMED)
        return (c + 1.0) / (len(self._recent) + 2.0)

    @property
    def resolved(self) -> int:
        """Alerts resolved as CONFIRMED or NOT_FELT within the precision window."""
        return len(self._recent)

    def _background(self) -> float:
        if not self._bg or self._bg[-1][0] - self._bg[0][0] < self.config.min_background_s:
            return math.nan
        return float(np.median(np.fromiter((p for _, p in self._bg), float, len(self._bg))))

    def push(
        self, t: float, speed_mps: float | None, accel_peak_mps2: float
    ) -> list[ConfirmationResult]:
        """One camera frame: the ego's speed and the frame's acceleration peak (NaN: no IMU).
        Returns the alerts resolved at this frame."""
        cfg = self.config
        v = math.nan if speed_mps is None else float(speed_mps)
        dt = t - self._t if math.isfinite(self._t) else 0.0
        self._t = t
        v_prev = self._v
        self._v = v
        step = 0.5 * (v + v_prev) * dt if math.isfinite(v) and math.isfinite(v_prev) else math.nan
        odo = (self._odo[-1][1] if self._odo else 0.0) + (step if math.isfinite(step) else 0.0)
        self._odo.append((t, odo))
        while self._odo and self._odo[0][0] < t - cfg.max_wait_s:
            self._odo.popleft()
        in_window = False
        out: list[ConfirmationResult] = []
        keep: list[_Pending] = []
        # the background is read only to resolve a pending alert (a median over its window:
        # not worth a frame without one)
        bg = self._background() if self._pending else math.nan
        for p in self._pending:
            if t <= p.t_s:
                keep.append(p)
                continue
            if not math.isfinite(step) or not math.isfinite(p.distance_m) or v < cfg.min_speed_mps:
                if math.isfinite(p.t_front):
                    p.missing = True
                if t - p.t_s > cfg.max_wait_s:
                    out.append(self._result(p, Confirmation.UNKNOWN, t, bg))
                    continue
                if math.isfinite(step):
                    p.travelled_m += step
                keep.append(p)
                continue
            p.travelled_m += step
            front_at = p.distance_m - cfg.camera_to_front_axle_m
            if math.isnan(p.t_front) and p.travelled_m >= front_at:
                p.t_front = t
                p.t_rear = t + cfg.wheelbase_m / max(v, cfg.min_speed_mps)
            if math.isnan(p.t_front):
                if t - p.t_s > cfg.max_wait_s:
                    out.append(self._result(p, Confirmation.UNKNOWN, t, bg))
                    continue
                # the window opens before_s ahead of the front axle
                if p.travelled_m >= front_at - cfg.before_s * v:
                    in_window = True
                    p.peak = _nanmax(p.peak, accel_peak_mps2)
                    p.missing |= not math.isfinite(accel_peak_mps2)
                keep.append(p)
                continue
            in_window = True
            p.peak = _nanmax(p.peak, accel_peak_mps2)
            p.missing |= not math.isfinite(accel_peak_mps2)
            if t >= p.t_rear + cfg.after_s:
                out.append(self._decide(p, t, bg))
                continue
            keep.append(p)
        self._pending = keep
        if not in_window and math.isfinite(accel_peak_mps2):
            self._bg.append((t, accel_peak_mps2))
            while self._bg and self._bg[0][0] < t - cfg.background_s:
                self._bg.popleft()
        return out

    def _decide(self, p: _Pending, t: float, bg: float) -> ConfirmationResult:
        cfg = self.config
        if p.missing or not math.isfinite(p.peak) or not math.isfinite(bg):
            return self._result(p, Confirmation.UNKNOWN, t, bg)
        felt = p.peak >= max(cfg.felt_ratio * bg, cfg.min_felt_mps2)
        if felt:
            outcome = Confirmation.CONFIRMED
        elif p.one_sided:
            outcome = Confirmation.UNKNOWN
        else:
            outcome = Confirmation.NOT_FELT
        return self._result(p, outcome, t, bg)

    def _result(
        self, p: _Pending, outcome: Confirmation, t: float, bg: float
    ) -> ConfirmationResult:
        self.counts[outcome] += 1
        if outcome != Confirmation.UNKNOWN:
            self._recent.append(outcome)
        return ConfirmationResult(p.alert_id, outcome, t, p.t_front, p.peak, bg)


def _nanmax(a: float, b: float) -> float:
    if math.isnan(a):
        return b
    if math.isnan(b):
        return a
    return max(a, b)
