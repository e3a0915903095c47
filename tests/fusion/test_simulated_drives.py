"""The issue's accuracy targets on simulated drives (simulator truth, smartphone-grade gyro).

Pitch errors are against the simulator's camera pitch relative to the first
frame. Visual measurements come from the truth as the vision front end would
deliver them (``conftest.front_end_measurements``: key frames every 2 s,
0.005 deg noise, failures where fog, night or a tunnel remove the texture).
Each test prints the figure it measured (``pytest -s``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
import pytest

from roadpreview.fusion import make_fusion
from roadpreview.types import FusionMode

if TYPE_CHECKING:  # conftest is not importable at run time (--import-mode=importlib)
    from tests.fusion.conftest import Drive, FrontEnd, FusionTestKit, Replay

pytestmark = pytest.mark.slow  # a simulated drive rendered and replayed: scheduled first

DEG = math.pi / 180.0
FUSED, IMU_ONLY = int(FusionMode.FUSED), int(FusionMode.IMU_ONLY)


@pytest.fixture(scope="module")
def drive(sim_drive: Callable[..., Drive]) -> Drive:
    """60 s ``texture-loss`` drive: fog 7-19 s, tunnel 27-37 s, night 45-56 s; the recorded
    smartphone IMU (imu.csv) with a 0.5 deg/s pitch-rate bias plus the phone's random walk."""
    return sim_drive("texture-loss", seed=0, duration_s=60.0, pitch_bias_deg_s=0.5)


@pytest.fixture(scope="module")
def kalman_run(drive: Drive, kit: FusionTestKit) -> tuple[FrontEnd, Replay]:
    fe = kit.front_end(drive)
    return fe, kit.replay(make_fusion("kalman"), drive, fe)


def test_fused_error_rms_within_one_second_windows(
    drive: Drive, kit: FusionTestKit, kalman_run: tuple[FrontEnd, Replay]
) -> None:
    """FUSED mode: the error RMS within every 1 s window (the detector's window, eq. 1) is
    at most 0.02 deg. Before the first texture loss nothing has drifted and the absolute
    error meets it too; after a loss the pitch level carries the drift of the loss (the
    relative visual pitch cannot see it), which the 1 s window removes."""
    _, r = kalman_run
    err = r.error_deg(drive)
    fused = (r.mode == FUSED) & (r.offset_conf > 0)
    within = kit.windowed_rms_deg(err, r.t, fused, demean=True)
    first_loss = drive.frame_t[np.argmax(~drive.texture)]
    absolute = kit.windowed_rms_deg(err, r.t, fused & (r.t < first_loss))
    print(
        f"\nFUSED 1 s windows: {within.size}, error RMS within a window max"
        f" {within.max():.4f} deg, median {np.median(within):.4f} deg; absolute before the"
        f" first loss ({absolute.size} windows) max {absolute.max():.4f} deg"
    )
    assert within.size >= 20
    assert within.max() <= 0.02
    assert absolute.size >= 3
    assert absolute.max() <= 0.02


def test_bias_converges_within_ten_seconds(
    drive: Drive, kalman_run: tuple[FrontEnd, Replay]
) -> None:
    """The gyro bias (0.5 deg/s plus walk) is estimated within 0.05 deg/s after 10 s."""
    _, r = kalman_run
    true_bias = np.interp(r.t, drive.imu_t - drive.time_offset_s, drive.imu_bias)
    err = np.degrees(np.abs(r.bias - true_bias))
    after = r.t >= 10.0
    print(
        f"\nbias error after 10 s: max {err[after].max():.4f} deg/s (at 10 s"
        f" {err[np.argmax(after)]:.4f})"
    )
    assert err[after].max() < 0.05


