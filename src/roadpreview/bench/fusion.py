"""``roadpreview bench fusion``: IMU samples per second through each fusion back end.

A synthetic drive (seeded): camera pitch of a car on a rough road (a few
sines from 0.3 to 2.5 Hz, ±1 deg) with 100 Hz gyro samples (interval means,
0.5 deg/s bias, 0.015 deg/s/√Hz noise, stamps 30 ms late) and a 30 Hz camera
whose visual pitch is relative to key frames renewed every 2 s (0.005 deg
noise), with a 2 s texture loss every 20 s. Events are pushed in arrival
order (a frame's result 50 ms after its exposure) and every frame is
estimated, as in the pipeline. Reported: the median wall time over repeats,
IMU samples per second, the real-time factor (drive seconds per wall second)
and the RMS error against the synthetic truth (a check that the run did the
work, not an accuracy benchmark).
"""

from __future__ import annotations

import math
from functools import partial

import numpy as np
from numpy.typing import NDArray

from roadpreview.bench._timing import format_table, median_seconds
from roadpreview.fusion import BACKENDS, VisualPitch, make_fusion

DEG = math.pi / 180.0
IMU_HZ = 100.0
CAMERA_HZ = 30.0
TARGETS = {"kalman": "≥ 100k samples/s", "factor-graph": "≥ 20x real time"}

_Events = list[tuple[float, int, tuple[float, ...]]]


def _pitch(
    t: NDArray[np.float64],
    amp: NDArray[np.float64],
    freq: NDArray[np.float64],
    phase: NDArray[np.float64],
) -> NDArray[np.float64]:
    out: NDArray[np.float64] = np.sum(amp * np.sin(2 * np.pi * freq * t[:, None] + phase), axis=1)
    return out


def synthetic_drive(
    duration_s: float, seed: int, *, camera_hz: float = CAMERA_HZ
) -> tuple[_Events, NDArray[np.float64], NDArray[np.float64]]:
    """Events in arrival order (time; kind 0 gyro, 1 visual, 2 vision failure, 3 estimate;
    payload), the frame times and the true pitch relative to the first frame."""
    rng = np.random.default_rng(seed)
    freq = np.array([0.3, 0.7, 1.3, 1.9, 2.5])
    amp = rng.uniform(0.1, 0.3, freq.size) * DEG
    phase = rng.uniform(0, 2 * np.pi, freq.size)
    # gyro: interval means of the rate = difference of the pitch over the interval
    t_true = np.arange(1, int(duration_s * IMU_HZ) + 1) / IMU_HZ
    p_end = _pitch(t_true, amp, freq, phase)
    p_start = _pitch(t_true - 1 / IMU_HZ, amp, freq, phase)
    rate = (p_end - p_start) * IMU_HZ + 0.5 * DEG
    rate += 0.015 * DEG * math.sqrt(IMU_HZ / 2) * rng.standard_normal(t_true.size)
    stamps = t_true + 0.030
    frames = np.arange(int(duration_s * camera_hz)) / camera_hz
    truth = _pitch(frames, amp, freq, phase)
    truth -= truth[0]
    events: _Events = [
        (float(s), 0, (float(s), float(w))) for s, w in zip(stamps, rate, strict=True)
    ]
    key = 0
    for i in range(1, frames.size):  # frames, not samples
        t = float(frames[i])
        arrival = t + 0.05
        if 10.0 <= t % 20.0 < 12.0:  # texture loss
            events.append((arrival, 2, (t,)))
            key = -1
            continue
        if key < 0:
            key = i
            continue
        dphi = truth[i] - truth[key] + 0.005 * DEG * rng.standard_normal()
        events.append((arrival, 1, (float(frames[key]), t, float(dphi))))
        if t - frames[key] >= 2.0 - 1e-9:
            key = i
    for i in range(1, frames.size):
        events.append((float(frames[i]) + 0.05 + 1e-9, 3, (float(frames[i]),)))
    events.sort(key=lambda e: (e[0], e[1]))
    return events, frames, truth


def _run_backend(name: str, events: _Events) -> NDArray[np.float64]:
    fusion = make_fusion(name)
    push_gyro, push_visual = fusion.push_gyro, fusion.push_visual
    fail, estimate = fusion.push_vision_failure, fusion.estimate
    out = [estimate(0.0).phi]
    std = 0.005 * DEG
    for _, kind, p in events:  # the stream, one event at a time as in the product
        if kind == 0:
            push_gyro(p[0], p[1])
        elif kind == 1:
            push_visual(VisualPitch(p[0], p[1], p[2], std, 0.8, True))
        elif kind == 2:
            fail(p[0], "texture")
        else:
            out.append(estimate(p[0]).phi)
    return np.asarray(out)


def run(repeats: int | None = None, quick: bool = False, seed: int = 0) -> str:
    repeats = repeats or (1 if quick else 3)
    duration = 20.0 if quick else 60.0
    events, _, truth = synthetic_drive(duration, seed)
    n_imu = sum(1 for e in events if e[1] == 0)
    rows: list[list[str]] = []
    for name in BACKENDS:
        seconds = median_seconds(partial(_run_backend, name, events), repeats)
        phi = _run_backend(name, events)
        rms = float(np.degrees(np.sqrt(np.mean((phi - truth) ** 2))))
        rows.append(
            [
                name,
                f"{seconds * 1e3:.1f}",
                f"{n_imu / seconds:,.0f}",
                f"{duration / seconds:,.0f}x",
                f"{rms:.3f}",
                TARGETS.get(name, ""),
            ]
        )
    header = ["back end", "wall ms", "IMU samples/s", "real time", "RMS deg", "target"]
    title = (
        f"fusion: {duration:.0f} s drive, {IMU_HZ:.0f} Hz IMU ({n_imu} samples) +"
        f" {CAMERA_HZ:.0f} Hz camera, median of {repeats} run(s)"
    )
    return title + "\n" + format_table(header, rows)
