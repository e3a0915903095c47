"""Simulated straight road: ISO 8608 roughness on two wheel tracks, hills, crossfall, anomalies.

The road is a height field h(X, Y) in the world frame of ``docs/method.md``
(X forward along the road, Y left, Z up). The lane the ego drives in is
centred on Y = 0; the oncoming lane is centred on Y = +lane width (right-hand
traffic), the centre line (the crown of the crossfall) at Y = +lane width / 2.
The models and their parameters are described in ``docs/simulator-physics.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import fft

from roadpreview.configtools import check_ranges, param
from roadpreview.errors import ConfigError

#: ISO 8608 road classes: geometric-mean displacement PSD Gd(n0) at n0 = 0.1 cycles/m, in m^3
ISO8608_GD_N0: dict[str, float] = {
    "A": 16e-6,
    "B": 64e-6,
    "C": 256e-6,
    "D": 1024e-6,
    "E": 4096e-6,
}
#: reference wavenumber of ISO 8608, cycles/m
ISO8608_N0 = 0.1
#: waviness exponent w of Gd(n) = Gd(n0) (n / n0)^-w used for every class
ISO8608_WAVINESS = 2.0

ANOMALY_KINDS = ("bump", "cushion", "pothole", "step", "wave")
SIDES = ("none", "left", "right", "both")


def iso8608_psd(n: ArrayLike, road_class: str) -> NDArray[np.float64]:
    """Displacement PSD Gd(n) in m^3 (m^2 per cycle/m) of an ISO 8608 class at wavenumbers n."""
    if road_class not in ISO8608_GD_N0:
        raise ConfigError(f"road_class = {road_class!r}: must be one of {list(ISO8608_GD_N0)}")
    n_arr = np.asarray(n, dtype=float)
    return ISO8608_GD_N0[road_class] * (n_arr / ISO8608_N0) ** (-ISO8608_WAVINESS)


# -- anomalies --------------------------------------------------------------------------


@dataclass(frozen=True)
class Anomaly:
    """One discrete road-surface anomaly, a box in plan view with a longitudinal profile.

    The longitudinal profile by kind (s = X - start_x_m, L = length_m, r = ramp length):

    * ``bump``, ``cushion``: trapezoid, rising over r to ``height_m``, flat top,
      falling over r (a cushion is a bump narrower than the lane);
    * ``pothole``: the same trapezoid with a negative height (r bevels its walls;
      0 = vertical walls);
    * ``step``: a permanent level change of ``height_m`` over a transition of
      ``length_m`` (0 = a sharp joint), from ``start_x_m`` to the end of the road;
    * ``wave``: ``height_m / 2 * (1 - cos(2 pi s / lambda))``, whole periods over
      ``length_m`` (lambda is ``wavelength_m`` rounded so that L holds whole periods).

    Across the road the anomaly covers ``|Y - center_y_m| <= width_m / 2`` with
    vertical side edges.
    """

    kind: str = param("bump", choices=ANOMALY_KINDS, help="bump, cushion, pothole, step or wave")
    start_x_m: float = param(100.0, unit="m", ge=0, help="X where the anomaly begins")
    length_m: float = param(
        2.0, unit="m", ge=0, le=200, help="extent along X; the transition length of a step"
    )
    height_m: float = param(
        0.06, unit="m", ge=-0.5, le=0.5, help="signed: potholes negative; peak-to-peak for a wave"
    )
    center_y_m: float = param(0.0, unit="m", help="lateral centre of the anomaly (Y, left +)")
    width_m: float = param(
        3.5,
        unit="m",
        gt=0,
        le=50,
        help="lateral extent; the lane width by default (both wheel tracks)",
    )
    ramp_m: float = param(
        0.0, unit="m", ge=0, le=10, help="ramp (bevel) length of a bump, cushion or pothole"
    )
    ramp_deg: float = param(
        0.0,
        unit="deg",
        ge=0,
        lt=90,
        help="ramp angle; when > 0 it sets the ramp length |h| / tan(angle)",
    )
    wavelength_m: float = param(2.0, unit="m", gt=0, le=100, help="wavelength of a wave")

    def validate(self, where: str) -> None:
        """Cross-field checks: sign of the height, ramps that fit, lengths by kind."""
        prefix = f"{where}." if where else ""
        if self.kind in ("bump", "cushion", "wave") and self.height_m <= 0:
            raise ConfigError(f"{prefix}height_m = {self.height_m} m: a {self.kind} must be > 0")
        if self.kind == "pothole" and self.height_m >= 0:
            raise ConfigError(f"{prefix}height_m = {self.height_m} m: a pothole must be < 0")
        if self.kind == "step" and self.height_m == 0:
            raise ConfigError(f"{prefix}height_m = 0 m: a step must have a height")
        if self.kind != "step" and self.length_m <= 0:
            raise ConfigError(f"{prefix}length_m = {self.length_m} m: a {self.kind} must be > 0")
        if self.kind in ("bump", "cushion", "pothole") and 2 * self.ramp_length_m > self.length_m:
            name = "ramp_deg" if self.ramp_deg > 0 else "ramp_m"
            raise ConfigError(
                f"{prefix}{name}: two ramps of {self.ramp_length_m:.3f} m do not fit in"
                f" length_m = {self.length_m} m"
            )

    @property
    def ramp_length_m(self) -> float:
        """Length of one ramp along X (from ``ramp_deg`` when it is set, else ``ramp_m``)."""
        if self.ramp_deg > 0:
            return abs(self.height_m) / math.tan(math.radians(self.ramp_deg))
        return self.ramp_m

    @property
    def end_x_m(self) -> float:
        """X where the anomaly ends (infinite for a step, which persists)."""
        return math.inf if self.kind == "step" else self.start_x_m + self.length_m

    @property
    def effective_wavelength_m(self) -> float:
        """The wave's wavelength rounded so that ``length_m`` holds whole periods."""
        cycles = max(1, round(self.length_m / self.wavelength_m))
        return self.length_m / cycles

    @property
    def apex_x_m(self) -> float:
        """X of the extreme point: the centre of a bump, cushion or pothole, the middle of a
        step's transition, the first crest of a wave."""
        if self.kind == "step":
            return self.start_x_m + 0.5 * self.length_m
        if self.kind == "wave":
            return self.start_x_m + 0.5 * self.effective_wavelength_m
        return self.start_x_m + 0.5 * self.length_m

    def covers_y(self, y: ArrayLike) -> NDArray[np.bool_]:
        """Whether lateral positions Y lie within the anomaly's lateral extent."""
        y_arr = np.asarray(y, dtype=float)
        return np.abs(y_arr - self.center_y_m) <= 0.5 * self.width_m

    def side(self, line_y_m: float, track_m: float) -> str:
        """Which wheels of a vehicle driving along ``line_y_m`` with track ``track_m`` run over
        the anomaly: ``"left"``, ``"right"``, ``"both"`` or ``"none"`` (wheel centre lines)."""
        left = bool(self.covers_y(line_y_m + 0.5 * track_m))
        right = bool(self.covers_y(line_y_m - 0.5 * track_m))
        return SIDES[int(left) + 2 * int(right)]

    def profile(self, x: ArrayLike) -> NDArray[np.float64]:
        """The longitudinal profile (height in m) at X, ignoring the lateral extent."""
        x_arr = np.asarray(x, dtype=float)
        s = x_arr - self.start_x_m
        h = self.height_m
        if self.kind == "step":
            if self.length_m > 0:
                return h * np.clip(s / self.length_m, 0.0, 1.0)
            return np.where(s >= 0, h, 0.0)
        inside = (s >= 0) & (s <= self.length_m)
        if self.kind == "wave":
            lam = self.effective_wavelength_m
            return np.where(inside, 0.5 * h * (1.0 - np.cos(2 * np.pi * s / lam)), 0.0)
        r = self.ramp_length_m
        if r > 0:
            frac = np.clip(np.minimum(s, self.length_m - s) / r, 0.0, 1.0)
            return np.where(inside, h * frac, 0.0)
        return np.where(inside, h, 0.0)

    def height(self, x: ArrayLike, y: ArrayLike) -> NDArray[np.float64]:
        """The anomaly's height contribution at (X, Y) (zero outside it); broadcasts."""
        x_arr, y_arr = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
        return np.where(self.covers_y(y_arr), self.profile(x_arr), 0.0)


