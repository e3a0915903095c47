"""The two-axle detector's signal side (`roadpreview.anomaly.two_axle`): the ring of
samples, the lead's channels on a regular frame grid (interpolated across dropped frames,
invalid stretches and the ego's own jolts, without the tracker's jumps), the templates
on that grid, the prewhitening filters and the running CFAR background level.

Arrays in, arrays out: the detector holds the state (the ring, the filters, the
background, the caches) and passes what each step needs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, signal

from roadpreview.anomaly.config import TwoAxleConfig
from roadpreview.anomaly.response import TemplateBank

FloatArray = NDArray[np.float64]

#: median |x| / this = std of a Gaussian x (the MAD consistency constant)
MAD_TO_STD = 0.6745
#: order of the prewhitening AR model (at 25-60 fps the body bounce, the tracking noise and
#: the compensation residual need about four poles; 2 underfits a class D road)
AR_ORDER = 4

# columns of the sample ring buffer (`TwoAxleDetector._row`)
COL_T, COL_Y, COL_YD, COL_COMP, COL_D, COL_V, COL_MODE, COL_DSTD, COL_JOLT = range(9)
NCOL = 9
# channels of the fit: heave (whole lead), roll (left - right), the compensation applied
HEAVE, ROLL, COMPENSATION = range(3)


class Ring:
    """The last ``capacity`` rows, readable as one contiguous slice (each row is written
    twice, at i and i + capacity)."""

    def __init__(self, capacity: int, columns: int) -> None:
        self.capacity = capacity
        self.data = np.full((2 * capacity, columns), np.nan)
        self.n = 0  # rows written so far

    def clear(self) -> None:
        self.data.fill(np.nan)
        self.n = 0

    def push(self, row: FloatArray) -> None:
        i = self.n % self.capacity
        self.data[i] = row
        self.data[i + self.capacity] = row
        self.n += 1

    def last(self, m: int) -> FloatArray:
        """The newest ``m`` rows (fewer if fewer were written), oldest first."""
        m = min(m, self.n, self.capacity)
        end = (self.n - 1) % self.capacity + self.capacity + 1
        return self.data[end - m : end]


class CfarBackground:
    """Running level of the fitted amplitudes: per channel and duration, the median of |ĥ|
    over the frames of the last ``span_s`` (anomalies take a few per cent of them: the
    median does not see them), or over the last ``short_s`` when that is higher (the level
    rises within seconds when the road or the tracking gets worse, and falls slowly).
    Rows live in a numpy ring; the medians are recomputed every ``refresh`` pushes."""

    def __init__(
        self, span_s: float, short_s: float, shape: tuple[int, int], refresh: int, capacity: int
    ) -> None:
        self.span_s = span_s
        self.short_s = short_s
        self.shape = shape
        self.refresh = refresh
        self._t = np.full(capacity, -np.inf)
        self._rows = np.full((capacity, shape[0] * shape[1]), np.nan)
        self._n = 0
        self._first_t = math.nan
        self._last_t = math.nan
        self._level = np.full(shape, np.inf)  # inf: no background yet

    @property
    def seconds(self) -> float:
        """Time span of the frames held."""
        if self._n < 2:
            return 0.0
        return min(self._last_t - self._first_t, self.span_s)

    @property
    def pushes(self) -> int:
        """Frames pushed so far."""
        return self._n

    def push(self, t: float, abs_amplitude: FloatArray) -> None:
        i = self._n % self._t.size
        self._t[i] = t
        self._rows[i] = abs_amplitude.ravel()
        if self._n == 0:
            self._first_t = t
        self._last_t = t
        self._n += 1
        if self._n % self.refresh == 0 or self._n == 2:
            self._update(t)

    def _update(self, t: float) -> None:
        recent = self._t >= t - self.span_s
        short = self._t >= t - self.short_s
        level = np.fmax(_nan_median(self._rows[recent]), _nan_median(self._rows[short]))
        level = level.reshape(self.shape) / MAD_TO_STD
        self._level = np.where(np.isfinite(level), level, np.inf)

    def level(self) -> FloatArray:
        """1-std-equivalent background (channel, duration), m (inf: none)."""
        return self._level


def _nan_median(x: FloatArray) -> FloatArray:
    """Median of each column over its finite values (NaN: none), one sort for all."""
    n = np.count_nonzero(np.isfinite(x), axis=0)
    srt = np.sort(x, axis=0)  # NaN sorts last
    cols = np.arange(x.shape[1])
    lo = np.maximum((n - 1) // 2, 0)
    hi = np.maximum(n // 2, 0)
    out = 0.5 * (srt[lo, cols] + srt[hi, cols])
    out[n == 0] = np.nan
    return np.asarray(out)


@dataclass(frozen=True, eq=False)
class TemplateGrid:
    """The templates on a regular frame grid ending now: raw (with `AR_ORDER` + 1 frames
    of history in front, for the filters), each duration's window, and the energy an
    unwhitened fit against a line would have (the white-noise floor)."""

    key: tuple[float, float]  #: (τ, frame interval)
    s: FloatArray  #: (J, m + p + 1)
    inside: FloatArray  #: (J, m) 1 inside each duration's window, 0 outside
    ss_raw: FloatArray  #: (J,)
    n: FloatArray  #: (J,) frames in each window


class Whitener:
    """A channel's prediction-error filter: first differences (a line becomes a constant,
    slow drift goes), then the AR(p) filter A(z) fitted to the background's differences by
    Yule-Walker, so that the road's own bouncing, the tracking noise and the compensation's
    residual come out white and the fit is the GLRT against the background's spectrum.
    A(z) = 1 until the first background has been seen."""

    def __init__(self, channel: int, order: int) -> None:
        self.channel = channel
        self.order = order
        self.a = np.array([1.0])
        self._b = np.array([1.0, -1.0])  # differences, then A(z): one FIR filter
        self.version = 0

    def fit(self, dx: FloatArray) -> None:
        """Fit A(z) to the differenced background samples ``dx`` (finite)."""
        p = self.order
        if dx.size < 10 * p:
            return
        dx = dx - dx.mean()
        r = np.array([np.dot(dx[k:], dx[: dx.size - k]) for k in range(p + 1)]) / dx.size
        if not r[0] > 0:
            return
        try:
            coef = linalg.solve_toeplitz(r[:p], r[1 : p + 1])
        except (np.linalg.LinAlgError, ValueError):
            return
        if np.all(np.isfinite(coef)):
            self.a = np.concatenate([[1.0], -coef])
            self._b = np.convolve(self.a, [1.0, -1.0])
            self.version += 1

    @property
    def white_gain(self) -> float:
        """Std of the output for white input of unit std (differences, then A(z))."""
        return float(np.sqrt(np.sum(self._b**2)))

    def apply(self, x: FloatArray) -> FloatArray:
        """Differences of ``x`` along its last axis through A(z) (an FIR filter), without
        the first p + 1 samples (the filters' start-up): ``x.shape[-1] - p - 1`` values."""
        if x.ndim == 1:
            # the per-frame case: np.convolve is faster than lfilter on one short row
            return np.convolve(x, self._b)[self.order + 1 : x.size]
        y = signal.lfilter(self._b, [1.0], x, axis=-1)
        return np.asarray(y[..., self.order + 1 :])


def template_grid(
    bank: TemplateBank, cfg: TwoAxleConfig, tau: float, dt: float, lag: FloatArray
) -> TemplateGrid:
    """The templates on the regular frame grid ending now (raw, zero outside each
    duration's window), with the filters' history in front."""
    span = lag + cfg.pre_s
    m = math.ceil(float(span.max()) / dt) + 1
    n = m + AR_ORDER + 1
    g = -dt * np.arange(n - 1, -1, -1)  # frame times relative to now
    inside = g[None, :] >= -span[:, None] - 1e-9
    rel = g[None, :] + lag[:, None]
    s = bank.two_axle(rel, tau, cfg.vehicle.rho)
    # the unwhitened fit's energy (against a line): the white tracking noise's floor
    w = inside.astype(float)
    cnt = w.sum(axis=1)
    g_mean = (w * g).sum(axis=1) / cnt
    gc = (g[None, :] - g_mean[:, None]) * w
    s_in = s * w
    s_mean = s_in.sum(axis=1) / cnt
    slope = (gc * s_in).sum(axis=1) / (gc * gc).sum(axis=1)
    s_line = (s_in - s_mean[:, None] - slope[:, None] * gc) * w
    return TemplateGrid(
        key=(tau, dt),
        s=s,
        inside=w[:, AR_ORDER + 1 :],
        ss_raw=(s_line * s_line).sum(axis=1),
        n=cnt,
    )


def whiten_templates(grid: TemplateGrid, whitener: Whitener) -> tuple[FloatArray, FloatArray]:
    """The grid's templates through ``whitener``, minus their mean within each window
    (zero outside it), and their energies."""
    sw = whitener.apply(grid.s)  # (J, m)
    inside = grid.inside
    cnt = inside.sum(axis=1)
    mean = (sw * inside).sum(axis=1) / cnt
    s_r = (sw - mean[:, None]) * inside
    return s_r, (s_r * s_r).sum(axis=1)


def channels_on_grid(
    rows: FloatArray,
    t: float,
    dt: float,
    n: int,
    cfg: TwoAxleConfig,
    ego_level: float,
    diff_std: FloatArray,
) -> FloatArray | None:
    """The channels (heave, roll, compensation) on the ``n`` grid times ending at ``t``
    (n, 3): the frames themselves on a regular grid, else interpolated across dropped
    frames and invalid stretches up to ``max_gap_s`` (a channel with a longer gap, or
    no sample, is NaN); None when the heave channel has such a gap or the history is
    too short. The lead's channels are also interpolated across the ego's own jolts
    (`jolt_mask` with ``ego_level``): the compensation misses part of such sharp motion.
    The result is without the tracker's jumps (`destep` with ``diff_std``)."""
    if rows.shape[0] >= n:
        win = rows[-n:]
        expected = t - dt * np.arange(n - 1, -1, -1)
        x = win[:, (COL_Y, COL_YD, COL_COMP)]
        jolted = jolt_mask(win, cfg, ego_level)
        regular = np.abs(win[:, COL_T] - expected).max() <= 0.25 * dt
        if regular and not jolted.any() and np.isfinite(x[:, 0]).all():
            return destep(x, cfg, diff_std)
    times = rows[:, COL_T]
    grid_t = t - dt * np.arange(n - 1, -1, -1)
    if times[0] > grid_t[0] + 0.5 * dt:
        return None  # not enough history
    first = max(int(np.searchsorted(times, grid_t[0], side="right")) - 1, 0)
    times = times[first:]
    jolted = jolt_mask(rows[first:], cfg, ego_level)
    allowed = cfg.max_gap_s + sum(cfg.jolt_mask_s) if jolted.any() else cfg.max_gap_s
    out = np.full((n, 3), np.nan)
    for c, col in enumerate((COL_Y, COL_YD, COL_COMP)):
        vals = rows[first:, col]
        ok = np.isfinite(vals) & (~jolted if c < 2 else True)
        if np.count_nonzero(ok) < 2:
            continue
        tv = times[ok]
        gaps = np.diff(np.concatenate([[grid_t[0]], tv, [grid_t[-1]]]))
        if gaps.max() > allowed + 0.5 * dt:
            continue
        out[:, c] = np.interp(grid_t, tv, vals[ok])
    return destep(out, cfg, diff_std) if np.isfinite(out[:, 0]).all() else None


def destep(x: FloatArray, cfg: TwoAxleConfig, diff_std: FloatArray) -> FloatArray:
    """The lead's channels without the tracker's jumps: a frame-to-frame change far
    beyond the background's (``glitch_sigma`` robust stds) and beyond its neighbours'
    (``glitch_ratio`` times the largest of the two frames either side; a body moves
    smoothly, a re-seeded grid or a box that snaps does not) is taken out of every
    later sample. ``diff_std``: the robust std of each channel's frame-to-frame change."""
    out = x
    for c in (HEAVE, ROLL):
        sd = diff_std[c]
        col = x[:, c]
        if not math.isfinite(sd) or not np.isfinite(col).all() or col.size < 6:
            continue
        d = np.diff(col)
        ad = np.abs(d)
        if ad.max() <= cfg.glitch_sigma * sd:  # the usual case: no jump at all
            continue
        big = ad > cfg.glitch_sigma * sd
        a = np.abs(np.pad(d, 2, mode="edge"))
        around = np.max(np.stack([a[:-4], a[1:-3], a[3:-1], a[4:]]), axis=0)
        jump = big & (np.abs(d) > cfg.glitch_ratio * around)
        if jump.any():
            if out is x:
                out = x.copy()
            out[1:, c] -= np.cumsum(np.where(jump, d, 0.0))
    return out


def jolt_mask(rows: FloatArray, cfg: TwoAxleConfig, ego_level: float) -> NDArray[np.bool_]:
    """Rows within ``jolt_mask_s`` (before, after) of a frame where the ego itself was
    jolted: its band-passed vertical acceleration peaked at ``jolt_ratio`` times its
    background (``ego_level``, m/s²) and at least ``jolt_min_mps2``."""
    peak = rows[:, COL_JOLT]
    if not math.isfinite(ego_level):
        return np.zeros(rows.shape[0], dtype=np.bool_)
    with np.errstate(invalid="ignore"):
        hit = peak >= max(cfg.jolt_ratio * ego_level, cfg.jolt_min_mps2)
    if not hit.any():
        return hit
    times = rows[:, COL_T]
    before, after = cfg.jolt_mask_s
    out = np.zeros_like(hit)
    for tj in times[hit]:  # a handful of jolt frames per window
        out |= (times >= tj - before) & (times <= tj + after)
    return out


@dataclass
class FrameFit:
    """The fits of one frame: per channel and duration."""

    amplitude: FloatArray  #: (3, J) road input, m (px per template unit without focal/d)
    sigma_fit: FloatArray  #: (J,) white-noise std of the amplitude for 1 px of noise, m
    t_cross: FloatArray  #: (J,) hypothesised front-axle crossing times, s
    valid_fraction: FloatArray  #: (J,) share of valid frames in each window
    n_valid: FloatArray  #: (J,) valid frames in each window
    metric: bool  #: amplitudes are in metres (focal and distance known)
    #: (2, J) whitened template energies of the heave and roll channels, px² per m²: the
    #: amplitude's std is the innovations' std / sqrt(energy)
    energy: FloatArray = field(default_factory=lambda: np.empty((2, 0)))
    innovation: FloatArray = field(default_factory=lambda: np.full(2, np.nan))  #: newest, px
    #: the early fit (`TwoAxleConfig.provisional`): (3, J) amplitudes, m, as ``amplitude``;
    #: (2, J) whitened energies; (J,) unwhitened std per px; (J,) hypothesised pulse centres
    early_amplitude: FloatArray | None = None
    early_energy: FloatArray = field(default_factory=lambda: np.empty((2, 0)))
    early_sigma_fit: FloatArray = field(default_factory=lambda: np.empty(0))
    early_centre: FloatArray = field(default_factory=lambda: np.empty(0))


def background_sigma(
    cfg: TwoAxleConfig,
    white: FloatArray,
    level: FloatArray | float,
    sigma_fit: FloatArray,
    amplitude: FloatArray,
) -> FloatArray:
    """The background std of each amplitude (2, J): the white-noise std ``white`` times the
    background's level (CFAR), never below the tracking noise carried through an
    unwhitened fit (``sigma_fit`` per px); the heave channel widened by the compensation's
    share of ``amplitude`` (its third row), the roll channel by the heave's leak (the halves
    never move quite alike)."""
    sig = np.maximum(white * level, cfg.tracking_noise_px * sigma_fit)
    comp = cfg.compensation_error_fraction * np.abs(amplitude[COMPENSATION])
    sig[HEAVE] = np.hypot(sig[HEAVE], np.where(np.isfinite(comp), comp, 0.0))
    leak = cfg.roll_leak_fraction * np.abs(amplitude[HEAVE])
    sig[ROLL] = np.hypot(sig[ROLL], np.where(np.isfinite(leak), leak, 0.0))
    return np.asarray(sig)
