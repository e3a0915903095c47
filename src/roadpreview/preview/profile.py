"""The road-profile preview: the road under the lead's wheels, by inverting its nominal response.

Per camera frame `ProfileEstimator.push` stores the lead's channels in a ring (O(1)); every
``period_s`` of frame time it solves for the road height under the lead's front wheel on
the frame grid of the last ``history_s`` and maps it to 0.5 m bins along the ego's path
(the method: `roadpreview.preview`, ``docs/method.md``, "The road-profile preview").
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import signal
from threadpoolctl import ThreadpoolController

from roadpreview.anomaly.base import TrajectorySample
from roadpreview.anomaly.response import NominalVehicle, TemplateBank
from roadpreview.anomaly.two_axle_signal import Ring
from roadpreview.configtools import check_ranges
from roadpreview.errors import InputDataError
from roadpreview.preview.config import PreviewConfig
from roadpreview.types import Alert, RoadPreview, Side

FloatArray = NDArray[np.float64]

# columns of the sample ring
COL_T, COL_Y, COL_ROLL, COL_D, COL_V, COL_F = range(6)
NCOL = 6
#: correlation of the left and right wheel tracks' roughness assumed by the prior (the
#: simulator's default; measured roads 0.3-0.7 at the wavelengths the body passes): the
#: heave (mean of the tracks) gets (1 + c) / 2 of a track's variance, the roll (their
#: difference) 2 (1 - c)
TRACK_CORRELATION = 0.5
#: the ramp responses are computed on this fine grid, s
_FINE_DT_S = 0.001
#: the operator is cached per wheelbase lag rounded to this, s (1.4 m/s of lead speed at
#: 50 km/h: a steady drive reuses one operator)
_TAU_STEP_S = 0.01
#: the ego's odometry is kept this long: an alert is passed well within it, s
_ODOMETRY_S = 30.0
#: sub-points per bin at which the profile is averaged over the bin
_SUB_POINTS = 5
#: the history is used in whole multiples of this (fewer operators while it fills up), s
_HISTORY_STEP_S = 0.5


@functools.lru_cache(maxsize=8)
def ramp_response(vehicle: NominalVehicle, dt_s: float, horizon_s: float = 6.0) -> TemplateBank:
    """The nominal quarter car's body displacement after the road under its wheel rises by
    1 m linearly over ``dt_s`` from t = 0 (the linear interpolation of the road between two
    frames), as a one-row `TemplateBank` (so that `TemplateBank.two_axle` builds the rear
    face's two-axle response from it)."""
    t = np.arange(0.0, horizon_s, _FINE_DT_S)
    u = np.clip(t / dt_s, 0.0, 1.0)
    _, q, _ = signal.lsim(vehicle.quarter_car, u, t)
    return TemplateBank(np.array([dt_s]), _FINE_DT_S, np.asarray(q, dtype=float)[None, :])


@dataclass(frozen=True, eq=False)
class FaceOperator:
    """The rear face's displacement on the observation grid per unit road increment, with the
    drift (offset and slope) projected out, in the eigenbasis of its normal matrix.

    Unknowns: the increments u_j of the road under the front wheel between grid times
    t_{j-1} and t_j, j = 0 .. n_unknown - 1 (u = V a in the eigenbasis V); observations:
    the last ``n_obs`` grid times. With white noise of variance r and a prior variance q
    per increment, the posterior of a is independent per direction: mean
    (P S V)^T z / r / (λ / r + 1 / q), variance 1 / (λ / r + 1 / q).
    """

    n_obs: int
    n_unknown: int
    psv: FloatArray  #: (n_obs, n_unknown) P S V: S with the drift projected out, rotated
    eigvals: FloatArray  #: (n_unknown,) λ of (P S)^T (P S), >= 0
    #: (n_obs, n_unknown) L V on the observed grid: the road w_k = sum_{j <= k} u_j there
    #: per eigen-direction
    lv: FloatArray


@functools.cache
def _blas() -> ThreadpoolController:
    """The process's thread pools, found once (a search of the loaded libraries costs
    milliseconds: not at every solve)."""
    return ThreadpoolController()


def _quantised(dt: float) -> float:
    """``dt`` on a grid of 1 % steps (one operator per frame rate, not per jitter)."""
    if not dt > 0:
        return math.nan
    k = round(math.log(dt) / math.log(1.01))
    return round(1.01**k, 6)


@functools.lru_cache(maxsize=128)
def face_operator(
    vehicle: NominalVehicle, dt_s: float, tau_s: float, n_obs: int, n_pre: int
) -> FaceOperator:
    """`FaceOperator` of the nominal car at grid step ``dt_s`` and wheelbase lag ``tau_s``,
    with ``n_pre`` unknown increments before the ``n_obs`` observed grid times (road whose
    response is still in the oldest frames). Cached: a steady drive reuses one."""
    n = n_pre + n_obs
    bank = ramp_response(vehicle, dt_s)
    lags = np.arange(-n, n + 2, dtype=float) * dt_s
    face = bank.two_axle(lags, tau_s, vehicle.rho)[0]  # face(m dt), m = -n .. n + 1
    k = np.arange(n_pre, n)[:, None]
    j = np.arange(n)[None, :]
    s = face[(k - j + 1) + n]  # the ramp of increment j starts at t_{j-1}
    tc = (np.arange(n_obs, dtype=float) - (n_obs - 1)) * dt_s
    x = np.column_stack([np.ones(n_obs), tc])
    ps = s - x @ np.linalg.lstsq(x, s, rcond=None)[0]
    lam, vec = np.linalg.eigh(ps.T @ ps)
    lv = np.cumsum(vec, axis=0)[n_pre:]
    return FaceOperator(n_obs, n, ps @ vec, np.maximum(lam, 0.0), lv)


@functools.lru_cache(maxsize=32)
def _smoother(n_obs: int, dt_s: float) -> tuple[FloatArray, FloatArray]:
    """The hat matrix of a least-squares quadratic in time on ``n_obs`` grid points (n, n),
    and the matrix giving that quadratic's slope at them (n, n)."""
    tc = (np.arange(n_obs, dtype=float) - (n_obs - 1)) * dt_s
    deg = 2 if n_obs >= 6 else 1
    design = np.vander(tc, deg + 1, increasing=True)
    fit = np.linalg.pinv(design)
    slope = np.column_stack([np.zeros(n_obs), np.ones(n_obs), 2.0 * tc])[:, : deg + 1]
    return design @ fit, slope @ fit


def _bin_average(
    x_k: FloatArray, edges: FloatArray, values: FloatArray
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """(bins, ...) the mean over each bin between ``edges`` of the linear interpolant of
    ``values`` (rows at the increasing positions ``x_k``), at `_SUB_POINTS` points per bin
    (a gather of two rows per point: no dense bins x positions matrix); and which bins
    have their centre inside the positions' span (the others are invalid)."""
    nb, n = edges.size - 1, x_k.size
    frac = (np.arange(_SUB_POINTS) + 0.5) / _SUB_POINTS
    pos = np.clip((edges[:-1, None] + (edges[1] - edges[0]) * frac).ravel(), x_k[0], x_k[-1])
    i1 = np.clip(np.searchsorted(x_k, pos, side="right"), 1, n - 1)
    x0 = x_k[i1 - 1]
    w1 = ((pos - x0) / (x_k[i1] - x0))[:, None]
    at = values[i1 - 1] * (1.0 - w1) + values[i1] * w1  # (nb * SUB, ...)
    mean = at.reshape(nb, _SUB_POINTS, *values.shape[1:]).mean(axis=1)
    centres = edges[:-1] + 0.5 * (edges[1] - edges[0])
    return np.asarray(mean, dtype=np.float64), (centres >= x_k[0]) & (centres <= x_k[-1])


def _on_grid(
    grid_t: FloatArray, t: FloatArray, values: FloatArray, ok: NDArray[np.bool_], max_gap_s: float
) -> tuple[FloatArray, int]:
    """The columns of ``values`` (rows at times ``t``; rows ``ok`` used) interpolated onto
    ``grid_t``, and the index of the first grid time after the last stretch without a used
    row longer than ``max_gap_s`` (the usable history starts there; ``grid_t.size``: none)."""
    tv = t[ok]
    if tv.size < 2:
        return np.full((grid_t.size, values.shape[1]), np.nan), grid_t.size
    vv = values[ok]
    i = np.clip(np.searchsorted(tv, grid_t, side="right"), 1, tv.size - 1)
    t0, t1 = tv[i - 1], tv[i]
    w = np.clip((grid_t - t0) / (t1 - t0), 0.0, 1.0)
    out = vv[i - 1] * (1.0 - w)[:, None] + vv[i] * w[:, None]
    bad = (grid_t < tv[0] - 1e-9) | (grid_t > tv[-1] + 1e-9) | ((t1 - t0) > max_gap_s)
    if not bad.any():
        return out, 0
    return out, int(np.flatnonzero(bad)[-1]) + 1


def _range_free(y: FloatArray, d: FloatArray) -> FloatArray:
    """``y`` (px) less its least-squares fit a + b / d over the window.

    The tracked row is y = c_y + f (h_cam - h_face) / d: the principal point and the
    rear face's mean height below the camera give a term in 1 / d that moves the row by
    pixels as the gap changes by metres (f 0.5 m / 15 m - f 0.5 m / 17 m = 4 px at
    f = 1000 px: 60 mm of road at 15 m). The road's response is what is left. (The halves'
    difference has no principal point, and the halves are at one height: it is taken as
    it is.)"""
    x = np.column_stack([np.ones_like(d), 1.0 / d])
    coef = np.linalg.lstsq(x, y, rcond=None)[0]
    return np.asarray(y - x @ coef, dtype=np.float64)


@dataclass(frozen=True, eq=False)
class _Window:
    """The lead's channels on the regular grid of one solve (oldest first)."""

    t: FloatArray  #: grid times, s
    heave_m: FloatArray  #: rear-face displacement observed, m (-(d / f) y_c)
    roll_m: FloatArray | None  #: the same of the halves' difference (None: no halves)
    d_m: FloatArray  #: smoothed lead distance, m
    v_lead: float  #: the lead's mean speed over ground, m/s
    x_m: FloatArray  #: the front wheel's road point ahead of the ego's front axle now, m
    lead_rear_axle_m: float  #: the lead's rear axle ahead of the ego's front axle now, m
    sigma_m: float  #: the tracking noise at the window's mean distance, m


class ProfileEstimator:
    """Streaming road-profile preview along the ego's path (``RP_PREVIEW``).

    ``push`` one `TrajectorySample` per camera frame (times increasing); every
    ``config.period_s`` of frame time it returns a `RoadPreview` (bins NaN where there is
    no estimate: too little history, a lost lead, no speed or focal length), else None.
    """

    def __init__(
        self,
        config: PreviewConfig | None = None,
        vehicle: NominalVehicle | None = None,
        *,
        principal_row_px: float = math.nan,
    ) -> None:
        self.config = config or PreviewConfig()
        self.vehicle = vehicle or NominalVehicle()
        #: the camera's principal point row c_y, px: the row becomes the rear face's height
        #: relative to the camera, (c_y - y) d / f, exactly; NaN: unknown, the row's term in
        #: 1 / d is fitted per window instead (`_range_free`)
        self.principal_row_px = float(principal_row_px)
        check_ranges(self.config, "PreviewConfig")
        self.config.validate("PreviewConfig")
        check_ranges(self.vehicle, "NominalVehicle")
        # the history, the settling span and a margin at up to 120 fps
        span = self.config.history_s + self.config.settle_s + 1.0
        self._ring = Ring(math.ceil(span * 120.0), NCOL)
        self._t_last = -math.inf
        self._next_t = -math.inf
        self._focal = math.nan
        # the ego's odometry (time, distance driven) over the alerts' lifetime, and the
        # alerted anomalies by id: their bins carry the alert's fit (`add_alert`)
        self._odo_t: list[float] = []
        self._odo_s: list[float] = []
        self._odo_v = math.nan
        self._alerts: dict[int, Alert] = {}

    def restart(self) -> None:
        """A new lead target: drop the history (the next previews are NaN until it refills).
        The alerted anomalies stay (they lie on the road, whichever car crossed them)."""
        self._ring.clear()

    def add_alert(self, alert: Alert) -> None:
        """An anomaly the detector confirmed (the pipeline draws no provisional alert: they
        are too often false): its bins carry the alert's height, over its length
        (one bin when unresolved), with its std, on its side's track, until the ego's front
        axle has passed it. The detector's fit assumes a discrete anomaly (a pulse under
        each axle), which the preview's random-walk prior spreads over metres: where it
        has spoken, its height is the better estimate."""
        if alert.distance_m is not None and alert.height_mm is not None:
            self._alerts[alert.alert_id] = alert

    def _driven_since(self, t0: float) -> float:
        """The ego's distance driven from ``t0`` to the last frame (NaN: unknown)."""
        ts, ss = self._odo_t, self._odo_s
        if not ts or t0 < ts[0]:
            return math.nan
        return ss[-1] - float(np.interp(t0, ts, ss))

    def _overlay(self, preview: RoadPreview) -> RoadPreview:
        """``preview`` with the alerted anomalies' bins (`add_alert`)."""
        if not self._alerts or preview.height_m.shape[1] == 0:
            return preview
        cfg = self.config
        height, std = preview.height_m.copy(), preview.std_m.copy()
        edges = preview.start_m + preview.bin_m * np.arange(height.shape[1] + 1)
        for alert_id, a in list(self._alerts.items()):  # a handful of alerts
            assert a.distance_m is not None
            assert a.height_mm is not None
            x = a.distance_m - cfg.camera_to_front_axle_m - self._driven_since(a.t_s)
            half = 0.5 * max(a.length_m or 0.0, preview.bin_m)
            if not math.isfinite(x) or x + half < 0.0:
                del self._alerts[alert_id]  # passed (or its place is lost)
                continue
            hit = (edges[1:] > x - half) & (edges[:-1] < x + half)
            if not hit.any():
                continue
            rows = (
                [0] if not preview.sides else {Side.LEFT: [0], Side.RIGHT: [1]}.get(a.side, [0, 1])
            )
            for r in rows:
                height[r, hit] = 1e-3 * a.height_mm
                std[r, hit] = 1e-3 * (a.height_std_mm if a.height_std_mm is not None else math.nan)
        return RoadPreview(
            preview.t_s,
            preview.bin_m,
            preview.start_m,
            height,
            std,
            preview.sides,
            preview.lead_rear_axle_m,
        )

    def push(self, sample: TrajectorySample) -> RoadPreview | None:
        """Take the next frame; return a preview when one is due (every ``period_s``).

        A sample without a finite time is skipped. Raises `InputDataError` when times do
        not increase.
        """
        cfg = self.config
        t = float(sample.t)
        if not math.isfinite(t):
            return None
        if t <= self._t_last:
            raise InputDataError(
                f"trajectory sample t = {t!r} s: times must increase (previous {self._t_last} s)"
            )
        self._t_last = t
        if not cfg.enabled:
            return None
        v_now = sample.ego_speed_mps
        if v_now is not None and math.isfinite(v_now) and v_now >= 0:
            if self._odo_t:
                v_prev = self._odo_v
                step = 0.5 * (v_now + v_prev) * (t - self._odo_t[-1])
                self._odo_t.append(t)
                self._odo_s.append(self._odo_s[-1] + step)
                if self._odo_t[0] < t - _ODOMETRY_S:
                    del self._odo_t[:1], self._odo_s[:1]
            else:
                self._odo_t.append(t)
                self._odo_s.append(0.0)
            self._odo_v = float(v_now)
        else:  # a gap in the speed: the alerts' places are lost from here on
            self._odo_t.clear()
            self._odo_s.clear()
        if math.isfinite(sample.focal_px) and sample.focal_px > 0:
            self._focal = float(sample.focal_px)
        ok = sample.valid and math.isfinite(sample.y_c)
        y = sample.y_c if ok else math.nan
        roll = sample.y_c_left - sample.y_c_right if ok else math.nan
        d = sample.lead_distance_m if ok and sample.lead_distance_m > 0 else math.nan
        v = sample.ego_speed_mps if sample.ego_speed_mps is not None else math.nan
        self._ring.push(np.array([t, y, roll, d, v, self._focal]))
        if t < self._next_t - 1e-3 * cfg.period_s:
            return None
        self._next_t = max(self._next_t + cfg.period_s, t + 0.5 * cfg.period_s)
        return self.preview(t)

    # -- the solve (at the period) -------------------------------------------------------
    def preview(self, t: float) -> RoadPreview:
        """The preview as of the last pushed frame at ``t`` (NaN bins where no estimate)."""
        # small matrices (a few hundred): BLAS threads only cost here (on a loaded 2-core
        # machine they multiplied the CPU time of a solve by 5-10)
        with _blas().limit(limits=1, user_api="blas"):
            win = self._window(t)
            if win is None:
                return self._overlay(self._empty(t, math.nan))
            return self._overlay(self._solve(t, win))

    def _empty(self, t: float, lead_rear_m: float) -> RoadPreview:
        cfg = self.config
        reach = lead_rear_m if math.isfinite(lead_rear_m) else cfg.max_range_m
        nb = max(0, math.ceil(min(reach, cfg.max_range_m) / cfg.bin_m - 1e-9))
        nan = np.full((1, nb), np.nan)
        return RoadPreview(t, cfg.bin_m, 0.0, nan, nan.copy(), False, lead_rear_m)

    def _centred(self, y: FloatArray, d: FloatArray) -> FloatArray:
        """The row relative to the principal point (`principal_row_px`), else less its fit
        in 1 / d (`_range_free`)."""
        if math.isfinite(self.principal_row_px):
            return np.asarray(y - self.principal_row_px, dtype=np.float64)
        return _range_free(y, d)

    def _window(self, t: float) -> _Window | None:
        """The channels on the frame grid ending at ``t``; None when unusable."""
        cfg = self.config
        veh = self.vehicle
        last = self._ring.last(16)
        focal = last[-1, COL_F]
        if last.shape[0] < 3 or not math.isfinite(focal):
            return None
        recent = np.diff(last[:, COL_T]).tolist()
        # the median step, to 1 %: a cache key (frame stamps jitter; the grid is resampled)
        # (at most grid_hz: the body's response is below 3 Hz, and the cost of a solve grows
        # with the square of the grid's length)
        dt = _quantised(max(sorted(recent)[len(recent) // 2], 1.0 / cfg.grid_hz))
        if not dt > 0:
            return None
        ahead = veh.rear_overhang_m + veh.wheelbase_m - cfg.camera_to_front_axle_m
        # the history needed: since the lead's front wheels were over the ego's front axle's
        # spot now, and half a second (for the body's response before it), at most history_s
        d_now, v_now = last[-1, COL_D], last[-1, COL_V]
        need = cfg.history_s
        if math.isfinite(d_now) and math.isfinite(v_now) and v_now > cfg.min_lead_speed_mps:
            need = min(need, (d_now + ahead) / v_now + _HISTORY_STEP_S)
        step = max(1, round(_HISTORY_STEP_S / dt))
        n_max = step * max(1, math.ceil(need / dt / step))
        grid = np.asarray(t - dt * np.arange(n_max - 1, -1, -1), dtype=np.float64)
        # the rows that cover the grid (and a sample before it to interpolate from)
        rows = self._ring.last(round((n_max * dt + cfg.max_gap_s) / min(recent)) + 2)
        times = rows[:, COL_T]
        lead = (
            np.isfinite(rows[:, COL_Y]) & np.isfinite(rows[:, COL_D]) & np.isfinite(rows[:, COL_V])
        )
        chan, start = _on_grid(grid, times, rows[:, COL_Y : COL_V + 1], lead, cfg.max_gap_s)
        n_obs = step * ((n_max - start) // step)
        if n_obs < step:
            return None
        chan = chan[n_max - n_obs :]
        grid = grid[n_max - n_obs :]
        heave, d_raw, v_ego = chan[:, 0], chan[:, COL_D - COL_Y], chan[:, COL_V - COL_Y]
        # the distance smoothed by a quadratic in time: its slope is the range rate
        hat, slope = _smoother(n_obs, dt)
        d = hat @ d_raw
        v_lead = float(np.mean(v_ego + slope @ d_raw))
        if not v_lead >= cfg.min_lead_speed_mps or d[-1] <= 0:
            return None
        # the ego's distance driven since each grid time (trapezoid on the grid)
        seg = 0.5 * (v_ego[1:] + v_ego[:-1]) * dt
        driven = np.concatenate([np.cumsum(seg[::-1])[::-1], [0.0]])
        x = d + ahead - driven
        if not (np.diff(x) > 0).all():
            return None
        roll = None
        halves = lead & np.isfinite(rows[:, COL_ROLL])
        if np.count_nonzero(halves[-n_obs:]) >= 0.5 * n_obs:
            r, r_start = _on_grid(
                grid, times, rows[:, COL_ROLL : COL_ROLL + 1], halves, cfg.max_gap_s
            )
            roll = -(d / focal) * r[:, 0] if r_start == 0 else None
        return _Window(
            t=grid,
            heave_m=-(d / focal) * self._centred(heave, d),
            roll_m=roll,
            d_m=d,
            v_lead=v_lead,
            x_m=x,
            lead_rear_axle_m=float(d[-1]) + veh.rear_overhang_m - cfg.camera_to_front_axle_m,
            sigma_m=float(np.mean(d)) / focal * cfg.tracking_noise_px,
        )

    def _solve(self, t: float, win: _Window) -> RoadPreview:
        cfg = self.config
        veh = self.vehicle
        dt = float(win.t[1] - win.t[0])
        tau = _TAU_STEP_S * round(veh.wheelbase_m / win.v_lead / _TAU_STEP_S)
        n_obs = win.t.size
        n_pre = math.ceil((tau + cfg.settle_s) / dt)
        op = face_operator(veh, dt, tau, n_obs, n_pre)
        reach = min(win.lead_rear_axle_m, cfg.max_range_m)
        nb = max(0, math.ceil(reach / cfg.bin_m - 1e-9))
        if nb == 0:
            return self._empty(t, win.lead_rear_axle_m)
        edges = cfg.bin_m * np.arange(nb + 1, dtype=np.float64)
        # the bins' means per eigen-direction (w_k = sum_{j <= k} u_j, u = V a), relative to
        # the least-squares line over the valid bins: the level and the grade are absorbed
        # by the drift and not observable
        gv_all, ok = _bin_average(win.x_m, edges, op.lv)
        if not ok.any():
            return self._empty(t, win.lead_rear_axle_m)
        gv = gv_all[ok]
        centres = (edges[:-1] + 0.5 * cfg.bin_m)[ok]
        gv = gv - gv.mean(axis=0)
        if centres.size >= 3:
            xc = centres - centres.mean()
            gv -= np.outer(xc / (xc @ xc), xc @ gv)
        # the random-walk prior per grid step of the road (spatial step v_lead dt)
        q_track = cfg.increment_var_m2_per_m * win.v_lead * dt
        channels = [(win.heave_m, 0.5 * (1.0 + TRACK_CORRELATION) * q_track, win.sigma_m**2)]
        if win.roll_m is not None:
            var_roll = 2.0 * (1.0 - TRACK_CORRELATION) * q_track
            channels.append((win.roll_m, var_roll, 2.0 * win.sigma_m**2))
        est = []
        for z, q, r in channels:  # two channels, not samples
            denom = op.eigvals / r + 1.0 / q
            u_rot = (z @ op.psv) / r / denom
            est.append((gv @ u_rot, (gv * gv) @ (1.0 / denom)))
        shape = (2 if len(est) == 2 else 1, nb)
        height = np.full(shape, np.nan)
        std = np.full(shape, np.nan)
        (h_heave, v_heave) = est[0]
        if len(est) == 1:
            height[0, ok] = h_heave
            std[0, ok] = np.sqrt(v_heave)
        else:
            h_roll, v_roll = est[1]
            # the detector's convention: one side of height h is h / 2 on the heave, +h
            # (left) or -h (right) on the roll: left = heave + roll / 2, right = heave - roll / 2
            height[0, ok] = h_heave + 0.5 * h_roll
            height[1, ok] = h_heave - 0.5 * h_roll
            std[:, ok] = np.sqrt(v_heave + 0.25 * v_roll)
        return RoadPreview(t, cfg.bin_m, 0.0, height, std, len(est) == 2, win.lead_rear_axle_m)


__all__ = ["FaceOperator", "ProfileEstimator", "face_operator", "ramp_response"]
