"""Modes and fallback: vision trust with hysteresis, re-validation, IMU timeout, DEGRADED."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
import pytest

from roadpreview.fusion import VisualPitch, make_fusion
from roadpreview.fusion.config import ModeConfig
from roadpreview.fusion.mode_machine import ModeSupervisor, VisionTrust
from roadpreview.fusion.streaming import StreamingPitchFusion
from roadpreview.types import FusionMode

if TYPE_CHECKING:  # conftest is not importable at run time (--import-mode=importlib)
    from tests.fusion.conftest import FusionTestKit


DEG = math.pi / 180.0
FUSED, VISUAL_ONLY = int(FusionMode.FUSED), int(FusionMode.VISUAL_ONLY)
IMU_ONLY, DEGRADED = int(FusionMode.IMU_ONLY), int(FusionMode.DEGRADED)


# -- the supervisor alone -------------------------------------------------------------------
def _trusted(cfg: ModeConfig | None = None) -> ModeSupervisor:
    sup = ModeSupervisor(cfg or ModeConfig())
    assert sup.good_frame(0.0, True)
    return sup


def _trust(sup: ModeSupervisor) -> VisionTrust:
    """``sup.trust`` read afresh: mypy keeps an asserted ``sup.trust`` narrowed across the
    calls that change it."""
    return sup.trust


def test_short_failures_are_bridged_a_lasting_one_loses_vision() -> None:
    dt = 1 / 30
    sup = _trusted()
    sup.bad_frame(dt)
    assert sup.update_mode(True) is FusionMode.FUSED
    assert sup.good_frame(2 * dt, True)
    # every other frame failing (a rough road's wheel hop): still fused, the gyro bridges
    t = 2 * dt
    for _ in range(30):
        t += dt
        sup.bad_frame(t)
        t += dt
        assert sup.good_frame(t, True)
        assert sup.update_mode(True) is FusionMode.FUSED
    # failures for less than loss_time_s (0.3 s): bridged
    last_good = t
    for _ in range(8):  # 0.267 s
        t += dt
        sup.bad_frame(t)
    assert sup.update_mode(True) is FusionMode.FUSED
    # for loss_time_s: lost
    while t - last_good < sup.cfg.loss_time_s - 1e-9:
        t += dt
        sup.bad_frame(t)
    assert sup.update_mode(True) is FusionMode.IMU_ONLY
    assert sup.update_mode(False) is FusionMode.DEGRADED


def test_validation_survives_single_failures_not_a_long_gap() -> None:
    dt = 1 / 30
    sup = _trusted()
    t = 0.0
    while sup.trusted():
        t += dt
        sup.bad_frame(t)
    t += dt
    start = t
    assert not sup.good_frame(t, True)
    assert sup.trust is VisionTrust.VALIDATING
    t += dt
    sup.bad_frame(t)  # one failed frame: keeps validating
    assert sup.trust is VisionTrust.VALIDATING
    while not sup.good_frame(t + dt, True):
        t += dt
    t += dt
    assert t - start == pytest.approx(0.3, abs=dt / 2)
    # a gap longer than loss_time_s while validating: lost, validation starts over
    while sup.trusted():
        t += dt
        sup.bad_frame(t)
    t += dt
    assert not sup.good_frame(t, True)
    t += sup.cfg.loss_time_s + 0.1
    sup.bad_frame(t)
    assert _trust(sup) is VisionTrust.LOST


def test_revalidation_needs_consistent_frames_for_the_whole_period() -> None:
    sup = _trusted()
    sup.bad_frame(0.1)
    sup.bad_frame(0.1 + sup.cfg.loss_time_s)
    dt = 1 / 30
    t = 1.0
    for _ in range(9):  # 0.267 s of good frames: not yet
        assert not sup.good_frame(t, True)
        t += dt
    assert sup.trust is VisionTrust.VALIDATING
    assert not sup.good_frame(t, False)  # disagrees with the gyro: back to the start
    assert _trust(sup) is VisionTrust.LOST
    t += dt
    start = t
    while not sup.good_frame(t, True):
        t += dt
    assert t - start == pytest.approx(0.3, abs=dt / 2)
    assert sup.reacquired_t == t
    assert sup.update_mode(True) is FusionMode.FUSED


def test_no_visual_news_for_too_long_loses_vision() -> None:
    sup = _trusted()
    sup.no_news(0.2)
    assert sup.trusted()
    sup.no_news(0.3)
    assert not sup.trusted()


def test_repeatedly_gated_vision_is_lost() -> None:
    """Rejections in a row lose trusted vision only once they also span loss_time_s since
    the last accepted measurement (a burst while the ego crosses a bump is bridged)."""
    dt = 1 / 30
    sup = _trusted()
    sup.gated(False, 5, 0.0)
    t = 0.0
    for _ in range(4):
        t += dt
        sup.gated(True, 5, t)
    t += dt
    sup.gated(False, 5, t)
    assert sup.trusted()
    last_ok = t
    for _ in range(8):  # 8 rejections in 0.27 s: a burst
        t += dt
        sup.gated(True, 5, t)
    assert sup.trusted()
    while t - last_ok < sup.cfg.loss_time_s - 1e-9:
        t += dt
        sup.gated(True, 5, t)
    assert sup.trust is VisionTrust.LOST


# -- the whole fusion on synthetic streams ---------------------------------------------------
@pytest.mark.parametrize("backend", ["kalman", "factor-graph"])
def test_imu_timeout_gives_visual_only_and_back(kit: FusionTestKit, backend: str) -> None:
    """No gyro from 8 to 9 s: VISUAL_ONLY from the timeout (0.2 s) on, FUSED again when it
    returns, no step in the output, and the bias estimate survives the outage."""
    d = kit.synthetic(14.0, seed=2, imu_gaps=((8.0, 9.0),))
    r = kit.replay(make_fusion(backend), d, kit.front_end(d))
    t = r.t
    vis_only = t[r.mode == VISUAL_ONLY]
    vis_only = vis_only[vis_only > 5.0]
    assert vis_only.size > 0
    assert 8.0 + 0.2 <= vis_only[0] <= 8.0 + 0.2 + 2 / 30
    assert vis_only[-1] < 9.0 + 0.15
    assert np.all(r.mode[(t > 9.2)] == FUSED)
    err = r.error_deg(d)
    steps = np.abs(np.diff(err))[(t[1:] > 7.5) & (t[1:] < 9.5)]
    assert steps.max() < 0.02
    i8, i10 = np.searchsorted(t, 7.9), np.searchsorted(t, 10.0)
    assert abs(np.degrees(r.bias[i10] - r.bias[i8])) < 0.02


def test_neither_source_is_degraded_and_the_std_grows(kit: FusionTestKit) -> None:
    d = kit.synthetic(14.0, seed=5, loss=((8.0, 10.0),), imu_gaps=((8.5, 9.5),))
    r = kit.replay(make_fusion("kalman"), d, kit.front_end(d))
    deg = np.flatnonzero(r.mode == DEGRADED)
    deg = deg[r.t[deg] > 5.0]
    assert deg.size > 0
    assert 8.5 + 0.2 <= r.t[deg[0]] <= 8.5 + 0.3
    assert np.all(np.diff(r.std[deg]) > 0)
    # vision is lost loss_time_s after its last good frame
    loss = ModeConfig().loss_time_s
    assert np.all(r.mode[(r.t > 8.05 + loss) & (r.t < 8.6)] == IMU_ONLY)


def test_vision_that_disagrees_with_the_gyro_is_not_trusted_again(kit: FusionTestKit) -> None:
    """After a loss the front end reports good quality but its pitch is wrong (a rate error
    of 1 deg/s against its key frame): it is never re-validated; the gyro carries on."""
    d = kit.synthetic(16.0, seed=6, loss=((6.0, 8.0),))
    fe = kit.front_end(d)
    for i, m in enumerate(fe.meas):
        if m is not None and m.t > 8.0:
            fe.meas[i] = replace(m, dphi=m.dphi + 1.0 * DEG * (m.t - m.t_ref))
    r = kit.replay(make_fusion("kalman"), d, fe)
    after = r.t > 8.5
    assert np.all(r.mode[after] == IMU_ONLY)
    clean = kit.replay(make_fusion("kalman"), d, kit.front_end(d))
    assert np.all(clean.mode[r.t > 8.4] == FUSED)


def test_startup_is_visual_only_until_the_time_offset_is_known(kit: FusionTestKit) -> None:
    """The gyro is fused once the camera-IMU offset is estimated (a 30 ms error would pull
    the pitch); the start is then processed again with the gyro, without a step."""
    d = kit.synthetic(10.0, seed=7, offset_s=0.06)
    r = kit.replay(make_fusion("kalman"), d, kit.front_end(d))
    known = r.offset_conf > 0
    first = int(np.argmax(known))
    assert 1.0 < r.t[first] < 4.0
    assert np.all(r.mode[1:first] == VISUAL_ONLY)
    assert np.all(r.mode[first:] == FUSED)
    assert abs(r.offset[-1] - 0.06) < 0.002
    steps = np.abs(np.diff(r.error_deg(d)))
    assert steps[first - 3 : first + 3].max() < 0.02


def test_failures_pushed_explicitly_count_as_bad_frames(kit: FusionTestKit) -> None:
    d = kit.synthetic(6.0, seed=8, loss=((3.0, 4.0),))
    f = make_fusion("kalman")
    r = kit.replay(f, d, kit.front_end(d))
    i = np.searchsorted(r.t, 3.0)
    lost = i + int(np.argmax(r.mode[i:] == IMU_ONLY))
    # the failed frames are bridged until loss_time_s after the last good frame
    assert np.all(r.mode[i:lost] == FUSED)
    assert r.t[lost] - r.t[i - 1] == pytest.approx(ModeConfig().loss_time_s, abs=1.01 / 30)


def test_a_failed_fit_from_the_estimator_is_a_vision_failure() -> None:
    from roadpreview.pitch.base import PitchEstimate

    m = VisualPitch.from_estimate(0.0, 0.1, PitchEstimate.failed("too few points"))
    assert not m.quality_ok


@pytest.mark.parametrize("offset_s", [0.057, 0.12])
def test_imu_outage_with_an_offset_above_a_frame_recovers_within_1s(
    kit: FusionTestKit, offset_s: float
) -> None:
    """No gyro from 6 to 9 s on a drive whose IMU stamps lag the camera by more than a
    frame (57 ms, and near the search range's end), merged by stamp as the run loop does
    (no latency). The returning samples are not "late" (the blind frames spent no gyro):
    FUSED again within 1 s of the first sample after the outage, and to the end."""
    d = kit.synthetic(14.0, seed=2, offset_s=offset_s, imu_gaps=((6.0, 9.0),))
    fusion = make_fusion("kalman")
    r = kit.replay(fusion, d, kit.front_end(d), latency_s=0.0)
    first_good = d.imu_t[d.imu_t > 9.0][0] - offset_s  # on the camera's clock
    after = r.t >= first_good
    fused = r.t[after & (r.mode == FUSED)]
    assert fused.size > 0
    assert fused[0] - first_good < 1.0
    assert np.all(r.mode[r.t >= first_good + 1.0] == FUSED)
    assert isinstance(fusion, StreamingPitchFusion)
    assert fusion.stats.get("late", 0) == 0  # no sample of the drive rejected as late
    assert np.all(r.mode[(r.t > 6.0 + 0.25) & (r.t < 9.0)] == VISUAL_ONLY)
