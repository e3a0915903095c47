"""Test utilities for the fusion: simulated drives, the vision front end's measurements, replay.

The simulator gives the truth (camera pitch at frame times, visibility) and a
smartphone-grade IMU: either the recording's own ``imu.csv`` (`sim_drive`, the
file a replay reads) or fresh `simulate_imu` realisations on one simulated
motion (`imu_realisations`, for statistics over sensor noise, bias walk and
clock offset). `synthetic_drive` needs no simulator (a few sines, an exact
gyro with bias and noise) for the stream-level tests. The vision front end is
not run (no video is rendered); `front_end_measurements` produces what it
would deliver:

* relative pitch against a key frame renewed every ``key_every_s`` (2 s): the
  frame that becomes the new key is still measured against the old key, the
  frames after it against the new one;
* Gaussian noise of ``std_deg`` = 0.005 deg per measurement (the middle of the
  0.003-0.01 deg the robust estimator reports at 720p with ~1000 background
  points), reported as the measurement's std, inlier ratio 0.8;
* a vision failure where the truth says the texture is gone: fog denser than
  0.03 /m (meteorological visibility below 100 m), light below 5 % of daylight,
  or inside a tunnel. The first good frame after a failure becomes a new key
  (it has no measurement of its own).

`replay` feeds a back end in arrival order: a gyro sample arrives at its stamp
(the logger's clock, which lags the truth by the IMU's time offset), a frame's
visual result and the estimate for it ``latency_s`` after the exposure.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from roadpreview.fusion import PitchFusion, VisualPitch
from roadpreview.sim.canlog import read_imu_csv
from roadpreview.sim.recording import Recording
from roadpreview.types import FusionMode

DEG = math.pi / 180.0
FOG_LIMIT_PER_M = 0.03
LIGHT_LIMIT = 0.05


@dataclass(frozen=True)
class Drive:
    """A simulated drive as the fusion sees it, with the truth."""

    rec: Recording | None  #: the recording folder (None for a fresh IMU realisation)
    frame_t: np.ndarray  #: frame times (camera clock), s
    pitch: np.ndarray  #: true camera pitch relative to the first frame, rad
    texture: np.ndarray  #: truth: vision has texture at the frame (bool)
    reason: list[str]  #: why the texture is gone ("" where it is not)
    imu_t: np.ndarray  #: IMU stamps (IMU clock), s
    imu_rate: np.ndarray  #: measured pitch rate (nose up +), rad/s
    imu_bias: np.ndarray  #: true pitch-rate bias in each sample, rad/s
    time_offset_s: float  #: simulator's IMU stamp minus true time


def _texture(truth: dict[str, np.ndarray]) -> tuple[np.ndarray, list[str]]:
    fog = truth["fog_density_per_m"] > FOG_LIMIT_PER_M
    dark = truth["light"] < LIGHT_LIMIT
    tunnel = truth["tunnel"].astype(bool)
    reason = [
        "tunnel" if tu else "fog" if fo else "night" if da else ""
        for fo, da, tu in zip(fog, dark, tunnel, strict=True)
    ]
    return ~(fog | dark | tunnel), reason


def open_drive(rec: Recording) -> Drive:
    truth = rec.truth
    imu = read_imu_csv(rec.folder / "imu.csv")
    texture, reason = _texture(truth)
    return Drive(
        rec=rec,
        frame_t=truth["frame_t_s"],
        pitch=truth["cam_pitch_rad"] - truth["cam_pitch_rad"][0],
        texture=texture,
        reason=reason,
        imu_t=imu.t_s,
        imu_rate=imu.rates_rad_s[:, 1],
        # the truth stores the sensor-axis bias; the pitch rate is -omega_y (sim.imu)
        imu_bias=-truth["imu_gyro_bias_rad_s"][:, 1],
        time_offset_s=float(rec.info["imu_time_offset_s"]),
    )


@pytest.fixture(scope="session")
def sim_drive(tmp_path_factory: pytest.TempPathFactory) -> Callable[..., Drive]:
    """Factory ``sim_drive(preset, seed=0, duration_s=60, pitch_bias_deg_s=0.5) -> Drive``.

    A smartphone-grade IMU as in the preset (its random 0-80 ms clock offset
    for ``wild`` and ``texture-loss``), with the pitch-rate bias fixed to
    ``pitch_bias_deg_s`` (the issue's 0.5 deg/s; the preset draws a random
    one) plus the preset's random walk. No video: nothing is rendered.
    Cached per session.
    """
    from roadpreview.sim.dataset import drive_config
    from roadpreview.sim.recording import write_recording

    root = tmp_path_factory.mktemp("fusion-drives")
    cache: dict[tuple[Any, ...], Drive] = {}

    def make(
        preset: str = "texture-loss",
        *,
        seed: int = 0,
        duration_s: float = 60.0,
        pitch_bias_deg_s: float | None = 0.5,
    ) -> Drive:
        key = (preset, seed, duration_s, pitch_bias_deg_s)
        if key not in cache:
            cfg = drive_config(preset, seed, duration_s=duration_s, width=640, height=360)
            if pitch_bias_deg_s is not None:
                imu = replace(
                    cfg.imu_config,
                    gyro_bias=(0.0, -pitch_bias_deg_s * DEG, 0.0),  # pitch rate = -omega_y
                    gyro_bias_std=0.0,
                )
                cfg = replace(cfg, imu_preset="custom", imu=imu)
            cfg = replace(cfg, output=replace(cfg.output, video=False, can_formats=[]))
            folder = Path(root) / f"{preset}-{seed}-{len(cache)}"
            write_recording(cfg, folder)
            cache[key] = open_drive(Recording.open(folder))
        return cache[key]

    return make


_MOTIONS: dict[tuple[Any, ...], Any] = {}


def make_imu_realisations(
    preset: str,
    seed: int,
    imu_seeds: list[int],
    *,
    duration_s: float = 60.0,
    grade: str = "smartphone",
    pitch_bias_deg_s: float = 0.5,
) -> list[Drive]:
    """One simulated motion, one IMU realisation per seed in ``imu_seeds`` (its own noise,
    bias walk and 0-80 ms clock offset, as the ``wild`` presets draw it). ``grade`` is
    "smartphone" (`ImuConfig.smartphone`) or "automotive" (`ImuConfig.automotive`); the
    pitch-rate bias is fixed to ``pitch_bias_deg_s`` either way."""
    from roadpreview.sim.dataset import drive_config
    from roadpreview.sim.imu import ImuConfig, simulate_imu
    from roadpreview.sim.motion import simulate_motion

    key = (preset, seed, duration_s)
    if key not in _MOTIONS:
        cfg = drive_config(preset, seed, duration_s=duration_s)
        _MOTIONS[key] = (cfg, simulate_motion(cfg.motion, np.random.default_rng([seed, 1])))
    cfg, motion = _MOTIONS[key]
    ego = motion.ego
    omega = np.column_stack([ego.roll_rate, ego.pitch_rate, ego.yaw_rate])
    attitude = np.column_stack([ego.roll, ego.pitch, ego.yaw])
    frame_t = cfg.frame_times()
    pitch = motion.camera_track(frame_t).pitch
    fog, light, tunnel = cfg.visibility(frame_t)
    texture, reason = _texture({"fog_density_per_m": fog, "light": light, "tunnel": tunnel})
    drives = []
    for imu_seed in imu_seeds:
        rng = np.random.default_rng([seed, 2, imu_seed])
        offset = round(float(rng.uniform(0.0, 0.08)), 4)
        base = ImuConfig.smartphone() if grade == "smartphone" else ImuConfig.automotive()
        imu_cfg = replace(
            base,
            gyro_bias=(0.0, -pitch_bias_deg_s * DEG, 0.0),  # pitch rate = -omega_y
            gyro_bias_std=0.0,
            time_offset_s=offset,
        )
        imu = simulate_imu(ego.t, omega, ego.accel_world, attitude, imu_cfg, rng)
        drives.append(
            Drive(
                rec=None,
                frame_t=frame_t,
                pitch=pitch - pitch[0],
                texture=texture,
                reason=reason,
                imu_t=imu.t_stamp_s,
                imu_rate=imu.rates_rad_s[:, 1],
                imu_bias=-imu.gyro_bias_rad_s[:, 1],
                time_offset_s=offset,
            )
        )
    return drives


def synthetic_drive(
    duration_s: float = 20.0,
    *,
    seed: int = 0,
    offset_s: float = 0.03,
    bias_deg_s: float = 0.5,
    gyro_noise_deg_s: float = 0.1,
    loss: tuple[tuple[float, float], ...] = (),
    imu_gaps: tuple[tuple[float, float], ...] = (),
) -> Drive:
    """A drive without the simulator: camera pitch of a few sines (±1 deg, 0.3-2.5 Hz),
    a 100 Hz gyro of interval means with bias, white noise and stamps ``offset_s`` late,
    30 Hz frames; texture lost in the ``loss`` intervals, no gyro in ``imu_gaps``."""
    rng = np.random.default_rng(seed)
    freq = np.array([0.3, 0.7, 1.3, 1.9, 2.5])
    amp = rng.uniform(0.1, 0.3, freq.size) * DEG
    phase = rng.uniform(0, 2 * np.pi, freq.size)

    def pitch(t: np.ndarray) -> np.ndarray:
        summed: np.ndarray = np.sum(amp * np.sin(2 * np.pi * freq * t[:, None] + phase), axis=1)
        return summed

    tt = np.arange(1, int(duration_s * 100) + 1) / 100.0
    rate = (pitch(tt) - pitch(tt - 0.01)) * 100.0 + bias_deg_s * DEG
    rate = rate + gyro_noise_deg_s * DEG * rng.standard_normal(tt.size)
    keep = np.ones(tt.size, dtype=bool)
    for a, b in imu_gaps:
        keep &= ~((tt >= a) & (tt < b))
    frames = np.arange(int(duration_s * 30)) / 30.0
    texture = np.ones(frames.size, dtype=bool)
    for a, b in loss:
        texture &= ~((frames >= a) & (frames < b))
    p = pitch(frames)
    return Drive(
        rec=None,
        frame_t=frames,
        pitch=p - p[0],
        texture=texture,
        reason=["" if ok else "tunnel" for ok in texture],
        imu_t=tt[keep] + offset_s,
        imu_rate=rate[keep],
        imu_bias=np.full(int(keep.sum()), bias_deg_s * DEG),
        time_offset_s=offset_s,
    )


@pytest.fixture(scope="session")
def imu_realisations() -> Callable[..., list[Drive]]:
    """`make_imu_realisations` (motions cached per session)."""
    return make_imu_realisations


@dataclass(frozen=True)
class FrontEnd:
    """What the vision front end delivers per frame: a measurement or a failure reason."""

    frame_t: np.ndarray
    meas: list[VisualPitch | None]
    failure: list[str]  #: "" where there is a measurement or a new key


def front_end_measurements(
    drive: Drive,
    *,
    std_deg: float = 0.005,
    key_every_s: float = 2.0,
    seed: int = 0,
    outliers: dict[int, float] | None = None,
) -> FrontEnd:
    """The vision front end's output for ``drive`` (module docstring); ``outliers`` adds
    gross errors (frame index -> added rad)."""
    rng = np.random.default_rng(seed)
    std = std_deg * DEG
    t, p = drive.frame_t, drive.pitch
    meas: list[VisualPitch | None] = []
    failure: list[str] = []
    key = -1
    for i in range(t.size):  # frames, not points
        if not drive.texture[i]:
            meas.append(None)
            failure.append(drive.reason[i])
            key = -1
            continue
        if key < 0:  # first good frame: the new key
            key = i
            meas.append(None)
            failure.append("")
            continue
        dphi = p[i] - p[key] + std * rng.standard_normal()
        if outliers and i in outliers:
            dphi += outliers[i]
        meas.append(VisualPitch(float(t[key]), float(t[i]), float(dphi), std, 0.8, True))
        failure.append("")
        if t[i] - t[key] >= key_every_s - 1e-9:
            key = i
    return FrontEnd(frame_t=t, meas=meas, failure=failure)


@dataclass
class Replay:
    """The back end's outputs at every frame."""

    t: np.ndarray
    phi: np.ndarray
    std: np.ndarray
    mode: np.ndarray
    bias: np.ndarray
    offset: np.ndarray
    offset_conf: np.ndarray

    def error_deg(self, drive: Drive) -> np.ndarray:
        err: np.ndarray = np.degrees(self.phi - drive.pitch)
        return err


