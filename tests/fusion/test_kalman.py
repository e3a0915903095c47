"""The `kalman` back end: gyro prediction, stochastic clones, gating, measurement noise."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from roadpreview.fusion import VisualPitch, make_fusion
from roadpreview.fusion.config import AlignmentConfig, GyroConfig, KalmanConfig
from roadpreview.fusion.gyro import GyroHistory
from roadpreview.fusion.kalman import GyroPitchKalmanFilter, kalman_fusion
from roadpreview.fusion.streaming import StreamingPitchFusion

if TYPE_CHECKING:  # conftest is not importable at run time (--import-mode=importlib)
    from tests.fusion.conftest import FusionTestKit


DEG = math.pi / 180.0


def test_prediction_equals_filterpy_predict_at_imu_rate() -> None:
    """The gyro drives the prediction at IMU rate: composing the interval from the running
    integral gives what filterpy's predict gives sample by sample (x exactly; P to 1e-6:
    the bias walk enters in continuous time rather than in 10 ms steps: 1e-6 relative)."""
    rng = np.random.default_rng(1)
    cfg = GyroConfig(rate_hz=100.0)
    n = 37  # a frame interval and then some
    t = 0.01 * np.arange(1, n + 1)
    w = rng.normal(0.0, 0.05, n)
    g = GyroHistory(cfg)
    for ti, wi in zip(t, w, strict=True):
        g.push(float(ti), float(wi))

    ref = KalmanFilter(dim_x=2, dim_z=1)
    ref.x = np.array([[0.01], [0.002]])
    ref.P = np.diag([1e-6, 1e-5])
    q = 0.5 * cfg.noise_density**2
    for wi in w[1:]:  # each sample is the mean rate over the 10 ms before it
        F = np.array([[1.0, -0.01], [0.0, 1.0]])
        ref.predict(
            u=np.array([[wi]]),
            B=np.array([[0.01], [0.0]]),
            F=F,
            Q=np.diag([q * 0.01, cfg.bias_random_walk**2 * 0.01]),
        )

    kf = GyroPitchKalmanFilter(KalmanConfig(gyro=cfg))
    kf.start(float(t[0]))
    kf.kf.x[:2] = [[0.01], [0.002]]
    kf.kf.P[:2, :2] = np.diag([1e-6, 1e-5])
    mo = g.motion(float(t[0]), float(t[-1]))
    kf.step(float(t[-1]), mo.dG, mo.dV, mo.dM)  # (and a clone, which leaves phi and b alone)
    assert kf.kf.x[0, 0] == pytest.approx(ref.x[0, 0], abs=1e-15)
    assert kf.kf.x[1, 0] == pytest.approx(ref.x[1, 0], abs=1e-15)
    assert np.allclose(kf.kf.P[:2, :2], ref.P, rtol=1e-5, atol=1e-18)


@pytest.mark.parametrize("seed", range(4))
def test_lean_update_equals_filterpy_update(seed: int) -> None:
    """The update written out for the scalar relative measurement (h = e0 - e_j) gives
    filterpy's ``KalmanFilter.update(z, R, H)`` (Joseph form): x, P and K to 1e-12 relative,
    on random states of the filter's size and scales, for every clone slot; P stays exactly
    symmetric."""
    rng = np.random.default_rng(seed)
    f = GyroPitchKalmanFilter()
    n = f.kf.dim_x
    for j in range(2, n):
        f.start(0.0)
        scale = np.diag(10.0 ** rng.uniform(-5.0, -2.0, n))  # rad, rad/s: mixed magnitudes
        a = rng.standard_normal((n, n))
        P = scale @ (a @ a.T + 0.1 * np.eye(n)) @ scale
        P = 0.5 * (P + P.T)  # exactly symmetric, as the filter keeps it
        x = scale @ rng.standard_normal((n, 1))
        f.kf.P[:] = P
        f.kf.x[:] = x
        z, R = float(rng.normal(0.0, 1e-4)), float(10.0 ** rng.uniform(-12.0, -7.0))

        ref = KalmanFilter(dim_x=n, dim_z=1)
        ref.x, ref.P = x.copy(), P.copy()
        h = np.zeros((1, n))
        h[0, 0], h[0, j] = 1.0, -1.0
        ref.update(z, R=np.array([[R]]), H=h)

        y = z - (x[0, 0] - x[j, 0])
        K = f._update(j, y, R)[:, n] / y  # the change of x is K y
        p_ref = 0.5 * (ref.P + ref.P.T)
        assert np.abs(f.kf.P - p_ref).max() <= 1e-12 * np.abs(p_ref).max()
        assert np.abs(f.kf.x - ref.x).max() <= 1e-12 * np.abs(ref.x).max()
        assert np.abs(K - ref.K[:, 0]).max() <= 1e-12 * np.abs(ref.K).max()
        assert np.array_equal(f.kf.P, f.kf.P.T)


@pytest.mark.parametrize("seed", range(3))
def test_frame_sequence_equals_filterpy(seed: int) -> None:
    """The filter's own per-frame calls (`step`: prediction and clone in one pass; `update`:
    gate and Joseph-form update) against filterpy's ``KalmanFilter.predict`` and ``update``
    on the same random sequence of 300 frames: with and without gyro (ΔM = 0), key frames
    pinned and renewed, a measurement on most frames against a random clone. After every
    call x and P agree to 1e-12 relative (filterpy: ``predict`` with F and Q premultiplied
    by the clone's copy matrix C, ``update`` with ``h = e0 - e_j``)."""
    rng = np.random.default_rng(seed)
    f = GyroPitchKalmanFilter(KalmanConfig(gate_sigma=1e6))  # nothing gated: same sequence
    n = f.kf.dim_x
    t = 0.0
    f.start(t)
    ref = KalmanFilter(dim_x=n, dim_z=1)
    ref.x, ref.P = f.kf.x.copy(), f.kf.P.copy()
    qb = f.config.gyro.bias_random_walk**2

    def close() -> None:
        assert np.abs(f.kf.x - ref.x).max() <= 1e-12 * np.abs(ref.x).max()
        assert np.abs(f.kf.P - ref.P).max() <= 1e-12 * np.abs(ref.P).max()

    key = t
    for _ in range(300):
        dt = float(rng.uniform(0.02, 0.05))
        dM = 0.0 if rng.random() < 0.1 else dt
        dG = float(rng.normal(0.0, 2e-3)) if dM else 0.0
        dV = float(rng.uniform(1e-11, 1e-8))
        t += dt
        f.step(t, dG, dV, dM)
        j = 2 + f._slots.index(t)
        C = np.eye(n)
        C[j] = 0.0
        C[j, 0] = 1.0  # x_j <- x_0
        F = np.eye(n)
        F[0, 1] = -dM
        Q = np.zeros((n, n))
        Q[0, 0] = dV + qb * dM**3 / 3.0
        Q[0, 1] = Q[1, 0] = -qb * dM**2 / 2.0
        Q[1, 1] = qb * dt
        B = np.zeros((n, 1))
        B[0, 0] = 1.0
        ref.predict(u=np.array([[dG]]), B=C @ B, F=C @ F, Q=C @ Q @ C.T)
        close()
        if key not in f._slots or rng.random() < 0.05:
            key = t  # a new key frame
            continue
        f.pin_key(key)
        jk = 2 + f._slots.index(key)
        dphi = float(f.kf.x[0, 0] - f.kf.x[jk, 0] + rng.normal(0.0, 1e-4))
        R = float(10.0 ** rng.uniform(-10.0, -7.0))
        assert f.update(VisualPitch(key, t, dphi, math.sqrt(R)), R)
        h = np.zeros((1, n))
        h[0, 0], h[0, jk] = 1.0, -1.0
        ref.update(np.array([[dphi]]), R=np.array([[R]]), H=h)
        close()
    assert np.array_equal(f.kf.P, f.kf.P.T)


def test_clone_slot_is_the_oldest_but_the_pinned_key() -> None:
    """The clone of a new frame replaces the oldest clone, or the second oldest when the oldest
    is the pinned key frame (`min` and `sorted` written plainly here), through fills from the
    initial -inf, changing pins and slots put back from a snapshot."""
    rng = np.random.default_rng(5)
    f = GyroPitchKalmanFilter()
    f.start(0.0)
    ref = list(f._slots)
    t = 0.0
    for step in range(2000):
        t += float(rng.uniform(0.01, 0.05))
        if step % 3 == 0:  # pin a frame's clone (as `pin_key`: a frame time), or nothing
            frames = [x for x in ref if x > -math.inf]
            f._pinned = float(rng.choice(frames)) if frames and rng.random() < 0.8 else math.nan
        if step % 97 == 0:  # a snapshot put back: a new list
            f._slots = list(f._slots)
        oldest = min(ref)
        if oldest == f._pinned:
            oldest = sorted(ref)[1]
        expected = ref.index(oldest)
        ref[expected] = t
        assert f._clone_slot(t) == expected
        assert f._slots == ref


def test_arrays_assigned_to_the_filterpy_filter_are_taken_up() -> None:
    """kf.P and kf.x are views of the filter's storage; a caller that assigns new arrays
    (filterpy style) is noticed at the next step, with the same result as writing in place."""
    a, b = GyroPitchKalmanFilter(), GyroPitchKalmanFilter()
    for f in (a, b):
        f.start(0.0)
    a.kf.x[0, 0] = 0.01
    b.kf.x = np.array(b.kf.x)
    b.kf.x[0, 0] = 0.01
    b.kf.P = b.kf.P.copy()
    for f in (a, b):
        f.step(0.1, 0.001, 1e-9, 0.1)
        f._update(2, 1e-4, 1e-10)
    assert np.array_equal(a.kf.P, b.kf.P)
    assert np.array_equal(a.kf.x, b.kf.x)
    assert b.kf.x[0, 0] != 0.01


def test_a_copied_filter_runs_on_as_the_original(kit: FusionTestKit) -> None:
    """Deep copies and pickles keep the filter's storage and remake its views: a copy taken
    mid-drive continues exactly as the original."""
    import copy
    import pickle

    d = kit.synthetic(6.0, seed=2)
    fe = kit.front_end(d)
    f = make_fusion("kalman")
    cut = 90
    first = kit.replay(f, d, replace(fe, frame_t=fe.frame_t[:cut], meas=fe.meas[:cut]))
    assert np.isfinite(first.phi).all()
    copies = [copy.deepcopy(f), pickle.loads(pickle.dumps(f))]
    rest = replace(fe, frame_t=fe.frame_t[cut:], meas=fe.meas[cut:], failure=fe.failure[cut:])
    gyro_after = d.imu_t > fe.frame_t[cut - 1] + 0.1
    runs = [
        kit.replay(g, d, rest, imu_t=d.imu_t[gyro_after], imu_rate=d.imu_rate[gyro_after])
        for g in (f, *copies)
    ]
    for r in runs[1:]:
        assert np.array_equal(r.phi, runs[0].phi)
        assert np.array_equal(r.std, runs[0].std)


def test_relative_measurements_recover_the_pitch_exactly(kit: FusionTestKit) -> None:
    """Noiseless gyro and vision against key frames renewed every 0.5 s: the output is the
    truth to within what one gyro sample resolves between frame times (a relative
    measurement used as absolute, or a key frame re-anchored wrongly, would be off by the
    key frame's pitch, up to a degree here)."""
    d = kit.synthetic(8.0, bias_deg_s=0.0, gyro_noise_deg_s=0.0, offset_s=0.0)
    f = make_fusion("kalman", alignment={"enabled": False})
    r = kit.replay(f, d, kit.front_end(d, std_deg=1e-6, key_every_s=0.5))
    err = np.degrees(np.abs(r.phi - d.pitch))
    assert err.max() < 0.003
    assert np.degrees(np.ptp(d.pitch)) > 0.5


def test_renewing_the_key_frame_injects_no_step(kit: FusionTestKit) -> None:
    """Noisy vision, key frames every 2 s: the frame-to-frame error change at a key renewal
    is no larger than anywhere else."""
    d = kit.synthetic(20.0, seed=3)
    fe = kit.front_end(d, key_every_s=2.0)
    r = kit.replay(make_fusion("kalman"), d, fe)
    derr = np.abs(np.diff(r.error_deg(d)))
    refs = np.array([m.t_ref if m is not None else np.nan for m in fe.meas])
    renewal = np.flatnonzero(np.diff(refs) > 0) + 1  # first frame against a new key
    renewal = renewal[r.t[renewal] > 4.0]
    others = np.setdiff1d(np.arange(120, derr.size), renewal - 1)
    assert renewal.size >= 6
    assert derr[renewal - 1].max() < 0.01
    assert derr[renewal - 1].max() < 3.0 * np.percentile(derr[others], 99)


def test_an_outlier_is_gated(kit: FusionTestKit) -> None:
    """A gross visual error (+0.5 deg on one frame) is rejected by the Mahalanobis gate."""
    d = kit.synthetic(12.0, seed=4)
    i = 300
    fe = kit.front_end(d, outliers={i: 0.5 * DEG})
    known = {
        "alignment": {"enabled": False, "initial_offset_s": d.time_offset_s, "prior_std_s": 0.0005}
    }
    f = make_fusion("kalman", **known)
    assert isinstance(f, StreamingPitchFusion)  # what make_fusion builds for this back end
    r = kit.replay(f, d, fe)
    err = np.abs(r.error_deg(d))
    assert f.stats.get("gated") == 1
    assert err[i] < 0.02
    # exactly as if vision had failed on that frame
    fe_fail = kit.front_end(d)
    fe_fail.meas[i] = None
    fe_fail.failure[i] = "poor fit"
    without = kit.replay(make_fusion("kalman", **known), d, fe_fail)
    assert np.array_equal(r.phi, without.phi)


def _one_update(inlier_ratio: float) -> float:
    """Correction of the pitch by one visual measurement 0.05 deg away from the prediction."""
    f = kalman_fusion(KalmanConfig(alignment=AlignmentConfig(enabled=False)))
    f.estimate(0.0)
    for k in range(1, 11):
        f.push_gyro(k * 0.01, 0.0)
    f.push_visual(VisualPitch(0.0, 0.1, 0.05 * DEG, 0.01 * DEG, inlier_ratio, True))
    return f.estimate(0.1).phi


def test_measurement_noise_follows_the_estimator_std_and_inlier_ratio() -> None:
    """Per-call R: the estimator's std, inflated when few points are inliers."""
    good, poor = _one_update(0.9), _one_update(0.2)
    assert 0 < poor < good < 0.05 * DEG


def test_the_filter_is_filterpys() -> None:
    f = GyroPitchKalmanFilter()
    assert isinstance(f.kf, KalmanFilter)
    assert f.kf.dim_x == 2 + KalmanConfig().n_clones
