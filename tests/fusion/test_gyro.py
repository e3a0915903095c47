"""The gyro buffer: exact integral of interval-mean samples, ordering, gaps and bad input."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest

from roadpreview.fusion.config import GyroConfig
from roadpreview.fusion.gyro import GyroHistory

DEG = math.pi / 180.0
DT = 0.01


def _rate(t: np.ndarray) -> np.ndarray:
    """Pitch (rad) of a bumpy ride; the sample at t is the mean rate over [t - DT, t]."""
    return 0.02 * np.sin(2 * np.pi * 1.3 * t) + 0.01 * np.sin(2 * np.pi * 0.4 * t + 1.0)


def _samples(n: int = 500) -> tuple[np.ndarray, np.ndarray]:
    t = DT * np.arange(1, n + 1)
    return t, (_rate(t) - _rate(t - DT)) / DT


def _filled(t: np.ndarray, w: np.ndarray, cfg: GyroConfig | None = None) -> GyroHistory:
    g = GyroHistory(cfg or GyroConfig(rate_hz=100.0))
    for ti, wi in zip(t, w, strict=True):
        assert g.push(float(ti), float(wi))
    return g


def test_integral_is_exact_for_interval_mean_samples() -> None:
    t, w = _samples()
    g = _filled(t, w)
    for a, b in [(0.05, 1.234), (1.0, 4.99), (2.345, 2.377)]:
        mo = g.motion(a, b)
        if abs(a / DT - round(a / DT)) < 1e-9 and abs(b / DT - round(b / DT)) < 1e-9:
            assert mo.dG == pytest.approx(
                _rate(np.array([b]))[0] - _rate(np.array([a]))[0], abs=1e-12
            )
        else:  # between stamps the rate is held over its interval: error below one sample
            assert abs(mo.dG - (_rate(np.array([b]))[0] - _rate(np.array([a]))[0])) < 1e-4
        assert mo.dM == pytest.approx(b - a)
        cfg = GyroConfig()
        assert mo.dV == pytest.approx(0.5 * cfg.noise_density**2 * (b - a))


def test_out_of_order_samples_give_the_same_integral(caplog: pytest.LogCaptureFixture) -> None:
    t, w = _samples(300)
    ref = _filled(t, w)
    rng = np.random.default_rng(0)
    order = np.arange(t.size)
    for i in range(0, t.size - 4, 4):  # shuffle within blocks of 4 (a CAN batch)
        order[i : i + 4] = rng.permutation(order[i : i + 4])
    g = GyroHistory(GyroConfig(rate_hz=100.0))
    with caplog.at_level(logging.WARNING):
        for j in order:
            assert g.push(float(t[j]), float(w[j]))
    assert g.rejects.counts.get("reordered", 0) > 0
    for a, b in [(0.1, 2.9), (0.555, 1.234)]:
        assert g.motion(a, b).dG == pytest.approx(ref.motion(a, b).dG, abs=1e-15)


@pytest.mark.parametrize(
    ("t", "rate", "kind"),
    [
        (1.005, math.nan, "nonfinite"),
        (math.nan, 0.1, "nonfinite"),
        (math.inf, 0.1, "nonfinite"),
        (1.005, 1e6, "range"),  # absurd
        (1.005, 2000.0 * DEG, "range"),  # at full scale: saturated
        (1.0, 0.3, "duplicate"),  # the stamp of an existing sample
        (0.5, 0.3, "late"),  # older than what is committed
    ],
)
def test_bad_samples_are_rejected_with_a_log_line(
    caplog: pytest.LogCaptureFixture, t: float, rate: float, kind: str
) -> None:
    ts, w = _samples(100)
    g = _filled(ts, w)
    g.floor = 0.6  # committed up to 0.6 s
    before = g.motion(0.7, 1.0)
    with caplog.at_level(logging.WARNING, logger="roadpreview.fusion.gyro"):
        assert not g.push(t, rate)
    assert g.rejects.counts == {kind: 1}
    assert any(kind in r.getMessage() or "rejected" in r.getMessage() for r in caplog.records)
    after = g.motion(0.7, 1.0)
    assert after == before
    assert math.isfinite(g.motion(0.0, 2.0).dG)


def test_backwards_stamp_within_the_uncommitted_part_is_sorted_in() -> None:
    ts, w = _samples(100)
    g = _filled(ts[:-1], w[:-1])
    last = g.motion(0.5, 0.99).dG
    g2 = _filled(ts, w)
    # the newest sample arrived before the one preceding it
    g3 = _filled(ts[:-2], w[:-2])
    assert g3.push(float(ts[-1]), float(w[-1]))
    assert g3.push(float(ts[-2]), float(w[-2]))
    assert g3.motion(0.5, 1.0).dG == pytest.approx(g2.motion(0.5, 1.0).dG, abs=1e-15)
    assert last == pytest.approx(g2.motion(0.5, 0.99).dG)


def test_short_gap_is_bridged_with_more_variance(caplog: pytest.LogCaptureFixture) -> None:
    t, w = _samples(300)
    keep = (t < 1.0) | (t > 1.1)  # 10 samples lost
    g = GyroHistory(GyroConfig(rate_hz=100.0))
    with caplog.at_level(logging.WARNING):
        for ti, wi in zip(t[keep], w[keep], strict=True):
            assert g.push(float(ti), float(wi))
    assert g.rejects.counts == {"gap": 1}
    assert "bridged" in caplog.text
    mo = g.motion(0.5, 2.0)
    truth = _rate(np.array([2.0]))[0] - _rate(np.array([0.5]))[0]
    assert abs(mo.dG - truth) < 0.1 * 0.03 * 2 * np.pi * 1.3 * 0.1  # a tenth of the rate x gap
    assert mo.dM == pytest.approx(1.5)
    full = _filled(t, w).motion(0.5, 2.0)
    assert mo.dV > full.dV + (GyroConfig().gap_rate_std_rad_s * 0.09) ** 2 * 0.9


def test_long_gap_is_an_outage_without_rate_or_bias() -> None:
    t, w = _samples(500)
    keep = (t < 1.0) | (t > 2.0)
    g = _filled(t[keep], w[keep])
    assert g.rejects.counts == {"outage": 1}
    mo = g.motion(1.0, 2.01)
    assert mo.dG == pytest.approx(w[t > 2.0][0] * 0.01)  # only the first sample after it
    assert mo.dM == pytest.approx(0.01)  # the bias acts only where measured
    assert mo.dV > (GyroConfig().blind_rate_std_rad_s * 0.9) ** 2


def test_sample_period_is_learnt_from_the_stamps() -> None:
    t = np.arange(1, 400) / 104.0
    g = _filled(t, np.zeros_like(t), GyroConfig(rate_hz=100.0))
    assert g.period == pytest.approx(1 / 104.0, rel=1e-6)


def test_beyond_the_newest_sample_the_last_rate_is_held() -> None:
    t, w = _samples(100)
    g = _filled(t, w)
    mo = g.motion(1.0, 1.05)
    assert mo.dG == pytest.approx(w[-1] * 0.05)
    assert mo.dV == pytest.approx((GyroConfig().hold_rate_std_rad_s * 0.05) ** 2)


def test_kept_query_results_equal_fresh_searches() -> None:
    """`motion3` keeps (G, V, M) and the rate at the end of its interval for the next frame's
    start, `rate_change` the rate at its start (a key frame's): on a stream with reordered
    and late samples, gaps and trimming (at the end past the key frame), every answer equals
    that of a buffer searching afresh (the kept values cleared before each query)."""
    rng = np.random.default_rng(3)
    t, w = _samples(4000)
    t = t + rng.uniform(-0.002, 0.002, t.size)  # jittered stamps: frames fall between knots
    order = np.arange(t.size)
    for i in range(0, t.size - 3, 3):  # some samples arrive out of order
        if rng.random() < 0.1:
            order[i : i + 3] = order[i : i + 3][::-1]
    drop = rng.random(t.size) < 0.01  # and some never (short gaps)
    late = rng.random(t.size) < 0.05  # some 60-90 ms late: sorted in behind kept values
    arrivals = sorted((k + (rng.integers(6, 10) if late[i] else 0), i) for k, i in enumerate(order))
    g = GyroHistory(GyroConfig(rate_hz=100.0, history_s=12.0))
    frame, key, n_checked = 0.5, 0.5, 0
    for _, j in arrivals:
        if drop[j]:
            continue
        g.push(float(t[j]), float(w[j]))
        newest = g.newest
        assert newest is not None
        while frame + 1 / 30 < newest - 0.05:  # frames as the fusion queries them
            prev, frame = frame, frame + 1 / 30
            if frame - key > 2.0 and frame < 25.0:  # then one key until it is trimmed away
                key = prev
            fresh = _fresh_copy(g)
            assert g.motion3(prev, frame) == fresh.motion3(prev, frame)
            assert g.rate_change(key, frame) == fresh.rate_change(key, frame)
            g.floor = prev
            g.trim(prev - 10.0)
            n_checked += 1
    assert n_checked > 1100


def _fresh_copy(g: GyroHistory) -> GyroHistory:
    import copy

    f = copy.copy(g)
    f._s, f._k = list(g._s), list(g._k)
    f._end_s = f._start_s = math.nan
    return f
