"""How the simulator's static world is laid out: `SceneConfig` and the road's cross-section."""

from __future__ import annotations

from dataclasses import dataclass

from roadpreview.configtools import check_ranges, param
from roadpreview.errors import ConfigError


@dataclass(frozen=True)
class SceneConfig:
    """How the static world is laid out and how finely its textures are sampled."""

    lane_width_m: float = param(3.5, unit="m", gt=2.0, le=5.0, help="typical European lane")
    shoulder_m: float = param(
        0.75, unit="m", ge=0.0, le=3.0, help="asphalt between edge line and kerb"
    )
    kerb_height_m: float = param(0.12, unit="m", ge=0.0, le=0.3, help="usual urban kerb")
    sidewalk_m: float = param(2.5, unit="m", gt=0.5, le=6.0, help="paved strip behind the kerb")
    verge_m: float = param(13.0, unit="m", gt=4.0, le=40.0, help="textured ground behind the kerb")
    road_texel_m: float = param(
        0.015, unit="m", gt=0.002, le=0.1, help="asphalt grain stays sharp down to ~5 m at 720p"
    )
    ground_texel_m: float = param(0.04, unit="m", gt=0.005, le=0.2, help="sidewalk and grass")
    facade_texel_m: float = param(0.04, unit="m", gt=0.005, le=0.2, help="window frames ~2 texels")
    texture_period_m: float = param(
        48.0,
        unit="m",
        gt=12.0,
        le=200.0,
        help="road texture repeats this often; a multiple of the 12 m dash cycle",
    )
    dash_length_m: float = param(3.0, unit="m", gt=0.5, help="centre-line dash")
    dash_gap_m: float = param(9.0, unit="m", gt=0.5, help="centre-line gap (3 + 9 = 12 m cycle)")
    building_probability: float = param(
        0.8, ge=0.0, le=1.0, help="share of roadside slots with a building rather than a fence"
    )
    setback_m: tuple[float, float] = param(
        (8.0, 11.0), unit="m", help="facade distance from the kerb (min, max)"
    )
    tree_spacing_m: float = param(14.0, unit="m", gt=2.0, help="mean gap between street trees")
    pole_spacing_m: float = param(32.0, unit="m", gt=5.0, help="street lamps")
    parked_car_spacing_m: float = param(45.0, unit="m", gt=6.0, help="mean gap between parked cars")
    n_facade_styles: int = param(8, ge=1, le=32, help="distinct facade textures")
    n_tree_styles: int = param(4, ge=1, le=16, help="distinct tree textures")
    n_parked_models: int = param(6, ge=1, le=64, help="distinct parked-car models")
    margin_m: float = param(
        320.0, unit="m", ge=0.0, help="objects extend this far past the drive (draw distance)"
    )
    tunnel_width_m: float = param(
        0.5, unit="m", ge=0.1, help="walkway between kerb and tunnel wall"
    )
    tunnel_height_m: float = param(5.5, unit="m", gt=3.0, help="ceiling above the road")
    tunnel_light_spacing_m: float = param(8.0, unit="m", gt=1.0, help="ceiling lamps")

    def validate(self, where: str = "SceneConfig") -> None:
        check_ranges(self, where)
        lo, hi = self.setback_m
        if not 2.0 <= lo <= hi:
            raise ConfigError(f"{where}.setback_m = {self.setback_m}: need 2 <= min <= max")
        cycle = self.dash_length_m + self.dash_gap_m
        if abs(self.texture_period_m / cycle - round(self.texture_period_m / cycle)) > 1e-9:
            raise ConfigError(
                f"{where}.texture_period_m = {self.texture_period_m} m must be a multiple of the "
                f"dash cycle {cycle} m (dash_length_m + dash_gap_m)"
            )

    # -- cross-section --------------------------------------------------------------
    @property
    def kerb_right_y(self) -> float:
        """Y of the right kerb (the ego lane is centred at Y = 0)."""
        return -(0.5 * self.lane_width_m + self.shoulder_m)

    @property
    def kerb_left_y(self) -> float:
        """Y of the left kerb, beyond the oncoming lane centred at Y = lane width."""
        return 1.5 * self.lane_width_m + self.shoulder_m
