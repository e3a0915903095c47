"""Beyond the paper's eq. 1: the detrended s, the compensation margin of the threshold and
the SETTLING suppression (docs/detector.md)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from roadpreview.anomaly import (
    DetectorConfig,
    TrajectorySample,
    WindowedMoments,
    WindowedStdDetector,
    noise_threshold_px,
)
from roadpreview.errors import ConfigError
from roadpreview.types import FusionMode, SuppressionReason

FPS = 30.0


def _detrended_std(t: np.ndarray, x: np.ndarray) -> float:
    """std (ddof 0) of the residuals of a least-squares line through (t, x)."""
    tt = t - t.mean()
    coef = np.polyfit(tt, x, 1)
    return float(np.std(x - np.polyval(coef, tt)))


# --- the detrended s ----------------------------------------------------------------------------


def test_detrended_s_equals_a_least_squares_fit_over_a_long_noisy_stream() -> None:
    """20 000 frames on a Unix clock, 400 px with a slow drift, NaN holes in one channel: the
    O(1) running update equals numpy.polyfit's residual std within 1e-9 (relative)."""
    rng = np.random.default_rng(11)
    n = 20_000
    t = 1.7e9 + np.arange(n) / FPS
    x = 400.0 + 30.0 * np.sin(2 * np.pi * (t - t[0]) / 600.0) + rng.normal(0.0, 0.4, (n, 2)).T
    x = x.T.copy()
    x[::7, 1] = np.nan
    m = WindowedMoments(1.0, 2, trend=True)
    worst = 0.0
    for k in range(n):
        m.push(float(t[k]), x[k])
        if k >= 29 and k % 37 == 0:
            got = m.detrended_std_values()
            for c in range(2):
                w = x[k - 29 : k + 1, c]
                ok = np.isfinite(w)
                want = _detrended_std(t[k - 29 : k + 1][ok], w[ok])
                worst = max(worst, abs(got[c] - want) / want)
    assert worst < 1e-9
    with pytest.raises(ConfigError, match="trend"):
        WindowedMoments(1.0, 1).detrended_std_values()


def test_a_ramp_is_not_a_bump_but_a_bump_on_a_ramp_is(make_trajectory: Any, bump: Any) -> None:
    """A lead that closes in: y_c drifts by 3 px/s (std 0.87 px per window, near the
    threshold in the paper's s). Detrended, s stays at 0; a 5 px bump on the ramp keeps
    almost its full s and is found once."""
    t = np.arange(int(8 * FPS)) / FPS
    ramp = 300.0 + 3.0 * t
    paper = WindowedStdDetector(DetectorConfig(detrend=False)).run(make_trajectory(t, ramp))
    assert np.nanmax(paper.s) == pytest.approx(3.0 * math.sqrt((30**2 - 1) / 12) / 30, rel=1e-6)
    flat = WindowedStdDetector().run(make_trajectory(t, ramp))
    assert np.nanmax(flat.s) < 1e-6
    bumpy = ramp - bump(t, 4.0, 0.5, 5.0)
    run = WindowedStdDetector().run(make_trajectory(t, bumpy))
    plain = WindowedStdDetector(DetectorConfig(detrend=False)).run(
        make_trajectory(t, 300.0 - bump(t, 4.0, 0.5, 5.0))
    )
    assert np.nanmax(run.s) > 0.9 * np.nanmax(plain.s)
    assert len(run.alerts) == 1
    assert 4.0 <= run.alerts[0].t_s <= 4.5


def test_a_step_keeps_a_third_less_than_half(make_trajectory: Any) -> None:
    """A step of A px: around the window's line its s peaks at A sqrt(1/12) = 0.289 A when
    the step sits at 21 % or 79 % of the window (A / 2 at the centre without detrending)."""
    t = np.arange(int(6 * FPS)) / FPS
    y = np.where(t >= 2.0, 392.0, 400.0)
    run = WindowedStdDetector().run(make_trajectory(t, y))
    assert np.nanmax(run.s) == pytest.approx(8.0 / math.sqrt(12), rel=0.03)
    want = [_detrended_std(t[k - 29 : k + 1], y[k - 29 : k + 1]) for k in range(29, len(t))]
    np.testing.assert_allclose(run.s[29:], want, rtol=1e-9, atol=1e-6)  # rounding of a 0


