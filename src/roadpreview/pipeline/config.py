"""The pipeline's one configuration file (``roadpreview.toml``): every part's settings.

Each part keeps its own typed dataclass next to its code (vision, pitch,
fusion, anomaly); this module gathers them into `PipelineConfig`, loads it
from TOML with unknown keys rejected (errors name the key and the file) and
applies command-line overrides. ``data/roadpreview.example.toml`` is the
documented example.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from roadpreview import configtools
from roadpreview.anomaly.config import AnomalyConfig
from roadpreview.configtools import param
from roadpreview.ego.vertical import EgoVerticalConfig
from roadpreview.fusion import BACKENDS
from roadpreview.fusion.heave import HeaveConfig
from roadpreview.pitch import ESTIMATORS
from roadpreview.plausibility import PlausibilityConfig
from roadpreview.preview.config import PreviewConfig
from roadpreview.vision.frontend import VisionConfig


@dataclass(frozen=True)
class PitchStageConfig:
    """``[pitch]``: which estimator and its options (see ``roadpreview.pitch``)."""

    estimator: str = param(
        "robust", choices=tuple(ESTIMATORS), help="the paper's robust LM by default"
    )
    options: dict[str, Any] = field(default_factory=dict)
    min_points: int = param(
        30, ge=5, help="fewer background pairs than this: vision failed for the fusion"
    )


@dataclass(frozen=True)
class FusionStageConfig:
    """``[fusion]``: which back end and its options (see ``roadpreview.fusion``)."""

    backend: str = param(
        "kalman",
        choices=tuple(BACKENDS),
        help="filterpy Kalman filter by default",
    )
    options: dict[str, Any] = field(default_factory=dict)
    horizon_highpass_s: float = param(
        3.0,
        unit="s",
        gt=0.0,
        le=60.0,
        help="the vision's horizon uses the fused pitch minus its low-pass over this time"
        " constant: the slow part is the road's grade (and start-up drift), which the lead,"
        " on the same road 5-40 m ahead, shares; bump pitching is 0.5-2 Hz",
    )
    max_pitch_rad: float = param(
        0.5,
        unit="rad",
        gt=0.0,
        lt=1.5,
        help="a fused pitch beyond this (29 deg: no car pitches so far, grades included) is a"
        " diverged fusion: the frame is not compensated (no alert from it), the fusion is"
        " reset, and it is logged and counted (pitch_diverged)",
    )
    frame_hold_s: float = param(
        0.0,
        unit="s",
        ge=0.0,
        le=0.5,
        help="the most the run loop holds a camera frame back, waiting for the IMU samples of"
        " its instant, so that the frame is fused and compensated with the gyro (committed),"
        " not on a bridged guess; also the hold while the camera-IMU offset is unknown. 0.12"
        " covers offsets up to 0.1 s. Off by default: it cuts the fused pitch's 1 s error by"
        " about a third, but the two-axle detector's background model, fitted on tentative"
        " frames, then scores some bumps lower (docs/fusion.md, 'Frames wait for their"
        " gyro'); 0: no hold",
    )
    frame_hold_margin_s: float = param(
        0.02,
        unit="s",
        ge=0.0,
        le=0.2,
        help="once the camera-IMU offset is estimated, a frame is held for the offset plus"
        " this (the gyro's reorder window, 10 ms, and 10 ms to spare), at most frame_hold_s:"
        " frames go out this much after the IMU has caught up with them",
    )


@dataclass(frozen=True)
class CanStageConfig:
    """``[can]``: the input mapping and the DBC; the buses of the daemon."""

    dbc: str = param("", help="DBC of the input messages; empty: roadpreview's own")
    mapping: str = param(
        "roadpreview", help="mapping file, or a shipped name: roadpreview, toyota_rav4"
    )
    input_interface: str = param("socketcan", help="python-can interface of the input bus")
    input_channel: str = param("can0", help="channel of the input bus")
    output_interface: str = param("", help="output bus interface; empty: the input bus")
    output_channel: str = param("", help="output bus channel; empty: the input bus")
    status_period_s: float = param(0.1, unit="s", gt=0.0, le=10.0, help="RP_STATUS cycle")
    alert_repeat_period_s: float = param(
        0.1,
        unit="s",
        gt=0.0,
        le=1.0,
        help="RP_ALERT + RP_ALERT_DETAIL repeated this often while an alert is active, with"
        " distance and time to arrival as of each send: a lost frame costs one period, not"
        " the alert",
    )
    imu_timeout_s: float = param(
        0.5, unit="s", gt=0.0, help="no gyro sample for this long: the IMU is gone (watchdog)"
    )


@dataclass(frozen=True)
class DaemonConfig:
    """``[daemon]``: the in-vehicle daemon (``roadpreview run``): camera and watchdogs."""

    camera_source: str = param(
        "0",
        help="cv2.VideoCapture source: a device index (digits), a video file (played at its"
        " recorded pace, for bench tests) or a stream URL",
    )
    camera_timeout_s: float = param(
        0.5,
        unit="s",
        gt=0.0,
        le=10.0,
        help="no camera frame for this long = camera lost (watchdog): about 15 frames at"
        " 30 fps, twice the fusion's vision timeout, so a single late frame is no failure;"
        " the pipeline then gets frames without image (vision failure) every status period",
    )
    camera_reopen_s: float = param(
        1.0,
        unit="s",
        gt=0.0,
        help="a device or stream that fails is reopened after this pause (a USB camera"
        " re-enumerates in about a second)",
    )
    can_queue_size: int = param(
        10_000,
        ge=1,
        help="received CAN frames waiting for the processing loop: 10 s of a busy bus;"
        " beyond it frames are dropped and counted",
    )
    can_latency_s: float = param(
        0.02,
        unit="s",
        ge=0.0,
        le=0.5,
        help="a frame is processed this long after its time stamp so CAN frames stamped"
        " before it (still in the driver or the notifier thread) are pushed first, as in a"
        " replay; small against the 1-2 s preview of an alert",
    )
    camera_width: int = param(
        0,
        unit="px",
        ge=0,
        help="frame width requested from a device or stream after opening; 0: the camera's"
        " default. Read back and logged; a refusal is a warning, a size other than the"
        " calibration's an error",
    )
    camera_height: int = param(
        0, unit="px", ge=0, help="frame height requested, as camera_width; 0: the default"
    )
    camera_fps: float = param(
        0.0,
        unit="1/s",
        ge=0.0,
        help="frame rate requested from a device or stream; 0: the camera's default",
    )
    status_log_period_s: float = param(
        10.0,
        unit="s",
        ge=0.0,
        help="one status log line (and systemd STATUS=) this often on the frames' clock:"
        " mode, fps, drops, alerts, bus errors, IMU and camera; 0: never",
    )
    watchdog_ping_s: float = param(
        0.0,
        unit="s",
        ge=0.0,
        help="systemd WATCHDOG=1 ping period; 0: half of the unit's WatchdogSec"
        " (WATCHDOG_USEC), no pings without it",
    )
    watchdog_stall_s: float = param(
        2.0,
        unit="s",
        gt=0.0,
        help="the loop processed no frame (not even the camera watchdog's image-less ones)"
        " for this long: stalled, the pings stop so systemd restarts the daemon; must exceed"
        " camera_timeout_s",
    )
    watchdog_camera_lost_s: float = param(
        0.0,
        unit="s",
        ge=0.0,
        help="the camera lost for this long also stops the pings (a hung driver that only a"
        " restart frees); 0: never (the daemon reopens the camera itself and keeps sending"
        " DEGRADED status)",
    )
    switch_interval_s: float = param(
        0.001,
        unit="s",
        gt=0.0,
        le=0.1,
        help="Python's thread switch interval while the daemon runs (sys.setswitchinterval;"
        " Python's default 0.005): how long the RP_STATUS sender may wait for the"
        " interpreter per busy thread; at 5 ms its period jitter under a burst of input on a"
        " loaded machine was twice that at 1 ms (docs/daemon.md)",
    )


@dataclass(frozen=True)
class LeadKinematicsConfig:
    """How the lead's acceleration is estimated (for the braking suppression)."""

    window_s: float = param(
        3.0,
        unit="s",
        gt=0.1,
        le=10.0,
        help="quadratic fit of the lead distance over this window: long enough to average out"
        " the distance jumps of a bump (~1 s), short enough for a 1-2 s braking manoeuvre",
    )


