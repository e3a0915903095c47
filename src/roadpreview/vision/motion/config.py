"""Settings of the motion lead finder (``[vision.finder_options]`` when ``finder = "motion"``)."""

from __future__ import annotations

from dataclasses import dataclass

from roadpreview.configtools import check_ranges, param
from roadpreview.vision.motion.rear import RearFitConfig


@dataclass(frozen=True)
class MotionFinderConfig:
    """Settings of `MotionLeadFinder` (small-image pixels unless stated)."""

    small_width_px: int = param(
        640, unit="px", ge=160, le=1920, help="analysis width; the front end's reduced image"
    )
    baseline_s: float = param(
        0.1,
        unit="s",
        gt=0.0,
        le=1.0,
        help="compare with the frame this much earlier: 3 frames at 30 fps give the road "
        "below a lead at 30 m about 0.5 px of parallax at 40 km/h (one frame at 10 fps)",
    )
    cell_px: int = param(
        16, ge=4, le=64, unit="px", help="corner grid cell, whole analysis area (~500 corners)"
    )
    fine_cell_px: int = param(
        6, ge=2, le=32, unit="px", help="finer grid where far leads are (near the FOE)"
    )
    fine_half_width: float = param(
        0.2, gt=0.0, le=0.5, help="fine zone half-width, fraction of the image width"
    )
    fine_below: float = param(
        0.15, gt=0.0, le=1.0, help="fine zone depth below the horizon, fraction of the height"
    )
    above_horizon: float = param(
        0.05,
        ge=0.0,
        le=0.5,
        help="analysis starts this fraction of the height above the horizon (roofs)",
    )
    min_corner: float = param(
        1e-4,
        gt=0.0,
        help="min-eigenvalue threshold (OpenCV's scale for 8-bit images); below is flat",
    )
    lk_window_px: int = param(11, ge=5, le=41, unit="px", help="LK window (half the cost of 15)")
    lk_levels: int = param(3, ge=0, le=6, help="pyramid levels: 8x the window of motion")
    max_fb_px: float = param(0.5, unit="px", gt=0.0, help="forward-backward check")
    min_flow_px: float = param(
        0.5, unit="px", gt=0.0, help="points moving less carry no information on the road's k"
    )
    noise_px: float = param(
        0.35, unit="px", gt=0.0, help="LK noise; the Cauchy scale of the road fit"
    )
    max_perp_px: float = param(
        1.5,
        unit="px",
        gt=0.0,
        help="motion across the FOE ray beyond this (plus 20 %) is not along the road",
    )
    ratio_slow: float = param(
        0.55, ge=0.0, le=1.0, help="object/road expansion below this: moves with or away from us"
    )
    ratio_fast: float = param(1.6, ge=1.0, help="above this (and floating): oncoming")
    min_points: int = param(5, ge=3, help="smallest cluster reported")
    max_distance_m: float = param(
        60.0, unit="m", gt=0.0, help="clusters whose base is farther are ignored"
    )
    lane_half_width_m: float = param(
        1.6, unit="m", gt=0.0, help="a static-looking cluster this close to our path: obstacle"
    )
    min_parallax_px: float = param(
        0.8,
        unit="px",
        gt=0.0,
        help="the road at 10 m must expand at least this much, else the ego is not moving",
    )
    min_road_points: int = param(8, ge=3, help="road points needed to trust the fit of k")
    min_vehicle_width_m: float = param(
        1.4, unit="m", gt=0.0, help="narrowest vehicle rear searched for (small car)"
    )
    max_vehicle_width_m: float = param(
        2.6, unit="m", gt=0.0, help="widest vehicle rear (a truck is 2.55 m)"
    )
    max_refine_width_m: float = param(
        2.2, unit="m", gt=0.0, help="widest rear the symmetric-edge search fits (cars, vans)"
    )
    max_vehicle_height_m: float = param(4.2, unit="m", gt=0.0, help="tallest vehicle")
    window_half_width_m: float = param(
        1.1, unit="m", gt=0.0, help="half-width of the lead window searched (a car and a margin)"
    )
    window_height_m: float = param(
        1.2, unit="m", gt=0.0, help="height of the lead window above its base"
    )
    road_band_m: float = param(
        0.6, unit="m", gt=0.0, help="height of the band below a window that must move as road"
    )
    min_rigid_fraction: float = param(
        0.6, gt=0.0, le=1.0, help="share of a window's points that must expand as one plane"
    )
    rear_min_width_m: float = param(
        1.3,
        unit="m",
        gt=0.0,
        help="narrowest rear fitted at the distance of its bottom row (a small car, "
        "less the horizon's uncertainty)",
    )
    rear_max_width_m: float = param(
        2.6,
        unit="m",
        gt=0.0,
        help="widest rear fitted at the distance of its bottom row (a car's widest "
        "section is ~0.8 m ahead of the contact, a van is 2.0 m wide)",
    )
    rear_rows_below: float = param(
        1.2,
        ge=0.0,
        help="the rear's bottom is searched this far (fraction of the rough width) below "
        "the motion window: a close lead's lower rear hardly moves against its road",
    )
    rear_centre_shift: float = param(
        0.6, ge=0.0, help="lateral search for the rear, fraction of the rough width"
    )
    rear_edge_aspect: float = param(
        0.75,
        gt=0.0,
        le=1.5,
        help="the side edges are measured over this fraction of the width above the "
        "bottom (bumper, lights, tyres)",
    )
    rear_min_edge: float = param(
        1.5,
        ge=0.0,
        help="weaker side edges (times the mean |gx| below the horizon): keep the motion box",
    )
    rear_bottom_sigma: float = param(
        0.25,
        ge=0.0,
        help="1-sigma of the fitted bottom line, fraction of the width: it may be the "
        "lower edge of a shadow cast behind the vehicle rather than the tyres' contact",
    )
    merge_expansion: float = param(
        0.01, ge=0.0, help="clusters whose expansions differ by less may be one vehicle"
    )

    def validate(self, where: str = "MotionFinderConfig") -> None:
        check_ranges(self, where)

    def rear_fit(self) -> RearFitConfig:
        """The rear fit's settings (the ``rear_*`` fields; the rest keep their defaults)."""
        return RearFitConfig(
            min_width_m=self.rear_min_width_m,
            max_width_m=self.rear_max_width_m,
            rows_below=self.rear_rows_below,
            centre_shift=self.rear_centre_shift,
            aspect=self.rear_edge_aspect,
        )