def paper_speed_bump(start_x_m: float, *, center_y_m: float = 0.0, width_m: float = 3.5) -> Anomaly:
    """The speed bump of the paper's controlled experiment: 6 cm high, 2 m long, 7 deg ramps."""
    return Anomaly(
        kind="bump",
        start_x_m=start_x_m,
        length_m=2.0,
        height_m=0.06,
        center_y_m=center_y_m,
        width_m=width_m,
        ramp_deg=7.0,
    )


# -- configuration ----------------------------------------------------------------------


def _default_mix() -> dict[str, float]:
    return {"bump": 0.25, "cushion": 0.05, "pothole": 0.4, "step": 0.2, "wave": 0.1}


@dataclass(frozen=True)
class RoadConfig:
    """How to generate a road. An explicit ``anomalies`` list replaces the random ones."""

    iso_class: str = param(
        "B",
        choices=("off", "A", "B", "C", "D", "E"),
        help="ISO 8608 roughness class; B is a good ordinary road",
    )
    length_m: float = param(1000.0, unit="m", gt=0, le=100_000, help="road from X = 0 to this")
    resolution_m: float = param(
        0.05, unit="m", gt=0, le=0.5, help="roughness sample spacing; Nyquist 10 cycles/m at 0.05 m"
    )
    min_wavenumber_cpm: float = param(
        0.011,
        unit="cycles/m",
        gt=0,
        le=1.0,
        help="ISO 8608 lower band limit; longer waves are hills",
    )
    track_spacing_m: float = param(
        1.6, unit="m", gt=0, le=3.0, help="lateral distance between the two roughness tracks"
    )
    track_coherence: float = param(
        0.5, ge=0, le=1, help="correlation of the two tracks (its square: coherence)"
    )
    hill_grade_pct: float = param(
        3.0, unit="%", ge=0, le=15, help="largest grade of the hills over the road"
    )
    hill_wavelength_m: float = param(
        400.0, unit="m", ge=20, le=10_000, help="main wavelength of the hills"
    )
    cross_slope_pct: float = param(
        2.0, unit="%", ge=-8, le=8, help="crossfall; > 0 falls from the centre line to the edges"
    )
    lane_width_m: float = param(3.5, unit="m", gt=2, le=6, help="ego lane centred on Y = 0")
    # param() returns dataclasses.field(default_factory=...), which RUF009 cannot see
    anomalies: list[Anomaly] = param(  # noqa: RUF009
        default_factory=list, help="explicit anomalies; non-empty replaces the random ones"
    )
    anomaly_density_per_km: float = param(
        8.0, unit="1/km", ge=0, le=200, help="mean number of random anomalies per km"
    )
    anomaly_mix: dict[str, float] = param(  # noqa: RUF009
        default_factory=_default_mix, help="relative frequency of each random kind"
    )
    anomaly_min_spacing_m: float = param(
        15.0, unit="m", ge=0, le=1000, help="least distance between random anomalies"
    )

    def validate(self, where: str) -> None:
        """Cross-field checks: anomaly kinds, mix weights, anomalies on the road."""
        prefix = f"{where}." if where else ""
        for i, a in enumerate(self.anomalies):
            path = f"{prefix}anomalies[{i}]"
            check_ranges(a, path)
            a.validate(path)
            if a.start_x_m > self.length_m:
                raise ConfigError(
                    f"{path}.start_x_m = {a.start_x_m} m: beyond length_m = {self.length_m} m"
                )
        for kind, weight in self.anomaly_mix.items():
            if kind not in ANOMALY_KINDS:
                raise ConfigError(
                    f"{prefix}anomaly_mix.{kind}: unknown kind (known: {', '.join(ANOMALY_KINDS)})"
                )
            if not (isinstance(weight, (int, float)) and math.isfinite(weight) and weight >= 0):
                raise ConfigError(f"{prefix}anomaly_mix.{kind} = {weight!r}: must be a number >= 0")
        if (
            self.anomaly_density_per_km > 0
            and not self.anomalies
            and sum(self.anomaly_mix.values()) <= 0
        ):
            raise ConfigError(f"{prefix}anomaly_mix: weights must not all be zero")
        if self.resolution_m * 4 > self.length_m:
            raise ConfigError(
                f"{prefix}resolution_m = {self.resolution_m} m: too coarse for"
                f" length_m = {self.length_m} m"
            )