@dataclass(frozen=True)
class PipelineConfig:
    """Everything the pipeline needs besides the camera calibration."""

    vision: VisionConfig = field(default_factory=VisionConfig)
    pitch: PitchStageConfig = field(default_factory=PitchStageConfig)
    fusion: FusionStageConfig = field(default_factory=FusionStageConfig)
    heave: HeaveConfig = field(default_factory=HeaveConfig)
    ego: EgoVerticalConfig = field(default_factory=EgoVerticalConfig)
    anomaly: AnomalyConfig = field(default_factory=AnomalyConfig)
    #: the road-profile preview (``RP_PREVIEW``) from the lead's response
    preview: PreviewConfig = field(default_factory=PreviewConfig)
    can: CanStageConfig = field(default_factory=CanStageConfig)
    #: the input gate after the integrity checks: physical ranges, gyro spikes, stamps
    plausibility: PlausibilityConfig = field(default_factory=PlausibilityConfig)
    lead: LeadKinematicsConfig = field(default_factory=LeadKinematicsConfig)
    daemon: DaemonConfig = field(default_factory=DaemonConfig)

    def validate(self, where: str = "") -> None:
        if not where:
            configtools.check_ranges(self)
            self.plausibility.validate("plausibility")

    @classmethod
    def load(cls, path: str | Path) -> PipelineConfig:
        """Read a configuration file; errors name the file and the key."""
        return configtools.load(cls, path)

    def save(self, path: str | Path) -> None:
        configtools.save(self, path)

    def with_overrides(
        self,
        *,
        finder: str | None = None,
        estimator: str | None = None,
        fusion: str | None = None,
    ) -> PipelineConfig:
        """Command-line flags override the file."""
        cfg = self
        if finder is not None:
            cfg = replace(cfg, vision=replace(cfg.vision, finder=finder))
        if estimator is not None:
            cfg = replace(cfg, pitch=replace(cfg.pitch, estimator=estimator))
        if fusion is not None:
            cfg = replace(cfg, fusion=replace(cfg.fusion, backend=fusion))
        return cfg
