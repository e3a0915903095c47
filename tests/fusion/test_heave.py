"""The camera heave observer: a known heave from a noisy phone accelerometer, the lever arm,
NaN / gaps / late samples, and the heave term that never jumps (docs/method.md, "Heave")."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
from numpy.typing import NDArray

from roadpreview.compensation import HeaveTerm, compensation, heave_term_px
from roadpreview.errors import ConfigError
from roadpreview.fusion.heave import HeaveConfig, HeaveEstimate, HeaveObserver
from roadpreview.types import ImuSample

G = 9.80665
NAN3 = (math.nan, math.nan, math.nan)
#: a phone in a windscreen holder (sim.imu.ImuConfig.smartphone): 400 µg/√Hz, 0.2 m/s² bias,
#: bias random walk 1e-3 m/s²/√s, 104 Hz
NOISE_DENSITY = 400e-6 * G
RATE_HZ = 104.0
FPS = 30.0

Array = NDArray[np.float64]


def _bump_response(t: Array, t0: float, a: float, f: float, zeta: float = 0.3) -> Array:
    """The body's heave after crossing a bump at t0: a damped ~1.3 Hz oscillation."""
    wn = 2 * np.pi * f
    wd = wn * math.sqrt(1 - zeta**2)
    tt = np.clip(t - t0, 0.0, None)
    return np.where(t >= t0, a * np.exp(-zeta * wn * tt) * np.sin(wd * tt), 0.0)


def _interval_means(fine_t: Array, x: Array, t: Array) -> Array:
    """Means of ``x`` over the sample interval before each ``t`` (an IMU's averaging)."""
    dt = fine_t[1] - fine_t[0]
    cum = np.concatenate([[0.0], np.cumsum(x[:-1] * dt)])
    means: Array = (np.interp(t, fine_t, cum) - np.interp(t - 1 / RATE_HZ, fine_t, cum)) * RATE_HZ
    return means


def _windowed_std(x: Array, n: int = 30) -> Array:
    """std of the last n samples at each sample (NaN while any is missing)."""
    out = np.full(len(x), np.nan)
    for i in range(n - 1, len(x)):
        w = x[i - n + 1 : i + 1]
        if np.isfinite(w).all():
            out[i] = w.std()
    return out


def _run(
    observer: HeaveObserver,
    t: Array,
    accel_z: Array,
    *,
    accel_x: Array | None = None,
    pitch_rate: Array | None = None,
    pitch: Array | None = None,
    frames: Array,
) -> list[HeaveEstimate]:
    """Feed the samples in time order; query at each frame time once the IMU has passed it."""
    out: list[HeaveEstimate] = []
    k = 0
    for i, ti in enumerate(t):
        if pitch is not None:
            observer.set_pitch(float(pitch[i]))
        rates = NAN3 if pitch_rate is None else (0.0, float(pitch_rate[i]), 0.0)
        fx = 0.0 if accel_x is None else float(accel_x[i])
        observer.push(ImuSample(float(ti), rates, (fx, 0.0, float(accel_z[i]))))
        while k < len(frames) and frames[k] <= ti:
            out.append(observer.at(float(frames[k])))
            k += 1
    return out


def _phone_drive(seed: int) -> tuple[Array, Array, Array, Array]:
    """20 s: a hill (0.8 m, 40 s period), a bump crossing at 8 s (3 cm, 1.3 Hz) and a dip
    at 13 s (2 cm, 1.6 Hz); a phone accelerometer. Returns the fine time, the heave without
    the hill (what the observer should give), the sample times and the vertical force."""
    rng = np.random.default_rng(seed)
    fine = np.arange(0.0, 20.0, 1e-3)
    bumps = _bump_response(fine, 8.0, 0.03, 1.3) + _bump_response(fine, 13.0, -0.02, 1.6)
    z = bumps + 0.8 * np.sin(2 * np.pi * fine / 40.0)
    acc = np.gradient(np.gradient(z, fine), fine)
    t = np.arange(1, int(20.0 * RATE_HZ)) / RATE_HZ
    bias = 0.2 + np.cumsum(1e-3 * math.sqrt(1 / RATE_HZ) * rng.standard_normal(len(t)))
    noise = NOISE_DENSITY * math.sqrt(RATE_HZ / 2) * rng.standard_normal(len(t))
    return fine, bumps, t, G + _interval_means(fine, acc, t) + bias + noise


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_bump_crossing_is_recovered_from_a_phone_accelerometer(seed: int) -> None:
    """Over every 1 s window (the detector's) the error's spread stays below 4.5 mm while the
    heave's own spread reaches 8.5 mm: the high-pass costs some of the slow part of the
    response (its phase lead at 1-2 Hz), noise and bias walk a fraction of a mm. The
    40 s hill is not heave: the lead rides on it too (docs/method.md)."""
    fine, bumps, t, fz = _phone_drive(seed)
    frames = np.arange(0.0, 19.9, 1 / FPS)
    est = _run(HeaveObserver(), t, fz, frames=frames)
    got = np.array([e.dz_m for e in est])
    truth = np.interp(frames[: len(got)], fine, bumps)
    assert not any(e.available for e in est if e.t < 3.0)  # warming up
    assert all(e.available for e in est if e.t >= 3.05)
    err = _windowed_std(got - truth)
    spread = _windowed_std(truth)
    crossing = (frames[: len(got)] > 7.5) & (frames[: len(got)] < 16.0)
    assert np.nanmax(spread[crossing]) == pytest.approx(0.0085, abs=0.0005)
    assert np.nanmax(err[crossing]) < 0.0045
    assert np.nanmax(err[crossing]) < 0.5 * np.nanmax(spread[crossing])
    calm = (frames[: len(got)] > 4.5) & ~crossing
    assert np.nanmax(err[calm]) < 0.0015  # noise, bias walk and the hill's leak


