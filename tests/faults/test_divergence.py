"""A diverged fusion (the soak's 320x180 drive reached |phi| >= 90 deg after 11 min and the
compensation raised, ending the drive) costs the frame, not the drive: the frame is not
compensated, the fusion starts again, and it is logged and counted."""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING

import pytest

from roadpreview.apps.replay import ReplayInputs, replay
from roadpreview.fusion.base import FusedPitch
from roadpreview.fusion.streaming import StreamingPitchFusion

if TYPE_CHECKING:
    from roadpreview.sim.recording import Recording


def test_a_diverged_pitch_costs_one_frame_and_resets_the_fusion(
    make_recording: Callable[..., Recording],
    monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
) -> None:
    rec = make_recording("controlled", seed=0, duration_s=3.0, width=320, height=180)
    clean = replay(ReplayInputs.from_recording(rec.folder), keep_results=True)
    assert clean.results is not None
    t_bad = clean.results[45].t  # 1.5 s into the drive
    estimate = StreamingPitchFusion.estimate
    resets: list[float] = []
    reset = StreamingPitchFusion.reset

    def diverging(self: StreamingPitchFusion, t: float) -> FusedPitch:
        fused = estimate(self, t)
        return replace(fused, phi=1.7) if t == t_bad else fused  # 97 deg: diverged

    def counting_reset(self: StreamingPitchFusion) -> None:
        resets.append(1.0)
        reset(self)

    monkeypatch.setattr(StreamingPitchFusion, "estimate", diverging)
    monkeypatch.setattr(StreamingPitchFusion, "reset", counting_reset)
    caplog.set_level(logging.ERROR)
    faulty = replay(ReplayInputs.from_recording(rec.folder), keep_results=True)
    assert faulty.results is not None
    assert faulty.frames == clean.frames  # the drive goes on
    bad = [r for r in faulty.results if r.t == t_bad]
    assert len(bad) == 1
    assert math.isfinite(clean.results[45].y_c)  # the lead was tracked at that frame
    assert math.isnan(bad[0].y_c)  # not compensated: no alert from it
    assert resets == [1.0]  # the fusion started again, once
    assert caplog.text.count("event=pitch_diverged") == 1
    before = [r for r in faulty.results if r.t < t_bad]
    assert [r.y_c for r in before] == [r.y_c for r in clean.results[: len(before)]]
