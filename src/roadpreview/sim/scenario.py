"""A whole simulated drive in one typed configuration (``scenario.toml``).

`ScenarioConfig` gathers what `roadpreview.sim.recording.write_recording`
needs to regenerate a drive bit for bit: the seed, the motion (road, vehicles,
traffic), the camera, the renderer, the scene, the IMU and speed sensors, the
visibility schedule (fog, night, tunnel) and which files to write. It loads
from TOML with unknown keys rejected and every error naming the field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roadpreview import configtools
from roadpreview.camera import CameraModel
from roadpreview.configtools import param
from roadpreview.errors import ConfigError
from roadpreview.sim.imu import IMU_PRESETS, ImuConfig, SpeedSensorConfig
from roadpreview.sim.motion import MotionConfig, _kinematics
from roadpreview.sim.render import RenderConfig
from roadpreview.sim.scene import SceneConfig


@dataclass(frozen=True)
class CameraSpec:
    """The simulated camera: resolution, field of view, frame rate, calibrated forward t.

    Its position on the ego body is ``motion.camera_forward_m`` / ``camera_height_m``.
    """

    width: int = param(1280, unit="px", ge=160, le=3840, help="720p: the pipeline's target")
    height: int = param(720, unit="px", ge=90, le=2160, help="720p")
    vfov_deg: float = param(
        54.0, unit="deg", gt=10.0, lt=120.0, help="the paper's camera (1920x1080, 54 deg)"
    )
    fps: float = param(30.0, unit="Hz", ge=5.0, le=120.0, help="the paper's T = 30 frames = 1 s")
    forward: tuple[float, float, float] = param(
        (0.0, 0.0, 1.0), help="direction of travel in camera coordinates (unit vector)"
    )

    def validate(self, where: str = "camera") -> None:
        norm = math.sqrt(sum(v * v for v in self.forward))
        if abs(norm - 1.0) > 1e-6:
            raise ConfigError(f"{where}.forward = {list(self.forward)}: must be a unit vector")

    def model(self, mount_height_m: float) -> CameraModel:
        """The calibrated `CameraModel` of this camera at the given mounting height."""
        return CameraModel.from_fov(
            self.width,
            self.height,
            self.vfov_deg,
            forward=self.forward,
            mount_height_m=mount_height_m,
        )


@dataclass(frozen=True)
class ConditionSegment:
    """A stretch of the drive with reduced visibility; it fades in and out over ``ramp_s``."""

    kind: str = param("fog", choices=("fog", "night", "tunnel"), help="what removes the texture")
    start_s: float = param(0.0, unit="s", ge=0.0, help="start of the segment")
    end_s: float = param(10.0, unit="s", gt=0.0, help="end of the segment")
    fog_density_per_m: float = param(
        0.08,
        unit="1/m",
        ge=0.0,
        le=1.0,
        help="Koschmieder extinction; 0.08/m = about 37 m meteorological visibility",
    )
    light: float = param(
        0.001,
        ge=0.0,
        le=1.0,
        help="scene light at night, a fraction of daylight (street-lit night ~ 0.001)",
    )
    ramp_s: float = param(1.5, unit="s", ge=0.0, le=30.0, help="fade in/out (a tunnel: 0)")

    def validate(self, where: str = "condition") -> None:
        if self.end_s <= self.start_s:
            raise ConfigError(
                f"{where}.end_s = {self.end_s}: must be after start_s = {self.start_s}"
            )


@dataclass(frozen=True)
class OutputSpec:
    """Which files a recording gets."""

    video: bool = param(True, help="video.mp4 through cv2.VideoWriter")
    video_fourcc: str = param("mp4v", help="codec of video.mp4 (OpenCV's FFmpeg backend)")
    can_formats: list[str] = param(  # noqa: RUF009 - param() wraps dataclasses.field
        default_factory=lambda: ["blf"], help="CAN log formats: blf, asc, log (candump)"
    )
    imu_csv: bool = param(True, help="imu.csv, smartphone style")
    masks: bool = param(False, help="per-frame vehicle masks as 16-bit PNG (for tests)")

    def validate(self, where: str = "output") -> None:
        bad = [f for f in self.can_formats if f not in ("blf", "asc", "log")]
        if bad:
            raise ConfigError(f"{where}.can_formats: unknown format(s) {bad}; use blf, asc, log")
        if len(self.video_fourcc) != 4:
            raise ConfigError(f"{where}.video_fourcc = {self.video_fourcc!r}: four characters")


#: road beyond the lead's last position: what the camera sees ahead of it (as the presets)
ROAD_MARGIN_M = 120.0
#: the longest road `RoadConfig` accepts (``road.length_m``), m
MAX_ROAD_M = 100_000.0


@dataclass(frozen=True)
class ScenarioConfig:
    """Everything that defines a simulated recording, with its seed."""

    name: str = param("custom", help="preset or scenario name (for reports)")
    seed: int = param(0, ge=0, help="one seed for the whole drive (spawned per part)")
    motion: MotionConfig = field(default_factory=MotionConfig)
    camera: CameraSpec = field(default_factory=CameraSpec)
    render: RenderConfig = field(default_factory=RenderConfig)
    scene: SceneConfig = field(default_factory=SceneConfig)
    imu_preset: str = param(
        "smartphone",
        choices=(*IMU_PRESETS, "custom"),
        help="IMU grade; 'custom' uses [imu] as given",
    )
    imu: ImuConfig | None = None
    speed: SpeedSensorConfig = field(default_factory=SpeedSensorConfig)
    conditions: list[ConditionSegment] = field(default_factory=list)
    output: OutputSpec = field(default_factory=OutputSpec)

    def validate(self, where: str = "") -> None:
        p = f"{where}." if where else ""
        if not where:  # built in code rather than loaded: check the parts as a file would be
            configtools.check_ranges(self)
            self.motion.validate("motion")
            self.camera.validate("camera")
            self.output.validate("output")
        if self.imu_preset == "custom" and self.imu is None:
            raise ConfigError(f"{p}imu: imu_preset = 'custom' needs an [imu] table")
        if self.imu_preset != "custom" and self.imu is not None:
            raise ConfigError(
                f"{p}imu: an [imu] table is only used with imu_preset = 'custom' "
                f"(got imu_preset = {self.imu_preset!r})"
            )
        for i, seg in enumerate(self.conditions):
            configtools.check_ranges(seg, f"{p}conditions[{i}]")
            seg.validate(f"{p}conditions[{i}]")
            if seg.start_s >= self.motion.duration_s:
                raise ConfigError(
                    f"{p}conditions[{i}].start_s = {seg.start_s}: after the end of the drive "
                    f"({self.motion.duration_s} s)"
                )

    # -- derived ------------------------------------------------------------------
    def with_duration(self, duration_s: float) -> ScenarioConfig:
        """This scenario for ``duration_s`` seconds: condition segments that begin after the
        end dropped, and the road lengthened (never shortened) so that the lead stays on
        it to the end (`road_for_drive`). Random anomalies (``anomaly_density_per_km``)
        spread over the longer road; explicit ones stay where they are."""
        cfg = replace(
            self,
            motion=replace(self.motion, duration_s=duration_s),
            conditions=[c for c in self.conditions if c.start_s < duration_s],
        )
        return cfg.road_for_drive()

    def road_for_drive(self) -> ScenarioConfig:
        """This scenario with a road at least `ROAD_MARGIN_M` beyond the point the lead's
        front wheels reach at the end of the drive (its speed plan, gap plan and
        manoeuvres); itself when the road is long enough. ConfigError for a drive that
        is infeasible for another reason, or longer than the longest road."""
        m = self.motion
        probe = replace(m, road=replace(m.road, length_m=math.inf))
        kin = _kinematics(probe, "motion")
        reach = float(kin.x_lead[-1]) + m.lead.cg_to_front_axle_m + m.lead.wheel_radius_m
        needed = math.ceil(reach + ROAD_MARGIN_M)
        if needed <= m.road.length_m:
            return self
        if needed > MAX_ROAD_M:
            raise ConfigError(
                f"motion.duration_s = {m.duration_s} s: the lead would drive to X = "
                f"{reach:.0f} m, beyond the longest road ({MAX_ROAD_M:.0f} m); shorten the drive"
            )
        road = replace(m.road, length_m=float(needed))
        return replace(self, motion=replace(m, road=road))

    @property
    def imu_config(self) -> ImuConfig:
        """The IMU's configuration (preset or custom)."""
        if self.imu_preset == "custom":
            assert self.imu is not None
            return self.imu
        return IMU_PRESETS[self.imu_preset]()

    def camera_model(self) -> CameraModel:
        return self.camera.model(self.motion.camera_height_m)

    def frame_times(self) -> NDArray[np.float64]:
        """Exposure times of the video frames (s), within the simulated span."""
        n = math.floor(self.motion.duration_s * self.camera.fps + 1e-9)
        return np.arange(n, dtype=np.float64) / self.camera.fps

    def visibility(
        self, t: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
        """(fog density 1/m, light factor, tunnel flag) at times ``t``, segments faded in/out."""
        tt = np.atleast_1d(np.asarray(t, dtype=np.float64))
        fog = np.zeros_like(tt)
        light = np.ones_like(tt)
        tunnel = np.zeros(tt.shape, dtype=bool)
        for seg in self.conditions:  # a handful of segments, not samples
            if seg.ramp_s > 0:
                w = np.clip(
                    np.minimum(tt - seg.start_s, seg.end_s - tt) / seg.ramp_s + 0.5, 0.0, 1.0
                )
            else:
                w = ((tt >= seg.start_s) & (tt < seg.end_s)).astype(np.float64)
            if seg.kind == "fog":
                fog = np.maximum(fog, w * seg.fog_density_per_m)
            elif seg.kind == "night":
                light = np.minimum(light, 1.0 - w * (1.0 - seg.light))
            else:
                tunnel |= (tt >= seg.start_s) & (tt < seg.end_s)
        return fog, light, tunnel

    # -- files --------------------------------------------------------------------
    @classmethod
    def load(cls, path: str | Path) -> ScenarioConfig:
        """Read ``scenario.toml``; errors name the file and the field."""
        return configtools.load(cls, path)

    def save(self, path: str | Path) -> None:
        configtools.save(self, path)
