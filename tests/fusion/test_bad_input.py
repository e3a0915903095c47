"""Bad input never reaches the state: it is rejected or bridged, with a log line."""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

import numpy as np
import pytest

from roadpreview.errors import InputDataError
from roadpreview.fusion import VisualPitch, make_fusion
from roadpreview.fusion.baselines import ImuOnlyPitch
from roadpreview.fusion.streaming import StreamingPitchFusion

if TYPE_CHECKING:  # conftest is not importable at run time (--import-mode=importlib)
    from tests.fusion.conftest import FusionTestKit


DEG = math.pi / 180.0


def _corrupt(t: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """Insert NaN, inf, absurd and saturated rates, duplicated and backwards stamps, and drop
    a short and a long stretch (a gap bridged, an outage) in a clean gyro stream."""
    tt, ww = list(t), list(w)
    bad_t = []
    expected = {"nonfinite": 0, "range": 0, "duplicate": 0, "late": 0}
    for i in range(200, t.size - 200, 97):  # a bad sample every ~1 s, after a good one
        kind = (i // 97) % 6
        if kind == 0:
            bad_t.append((i, t[i] + 0.002, math.nan))
            expected["nonfinite"] += 1
        elif kind == 1:
            bad_t.append((i, t[i] + 0.002, math.inf))
            expected["nonfinite"] += 1
        elif kind == 2:
            bad_t.append((i, t[i] + 0.002, 1e6))  # absurd
            expected["range"] += 1
        elif kind == 3:
            bad_t.append((i, t[i] + 0.002, -2000.0 * DEG))  # saturated phone gyro
            expected["range"] += 1
        elif kind == 4:
            bad_t.append((i, t[i], w[i] + 0.3))  # duplicated stamp, another value
            expected["duplicate"] += 1
        else:
            bad_t.append((i, t[i] - 1.0, 0.0))  # far backwards: that time is committed
            expected["late"] += 1
    out_t, out_w = [], []
    j = 0
    for i, (ti, wi) in enumerate(zip(tt, ww, strict=True)):
        if 5.00 <= ti < 5.05 or 7.0 <= ti < 7.6:  # a 50 ms gap and a 0.6 s outage
            continue
        out_t.append(ti)
        out_w.append(wi)
        while j < len(bad_t) and bad_t[j][0] == i:
            out_t.append(bad_t[j][1])
            out_w.append(bad_t[j][2])
            j += 1
    return np.array(out_t), np.array(out_w), expected


@pytest.mark.parametrize("backend", ["kalman", "factor-graph", "imu-only"])
def test_corrupted_gyro_stream(
    kit: FusionTestKit, caplog: pytest.LogCaptureFixture, backend: str
) -> None:
    d = kit.synthetic(12.0, seed=11)
    fe = kit.front_end(d)
    t_bad, w_bad, expected = _corrupt(d.imu_t, d.imu_rate)
    f = make_fusion(backend)
    with caplog.at_level(logging.WARNING):
        r = kit.replay(f, d, fe, imu_t=t_bad, imu_rate=w_bad)
    if isinstance(f, StreamingPitchFusion):
        stats = f.stats
    else:
        assert isinstance(f, ImuOnlyPitch)
        stats = f.events.counts
    for kind, n in expected.items():
        assert stats.get(kind, 0) == n, (kind, stats)
    assert stats.get("gap") == 1
    assert stats.get("outage") == 1
    assert "rejected" in caplog.text
    assert "bridged" in caplog.text
    assert np.all(np.isfinite(r.phi))
    assert np.all(np.isfinite(r.std))
    if backend != "imu-only":
        # the same drive with only the gap and the outage: the bad samples changed nothing
        keep = ~(((d.imu_t >= 5.0) & (d.imu_t < 5.05)) | ((d.imu_t >= 7.0) & (d.imu_t < 7.6)))
        ref = kit.replay(
            make_fusion(backend), d, fe, imu_t=d.imu_t[keep], imu_rate=d.imu_rate[keep]
        )
        assert np.degrees(np.abs(r.phi - ref.phi)).max() < 1e-9
        err = r.error_deg(d)
        assert np.abs(err).max() < 0.1


def test_out_of_order_gyro_within_the_reorder_window(kit: FusionTestKit) -> None:
    """Samples swapped pairwise (a CAN batch out of order) give the same result (to 1e-3 deg:
    the offset window sees the newest sample a few ms earlier or later)."""
    d = kit.synthetic(8.0, seed=12)
    fe = kit.front_end(d)
    t, w = d.imu_t.copy(), d.imu_rate.copy()
    t[1:-1:2], t[2::2] = d.imu_t[2::2].copy(), d.imu_t[1:-1:2].copy()
    w[1:-1:2], w[2::2] = d.imu_rate[2::2].copy(), d.imu_rate[1:-1:2].copy()
    f = make_fusion("kalman")
    assert isinstance(f, StreamingPitchFusion)  # what make_fusion builds for this back end
    r = kit.replay(f, d, fe, imu_t=t, imu_rate=w)
    ref = kit.replay(make_fusion("kalman"), d, fe)
    assert f.stats.get("reordered", 0) > 100
    assert np.degrees(np.abs(r.phi - ref.phi)).max() < 1e-3


def test_nonsense_visual_measurements_count_as_failures(caplog: pytest.LogCaptureFixture) -> None:
    f = make_fusion("kalman")
    assert isinstance(f, StreamingPitchFusion)  # what make_fusion builds for this back end
    f.estimate(0.0)
    with caplog.at_level(logging.WARNING):
        f.push_visual(VisualPitch(0.0, 1 / 30, math.nan, 1e-4, 0.8, True))
        f.push_visual(VisualPitch(0.0, 2 / 30, 0.01, -1.0, 0.8, True))
        f.push_visual(VisualPitch(0.0, 3 / 30, 1.0, 1e-4, 0.8, True))  # 57 deg: not a pitch
        f.push_visual(VisualPitch(0.2, 0.1, 0.001, 1e-4, 0.8, True))  # key after the frame
        f.push_visual(VisualPitch(math.nan, 0.2, 0.001, 1e-4, 0.8, True))
    stats = f.stats
    assert stats == {"visual-bad": 3, "visual-time": 2}
    assert "unusable" in caplog.text
    out = [f.estimate(k / 30) for k in range(1, 4)]
    assert all(o.phi == 0.0 for o in out)


@pytest.mark.parametrize("backend", ["kalman", "factor-graph", "visual-only", "imu-only", "none"])
def test_estimate_times_must_not_go_backwards(backend: str) -> None:
    f = make_fusion(backend)
    f.estimate(1.0)
    assert f.estimate(1.0).t == 1.0  # the same frame again: the same answer
    with pytest.raises(InputDataError, match="before the previous"):
        f.estimate(0.5)
    with pytest.raises(InputDataError, match="not a finite time"):
        f.estimate(math.nan)


def test_roll_and_yaw_rates_are_checked() -> None:
    f = make_fusion("kalman")
    assert isinstance(f, StreamingPitchFusion)  # what make_fusion builds for this back end
    assert f.push_gyro(0.01, 0.0, roll_rate=0.1, yaw_rate=-0.2)
    assert not f.push_gyro(0.02, 0.0, yaw_rate=math.nan)
    assert f.stats == {"nonfinite": 1}
