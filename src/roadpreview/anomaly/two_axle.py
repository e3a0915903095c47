"""The product's detector: a two-axle matched filter on the lead's road input, prewhitened
against the road's own background (GLRT), normalised by that background (CFAR), on a heave
and a roll channel.

Per camera frame (``docs/detector.md``, "The two-axle detector"):

1. **Channels.** Heave: the whole lead's compensated image row y_c. Roll: the
   difference of its halves y_c,L - y_c,R, in which the ego's pitch and heave
   (the same for both halves) cancel. Both in pixels, on the regular frame grid
   (dropped frames and short invalid stretches interpolated, and so are the
   frames around the ego's own jolts: the compensation misses part of those).
2. **Hypothesis.** The lead's front axle met an anomaly of duration D (length /
   speed) at t_k; its rear axle meets it τ = wheelbase / v_lead later, with
   v_lead the ego's speed plus the range rate. The rear face then moves by h
   times the nominal car's two-axle response (`roadpreview.anomaly.response`),
   i.e. y moves by -f/d times that. One hypothesis per duration of the bank,
   each ending at this frame: t_k = t - τ - D - ``post_s``.
3. **Prewhitening.** Each channel is differenced and passed through the
   prediction-error filter of an AR(4) model fitted to its background (the
   lead's own bouncing on this road, the tracking noise, the compensation's
   residual: `Whitener`); the templates go through the same filters.
4. **Fit.** Least squares of the whitened channel on the whitened template plus a
   constant over [t_k - ``pre_s``, t]: the amplitude is the road input ĥ in
   metres (bump +, pothole -), its white-noise std the innovations' std over the
   template's whitened energy.
5. **Background (CFAR).** The amplitudes in units of that std have a running
   median over the last ``background_s`` (and the last ``background_short_s``,
   if higher) of frames away from events: the background's departure from the
   whitening model. The score is z = |ĥ| / (white-noise std x that level),
   widened for the compensation's share on the heave channel and for the
   heave's leak into the roll channel, floored by the tracking noise.
6. **Event.** z >= ``threshold_z`` and |ĥ| >= ``min_height_mm`` (a margin over
   the road's background and a floor in millimetres of road: independent of the
   camera's resolution, focal length and frame rate) opens an excursion; its
   best frame within ``peak_window_s`` describes it, and it is sent then.
   `_refine` settles its crossing time, height and sign on the frames seen
   since, every duration and alignment within ``refine_search_s`` on one
   common window. Side: BOTH when the roll channel's amplitude is less than
   ``one_sided_ratio`` times the heave channel's, else LEFT / RIGHT from the
   signs. Length: v_lead x D where D is resolved.

No fit while the lead is nearer than ``min_distance_m`` or its distance jumps
within the window (the tracker holds something else), nor while the lead
stands still; no score while the background is being learnt. The suppression
rules (lead braking, DEGRADED, unsettled IMU_ONLY) are the windowed-std
detector's (`SuppressionTracker`).

This module holds the detector (the fit, the score, the events and their refinement);
`roadpreview.anomaly.two_axle_signal` its signal side (steps 1, 3 and 5's level: the
channels on the frame grid, the templates on it, the whitening filters, the background).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import replace

import numpy as np

from roadpreview.anomaly.base import (
    AnomalyEvent,
    DetectorFrame,
    EventKind,
    LastFrame,
    TrajectorySample,
    next_time,
    run_frames,
)
from roadpreview.anomaly.config import TwoAxleConfig
from roadpreview.anomaly.response import TemplateBank
from roadpreview.anomaly.suppression import SuppressionTracker
from roadpreview.anomaly.two_axle_events import (
    ExcursionPicker,
    Pending,
    TwoAxleRun,
    calibrated,
    fitted_event,
)
from roadpreview.anomaly.two_axle_refine import Hypothesis as _Hypothesis
from roadpreview.anomaly.two_axle_refine import refine_event
from roadpreview.anomaly.two_axle_signal import (
    AR_ORDER,
    COL_D,
    COL_JOLT,
    COL_T,
    COL_V,
    COL_Y,
    COL_YD,
    HEAVE,
    MAD_TO_STD,
    NCOL,
    ROLL,
    CfarBackground,
    FloatArray,
    FrameFit,
    Ring,
    TemplateGrid,
    Whitener,
    background_sigma,
    channels_on_grid,
    template_grid,
    whiten_templates,
)
from roadpreview.configtools import check_ranges
from roadpreview.types import Side, SuppressionReason

#: the two-axle lag is rounded to this for the template cache, s (3 % of a 0.17 s lag at
#: 60 km/h: well inside the bank's duration steps)
_TAU_STEP_S = 0.005
#: templates cached for this many (lag, frame interval) pairs
_MAX_GRIDS = 64
#: the background ring holds ``background_s`` at up to this frame rate, Hz
_MAX_FPS = 120.0
#: the frame interval is re-measured every this many frames
_REMEASURE_FRAMES = 30
#: the range rate (a slope over a second) is re-fitted every this many frames
_RANGE_RATE_EVERY = 5


class TwoAxleDetector(LastFrame):
    """Streaming two-axle CFAR detector (module docstring). Push in time order."""

    def __init__(self, config: TwoAxleConfig | None = None) -> None:
        self.config = config or TwoAxleConfig()
        check_ranges(self.config, "TwoAxleConfig")
        self.config.validate()
        cfg = self.config
        self.bank = TemplateBank.cached(cfg.vehicle, cfg.durations_s)
        self._durations = np.asarray(cfg.durations_s, dtype=float)
        self._ring = Ring(cfg.buffer_frames, NCOL)
        self._background = self._new_background()
        self._suppression = SuppressionTracker(
            lead_accel_limit_mps2=cfg.lead_accel_limit_mps2,
            settle_s=cfg.imu_only_settle_s,
            span_s=cfg.max_window_s + cfg.suppress_hold_s,
        )
        self._picker = self._new_picker()
        # the early fit: its own background (its amplitudes are not the full fit's), its
        # templates, the provisional events waiting for the two-axle fit
        self._early_background = self._new_background()
        self._early_grids: dict[tuple[float, float], TemplateGrid] = {}
        self._early_whitened: dict[
            tuple[float, float, int, int], tuple[FloatArray, FloatArray]
        ] = {}
        self._pending: list[Pending] = []
        self._provisionals = 0  # provisional events numbered so far
        self._last_early_t = -math.inf  # crossing of the last provisional event, s
        self._early_stands = False  # it was not cancelled
        self._frame: DetectorFrame | None = None
        self._t_last = -math.inf
        self._last_event_t = -math.inf
        self._last_cross_t = -math.inf  # crossing time of the last event reported
        self._range_rate = math.nan
        self._grids: dict[tuple[float, float], TemplateGrid] = {}
        self._whitened_cache: dict[
            tuple[float, float, int, int], tuple[FloatArray, FloatArray]
        ] = {}
        self._whiteners = (Whitener(HEAVE, AR_ORDER), Whitener(ROLL, AR_ORDER))
        # per background frame: differences of heave and roll, the ego's acceleration peak,
        # the heave and roll innovations
        self._ar_rows = np.full((math.ceil(cfg.background_s * _MAX_FPS), 5), np.nan)
        self._innovation_std = np.full(2, np.nan)  # px, heave and roll
        self._diff_std = np.full(2, np.nan)  # robust std of the frame-to-frame change, px
        self._last_sigma = np.full((2, len(cfg.durations_s)), np.nan)
        self._ar_n = 0
        self._ego_level = math.nan  # the ego's background peak acceleration, m/s²
        self._tau = math.nan  # the two-axle lag of the last fit, s
        self._dt = math.nan  # the frame interval, s, and the frame count it was measured at
        self._dt_at = 0
        self._rate_at = -_RANGE_RATE_EVERY  # frame count of the last range-rate fit
        self._focal = math.nan

    def _new_background(self) -> CfarBackground:
        cfg = self.config
        return CfarBackground(
            cfg.background_s,
            cfg.background_short_s,
            (2, len(cfg.durations_s)),
            cfg.background_refresh_frames,
            capacity=math.ceil(cfg.background_s * _MAX_FPS),
        )

    def _new_picker(self) -> ExcursionPicker:
        return ExcursionPicker(self.config.peak_window_s)

    @property
    def background_m(self) -> FloatArray:
        """The background std of each amplitude at the last scored frame (channel heave /
        roll, duration), m (NaN before the first)."""
        return self._last_sigma

    # -- per frame -----------------------------------------------------------------------
    def push(self, sample: TrajectorySample) -> list[AnomalyEvent]:
        """Take the next frame; return the events confirmed at it (suppressed ones included)."""
        t = self._t_last = next_time(sample.t, self._t_last)
        self._ring.push(self._row(sample))
        suppressed = self._suppression.push(sample)
        fit = self._fit(t, sample)
        if fit is None:
            self._frame = DetectorFrame(
                t, math.nan, math.nan, math.nan, math.nan, 0, suppressed, threshold=math.nan
            )
            return self._confirm(self._picker.due(t), t) + self._cancel_due(t)
        cfg = self.config
        learning = self._background.seconds < cfg.background_min_s
        if learning and not (
            self._whiteners[HEAVE].version > 0 and math.isfinite(self._innovation_std[HEAVE])
        ):
            # nothing known of the road yet: no score
            self._update_background(t, fit, 0.0)
            self._frame = DetectorFrame(
                t, math.nan, math.nan, math.nan, math.nan, 0, suppressed, threshold=cfg.threshold_z
            )
            return self._confirm(self._picker.due(t), t) + self._cancel_due(t)
        # while the road is being learnt the whitening model stands for the background
        # (its measured departure is not known yet) and the margin is wider
        threshold = cfg.threshold_z * (cfg.learning_threshold_factor if learning else 1.0)
        sigma = self._sigma(fit, learning=learning)
        self._last_sigma = sigma
        z = np.abs(fit.amplitude[:2]) / sigma  # (2, J)
        with np.errstate(invalid="ignore"):
            z = np.where(np.isfinite(z), z, -1.0)
        c, j = np.unravel_index(int(np.argmax(z)), z.shape)
        score = float(z[c, j])
        self._update_background(t, fit, score)
        height = float(fit.amplitude[HEAVE, j])
        self._frame = DetectorFrame(
            t=t,
            s=math.nan,
            s_left=math.nan,
            s_right=math.nan,
            threshold_px=math.nan,
            n_samples=int(fit.n_valid[j]),
            suppressed=suppressed,
            score=score if score >= 0 else math.nan,
            threshold=threshold,
            t_score=float(fit.t_cross[j]),
            height_m=height if fit.metric else math.nan,
            background_m=float(sigma[c, j]) if fit.metric else math.nan,
        )
        # what is confirmed now first, so that its refractory applies to this frame
        events = self._confirm(self._picker.due(t), t)
        for e in events:
            if not e.suppressed:
                self._last_cross_t = e.t_s
        t_cross = float(fit.t_cross[j]) + 0.5 * float(self._durations[j])  # the pulse's middle
        eligible = (
            score >= threshold
            and (
                not fit.metric
                or self._event_height(fit.amplitude, int(j))[0] >= cfg.min_height_mm * 1e-3
            )
            # the ringing of an anomaly already reported is no new anomaly
            and not -cfg.refractory_s[0] <= t_cross - self._last_cross_t <= cfg.refractory_s[1]
        )
        value = score if eligible else -math.inf

        def describe() -> tuple[AnomalyEvent, _Hypothesis]:
            return self._describe(t, fit, sigma, int(c), int(j), score, suppressed)

        self._picker.offer(t, value, describe)
        if eligible:
            self._last_event_t = t
        if cfg.provisional:
            events += self._early(t, fit, suppressed, learning=learning)
            events += self._cancel_due(t)
        return events

    # -- provisional events ----------------------------------------------------------------
    def _early(
        self, t: float, fit: FrameFit, suppressed: SuppressionReason, *, learning: bool
    ) -> list[AnomalyEvent]:
        """The early fit's score at this frame; a PROVISIONAL event when it is over
        ``provisional_threshold_z`` and the floor, away from the anomalies reported."""
        cfg = self.config
        amp = fit.early_amplitude
        if amp is None or not fit.metric:
            return []
        # while the road is being learnt: the whitening model for the background and the
        # wider margin, as the two-axle fit (the drive's first seconds are when its alerts
        # come latest: the provisional one matters most there)
        sig = self._early_sigma(fit, amp, learning=learning)
        z = np.abs(amp[:2]) / sig
        with np.errstate(invalid="ignore"):
            z = np.where(np.isfinite(z), z, -1.0)
        c, j = np.unravel_index(int(np.argmax(z)), z.shape)
        score = float(z[c, j])
        factor = cfg.learning_threshold_factor if learning else 1.0
        if score < cfg.provisional_threshold_z * factor:
            return []
        centre = float(fit.early_centre[j])
        lo, hi = cfg.refractory_s
        if (
            -lo <= centre - self._last_cross_t <= hi
            # the ringing of a provisional anomaly that still stands is no new one
            or (self._early_stands and -lo <= centre - self._last_early_t <= hi)
            or abs(centre - self._last_early_t) <= cfg.provisional_match_s
            or self._picker_holds(centre)
        ):
            return []
        a_h, a_r = float(amp[HEAVE, j]), float(amp[ROLL, j])
        size, side, height = self._event_height(amp, int(j))
        if size < cfg.min_height_mm * 1e-3 or not (math.isfinite(a_h) or math.isfinite(a_r)):
            return []
        self._last_early_t = centre
        self._early_stands = True
        self._provisionals += 1
        rows = self._ring.last(cfg.buffer_frames)
        event = fitted_event(
            cfg,
            rows,
            t=t,
            centre=centre,
            side=side if math.isfinite(a_r) else Side.UNKNOWN,
            height_m=height,
            std_m=float(sig[c, j]),
            score=score,
            threshold=cfg.provisional_threshold_z,
            confidence=calibrated(
                cfg.provisional_confidence_logit, score, cfg.provisional_threshold_z
            ),
            suppressed=suppressed,
            lead_speed_mps=self._lead_speed(rows),
            t_emit_s=t,
            kind=EventKind.PROVISIONAL,
            ref=self._provisionals,
        )
        if not suppressed:
            # the two-axle fit has tried every duration with this crossing by then
            tau = self._tau if math.isfinite(self._tau) else 0.0
            half = 0.5 * float(self._durations[-1])
            check = centre + tau + half + cfg.post_s + cfg.provisional_check_s
            self._pending.append(
                Pending(self._provisionals, event, check, check + cfg.peak_window_s)
            )
        return [event]

    def _picker_holds(self, centre: float) -> bool:
        """The two-axle fit already has an excursion open for this crossing."""
        cand = self._picker._cand
        return cand is not None and abs(cand[2][0].t_s - centre) <= self.config.provisional_match_s

    def _early_sigma(self, fit: FrameFit, amp: FloatArray, *, learning: bool) -> FloatArray:
        """As `_sigma`, for the early fit (its own background level)."""
        white = self._innovation_std[:, None] / np.sqrt(fit.early_energy)
        level = 1.0 if learning else self._early_background.level()
        return background_sigma(self.config, white, level, fit.early_sigma_fit, amp)

    def _cancel_due(self, t: float) -> list[AnomalyEvent]:
        """Provisional events the two-axle fit did not confirm: at their check no excursion
        for their crossing is open, or their confirmation is overdue."""
        out = []
        keep = []
        for p in self._pending:
            if t >= p.due_t or (t >= p.check_t and not self._picker_holds(p.event.t_s)):
                out.append(self._cancelled(p, t))
            else:
                keep.append(p)
        self._pending = keep
        return out

    def _cancelled(self, p: Pending, t: float) -> AnomalyEvent:
        if p.event.t_s == self._last_early_t:
            self._early_stands = False
        return replace(p.event, t_emit_s=t, kind=EventKind.CANCELLED)

    def _link(self, event: AnomalyEvent) -> AnomalyEvent:
        """A confirmed two-axle event confirms the pending provisional one nearest its
        crossing (within ``provisional_match_s``)."""
        if event.suppressed or not self._pending:
            return event
        gaps = [abs(p.event.t_s - event.t_s) for p in self._pending]
        k = int(np.argmin(gaps))
        if gaps[k] > self.config.provisional_match_s:
            return event
        p = self._pending.pop(k)
        return replace(event, ref=p.ref)

    def _confirm(
        self, confirmed: list[tuple[AnomalyEvent, _Hypothesis]], t: float
    ) -> list[AnomalyEvent]:
        """The events whose peak is confirmed now, with the height refined on the frames
        seen since (`_refine`), emitted at ``t``."""
        return [self._link(replace(self._refine(e, h), t_emit_s=t)) for e, h in confirmed]

    def _row(self, sample: TrajectorySample) -> FloatArray:
        ok = sample.valid
        y = sample.y_c if ok and math.isfinite(sample.y_c) else math.nan
        yl, yr = sample.y_c_left, sample.y_c_right
        yd = yl - yr if ok and math.isfinite(yl) and math.isfinite(yr) else math.nan
        speed = sample.ego_speed_mps
        d = sample.lead_distance_m
        return np.array(
            [
                sample.t,
                y,
                yd,
                sample.compensation_px,
                d if math.isfinite(d) and d > 0 else math.nan,
                math.nan if speed is None or not math.isfinite(speed) else speed,
                float(int(sample.mode)),
                sample.lead_distance_std_m,
                sample.ego_accel_peak_mps2,
            ]
        )

    def _lead_speed(self, rows: FloatArray) -> float:
        """v_lead = ego speed + range rate (slope of the distance over ``range_rate_s``)."""
        cfg = self.config
        v_ego = rows[-1, COL_V]
        if not math.isfinite(v_ego):
            return math.nan
        n = self._ring.n
        if n - self._rate_at < _RANGE_RATE_EVERY and math.isfinite(self._range_rate):
            return float(v_ego + self._range_rate)
        self._rate_at = n
        t = rows[:, COL_T]
        recent = t >= t[-1] - cfg.range_rate_s
        d = rows[recent, COL_D]
        tt = t[recent]
        ok = np.isfinite(d)
        if np.count_nonzero(ok) >= 5 and tt[ok][-1] - tt[ok][0] >= 0.5 * cfg.range_rate_s:
            tc = tt[ok] - tt[ok].mean()
            slope = float(np.dot(tc, d[ok] - d[ok].mean()) / np.dot(tc, tc))
            # the box (hence the distance) jumps while the lead bounces: a rate past what a
            # car does is not believed
            limit = cfg.max_range_rate_mps
            self._range_rate = float(np.clip(slope, -limit, limit))
        rate = self._range_rate if math.isfinite(self._range_rate) else 0.0
        return float(v_ego + rate)

    def _fit(self, t: float, sample: TrajectorySample) -> FrameFit | None:
        """Least-squares fits of every duration's template on each channel, prewhitened
        (None: no fit possible at this frame: too little history, a lead standing still,
        a gap in the window longer than ``max_gap_s``).

        The channels are taken on the regular frame grid ending now (dropped frames and
        short invalid stretches are interpolated), differenced and filtered by their
        background's prediction-error filter (`Whitener`); the templates go through the
        same filters and are cached per (τ, frame interval, filter), residualised against a
        constant within each duration's window, so that the fit is one small matrix
        product per channel."""
        cfg = self.config
        rows = self._ring.last(cfg.buffer_frames)
        if rows.shape[0] < cfg.min_frames:
            return None
        v_lead = self._lead_speed(rows)
        if math.isfinite(v_lead) and v_lead < cfg.min_lead_speed_mps:
            return None
        tau = cfg.vehicle.wheelbase_m / v_lead if math.isfinite(v_lead) else math.nan
        if math.isfinite(tau):
            tau = round(tau / _TAU_STEP_S) * _TAU_STEP_S
        lag = (0.0 if math.isnan(tau) else tau) + self._durations + cfg.post_s  # (J,)
        focal = sample.focal_px
        self._tau, self._focal = tau, focal
        dt = self._frame_interval(rows[:, COL_T])
        if not math.isfinite(dt):
            return None
        grid = self._grid(tau, dt, lag)
        n = grid.s.shape[1]  # frames of the longest window plus the filters' history
        x = self._on_grid(rows, t, dt, n)
        if x is None:
            return None
        d = rows[-n:, COL_D] if rows.shape[0] >= n else rows[:, COL_D]
        d_ok = d[np.isfinite(d)]
        d_med = float(d_ok.mean()) if d_ok.size else math.nan  # (jumps are refused below)
        if d_ok.size and (
            d_med < cfg.min_distance_m or float(d_ok.max()) > cfg.max_distance_ratio * d_ok.min()
        ):
            # a lead nearer than a car's length, or one whose distance jumps within the
            # window: the tracker holds something else (the road, a passing car, a box that
            # grew), not a lead whose road we can read
            return None
        metric = bool(math.isfinite(focal) and focal > 0 and math.isfinite(d_med))
        scale = -focal / d_med if metric else -1.0
        j_n = len(lag)
        amp = np.full((3, j_n), np.nan)
        energy = np.full((2, j_n), np.nan)
        innovation = np.full(2, np.nan)
        heave, roll = self._whiteners
        for c, w in enumerate((heave, roll, heave)):  # the compensation as the heave
            xc = x[:, c]
            if not np.isfinite(xc).all():
                continue
            s_r, ss = self._whitened(grid, w)
            xw = w.apply(xc)
            amp[c] = (s_r @ xw) / ss
            if c < 2:
                energy[c] = ss
                innovation[c] = xw[-1]
        result = FrameFit(
            amplitude=amp / scale,
            sigma_fit=1.0 / (np.sqrt(grid.ss_raw) * abs(scale)),
            t_cross=t - lag,
            valid_fraction=np.ones_like(lag),
            n_valid=grid.n,
            metric=metric,
            energy=energy * scale * scale,
            innovation=innovation,
        )
        if cfg.provisional and metric:
            self._fit_early(result, x, t, tau, dt, scale)
        return result

    def _fit_early(
        self, fit: FrameFit, x: FloatArray, t: float, tau: float, dt: float, scale: float
    ) -> None:
        """The early fit into ``fit``: every duration's two-axle template cut
        ``provisional_lag_s`` after the front axle met the anomaly's middle, fitted to the
        end of the same whitened channels (the same filters, a shorter window)."""
        cfg = self.config
        lag = 0.5 * self._durations + cfg.provisional_lag_s
        grid = self._grid(tau, dt, lag, self._early_grids)
        n = grid.s.shape[1]
        if x.shape[0] < n:
            return
        xe = x[-n:]
        j_n = len(lag)
        amp = np.full((3, j_n), np.nan)
        energy = np.full((2, j_n), np.nan)
        heave, roll = self._whiteners
        for c, w in enumerate((heave, roll, heave)):
            xc = xe[:, c]
            if not np.isfinite(xc).all():
                continue
            s_r, ss = self._whitened(grid, w, self._early_whitened)
            amp[c] = (s_r @ w.apply(xc)) / ss
            if c < 2:
                energy[c] = ss
        fit.early_amplitude = amp / scale
        fit.early_energy = energy * scale * scale
        fit.early_sigma_fit = 1.0 / (np.sqrt(grid.ss_raw) * abs(scale))
        fit.early_centre = t - cfg.provisional_lag_s + 0.0 * lag

    def _on_grid(self, rows: FloatArray, t: float, dt: float, n: int) -> FloatArray | None:
        """The channels on the regular grid of ``n`` frames ending at ``t``
        (`channels_on_grid`, with this road's jolt level and frame-to-frame change)."""
        return channels_on_grid(rows, t, dt, n, self.config, self._ego_level, self._diff_std)

    def _frame_interval(self, times: FloatArray) -> float:
        """The median frame interval of the last frames, rounded to 0.1 ms (NaN: unknown);
        re-measured every `_REMEASURE_FRAMES` frames (a camera keeps its rate)."""
        n = self._ring.n
        if times.size < 3:
            return math.nan
        if math.isnan(self._dt) or n - self._dt_at >= _REMEASURE_FRAMES:
            dt = float(np.median(np.diff(times[-32:])))
            self._dt = round(dt, 4) if dt > 0 else math.nan
            self._dt_at = n
        return self._dt

    def _grid(
        self,
        tau: float,
        dt: float,
        lag: FloatArray,
        cache: dict[tuple[float, float], TemplateGrid] | None = None,
    ) -> TemplateGrid:
        """The templates on the regular frame grid ending now (`template_grid`), cached per
        (τ, frame interval) in ``cache`` (default: the two-axle fit's; the early fit's lags
        are other ones)."""
        store = self._grids if cache is None else cache
        key = (tau, dt)
        grid = store.get(key)
        if grid is None:
            grid = template_grid(self.bank, self.config, tau, dt, lag)
            if len(store) >= _MAX_GRIDS:
                store.pop(next(iter(store)))
            store[key] = grid
        return grid

    def _whitened(
        self,
        grid: TemplateGrid,
        whitener: Whitener,
        cache: dict[tuple[float, float, int, int], tuple[FloatArray, FloatArray]] | None = None,
    ) -> tuple[FloatArray, FloatArray]:
        """The grid's templates through ``whitener`` (`whiten_templates`), cached per filter
        version (in ``cache``, default the two-axle fit's)."""
        store = self._whitened_cache if cache is None else cache
        key = (*grid.key, whitener.channel, whitener.version)
        hit = store.get(key)
        if hit is None:
            hit = whiten_templates(grid, whitener)
            if len(store) >= 4 * _MAX_GRIDS:
                store.clear()
            store[key] = hit
        return hit

    def _sigma(self, fit: FrameFit, *, learning: bool = False) -> FloatArray:
        """The background std of each amplitude (2, J): the running level, the tracking
        noise at this distance and the floor, and for the heave channel the compensation's
        share."""
        # the white-noise std of each amplitude, times the background's measured departure
        # from it (CFAR); never below the tracking noise carried through an unwhitened fit
        white = self._innovation_std[:, None] / np.sqrt(fit.energy)
        level = 1.0 if learning else self._background.level()
        return background_sigma(self.config, white, level, fit.sigma_fit, fit.amplitude)

    def _update_background(self, t: float, fit: FrameFit, score: float) -> None:
        """A frame that may count as background: its amplitudes feed the running level, its
        channels' differences the whitening filters (both refreshed together)."""
        cfg = self.config
        if t - self._last_event_t < cfg.guard_s or not fit.metric:
            return
        amp = np.abs(fit.amplitude[:2])
        if not np.isfinite(amp).any():
            return
        last = self._ring.last(2)
        if last.shape[0] == 2:
            i = self._ar_n % self._ar_rows.shape[0]
            self._ar_rows[i, 0] = last[1, COL_Y] - last[0, COL_Y]
            self._ar_rows[i, 1] = last[1, COL_YD] - last[0, COL_YD]
            self._ar_rows[i, 2] = last[1, COL_JOLT]
            self._ar_rows[i, 3:5] = fit.innovation
            self._ar_n += 1
        if math.isfinite(self._innovation_std[HEAVE]):
            # the amplitudes in units of their white-noise std: independent of the filter
            self._background.push(t, amp * np.sqrt(fit.energy) / self._innovation_std[:, None])
            if fit.early_amplitude is not None:
                early = np.abs(fit.early_amplitude[:2]) * np.sqrt(fit.early_energy)
                self._early_background.push(t, early / self._innovation_std[:, None])
        elif self._ar_n >= 2:
            self._refresh_filters()
        if self._background.pushes % self._background.refresh == 0:
            self._refresh_filters()

    def _refresh_filters(self) -> None:
        """Refit the whitening filters to the background's differences, and the innovations'
        robust std (under the filters in force when each frame was fitted: they change
        slowly), floored by the tracking noise through the filter."""
        cfg = self.config
        held = self._ar_rows[: min(self._ar_n, self._ar_rows.shape[0])]
        for c, w in enumerate(self._whiteners):
            dx = held[:, c]
            w.fit(dx[np.isfinite(dx)])
            ok = dx[np.isfinite(dx)]
            if ok.size >= 10:
                self._diff_std[c] = float(np.median(np.abs(ok - np.median(ok)))) / MAD_TO_STD
            inn = held[:, 3 + c]
            inn = inn[np.isfinite(inn)]
            floor = cfg.tracking_noise_px * w.white_gain
            if inn.size >= 5:
                self._innovation_std[c] = max(float(np.median(np.abs(inn))) / MAD_TO_STD, floor)
        ego = held[:, 2]
        ego = ego[np.isfinite(ego)]
        self._ego_level = float(np.median(ego)) if ego.size >= 10 else math.nan

    def _event_height(self, amplitude: FloatArray, j: int) -> tuple[float, Side, float]:
        """|height|, side and signed height of the anomaly at duration ``j`` of a fit's
        amplitudes (heave, roll, ...)."""
        a_h = float(amplitude[HEAVE, j])
        a_r = float(amplitude[ROLL, j])
        if not math.isfinite(a_r):
            return abs(a_h), Side.UNKNOWN, a_h
        if not math.isfinite(a_h) or abs(a_r) < self.config.one_sided_ratio * abs(a_h):
            return abs(a_h), Side.BOTH, a_h
        # one side of height h: the heave channel sees h / 2, the roll channel h on the
        # left and -h on the right
        if a_h * a_r >= 0:
            return abs(a_r), Side.LEFT, a_r
        return abs(a_r), Side.RIGHT, -a_r

    def _describe(
        self,
        t: float,
        fit: FrameFit,
        sigma: FloatArray,
        c: int,
        j: int,
        score: float,
        suppressed: SuppressionReason,
    ) -> tuple[AnomalyEvent, _Hypothesis]:
        cfg = self.config
        _, side, height = self._event_height(fit.amplitude, j)
        rows = self._ring.last(cfg.buffer_frames)
        # the front axle over the anomaly's middle (its pulse's centre)
        t_cross = float(fit.t_cross[j]) + 0.5 * float(self._durations[j])
        if not fit.metric:
            height = math.nan
        return fitted_event(
            cfg,
            rows,
            t=t,
            centre=t_cross,
            side=side,
            height_m=height,
            std_m=float(sigma[c, j]) if fit.metric else math.nan,
            score=score,
            threshold=cfg.threshold_z,
            confidence=self.confidence(score),
            suppressed=suppressed,
            lead_speed_mps=self._lead_speed(rows),
            valid_fraction=float(fit.valid_fraction[j]),
        ), _Hypothesis(
            center_s=t_cross,
            tau_s=self._tau,
            channel=c,
            noise_m=float(sigma[c, j]) if fit.metric else math.nan,
            focal_px=self._focal,
        )

    def _refine(self, event: AnomalyEvent, hyp: _Hypothesis) -> AnomalyEvent:
        """Crossing time, height, its std and the length from every duration's template
        fitted to one common window, [centre - longest / 2 - pre - search, now], with the
        pulse centres shifted by up to ± ``refine_search_s`` around the peak's: a fair
        comparison of durations and alignments (each detection window ends at its own
        template's end, and the matched filter's side lobes, half a body period off, fit
        with the opposite sign). The best fit gives the crossing, the height and its sign;
        the durations that fit within ``close_fit_fraction`` of it give the std (a short
        anomaly's body response is its height x length, which trade)."""
        cfg = self.config
        dt = self._dt
        if not math.isfinite(hyp.noise_m) or not math.isfinite(event.height_m) or not dt > 0:
            return event
        rows = self._ring.last(cfg.buffer_frames)
        dur = self._durations
        t_now = float(rows[-1, COL_T])
        search = cfg.refine_search_s
        earliest = hyp.center_s - search - 0.5 * float(dur.max()) - cfg.pre_s
        n = math.ceil((t_now - earliest) / dt) + AR_ORDER + 2
        x = self._on_grid(rows, t_now, dt, n)
        d = rows[np.isfinite(rows[:, COL_D]), COL_D]
        if x is None or not d.size:
            return event
        return refine_event(
            event,
            hyp,
            cfg=cfg,
            bank=self.bank,
            durations=dur,
            rows=rows,
            x=x,
            d=d,
            dt=dt,
            innovation_std=self._innovation_std,
            whiteners=self._whiteners,
        )

    def confidence(self, score: float) -> float:
        """The calibrated probability that an event of this score is real."""
        return calibrated(self.config.confidence_logit, score, self.config.threshold_z)

    # -- stream control ------------------------------------------------------------------
    def restart(self) -> list[AnomalyEvent]:
        """A new target (the tracker switched vehicles): pending events, then an empty
        window; the road's background is kept (it is the same road)."""
        events = self.flush()
        self._ring.clear()
        self._picker = self._new_picker()
        self._last_early_t = -math.inf
        self._range_rate = math.nan
        self._dt = math.nan
        return events

    def flush(self) -> list[AnomalyEvent]:
        """End of stream (or a new target): the pending event, confirmed at the last frame's
        time, and the provisional events it did not confirm, cancelled."""
        events = self._confirm(self._picker.flush(), self._t_last)
        events += [self._cancelled(p, self._t_last) for p in self._pending]
        self._pending = []
        return events

    def run(self, samples: Iterable[TrajectorySample]) -> TwoAxleRun:
        """Push every sample, flush, and return per-frame arrays and all events."""
        columns, suppressed, events = run_frames(
            self, samples, ("t", "score", "t_score", "height_m", "background_m")
        )
        t, score, t_score, height_m, background_m = columns
        return TwoAxleRun(t, score, t_score, height_m, background_m, suppressed, events)
