"""Configuration of the road-profile preview (``RP_PREVIEW``, ``docs/method.md``).

Every default carries its unit and the reason for its value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from roadpreview.anomaly.response import ISO8608_N0
from roadpreview.configtools import param
from roadpreview.errors import ConfigError


@dataclass(frozen=True)
class PreviewConfig:
    """The road-profile preview (`roadpreview.preview.ProfileEstimator`)."""

    enabled: bool = param(True, help="produce previews (false: push always returns None)")
    period_s: float = param(
        0.2,
        unit="s",
        gt=0,
        le=10,
        help="a preview every this much frame time (RP_PREVIEW's cycle, 200 ms: the ego"
        " covers 2.8 m at 50 km/h between two, which a receiver shifts by its odometry; a"
        " solve costs about 0.8 ms, so 5 Hz keeps the preview under 0.15 ms a frame at"
        " 30 fps)",
    )
    grid_hz: float = param(
        20.0,
        unit="Hz",
        ge=5.0,
        le=240.0,
        help="the lead's channels are resampled to at most this rate for the inversion: the"
        " body's response lies below 3 Hz and a solve's cost grows with the square of the"
        " grid (at 50 km/h a 20 Hz grid step is 0.7 m of road, a wheel's footprint smeared"
        " by the suspension anyway)",
    )
    bin_m: float = param(
        0.5,
        unit="m",
        gt=0.05,
        le=5,
        help="bin length along the path: a wheel's contact patch and envelope smooth the road"
        " over ~0.3 m; the frame rate samples it every 0.46 m at 50 km/h and 30 fps",
    )
    history_s: float = param(
        4.0,
        unit="s",
        gt=0.5,
        le=20,
        help="most lead history inverted at a preview: it reaches back to when the lead's"
        " front wheels were on the road now under the ego's front axle, (d + 3.4 m) / v"
        " + 0.5 s (1.8 s at 15 m and 50 km/h, 4.5 s at 30 m and 30 km/h); the solve's cost"
        " grows with its square",
    )
    settle_s: float = param(
        1.2,
        unit="s",
        ge=0,
        le=5,
        help="road before the history is unknown too, for this long (plus a wheelbase): its"
        " response (the body rings for ~3 / (2 pi f zeta) = 1.2 s) is still in the oldest"
        " frames",
    )
    max_range_m: float = param(
        60.0,
        unit="m",
        gt=0,
        le=500,
        help="bins beyond this from the ego's front axle are not sent (and without a lead"
        " distance this many metres of NaN bins are)",
    )
    roughness_gd_m3: float = param(
        64e-6,
        unit="m^3",
        gt=0,
        le=0.1,
        help="the road's ISO 8608 G_d(n0) at n0 = 0.1 cycles/m, the prior: class B's mean"
        " (A 16e-6, C 256e-6). G_d(n) ~ n^-2 is a random walk in space with increment"
        " variance 2 pi^2 G_d(n0) n0^2 per metre; larger lets the estimate follow sharper"
        " features and more noise",
    )
    tracking_noise_px: float = param(
        0.15,
        unit="px",
        gt=0,
        le=10,
        help="white noise of the lead's image row, as TwoAxleConfig.tracking_noise_px (LK grid"
        " on a car's rear); the halves' difference has twice its variance",
    )
    camera_to_front_axle_m: float = param(
        0.2,
        unit="m",
        ge=-5.0,
        le=10.0,
        help="the ego's front axle is this far ahead of the camera, as"
        " AlertConfig.camera_to_front_axle_m (the simulator's car: 0.2 m)",
    )
    min_lead_speed_mps: float = param(
        1.0,
        unit="m/s",
        gt=0,
        le=50,
        help="a slower lead gives no preview: its wheels' positions stop ordering the road"
        " and the wheelbase lag tau grows without bound",
    )
    max_gap_s: float = param(
        0.3,
        unit="s",
        gt=0,
        le=5,
        help="dropped frames and invalid stretches up to this long are interpolated; the road"
        " under a longer gap is left without data (its bins widen in std or go NaN)",
    )

    @property
    def increment_var_m2_per_m(self) -> float:
        """Variance of the road's height increment per metre of path, m²/m: the random
        walk whose one-sided PSD is G_d(n0) (n / n0)^-2 (D = 2 π² G_d(n0) n0²)."""
        return 2.0 * math.pi**2 * self.roughness_gd_m3 * ISO8608_N0**2

    def validate(self, where: str = "PreviewConfig") -> None:
        """Cross-field checks."""
        if self.bin_m > self.max_range_m:
            raise ConfigError(
                f"{where}.bin_m = {self.bin_m} m: larger than max_range_m = {self.max_range_m} m"
            )


__all__ = ["PreviewConfig"]
