"""Write a simulated drive to disk as a real recording with ground truth, and read it back.

One folder per drive (the format: `roadpreview.sources.recording`)::

    video.mp4          the camera, through cv2.VideoWriter (real compression artefacts)
    frames.csv         frame index -> time stamp (s, the simulation clock)
    can.blf / .asc / .log   IMU, vehicle speed and wheel speeds as CAN frames (data/roadpreview.dbc)
    imu.csv            the same IMU, smartphone style
    camera.toml        K, forward direction t, mounting height
    scenario.toml      every parameter and the seed: regenerates the drive bit for bit
    truth.npz          per frame: camera pose, lead box / rear centre / distance, visibility;
                       per IMU sample: true rates and bias
    truth.json         events (type, size, side, crossing times, hard flag), clocks, summary
    masks/NNNNNN.png   optional per-frame vehicle-id masks (16-bit PNG)

CAN logs are stamped in Unix time: simulation t = 0 is ``can_t0_unix_s`` in
``truth.json`` (python-can's writers need absolute times).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from threadpoolctl import threadpool_limits

from roadpreview.camera import CameraModel
from roadpreview.canbus import load_database
from roadpreview.errors import OperationError
from roadpreview.sim.canlog import DEFAULT_T0_UNIX_S, write_drive_can, write_imu_csv
from roadpreview.sim.imu import simulate_imu, simulate_speed
from roadpreview.sim.motion import DriveMotion, simulate_motion
from roadpreview.sim.render import SceneRenderer
from roadpreview.sim.scenario import ScenarioConfig
from roadpreview.sim.scene import generate_scene
from roadpreview.sim.types import Conditions
from roadpreview.sources.recording import RecordingFolder

log = logging.getLogger(__name__)

TRUTH_VERSION = 1


@dataclass(frozen=True)
class RecordingInfo:
    """What `write_recording` wrote."""

    folder: Path
    n_frames: int
    n_imu_samples: int
    n_can_frames: int
    seconds: float


def _seeds(seed: int) -> dict[str, np.random.Generator]:
    """Independent generators per part, so that turning a part off changes no other."""
    parts = ("motion", "imu", "speed", "render")
    children = np.random.SeedSequence(seed).spawn(len(parts))
    return {p: np.random.default_rng(s) for p, s in zip(parts, children, strict=True)}


def _event_dict(e: Any) -> dict[str, Any]:
    out = dataclasses.asdict(e)
    return {k: (None if isinstance(v, float) and not np.isfinite(v) else v) for k, v in out.items()}


def write_recording(
    cfg: ScenarioConfig,
    folder: str | Path,
    *,
    progress: Callable[[int, int], None] | None = None,
) -> RecordingInfo:
    """Simulate ``cfg`` and write its recording into ``folder`` (created; files replaced).

    The same ``cfg`` gives the same bits in any process on one machine and library build:
    the simulation runs with one BLAS thread (a matrix product's kernel, and with it the
    last bit of the vehicle dynamics, depends on BLAS's thread count: a 1-thread Dask
    worker and a process with every core differed by 2e-17 in the IMU's true rates). Its
    matrices are small (state-space models of a few states), so one thread costs nothing.
    """
    with threadpool_limits(limits=1, user_api="blas"):
        return _write_recording(cfg, Path(folder), progress)


def _write_recording(
    cfg: ScenarioConfig, folder: Path, progress: Callable[[int, int], None] | None
) -> RecordingInfo:
    t_start = time.perf_counter()
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    rngs = _seeds(cfg.seed)
    drive = simulate_motion(cfg.motion, rngs["motion"])
    camera = cfg.camera_model()
    frame_t = cfg.frame_times()
    n = frame_t.size

    cfg.save(folder / "scenario.toml")
    camera.save(folder / "camera.toml")
    with (folder / "frames.csv").open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["frame", "t_s"])
        w.writerows((i, f"{t:.6f}") for i, t in enumerate(frame_t))

    frames_truth = _render_video(cfg, drive, camera, frame_t, folder, rngs["render"], progress)

    # IMU at the ego's CG: rates in our conventions, world acceleration, attitude
    ego = drive.ego
    omega = np.column_stack([ego.roll_rate, ego.pitch_rate, ego.yaw_rate])
    attitude = np.column_stack([ego.roll, ego.pitch, ego.yaw])
    imu = simulate_imu(ego.t, omega, ego.accel_world, attitude, cfg.imu_config, rngs["imu"])
    speed = simulate_speed(ego.t, ego.v, cfg.speed, rngs["speed"])
    db = load_database()
    n_can = 0
    for fmt in cfg.output.can_formats:
        n_can = write_drive_can(
            folder / f"can.{fmt}", imu, speed, db=db, t0_unix_s=DEFAULT_T0_UNIX_S
        )
    if cfg.output.imu_csv:
        write_imu_csv(folder / "imu.csv", imu)

    arrays: dict[str, Any] = dict(frames_truth)
    np.savez_compressed(
        folder / "truth.npz",
        **arrays,
        imu_t_stamp_s=imu.t_stamp_s,
        imu_t_true_s=imu.t_true_s,
        imu_true_rates_rad_s=imu.true_rates_rad_s,
        imu_gyro_bias_rad_s=imu.gyro_bias_rad_s,
        speed_t_stamp_s=speed.t_stamp_s,
        speed_true_m_s=speed.true_speed_m_s,
    )
    events = [_event_dict(e) for e in drive.events]
    summary = {
        "truth_version": TRUTH_VERSION,
        "scenario": cfg.name,
        "seed": cfg.seed,
        "n_frames": int(n),
        "fps": cfg.camera.fps,
        "duration_s": cfg.motion.duration_s,
        "can_t0_unix_s": DEFAULT_T0_UNIX_S,
        "imu_time_offset_s": cfg.imu_config.time_offset_s,
        "imu_rate_hz": cfg.imu_config.rate_hz,
        "imu_mount_ypr_deg": list(cfg.imu_config.mount_ypr_deg),
        "n_events": len(events),
        "n_lead_hits": sum(1 for e in drive.events if e.lead_hits),
        "n_hard": sum(1 for e in drive.events if e.hard),
        "events": events,
        "conditions": [dataclasses.asdict(c) for c in cfg.conditions],
    }
    (folder / "truth.json").write_text(json.dumps(summary, indent=2))
    return RecordingInfo(
        folder=folder,
        n_frames=int(n),
        n_imu_samples=len(imu),
        n_can_frames=n_can,
        seconds=time.perf_counter() - t_start,
    )


def _render_video(
    cfg: ScenarioConfig,
    drive: DriveMotion,
    camera: CameraModel,
    frame_t: NDArray[np.float64],
    folder: Path,
    rng: np.random.Generator,
    progress: Callable[[int, int], None] | None,
) -> dict[str, NDArray[Any]]:
    """Render every frame (writing the video) and collect the per-frame truth."""
    n = frame_t.size
    track = drive.camera_track(frame_t)
    cam_rate = np.interp(frame_t, drive.ego.t, drive.ego.pitch_rate)
    fog, light, tunnel = cfg.visibility(frame_t)
    lead_distance = drive.lead_distance(frame_t)
    lead_s = drive.lead.sample(frame_t)
    truth: dict[str, NDArray[Any]] = {
        "frame_t_s": frame_t,
        "cam_x_m": track.position[:, 0],
        "cam_y_m": track.position[:, 1],
        "cam_z_m": track.position[:, 2],
        "cam_pitch_rad": track.pitch,
        "cam_roll_rad": track.roll,
        "cam_yaw_rad": track.yaw,
        "cam_pitch_rate_rad_s": cam_rate,
        "lead_distance_m": lead_distance,
        "lead_pitch_rad": lead_s.pitch,
        "lead_heave_m": lead_s.heave,
        "ego_speed_m_s": np.interp(frame_t, drive.ego.t, drive.ego.v),
        "fog_density_per_m": fog,
        "light": light,
        "tunnel": tunnel,
        "lead_box_px": np.full((n, 4), np.nan),
        "lead_rear_px": np.full((n, 2), np.nan),
    }
    if not cfg.output.video and not cfg.output.masks:
        return truth
    scene = generate_scene(
        cfg.scene,
        seed=cfg.seed,
        length_m=cfg.motion.road.length_m,
        road_height=lambda x, y: float(drive.road.slow_height(x, y)),
    )
    renderer = SceneRenderer(camera, scene, cfg.render)
    writer = None
    if cfg.output.video:
        writer = cv2.VideoWriter(
            str(folder / "video.mp4"),
            cv2.VideoWriter.fourcc(*cfg.output.video_fourcc),
            cfg.camera.fps,
            camera.size,
        )
        if not writer.isOpened():
            raise OperationError(
                f"{folder / 'video.mp4'}: cv2.VideoWriter cannot open codec "
                f"{cfg.output.video_fourcc!r}"
            )
    if cfg.output.masks:
        (folder / "masks").mkdir(exist_ok=True)
    try:
        for i in range(n):  # frames, not pixels
            t = float(frame_t[i])
            cond = Conditions(
                fog_density_per_m=float(fog[i]), light=float(light[i]), tunnel=bool(tunnel[i])
            )
            frame = renderer.render(
                track.pose(i),
                drive.vehicles_at(t),
                cond,
                rng,
                pitch_rate_rad_s=float(cam_rate[i]),
            )
            if writer is not None:
                writer.write(frame.image)
            if cfg.output.masks:
                cv2.imwrite(
                    str(folder / "masks" / f"{i:06d}.png"), frame.vehicle_mask.astype(np.uint16)
                )
            if frame.lead_box is not None:
                truth["lead_box_px"][i] = frame.lead_box
            if frame.lead_rear_center_px is not None:
                truth["lead_rear_px"][i] = frame.lead_rear_center_px
            if progress is not None:
                progress(i + 1, n)
    finally:
        if writer is not None:
            writer.release()
    return truth


# -- reading ---------------------------------------------------------------------------------
class Recording(RecordingFolder):
    """A recording folder opened by the simulator's side: `RecordingFolder` (the format,
    `roadpreview.sources.recording`) plus the scenario as a `ScenarioConfig`."""

    @property
    def config(self) -> ScenarioConfig:
        """The scenario that made the drive (scenario.toml, checked)."""
        return ScenarioConfig.load(self.folder / "scenario.toml")
