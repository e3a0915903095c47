"""`RenderConfig`: camera optics, sensor, lighting and drawing limits of the simulated camera."""

from __future__ import annotations

from dataclasses import dataclass

from roadpreview.configtools import check_ranges, param
from roadpreview.errors import ConfigError


@dataclass(frozen=True)
class RenderConfig:
    """Camera, optics and sensor of the simulated front camera, and drawing limits."""

    near_m: float = param(0.3, unit="m", gt=0.0, le=5.0, help="near clipping plane")
    max_distance_m: float = param(
        300.0, unit="m", gt=20.0, help="beyond this the road is haze; f*1.3 m/300 m ~ 4 px"
    )
    lod_px: float = param(
        5.0, unit="px", ge=0.0, help="planes smaller than this are filled with their mean colour"
    )
    lod_thin_px: float = param(
        2.5, unit="px", ge=0.0, help="planes thinner than this (area / longest edge) too"
    )
    mip_bias: float = param(0.0, ge=-2.0, le=2.0, help="+1 = one mip level blurrier")
    sky_downsample: int = param(2, ge=1, le=8, help="the smooth sky is warped at 1/n resolution")
    optics_blur_sigma_px: float = param(
        0.6, unit="px", ge=0.0, le=5.0, help="lens PSF + pixel integration; antialiases edges"
    )
    exposure_ev: float = param(0.0, unit="EV", ge=-8.0, le=8.0, help="manual exposure offset")
    gamma: float = param(2.2, gt=1.0, le=3.0, help="output encoding, the same as the textures'")
    auto_exposure: bool = param(True, help="gain follows the scene light, up to max_gain")
    max_gain: float = param(
        32.0,
        ge=1.0,
        le=1000.0,
        help="auto exposure limit, exposure x analog gain over day (~1/500 -> 1/60 s, x4): 30 dB",
    )
    full_well_e: float = param(
        10000.0, unit="e-", gt=100.0, help="electrons at white at unity gain (small CMOS pixel)"
    )
    read_noise_e: float = param(4.0, unit="e-", ge=0.0, help="read noise")
    noise: bool = param(True, help="add shot + read noise")
    exposure_time_s: float = param(
        0.008, unit="s", ge=0.0, le=0.1, help="for the vertical motion blur of pitch rate"
    )
    motion_blur: bool = param(True, help="blur by f * pitch_rate * exposure_time vertically")
    airlight_bgr: tuple[int, int, int] = param(
        (206, 204, 200), help="fog colour in daylight (BGR); scaled by the light"
    )
    headlights_below_light: float = param(
        0.3, ge=0.0, le=1.0, help="Conditions.light below which the headlights are on"
    )
    headlight_gain: float = param(
        0.004,
        ge=0.0,
        help="low-beam illuminance on axis at headlight_ref_m over daylight (~40 lx / 10 klx)",
    )
    headlight_ref_m: float = param(10.0, unit="m", gt=0.0, help="reference distance of the gain")
    headlight_spread_deg: float = param(
        16.0, unit="deg", gt=1.0, le=90.0, help="horizontal 1/e half-width of the low beam"
    )
    headlight_cutoff_deg: float = param(
        -0.6, unit="deg", ge=-10.0, le=10.0, help="low-beam cut-off elevation"
    )
    lamp_glow_sigma: float = param(
        0.012, gt=0.0, le=0.2, help="glow of lamps at night, fraction of the image height"
    )
    lamp_glow_gain: float = param(1.5, ge=0.0, le=10.0, help="strength of the glow")
    tunnel_light: float = param(
        0.005, ge=0.0, le=1.0, help="tunnel interior lighting over daylight (~50 lx / 10 klx)"
    )
    metering_distance_m: float = param(
        15.0, unit="m", gt=0.0, help="auto exposure meters the road lit by the low beam here"
    )

    def validate(self, where: str = "RenderConfig") -> None:
        check_ranges(self, where)
        if any(not 0 <= c <= 255 for c in self.airlight_bgr):
            raise ConfigError(f"{where}.airlight_bgr = {self.airlight_bgr}: components in 0..255")
