"""Heave compensation on a simulator recording: the sign, the gain at an ego bump crossing,
and what happens without an accelerometer (docs/method.md, "Heave")."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import replace
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.signal import butter, sosfiltfilt

from roadpreview.apps.replay import ReplayInputs, replay
from roadpreview.canbus import load_database, read_can_log
from roadpreview.canbus.dbc import IMU_ACCEL
from roadpreview.fusion.heave import HeaveConfig
from roadpreview.loop import run
from roadpreview.pipeline import Pipeline, PipelineConfig
from roadpreview.pipeline.pipeline import FrameResult
from roadpreview.sim.recording import Recording
from roadpreview.sinks.files import ResultsSink
from roadpreview.sources.can import CanLogSource, make_decoder
from roadpreview.sources.video import VideoFileSource
from roadpreview.types import InputSample

pytestmark = pytest.mark.slow  # a simulated drive rendered and replayed: scheduled first

Array = NDArray[np.float64]

#: the demo drive's first bump: the ego's front wheels reach it at 7.78 s, the rear at 8.10 s
EGO_CROSSING = (7.9, 8.9)


@pytest.fixture(scope="module")
def demo10(make_recording: Callable[..., Recording]) -> Recording:
    return make_recording("demo", seed=0, duration_s=10.0, width=1280, height=720)


@pytest.fixture(scope="module")
def results(demo10: Recording) -> list[FrameResult]:
    out = replay(ReplayInputs.from_recording(demo10.folder), keep_results=True).results
    assert out is not None
    return out


def _column(results: list[FrameResult], name: str) -> Array:
    return np.array([getattr(r, name) for r in results], dtype=float)


def _window_spread(x: Array, n: int = 30, detrend: bool = False) -> Array:
    """The detector's s over the last n frames (std, or around the least-squares line)."""
    out = np.full(len(x), np.nan)
    k = np.arange(n, dtype=float)
    for i in range(n - 1, len(x)):
        w = x[i - n + 1 : i + 1]
        if np.isfinite(w).all():
            if detrend:
                w = w - np.polyval(np.polyfit(k, w, 1), k)
            out[i] = w.std()
    return out


def test_a_rising_camera_is_taken_out_of_the_lead_trajectory(
    demo10: Recording, results: list[FrameResult]
) -> None:
    """Around the ego's bump crossing, with the TRUE pitch removed (so that only the heave is
    left to compensate), subtracting our heave term shrinks the detector's s (detrended, as
    it runs by default) by more than 40 % (measured: 1.58 -> 0.60 px); adding it instead
    (the wrong sign) makes it 50 % larger (3.07 px). The paper's plain std shrinks by
    20 % (2.23 -> 1.45 px). The pipeline's own y_c, with the fused pitch, gains less
    (1.21 -> 0.98 px): the residual of the pitch compensation remains."""
    f = demo10.camera.fy
    t = _column(results, "t") - _column(results, "t")[0]
    y, hpx = _column(results, "y"), _column(results, "heave_px")
    true_pitch = demo10.truth["cam_pitch_rad"] - demo10.truth["cam_pitch_rad"][0]
    y_true_c = y - f * np.tan(true_pitch)
    sel = (t > EGO_CROSSING[0]) & (t < EGO_CROSSING[1])

    def s(x: Array, detrend: bool = True) -> float:
        return float(np.nanmax(_window_spread(x, detrend=detrend)[sel]))

    assert s(y_true_c) > 1.2  # the heave is visible: more than the 1 px threshold
    assert s(y_true_c - hpx) < 0.6 * s(y_true_c)
    assert s(y_true_c + hpx) > 1.5 * s(y_true_c)
    assert s(y_true_c - hpx, detrend=False) < 0.8 * s(y_true_c, detrend=False)
    y_c = _column(results, "y_c")
    assert s(y_c) < 0.9 * s(y_c + hpx)  # with vs without the heave term


