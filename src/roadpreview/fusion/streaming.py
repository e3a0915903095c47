"""`StreamingPitchFusion`: the gyro-visual pitch fusion around a `PitchBackEnd`.

The `kalman` and `factor-graph` back ends are this class holding a Kalman filter or a
fixed-lag smoother (`roadpreview.fusion.base.PitchBackEnd`: start, step, pin_key,
update, end_frame, estimate). What every back end needs and nothing in it is specific to
one of them is here:

* the gyro buffer (`GyroHistory`: validation, ordering, gaps, running integral),
* the camera-IMU time offset (`TimeOffsetEstimator`), applied to every gyro query,
* the frames and their visual results, processed in time order,
* the mode supervisor (`ModeSupervisor`: vision trust with hysteresis, IMU liveness),
* re-validation of vision against the gyro, the measurement variance,
* the output stage: a correction at a mode switch is eased in, never a step.

Time handling. Frames are committed (processed for good, in time order) up
to a horizon: the frame time asked for, but no later than the newest gyro
sample (on the camera clock) minus `GyroConfig.reorder_window_s`, so that
gyro samples still on their way are not missed. When the IMU has timed out
the horizon is the frame time and the gap is bridged without gyro. Frames
beyond the horizon are processed tentatively for the output (the last gyro
rate held, with growing variance) and processed again for good once the
gyro has arrived. Back ends that can copy their state (`RewindableBackEnd`) do
this exactly (`kalman`); the others extrapolate from their last committed frame.

Cost. Everything here runs once per frame or once per gyro sample, so the hot
paths (`push_gyro`, `push_visual`, `estimate` with the frame it commits) are
written for CPython: settings read once into attributes, the gyro's interval
as a plain tuple (`GyroHistory.motion3`, which keeps the end of one frame's
interval for the start of the next), one back-end call to move to a frame and
keep it (`PitchBackEnd.step`), a measurement's variance as far as it is known computed
when it arrives, O(1) checks before any search. `roadpreview bench fusion`
measures the whole streaming path.
"""

from __future__ import annotations

import bisect
import logging
import math
from dataclasses import replace

from roadpreview.errors import InputDataError
from roadpreview.fusion.base import FusedPitch, PitchBackEnd, RewindableBackEnd, VisualPitch
from roadpreview.fusion.config import FusionConfig
from roadpreview.fusion.gyro import GyroHistory, Motion
from roadpreview.fusion.mode_machine import ModeSupervisor, VisionTrust
from roadpreview.fusion.timesync import TimeOffsetEstimator
from roadpreview.types import FusionMode

log = logging.getLogger(__name__)

_INF = math.inf
_exp, _sqrt = math.exp, math.sqrt
_TRUSTED = VisionTrust.TRUSTED

#: a frame's visual measurements: (measurement, its variance before the time-offset term,
#: None if unusable)
_Metas = list[tuple[VisualPitch, float | None]]


