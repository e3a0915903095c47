"""Road roughness as a state: an ISO 8608 class estimate from the ego's and the lead's motion.

A suspension wants "rough road" as a state, not ten alerts a minute. ISO 8608
classes a road by its displacement PSD at n0 = 0.1 cycles/m, G_d(n0), with a
waviness of 2: class A up to 32e-6 m³, each class 4 times the previous (B up
to 128e-6, C 512e-6, D 2048e-6, E 8192e-6, ...). At speed v such a road drives
a linear car with a temporal PSD G_d(n0) n0² v / f², so the mean square of any
linear output is G_d(n0) times a gain of the car and the speed
(`roadpreview.anomaly.response.roughness_gain`); inverted, a measured mean
square gives G_d(n0):

* **ego** (the road under the car): the band-passed vertical acceleration of
  the body (`roadpreview.ego`), mean square over 1 s blocks, against the nominal
  quarter car's acceleration gain through the same high-pass;
* **lead** (the road ahead; off by default, ``lead_estimate``): the lead's
  compensated image row in metres at its distance (y_c d / f), detrended over
  1 s blocks, against the rear face's gain (both axles on the same track, τ
  apart) through the same detrending, with the tracking noise taken off. On the
  evaluation's drives this block variance is 100-500 times the lead's true
  heave: within a second, y_c moves with the pitch compensation's residual
  (0.1° is 3 px at 20 m) far more than with the lead's body, and the class
  comes out E-H on every road from A to E. It is not published unless asked for.

Both average the car's two wheel tracks, whose short waves are independent:
``track_averaging`` (0.5, the variance of the mean of two independent tracks)
scales the gains. Over the last ``window_s`` the class is taken from the median
of the blocks' mean squares: the blocks an anomaly or a hill crest falls in are
a minority, and the median does not see them (a trimmed mean did: on the wild
drives it put 6 of 22 one class too high; the median gets all 22 and the 12
generalization drives right). The estimate is recomputed once per block (O(1)
per frame).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from roadpreview.anomaly.response import ISO8608_N0, NominalVehicle
from roadpreview.configtools import check_ranges, param
from roadpreview.types import ISO8608_CLASSES, RoadState

FloatArray = NDArray[np.float64]

#: ISO 8608 classes and the geometric mean G_d(n0) of each (m³)
ISO8608_GD_N0 = {c: 16e-6 * 4.0**i for i, c in enumerate(ISO8608_CLASSES)}


def iso8608_class(gd_n0: float) -> str | None:
    """The class whose range (mean / 2 .. mean x 2) holds ``gd_n0`` (None: unknown)."""
    if not math.isfinite(gd_n0) or gd_n0 <= 0:
        return None
    i = math.floor(math.log(gd_n0 / 32e-6, 4.0)) + 1
    return ISO8608_CLASSES[min(max(i, 0), len(ISO8608_CLASSES) - 1)]


@dataclass(frozen=True)
class RoughnessConfig:
    """``[anomaly.roughness]``: the road-class estimate."""

    enabled: bool = param(True, help="estimate the road's ISO 8608 class")
    window_s: float = param(
        20.0, unit="s", gt=1.0, le=600.0, help="the class is taken over this much driving"
    )
    block_s: float = param(1.0, unit="s", gt=0.1, le=10.0, help="mean squares per block")
    min_blocks: int = param(5, ge=1, le=1000, help="fewer blocks: no estimate")
    lead_estimate: bool = param(
        False,
        help="also class the road ahead from the lead's compensated row (RoadClassLead);"
        " dominated by the pitch compensation's residual on the evaluation's drives",
    )
    min_speed_mps: float = param(
        3.0, unit="m/s", gt=0.0, le=50.0, help="slower, the road excites too little to class it"
    )
    track_averaging: float = param(
        0.5,
        unit="",
        gt=0.0,
        le=1.0,
        help="variance share of one track left when the car averages two tracks whose short"
        " waves are independent",
    )
    accel_highpass_tau_s: float = param(
        0.5, unit="s", gt=0.0, le=60.0, help="the ego monitor's high-pass (`[ego]`), for the gain"
    )
    accel_band_hz: tuple[float, float] = param(
        (0.1, 25.0), unit="Hz", help="frequencies the acceleration gain integrates over"
    )
    tracking_noise_px: float = param(
        0.15, unit="px", ge=0.0, le=10.0, help="tracking noise taken off the lead's blocks"
    )


@lru_cache(maxsize=256)
def _accel_gain(
    vehicle: NominalVehicle, speed_q: float, tau: float, band: tuple[float, float]
) -> float:
    """Mean square of the body's vertical acceleration at its centre per unit G_d(n0): the
    two axles see the same track a wheelbase apart, and the centre moves as their
    average (weighted by the CG's position; a typical 45:55), through the monitor's
    high-pass."""
    f = np.geomspace(band[0], band[1], 400)
    w = 2 * np.pi * f
    hp = (w * tau) ** 2 / (1.0 + (w * tau) ** 2)
    lag = vehicle.wheelbase_m / speed_q
    axles = np.abs(0.55 + 0.45 * np.exp(-1j * w * lag)) ** 2
    integrand = vehicle.gain_sq(f, 2) * axles * hp / (f * f)
    return float(ISO8608_N0**2 * speed_q * np.trapezoid(integrand, f))


def _detrend_response(f: FloatArray, block_s: float) -> FloatArray:
    """Share of a sinusoid's variance left after removing its least-squares line over a
    block (averaged over phase)."""
    t = np.linspace(0.0, block_s, 64)
    basis = np.column_stack([np.ones_like(t), t - t.mean()])
    proj = basis @ np.linalg.pinv(basis)
    out = np.empty(f.size)
    for k, fk in enumerate(f):  # once per (speed, block) pair, cached
        c, s = np.cos(2 * np.pi * fk * t), np.sin(2 * np.pi * fk * t)
        rc, rs = c - proj @ c, s - proj @ s
        out[k] = (rc @ rc + rs @ rs) / t.size  # mean over phase of resid var / (1/2)
    return out


@lru_cache(maxsize=256)
def _lead_gain(vehicle: NominalVehicle, speed_q: float, block_s: float) -> float:
    f = np.geomspace(0.05, 15.0, 300)
    w = 2 * np.pi * f
    tau = vehicle.wheelbase_m / speed_q
    rho = vehicle.rho
    axles = np.abs((1 + rho) * np.exp(-1j * w * tau) - rho) ** 2
    integrand = vehicle.gain_sq(f, 0) * axles * _detrend_response(f, block_s) / (f * f)
    return float(ISO8608_N0**2 * speed_q * np.trapezoid(integrand, f))


class _Blocks:
    """Mean squares of 1 s blocks over a window, their median on demand."""

    def __init__(self) -> None:
        self.values: deque[tuple[float, float]] = deque()

    def add(self, t: float, ms: float, window_s: float) -> None:
        self.values.append((t, ms))
        while self.values and self.values[0][0] < t - window_s:
            self.values.popleft()

    def median(self, min_blocks: int) -> float:
        if len(self.values) < min_blocks:
            return math.nan
        return float(np.median([m for _, m in self.values]))


class RoadRoughness:
    """Per-frame inputs in, the `RoadState` out (module docstring)."""

    def __init__(
        self, config: RoughnessConfig | None = None, vehicle: NominalVehicle | None = None
    ) -> None:
        self.config = config or RoughnessConfig()
        check_ranges(self.config, "RoughnessConfig")
        self.vehicle = vehicle or NominalVehicle()
        self.state = RoadState()
        self._ego = _Blocks()
        self._lead = _Blocks()
        self._block_start = math.nan
        self._acc_sq = 0.0  # ego: sum of mean squares x samples in this block
        self._acc_n = 0
        self._speed_sum = 0.0
        self._speed_n = 0
        self._lead_rows: list[tuple[float, float, float]] = []  # (t, metres, px scale)

    def push(
        self,
        t: float,
        *,
        ego_speed_mps: float | None,
        ego_accel_rms_mps2: float,
        ego_accel_samples: int,
        lead_y_c_px: float,
        lead_distance_m: float,
        focal_px: float,
        lead_valid: bool,
    ) -> RoadState:
        """One camera frame; the state (updated once per block)."""
        cfg = self.config
        if not cfg.enabled:
            return self.state
        if math.isnan(self._block_start):
            self._block_start = t
        v = math.nan if ego_speed_mps is None else float(ego_speed_mps)
        if math.isfinite(v):
            self._speed_sum += v
            self._speed_n += 1
        if math.isfinite(ego_accel_rms_mps2) and ego_accel_samples > 0:
            self._acc_sq += ego_accel_rms_mps2**2 * ego_accel_samples
            self._acc_n += ego_accel_samples
        if (
            cfg.lead_estimate
            and lead_valid
            and math.isfinite(lead_y_c_px)
            and math.isfinite(lead_distance_m)
            and math.isfinite(focal_px)
            and focal_px > 0
        ):
            scale = lead_distance_m / focal_px
            self._lead_rows.append((t, lead_y_c_px * scale, scale))
        if t - self._block_start >= cfg.block_s:
            self._close_block(t)
        return self.state

    def _close_block(self, t: float) -> None:
        cfg = self.config
        v = self._speed_sum / self._speed_n if self._speed_n else math.nan
        if math.isfinite(v) and v >= cfg.min_speed_mps:
            if self._acc_n:
                self._ego.add(t, self._acc_sq / self._acc_n, cfg.window_s)
            rows = self._lead_rows
            if cfg.lead_estimate and len(rows) >= 8:
                arr = np.asarray(rows)
                tt = arr[:, 0] - arr[:, 0].mean()
                z = arr[:, 1]
                coef = np.polyfit(tt, z, 1)
                ms = float(np.mean((z - np.polyval(coef, tt)) ** 2))
                noise = (cfg.tracking_noise_px * float(arr[:, 2].mean())) ** 2
                self._lead.add(t, max(ms - noise, 0.0), cfg.window_s)
        self._block_start = t
        self._acc_sq, self._acc_n = 0.0, 0
        self._speed_sum, self._speed_n = 0.0, 0
        self._lead_rows = []
        self._estimate(v)

    def _estimate(self, v: float) -> None:
        cfg = self.config
        if not (math.isfinite(v) and v >= cfg.min_speed_mps):
            return
        v_q = round(v * 2.0) / 2.0  # gains cached per 0.5 m/s
        ego_ms = self._ego.median(cfg.min_blocks)
        lead_ms = self._lead.median(cfg.min_blocks)
        avg = cfg.track_averaging
        ego_g = ego_ms / (
            avg * _accel_gain(self.vehicle, v_q, cfg.accel_highpass_tau_s, cfg.accel_band_hz)
        )
        lead_g = lead_ms / (avg * _lead_gain(self.vehicle, v_q, cfg.block_s))
        ego_c, lead_c = iso8608_class(ego_g), iso8608_class(lead_g)
        use_ego = ego_c is not None
        self.state = RoadState(
            iso_class=ego_c if use_ego else lead_c,
            gd_n0=ego_g if use_ego else lead_g,
            ego_class=ego_c,
            ego_gd_n0=ego_g,
            lead_class=lead_c,
            lead_gd_n0=lead_g,
        )