def test_the_egos_own_bump_is_invisible_in_y_c(
    demo10: Recording, results: list[FrameResult]
) -> None:
    """E2's measure on a short simulated crossing: while the ego crosses the demo's first bump
    (its front axle at 7.78 s; the lead's at 6.06 s, 1.7 s before: the lead is still
    settling), the detector's 1 s std of the product's y_c (detrended, `windowed_std`)
    stays at or below 1.0 px, the issue's 90th-percentile target, and within 0.3 px of the
    true trajectory's, which is what the lead's own settling leaves (measured 0.87 against
    0.62 px; 0.78 with frames held for their gyro, ``[fusion] frame_hold_s``)."""
    from roadpreview.eval.experiments.ceiling import true_compensated_y, windowed_std

    t = _column(results, "t") - _column(results, "t")[0]
    s = windowed_std(t, _column(results, "y_c"))
    sel = (t >= EGO_CROSSING[0]) & (t <= EGO_CROSSING[0] + 1.5)
    tt, yc_true, _ = true_compensated_y(demo10.truth, demo10.camera.fy)
    s_true = windowed_std(tt, yc_true)
    floor = float(np.nanmax(s_true[(tt >= EGO_CROSSING[0]) & (tt <= EGO_CROSSING[0] + 1.5)]))
    assert float(np.nanmax(s[sel])) <= min(1.0, floor + 0.3)


def test_the_heave_follows_the_camera_height(demo10: Recording, results: list[FrameResult]) -> None:
    """heave_m against the simulator's camera height (high-passed at the observer's 0.2 Hz,
    zero phase): correlated above 0.9 over the crossing, the error's 1 s spread below 40 %
    of the heave's (measured 8.9 of 29 mm: the high-pass's phase lead at 1-2 Hz)."""
    t = _column(results, "t") - _column(results, "t")[0]
    heave = _column(results, "heave_m")
    assert np.isnan(heave[t < 3.0 - 1e-6]).all()  # warming up
    assert np.isfinite(heave[t > 3.1]).all()
    sos = butter(2, 0.2, "hp", fs=1.0 / float(np.median(np.diff(t))), output="sos")
    truth = sosfiltfilt(sos, demo10.truth["cam_z_m"])
    sel = (t > EGO_CROSSING[0] - 0.5) & (t < EGO_CROSSING[1])
    assert np.corrcoef(heave[sel], truth[sel])[0, 1] > 0.9
    err = np.nanmax(_window_spread(heave - truth)[sel])
    assert err < 0.4 * np.nanmax(_window_spread(truth)[sel])


def _run_pipeline(
    rec: Any, config: PipelineConfig, drop_ids: set[int], frames: int
) -> list[FrameResult]:
    """The pipeline over a recording, without the CAN frames of ``drop_ids``."""
    inputs = ReplayInputs.from_recording(rec.folder)
    assert inputs.video_start_s is not None
    video = VideoFileSource(
        inputs.video, start_s=inputs.video_start_s, frames_csv=inputs.frames_csv
    )
    decoder = make_decoder()

    class _Dropping(CanLogSource):
        """The log without the frames of ``drop_ids`` (an accelerometer that is not there)."""

        def __iter__(self) -> Iterator[InputSample]:
            for msg in read_can_log(self.path):
                if msg.arbitration_id not in drop_ids:
                    yield from self.decoder.decode(msg)

    results = ResultsSink()
    run([video, _Dropping(inputs.can_logs[0], decoder)], Pipeline(rec.camera, config),
        [results], max_frames=frames)
    return results.results


@pytest.mark.parametrize("case", ["no accelerometer on the bus", "heave disabled"])
def test_without_heave_the_compensation_is_the_papers(demo10: Recording, case: str) -> None:
    """No IMU_ACCEL frames (only rates) or ``[heave] enabled = false``: heave_m is NaN,
    heave_px 0 and y_c = y - f tan φ exactly; the fusion is unaffected (FUSED)."""
    accel_id = load_database().get_message_by_name(IMU_ACCEL).frame_id
    config = PipelineConfig()
    drop: set[int] = set()
    if case == "heave disabled":
        config = replace(config, heave=HeaveConfig(enabled=False))
    else:
        drop = {accel_id}
    out = _run_pipeline(demo10, config, drop, frames=150)
    assert all(math.isnan(r.heave_m) and r.heave_px == 0.0 for r in out)
    f = demo10.camera.fy
    for r in out:
        if math.isfinite(r.y):
            assert r.y_c == pytest.approx(r.y - f * math.tan(r.phi), abs=1e-9)
    assert out[-1].mode.name == "FUSED"


def test_the_frame_table_has_the_heave_columns() -> None:
    cols = FrameResult.COLUMNS
    i = cols.index("heave_m")
    assert cols[i : i + 2] == ("heave_m", "heave_px")
    assert cols[:6] == ("t", "index", "y", "y_left", "y_right", "y_c")  # nothing moved
