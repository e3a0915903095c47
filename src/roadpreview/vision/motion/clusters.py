"""Vehicles as clusters of points the static scene cannot explain.

The odd points (moving unlike the road, or across their FOE ray) are grouped into
spatially connected clusters on a grid of cells, each kept to the points that share
one expansion; clusters that expand alike and together fit one vehicle's rear are
merged. A cluster is classified by ``ratio = e_cluster / e_road(base)``: ``vehicle``
(below ``ratio_slow``: moves with or away from us), ``oncoming`` (above ``ratio_fast``
and floating above the road its expansion implies), ``obstacle`` (static-looking, in
our lane); vehicles and obstacles are boxed by their side edges (`refine_sides`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TypedDict

import cv2
import numpy as np
from numpy.typing import NDArray

from roadpreview.vision.base import U8, Box, Detection, box_to_full
from roadpreview.vision.motion.config import MotionFinderConfig
from roadpreview.vision.motion.egomotion import PointMotion, ViewGeometry, road_expansion
from roadpreview.vision.motion.rear import refine_sides


class ClusterRecord(TypedDict):
    """What the finder measured of one cluster or of the lead window (diagnostics)."""

    n: int
    box_small: Box
    e: float
    ratio: float
    distance_m: float
    lateral_m: float
    kind: str


@dataclass
class _Cluster:
    x0: float
    y0: float
    x1: float
    y1: float
    e: float
    n: int


@dataclass(frozen=True)
class Clusters:
    """The clusters' detections (full-resolution boxes), a record of every cluster
    classified (small-image boxes), and why there is no detection ("" when there is)."""

    detections: list[Detection] = field(default_factory=list)
    records: list[ClusterRecord] = field(default_factory=list)
    reason: str = ""


def find_clusters(
    points: PointMotion,
    odd: NDArray[np.bool_],
    k: float,
    geom: ViewGeometry,
    small: U8,
    scale: float,
    full_size: tuple[int, int],
    cfg: MotionFinderConfig,
) -> Clusters:
    """Group the ``odd`` points into rigid clusters, classify and box them (``small`` is
    the reduced image, ``scale`` its scale, ``full_size`` the full image's (w, h))."""
    a, e, rn = points.a, points.e, points.rn
    f, foe, v_h, hgt = geom.f, geom.foe, geom.v_horizon, geom.height_m
    h, w = small.shape
    idx = np.nonzero(odd)[0]
    if idx.size < cfg.min_points:
        return Clusters(reason="every point moves like the static scene")
    cell = cfg.cell_px
    gh, gw = h // cell + 1, w // cell + 1
    occ = np.zeros((gh, gw), np.uint8)
    ci = (a[idx] // cell).astype(np.int64)
    occ[ci[:, 1], ci[:, 0]] = 1
    n_lab, labels = cv2.connectedComponents(occ, connectivity=8)
    lab = labels[ci[:, 1], ci[:, 0]]
    counts = np.bincount(lab, minlength=n_lab)
    y_max = f * hgt / cfg.max_distance_m
    found: list[_Cluster] = []
    for L in np.nonzero(counts >= cfg.min_points)[0]:  # a handful of clusters
        if L == 0:
            continue
        members = idx[lab == L]
        # one rigid object expands by one common e: keep the points near the median
        ec = float(np.median(e[members]))
        dev = np.abs(rn[members] * (e[members] - ec))
        spread = max(1.4826 * float(np.median(dev)), cfg.noise_px)
        members = members[dev <= 3.0 * spread + 1.0]
        if members.size < cfg.min_points:
            continue
        pts = a[members]
        x0, y0 = pts.min(axis=0)
        x1, y1 = pts.max(axis=0)
        if y1 - v_h < y_max:
            continue  # base above the horizon or too far away
        found.append(
            _Cluster(
                float(x0),
                float(y0),
                float(x1),
                float(y1),
                float(np.median(e[members])),
                int(members.size),
            )
        )
    found = _merge(found, f, hgt, v_h, cfg)
    dets: list[Detection] = []
    records: list[ClusterRecord] = []
    for c in found:  # a handful of clusters
        yb = c.y1 - v_h
        e_base = float(road_expansion(k, np.array([yb]), f)[0])
        ratio = c.e / e_base if e_base > 0 else math.inf
        d_base = f * hgt / yb
        lateral = (0.5 * (c.x0 + c.x1) - foe[0]) * d_base / f
        tall_m = (c.y1 - c.y0) * d_base / f
        kind = ""
        score = 0.0
        if ratio < cfg.ratio_slow:
            kind = "vehicle"
            score = float(np.clip(1.0 - ratio, 0.0, 1.0))
        elif ratio > cfg.ratio_fast:
            y_contact = f * c.e / (k * (1.0 + c.e)) if c.e > 0 else math.inf
            if y_contact - yb > max(4.0, 0.25 * y_contact):
                kind = "oncoming"
                score = float(np.clip(1.0 - 1.0 / ratio, 0.0, 1.0))
        if not kind and abs(lateral) <= cfg.lane_half_width_m and tall_m >= 0.4:
            kind = "obstacle"
            score = 0.5
        box_s: Box = (c.x0, c.y0, c.x1, c.y1)
        if kind in ("vehicle", "obstacle"):
            box_s = refine_sides(
                small,
                box_s,
                d_base,
                f,
                min_width_m=cfg.min_vehicle_width_m,
                max_width_m=cfg.max_refine_width_m,
                pad_px=0.25 * cfg.cell_px,
            )
        records.append(
            ClusterRecord(
                n=c.n,
                box_small=box_s,
                e=c.e,
                ratio=ratio,
                distance_m=d_base,
                lateral_m=lateral,
                kind=kind,
            )
        )
        if not kind:
            continue
        box = box_to_full(box_s, scale, *full_size)
        sigma = max(2.0 / scale, 0.05 * (box[2] - box[0]))
        dets.append(Detection(box, score, kind, edge_sigma_px=sigma))
    return Clusters(dets, records, "" if dets else "no cluster moves like a vehicle")


def _merge(
    found: list[_Cluster], f: float, hgt: float, v_h: float, cfg: MotionFinderConfig
) -> list[_Cluster]:
    """Merge clusters that expand alike and together still fit one vehicle's rear."""
    merged = True
    while merged and len(found) > 1:  # a handful of clusters
        merged = False
        for i in range(len(found)):
            for j in range(i + 1, len(found)):
                a, b = found[i], found[j]
                x0, y0 = min(a.x0, b.x0), min(a.y0, b.y0)
                x1, y1 = max(a.x1, b.x1), max(a.y1, b.y1)
                d = f * hgt / max(y1 - v_h, 1e-6)
                if (x1 - x0) * d / f > cfg.max_vehicle_width_m:
                    continue
                if (y1 - y0) * d / f > cfg.max_vehicle_height_m:
                    continue
                if abs(a.e - b.e) > max(cfg.merge_expansion, 0.3 * max(abs(a.e), abs(b.e))):
                    continue
                n = a.n + b.n
                found[i] = _Cluster(x0, y0, x1, y1, (a.e * a.n + b.e * b.n) / n, n)
                del found[j]
                merged = True
                break
            if merged:
                break
    return found