def test_nose_up_raises_a_camera_ahead_of_the_imu_by_the_lever_arm() -> None:
    """The IMU at the centre of gravity does not heave; the body pitches ±1° at 1.5 Hz, so a
    camera L = 1 m ahead rises by L sin φ (17 mm): recovered to 2.5 mm over the window. The
    gravity in the pitched body axes (f_x = g sin φ, f_z = g cos φ) is rotated back by φ.
    Without the lever arm (L = 0) the estimate stays below 0.5 mm."""
    fine = np.arange(0.0, 12.0, 1e-3)
    env = np.clip((fine - 2.0) / 2.0, 0.0, 1.0)
    phi_f = math.radians(1.0) * env * np.sin(2 * np.pi * 1.5 * fine)
    t = np.arange(1, int(12.0 * RATE_HZ)) / RATE_HZ
    phi = np.interp(t, fine, phi_f)
    rate = _interval_means(fine, np.gradient(phi_f, fine), t)
    frames = np.arange(0.0, 11.9, 1 / FPS)
    results = {}
    for lever in (1.0, 0.0):
        obs = HeaveObserver(HeaveConfig(imu_to_camera_forward_m=lever))
        est = _run(
            obs,
            t,
            G * np.cos(phi),
            accel_x=G * np.sin(phi),
            pitch_rate=rate,
            pitch=phi,
            frames=frames,
        )
        assert all(e.lever_arm for e in est)
        results[lever] = np.array([e.dz_m for e in est])
    ff = frames[: len(results[1.0])]
    truth = 1.0 * np.sin(np.interp(ff, fine, phi_f))
    late = ff > 6.0
    err = _windowed_std(results[1.0] - truth)
    assert np.nanmax(_windowed_std(truth)[late]) == pytest.approx(0.0123, abs=0.0005)
    assert np.nanmax(err[late]) < 0.0025
    assert np.corrcoef(results[1.0][late], truth[late])[0, 1] > 0.98  # the sign: nose up, up
    assert np.nanmax(np.abs(results[0.0][late])) < 0.0005


def test_no_accelerometer_means_no_heave() -> None:
    """Rates only (an IMU that sends no IMU_ACCEL, or NaN accelerations): never available."""
    obs = HeaveObserver()
    for k in range(600):
        obs.push(ImuSample(k / 100.0, (0.0, 0.01, 0.0), NAN3))
    e = obs.at(5.0)
    assert not e.available
    assert math.isnan(e.dz_m)
    assert e.reason == "no acceleration"


def test_a_gap_restarts_the_filter_and_is_logged(caplog: pytest.LogCaptureFixture) -> None:
    """0.5 s without accelerometer: the estimate is unavailable for the warm-up, then back."""
    obs = HeaveObserver()
    t = np.concatenate([np.arange(1, 600) / 100.0, 6.5 + np.arange(0, 600) / 100.0])
    seen: dict[float, HeaveEstimate] = {}
    with caplog.at_level(logging.WARNING, logger="roadpreview.fusion.heave"):
        for ti in t:
            obs.push(ImuSample(float(ti), NAN3, (0.0, 0.0, G)))
            for tq in (5.5, 6.2, 9.0, 9.6):
                if abs(ti - tq) < 1e-9 or (tq == 6.2 and abs(ti - 6.5) < 1e-9):
                    seen[tq] = obs.at(tq)
    assert obs.counts["gap"] == 1
    assert "restarting" in caplog.text
    assert seen[5.5].available
    assert not seen[6.2].available  # inside the gap: before the restarted history
    assert not seen[9.0].available  # 2.5 s after the restart: warming up
    assert seen[9.0].reason == "warming up"
    assert seen[9.6].available
    assert seen[9.6].dz_m == pytest.approx(0.0, abs=1e-9)  # the gravity mean is kept


