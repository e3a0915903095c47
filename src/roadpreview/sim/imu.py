"""Motion sensors of the simulated car: a 6-DoF MEMS IMU and the ESC's speed measurements.

Both models take ground truth on a fine time grid (e.g. 1 kHz, from the
vehicle dynamics) and return what the sensor would deliver: samples at the
sensor's rate, with the sensor's time stamps, noise, bias, range and
resolution, together with the truth at the same instants.

Axes and signs (``docs/method.md``, ``docs/can-interface.md``):

* The IMU's axes are the body axes of ISO 8855: x forward, y LEFT, z UP,
  right-handed. ``gyro_rad_s`` and ``accel_m_s2`` of the samples are in
  these axes, as the silicon measures them (and as the IMU CSV stores them).
  A chip mounted rotated (``ImuConfig.mount_ypr_deg``) measures in its own
  axes instead: ``v_chip = M^T v_body`` with M = `ImuConfig.mount_rotation`
  (what ``roadpreview calibrate`` estimates and a mapping's ``[mount]`` undoes).
* roadpreview's rates are [roll rate, pitch rate, yaw rate] with roll
  positive left side up, pitch positive NOSE UP, yaw positive turning left.
  Roll and yaw rates are +omega_x and +omega_z; the pitch rate is
  **-omega_y**, because a right-handed rotation about y (pointing left)
  lowers the nose. `RATE_SIGNS` converts one into the other (it is its own
  inverse); the ``rates_rad_s`` properties apply it, and the CAN message
  ``IMU_RATES`` carries the rates in roadpreview's convention.
* The accelerometer measures specific force, the acceleration minus
  gravity, in body axes: at rest on level ground it reads (0, 0, +g).

This module is pure math: no files, no clocks (`roadpreview.sim.canlog`
writes the results).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.integrate import cumulative_trapezoid
from scipy.spatial.transform import Rotation

from roadpreview.canbus.samples import RATE_SIGNS, ImuMeasurements
from roadpreview.configtools import check_ranges, param
from roadpreview.errors import ConfigError, InputDataError
from roadpreview.sim.frames import body_to_world

DEG = math.pi / 180.0
KMH = 1.0 / 3.6  # m/s per km/h
STANDARD_GRAVITY_M_S2 = 9.80665
#: wheel order of every wheel-speed array
WHEELS = ("FL", "FR", "RL", "RR")

Array = NDArray[np.float64]


# ---------------------------------------------------------------------------------------------
# configuration


@dataclass
class ImuConfig:
    """A 6-DoF MEMS IMU: rate, noise, bias, range, resolution and time stamping.

    Noise densities are one-sided (datasheet) values N: a sample at rate fs
    has white noise of standard deviation N * sqrt(fs / 2) (the noise in a
    bandwidth of fs / 2; equivalently the mean over one sample interval of
    continuous white noise of one-sided density N). Biases are a constant
    per-axis offset (``*_bias`` plus a draw of standard deviation
    ``*_bias_std``) plus a random walk. Defaults are the `automotive` preset.
    """

    rate_hz: float = param(
        100.0, unit="Hz", ge=100.0, le=200.0, help="output data rate; CAN IMUs send every 10 ms"
    )
    sampling: str = param(
        "average",
        choices=("average", "sample"),
        help="'average': mean over the sample interval (the sensor's"
        " anti-alias filter); 'sample': the instantaneous value",
    )
    gyro_noise_density: float = param(
        0.005 * DEG, unit="rad/s/√Hz", ge=0.0, help="rate noise density (0.005 °/s/√Hz)"
    )
    gyro_bias: tuple[float, float, float] = param(
        (0.0, 0.0, 0.0), unit="rad/s", help="fixed part of the initial bias, x/y/z"
    )
    gyro_bias_std: float = param(
        0.05 * DEG, unit="rad/s", ge=0.0, help="per-axis std of the random initial bias (0.05 °/s)"
    )
    gyro_bias_random_walk: float = param(
        1e-4 * DEG, unit="rad/s/√s", ge=0.0, help="bias random walk; ~3 °/h drift over a minute"
    )
    gyro_range: float = param(
        125.0 * DEG, unit="rad/s", gt=0.0, help="full scale ±125 °/s; the output saturates there"
    )
    gyro_lsb: float = param(
        DEG / 262.4, unit="rad/s", ge=0.0, help="resolution, 16 bit over ±125 °/s (0 = none)"
    )
    accel_noise_density: float = param(
        150e-6 * STANDARD_GRAVITY_M_S2, unit="m/s²/√Hz", ge=0.0, help="150 µg/√Hz"
    )
    accel_bias: tuple[float, float, float] = param(
        (0.0, 0.0, 0.0), unit="m/s²", help="fixed part of the initial bias, x/y/z"
    )
    accel_bias_std: float = param(
        0.05, unit="m/s²", ge=0.0, help="per-axis std of the random initial bias (~5 mg)"
    )
    accel_bias_random_walk: float = param(2e-4, unit="m/s²/√s", ge=0.0, help="bias random walk")
    accel_range: float = param(
        3.0 * STANDARD_GRAVITY_M_S2, unit="m/s²", gt=0.0, help="full scale ±3 g"
    )
    accel_lsb: float = param(
        STANDARD_GRAVITY_M_S2 / 10920.0,
        unit="m/s²",
        ge=0.0,
        help="resolution, 16 bit over ±3 g (0 = none)",
    )
    time_offset_s: float = param(
        0.0, unit="s", ge=-0.08, le=0.08, help="stamp minus true sample time; > 0: the stamps lag"
    )
    timestamp_jitter_s: float = param(
        0.0, unit="s", ge=0.0, help="std of the random error of each stamp"
    )
    gravity_m_s2: float = param(
        STANDARD_GRAVITY_M_S2, unit="m/s²", ge=9.7, le=9.9, help="local gravity (standard gravity)"
    )
    mount_ypr_deg: tuple[float, float, float] = param(
        (0.0, 0.0, 0.0),
        unit="deg",
        help="how the chip sits in the body: yaw, pitch, roll of its axes (intrinsic z-y-x,"
        " right-handed about ISO 8855's axes, so +pitch tips the chip's x down); 0: aligned",
    )

    def validate(self, where: str = "ImuConfig") -> None:
        """Check the ranges and the relations between fields; raise `ConfigError`."""
        check_ranges(self, where)
        for name in ("gyro", "accel"):
            lsb, rng = getattr(self, f"{name}_lsb"), getattr(self, f"{name}_range")
            if lsb >= rng:
                raise ConfigError(f"{where}.{name}_lsb = {lsb}: must be smaller than the range")
            bias = getattr(self, f"{name}_bias")
            if len(bias) != 3 or not all(math.isfinite(float(b)) for b in bias):
                raise ConfigError(f"{where}.{name}_bias = {bias!r}: must be 3 finite numbers")
        if len(self.mount_ypr_deg) != 3 or not all(
            math.isfinite(float(a)) for a in self.mount_ypr_deg
        ):
            raise ConfigError(
                f"{where}.mount_ypr_deg = {self.mount_ypr_deg!r}: must be 3 finite angles"
            )
        if self.timestamp_jitter_s > 0.1 / self.rate_hz:
            raise ConfigError(
                f"{where}.timestamp_jitter_s = {self.timestamp_jitter_s} s: must be <= 0.1 /"
                f" rate_hz = {0.1 / self.rate_hz:.6f} s (stamps would leave their order)"
            )

    @classmethod
    def automotive(cls) -> ImuConfig:
        """An automotive-grade 6-DoF MEMS IMU on CAN (ESC / ADAS inertial sensor class).

        Datasheet-class values, honest approximations rather than one part's
        guaranteed limits. Gyro noise 0.005 °/s/√Hz lies between consumer-
        automotive parts of the Bosch BMI088 / SMI230 class (about
        0.014 °/s/√Hz) and high-end ADAS parts such as Murata's SCHA63T
        (about 0.0015 °/s/√Hz). The initial bias of 0.05 °/s (1 sigma) is
        what remains after the end-of-line and standstill offset calibration
        an ESC performs (raw zero-rate offsets are specified at ±1 °/s and
        more); the random walk gives the few °/h of bias instability these
        parts quote. Range and LSB are the 16-bit ±125 °/s and ±3 g settings
        (262.4 LSB/(°/s), 10920 LSB/g, as in the BMI088 datasheet tables);
        accelerometer noise about 150 µg/√Hz (BMI088 class). Time stamps:
        received on CAN about 4 ms after sampling (processing and bus),
        0.1 ms jitter: assumptions, not measured.
        """
        return cls(time_offset_s=0.004, timestamp_jitter_s=1e-4)

    @classmethod
    def smartphone(cls) -> ImuConfig:
        """A phone's IMU in a windscreen holder (ST LSM6DS3 / Bosch BMI160 class).

        Datasheet noise is 0.004-0.008 °/s/√Hz (LSM6DS3 "7 mdps/√Hz", BMI160
        0.007 °/s/√Hz); we use 0.015 °/s/√Hz for the whole phone in its
        holder. Initial bias 0.5 °/s (1 sigma): what Android's run-time
        calibration leaves (raw zero-rate offsets are up to several °/s; the
        real comma2k19 phone's estimated bias was 0.6 / 2.0 / 3.9 °/s). The
        bias random walk is noticeable over a minute (about 0.02 °/s). Range,
        resolution and rate match the real comma2k19 phone recording in
        ../shared: its steps are 0.070 °/s and 0.00238 m/s², i.e. an
        LSM6DS3 at ±2000 °/s and ±8 g (70 mdps/LSB, 0.244 mg/LSB), sampled at
        104 Hz with 14 µs stamp jitter. Accelerometer noise about
        400 µg/√Hz (datasheet 90-180 µg/√Hz, plus the holder), initial bias
        0.2 m/s² (about 20 mg). Time offset 30 ms: an assumption.
        """
        return cls(
            rate_hz=104.0,
            gyro_noise_density=0.015 * DEG,
            gyro_bias_std=0.5 * DEG,
            gyro_bias_random_walk=3e-3 * DEG,
            gyro_range=2000.0 * DEG,
            gyro_lsb=0.070 * DEG,
            accel_noise_density=400e-6 * STANDARD_GRAVITY_M_S2,
            accel_bias_std=0.2,
            accel_bias_random_walk=1e-3,
            accel_range=8.0 * STANDARD_GRAVITY_M_S2,
            accel_lsb=0.244e-3 * STANDARD_GRAVITY_M_S2,
            time_offset_s=0.030,
            timestamp_jitter_s=14e-6,
        )

    @classmethod
    def ideal(cls, rate_hz: float = 100.0) -> ImuConfig:
        """No noise, no bias, no quantisation, huge range, exact stamps (for tests)."""
        return cls(
            rate_hz=rate_hz,
            gyro_noise_density=0.0,
            gyro_bias_std=0.0,
            gyro_bias_random_walk=0.0,
            gyro_range=1e6,
            gyro_lsb=0.0,
            accel_noise_density=0.0,
            accel_bias_std=0.0,
            accel_bias_random_walk=0.0,
            accel_range=1e6,
            accel_lsb=0.0,
        )

    @property
    def mount_rotation(self) -> Array:
        """(3, 3) rotation taking vectors in the chip's axes to the body's (ISO 8855)."""
        rot: Array = Rotation.from_euler("ZYX", self.mount_ypr_deg, degrees=True).as_matrix()
        return rot

    @property
    def gyro_noise_std(self) -> float:
        """Standard deviation of the white gyro noise of one sample, rad/s."""
        return self.gyro_noise_density * math.sqrt(self.rate_hz / 2.0)

    @property
    def accel_noise_std(self) -> float:
        """Standard deviation of the white accelerometer noise of one sample, m/s²."""
        return self.accel_noise_density * math.sqrt(self.rate_hz / 2.0)


#: named IMU presets (config files may name one)
IMU_PRESETS = {"automotive": ImuConfig.automotive, "smartphone": ImuConfig.smartphone}


@dataclass
class SpeedSensorConfig:
    """The ESC's vehicle speed and wheel speeds, as sent on CAN.

    Speeds are means over one message interval (the ESC counts sensor-wheel
    edges over its cycle), stamped ``time_offset_s`` after the end of it,
    and quantised to the CAN signals' resolution. Below
    ``standstill_below_kmh`` the speeds read 0 and the direction is
    Standstill (wheel-speed sensors cannot time edges that far apart).
    """

    rate_hz: float = param(
        50.0, unit="Hz", ge=10.0, le=100.0, help="speed messages every 20 ms, as common"
    )
    time_offset_s: float = param(
        0.010, unit="s", ge=0.0, le=0.2, help="ESC processing and filtering latency (assumption)"
    )
    timestamp_jitter_s: float = param(
        1e-4, unit="s", ge=0.0, le=2e-3, help="std of the random error of each stamp"
    )
    speed_lsb_kmh: float = param(
        0.01, unit="km/h", ge=0.0, help="resolution of VEHICLE_SPEED.VehicleSpeed"
    )
    wheel_speed_lsb_kmh: float = param(
        0.03125, unit="km/h", ge=0.0, help="resolution of the WHEEL_SPEEDS signals"
    )
    wheel_speed_noise_kmh: float = param(
        0.05,
        unit="km/h",
        ge=0.0,
        help="std of wheel-speed noise (tone-wheel pitch errors, tyre vibration)",
    )
    standstill_below_kmh: float = param(
        0.5, unit="km/h", ge=0.0, le=5.0, help="slowest speed the wheel-speed sensors resolve"
    )

    def validate(self, where: str = "SpeedSensorConfig") -> None:
        """Check the ranges; raise `ConfigError`."""
        check_ranges(self, where)


# ---------------------------------------------------------------------------------------------
# results


@dataclass(frozen=True)
class ImuSamples:
    """Simulated IMU output together with the truth at the same samples.

    Measured and true values are in the IMU's axes (module docstring); the
    true values are what a perfect sensor with the same sampling (average or
    point) would output. Bias arrays are the bias each sample contains.
    """

    t_stamp_s: Array  #: (n,) time stamps as the sensor / logger gives them
    t_true_s: Array  #: (n,) true time at which each sample was latched
    gyro_rad_s: Array  #: (n, 3) measured rate
    accel_m_s2: Array  #: (n, 3) measured specific force
    true_gyro_rad_s: Array  #: (n, 3) rate without bias, noise, saturation, quantisation
    true_accel_m_s2: Array  #: (n, 3) specific force without errors
    gyro_bias_rad_s: Array  #: (n, 3) gyro bias in each sample
    accel_bias_m_s2: Array  #: (n, 3) accelerometer bias in each sample
    rate_hz: float

    def __len__(self) -> int:
        return len(self.t_stamp_s)

    @property
    def rates_rad_s(self) -> Array:
        """(n, 3) measured [roll, pitch (nose up +), yaw] rates."""
        rates: Array = self.gyro_rad_s * RATE_SIGNS
        return rates

    @property
    def true_rates_rad_s(self) -> Array:
        """(n, 3) true [roll, pitch (nose up +), yaw] rates."""
        rates: Array = self.true_gyro_rad_s * RATE_SIGNS
        return rates

    def measurements(self) -> ImuMeasurements:
        """Only what the sensor delivers (stamped times, measured values)."""
        return ImuMeasurements(self.t_stamp_s, self.gyro_rad_s, self.accel_m_s2)


@dataclass(frozen=True)
class SpeedSamples:
    """ESC speed measurements as sent on CAN, with the truth.

    Speeds are magnitudes (SI, m/s) quantised to the CAN resolution; the
    direction is 0 = standstill, 1 = forward, 2 = reverse (the DBC's
    ``MovingDirection``). Wheels in the order of `WHEELS`.
    """

    t_stamp_s: Array  #: (n,) time stamps
    t_true_s: Array  #: (n,) end of each measuring interval
    speed_m_s: Array  #: (n,) vehicle speed magnitude
    wheel_speeds_m_s: Array  #: (n, 4) wheel speed magnitudes FL, FR, RL, RR
    direction: NDArray[np.int8]  #: (n,) 0 standstill, 1 forward, 2 reverse
    true_speed_m_s: Array  #: (n,) signed true mean speed over the interval
    true_wheel_speeds_m_s: Array  #: (n, 4) signed true mean wheel speeds

    def __len__(self) -> int:
        return len(self.t_stamp_s)


STANDSTILL, FORWARD, REVERSE = 0, 1, 2


# ---------------------------------------------------------------------------------------------
# helpers


def _as_time_grid(t: ArrayLike, name: str) -> Array:
    arr = np.asarray(t, dtype=np.float64)
    if arr.ndim != 1 or arr.size < 2:
        raise InputDataError(f"{name}: must be a 1-D array of at least 2 times, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputDataError(f"{name}: contains NaN or infinite times")
    if not np.all(np.diff(arr) > 0):
        i = int(np.argmax(np.diff(arr) <= 0))
        raise InputDataError(f"{name}: times must increase (t[{i + 1}] <= t[{i}])")
    return arr


def _as_series(x: ArrayLike, n: int, cols: int | None, name: str) -> Array:
    arr = np.asarray(x, dtype=np.float64)
    shape = (n,) if cols is None else (n, cols)
    if arr.shape != shape:
        raise InputDataError(f"{name}: shape {arr.shape}, expected {shape}")
    if not np.all(np.isfinite(arr)):
        raise InputDataError(f"{name}: contains NaN or infinite values")
    return arr


def _sample_grid(t_truth: Array, rate_hz: float, what: str) -> Array:
    """True sample instants: every 1/rate from one interval after the start of the truth."""
    period = 1.0 / rate_hz
    n = math.floor((t_truth[-1] - t_truth[0]) / period + 1e-9)
    if n < 1:
        raise InputDataError(
            f"{what}: the truth covers {t_truth[-1] - t_truth[0]:.4f} s, shorter than one"
            f" sample interval ({period:.4f} s)"
        )
    times: Array = t_truth[0] + period * np.arange(1, n + 1)
    return times


def _resample(t_truth: Array, x: Array, t_samples: Array, period: float, mode: str) -> Array:
    """Truth ``x`` (n,) or (n, k) at the sample instants: interval means or point values.

    Means are exact for a truth that is linear between grid points: the
    trapezoidal running integral is interpolated at both ends of each interval.
    """
    x2 = x.reshape(len(t_truth), -1)
    if mode == "sample":
        out = np.column_stack([np.interp(t_samples, t_truth, c) for c in x2.T])
    else:
        integral = cumulative_trapezoid(x2, t_truth, axis=0, initial=0.0)
        ends = np.column_stack([np.interp(t_samples, t_truth, c) for c in integral.T])
        starts = np.column_stack([np.interp(t_samples - period, t_truth, c) for c in integral.T])
        out = (ends - starts) / period
    return out.reshape((len(t_samples), *x.shape[1:]))


def _saturate_quantise(x: Array, full_scale: float, lsb: float) -> Array:
    """Clip to ±full scale, round to the LSB, stay inside the full scale."""
    y = np.clip(x, -full_scale, full_scale)
    if lsb > 0.0:
        top = lsb * math.floor(full_scale / lsb)
        y = np.clip(lsb * np.round(y / lsb), -top, top)
    return y


def _bias_path(initial: Array, random_walk: float, period: float, z: Array) -> Array:
    """Bias per sample: ``initial`` (3,) plus a random walk from standard normals ``z`` (n, 3)."""
    steps = random_walk * math.sqrt(period) * z
    steps[0] = 0.0
    return initial + np.cumsum(steps, axis=0)


def rotation_body_to_world(attitude: ArrayLike) -> Array:
    """(n, 3, 3) rotations taking body (x fwd, y left, z up) vectors to the world frame.

    ``attitude`` (n, 3) is [roll, pitch, yaw] in roadpreview's convention;
    the rotation is yaw about z, then pitch, then roll about x (ISO 8855
    order), with ISO's pitch angle equal to minus ours.
    """
    att = np.asarray(attitude, dtype=np.float64).reshape(-1, 3)
    return body_to_world(att[:, 1], att[:, 0], att[:, 2])


def body_rates_from_euler(t: ArrayLike, attitude: ArrayLike) -> Array:
    """Body rates [roll, pitch (nose up +), yaw] (n, 3) from an attitude history.

    ``attitude`` (n, 3) is [roll, pitch, yaw] (roadpreview convention) at
    times ``t``; the Euler-angle rates are taken with ``np.gradient``
    (second order), then mapped to body rates with the ZYX kinematics. For
    a trajectory that only pitches, the pitch rate is simply d(pitch)/dt.
    """
    tt = _as_time_grid(t, "t")
    att = _as_series(attitude, len(tt), 3, "attitude")
    roll, pitch = att[:, 0], att[:, 1]
    droll, dpitch, dyaw = (np.gradient(att[:, i], tt) for i in range(3))
    # ISO body rates with ISO pitch = -pitch:
    #   p = droll - dyaw sin(pitch_iso);  q = dpitch_iso cos(roll) + dyaw sin(roll) cos(pitch_iso)
    #   r = -dpitch_iso sin(roll) + dyaw cos(roll) cos(pitch_iso)
    p = droll + dyaw * np.sin(pitch)
    q = -dpitch * np.cos(roll) + dyaw * np.sin(roll) * np.cos(pitch)
    r = dpitch * np.sin(roll) + dyaw * np.cos(roll) * np.cos(pitch)
    rates: Array = np.column_stack([p, q, r]) * RATE_SIGNS
    return rates


# ---------------------------------------------------------------------------------------------
# models


def simulate_imu(
    t_truth: ArrayLike,
    omega_body: ArrayLike,
    accel_world: ArrayLike,
    attitude: ArrayLike,
    cfg: ImuConfig,
    rng: np.random.Generator,
) -> ImuSamples:
    """Sample a MEMS IMU from ground truth.

    Parameters
    ----------
    t_truth
        (n,) increasing truth times, s (a fine grid, e.g. 1 kHz).
    omega_body
        (n, 3) true body rates [roll, pitch, yaw], rad/s, in roadpreview's
        convention (pitch rate positive nose up); see `body_rates_from_euler`.
    accel_world
        (n, 3) acceleration of the IMU's location in the world frame (X fwd,
        Y left, Z up), m/s², gravity NOT included.
    attitude
        (n, 3) [roll, pitch, yaw], rad, to turn gravity and the acceleration
        into body axes.
    cfg
        The sensor (`ImuConfig`, e.g. ``ImuConfig.automotive()``).
    rng
        Source of every random draw; the draws are made in a fixed order
        whatever the noise levels, so a zero-noise run and a noisy run with
        the same seed share their bias.

    The n_s samples are latched at ``t_truth[0] + k / rate_hz``, k = 1..n_s,
    each (``sampling="average"``) the mean over the interval before it, so a
    sample lags its interval's centre by half a period; the stamp is
    ``t_true + time_offset_s + jitter``. Measured = true + bias + white
    noise, then clipped to the range and rounded to the LSB.
    """
    cfg.validate()
    tt = _as_time_grid(t_truth, "t_truth")
    n = len(tt)
    omega = _as_series(omega_body, n, 3, "omega_body")
    acc_w = _as_series(accel_world, n, 3, "accel_world")
    att = _as_series(attitude, n, 3, "attitude")

    period = 1.0 / cfg.rate_hz
    t_true = _sample_grid(tt, cfg.rate_hz, "simulate_imu")
    m = len(t_true)

    # roadpreview rates -> ISO body rates -> the chip's axes (``v_chip = M^T v_body``)
    mount = cfg.mount_rotation
    gyro_truth_fine = (omega * RATE_SIGNS) @ mount
    specific_force_world = acc_w + np.array([0.0, 0.0, cfg.gravity_m_s2])
    rot = rotation_body_to_world(att)
    specific_force_body = np.einsum("nji,nj->ni", rot, specific_force_world) @ mount

    true_gyro = _resample(tt, gyro_truth_fine, t_true, period, cfg.sampling)
    true_accel = _resample(tt, specific_force_body, t_true, period, cfg.sampling)

    # fixed draw order: gyro bias, walk, noise; accel bias, walk, noise; stamps
    gyro_bias0 = np.asarray(cfg.gyro_bias, dtype=np.float64) + cfg.gyro_bias_std * (
        rng.standard_normal(3)
    )
    gyro_bias = _bias_path(
        gyro_bias0, cfg.gyro_bias_random_walk, period, rng.standard_normal((m, 3))
    )
    gyro_noise = cfg.gyro_noise_std * rng.standard_normal((m, 3))
    accel_bias0 = np.asarray(cfg.accel_bias, dtype=np.float64) + cfg.accel_bias_std * (
        rng.standard_normal(3)
    )
    accel_bias = _bias_path(
        accel_bias0, cfg.accel_bias_random_walk, period, rng.standard_normal((m, 3))
    )
    accel_noise = cfg.accel_noise_std * rng.standard_normal((m, 3))
    jitter = cfg.timestamp_jitter_s * rng.standard_normal(m)

    gyro = _saturate_quantise(true_gyro + gyro_bias + gyro_noise, cfg.gyro_range, cfg.gyro_lsb)
    accel = _saturate_quantise(
        true_accel + accel_bias + accel_noise, cfg.accel_range, cfg.accel_lsb
    )
    return ImuSamples(
        t_stamp_s=t_true + cfg.time_offset_s + jitter,
        t_true_s=t_true,
        gyro_rad_s=gyro,
        accel_m_s2=accel,
        true_gyro_rad_s=true_gyro,
        true_accel_m_s2=true_accel,
        gyro_bias_rad_s=gyro_bias,
        accel_bias_m_s2=accel_bias,
        rate_hz=cfg.rate_hz,
    )


def _quantise(x: Array, lsb: float) -> Array:
    return lsb * np.round(x / lsb) if lsb > 0.0 else x


def simulate_speed(
    t_truth: ArrayLike,
    speed_m_s: ArrayLike,
    cfg: SpeedSensorConfig,
    rng: np.random.Generator,
    wheel_speeds_m_s: ArrayLike | None = None,
) -> SpeedSamples:
    """The ESC's vehicle and wheel speeds from true signed speeds (negative = reversing).

    ``speed_m_s`` (n,) is the vehicle's longitudinal speed on the truth grid
    ``t_truth``; ``wheel_speeds_m_s`` (n, 4) the wheels' circumferential
    speeds FL, FR, RL, RR (default: all equal to the vehicle speed). Each
    message holds the interval means, quantised to the CAN resolution; the
    wheel speeds get white noise first. Draw order: wheel noise, stamps.
    """
    cfg.validate()
    tt = _as_time_grid(t_truth, "t_truth")
    n = len(tt)
    v = _as_series(speed_m_s, n, None, "speed_m_s")
    wheels = (
        np.repeat(v[:, None], 4, axis=1)
        if wheel_speeds_m_s is None
        else _as_series(wheel_speeds_m_s, n, 4, "wheel_speeds_m_s")
    )
    period = 1.0 / cfg.rate_hz
    t_true = _sample_grid(tt, cfg.rate_hz, "simulate_speed")
    m = len(t_true)
    v_mean = _resample(tt, v, t_true, period, "average")
    w_mean = _resample(tt, wheels, t_true, period, "average")

    wheel_noise = cfg.wheel_speed_noise_kmh * KMH * rng.standard_normal((m, 4))
    jitter = cfg.timestamp_jitter_s * rng.standard_normal(m)

    threshold = cfg.standstill_below_kmh * KMH
    moving = np.abs(v_mean) >= threshold
    direction = np.where(moving, np.where(v_mean > 0, FORWARD, REVERSE), STANDSTILL).astype(np.int8)
    speed = np.where(moving, _quantise(np.abs(v_mean) / KMH, cfg.speed_lsb_kmh) * KMH, 0.0)
    w_abs = np.abs(np.abs(w_mean) + wheel_noise)
    w_abs = np.where(np.abs(w_mean) >= threshold, w_abs, 0.0)
    wheel = _quantise(w_abs / KMH, cfg.wheel_speed_lsb_kmh) * KMH
    return SpeedSamples(
        t_stamp_s=t_true + cfg.time_offset_s + jitter,
        t_true_s=t_true,
        speed_m_s=speed,
        wheel_speeds_m_s=wheel,
        direction=direction,
        true_speed_m_s=v_mean,
        true_wheel_speeds_m_s=w_mean,
    )