# -- the road ---------------------------------------------------------------------------


class Road:
    """A straight road: h(X, Y) = hills(X) + crossfall(Y) + roughness(X, Y) + anomalies(X, Y).

    Roughness is sampled every ``dx`` metres on two tracks at ``right_track_y_m`` and
    ``left_track_y_m``; between them it is interpolated linearly in Y, outside them the
    pattern is mirrored (Y is folded back into the band between the tracks), so that a
    wheel one track width off the lane centre sees the other track's profile rather than
    a copy of its neighbour's. Beyond X in [0, length] the profiles hold their end values.
    """

    def __init__(
        self,
        *,
        length_m: float,
        lane_width_m: float,
        dx_m: float,
        left_profile: NDArray[np.float64],
        right_profile: NDArray[np.float64],
        left_track_y_m: float,
        right_track_y_m: float,
        hill_amplitudes_m: NDArray[np.float64],
        hill_wavenumbers_rad_per_m: NDArray[np.float64],
        hill_phases_rad: NDArray[np.float64],
        cross_slope: float,
        anomalies: tuple[Anomaly, ...] | list[Anomaly] = (),
    ) -> None:
        if left_profile.shape != right_profile.shape or left_profile.ndim != 1:
            raise ConfigError("left_profile/right_profile: must be 1-D arrays of equal length")
        if not left_track_y_m > right_track_y_m:
            raise ConfigError("left_track_y_m: must be greater (further left) than right_track_y_m")
        self.length_m = float(length_m)
        self.lane_width_m = float(lane_width_m)
        self.dx_m = float(dx_m)
        self.left_profile = left_profile
        self.right_profile = right_profile
        self.left_track_y_m = float(left_track_y_m)
        self.right_track_y_m = float(right_track_y_m)
        self.hill_amplitudes_m = np.asarray(hill_amplitudes_m, dtype=float)
        self.hill_wavenumbers_rad_per_m = np.asarray(hill_wavenumbers_rad_per_m, dtype=float)
        self.hill_phases_rad = np.asarray(hill_phases_rad, dtype=float)
        #: dh/dY of the crossfall: the surface falls by this per metre away from the crown
        self.cross_slope = float(cross_slope)
        self.crown_y_m = 0.5 * self.lane_width_m
        self.anomalies: tuple[Anomaly, ...] = tuple(sorted(anomalies, key=lambda a: a.start_x_m))

    @classmethod
    def flat(
        cls,
        length_m: float = 1000.0,
        *,
        lane_width_m: float = 3.5,
        anomalies: tuple[Anomaly, ...] | list[Anomaly] = (),
    ) -> Road:
        """A flat, level road (no roughness, hills or crossfall), optionally with anomalies."""
        zeros = np.zeros(2)
        return cls(
            length_m=length_m,
            lane_width_m=lane_width_m,
            dx_m=length_m,
            left_profile=zeros,
            right_profile=zeros.copy(),
            left_track_y_m=0.8,
            right_track_y_m=-0.8,
            hill_amplitudes_m=np.zeros(0),
            hill_wavenumbers_rad_per_m=np.zeros(0),
            hill_phases_rad=np.zeros(0),
            cross_slope=0.0,
            anomalies=anomalies,
        )

    # -- components ------------------------------------------------------------------
    def hills(self, x: ArrayLike) -> NDArray[np.float64]:
        """Elevation of the slow longitudinal part (hills) at X."""
        x_arr = np.asarray(x, dtype=float)
        out = np.zeros_like(x_arr)
        for amp, k, ph in zip(
            self.hill_amplitudes_m,
            self.hill_wavenumbers_rad_per_m,
            self.hill_phases_rad,
            strict=True,
        ):
            out += amp * np.sin(k * x_arr + ph)
        return out

    def grade(self, x: ArrayLike) -> NDArray[np.float64]:
        """dh/dX of the slow part (hills) at X (rise over run, positive uphill)."""
        x_arr = np.asarray(x, dtype=float)
        out = np.zeros_like(x_arr)
        for amp, k, ph in zip(
            self.hill_amplitudes_m,
            self.hill_wavenumbers_rad_per_m,
            self.hill_phases_rad,
            strict=True,
        ):
            out += amp * k * np.cos(k * x_arr + ph)
        return out

    def crossfall(self, y: ArrayLike) -> NDArray[np.float64]:
        """Elevation of the crossfall at Y: the surface falls away from the crown on both sides."""
        y_arr = np.asarray(y, dtype=float)
        return -self.cross_slope * np.abs(y_arr - self.crown_y_m)

    def cross_slope_at(self, y: ArrayLike) -> NDArray[np.float64]:
        """dh/dY of the crossfall at Y (positive: the surface rises to the left)."""
        y_arr = np.asarray(y, dtype=float)
        return np.where(y_arr < self.crown_y_m, self.cross_slope, -self.cross_slope)

    def slow_height(self, x: ArrayLike, y: ArrayLike) -> NDArray[np.float64]:
        """The smooth road (hills + crossfall) without roughness or anomalies."""
        x_arr, y_arr = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
        return self.hills(x_arr) + self.crossfall(y_arr)

    def roughness(self, x: ArrayLike, y: ArrayLike) -> NDArray[np.float64]:
        """The random roughness at (X, Y), interpolated between (and mirrored beyond) the tracks."""
        x_arr, y_arr = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
        n = self.left_profile.size
        pos = np.clip(x_arr / self.dx_m, 0.0, n - 1.0)
        i0 = np.minimum(pos.astype(np.intp), n - 2) if n > 1 else np.zeros(pos.shape, np.intp)
        frac = pos - i0
        left = self.left_profile[i0] * (1 - frac) + self.left_profile[i0 + 1] * frac
        right = self.right_profile[i0] * (1 - frac) + self.right_profile[i0 + 1] * frac
        u = (y_arr - self.right_track_y_m) / (self.left_track_y_m - self.right_track_y_m)
        # triangle wave in Y: 0 on the right track, 1 on the left one, mirrored beyond them
        w_left = 1.0 - np.abs(np.mod(u, 2.0) - 1.0)
        return (1.0 - w_left) * right + w_left * left

    def anomaly_height(self, x: ArrayLike, y: ArrayLike) -> NDArray[np.float64]:
        """The sum of the anomalies' contributions at (X, Y)."""
        x_arr, y_arr = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
        out = np.zeros(x_arr.shape)
        for a in self.anomalies:
            mask = (x_arr >= a.start_x_m) & a.covers_y(y_arr)
            if a.kind != "step":
                mask &= x_arr <= a.end_x_m
            if mask.any():
                out[mask] += a.profile(x_arr[mask])
        return out

    def height(self, x: ArrayLike, y: ArrayLike) -> NDArray[np.float64]:
        """Road elevation in m at world (X, Y); vectorised, broadcasts ``x`` against ``y``."""
        x_arr, y_arr = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
        return (
            self.hills(x_arr)
            + self.crossfall(y_arr)
            + self.roughness(x_arr, y_arr)
            + self.anomaly_height(x_arr, y_arr)
        )