def replay(
    fusion: PitchFusion,
    drive: Drive,
    fe: FrontEnd,
    *,
    latency_s: float = 0.1,
    imu_t: np.ndarray | None = None,
    imu_rate: np.ndarray | None = None,
) -> Replay:
    """Feed ``fusion`` in arrival order (module docstring) and collect its outputs."""
    gt = drive.imu_t if imu_t is None else imu_t
    gr = drive.imu_rate if imu_rate is None else imu_rate
    ft = fe.frame_t
    n = ft.size
    out = {k: np.empty(n) for k in ("phi", "std", "mode", "bias", "offset", "offset_conf")}
    j = 0
    for i in range(n):  # events, in arrival order
        arrival = ft[i] + latency_s
        while j < gt.size and gt[j] <= arrival:
            fusion.push_gyro(float(gt[j]), float(gr[j]))
            j += 1
        m = fe.meas[i]
        if m is not None:
            fusion.push_visual(m)
        elif fe.failure[i]:
            fusion.push_vision_failure(float(ft[i]), fe.failure[i])
        r = fusion.estimate(float(ft[i]))
        out["phi"][i] = r.phi
        out["std"][i] = r.std
        out["mode"][i] = int(r.mode)
        out["bias"][i] = r.bias
        out["offset"][i] = r.time_offset
        out["offset_conf"][i] = r.time_offset_confidence
    return Replay(t=ft.copy(), **out)


