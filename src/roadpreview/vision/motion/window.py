"""The lead found as a rigid window: the vehicle ahead is a block of points that expand
as one plane, slower than the road at its base, standing on road that moves as road.

`find_lead_window` tries candidate bases (rows) x lateral offsets at once (vectorised
over windows x points) and keeps the nearest good one; `masked_median` gives every
window's median expansion from one sort.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from roadpreview.vision.base import F64
from roadpreview.vision.motion.config import MotionFinderConfig
from roadpreview.vision.motion.egomotion import PointMotion, ViewGeometry, road_expansion


@dataclass(frozen=True)
class LeadWindow:
    """The lead window found by the motion (small-image pixels), before its rear fit."""

    #: (x0, y0, x1, y1): the rigid points' columns, the window's top and base rows
    rough: tuple[float, float, float, float]
    #: flat-road distance of the base (m)
    distance_m: float
    #: points in the window
    n: int
    #: their median expansion
    e: float
    #: that expansion over the road's at the base (0: keeps its distance, 1: static)
    ratio: float
    #: lateral offset of the window from our path (m)
    lateral_m: float
    #: it moves with or away from us (else: static in our lane)
    slow: bool


def find_lead_window(
    points: PointMotion,
    res: F64,
    tol: F64,
    k: float,
    geom: ViewGeometry,
    height: int,
    cfg: MotionFinderConfig,
) -> LeadWindow | None:
    """The vehicle ahead as a rigid window: for candidate bases (rows) and lateral
    offsets, a vehicle-sized window whose points expand as one plane, slower than
    the road at its base (or static but in our lane), above road that moves as road.
    The nearest (lowest) such window wins. ``res`` and ``tol`` are each point's motion
    against the road's (px) and what the road allows; ``height`` is the image's.
    Vectorised over windows x points."""
    a, e, rn, y, usable = points.a, points.e, points.rn, points.y, points.usable
    f, foe, v_h, hgt = geom.f, geom.foe, geom.v_horizon, geom.height_m
    h = height
    y_lo = f * hgt / cfg.max_distance_m
    y_hi = (h - 2.0) - v_h
    if y_hi <= y_lo:
        return None
    yb = np.arange(y_hi, y_lo, -3.0)  # nearest first
    lat = np.array([-0.9, -0.45, 0.0, 0.45, 0.9])  # m
    d = f * hgt / yb  # base distance of each candidate
    half = f * cfg.window_half_width_m / d
    xc = foe[0] + lat[None, :] * f / d[:, None]  # (B, L)
    top = yb - f * cfg.window_height_m / d
    below = yb + f * cfg.road_band_m / d
    sel = usable & (y > 0.5)
    px, py = a[sel, 0], y[sel]
    es, rs = e[sel], rn[sel]
    ground = np.abs(res[sel]) <= tol[sel]
    # (B, L, N) membership of each point in each window and in the band below
    inx = np.abs(px[None, None, :] - xc[:, :, None]) <= 0.8 * half[:, None, None]
    inw = inx & (py[None, None, :] <= yb[:, None, None]) & (py[None, None, :] >= top[:, None, None])
    inb = (
        inx & (py[None, None, :] > yb[:, None, None]) & (py[None, None, :] <= below[:, None, None])
    )
    n_w = inw.sum(axis=2)
    if not np.any(n_w >= cfg.min_points):
        return None
    emed = masked_median(es, inw)  # the median expansion of each window
    dev = np.abs(rs[None, None, :] * (es[None, None, :] - emed[:, :, None]))
    tol_w = 2.5 * cfg.noise_px + 0.15 * np.abs(rs[None, None, :] * emed[:, :, None])
    rigid_pts = inw & (dev <= tol_w)
    rigid = rigid_pts.sum(axis=2) / np.maximum(n_w, 1)
    # the object must reach down to the candidate base (else the base is road)
    lowest = np.max(np.where(rigid_pts, py[None, None, :], -np.inf), axis=2)
    reaches = lowest >= yb[:, None] - 0.15 * (yb - top)[:, None]
    n_b = inb.sum(axis=2)
    road_below = np.where(inb, ground[None, None, :], False).sum(axis=2) / np.maximum(n_b, 1)
    eg = road_expansion(k, yb, f)[:, None]
    ratio = emed / np.maximum(eg, 1e-12)
    slow = ratio < cfg.ratio_slow
    static_in_lane = (np.abs(ratio - 1.0) < 0.35) & (np.abs(lat)[None, :] <= 0.5)
    good = (
        (n_w >= cfg.min_points)
        & (rigid >= cfg.min_rigid_fraction)
        & (slow | static_in_lane)
        & reaches
        & (n_b >= 2)
        & (road_below >= 0.5)
    )
    if not good.any():
        return None
    bi = int(np.nonzero(good.any(axis=1))[0][0])  # nearest base row
    row = np.where(good[bi], n_w[bi] * rigid[bi], -1.0)
    li = int(np.argmax(row))
    # the rigid points of every good window at this base: the vehicle's columns
    members = (inw[bi] & (dev[bi] <= tol_w[bi]) & good[bi][:, None]).any(axis=0)
    xs = px[members]
    hx0, hx1 = float(np.percentile(xs, 5)), float(np.percentile(xs, 95))
    return LeadWindow(
        rough=(hx0, float(top[bi] + v_h), hx1, float(yb[bi] + v_h)),
        distance_m=float(d[bi]),
        n=int(n_w[bi, li]),
        e=float(emed[bi, li]),
        ratio=float(ratio[bi, li]),
        lateral_m=float(lat[li]),
        slow=bool(slow[bi, li]),
    )


def masked_median(values: F64, member: NDArray[np.bool_]) -> F64:
    """Median of ``values`` (N,) over the members of each window ``member`` (..., N), NaN
    for an empty window; the same numbers as ``np.nanmedian`` over the masked values,
    from one sort of the values and running member counts (no sort per window)."""
    if values.size == 0:
        return np.full(member.shape[:-1], np.nan)
    order = np.argsort(values, kind="stable")
    v = values[order]
    cnt = np.cumsum(member[..., order], axis=-1, dtype=np.int32)
    n = cnt[..., -1:]
    # the (n - 1) // 2 -th and n // 2 -th members in sorted order (0-based)
    lo = np.argmax(cnt > (n - 1) // 2, axis=-1)
    hi = np.argmax(cnt > n // 2, axis=-1)
    return np.where(n[..., 0] > 0, (v[lo] + v[hi]) / 2, np.nan)
