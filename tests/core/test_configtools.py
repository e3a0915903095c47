"""Typed configuration: unknown keys, wrong types and out-of-range values name the field."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import pytest

from roadpreview import configtools
from roadpreview.configtools import from_mapping, param, to_mapping
from roadpreview.errors import ConfigError


@dataclass(frozen=True)
class Inner:
    speed_kmh: float = param(20.0, unit="km/h", gt=0.0, le=200.0, help="test")
    mode: str = param("a", choices=("a", "b"))


@dataclass(frozen=True)
class Outer:
    seed: int = param(0, ge=0)
    inner: Inner = field(default_factory=Inner)
    gains: tuple[float, float] = (1.0, 2.0)
    name: str | None = None

    def validate(self, where: str) -> None:
        if self.gains[0] > self.gains[1]:
            raise ConfigError(f"{where}.gains: first must not exceed second")


def test_round_trip_through_toml(tmp_path: Path) -> None:
    cfg = Outer(seed=3, inner=Inner(speed_kmh=35.0, mode="b"), gains=(0.5, 4.0), name="x")
    path = tmp_path / "c.toml"
    configtools.save(cfg, path)
    assert configtools.load(Outer, path) == cfg
    assert to_mapping(Outer())["inner"] == {"speed_kmh": 20.0, "mode": "a"}


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"sed": 1}, "unknown key sed"),
        ({"inner": {"speed": 3}}, "unknown key inner.speed"),
        ({"inner": {"speed_kmh": -5}}, r"inner.speed_kmh = -5.0 km/h: must be > 0.0"),
        ({"inner": {"speed_kmh": "fast"}}, "inner.speed_kmh: must be a number"),
        ({"inner": {"mode": "c"}}, "inner.mode"),
        ({"seed": 1.5}, "seed: must be an integer"),
        ({"gains": [1.0]}, "gains: must have 2 elements"),
        ({"gains": [3.0, 1.0]}, "gains: first must not exceed second"),
        ({"inner": 3}, "inner: must be a table"),
    ],
)
def test_errors_name_the_field(data: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        from_mapping(Outer, data, source="scenario.toml")
    with pytest.raises(ConfigError, match=r"scenario\.toml"):
        from_mapping(Outer, data, source="scenario.toml")