def test_mode_switches_where_texture_is_lost_and_regained(
    drive: Drive, kalman_run: tuple[FrontEnd, Replay]
) -> None:
    """FUSED -> IMU_ONLY within 0.5 s of each truth texture loss and back within 0.5 s of the
    texture returning (after re-validation), nothing else after the start."""
    _, r = kalman_run
    t = drive.frame_t
    lost = t[1:][np.diff(drive.texture.astype(int)) < 0]
    regained = t[1:][np.diff(drive.texture.astype(int)) > 0]
    mode = r.mode.astype(int)
    ch = np.flatnonzero(np.diff(mode)) + 1
    switches = [(t[i], mode[i - 1], mode[i]) for i in ch if t[i] > 5.0]
    to_imu = [s[0] for s in switches if s[2] == IMU_ONLY]
    to_fused = [s[0] for s in switches if s[2] == FUSED]
    d_loss = np.array(to_imu) - lost
    d_regain = np.array(to_fused) - regained
    print(
        f"\nswitch delays: to IMU_ONLY {np.round(d_loss, 3)} s, back to FUSED"
        f" {np.round(d_regain, 3)} s"
    )
    assert len(switches) == 2 * lost.size
    assert len(to_imu) == lost.size
    assert len(to_fused) == regained.size
    assert np.all((d_loss >= 0) & (d_loss <= 0.5))
    assert np.all((d_regain >= 0) & (d_regain <= 0.5))


def test_no_step_in_the_output_at_a_mode_switch(
    drive: Drive, kalman_run: tuple[FrontEnd, Replay]
) -> None:
    """At every switch the output moves by what the camera moved, within 0.02 deg."""
    _, r = kalman_run
    mode = r.mode.astype(int)
    ch = np.flatnonzero(np.diff(mode)) + 1
    ch = ch[r.t[ch] > 5.0]
    jumps = [
        np.degrees((r.phi[i] - r.phi[i - 1]) - (drive.pitch[i] - drive.pitch[i - 1])) for i in ch
    ]
    print(f"\noutput step at switches beyond the true motion: max {np.abs(jumps).max():.4f} deg")
    assert np.abs(jumps).max() < 0.02


def test_imu_only_covariance_grows_honestly(
    drive: Drive, kalman_run: tuple[FrontEnd, Replay]
) -> None:
    """While vision is lost the std grows, and it covers the drift (within 3 sigma)."""
    _, r = kalman_run
    err = r.error_deg(drive)
    loss = r.mode == IMU_ONLY
    segs = np.flatnonzero(np.diff(np.concatenate([[0], loss.astype(int), [0]])))
    for a, b in zip(segs[::2], segs[1::2], strict=True):
        growth = np.degrees(r.std[a:b])
        assert np.all(np.diff(growth) >= -1e-9)
        drift = np.abs(err[a:b] - err[a - 1])
        sigma = np.sqrt(np.maximum(growth**2 - np.degrees(r.std[a - 1]) ** 2, 1e-12))
        assert np.all(drift[5:] <= 3 * sigma[5:] + 0.005)


def test_texture_loss_fused_beats_drifting_imu_only(
    imu_realisations: Callable[..., list[Drive]], kit: FusionTestKit
) -> None:
    """The paper's observation reproduced and beaten, over 16 IMU realisations of one drive
    (noise, bias walk, clock offset). During the 10.2 s tunnel the integrated gyro with its
    uncorrected 0.5 deg/s bias drifts past 1 deg every time; the fused pitch drifts less than
    0.1 deg in the median. Not every time: with this phone's bias random walk
    (0.003 deg/s/sqrt(s)) and white noise the drift over 10 s has a std of about 0.07 deg
    whatever the filter does (docs/fusion.md); with an automotive gyro see the next test."""
    drives = imu_realisations("texture-loss", 0, list(range(16)))
    tunnel = kit.segments(~drives[0].texture)[1]
    fused, imu = [], []
    for d in drives:
        fe = kit.front_end(d)
        e = kit.replay(make_fusion("kalman"), d, fe).error_deg(d)
        ei = kit.replay(make_fusion("imu-only"), d, fe).error_deg(d)
        a, b = tunnel
        fused.append(np.abs(e[a:b] - e[a - 1]).max())
        imu.append(np.abs(ei[a:b] - ei[a - 1]).max())
    fused_a, imu_a = np.array(fused), np.array(imu)
    print(
        f"\ntunnel {drives[0].frame_t[tunnel[1] - 1] - drives[0].frame_t[tunnel[0]]:.1f} s:"
        f" fused drift median {np.median(fused_a):.3f} deg,"
        f" 90 % {np.percentile(fused_a, 90):.3f},"
        f" max {fused_a.max():.3f}, below 0.1 deg in {np.mean(fused_a < 0.1):.0%};"
        f" imu-only min {imu_a.min():.2f} deg"
    )
    assert imu_a.min() > 1.0
    assert np.median(fused_a) < 0.1
    assert np.mean(fused_a < 0.1) >= 0.7
    assert fused_a.max() < 0.25


