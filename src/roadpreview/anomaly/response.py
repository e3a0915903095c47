"""The nominal lead vehicle's vertical response to a road anomaly: the detector's templates.

A car crosses a short anomaly with its front axle, then with its rear axle a
wheelbase later. With a pitch dynamic index near 1 (most cars: 0.8-1.2) the
two axles ride as two independent quarter cars, and a point of the body at
``rear_overhang_m`` behind the rear axle, the rear face the camera tracks,
moves as the rear axle's response extrapolated along the body:

    z_face(t) = (1 + ρ) q(t - τ) - ρ q(t),   ρ = overhang / wheelbase,  τ = wheelbase / v

(front axle over the anomaly at t = 0). q is the body displacement of a
two-mass quarter car (sprung corner mass on a spring-damper, wheel mass on
the tyre spring) driven by the road profile under the wheel:

    Z_s / W = k_t (c s + k) / [(m_s s² + c s + k)(m_u s² + c s + k + k_t) - (c s + k)²]

The anomaly is a raised-cosine-tapered pulse (Tukey, half of it ramps) of
unit height and duration D = length / v under the wheel, so a template is
fixed by (D, τ); the detector keeps a bank over D. Everything here is
linear: an anomaly of height h gives h times the template (a pothole -h).
The parameters are those of a typical mid-size car (``docs/detector.md``);
the simulated leads (small car, SUV, van) differ on purpose.

The same quarter car gives the gains that turn a road roughness (ISO 8608
displacement PSD G_d(n) = G_d(n0) (n / n0)^-2) into the RMS of body
displacement and acceleration at a speed (`roughness_gain`), for the road
class estimate (`roadpreview.anomaly.roughness`).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from roadpreview.configtools import param

FloatArray = NDArray[np.float64]

#: ISO 8608 reference wavenumber n0, cycles/m
ISO8608_N0 = 0.1


@dataclass(frozen=True)
class NominalVehicle:
    """A typical car as the detector assumes it (one corner and the axle geometry)."""

    corner_mass_kg: float = param(
        350.0, unit="kg", gt=0, le=5000, help="sprung mass per corner (a 1400 kg body / 4)"
    )
    ride_freq_hz: float = param(
        1.3, unit="Hz", ge=0.5, le=3.0, help="body natural frequency on its springs; cars 1.0-1.6"
    )
    damping_ratio: float = param(0.3, ge=0.05, le=1.5, help="ride damping ratio; cars 0.2-0.4")
    unsprung_mass_kg: float = param(
        40.0, unit="kg", gt=0, le=500, help="wheel, brake and upright per corner"
    )
    tyre_stiffness_npm: float = param(
        250e3, unit="N/m", gt=1e4, le=1e7, help="vertical tyre rate; car tyres 200-300 kN/m"
    )
    wheelbase_m: float = param(
        2.7, unit="m", gt=1.0, le=8.0, help="axle to axle: small cars 2.4, SUVs 2.9, vans 3.4"
    )
    rear_overhang_m: float = param(
        0.9, unit="m", ge=0.0, le=3.0, help="rear axle to the rear face the camera tracks"
    )
    track_m: float = param(
        1.55, unit="m", gt=0.5, le=3.0, help="lateral wheel spacing (the roll channel's lever)"
    )

    @property
    def rho(self) -> float:
        """ρ = overhang / wheelbase: how much the rear face amplifies the rear axle."""
        return self.rear_overhang_m / self.wheelbase_m

    @cached_property
    def quarter_car(self) -> signal.TransferFunction:
        """Road displacement -> body displacement of one corner (continuous time)."""
        ms, mu, kt = self.corner_mass_kg, self.unsprung_mass_kg, self.tyre_stiffness_npm
        w = 2.0 * math.pi * self.ride_freq_hz
        k_ride = ms * w * w
        k = k_ride * kt / (kt - k_ride)  # in series with the tyre: k_ride at the body
        c = 2.0 * self.damping_ratio * ms * w
        a = np.array([ms, c, k])
        b = np.array([mu, c, k + kt])
        cs_k = np.array([c, k])
        den: FloatArray = np.polysub(np.polymul(a, b), np.polymul(cs_k, cs_k))
        num = kt * cs_k
        return signal.TransferFunction(num, den)

    def gain_sq(self, f_hz: FloatArray, derivative: int = 0) -> FloatArray:
        """|H(j 2π f)|² of the quarter car, times (2π f)^(2 derivative) (velocity,
        acceleration)."""
        w = 2.0 * np.pi * np.asarray(f_hz, dtype=float)
        _, h = signal.freqs(self.quarter_car.num, self.quarter_car.den, worN=w)
        return np.asarray(np.abs(h) ** 2 * w ** (2 * derivative), dtype=float)


def tukey_pulse(t: FloatArray, duration_s: float, taper: float = 0.5) -> FloatArray:
    """Unit pulse of ``duration_s`` starting at t = 0 with raised-cosine ramps over ``taper``
    of it (half each side): a bump or cushion with ramps, a pothole with rounded edges."""
    t = np.asarray(t, dtype=float)
    x = np.clip(t / duration_s, 0.0, 1.0)
    out = np.ones_like(x)
    r = 0.5 * taper
    up = x < r
    down = x > 1.0 - r
    out[up] = 0.5 * (1.0 - np.cos(np.pi * x[up] / r))
    out[down] = 0.5 * (1.0 - np.cos(np.pi * (1.0 - x[down]) / r))
    out[(t < 0) | (t > duration_s)] = 0.0
    return out


@dataclass(frozen=True)
class TemplateBank:
    """Quarter-car responses to unit pulses of several durations on a fine time grid.

    ``q[j, i]`` is the body displacement (m per m of road height) at ``i * dt_s`` after
    the wheel reaches the start of a pulse of ``durations_s[j]``.
    """

    durations_s: FloatArray
    dt_s: float
    q: FloatArray  #: (J, N)

    @classmethod
    def build(
        cls,
        vehicle: NominalVehicle,
        durations_s: tuple[float, ...],
        *,
        horizon_s: float = 4.0,
        dt_s: float = 0.002,
    ) -> TemplateBank:
        t = np.arange(0.0, horizon_s, dt_s)
        rows = []
        sys = vehicle.quarter_car
        for d in durations_s:
            _, y, _ = signal.lsim(sys, tukey_pulse(t, d), t)
            rows.append(y)
        return cls(np.asarray(durations_s, dtype=float), dt_s, np.asarray(rows, dtype=float))

    @classmethod
    @functools.lru_cache(maxsize=16)
    def cached(cls, vehicle: NominalVehicle, durations_s: tuple[float, ...]) -> TemplateBank:
        """`build` with the default grid, computed once per vehicle and bank (detectors are
        made per drive, and the responses take a quarter of a second)."""
        return cls.build(vehicle, durations_s)

    def response(self, t_rel: FloatArray, *, rows: int | None = None) -> FloatArray:
        """q_j at times ``t_rel``, (J, M) per template or (M,) shared: (J, M); 0 before the
        pulse, the last value held after the horizon (nearest fine-grid sample). With
        ``rows`` = J, ``t_rel`` may hold several blocks of J rows (K J, M): template j for
        row i is j = i mod J."""
        n_j, n = self.q.shape
        idx = np.rint(np.asarray(t_rel, dtype=float) / self.dt_s).astype(np.intp)
        if rows is not None and idx.ndim == 2 and idx.shape[0] % n_j == 0:
            q = np.tile(self.q, (idx.shape[0] // n_j, 1))
        else:
            q = self.q
            idx = np.broadcast_to(idx, (n_j, idx.shape[-1]))
        out = np.take_along_axis(q, np.clip(idx, 0, n - 1), axis=1)
        out[idx < 0] = 0.0
        return out

    def two_axle(
        self, t_rel: FloatArray, tau_s: float, rho: float, *, rows: int | None = None
    ) -> FloatArray:
        """Rear-face displacement (J, ...) per m of road height: (1 + ρ) q(t - τ) - ρ q(t),
        t from the front axle reaching the anomaly. ``tau_s`` NaN: the rear axle alone
        (the speed is unknown, so the two-axle lag is; t from the rear axle). ``rows``:
        as `response`."""
        if not math.isfinite(tau_s):
            return self.response(t_rel, rows=rows)
        rear = self.response(np.asarray(t_rel) - tau_s, rows=rows)
        return (1.0 + rho) * rear - rho * self.response(t_rel, rows=rows)


def roughness_gain(
    vehicle: NominalVehicle,
    speed_mps: float,
    *,
    derivative: int,
    band_hz: tuple[float, float],
    n_freq: int = 400,
) -> float:
    """RMS² of the body's displacement (``derivative`` 0) or acceleration (2) per unit
    G_d(n0) (m³) of an ISO 8608 road at ``speed_mps``, within ``band_hz``.

    The road's temporal PSD at speed v is G_d(f / v) / v = G_d(n0) n0² v / f² (waviness
    2), so RMS² = G_d(n0) n0² v ∫ |H(f)|² (2π f)^(2 derivative) / f² df over the band.
    """
    if speed_mps <= 0:
        return math.nan
    f = np.geomspace(band_hz[0], band_hz[1], n_freq)
    integrand = vehicle.gain_sq(f, derivative) / (f * f)
    return float(ISO8608_N0**2 * speed_mps * np.trapezoid(integrand, f))


__all__ = [
    "ISO8608_N0",
    "NominalVehicle",
    "TemplateBank",
    "roughness_gain",
    "tukey_pulse",
]