@pytest.mark.parametrize("detrend", [False, True])
def test_noise_exceeds_the_threshold_at_the_stated_rate(
    detrend: bool, make_trajectory: Any
) -> None:
    """White noise: disjoint windows exceed noise_threshold_px(σ, 30, p) at rate p, with
    N - 1 degrees of freedom for the plain std and N - 2 around the line."""
    rng = np.random.default_rng(8)
    sigma, p = 0.5, 0.05
    thr = noise_threshold_px(sigma, 30, p, detrended=detrend)
    t = np.arange(36_000) / FPS
    y = 300.0 + rng.normal(0.0, sigma, len(t))
    cfg = DetectorConfig(threshold_px=thr, detrend=detrend)
    run = WindowedStdDetector(cfg).run(make_trajectory(t, y))
    disjoint = run.s[29::30]
    k = int(np.count_nonzero(disjoint > thr))
    expected = p * len(disjoint)
    assert abs(k - expected) < 4 * math.sqrt(expected * (1 - p)), (k, expected)
    assert noise_threshold_px(sigma, 30, p, detrended=True) < noise_threshold_px(sigma, 30, p)


# --- the compensation margin --------------------------------------------------------------------


def _samples(
    t: np.ndarray, y: np.ndarray, comp: np.ndarray, modes: list[FusionMode] | None = None
) -> list[TrajectorySample]:
    return [
        TrajectorySample(
            t=float(t[k]),
            y_c=float(y[k]),
            lead_distance_m=15.0,
            compensation_px=float(comp[k]),
            mode=FusionMode.FUSED if modes is None else modes[k],
        )
        for k in range(len(t))
    ]


def test_the_threshold_rises_while_the_compensation_works_hard(bump: Any) -> None:
    """The ego crosses a bump: its compensation swings by ±20 px at 1.5 Hz for 1.5 s. The
    threshold becomes sqrt(1 + (0.1 * s_comp)²) (s_comp = 14 px: 1.72 px), so a 1.4 px
    residual there is no alert; the same bump with a calm ego is one."""
    t = np.arange(int(10 * FPS)) / FPS
    swing = np.where((t > 4.0) & (t < 5.5), 20.0 * np.sin(2 * np.pi * 1.5 * t), 0.0)
    y = 300.0 - bump(t, 4.5, 0.5, 4.0)  # s peaks near 1.4 px
    det = WindowedStdDetector()
    hard = det.run(_samples(t, y, 50.0 + swing))
    assert np.nanmax(hard.s) == pytest.approx(1.4, abs=0.2)
    k = int(np.nanargmax(hard.threshold_px))
    s_comp = _detrended_std(t[k - 29 : k + 1], swing[k - 29 : k + 1])
    assert hard.threshold_px[k] == pytest.approx(math.hypot(1.0, 0.1 * s_comp), rel=1e-9)
    assert hard.threshold_px[k] > 1.6
    assert hard.events == []
    calm = WindowedStdDetector().run(_samples(t, y, np.full(len(t), 50.0)))
    assert np.nanmax(calm.threshold_px) == pytest.approx(1.0)
    assert len(calm.alerts) == 1
    unknown = WindowedStdDetector().run(_samples(t, y, np.full(len(t), np.nan)))
    assert np.nanmax(unknown.threshold_px) == pytest.approx(1.0)  # no compensation: no margin
    off = WindowedStdDetector(DetectorConfig(compensation_error_fraction=0.0))
    assert len(off.run(_samples(t, y, 50.0 + swing)).alerts) == 1


# --- SETTLING -----------------------------------------------------------------------------------


def test_imu_only_is_suppressed_until_the_fusion_has_been_fused_long_enough(bump: Any) -> None:
    """IMU_ONLY 2-4 s after the start (3 s FUSED before): the gyro bias is not learnt, a bump
    there is a SETTLING event. Later, after 20 s of FUSED, an IMU_ONLY stretch (fog) is not
    suppressed and its bump is an alert."""
    t = np.arange(int(40 * FPS)) / FPS
    imu_only = ((t >= 3.0) & (t < 5.0)) | ((t >= 30.0) & (t < 33.0))
    modes = [FusionMode.IMU_ONLY if m else FusionMode.FUSED for m in imu_only]
    y = 300.0 - bump(t, 3.8, 0.5, 5.0) - bump(t, 31.0, 0.5, 5.0)
    run = WindowedStdDetector().run(_samples(t, y, np.zeros(len(t)), modes))
    assert [(round(e.t_s), e.suppressed) for e in run.events] == [
        (4, SuppressionReason.SETTLING),
        (31, SuppressionReason.NONE),
    ]
    flagged = t[(run.suppressed & int(SuppressionReason.SETTLING)) != 0]
    assert flagged.min() == pytest.approx(3.0)
    assert flagged.max() == pytest.approx(5.0 - 1 / FPS + 1.0 + 0.5, abs=1.01 / FPS)
    never = WindowedStdDetector(DetectorConfig(imu_only_settle_s=0.0))
    assert not never.run(_samples(t, y, np.zeros(len(t)), modes)).suppressed.any()
