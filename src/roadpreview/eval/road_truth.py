"""The simulator's truth for road-profile previews: the true road at the bins, and the errors.

A recording does not store the road: ``truth.npz`` holds per frame the camera pose, the
lead's distance, pitch and heave and the ego's speed, ``truth.json`` the discrete anomalies,
but neither the roughness profiles nor the wheel tracks' heights. ``scenario.toml`` does
regenerate the drive bit for bit, so `drive_for_scenario` rebuilds the `DriveMotion` (road
and both vehicles) from it, and the functions here read the road from that.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from roadpreview.anomaly.response import NominalVehicle
from roadpreview.sim.motion import DriveMotion, simulate_motion
from roadpreview.sim.recording import _seeds
from roadpreview.sim.scenario import ScenarioConfig
from roadpreview.types import RoadPreview

FloatArray = NDArray[np.float64]

#: the true road is averaged over each bin at this spacing, m (the road's own resolution)
_TRUTH_STEP_M = 0.05


def drive_for_scenario(cfg: ScenarioConfig) -> DriveMotion:
    """The drive (road, ego, lead) of a recording's ``scenario.toml``, as
    `roadpreview.sim.recording.write_recording` simulated it (the same seed stream)."""
    return simulate_motion(cfg.motion, _seeds(cfg.seed)["motion"])


def reference_plane(height_m: FloatArray, centres_m: FloatArray) -> FloatArray:
    """``height_m`` (tracks, bins) minus, per track, its least-squares line over the finite
    bins (the previews' reference: level and grade are not observable)."""
    out = np.full(height_m.shape, np.nan)
    for i, row in enumerate(height_m):  # one or two tracks
        ok = np.isfinite(row)
        if not ok.any():
            continue
        x = centres_m[ok] - centres_m[ok].mean()
        r = row[ok] - row[ok].mean()
        if ok.sum() >= 3:
            r = r - x * (x @ r) / (x @ x)
        out[i, ok] = r
    return out


def true_heights(preview: RoadPreview, drive: DriveMotion) -> FloatArray:
    """The true road (tracks, bins) at the preview's bins, with its reference.

    Per bin: the raw road height (no tyre envelope) averaged over the bin along the
    lead's wheel tracks (its line ± half its track), both tracks' mean when the preview
    has one row; then the least-squares line over the bins the preview has an estimate
    for is removed, as the preview's. NaN where the preview has none.
    """
    cfg = drive.config
    x_front = float(drive.ego.sample([preview.t_s]).x[0]) + cfg.ego.cg_to_front_axle_m
    nb = preview.height_m.shape[1]
    sub = np.arange(_TRUTH_STEP_M / 2, preview.bin_m, _TRUTH_STEP_M)
    x = x_front + preview.start_m + preview.bin_m * np.arange(nb)[:, None] + sub[None, :]
    half = 0.5 * cfg.lead.track_m
    left = drive.road.height(x, cfg.lead_lateral_m + half).mean(axis=1)
    right = drive.road.height(x, cfg.lead_lateral_m - half).mean(axis=1)
    rows = np.stack([left, right]) if preview.sides else 0.5 * (left + right)[None, :]
    rows = np.where(preview.valid, rows, np.nan)
    return reference_plane(rows, preview.centres_m)


@dataclass(frozen=True)
class PreviewError:
    """How far a series of previews is from the true road (falsy: no bin compared)."""

    rms_mm: float  #: RMS height error over the compared bins, mm
    max_abs_mm: float  #: the largest absolute error, mm
    true_rms_mm: float  #: RMS of the true road at the same bins (the error's scale), mm
    n_bins: int  #: bins compared (over every preview and track)
    #: correlation of the ego's vertical acceleration predicted from the previews (the
    #: nominal quarter car over the previewed road at its front axle) with the measured one;
    #: NaN: not computed
    accel_correlation: float = math.nan

    def __bool__(self) -> bool:
        return self.n_bins > 0


def compare(
    previews: Sequence[RoadPreview], drive: DriveMotion, *, recent_s: float = 2.0
) -> PreviewError:
    """The error of ``previews`` against the road of ``drive``, over the bins whose spot the
    lead's front wheels passed within the last ``recent_s`` before each preview."""
    cfg = drive.config
    lead_front = drive.lead.x + cfg.lead.cg_to_front_axle_m
    errors: list[FloatArray] = []
    truths: list[FloatArray] = []
    for p in previews:  # previews, not frames
        if not p.valid.any():
            continue
        x_front = float(drive.ego.sample([p.t_s]).x[0]) + cfg.ego.cg_to_front_axle_m
        spot = x_front + p.centres_m
        t_passed = np.interp(spot, lead_front, drive.lead.t, left=-math.inf, right=math.inf)
        recent = (p.t_s - t_passed <= recent_s) & (t_passed <= p.t_s)
        keep = p.valid & recent[None, :]
        if keep.sum() < 3:
            continue
        masked = RoadPreview(
            p.t_s,
            p.bin_m,
            p.start_m,
            np.where(keep, p.height_m, np.nan),
            np.where(keep, p.std_m, np.nan),
            p.sides,
            p.lead_rear_axle_m,
        )
        truth = true_heights(masked, drive)
        est = reference_plane(masked.height_m, p.centres_m)
        errors.append((est - truth)[keep])
        truths.append(truth[keep])
    if not errors:
        return PreviewError(math.nan, math.nan, math.nan, 0)
    err = np.concatenate(errors)
    tru = np.concatenate(truths)
    return PreviewError(
        rms_mm=1e3 * float(np.sqrt(np.mean(err**2))),
        max_abs_mm=1e3 * float(np.abs(err).max()),
        true_rms_mm=1e3 * float(np.sqrt(np.mean(tru**2))),
        n_bins=int(err.size),
        accel_correlation=accel_correlation(previews, drive),
    )


def ego_front_road(
    previews: Sequence[RoadPreview], drive: DriveMotion
) -> tuple[FloatArray, FloatArray]:
    """The road under the ego's front wheels as the previews foresaw it: (ego front axle's
    world X, height), stitched from each preview's bins up to where the next preview's
    ego front axle is (the oldest, best-resolved part of each), each piece's level and
    grade matched to the one before on their overlap."""
    cfg = drive.config
    xs: list[FloatArray] = []
    hs: list[FloatArray] = []
    ordered = [p for p in previews if p.valid.any()]
    fronts = [float(drive.ego.sample([p.t_s]).x[0]) + cfg.ego.cg_to_front_axle_m for p in ordered]
    for i, p in enumerate(ordered):  # previews, not frames
        n = p.valid.sum(axis=0)
        h = np.where(p.valid, p.height_m, 0.0).sum(axis=0) / np.where(n > 0, n, 1)
        h = np.where(n > 0, h, np.nan)  # (no track valid: no estimate)
        x = fronts[i] + p.centres_m
        ok = np.isfinite(h)
        until = fronts[i + 1] if i + 1 < len(ordered) else fronts[i] + p.bin_m
        overlap = ok & (x < until + 2.0)  # the new piece plus 2 m of overlap to match
        if not overlap.any():
            continue
        x, h = x[overlap], h[overlap]
        if xs:
            prev_x, prev_h = xs[-1], hs[-1]
            shared = (x >= prev_x[0]) & (x <= prev_x[-1])
            if shared.sum() >= 2:
                h = h + np.mean(np.interp(x[shared], prev_x, prev_h) - h[shared])
            elif prev_x.size:
                h = h + (prev_h[-1] - h[0])
        start = x > (xs[-1][-1] if xs else -math.inf)
        if start.any():  # (a piece the last one covers whole adds nothing)
            xs.append(x[start])
            hs.append(h[start])
    if not xs:
        return np.zeros(0), np.zeros(0)
    return np.concatenate(xs), np.concatenate(hs)


def accel_correlation(
    previews: Sequence[RoadPreview],
    drive: DriveMotion,
    vehicle: NominalVehicle | None = None,
    *,
    band_hz: tuple[float, float] = (0.5, 4.0),
) -> float:
    """Correlation of the ego's vertical acceleration predicted from the previews with the
    simulated one, both band-passed to ``band_hz`` (the body's band).

    Predicted: the nominal quarter car over the previewed road under the front wheels
    (`ego_front_road`) and, a wheelbase later, the rear ones, their mean (a body whose CG
    is half-way); measured: the ego's CG vertical acceleration. NaN with under 2 s of road.
    """
    veh = vehicle or NominalVehicle()
    x_road, h_road = ego_front_road(previews, drive)
    t = drive.ego.t
    dt = 0.01
    tg = np.arange(t[0], t[-1], dt)
    ego = drive.ego.sample(tg)
    x_front = ego.x + drive.config.ego.cg_to_front_axle_m
    covered = (x_front >= (x_road[0] if x_road.size else math.inf)) & (
        x_front <= (x_road[-1] if x_road.size else -math.inf)
    )
    if covered.sum() * dt < 2.0:
        return math.nan
    tg, x_front, acc = tg[covered], x_front[covered], ego.accel_world[covered, 2]
    w_front = np.interp(x_front, x_road, h_road)
    tf = signal.TransferFunction(
        np.polymul(veh.quarter_car.num, [1.0, 0.0, 0.0]), veh.quarter_car.den
    )
    _, a_front, _ = signal.lsim(tf, w_front - w_front[0], tg - tg[0])
    w_rear = np.interp(x_front - veh.wheelbase_m, x_road, h_road, left=w_front[0])
    _, a_rear, _ = signal.lsim(tf, w_rear - w_rear[0], tg - tg[0])
    predicted = 0.5 * (a_front + a_rear)
    sos = signal.butter(2, band_hz, btype="bandpass", fs=1.0 / dt, output="sos")
    p = signal.sosfiltfilt(sos, predicted)
    m = signal.sosfiltfilt(sos, acc)
    skip = int(1.0 / dt)  # the filters' start
    p, m = p[skip:], m[skip:]
    if p.size < 10 or not (np.std(p) > 0 and np.std(m) > 0):
        return math.nan
    return float(np.corrcoef(p, m)[0, 1])


__all__ = [
    "PreviewError",
    "accel_correlation",
    "compare",
    "drive_for_scenario",
    "ego_front_road",
    "reference_plane",
    "true_heights",
]


@dataclass(frozen=True)
class AnomalyInPreview:
    """How one true anomaly appeared in the preview ``delay_s`` after the lead crossed it."""

    index: int  #: the truth event's index
    kind: str
    height_mm: float  #: its true height (signed)
    length_m: float
    t_s: float  #: the preview's time (NaN: no preview then)
    ahead_m: float  #: the anomaly ahead of the ego's front axle then, m
    previewed_mm: float  #: the previewed height of largest magnitude over it (NaN: none)


def at_anomalies(
    previews: Sequence[RoadPreview],
    drive: DriveMotion,
    events: Sequence[dict[str, object]],
    *,
    delay_s: float = 1.0,
    t0: float = 0.0,
) -> list[AnomalyInPreview]:
    """For each truth event the lead crossed (``truth.json``'s events, times from ``t0``):
    the first preview ``delay_s`` after its front axle did, and the previewed height over
    the anomaly's extent (± half its length and a bin): the largest in magnitude, on any
    track."""
    cfg = drive.config
    times = np.array([p.t_s for p in previews])
    out = []
    for e in events:
        t_lead = e.get("lead_front_t_s")
        if t_lead is None or not e.get("lead_hits"):
            continue
        length = float(e.get("length_m") or 0.0)  # type: ignore[arg-type]
        k = int(np.searchsorted(times, t0 + float(t_lead) + delay_s))  # type: ignore[arg-type]
        t, ahead, seen = math.nan, math.nan, math.nan
        if k < len(previews):
            p = previews[k]
            t = p.t_s
            x_front = float(drive.ego.sample([t - t0]).x[0]) + cfg.ego.cg_to_front_axle_m
            ahead = float(e["apex_x_m"]) - x_front  # type: ignore[arg-type]
            over = np.abs(p.centres_m - ahead) <= 0.5 * length + p.bin_m
            h = np.where(over[None, :] & p.valid, p.height_m, np.nan)
            if np.isfinite(h).any():
                seen = 1e3 * float(h.flat[int(np.nanargmax(np.abs(h)))])
        out.append(
            AnomalyInPreview(
                int(e["index"]),  # type: ignore[call-overload]
                str(e["kind"]),
                1e3 * float(e["height_m"]),  # type: ignore[arg-type]
                length,
                t,
                ahead,
                seen,
            )
        )
    return out
