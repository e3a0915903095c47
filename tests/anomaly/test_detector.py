"""WindowedStdDetector: analytic peaks, false-positive rate, NMS, sides, suppression, thresholds."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from roadpreview.anomaly import (
    AnomalyConfig,
    DetectorConfig,
    SignalModel,
    TrajectorySample,
    WindowedStdDetector,
    noise_threshold_px,
)
from roadpreview.configtools import load, save
from roadpreview.errors import ConfigError, InputDataError
from roadpreview.types import FusionMode, Side, SuppressionReason

#: the paper's s (eq. 1): the plain std of the window, no detrending
PAPER = DetectorConfig(detrend=False, emit="peak")


def _step_s(a_px: float, n_window: int, c: int) -> float:
    """std (ddof 0) of a window of n samples, c of them at a_px and the rest at 0."""
    return a_px * math.sqrt(c * (n_window - c)) / n_window


# --- analytic peaks -----------------------------------------------------------------------------


@pytest.mark.parametrize(("fps", "a_px"), [(30.0, 6.0), (25.0, 4.0), (60.0, 3.0)])
def test_step_gives_the_analytic_s_curve_and_one_event(
    fps: float, a_px: float, make_trajectory: Any
) -> None:
    """A step of A px: with c of the N window samples after it, s = A sqrt(c (N - c)) / N.

    The maximum is A / 2 when N is even (half the window on each side), and
    A sqrt((N² - 1) / 4) / N when N is odd. The event's crossing time is the step.
    """
    n_window = round(fps)  # T = 1 s
    t = np.arange(int(6 * fps)) / fps
    k0 = int(2 * fps)  # the step happens at frame k0 (t = 2 s)
    y = np.where(np.arange(len(t)) >= k0, 400.0 - a_px, 400.0)  # the lead rises: v decreases
    run = WindowedStdDetector(PAPER).run(make_trajectory(t, y))
    for c in range(1, n_window):
        assert run.s[k0 + c - 1] == pytest.approx(_step_s(a_px, n_window, c), rel=1e-9)
    s_max = a_px / 2 if n_window % 2 == 0 else a_px * math.sqrt((n_window**2 - 1) / 4) / n_window
    assert np.nanmax(run.s) == pytest.approx(s_max, rel=1e-9)
    assert len(run.events) == 1
    e = run.events[0]
    assert e.s_px == pytest.approx(s_max, rel=1e-9)
    assert e.t_s == pytest.approx(t[k0])  # steepest change = the step
    assert e.t_peak_s == pytest.approx(t[k0 + n_window // 2 - 1], abs=1.01 / fps)
    assert e.t_emit_s - e.t_peak_s == pytest.approx(1.0, abs=1.01 / fps)  # NMS window
    assert e.side == Side.BOTH
    assert not e.suppressed


def test_rectangular_pulse_gives_a_plateau_and_one_event(make_trajectory: Any) -> None:
    """A pulse of w frames inside the window: s = A sqrt(w (N - w)) / N for N - w + 1 frames."""
    fps, a_px, w = 30.0, 4.0, 6
    t = np.arange(180) / fps
    y = np.full(len(t), 250.0)
    y[60 : 60 + w] -= a_px
    run = WindowedStdDetector(PAPER).run(make_trajectory(t, y))
    plateau = run.s[60 + w - 1 : 60 + 30]
    assert len(plateau) == 30 - w + 1
    np.testing.assert_allclose(plateau, a_px * math.sqrt(w * (30 - w)) / 30, rtol=1e-12)
    assert a_px * math.sqrt(w * (30 - w)) / 30 == pytest.approx(1.6)
    assert len(run.events) == 1
    assert run.events[0].t_s in (pytest.approx(t[60]), pytest.approx(t[60 + w]))  # an edge


# --- noise --------------------------------------------------------------------------------------


def test_noise_only_exceeds_the_threshold_at_the_stated_rate(make_trajectory: Any) -> None:
    """White noise vs noise_threshold_px(σ, 30, p): independent windows exceed it with rate p."""
    rng = np.random.default_rng(7)
    sigma, p = 0.5, 0.05
    thr = noise_threshold_px(sigma, 30, p)
    n = 36_000
    t = np.arange(n) / 30.0
    y = 300.0 + rng.normal(0.0, sigma, n)
    run = WindowedStdDetector(DetectorConfig(threshold_px=thr)).run(make_trajectory(t, y))
    disjoint = run.s[29::30]  # windows that share no sample are independent
    k = int(np.count_nonzero(disjoint > thr))
    expected = p * len(disjoint)
    assert abs(k - expected) < 4 * math.sqrt(expected * (1 - p)), (k, expected)
    # all frames: the same marginal rate (clustered, so only loosely)
    assert np.mean(run.s[29:] > thr) == pytest.approx(p, rel=0.35)


def test_default_threshold_derivation() -> None:
    """0.4 px noise and 1e-6 false positives per frame give 0.65 px; the default 1 px is above."""
    assert noise_threshold_px(0.4, 30, 1e-6) == pytest.approx(0.655, abs=0.001)
    assert DetectorConfig().threshold_px > noise_threshold_px(0.4, 30, 1e-6)
    with pytest.raises(ConfigError):
        noise_threshold_px(0.0, 30, 1e-6)


# --- NMS ----------------------------------------------------------------------------------------


def test_nms_gives_one_event_per_bump(make_trajectory: Any, bump: Any) -> None:
    rng = np.random.default_rng(3)
    fps = 30.0
    t = np.arange(int(50 * fps)) / fps
    starts = np.arange(3.0, 45.0, 5.0)
    y = 420.0 + rng.normal(0.0, 0.3, len(t))
    for s0 in starts:
        y -= bump(t, s0, 0.5, 5.0)
    run = WindowedStdDetector(DetectorConfig(emit="peak")).run(make_trajectory(t, y))
    assert np.count_nonzero(run.s > 1.0) > 10 * len(starts)  # many frames above threshold ...
    assert len(run.events) == len(starts)  # ... one event per bump
    for e, s0 in zip(run.events, starts, strict=True):
        assert s0 <= e.t_s <= s0 + 0.5  # the crossing lies on the bump
        assert e.t_emit_s - e.t_peak_s == pytest.approx(1.0, abs=0.04)
    # onset emission: the same bumps, one event each, emitted when s first crosses the
    # threshold: at least 0.9 s earlier than the confirmed peak (1 s NMS + the rise)
    onset = WindowedStdDetector(DetectorConfig(emit="onset")).run(make_trajectory(t, y))
    assert len(onset.events) == len(starts)
    for e, p, s0 in zip(onset.events, run.events, starts, strict=True):
        assert s0 <= e.t_emit_s <= s0 + 1.0  # while the bump is still in the window
        assert e.t_emit_s <= p.t_emit_s - 0.9
        assert e.s_px < p.s_px  # described at the onset, not the peak


def test_nms_window_shorter_than_the_detector_window_is_refused() -> None:
    with pytest.raises(ConfigError, match="nms_window_s"):
        WindowedStdDetector(DetectorConfig(window_s=1.0, nms_window_s=0.5))


# --- sides --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("left_px", "right_px", "side"),
    [(6.0, 2.0, Side.LEFT), (2.0, 6.0, Side.RIGHT), (5.0, 5.0, Side.BOTH), (5.0, 4.0, Side.BOTH)],
)
def test_side_from_the_half_trajectories(
    left_px: float, right_px: float, side: Side, make_trajectory: Any, bump: Any
) -> None:
    """A rigid rear over a pothole under the left wheels: halves move 3:1, the centre 2:1."""
    t = np.arange(150) / 30.0
    hump = bump(t, 2.0, 0.4, 1.0)
    left = 300.0 + left_px * hump  # the lead drops into the pothole: v increases
    right = 300.0 + right_px * hump
    y = 0.5 * (left + right)
    run = WindowedStdDetector().run(make_trajectory(t, y, left=left, right=right))
    assert [e.side for e in run.events] == [side]


def test_side_unknown_without_half_trajectories(make_trajectory: Any, bump: Any) -> None:
    t = np.arange(150) / 30.0
    y = 300.0 + bump(t, 2.0, 0.4, 5.0)
    nan = np.full(len(t), np.nan)
    run = WindowedStdDetector().run(make_trajectory(t, y, left=nan, right=nan))
    assert [e.side for e in run.events] == [Side.UNKNOWN]
    assert np.isnan(run.s_left).all()


# --- suppression --------------------------------------------------------------------------------


def test_hard_braking_lead_is_suppressed_visibly_and_does_not_hide_a_later_bump(
    make_trajectory: Any,
) -> None:
    """The braking dive is reported as a suppressed event; a bump 1.3 s later is a real event.

    The NMS window is 3 s here: one shared NMS would let the (larger) dive peak
    swallow the bump, which is why suppressed peaks have their own NMS.
    """
    fps = 30.0
    t = np.arange(int(20 * fps)) / fps
    accel = np.where((t >= 10.0) & (t < 10.5), -5.0, 0.0)  # hard braking for 0.5 s
    y = np.full(len(t), 300.0)
    y[t >= 10.4] += 8.0  # the dive moves the lead's rear down by 8 px
    y[t >= 12.2] -= 3.0  # then a real bump lifts it (a 3 px step)
    cfg = replace(PAPER, nms_window_s=3.0)  # steps: the paper's s (detrending halves them)
    run = WindowedStdDetector(cfg).run(make_trajectory(t, y, lead_accel=accel))
    suppressed = [e for e in run.events if e.suppressed]
    real = run.alerts
    assert len(suppressed) == 1
    assert suppressed[0].suppressed == SuppressionReason.LEAD_ACCEL
    assert suppressed[0].t_s == pytest.approx(10.4, abs=0.04)
    assert len(real) == 1
    assert real[0].t_s == pytest.approx(12.2, abs=0.04)
    assert real[0].s_px < suppressed[0].s_px
    # the frames say why: from the first hard frame until window + hold after the last one
    flagged = t[run.suppressed == int(SuppressionReason.LEAD_ACCEL)]
    assert flagged.min() == pytest.approx(10.0)
    assert flagged.max() == pytest.approx(10.5 - 1 / fps + 1.0 + 0.5, abs=1.01 / fps)


def test_degraded_fusion_is_suppressed(make_trajectory: Any, bump: Any) -> None:
    fps = 30.0
    t = np.arange(int(10 * fps)) / fps
    modes = [FusionMode.DEGRADED if 4.0 <= tk < 5.0 else FusionMode.FUSED for tk in t]
    y = 300.0 + bump(t, 4.3, 0.4, 6.0)
    det = WindowedStdDetector()
    run = det.run(make_trajectory(t, y, modes=modes))
    assert [e.suppressed for e in run.events] == [SuppressionReason.DEGRADED]
    assert run.alerts == []
    assert det.frame is not None
    assert not det.frame.suppressed  # long after the degraded second


def test_moderate_lead_acceleration_is_not_suppressed(make_trajectory: Any, bump: Any) -> None:
    t = np.arange(150) / 30.0
    y = 300.0 + bump(t, 2.0, 0.4, 5.0)
    run = WindowedStdDetector().run(make_trajectory(t, y, lead_accel=np.full(len(t), -1.5)))
    assert len(run.alerts) == 1
    assert not run.suppressed.any()


# --- thresholds ---------------------------------------------------------------------------------


def test_distance_aware_threshold(make_trajectory: Any) -> None:
    """α f h_min / d: 5 px at 10 m for 5 cm with f = 1000 px; never below the pixel threshold."""
    signal = SignalModel(focal_px=1000.0)
    cfg = DetectorConfig(threshold_mode="distance", min_height_m=0.05, signal=signal)
    det = WindowedStdDetector(cfg)
    assert det.threshold_px(10.0) == pytest.approx(5.0)
    assert det.threshold_px(80.0) == pytest.approx(1.0)  # 0.625 px: the pixel floor
    assert det.threshold_px(math.nan) == pytest.approx(1.0)
    t = np.arange(180) / 30.0
    y = np.where(t >= 2.0, 294.0, 300.0)  # s peaks at 3 px
    near = make_trajectory(t, y, distance_m=10.0)  # 6 px at 10 m: a 6 cm step, below the 5 cm line?
    # f δ / d = 6 px -> δ = 6 cm, but s = 3 px < 5 px: the distance threshold asks for s of a
    # 5 cm anomaly (α = 1), so the step passes only in pixel mode
    assert WindowedStdDetector(cfg).run(near).events == []
    assert len(WindowedStdDetector(DetectorConfig(signal=signal)).run(near).events) == 1
    far = make_trajectory(t, y, distance_m=80.0)
    assert len(WindowedStdDetector(cfg).run(far).events) == 1


def test_distance_mode_needs_a_focal_length() -> None:
    with pytest.raises(ConfigError, match="focal_px"):
        WindowedStdDetector(DetectorConfig(threshold_mode="distance"))


# --- validity and input checks ------------------------------------------------------------------


def test_invalid_frames_are_left_out_and_gaps_restart_the_window(make_trajectory: Any) -> None:
    fps = 30.0
    t = np.arange(300) / fps
    rng = np.random.default_rng(1)
    y = 300.0 + rng.normal(0, 1.0, len(t))
    valid = np.ones(len(t), bool)
    valid[100:105] = False  # a lost track for 5 frames
    keep = (t < 6.0) | (t >= 7.5)  # 1.5 s of frames never arrive
    samples = [s for s, k in zip(make_trajectory(t, y, valid=valid), keep, strict=True) if k]
    run = WindowedStdDetector(PAPER).run(samples)
    tt = run.t
    k = int(np.searchsorted(tt, t[110]))
    window = (t > t[110] - 1.0 + 1e-6) & (t <= t[110]) & valid
    assert run.s[k] == pytest.approx(np.std(y[window]), rel=1e-12)
    after_gap = (tt >= 7.5) & (tt < 7.5 + 0.5 - 1e-9)
    assert np.isnan(run.s[after_gap]).all()  # less than half a window since the gap
    assert np.isfinite(run.s[tt >= 8.0]).all()


def test_times_must_increase() -> None:
    det = WindowedStdDetector()
    det.push(TrajectorySample(t=1.0, y_c=3.0))
    with pytest.raises(InputDataError, match="increase"):
        det.push(TrajectorySample(t=1.0, y_c=3.0))
    with pytest.raises(InputDataError):
        det.push(TrajectorySample(t=math.nan, y_c=3.0))


def test_frame_output_is_available_every_frame(make_trajectory: Any) -> None:
    det = WindowedStdDetector(PAPER)
    assert det.frame is None
    t = np.arange(60) / 30.0
    for s in make_trajectory(t, 300.0 + np.sin(t)):
        det.push(s)
        assert det.frame is not None
        assert det.frame.t == s.t
    assert det.frame is not None
    assert det.frame.s == pytest.approx(np.std(300.0 + np.sin(t[-30:])), rel=1e-12)
    assert det.frame.n_samples == 30
    assert not det.frame.above


def test_config_from_toml_names_the_file_and_field(tmp_path: Path) -> None:
    path = tmp_path / "anomaly.toml"
    path.write_text(
        "[detector]\nwindow_s = 1.5\nnms_window_s = 2.0\n[detector.signal]\nalpha = 0.5\n"
    )
    cfg = load(DetectorConfig, path, table="detector")
    assert cfg.window_s == 1.5
    assert cfg.signal.alpha == 0.5
    path.write_text("[detector]\nthreshold_px = -1.0\n")
    with pytest.raises(ConfigError, match=r"anomaly\.toml.*detector\.threshold_px"):
        load(DetectorConfig, path, table="detector")
    with pytest.raises(ConfigError, match="window_s"):
        WindowedStdDetector(replace(DetectorConfig(), window_s=-1.0))


def test_anomaly_table_round_trips_through_toml(tmp_path: Path) -> None:
    path = tmp_path / "roadpreview.toml"
    path.write_text(
        "[anomaly]\ndetector = 'std'\n"
        "[anomaly.std]\nthreshold_mode = 'distance'\n"
        "[anomaly.std.signal]\nfocal_px = 910.0\n"
        "[anomaly.two_axle]\nthreshold_z = 6.0\n"
        "[anomaly.alert]\nmin_speed_mps = 1.0\n"
    )
    cfg = load(AnomalyConfig, path, table="anomaly")
    assert cfg.detector == "std"
    assert cfg.std.signal.focal_px == 910.0
    assert cfg.two_axle.threshold_z == 6.0
    assert cfg.alert.min_speed_mps == 1.0
    save(cfg, tmp_path / "out.toml")
    assert load(AnomalyConfig, tmp_path / "out.toml") == cfg
    path.write_text("[anomaly.std]\nthreshold_mode = 'distance'\n")
    with pytest.raises(ConfigError, match=r"anomaly\.std\.threshold_mode.*focal_px"):
        load(AnomalyConfig, path, table="anomaly")
    path.write_text("[anomaly]\ndetector = 'cusum'\n")
    with pytest.raises(ConfigError, match=r"anomaly\.detector.*two-axle"):
        load(AnomalyConfig, path, table="anomaly")
