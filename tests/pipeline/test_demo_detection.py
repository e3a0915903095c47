"""The whole `demo` drive (60 s, 720p, the drive `make demo` replays) against its truth.

The product's detector (two-axle, `roadpreview.anomaly.two_axle`) must raise at most one
false alarm per minute and find every anomaly under both of the lead's wheel tracks (the
speed bumps and the cushion, 60-70 mm) before the ego reaches it (positive lead time: the
alert is a preview, not a report). The demo's one-sided 60 mm pothole (0.8 m long) is not
asserted: the lead's wheel bridges part of it, its body moves 19 mm (heave) and 0.9 deg
(pitch) and its halves alike, so even the true compensated trajectory (truth.npz:
rear-face row less f tan(pitch) and the camera's heave) has s = 0.55 px at the crossing,
against 1.6-2.8 px for the bumps. It is counted and shown as missed by `make demo`.

The detector runs at the operating point chosen on the wild set (threshold_z = 6: the
lowest with at most 0.5 false alarms per minute there). At it, the 60 mm bump the lead
crosses at 14.7 m scores 5.4 (fitted 46 mm against a background of 8.7 mm on this class B
road): its signature is there, measured with the right sign and size, but below the
threshold. Asserted is what the operating point guarantees (every alert is a true preview,
every two-track anomaly is seen, as a bump); "all of them" is the issue's target,
kept as a strict expected failure so that it is noticed when it is met.

The fog bank (34.5-40.5 s, 15 m visibility, 1 s fades) must take the texture away: the
fusion falls back to IMU_ONLY inside it, says why, and is FUSED again once it lifts.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from roadpreview.apps.replay import ReplayInputs, replay
from roadpreview.apps.result import ReplayResult
from roadpreview.pipeline.config import PipelineConfig
from roadpreview.pipeline.truthmatch import MatchReport, MatchRow
from roadpreview.sim.presets import demo
from roadpreview.sim.recording import Recording
from roadpreview.types import FusionMode

pytestmark = pytest.mark.slow  # a simulated drive rendered and replayed: scheduled first


@pytest.fixture(scope="module")
def demo_replay(make_recording: Callable[..., Recording]) -> ReplayResult:
    rec = make_recording("demo", seed=0, duration_s=None, width=None, height=None)
    return replay(ReplayInputs.from_recording(rec.folder), keep_results=True)


@pytest.fixture(scope="module")
def demo_run(demo_replay: ReplayResult) -> MatchReport:
    assert demo_replay.match is not None
    return demo_replay.match


def test_demo_fog_bank_falls_back_to_the_imu_and_recovers(demo_replay: ReplayResult) -> None:
    (fog,) = demo(0).conditions
    modes = [(t - demo_replay.video_start_s, m, why) for t, m, why in demo_replay.mode_changes]
    inside = [(t, why) for t, m, why in modes if m is FusionMode.IMU_ONLY]
    # the texture goes within the fade-in, and the reason names it
    assert any(fog.start_s <= t <= fog.start_s + 2 * fog.ramp_s for t, _ in inside), modes
    assert any("texture" in why for t, why in inside if fog.start_s <= t <= fog.end_s), modes
    # FUSED again within the fade-out plus the 0.3 s re-validation, and to the end
    after = [(t, m) for t, m, _ in modes if t > fog.start_s]
    back = [t for t, m in after if m is FusionMode.FUSED]
    assert back, modes
    assert fog.end_s - fog.ramp_s <= back[0] <= fog.end_s + 1.0, modes
    assert after[-1][1] is FusionMode.FUSED, modes
    # no IMU_ONLY outside the fog after the start-up
    assert all(fog.start_s <= t <= fog.end_s for t, _ in inside if t > 3.0), modes


def test_demo_raises_at_most_one_false_alarm_per_minute(demo_run: MatchReport) -> None:
    assert demo_run.duration_s >= 55.0
    assert demo_run.false_alarms_per_min <= 1.0, demo_run.table()


def _two_track(demo_run: MatchReport) -> list[MatchRow]:
    rows = [r for r in demo_run.rows if r.expected and r.lead_side == "both"]
    assert len(rows) >= 4, demo_run.table()  # four bumps and a cushion in the preset
    return rows


def test_demo_alerts_are_true_previews(demo_run: MatchReport) -> None:
    hits = [r for r in demo_run.rows if r.alert is not None]
    assert len(hits) >= 3, demo_run.table()
    for r in hits:
        assert r.lead_time_s > 0.5, demo_run.table()  # (False for NaN: no arrival)
        assert r.alert is not None  # (a hit)
        assert r.alert.height_mm is not None
        assert r.alert.height_mm * r.height_mm > 0, demo_run.table()  # bump +, pothole -


def test_demo_scores_every_two_track_anomaly_well_above_its_background(
    demo_replay: ReplayResult, demo_run: MatchReport
) -> None:
    """The best score whose window describes the crossing (front axle within -0.3..+0.8 s)
    is well above the background (>= 0.75 of the threshold, i.e. >= 4.5 sigma), and its
    fitted road input is above the alert's minimum height and not above twice the truth.
    (The sign is the alert's, after its refinement: a single frame's best template can be
    the rebound's. Sizes are the inverse model of a typical car, not this lead's: the
    cushion reads 27 mm for 70 mm; height errors are measured in the evaluation.)"""
    assert demo_replay.results is not None
    start = demo_replay.video_start_s
    res = [r for r in demo_replay.results if r.score == r.score]
    score_t = np.array([r.score_t - start for r in res])
    for row in _two_track(demo_run):
        near = [r for r, ts in zip(res, score_t, strict=True) if -0.3 <= ts - row.t_lead_s <= 0.8]
        assert near, f"event {row.event_index}: no score describes its crossing"
        best = max(near, key=lambda r: r.score)
        assert best.score >= 0.75 * best.score_threshold, (row, best.score, demo_run.table())
        height_mm = 1e3 * abs(best.road_input_m)
        min_mm = PipelineConfig().anomaly.two_axle.min_height_mm
        assert min_mm <= height_mm <= 2.0 * row.height_mm, (row, height_mm)


@pytest.mark.xfail(
    strict=True,
    reason="issue 14 target not met: the 60 mm bump at 14.7 m scores 5.4 < threshold_z 6",
)
def test_demo_detects_every_two_track_anomaly_before_the_ego_reaches_it(
    demo_run: MatchReport,
) -> None:
    for r in _two_track(demo_run):
        assert r.alert is not None, f"event {r.event_index} ({r.kind}) missed\n{demo_run.table()}"
        assert r.lead_time_s > 0.5, demo_run.table()
    assert demo_run.recall >= 0.8, demo_run.table()