# -- generation -------------------------------------------------------------------------


def _rough_spectrum(
    cfg: RoadConfig, n_samples: int, rng: np.random.Generator
) -> tuple[NDArray[np.complex128], NDArray[np.complex128]]:
    """Fourier coefficients (``irfft`` convention) of the left and right roughness tracks:
    amplitudes sqrt(2 Gd(n) dn) on both, random phases, the right track's phase lagging the
    left one's by a wrapped-normal random angle so that the tracks correlate by the coherence."""
    nbin = n_samples // 2 + 1
    dn = 1.0 / (n_samples * cfg.resolution_m)
    n = np.arange(nbin) * dn
    band = (n >= cfg.min_wavenumber_cpm) & (np.arange(nbin) > 0)
    if n_samples % 2 == 0:
        band[-1] = False  # the Nyquist bin cannot carry an arbitrary phase
    amp = np.zeros(nbin)
    if cfg.iso_class != "off":
        amp[band] = np.sqrt(2.0 * iso8608_psd(n[band], cfg.iso_class) * dn)
    phase_left = rng.uniform(0.0, 2 * np.pi, nbin)
    c = cfg.track_coherence
    if c > 0:
        # wrapped-normal phase lag: E[cos(lag)] = exp(-sigma^2 / 2) = c, the track correlation
        sigma = math.sqrt(-2.0 * math.log(c))
        phase_right = phase_left + sigma * rng.standard_normal(nbin)
    else:
        phase_right = rng.uniform(0.0, 2 * np.pi, nbin)
    scale = 0.5 * n_samples * amp
    return scale * np.exp(1j * phase_left), scale * np.exp(1j * phase_right)