class StreamingPitchFusion:
    """Pitch from gyro and relative visual pitch, streamed: buffering, time offset, modes and
    output around a `PitchBackEnd` (a `PitchFusion`)."""

    _last_query: float
    _last_out: FusedPitch | None
    _level: float
    _level_t: float

    def __init__(self, backend: PitchBackEnd, config: FusionConfig) -> None:
        config.validate("fusion")
        self.config = config
        self.backend = backend
        #: the back end when it can copy its state (exact tentative frames), else None
        self._rewind = backend if isinstance(backend, RewindableBackEnd) else None
        self.name = backend.name
        self.events = backend.events
        self.gyro = GyroHistory(config.gyro, self.events)
        self.aligner = TimeOffsetEstimator(config.alignment)
        # settings used per frame, read once (the config is frozen)
        g, v, mo = config.gyro, config.vision, config.modes
        self._timeout = g.timeout_s
        self._reorder = g.reorder_window_s
        self._history = g.history_s
        self._blind = g.blind_rate_std_rad_s
        self._std_scale = v.std_scale
        self._min_var = v.min_std_rad**2
        self._low_inliers = v.low_inlier_ratio
        self._min_inliers = v.min_inlier_ratio
        self._max_dphi = v.max_abs_dphi_rad
        self._capture = mo.level_capture_s
        self._ease = mo.level_ease_s
        self._track_add = self.aligner.track.add  # usable measurements -> the visual rate track
        self._gate_with_gyro = backend.gate_with_gyro
        self._max_rejections = backend.max_rejections
        self._reset_core()

    # -- public interface -------------------------------------------------------------------
    def reset(self) -> None:
        """Forget everything (a new drive)."""
        self.gyro.reset()
        self.aligner.reset()
        self.events.counts.clear()
        self._reset_core()

    def push_gyro(
        self,
        t: float,
        pitch_rate: float,
        roll_rate: float | None = None,
        yaw_rate: float | None = None,
    ) -> bool:
        """Add a gyro sample (IMU clock). Roll and yaw rates are checked, not yet used.

        (Keyword-only in `PitchFusion`; plain parameters here because CPython 3.11 does not
        specialise calls to functions with keyword-only parameters: 70 ns more per sample.)
        """
        if roll_rate is None and yaw_rate is None:
            return self.gyro.push(t, pitch_rate)
        for name, v in (("roll_rate", roll_rate), ("yaw_rate", yaw_rate)):
            if v is not None and not math.isfinite(v):
                self.events("nonfinite", "%s %r at t=%r is not finite: sample rejected", name, v, t)
                return False
        return self.gyro.push(t, pitch_rate)

    def push_visual(self, meas: VisualPitch) -> None:
        """Add a relative visual measurement (camera clock)."""
        t, t_ref = meas.t, meas.t_ref
        if not -_INF < t_ref < t < _INF:  # both finite and t_ref < t (NaN fails too)
            self.events(
                "visual-time",
                "visual measurement with times t_ref=%r, t=%r ignored (need t_ref < t)",
                t_ref,
                t,
            )
            return
        t_done = self._t  # (before the start -inf)
        if t <= t_done:
            self.events(
                "visual-late",
                "visual measurement of frame t=%.6f arrived after the frame was committed",
                t,
            )
            return
        if t_ref > t_done:  # (a committed key frame needs nothing)
            self._add_frame(t_ref)
        frames = self._frames
        if not frames or t > frames[-1]:
            frames.append(t)  # the usual case of `_add_frame`: the newest frame
        else:
            self._add_frame(t)
        # usable (the front end says so and the numbers make sense)? Then its variance as
        # far as it is known now: the estimator's std scaled, its floor added, inflated for
        # few inliers (the time-offset term is added when the frame is processed); None:
        # unusable
        var: float | None = None
        if meas.quality_ok:
            std, ratio, dphi = meas.std, meas.inlier_ratio, meas.dphi
            max_dphi = self._max_dphi
            # finite and in range (NaN fails every comparison; an infinite std or ratio is
            # caught by its bound or by the explicit test)
            if (
                -max_dphi <= dphi <= max_dphi
                and 0.0 < std < _INF
                and self._min_inliers <= ratio < _INF
            ):
                std *= self._std_scale  # `VisionConfig.variance`, inline
                var = std * std + self._min_var
                low = self._low_inliers
                if ratio < low:
                    var *= (low / ratio) ** 2
                self._track_add(t_ref, t, dphi)
            else:
                self._unusable(meas)
        vis = self._vis
        metas = vis.get(t)
        if metas is None:
            vis[t] = [(meas, var)]
        else:
            metas.append((meas, var))

    def push_vision_failure(self, t: float, reason: str) -> None:
        """Vision gave nothing usable for the frame at ``t`` (``reason`` for the log)."""
        if not math.isfinite(t) or (self._started and t <= self._t):
            self.events("visual-late", "vision failure at t=%r ignored (late or not finite)", t)
            return
        self._add_frame(t)
        self._fails[t] = reason

    def estimate(self, t: float) -> FusedPitch:
        """The fused pitch at frame time ``t`` (non-decreasing from call to call)."""
        if not self._last_query < t < _INF:  # the usual case passes one test
            if not math.isfinite(t):
                raise InputDataError(f"estimate(t): t = {t!r} is not a finite time")
            if t < self._last_query:
                raise InputDataError(
                    f"estimate(t): t = {t:.6f} s is before the previous query"
                    f" ({self._last_query:.6f} s); frame times must not go backwards"
                )
            if self._last_out is not None:  # the same frame again
                return self._last_out
        self._last_query = t
        frames = self._frames
        if not frames or frames[-1] != t:  # (usually its visual result has added it)
            self._add_frame(t)
        if not self._started:
            self._start(frames[0])
        if t >= self._next_align:
            self._align(t)
        self._commit(t)
        # the level offset: decay it (time constant `ModeConfig.level_ease_s`) and take in a
        # new shift of the key frame's estimate (`_level_shift`, inline), so that the output
        # does not step with it
        sup = self._sup  # (after the commit, which may have started it again)
        backend = self.backend
        shift = backend.take_level_shift()
        if not self._t - sup.reacquired_t <= self._capture:
            shift = 0.0
        ease = self._ease
        if ease > 0.0:
            level = self._level
            if level != 0.0:
                level *= _exp(-(t - self._level_t) / ease)
                if abs(level) < 1e-12:
                    level = 0.0
            self._level_t = t
            self._level = level = level - shift
        else:
            self._level = level = 0.0
        if frames and frames[0] <= t:
            phi, var, mode, shift = self._tentative(t)
            phi -= shift
            _, _, b, bvar = backend.estimate()
        else:
            phi, var, b, bvar = backend.estimate()
            mode = sup.mode
        # (`0.0 if x < 0.0 else x` is max(x, 0.0) without calling the builtin; NaN stays NaN)
        out = FusedPitch(  # t, phi, std, mode, bias, time_offset, its confidence, bias_std
            t,
            phi + level,
            _sqrt(0.0 if var < 0.0 else var),
            mode,
            b,
            self._tau,
            self._tau_conf,
            _sqrt(0.0 if bvar < 0.0 else bvar),
        )
        self._last_out = out
        return out

    @property
    def stats(self) -> dict[str, int]:
        """Counts of rejected, bridged, reordered and gated inputs by kind."""
        return dict(self.events.counts)

    # -- internals --------------------------------------------------------------------------
    def _reset_core(self) -> None:
        cfg = self.config
        self._frames: list[float] = []  # pending frame times, sorted
        # per frame: (measurement, its variance before the time-offset term; None: unusable)
        self._vis: dict[float, _Metas] = {}
        self._fails: dict[float, str] = {}
        self._started = False
        self._t0 = math.nan
        self._t = -math.inf  # time of the committed state
        self._sup = ModeSupervisor(cfg.modes)
        self._tau = cfg.alignment.initial_offset_s
        self._tau_std = cfg.alignment.prior_std_s
        self._tau_conf = 0.0
        self._next_align = -math.inf if cfg.alignment.enabled else math.inf
        self._last_query = -math.inf
        self._last_out: FusedPitch | None = None
        # frames committed before the gyro was ready (processed again once it is)
        self._startup: list[tuple[float, _Metas | None, str | None]] | None
        self._startup = []
        self._ready = not cfg.alignment.enabled  # the gyro may be fused (offset known)
        self._level = 0.0  # output minus state: level changes being eased in
        self._level_t = -math.inf

    def _add_frame(self, t: float) -> None:
        """A frame time to process (finite ``t``); nothing if it is committed or known."""
        if t <= self._t:  # at or before the committed state (before the start _t is -inf)
            return
        frames = self._frames
        if not frames or t > frames[-1]:
            frames.append(t)
            return
        i = bisect.bisect_left(frames, t)
        if frames[i] != t:
            frames.insert(i, t)

    def _start(self, t0: float) -> None:
        self._started = True
        self._t0 = t0
        self._t = t0
        self.backend.start(t0)
        self._frames.pop(0)
        alive = self._alive(t0)
        self._handle_frame_inputs(t0, self._sup, True, alive)
        self._sup.update_mode(alive)
        self._vis.pop(t0, None)
        self._fails.pop(t0, None)

    def _gyro_ready(self, t: float) -> bool:
        """The gyro is fused once the time offset is known (or the wait is over)."""
        if not self._ready:
            a = self.config.alignment
            self._ready = self._tau_conf > 0.0 or t - self._t0 >= a.max_wait_s
        return self._ready

    def _alive(self, t: float) -> bool:
        """Is the IMU usable at camera time ``t`` (ready, and judged by the newest sample)?"""
        if not (self._ready or self._gyro_ready(t)):
            return False
        newest = self.gyro.newest
        if newest is None:
            return t - self._t0 <= self._timeout
        return newest - self._tau >= t - self._timeout

    def _motion(self, t1: float, t2: float, alive: bool) -> Motion:
        return Motion(*self._motion3(t1, t2, alive))

    def _motion3(self, t1: float, t2: float, alive: bool) -> tuple[float, float, float]:
        """(dG, dV, dM) over camera times [t1, t2]: the gyro, or no gyro at all."""
        if not alive:
            d = t2 - t1
            return 0.0, (self._blind * d) ** 2, 0.0
        tau = self._tau
        return self.gyro.motion3(t1 + tau, t2 + tau)

    def _align(self, t: float) -> None:
        cfg = self.config.alignment
        if not cfg.enabled or t < self._next_align:
            return
        first = self._tau_conf == 0.0
        self._next_align = t + (min(0.5, cfg.update_period_s) if first else cfg.update_period_s)
        est = self.aligner.estimate(self.gyro)
        if est is None:
            return
        if est.correlation >= cfg.min_correlation:
            if abs(est.offset_s - self._tau) > 0.5 * cfg.step_s:
                log.info(
                    "fusion[%s]: camera-IMU offset %.4f s (correlation %.3f, %d increments)",
                    self.name,
                    est.offset_s,
                    est.correlation,
                    est.n_increments,
                )
            self._tau = est.offset_s
            self._tau_conf = est.correlation
            self._tau_std = max(est.std_s, cfg.min_std_s)

    def _commit(self, t: float) -> None:
        gyro = self.gyro
        newest = gyro.newest
        tau = self._tau
        ready = self._ready or self._gyro_ready(t)
        if not ready:
            horizon = t  # gyro not fused yet (offset unknown): nothing to wait for
        elif newest is None:
            horizon = t if t - self._t0 > self._timeout else self._t0
        elif t - (newest - tau) > self._timeout:
            horizon = t  # IMU lost: bridge without gyro
        else:
            horizon = newest - tau - self._reorder
            if not horizon < t:
                horizon = t
        if ready and self._startup is not None:
            self._rerun_startup()
        frames = self._frames
        if frames and frames[0] <= horizon:
            sup = self._sup
            vis, fails, startup = self._vis, self._fails, self._startup
            keep = None if ready else startup  # frames to process again once the gyro is ready
            n = 0
            for tf in frames:  # (processing a frame leaves the list alone)
                if tf > horizon:
                    break
                self._process_frame(tf, sup, True)
                meas = vis.pop(tf, None)
                fail = fails.pop(tf, None) if fails else None
                if keep is not None:
                    keep.append((tf, meas, fail))
                n += 1
            del frames[:n]
            if startup is not None and self._t - self._t0 > self._history - 1.0:
                self._startup = None  # too long ago: the gyro history no longer covers it
        t_gyro = self._t + tau
        # gyro up to here is spent: later samples for it are late. Never beyond the newest
        # sample received: frames committed without gyro (IMU lost, or before the offset was
        # known) spent no gyro, and a sample newer than every other one is the IMU coming
        # back, whatever the offset (else, with an offset above a frame, every returning
        # sample was "late" and the IMU never recovered)
        if newest is not None and newest < t_gyro:
            t_gyro = newest
        floor = gyro.floor
        if ready and t_gyro > floor:
            gyro.floor = floor = t_gyro
        gyro.trim((floor if floor > t_gyro else t_gyro) - self._history)

    def _rerun_startup(self) -> None:
        """The offset has just become known: process the frames since the start again, now
        with the gyro, so that the bias is learnt from the first frame on. The output does
        not step: the change enters as a level change (eased in)."""
        frames, self._startup = self._startup, None
        if not frames:
            return
        backend = self.backend
        phi_before = backend.estimate()[0]
        backend.take_level_shift()
        self._sup = ModeSupervisor(self.config.modes)
        self._t = self._t0
        backend.start(self._t0)
        for tf, vis, fail in frames:
            if vis is not None:
                self._vis[tf] = vis
            if fail is not None:
                self._fails[tf] = fail
            self._process_frame(tf, self._sup, True)
            self._vis.pop(tf, None)
            self._fails.pop(tf, None)
        backend.take_level_shift()
        self._level -= backend.estimate()[0] - phi_before
        log.info(
            "fusion[%s]: camera-IMU offset known (%.4f s): %d startup frames processed again"
            " with the gyro",
            self.name,
            self._tau,
            len(frames),
        )

    def _process_frame(
        self, tf: float, sup: ModeSupervisor, apply: bool
    ) -> tuple[bool, list[tuple[VisualPitch, float]]]:
        """Advance to frame ``tf`` and handle its visual results (``apply``: in the back end;
        else only decide). Returns the IMU liveness and (when not ``apply``) the measurements
        to fuse."""
        # the IMU's liveness (`_alive`) and the motion since the state (`_motion3`), inline:
        # this runs once per frame
        gyro = self.gyro
        if self._ready or self._gyro_ready(tf):
            newest = gyro.newest
            if newest is None:
                alive = tf - self._t0 <= self._timeout
            else:
                alive = newest - self._tau >= tf - self._timeout
        else:
            alive = False
        if apply:
            t1 = self._t
            if alive:
                tau = self._tau
                dG, dV, dM = gyro.motion3(t1 + tau, tf + tau)
                self.backend.step(tf, dG, dV, dM)
            else:
                self.backend.step(tf, 0.0, (self._blind * (tf - t1)) ** 2, 0.0)
            self._t = tf
        fuse = self._handle_frame_inputs(tf, sup, apply, alive)
        sup.update_mode(alive)
        if apply:
            self.backend.end_frame(tf)
        return alive, fuse

    def _handle_frame_inputs(
        self, tf: float, sup: ModeSupervisor, apply: bool, imu_ok: bool
    ) -> list[tuple[VisualPitch, float]]:
        """Decide per measurement of frame ``tf`` (trust, gyro check) and fuse the accepted
        ones when ``apply``; else return them with their variances."""
        fuse: list[tuple[VisualPitch, float]] = []
        metas = self._vis.get(tf)
        if not metas:
            if tf in self._fails:
                sup.bad_frame(tf)
            else:
                sup.no_news(tf)
            return fuse
        gyro, backend = self.gyro, self.backend
        use_gyro = imu_ok and gyro.newest is not None
        tau = self._tau
        for m, var in metas:
            if var is None:  # unusable
                sup.bad_frame(tf)
                continue
            if apply:
                backend.pin_key(m.t_ref)
            # the measurement's variance (`push_visual`: the estimator's, inflated for few
            # inliers) plus the part of the gyro that a time-offset error would move:
            # (σ_τ Δω)²
            if use_gyro:
                var += (self._tau_std * gyro.rate_change(m.t_ref + tau, m.t + tau)) ** 2
            trusted = sup.trust is _TRUSTED
            if trusted and not self._gate_with_gyro:
                # fused unchecked: `good_frame` of trusted vision, inline (the usual case)
                sup.bad_frames = 0
                sup.last_good_t = tf
            else:
                consistent = self._consistent(m, var, imu_ok)
                if not consistent and trusted:  # an outlier against the gyro
                    if apply:
                        self.events(
                            "gated",
                            "visual measurement at t=%.6f disagrees with the gyro: not fused",
                            m.t,
                        )
                    sup.gated(True, self._max_rejections, tf)
                    continue
                if not sup.good_frame(tf, consistent):
                    continue
            if apply:
                if backend.update(m, var):
                    # `gated(False, ...)`, inline (max_rejections >= 1)
                    sup.rejected = 0
                    sup.last_accepted_t = tf
                else:
                    sup.gated(True, self._max_rejections, tf)
            else:
                fuse.append((m, var))
        return fuse

    def _unusable(self, m: VisualPitch) -> None:
        """Log a measurement the front end passed whose numbers make no sense (a failure)."""
        self.events(
            "visual-bad",
            "visual measurement t=%.6f (dphi=%r, std=%r, inliers=%r) unusable: a failure",
            m.t,
            m.dphi,
            m.std,
            m.inlier_ratio,
        )

    def _consistent(self, m: VisualPitch, var: float, imu_ok: bool) -> bool:
        """Re-validation: does the visual increment agree with the gyro over [t_ref, t]?"""
        if not imu_ok or not self.gyro.covers(m.t_ref + self._tau):
            return True  # nothing to check against (no gyro, or the key is too old)
        mo = self.gyro.motion(m.t_ref + self._tau, m.t + self._tau)
        _, _, b, bvar = self.backend.estimate()
        pred = mo.dG - b * mo.dM
        tot = var + mo.dV + mo.dM * mo.dM * bvar
        return abs(m.dphi - pred) <= self.config.modes.consistency_sigma * math.sqrt(tot)

    def _tentative(self, t: float) -> tuple[float, float, FusionMode, float]:
        """Output for frames beyond the commit horizon, without committing them:
        (phi, variance, mode, level shift of the key frame meanwhile)."""
        frames = [f for f in self._frames if f <= t]
        rewind = self._rewind
        if rewind is not None:
            snap = (rewind.snapshot(), self._t, replace(self._sup))
            try:
                for tf in frames:
                    self._process_frame(tf, self._sup, True)
                phi, var, _, _ = rewind.estimate()
                return phi, var, self._sup.mode, self._level_shift(self._sup)
            finally:
                bk, self._t, self._sup = snap
                rewind.restore(bk)
        # back ends that cannot copy their state: the gyro from the newest committed state,
        # each accepted visual measurement fused by its variance against the key frame's
        # estimate (committed or extrapolated here), their correlation neglected
        sup = replace(self._sup)
        backend = self.backend
        phi, var, b, bvar = backend.estimate()
        t_prev = self._t
        head: dict[float, tuple[float, float]] = {}
        for tf in frames:
            alive, fuse = self._process_frame(tf, sup, False)
            mo = self._motion(t_prev, tf, alive)
            phi += mo.dG - b * mo.dM
            var += mo.dV + mo.dM * mo.dM * bvar
            for m, r in fuse:
                ref = head.get(m.t_ref) or backend.frame_estimate(m.t_ref)
                if ref is not None:
                    v_vis = ref[1] + r
                    phi = (phi * v_vis + (ref[0] + m.dphi) * var) / (var + v_vis)
                    var = var * v_vis / (var + v_vis)
            head[tf] = (phi, var)
            t_prev = tf
        return phi, var, sup.mode, 0.0

    def _level_shift(self, sup: ModeSupervisor) -> float:
        """The key frame's estimate moved by the back end's shift: a level change to ease in
        shortly after a re-acquisition; otherwise the state is output as it is."""
        shift = self.backend.take_level_shift()
        return shift if self._t - sup.reacquired_t <= self._capture else 0.0
