"""The road-profile preview recovers a known road through the nominal car's response."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from tests.preview.conftest import box_bump, flat, lead_spot_ahead_m, synth_samples

from roadpreview.anomaly.base import TrajectorySample
from roadpreview.errors import ConfigError, InputDataError
from roadpreview.preview import PreviewConfig, ProfileEstimator
from roadpreview.types import RoadPreview

SPEED = 50 / 3.6
DIST = 15.0
#: where the bump starts along the lead's front wheel path, m (crossed at 4.32 s)
BUMP_S = 60.0


def run(samples: list[TrajectorySample], config: PreviewConfig | None = None) -> list[RoadPreview]:
    est = ProfileEstimator(config)
    return [p for s in samples if (p := est.push(s)) is not None]


def at(previews: list[RoadPreview], t: float) -> RoadPreview:
    return min(previews, key=lambda p: abs(p.t_s - t))


@pytest.fixture(scope="module")
def bump_previews() -> list[RoadPreview]:
    bump = box_bump(BUMP_S)
    return run(synth_samples(bump, bump))


def test_a_bump_is_recovered_where_it_is(bump_previews: list[RoadPreview]) -> None:
    """A 60 mm, 0.5 m bump under both tracks, lead at 15 m and 50 km/h, f = 1000 px,
    0.15 px of tracking noise. The suspension passes the bump's volume (height x length),
    not its shape: with the ISO 8608 class B prior the 0.5 m bump comes out about 2 m wide
    (measured: 12 mm peak, 1.5 m at half height). Tolerances: peak within 1 m of the
    bump's middle; peak height 8-25 mm; the volume above the local level within 35 %."""
    t_cross = (BUMP_S + 0.25) / SPEED
    for age in (0.6, 1.0):  # the bump half-way to the ego, and near it
        p = at(bump_previews, t_cross + age)
        assert p.sides
        assert p.height_m.shape[0] == 2
        x_true = lead_spot_ahead_m(DIST, SPEED, p.t_s - t_cross)
        h = np.nanmean(p.height_m, axis=0)
        k = int(np.nanargmax(h))
        assert abs(p.centres_m[k] - x_true) <= 1.0
        assert 0.008 <= h[k] <= 0.025
        near = np.abs(p.centres_m - x_true) <= 2.0
        level = np.nanmedian(h[~near])
        volume = float(np.nansum(h[near] - level) * p.bin_m)
        assert volume == pytest.approx(0.06 * 0.5, rel=0.35)
        assert np.all(p.std_m[p.valid] < 0.01)


def test_preview_geometry(bump_previews: list[RoadPreview]) -> None:
    """Bins of 0.5 m from the ego's front axle to the lead's rear axle (15 + 0.9 - 0.2 m)."""
    p = bump_previews[-1]
    assert p.bin_m == 0.5
    assert p.start_m == 0.0
    assert p.lead_rear_axle_m == pytest.approx(DIST + 0.9 - 0.2, abs=1e-6)
    assert p.height_m.shape[1] == math.ceil(p.lead_rear_axle_m / 0.5)
    assert p.valid.all()
    # one preview per period of frame time (RP_PREVIEW's cycle), after the first
    dts = np.diff([q.t_s for q in bump_previews])[1:]
    assert np.all(np.abs(dts - PreviewConfig().period_s) < 0.034)


def test_flat_road_is_flat() -> None:
    """Tracking noise alone: every bin valid and within 5 mm (measured RMS ~1 mm)."""
    previews = run(synth_samples(flat, flat, seed=3))
    late = [p for p in previews if p.t_s > 5.0]
    h = np.concatenate([p.height_m.ravel() for p in late])
    assert all(p.valid.all() for p in late)
    assert np.abs(h).max() < 0.005
    assert np.sqrt(np.mean(h**2)) < 0.002


def test_one_sided_bump_is_on_the_right_track_only() -> None:
    previews = run(synth_samples(flat, box_bump(BUMP_S), seed=5))
    t_cross = (BUMP_S + 0.25) / SPEED
    p = at(previews, t_cross + 0.8)
    left, right = p.height_m
    assert np.nanmax(right) > 0.008
    assert np.nanmax(np.abs(left)) < 0.4 * np.nanmax(right)
    x_true = lead_spot_ahead_m(DIST, SPEED, p.t_s - t_cross)
    assert abs(p.centres_m[int(np.nanargmax(right))] - x_true) <= 1.0


def test_without_halves_one_track() -> None:
    samples = [replace(s, y_c_left=math.nan, y_c_right=math.nan) for s in synth_samples(flat, flat)]
    p = run(samples)[-1]
    assert not p.sides
    assert p.height_m.shape[0] == 1
    assert p.valid.all()


@pytest.mark.parametrize(
    "change",
    [
        {"focal_px": math.nan},
        {"valid": False},
        {"lead_distance_m": math.nan},
        {"ego_speed_mps": None},
        {"y_c": math.nan},
    ],
)
def test_missing_inputs_give_nan_bins(change: dict[str, object]) -> None:
    samples = [replace(s, **change) for s in synth_samples(flat, flat, duration_s=3.0)]  # type: ignore[arg-type]
    previews = run(samples)
    assert len(previews) == pytest.approx(3.0 / PreviewConfig().period_s, abs=1)
    for p in previews:
        assert p.height_m.shape[1] > 0
        assert not p.valid.any()
        assert np.isnan(p.height_m).all()


def test_lost_lead_then_back() -> None:
    """A lead lost for 1 s: NaN bins while the history after the gap is short, estimates
    again once it refills; a NaN time is skipped; times must increase."""
    samples = synth_samples(flat, flat, duration_s=8.0)
    lost = [replace(s, valid=False) if 3.0 <= s.t < 4.0 else s for s in samples]
    est = ProfileEstimator()
    out = []
    for s in lost:
        p = est.push(s)
        if p is not None:
            out.append(p)
    assert est.push(replace(samples[-1], t=math.nan)) is None

    def at(t: float) -> RoadPreview:
        return min(out, key=lambda q: abs(q.t_s - t))

    assert not at(4.0).valid.any()
    assert at(8.0).valid.all()
    with pytest.raises(InputDataError):
        est.push(samples[0])


def test_restart_drops_history() -> None:
    samples = synth_samples(flat, flat, duration_s=6.0)
    est = ProfileEstimator()
    for s in samples[:150]:
        est.push(s)
    est.restart()
    p = None
    for s in samples[150:160]:
        p = est.push(s) or p
    assert p is not None
    assert not p.valid.any()


def test_disabled_and_config_ranges() -> None:
    est = ProfileEstimator(PreviewConfig(enabled=False))
    assert all(est.push(s) is None for s in synth_samples(flat, flat, duration_s=1.0))
    with pytest.raises(ConfigError):
        ProfileEstimator(PreviewConfig(period_s=0.0))
    with pytest.raises(ConfigError):
        ProfileEstimator(PreviewConfig(bin_m=10.0, max_range_m=5.0))
