"""The two-axle detector's refinement of a confirmed event (`refine_event`): every
duration's template fitted to one common window around the detection's crossing
(`roadpreview.anomaly.two_axle`, step 6 of its docstring)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from roadpreview.anomaly.base import AnomalyEvent
from roadpreview.anomaly.config import TwoAxleConfig
from roadpreview.anomaly.response import TemplateBank
from roadpreview.anomaly.two_axle_signal import (
    COL_D,
    COL_DSTD,
    COL_T,
    HEAVE,
    ROLL,
    FloatArray,
    Whitener,
)
from roadpreview.types import Side


@dataclass(frozen=True)
class Hypothesis:
    """What a candidate event was fitted with, for refining it when it is confirmed."""

    center_s: float  #: centre of the anomaly's pulse under the front axle, s
    tau_s: float  #: the two-axle lag, s (NaN: unknown)
    channel: int  #: HEAVE or ROLL
    noise_m: float  #: the background std of the amplitude, m (NaN: not metric)
    focal_px: float


def refine_event(
    event: AnomalyEvent,
    hyp: Hypothesis,
    *,
    cfg: TwoAxleConfig,
    bank: TemplateBank,
    durations: FloatArray,
    rows: FloatArray,
    x: FloatArray,
    d: FloatArray,
    dt: float,
    innovation_std: FloatArray,
    whiteners: tuple[Whitener, Whitener],
) -> AnomalyEvent:
    """``event`` refined (`TwoAxleDetector._refine`'s docstring) on the detector's frames
    ``rows``, its channels ``x`` on the regular grid of step ``dt`` ending at the last
    frame, the known lead distances ``d``, the channels' white-noise stds and filters."""
    dur = durations
    n = x.shape[0]
    t_now = float(rows[-1, COL_T])
    search = cfg.refine_search_s
    grid_t = t_now - dt * np.arange(n - 1, -1, -1)
    shifts = np.arange(-search, search + 0.5 * dt, dt)
    centers = hyp.center_s + shifts  # (K,)
    starts = centers[:, None] - 0.5 * dur[None, :]  # (K, J)
    rel = grid_t[None, None, :] - starts[:, :, None]  # (K, J, n)
    k_n, j_n = starts.shape
    s = bank.two_axle(rel.reshape(k_n * j_n, n), hyp.tau_s, cfg.vehicle.rho, rows=j_n)
    s *= -hyp.focal_px / float(np.median(d))
    # per channel: the whitened fit's correlation and energy at every (alignment,
    # duration), weighted by the channel's white-noise variance (the roll channel's
    # widened by the heave's leak)
    corr, energy_c = [], []
    sd = innovation_std
    weights = (
        1.0 / sd[HEAVE] ** 2,
        1.0 / (sd[ROLL] ** 2 + (cfg.roll_leak_fraction * sd[HEAVE]) ** 2),
    )
    for c in (HEAVE, ROLL):
        xc = x[:, c]
        if not np.isfinite(xc).all() or not math.isfinite(weights[c]):
            corr.append(np.zeros(k_n * j_n))
            energy_c.append(np.zeros(k_n * j_n))
            continue
        w = whiteners[c]
        sw = w.apply(s)
        s_r = sw - sw.mean(axis=1, keepdims=True)
        xw = w.apply(xc)
        corr.append(weights[c] * (s_r @ (xw - xw.mean())))
        energy_c.append(weights[c] * (s_r * s_r).sum(axis=1))
    # the GLRT of each side hypothesis: the channels' amplitudes are (h, 0) for both
    # sides, (h / 2, h) for the left, (h / 2, -h) for the right
    sides: tuple[tuple[Side, float, float], ...] = (
        (Side.BOTH, 1.0, 0.0),
        (Side.LEFT, 0.5, 1.0),
        (Side.RIGHT, 0.5, -1.0),
    )
    if not (energy_c[ROLL] > 0).any():
        sides = ((Side.BOTH, 1.0, 0.0),)
    # the detection's crossing as a prior (a Gaussian of std ``refine_prior_s`` on the
    # shift, in the fit's chi-square units): a side lobe half a body period off, of the
    # opposite sign, takes the crossing (and the height's sign) only when it fits
    # decisively better, not by a hair that the libraries' last bits decide
    penalty = np.repeat((shifts / cfg.refine_prior_s) ** 2, j_n)
    best_e, best_side, amp, energy = -math.inf, event.side, np.zeros(1), np.zeros(1)
    for side, u_h, u_r in sides:
        num = u_h * corr[HEAVE] + u_r * corr[ROLL]
        den = u_h * u_h * energy_c[HEAVE] + u_r * u_r * energy_c[ROLL]
        with np.errstate(invalid="ignore", divide="ignore"):
            a = num / np.where(den > 0, den, np.nan)
            e = a * num - penalty
        if np.isfinite(e).any() and float(np.nanmax(e)) > best_e:
            best_e, best_side, amp, energy = float(np.nanmax(e)), side, a, e
    if not math.isfinite(best_e) or float(np.nanmax(energy + penalty)) <= 0:
        return event
    e2 = energy.reshape(k_n, j_n)
    a2 = amp.reshape(k_n, j_n)
    k, best = np.unravel_index(int(np.nanargmax(e2)), e2.shape)
    # every (alignment, duration) that fits almost as well bounds the height: its
    # posterior within (1 - close_fit_fraction) of the best's fit energy of the best's
    fit_best = float(e2[k, best] + penalty.reshape(k_n, j_n)[k, best])
    close = np.isfinite(e2) & (e2 >= e2[k, best] - (1.0 - cfg.close_fit_fraction) * fit_best)
    spread = float(np.std(a2[close])) if np.count_nonzero(close) > 1 else 0.0
    height = float(a2[k, best])
    length = math.nan
    if best > 0 and not close[:, 0].any() and math.isfinite(event.lead_speed_mps):
        length = event.lead_speed_mps * float(dur[best])
    t_cross = float(centers[k])
    # the lead's distance at the refined crossing (nearest frame that has one)
    times = rows[:, COL_T]
    known = np.flatnonzero(np.isfinite(rows[:, COL_D]))
    i = int(known[np.argmin(np.abs(times[known] - t_cross))])
    distance = float(rows[i, COL_D])
    v = cfg.vehicle
    if event.side is Side.UNKNOWN:
        best_side = Side.UNKNOWN  # no halves: the side stays unknown
    return replace(
        event,
        t_s=t_cross,
        side=best_side,
        height_m=height,
        height_std_m=math.hypot(hyp.noise_m, spread),
        length_m=length,
        lead_distance_m=distance,
        lead_distance_std_m=float(rows[i, COL_DSTD]),
        anomaly_distance_m=distance + v.rear_overhang_m + v.wheelbase_m,
    )
