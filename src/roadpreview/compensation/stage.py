"""`Compensator`: pipeline step 4 as one stage, y_c = compensate(y, φ, heave, d).

Per frame it takes the lead's rows (centre and halves), the fused pitch φ, the fusion's
camera-IMU time offset and the lead's distance d, and returns `Compensated`: y_c and
the two terms it subtracted, the pitch term f tan φ and the heave term f Δz / d. The
camera's heave Δz comes from the accelerometer (`roadpreview.fusion.heave.HeaveObserver`,
fed by `push_imu`, queried on the IMU clock: frame time + the time offset); the term is
held while Δz or d is unknown and never jumps (`HeaveTerm`).

The math is `roadpreview.compensation.model`; the evaluation's error budget feeds the same
functions with the simulator's truth in place of one term at a time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from roadpreview.compensation.model import compensation, heave_term_px
from roadpreview.fusion.heave import HeaveConfig, HeaveEstimate, HeaveObserver
from roadpreview.plausibility import PlausibilityConfig
from roadpreview.types import ImuSample

_NAN = math.nan


class HeaveTerm:
    """The heave term f Δz / d that the pipeline subtracts from y, per frame, never jumping.

    The lead's distance d comes from the vision; a frame without one (or one below
    ``min_distance_m``, more often a wrong box than a real gap) uses the last good one
    for ``distance_hold_s``. While Δz or d is unknown the term is held at its last
    value; when both are back it goes on from there, ``held + f (Δz - Δz_on) / d``: a
    constant offset does not change s, a jump would look like a bump. A new target
    starts the term again from 0 (the detector's window restarts anyway).
    """

    def __init__(self, config: HeaveConfig, focal_px: float) -> None:
        self.config = config
        self.focal_px = focal_px
        self.reset()

    def reset(self) -> None:
        self._t_d = -math.inf  # time of the last good distance
        self._d = math.nan  # the last good distance, m
        self._ref: tuple[float, float] | None = None  # (Δz, term) when the term resumed
        self.px = 0.0  #: the term of the last frame, px
        self.active = False  #: the last frame had both Δz and d (the term followed Δz)

    def update(self, t: float, est: HeaveEstimate, distance_m: float, new_target: bool) -> float:
        """The term (px, v down) for the frame at ``t`` given the observer's estimate."""
        c = self.config
        if new_target:
            self.reset()
        if math.isfinite(distance_m) and distance_m >= max(c.min_distance_m, 1e-3):
            self._t_d, self._d = t, distance_m
        if not est.available or t - self._t_d > c.distance_hold_s:
            self._ref = None
            self.active = False
            return self.px
        if self._ref is None:
            self._ref = (est.dz_m, self.px)
        z_on, px_on = self._ref
        self.px = px_on + float(heave_term_px(est.dz_m - z_on, self._d, self.focal_px))
        self.active = True
        return self.px


@dataclass(frozen=True)
class Compensated:
    """One frame's compensation (px, v down; NaN: not compensated)."""

    y_c: float
    y_c_left: float
    y_c_right: float
    #: f tan φ, the pitch term subtracted (0 for a frame whose pitch was unusable)
    pitch_px: float = 0.0
    #: the heave term subtracted (`HeaveTerm`): 0 without a heave estimate
    heave_px: float = 0.0
    #: the camera's heave Δz at the frame, m (NaN: unavailable or disabled)
    heave_m: float = _NAN

    @property
    def total_px(self) -> float:
        """Everything subtracted from y: the pitch and the heave term."""
        return self.pitch_px + self.heave_px


class Compensator:
    """The streaming compensation stage (module docstring)."""

    def __init__(
        self,
        focal_px: float,
        heave: HeaveConfig | None = None,
        plausibility: PlausibilityConfig | None = None,
    ) -> None:
        """``heave``: the heave observer's settings; None or ``enabled = false``: pitch only."""
        self.focal_px = float(focal_px)
        on = heave is not None and heave.enabled
        self.observer = HeaveObserver(heave, plausibility) if on else None
        self._term = HeaveTerm(heave, self.focal_px) if heave is not None and on else None

    def push_imu(self, sample: ImuSample) -> None:
        """An IMU sample for the heave observer (nothing when heave is off)."""
        if self.observer is not None:
            self.observer.push(sample)

    def heave(
        self, t: float, phi: float, time_offset_s: float, distance_m: float, target_changed: bool
    ) -> tuple[float, float]:
        """(Δz m, NaN if unavailable; the heave term px) at frame ``t``: the observer is
        told the pitch (it rotates the specific force) and queried at ``t`` + the offset."""
        obs, term = self.observer, self._term
        if obs is None or term is None:
            return _NAN, 0.0
        obs.set_pitch(phi)
        offset = time_offset_s if math.isfinite(time_offset_s) else 0.0
        est = obs.at(t + offset)
        return est.dz_m, term.update(t, est, distance_m, target_changed)

    def frame(
        self,
        t: float,
        rows: tuple[float, float, float],
        phi: float,
        *,
        time_offset_s: float = 0.0,
        distance_m: float = _NAN,
        target_changed: bool = False,
        valid: bool = True,
    ) -> Compensated:
        """Compensate one frame's rows (centre, left, right; NaN: no lead). ``valid``
        False (the fusion diverged): nothing is compensated, every y_c is NaN; the heave
        observer still follows the frame."""
        heave_m, heave_px = self.heave(t, phi, time_offset_s, distance_m, target_changed)
        if not valid:
            return Compensated(_NAN, _NAN, _NAN, 0.0, heave_px, heave_m)
        f = self.focal_px
        pitch_px = f * math.tan(phi)
        y, yl, yr = (
            float(compensation(v, phi, f)) - heave_px if math.isfinite(v) else _NAN for v in rows
        )
        return Compensated(y, yl, yr, pitch_px, heave_px, heave_m)


__all__ = ["Compensated", "Compensator", "HeaveTerm"]
