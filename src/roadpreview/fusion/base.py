"""The pitch-fusion interfaces: what goes in (gyro, visual pitch), what comes out (`FusedPitch`),
and the estimator a fusion holds (`PitchBackEnd`).

Every back end is a streaming estimator with the same five calls::

    fusion.push_gyro(t_stamp, pitch_rate)                  # IMU clock, rad/s, nose up +
    fusion.push_visual(VisualPitch(t_ref, t, dphi, std, inlier_ratio, quality_ok))
    fusion.push_vision_failure(t, "fog")                  # the front end saw no texture
    out = fusion.estimate(t)                              # at a frame time (camera clock)
    fusion.reset()

Times are seconds. Gyro time stamps are on the IMU's clock, which may be
offset from the camera's (the fusion estimates the offset); visual times are
frame times on the camera clock. Angles are radians, pitch positive nose up
(``docs/method.md``). The fused pitch is relative to the camera's attitude at
the first frame (``docs/fusion.md``).

The `kalman` and `factor-graph` back ends are one `StreamingPitchFusion`
(`roadpreview.fusion.streaming`: gyro buffering, time offset, modes, output)
holding a `PitchBackEnd`, the estimator proper (filterpy's Kalman filter,
gtsam's fixed-lag smoother), as a Stone Soup tracker holds its predictor and
updater.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Protocol, runtime_checkable

from roadpreview.fusion.gyro import RejectCounter
from roadpreview.pitch.base import PitchEstimate, PitchInDegrees
from roadpreview.types import FusionMode


def _slot_setters(cls: type) -> tuple[Callable[[object, object], None], ...]:
    """The slot setters of a dataclass's fields, in field order.

    `VisualPitch` and `FusedPitch` are made once per frame. The ``__init__`` that
    `dataclass` writes for a frozen class sets each field with ``object.__setattr__``;
    theirs (``init=False``, written out) calls the slot's own setter instead, which is the
    same store at half the cost (about 1 µs instead of 2 per object).
    """
    return tuple(cls.__dict__[f.name].__set__ for f in fields(cls))


@dataclass(frozen=True, slots=True, init=False)
class VisualPitch:
    """A visual pitch measurement between two frames, as the vision front end delivers it.

    ``dphi`` is phi(t) - phi(t_ref): the pitch of frame ``t`` relative to the
    reference (key) frame ``t_ref``, or to the previous frame for a
    frame-to-frame pair. ``std`` (rad) and ``inlier_ratio`` come from the
    pitch estimator; ``quality_ok`` is the front end's verdict on the frame
    (enough texture, enough points, a good fit).
    """

    t_ref: float
    t: float
    dphi: float
    std: float
    inlier_ratio: float = 1.0
    quality_ok: bool = True

    def __init__(
        self,
        t_ref: float,
        t: float,
        dphi: float,
        std: float,
        inlier_ratio: float = 1.0,
        quality_ok: bool = True,
    ) -> None:
        set_t_ref, set_t, set_dphi, set_std, set_inlier_ratio, set_quality_ok = _VISUAL_SETTERS
        set_t_ref(self, t_ref)
        set_t(self, t)
        set_dphi(self, dphi)
        set_std(self, std)
        set_inlier_ratio(self, inlier_ratio)
        set_quality_ok(self, quality_ok)

    @classmethod
    def from_estimate(
        cls, t_ref: float, t: float, est: PitchEstimate, *, quality_ok: bool = True
    ) -> VisualPitch:
        """Wrap a `PitchEstimate` of frame ``t`` against key frame ``t_ref``.

        A falsy estimate (failed fit) gives a measurement with ``quality_ok``
        False, which the fusion treats as a vision failure at ``t``.
        """
        return cls(
            t_ref=t_ref,
            t=t,
            dphi=est.phi,
            std=est.std,
            inlier_ratio=est.inlier_ratio,
            quality_ok=quality_ok and bool(est),
        )


_VISUAL_SETTERS = _slot_setters(VisualPitch)


@dataclass(frozen=True, slots=True, init=False)
class FusedPitch(PitchInDegrees):
    """The fused camera pitch at a frame time.

    ``phi`` (rad) is relative to the attitude at the first frame; ``std`` its
    standard deviation (it grows honestly while vision is lost); ``bias`` the
    gyro pitch-rate bias estimate (rad/s) with ``bias_std``; ``time_offset``
    the IMU clock minus the camera clock (s, stamps lag when positive) that
    the fusion applies, with ``time_offset_confidence`` in [0, 1] (0: not
    estimated yet, the configured initial value is used).
    """

    t: float
    phi: float
    std: float
    mode: FusionMode
    bias: float = math.nan
    time_offset: float = 0.0
    time_offset_confidence: float = 0.0
    bias_std: float = math.nan

    def __init__(
        self,
        t: float,
        phi: float,
        std: float,
        mode: FusionMode,
        bias: float = math.nan,
        time_offset: float = 0.0,
        time_offset_confidence: float = 0.0,
        bias_std: float = math.nan,
    ) -> None:
        set_t, set_phi, set_std, set_mode, set_bias, set_off, set_conf, set_bias_std = (
            _FUSED_SETTERS
        )
        set_t(self, t)
        set_phi(self, phi)
        set_std(self, std)
        set_mode(self, mode)
        set_bias(self, bias)
        set_off(self, time_offset)
        set_conf(self, time_offset_confidence)
        set_bias_std(self, bias_std)


_FUSED_SETTERS = _slot_setters(FusedPitch)


@runtime_checkable
class PitchFusion(Protocol):
    """Fuses gyro pitch rates with relative visual pitch; one value per frame time."""

    #: registry name ("kalman", "factor-graph", "visual-only", "imu-only", "none")
    name: str

    def push_gyro(
        self,
        t: float,
        pitch_rate: float,
        *,
        roll_rate: float | None = None,
        yaw_rate: float | None = None,
    ) -> bool:
        """Add one gyro sample (IMU clock, rad/s); False if it was rejected (logged)."""
        ...

    def push_visual(self, meas: VisualPitch) -> None:
        """Add a relative visual pitch measurement between two frame times."""
        ...

    def push_vision_failure(self, t: float, reason: str) -> None:
        """Say that vision gave nothing usable for the frame at ``t``."""
        ...

    def estimate(self, t: float) -> FusedPitch:
        """The fused pitch at frame time ``t`` (camera clock), from everything pushed so far."""
        ...

    def reset(self) -> None:
        """Forget everything (a new drive)."""
        ...


#: (phi, its variance, gyro bias, its variance) of a back end's current state
BackEndEstimate = tuple[float, float, float, float]


class PitchBackEnd(Protocol):
    """The estimator inside `StreamingPitchFusion`: pitch and gyro bias at frame times.

    The fusion calls it in time order, frame by frame: `start` at the first frame, then per
    frame `step` (the gyro's motion since the previous frame), `pin_key` and `update` for
    each visual measurement of that frame that the mode machine lets through, and
    `end_frame`. Everything else (buffering, ordering, time offset, modes, re-validation,
    the output's easing) is the fusion's. Angles in rad, rates in rad/s, times in s on the
    camera clock.
    """

    #: registry name ("kalman", "factor-graph")
    name: str
    #: where the back end counts and logs what it skips or rejects (shared with the fusion)
    events: RejectCounter
    #: consecutive rejected measurements (`update` False) that make vision lost
    max_rejections: int
    #: test every fused measurement against the gyro (a back end without its own gate);
    #: re-validation after a loss always does
    gate_with_gyro: bool

    def start(self, t0: float) -> None:
        """Forget everything and start at the first frame ``t0``: phi = 0 there, the bias
        prior of the config."""
        ...

    def step(self, t: float, dG: float, dV: float, dM: float) -> None:
        """Move to the next frame ``t`` with the gyro over the interval (`Motion`: integral
        ``dG``, its variance ``dV``, measured time ``dM``) and keep that frame's state for
        later relative measurements."""
        ...

    def pin_key(self, t_ref: float) -> None:
        """A usable measurement refers to key frame ``t_ref``: keep that frame's state."""
        ...

    def update(self, meas: VisualPitch, var: float) -> bool:
        """Fuse ``meas`` (of the current frame) with variance ``var``; False if rejected
        as an outlier."""
        ...

    def end_frame(self, t: float) -> None:
        """Every measurement of frame ``t`` has been given (a smoother solves here)."""
        ...

    def estimate(self) -> BackEndEstimate:
        """(phi, variance, bias, variance) of the current (last stepped) frame."""
        ...

    def frame_estimate(self, t: float) -> tuple[float, float] | None:
        """(phi, variance) of the earlier frame ``t`` if the back end still holds it."""
        ...

    def take_level_shift(self) -> float:
        """How far the estimate of the pinned key frame has moved since the last call (the
        part of the corrections that changes the absolute level, eased into the output)."""
        ...


@runtime_checkable
class RewindableBackEnd(PitchBackEnd, Protocol):
    """A back end that can copy and put back its state: frames beyond the gyro are then
    processed exactly (and again later for good) instead of extrapolated."""

    def snapshot(self) -> object:
        """A copy of the state (opaque to the caller)."""
        ...

    def restore(self, snapshot: object) -> None:
        """Put back a `snapshot` of this back end."""
        ...