def windowed_rms_deg(
    err_deg: np.ndarray,
    t: np.ndarray,
    mask: np.ndarray,
    window_s: float = 1.0,
    demean: bool = False,
) -> np.ndarray:
    """RMS of the error in consecutive ``window_s`` windows wholly inside ``mask``."""
    out = []
    edges = np.arange(t[0], t[-1], window_s)
    for a in edges:  # windows, a few dozen
        w = (t >= a) & (t < a + window_s)
        if w.sum() < 5 or not mask[w].all():
            continue
        e = err_deg[w] - (err_deg[w].mean() if demean else 0.0)
        out.append(float(np.sqrt(np.mean(e**2))))
    return np.asarray(out)


def segments(flag: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) index pairs of the runs where ``flag`` is True."""
    f = np.concatenate([[False], flag.astype(bool), [False]])
    d = np.flatnonzero(np.diff(f.astype(int)))
    return [(int(a), int(b)) for a, b in zip(d[::2], d[1::2], strict=True)]


@dataclass(frozen=True)
class FusionTestKit:
    """The helpers above, handed to tests as one fixture."""

    front_end: Callable[..., FrontEnd] = front_end_measurements
    replay: Callable[..., Replay] = replay
    synthetic: Callable[..., Drive] = synthetic_drive
    windowed_rms_deg: Callable[..., np.ndarray] = windowed_rms_deg
    segments: Callable[[np.ndarray], list[tuple[int, int]]] = segments
    FUSED: int = int(FusionMode.FUSED)
    IMU_ONLY: int = int(FusionMode.IMU_ONLY)
    VISUAL_ONLY: int = int(FusionMode.VISUAL_ONLY)
    DEGRADED: int = int(FusionMode.DEGRADED)


@pytest.fixture(scope="session")
def kit() -> FusionTestKit:
    """The fusion test helpers (front end, replay, windowed RMS, segments)."""
    return FusionTestKit()
