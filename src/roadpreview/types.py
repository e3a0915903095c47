"""The vocabulary every package speaks: typed, time-stamped samples in, alerts and status out.

This module is at the bottom of the import order: it imports nothing from
roadpreview, and every package (sources, vision, pitch, fusion, anomaly, the
pipeline, the sinks, CAN) imports its sample types from here, never from each
other. Times are seconds on the pipeline's clock (the log clock of a replay,
``time.time()`` in the daemon).

Inputs (what `roadpreview.sources` yield and `Pipeline.push` takes):

* `CameraFrame`: a BGR image (or None: the frame could not be decoded) with its
  time stamp and frame index;
* `ImuSample`: body rates and/or specific force;
* `SpeedSample`: the ego's speed over ground.

Outputs (what the pipeline emits and `roadpreview.sinks` write):

* `Alert`: one road anomaly ahead, for the predictive suspension;
* `ConfirmationResult`: what the ego felt when it reached an alerted spot;
* `Status`: the periodic health and mode report (``RP_STATUS``, ``RP_ROAD_STATUS``).

Conventions (``docs/method.md``): rates are roll positive when the left side
rises, pitch positive when the nose rises, yaw positive when turning left,
rad/s; accelerations are specific force in ISO 8855 body axes (x forward,
y left, z up; +9.81 m/s² on z at rest). A quantity a sample does not carry is NaN.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import IntEnum, IntFlag
from typing import TypeAlias

import numpy as np
from numpy.typing import NDArray

#: a camera image: H x W x 3, BGR, uint8 (OpenCV's layout)
Image: TypeAlias = NDArray[np.uint8]


# -- modes and flags ----------------------------------------------------------------------
class FusionMode(IntEnum):
    """Where the pitch used for compensation comes from at a frame.

    The integer values are the ones sent on CAN (``data/roadpreview.dbc``).
    """

    #: visual pitch and gyro both valid and fused
    FUSED = 0
    #: no IMU (absent or timed out): visual pitch only
    VISUAL_ONLY = 1
    #: vision failed (too few points, poor fit, low texture): gyro integration, bias frozen
    IMU_ONLY = 2
    #: neither source usable: no compensation can be trusted
    DEGRADED = 3


class Side(IntEnum):
    """Which half of the lead vehicle the anomaly moved; the integer goes on CAN.

    Seen from behind, the left half of the lead's image is the lead's (and the
    ego's) left side.
    """

    #: the half-vehicle trajectories were not available
    UNKNOWN = 0
    #: under the left wheels only (for example a pothole)
    LEFT = 1
    #: under the right wheels only
    RIGHT = 2
    #: full width (for example a speed bump)
    BOTH = 3


class SuppressionReason(IntFlag):
    """Why alerts are held back at a frame; falsy when they are not. Bits go on CAN."""

    NONE = 0
    #: the lead brakes or accelerates hard: its pitch is longitudinal dynamics, not the road
    LEAD_ACCEL = 1
    #: the fusion is DEGRADED: the trajectory is not compensated for the ego pitch
    DEGRADED = 2
    #: the fusion is IMU_ONLY before it has been FUSED long enough to know the gyro bias:
    #: the integrated pitch drifts
    SETTLING = 4


class Confirmation(IntEnum):
    """What the ego felt at an alerted spot; the integer goes on CAN."""

    UNKNOWN = 0
    CONFIRMED = 1
    NOT_FELT = 2


#: ISO 8608 road classes, smoothest first (CAN: index + 1, 0 unknown)
ISO8608_CLASSES = ("A", "B", "C", "D", "E", "F", "G", "H")


# -- inputs -------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True, eq=False)
class CameraFrame:
    """One camera frame: the image (None: it could not be decoded) and its time stamp."""

    t_s: float  #: time stamp on the pipeline's clock, s
    image: Image | None  #: BGR uint8, H x W x 3; None: undecodable (a vision failure)
    index: int = 0  #: frame number in its source (0 = the first frame read)


@dataclass(frozen=True, slots=True)
class ImuSample:
    """Body rates and/or specific force at one time stamp (NaN: not in this sample)."""

    t_s: float  #: time stamp (the frame's log / reception time), s
    rates_rad_s: tuple[float, float, float]  #: (roll, pitch nose-up +, yaw left +), rad/s
    accel_m_s2: tuple[float, float, float]  #: specific force (x fwd, y left, z up), m/s²
    source: str = ""  #: message (or file) the sample came from

    @property
    def pitch_rate_rad_s(self) -> float:
        """Pitch rate, nose up positive (NaN if not in this sample)."""
        return self.rates_rad_s[1]

    @property
    def has_rates(self) -> bool:
        """True if at least one rate is present."""
        return any(not math.isnan(r) for r in self.rates_rad_s)

    @property
    def has_accel(self) -> bool:
        """True if at least one acceleration is present."""
        return any(not math.isnan(a) for a in self.accel_m_s2)


@dataclass(frozen=True, slots=True)
class SpeedSample:
    """Vehicle speed over ground (magnitude) at one time stamp."""

    t_s: float  #: time stamp, s
    speed_mps: float  #: m/s (NaN: the sender flagged it not available)
    source: str = ""  #: message the sample came from


#: what a CAN decoder or an IMU file yields
InputSample: TypeAlias = ImuSample | SpeedSample
#: anything `Pipeline.push` takes
Sample: TypeAlias = CameraFrame | ImuSample | SpeedSample


# -- outputs ------------------------------------------------------------------------------
class AlertState(IntEnum):
    """Where an alert stands; the integer goes on CAN (``RP_ALERT_DETAIL.AlertState``).

    An alert is PROVISIONAL from the lead's front-axle response alone, then CONFIRMED by the
    two-axle fit under the same id, or ended CANCELLED (``RP_ALERT_END``, cause
    NOT_CONFIRMED) when the rear axle does not match. An alert the two-axle fit raises
    without a provisional one before it is CONFIRMED from its first frame (every alert of
    DBC version 1 was: raw 0).
    """

    CONFIRMED = 0  #: the two-axle fit matched: height and length are refined
    PROVISIONAL = 1  #: the front axle's response alone: confirmation or cancellation follows


@dataclass(frozen=True, slots=True)
class Alert:
    """A predictive alert about one road anomaly ahead.

    Times are on the pipeline's clock. The anomaly is ``distance_m`` ahead of
    the ego at ``t_s`` and reached at ``t_s + time_to_arrival_s`` if the speed
    stays the same; the alert exists from ``t_emit_s`` on (detection delay
    ``t_emit_s - t_s``). None: unknown.
    """

    t_s: float  #: when the lead crossed the anomaly, s
    t_emit_s: float  #: when the detector confirmed it, s
    distance_m: float | None  #: distance from the ego camera to the anomaly at t_s, m
    time_to_arrival_s: float | None  #: until the ego's front axle is there, from t_s, s
    severity_px: float  #: the detector's score (std: peak s in px; two-axle: background stds)
    #: estimated anomaly height, mm: signed (bump +, pothole -) from the two-axle
    #: detector's inverse model; the std detector's α f δ / d model gives a magnitude
    height_mm: float | None
    side: Side  #: left / right / both / unknown
    #: probability that the anomaly is real (two-axle: calibrated on the evaluation's
    #: training folds); the std detector's is a heuristic (docs/detector.md)
    confidence: float
    mode: FusionMode  #: fusion mode at the crossing
    alert_id: int = 0  #: sequence number of the alert since start (CAN: modulo 256)
    height_std_mm: float | None = None  #: std of ``height_mm`` (None: unknown)
    length_m: float | None = None  #: estimated length along the road (None: not resolved)
    lead_speed_mps: float | None = None  #: the lead's speed when it crossed, m/s
    state: AlertState = AlertState.CONFIRMED  #: provisional or confirmed (`AlertState`)
    #: when this alert id was first sent (its provisional emission), s; NaN: at ``t_emit_s``
    t_first_s: float = math.nan

    @property
    def t_first_sent_s(self) -> float:
        """When the first ``RP_ALERT`` of this alert went out (provisional or not), s."""
        return self.t_first_s if math.isfinite(self.t_first_s) else self.t_emit_s

    @property
    def arrival_t_s(self) -> float | None:
        """Predicted time the ego reaches the anomaly (None if unknown)."""
        return None if self.time_to_arrival_s is None else self.t_s + self.time_to_arrival_s

    def time_left_s(self, now_s: float) -> float | None:
        """Time until the ego reaches the anomaly, seen at ``now_s`` (None if unknown)."""
        arrival = self.arrival_t_s
        return None if arrival is None else arrival - now_s


@dataclass(frozen=True, slots=True)
class ConfirmationResult:
    """What the ego felt at one alerted spot."""

    alert_id: int  #: the alert's id
    outcome: Confirmation
    t_s: float  #: when it was decided (the window's end), s
    t_arrival_s: float  #: when the ego's front axle reached the spot (NaN: never), s
    peak_mps2: float  #: largest band-passed vertical acceleration in the window (NaN: none)
    background_mps2: float  #: the ego's background peak level then (NaN: none)


@dataclass(frozen=True, slots=True)
class RoadState:
    """The road's roughness now; None / NaN: unknown."""

    iso_class: str | None = None  #: the reported class (ego's, else lead's)
    gd_n0: float = math.nan  #: its G_d(n0), m³
    ego_class: str | None = None  #: from the ego's vertical acceleration
    ego_gd_n0: float = math.nan
    lead_class: str | None = None  #: from the lead's motion (the road ahead)
    lead_gd_n0: float = math.nan

    @property
    def class_index(self) -> int:
        """0 unknown, 1 = A .. 8 = H (the CAN encoding)."""
        return 0 if self.iso_class is None else ISO8608_CLASSES.index(self.iso_class) + 1


@dataclass(frozen=True, slots=True)
class Status:
    """What ``RP_STATUS`` and ``RP_ROAD_STATUS`` report; None: not available."""

    mode: FusionMode  #: current fusion mode
    pitch_rad: float | None = None  #: fused camera pitch, nose up +, rad
    gyro_bias_rad_s: float | None = None  #: estimated gyro pitch-rate bias, rad/s
    texture_quality: float | None = None  #: background texture quality, 0..1
    time_offset_s: float | None = None  #: IMU stamp minus camera stamp, s
    suppressed: SuppressionReason = SuppressionReason.NONE  #: why alerts are held back now
    alerts_sent: int = 0  #: alerts sent since start
    #: input frames dropped since start; the encoder sends the increase since its last frame
    input_errors_total: int = 0
    frames_processed: int = 0  #: camera frames processed since start
    # --- carried by RP_ROAD_STATUS ---
    road: RoadState | None = None  #: the road's roughness class estimate (None: unknown)
    precision: float | None = None  #: running online precision of the checked alerts, 0..1
    confirmed: int = 0  #: alerts the ego confirmed since start
    not_felt: int = 0  #: alerts the ego did not feel since start
    # --- carried by RP_INPUT_STATUS ---
    #: input samples rejected or noted since start, by reason (the sources' ``problems``:
    #: rejected_range, rejected_spike, saturated, e2e_crc, ...); the encoder sends the
    #: increase since its last frame, grouped
    input_problems_total: Mapping[str, int] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class RoadPreview:
    """The road ahead along the ego's path, where the lead's wheels have been (``RP_PREVIEW``).

    Bins of ``bin_m`` from the ego's front axle (bin k covers [start_m + k bin_m, start_m +
    (k + 1) bin_m) ahead of it) to the lead's rear axle. ``height_m`` and ``std_m`` are
    (tracks, bins): one track (both wheel tracks alike) or two (left, right), heights
    relative to the road's local line (the least-squares line over the track's valid bins:
    level and grade are not observable; up +); NaN where a bin has no valid estimate.
    """

    t_s: float  #: the frame the preview is as of, s
    bin_m: float  #: bin length along the path, m
    start_m: float  #: near edge of bin 0 ahead of the ego's front axle, m
    height_m: NDArray[np.float64]  #: (tracks, bins) road height, m (NaN: no estimate)
    std_m: NDArray[np.float64]  #: (tracks, bins) its standard deviation, m (NaN: none)
    sides: bool  #: True: rows are the left and the right track; False: one row for both
    lead_rear_axle_m: float  #: the lead's rear axle ahead of the ego's front axle, m

    @property
    def valid(self) -> NDArray[np.bool_]:
        """(tracks, bins): the bins with an estimate."""
        return np.isfinite(self.height_m) & np.isfinite(self.std_m)

    @property
    def centres_m(self) -> NDArray[np.float64]:
        """The bins' centres ahead of the ego's front axle, m."""
        n = self.height_m.shape[1]
        return np.asarray(self.start_m + self.bin_m * (np.arange(n) + 0.5), dtype=np.float64)


__all__ = [
    "ISO8608_CLASSES",
    "Alert",
    "AlertState",
    "CameraFrame",
    "Confirmation",
    "ConfirmationResult",
    "FusionMode",
    "Image",
    "ImuSample",
    "InputSample",
    "RoadPreview",
    "RoadState",
    "Sample",
    "Side",
    "SpeedSample",
    "Status",
    "SuppressionReason",
]
