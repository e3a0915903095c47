"""The run loop's frame hold (`roadpreview.loop.hold_frames`, ``[fusion] frame_hold_s``): a
camera frame goes into the pipeline after the IMU samples of its instant, so that it is
fused and compensated on the gyro (committed), not on a bridged guess."""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import replace

import numpy as np
import pytest

from roadpreview.camera import CameraModel
from roadpreview.loop import hold_frames
from roadpreview.pipeline import Pipeline, PipelineConfig
from roadpreview.pipeline.pipeline import HOLD_STEP_S
from roadpreview.types import CameraFrame, ImuSample, Sample


def _imu(t: float) -> ImuSample:
    return ImuSample(t_s=t, rates_rad_s=(0.0, 0.0, 0.0), accel_m_s2=(0.0, 0.0, 9.81))


def _frame(t: float) -> CameraFrame:
    return CameraFrame(t_s=t, image=None)


def _stream(t_end: float = 1.0, imu_lag_s: float = 0.03) -> list[Sample]:
    """30 fps frames and 100 Hz IMU samples whose stamps lag the frames' clock by
    ``imu_lag_s`` (the sample for instant t is stamped t + lag), in stamp order."""
    out: list[Sample] = [_frame(float(t)) for t in np.arange(0.0, t_end, 1 / 30)]
    out += [_imu(float(t) + imu_lag_s) for t in np.arange(0.0, t_end, 0.01)]
    return sorted(out, key=lambda s: (s.t_s, isinstance(s, CameraFrame)))


@pytest.mark.parametrize("hold", [0.0, 0.04, 0.1])
def test_each_frame_comes_after_the_samples_stamped_up_to_its_hold(hold: float) -> None:
    out = list(hold_frames(_stream(), lambda: hold))

    def key(s: Sample) -> tuple[str, float]:
        return (type(s).__name__, s.t_s)

    assert sorted(map(key, out)) == sorted(map(key, _stream()))  # nothing lost or added
    frames = [i for i, s in enumerate(out) if isinstance(s, CameraFrame)]
    assert [out[i].t_s for i in frames] == sorted(out[i].t_s for i in frames)  # in order
    for i in frames:
        t = out[i].t_s
        before = [s.t_s for s in out[:i] if isinstance(s, ImuSample)]
        after = [s.t_s for s in out[i + 1 :] if isinstance(s, ImuSample)]
        assert all(ts > t + hold for ts in after)  # every sample up to t + hold is in
        assert all(ts <= t + hold + 1e-12 for ts in before)  # and none later


def test_a_changing_hold_never_reorders_frames_and_the_end_flushes() -> None:
    holds = iter([0.1, 0.0, 0.05] * 20)
    out = list(hold_frames(_stream(0.5), lambda: next(holds)))
    frames = [s.t_s for s in out if isinstance(s, CameraFrame)]
    assert frames == sorted(frames)
    assert len(frames) == 15
    assert isinstance(out[-1], CameraFrame) or out[-1].t_s >= frames[-1]


def test_without_an_imu_frames_are_delayed_by_the_hold_only() -> None:
    """Camera only: a frame goes out when a frame stamped a hold later arrives."""
    frames = [_frame(t) for t in np.arange(0.0, 1.0, 0.1)]
    out = list(hold_frames(frames, lambda: 0.25))
    assert [s.t_s for s in out] == [s.t_s for s in frames]


def test_the_pipeline_holds_for_its_estimated_offset() -> None:
    """Before the offset is known: the configured most; after: the offset + the margin,
    reached in steps of HOLD_STEP_S a frame. Off by default (0: no hold)."""
    default = Pipeline(CameraModel.from_fov(640, 360, 54.0), PipelineConfig())
    assert default.frame_hold_s() == 0.0
    base = PipelineConfig()
    cfg = replace(base, fusion=replace(base.fusion, frame_hold_s=0.12))
    pipe = Pipeline(CameraModel.from_fov(640, 360, 54.0), cfg)
    assert pipe.frame_hold_s() == pytest.approx(cfg.fusion.frame_hold_s)
    r = pipe.push(_frame(0.0))
    assert r is not None
    object.__setattr__(r, "time_offset", 0.031)
    target = 0.031 + cfg.fusion.frame_hold_margin_s
    holds = [pipe.frame_hold_s() for _ in range(30)]  # shrinking by HOLD_STEP_S a frame
    assert holds[0] == pytest.approx(cfg.fusion.frame_hold_s - HOLD_STEP_S)
    assert np.all(np.diff(holds) >= -HOLD_STEP_S - 1e-12)
    assert holds[-1] == pytest.approx(target)
    object.__setattr__(r, "time_offset", 0.5)
    assert pipe.frame_hold_s() == pytest.approx(cfg.fusion.frame_hold_s)
    object.__setattr__(r, "time_offset", math.nan)
    assert pipe.frame_hold_s() == pytest.approx(cfg.fusion.frame_hold_s)


def test_frames_held_when_the_input_fails_come_out_before_the_failure() -> None:
    def failing() -> Iterator[Sample]:
        yield _frame(0.0)
        yield _frame(0.1)
        raise ValueError("the source died")

    it = hold_frames(failing(), lambda: 0.5)
    assert [s.t_s for s in (next(it), next(it))] == [0.0, 0.1]
    with pytest.raises(ValueError, match="died"):
        next(it)
    # a generator closed by its consumer while frames are held closes cleanly
    it2 = hold_frames(_stream(), lambda: 0.5)
    next(it2)
    it2.close()