def test_late_and_broken_samples_are_dropped(caplog: pytest.LogCaptureFixture) -> None:
    obs = HeaveObserver()
    with caplog.at_level(logging.WARNING, logger="roadpreview.fusion.heave"):
        for k in range(1, 500):
            obs.push(ImuSample(k / 100.0, NAN3, (0.0, 0.0, G)))
        obs.push(ImuSample(4.0, NAN3, (0.0, 0.0, G + 5.0)))  # late
        obs.push(ImuSample(5.0, NAN3, (0.0, 0.0, 1e6)))  # absurd
        obs.push(ImuSample(5.0, NAN3, (0.0, 0.0, math.inf)))
    assert obs.counts["out_of_order"] == 1
    assert obs.counts["bad_accel"] == 2
    assert "not after the previous one" in caplog.text
    assert obs.at(4.95).dz_m == pytest.approx(0.0, abs=1e-9)


def test_queries_interpolate_and_extrapolate_a_little() -> None:
    """A 2 cm heave at 1.5 Hz: frame times between samples are interpolated; up to 0.1 s
    ahead of the newest sample the velocity extrapolates (the IMU stamps of a frame's
    instant arrive after the frame when they lag), within ½ a δt² (0.8 mm for 30 ms) of
    what the samples say once they arrived; farther ahead it is unavailable."""
    w = 2 * np.pi * 1.5
    t = np.arange(1, 801) / 100.0
    fz = G - 0.02 * w**2 * np.sin(w * t)  # z = 0.02 sin(w t), sampled as point values
    obs = HeaveObserver()
    for ti, a in zip(t, fz, strict=True):
        obs.push(ImuSample(float(ti), NAN3, (0.0, 0.0, float(a))))
        if abs(ti - 7.0) < 1e-9:
            ahead = obs.at(7.03)
            assert ahead.available
            far = obs.at(7.2)
            assert not far.available
            assert "no acceleration for" in far.reason
    later = obs.at(7.03)
    assert ahead.dz_m == pytest.approx(later.dz_m, abs=0.0008)
    z = {tq: obs.at(tq).dz_m for tq in (7.5, 7.505, 7.51)}
    assert z[7.505] == pytest.approx(0.5 * (z[7.5] + z[7.51]), rel=1e-9)


def test_the_config_is_checked() -> None:
    with pytest.raises(ConfigError, match="history_s"):
        HeaveObserver(HeaveConfig(history_s=0.05, max_gap_s=0.1))
    with pytest.raises(ConfigError, match="cutoff_hz"):
        HeaveObserver(HeaveConfig(cutoff_hz=0.0))


# --- the term in the image ----------------------------------------------------------------------


def test_a_rising_camera_moves_the_lead_down_and_the_compensation_removes_it() -> None:
    """Camera up by 2 cm, lead at 10 m, f = 1000 px: the lead's row grows by f Δz / d = 2 px
    (v down); y_c = y - f tan φ - f Δz / d takes it back. Unknown Δz or d: no heave term."""
    f, dz, d = 1000.0, 0.02, 10.0
    assert heave_term_px(dz, d, f) == pytest.approx(2.0)
    y0 = 360.0
    assert compensation(y0 + 2.0, 0.0, f, heave_m=dz, distance_m=d) == pytest.approx(y0)
    out = compensation(
        [y0, y0, y0], 0.0, f, heave_m=[math.nan, dz, dz], distance_m=[d, math.nan, 0]
    )
    np.testing.assert_allclose(out, y0)
    phi = math.radians(1.0)
    both = compensation(y0 + f * math.tan(phi) + 2.0, phi, f, heave_m=dz, distance_m=d)
    assert both == pytest.approx(y0)


def test_the_heave_term_holds_while_unknown_and_never_jumps() -> None:
    term = HeaveTerm(HeaveConfig(), focal_px=1000.0)

    def est(dz: float) -> HeaveEstimate:
        return HeaveEstimate(0.0, dz, math.isfinite(dz), True)

    assert term.update(0.0, est(0.01), 10.0, False) == pytest.approx(0.0)  # starts at 0
    assert term.update(0.1, est(0.03), 10.0, False) == pytest.approx(2.0)  # f (0.03 - 0.01) / 10
    assert term.update(0.2, est(math.nan), 10.0, False) == pytest.approx(2.0)  # held
    assert not term.active
    assert term.update(0.3, est(0.05), 10.0, False) == pytest.approx(2.0)  # resumes from there
    assert term.update(0.4, est(0.04), 20.0, False) == pytest.approx(1.5)  # 2 + f (-0.01) / 20
    # a missing distance: the last one for 0.5 s, then held
    assert term.update(0.8, est(0.06), math.nan, False) == pytest.approx(2.5)
    assert term.update(1.0, est(0.08), math.nan, False) == pytest.approx(2.5)
    assert term.update(1.1, est(0.08), 3.0, False) == pytest.approx(2.5)  # too close: held
    assert term.update(1.2, est(0.02), 20.0, True) == pytest.approx(0.0)  # a new target