def _hills(
    cfg: RoadConfig, rng: np.random.Generator
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Three sinusoids around the hill wavelength, scaled so the largest grade on the road
    equals ``hill_grade_pct``."""
    ratios = np.array([1.0, 0.55, 1.8])
    rel_amp = np.array([1.0, 0.35, 0.8])
    k = 2 * np.pi / (cfg.hill_wavelength_m * ratios)
    phases = rng.uniform(0.0, 2 * np.pi, 3)
    if cfg.hill_grade_pct <= 0:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    xs = np.linspace(0.0, cfg.length_m, max(200, int(cfg.length_m / 2.0)))
    grade = (rel_amp[:, None] * k[:, None] * np.cos(k[:, None] * xs + phases[:, None])).sum(0)
    peak = float(np.abs(grade).max())
    amps = rel_amp * (cfg.hill_grade_pct / 100.0) / peak
    return amps, k, phases


def _random_anomaly(kind: str, x0: float, cfg: RoadConfig, rng: np.random.Generator) -> Anomaly:
    """One anomaly of ``kind`` starting at ``x0``, its size drawn from typical real ranges."""
    half_track = 0.5 * cfg.track_spacing_m
    lane = cfg.lane_width_m
    if kind == "bump":
        h = rng.uniform(0.03, 0.10)
        length = rng.uniform(0.3, 4.0)
        ramp = min(h / math.tan(math.radians(rng.uniform(7.0, 25.0))), 0.45 * length)
        return Anomaly(
            kind=kind, start_x_m=x0, length_m=length, height_m=h, width_m=lane, ramp_m=ramp
        )
    if kind == "cushion":
        h = rng.uniform(0.05, 0.08)
        length = rng.uniform(2.0, 3.5)
        ramp = min(h / math.tan(math.radians(rng.uniform(7.0, 12.0))), 0.45 * length)
        return Anomaly(
            kind=kind,
            start_x_m=x0,
            length_m=length,
            height_m=h,
            width_m=rng.uniform(1.7, 1.9),
            ramp_m=ramp,
        )
    if kind == "pothole":
        depth = rng.uniform(0.02, 0.08)
        length = rng.uniform(0.3, 1.0)
        width = rng.uniform(0.3, 0.8)
        where = rng.choice(3, p=[0.4, 0.4, 0.2])  # left track, right track, between the tracks
        centre = (half_track, -half_track, 0.0)[int(where)] + rng.uniform(-0.1, 0.1)
        if where == 2:
            width = min(width, cfg.track_spacing_m - 0.4)
        return Anomaly(
            kind=kind,
            start_x_m=x0,
            length_m=length,
            height_m=-depth,
            center_y_m=centre,
            width_m=width,
            ramp_m=rng.uniform(0.0, 0.05),
        )
    if kind == "step":
        h = rng.uniform(0.01, 0.03) * rng.choice([-1.0, 1.0])
        return Anomaly(
            kind=kind, start_x_m=x0, length_m=rng.uniform(0.0, 0.05), height_m=h, width_m=lane
        )
    if kind == "wave":
        length = rng.uniform(5.0, 30.0)
        return Anomaly(
            kind=kind,
            start_x_m=x0,
            length_m=length,
            height_m=rng.uniform(0.01, 0.04),
            width_m=lane,
            wavelength_m=rng.uniform(1.5, 6.0),
        )
    raise ConfigError(f"anomaly kind {kind!r}: must be one of {list(ANOMALY_KINDS)}")


def _random_anomalies(cfg: RoadConfig, rng: np.random.Generator) -> list[Anomaly]:
    """Poisson-many anomalies at uniform positions, kinds drawn from ``anomaly_mix``."""
    count = int(rng.poisson(cfg.anomaly_density_per_km * cfg.length_m / 1000.0))
    margin = min(20.0, 0.1 * cfg.length_m)
    starts = np.sort(rng.uniform(margin, cfg.length_m - margin, count))
    kinds = [k for k, w in cfg.anomaly_mix.items() if w > 0]
    weights = np.array([cfg.anomaly_mix[k] for k in kinds], dtype=float)
    chosen: NDArray[np.int64] = (
        rng.choice(len(kinds), size=count, p=weights / weights.sum())
        if kinds
        else np.zeros(0, dtype=np.int64)
    )
    out: list[Anomaly] = []
    last_end = -math.inf
    for x0, ki in zip(starts, chosen, strict=True):
        a = _random_anomaly(kinds[int(ki)], float(x0), cfg, rng)
        end = a.start_x_m + a.length_m  # a step's transition; it persists beyond
        if a.start_x_m - last_end < cfg.anomaly_min_spacing_m or end > cfg.length_m:
            continue
        out.append(a)
        last_end = end
    return out


def generate_road(cfg: RoadConfig, rng: np.random.Generator) -> Road:
    """A random road from ``cfg``; the same generator state gives the same road."""
    check_ranges(cfg, "road")
    cfg.validate("road")
    n_needed = math.ceil(cfg.length_m / cfg.resolution_m) + 1
    n_samples = fft.next_fast_len(n_needed, real=True)
    left_c, right_c = _rough_spectrum(cfg, n_samples, rng)
    left = fft.irfft(left_c, n_samples)[:n_needed]
    right = fft.irfft(right_c, n_samples)[:n_needed]
    amps, ks, phases = _hills(cfg, rng)
    anomalies = (
        list(cfg.anomalies)
        if cfg.anomalies
        else (_random_anomalies(cfg, rng) if cfg.anomaly_density_per_km > 0 else [])
    )
    half = 0.5 * cfg.track_spacing_m
    return Road(
        length_m=cfg.length_m,
        lane_width_m=cfg.lane_width_m,
        dx_m=cfg.resolution_m,
        left_profile=np.ascontiguousarray(left),
        right_profile=np.ascontiguousarray(right),
        left_track_y_m=half,
        right_track_y_m=-half,
        hill_amplitudes_m=amps,
        hill_wavenumbers_rad_per_m=ks,
        hill_phases_rad=phases,
        cross_slope=cfg.cross_slope_pct / 100.0,
        anomalies=anomalies,
    )


__all__ = [
    "ANOMALY_KINDS",
    "ISO8608_GD_N0",
    "Anomaly",
    "Road",
    "RoadConfig",
    "generate_road",
    "iso8608_psd",
    "paper_speed_bump",
]