def test_texture_loss_with_an_automotive_gyro(
    imu_realisations: Callable[..., list[Drive]], kit: FusionTestKit
) -> None:
    """The same 0.5 deg/s bias on an automotive-grade gyro: every 10 s loss under 0.1 deg."""
    drives = imu_realisations("texture-loss", 0, list(range(6)), grade="automotive")
    worst = 0.0
    for d in drives:
        fe = kit.front_end(d)
        fusion = make_fusion(
            "kalman", gyro={"noise_density": 0.005 * DEG, "bias_random_walk": 3e-4 * DEG}
        )
        e = kit.replay(fusion, d, fe).error_deg(d)
        for a, b in kit.segments(~d.texture):
            worst = max(worst, float(np.abs(e[a:b] - e[a - 1]).max()))
    print(f"\nautomotive gyro: worst drift over the three ~10 s losses {worst:.3f} deg")
    assert worst < 0.1


@pytest.mark.parametrize("seed", [0, 3, 5])
def test_time_offset_within_five_ms(
    sim_drive: Callable[..., Drive], kit: FusionTestKit, seed: int
) -> None:
    """``wild`` drives (recorded IMU, random 0-80 ms clock offset): the estimate is within
    5 ms of the simulator's offset, with a high confidence."""
    d = sim_drive("wild", seed=seed, duration_s=30.0, pitch_bias_deg_s=None)
    r = kit.replay(make_fusion("kalman"), d, kit.front_end(d))
    err_ms = abs(r.offset[-1] - d.time_offset_s) * 1e3
    print(
        f"\nwild seed {seed}: true offset {d.time_offset_s * 1e3:.1f} ms, estimated"
        f" {r.offset[-1] * 1e3:.2f} ms (error {err_ms:.2f} ms,"
        f" confidence {r.offset_conf[-1]:.3f})"
    )
    assert err_ms < 5.0
    assert r.offset_conf[-1] > 0.9


def test_time_offset_over_many_clock_offsets(
    imu_realisations: Callable[..., list[Drive]], kit: FusionTestKit
) -> None:
    """Twelve clock offsets drawn in 0-80 ms on one drive: every estimate within 5 ms."""
    errs = []
    for d in imu_realisations("wild", 1, list(range(12)), duration_s=30.0):
        r = kit.replay(make_fusion("kalman"), d, kit.front_end(d))
        errs.append(abs(r.offset[-1] - d.time_offset_s) * 1e3)
    print(
        f"\ntime offset error over 12 offsets: max {max(errs):.2f} ms, median"
        f" {np.median(errs):.2f} ms"
    )
    assert max(errs) < 5.0


def test_kalman_and_factor_graph_agree(
    drive: Drive, kit: FusionTestKit, kalman_run: tuple[FrontEnd, Replay]
) -> None:
    """The same drive through both back ends: within 0.01 deg at every frame, same modes."""
    fe, rk = kalman_run
    rg = kit.replay(make_fusion("factor-graph"), drive, fe)
    diff = np.degrees(np.abs(rk.phi - rg.phi))
    print(
        f"\nkalman vs factor-graph: max {diff.max():.4f} deg, bias max"
        f" {np.degrees(np.abs(rk.bias - rg.bias)).max():.5f} deg/s"
    )
    assert diff.max() < 0.01
    assert np.array_equal(rk.mode, rg.mode)
    assert np.degrees(np.abs(rk.bias - rg.bias)).max() < 0.005


def test_gyro_arriving_after_the_frame_is_extrapolated_then_committed(
    drive: Drive, kit: FusionTestKit
) -> None:
    """Frames estimated before their gyro has arrived (no latency, stamps 0-80 ms late):
    the held-rate extrapolation costs little, and the committed result is unaffected."""
    fe = kit.front_end(drive)
    late = kit.replay(make_fusion("kalman"), drive, fe, latency_s=0.0)
    err = late.error_deg(drive)
    fused = (late.mode == FUSED) & (late.offset_conf > 0)
    within = kit.windowed_rms_deg(err, late.t, fused, demean=True)
    print(f"\nno latency: FUSED within-window RMS max {within.max():.4f} deg")
    assert within.max() <= 0.03
