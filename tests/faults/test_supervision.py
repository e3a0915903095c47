"""Issue 17, item 4: the run loop supervises its sources. A source whose iterator raises is
logged, counted and restarted (a file source resumes after its last sample, a live one
after a backoff); one that keeps failing ends the run with `SourceFailed` after the sinks
are closed. The per-source problem counts reach `RunSummary.source_problems`."""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any, cast

import pytest

from roadpreview.loop import RunSummary, SourceFailed, Supervision, run
from roadpreview.pipeline import FrameResult
from roadpreview.sinks import Sink
from roadpreview.types import Alert, CameraFrame, FusionMode, ImuSample, Sample, Status

FAST = Supervision(max_restarts=3, backoff_s=0.01, max_backoff_s=0.02, healthy_s=60.0)


@dataclass
class _Result:
    """The fields of a `FrameResult` the loop reads."""

    t: float
    mode: FusionMode = FusionMode.FUSED
    pitch_reason: str = ""
    alerts: list[Alert] = field(default_factory=list)
    confirmations: list[Any] = field(default_factory=list)


class _Stage:
    """Records every sample pushed (no estimation: the loop's behaviour only)."""

    def __init__(self) -> None:
        self.input_errors = 0
        self.pushed: list[Sample] = []

    def push(self, sample: Sample) -> FrameResult | None:
        self.pushed.append(sample)
        if isinstance(sample, CameraFrame):
            return cast("FrameResult", _Result(sample.t_s))
        return None

    def finish(self) -> list[Alert]:
        return []

    def status(self) -> Status:
        return Status(mode=FusionMode.FUSED, input_errors_total=self.input_errors)


class _Closed(Sink):
    def __init__(self) -> None:
        self.summary: RunSummary | None = None

    def close(self, summary: RunSummary) -> None:
        self.summary = summary


class _Flaky:
    """A source of frames (or IMU samples) at 10 Hz whose iterator raises at the given
    sample numbers (counted over all iterations); ``problems`` as the shared contract."""

    def __init__(
        self,
        name: str,
        n: int,
        *,
        raise_at: set[int] | None = None,
        always: bool = False,
        live: bool = False,
        imu: bool = False,
        t0: float = 100.0,
    ) -> None:
        self.name = name
        self.n = n
        self.raise_at = raise_at or set()
        self.always = always
        self.live = live
        self.imu = imu
        self.t0 = t0
        self.iterations = 0
        self.problems: Counter[str] = Counter()
        self._given = 0
        self._closed = threading.Event()

    @property
    def errors(self) -> int:
        return 0

    def __iter__(self) -> Iterator[Sample]:
        self.iterations += 1
        if self.always:
            raise OSError(f"{self.name}: device gone")
        for i in range(self.n):
            if self._closed.is_set():
                return
            if self._given in self.raise_at:
                self.raise_at.discard(self._given)
                self.problems["corrupt_frame"] += 1
                raise RuntimeError(f"decoder crashed at sample {i}")
            self._given += 1
            t = self.t0 + 0.1 * i if not self.live else time.time()
            if self.imu:
                yield ImuSample(t + 0.05, (0.0, 0.0, 0.0), (0.0, 0.0, 9.81))
            else:
                yield CameraFrame(t, None, i)
            if self.live:
                time.sleep(0.01)

    def close(self) -> None:
        self._closed.set()


def _times(stage: _Stage, kind: type) -> list[float]:
    return [s.t_s for s in stage.pushed if isinstance(s, kind)]


def test_a_file_source_that_raises_once_is_resumed_after_its_last_sample(
    caplog: pytest.LogCaptureFixture,
) -> None:
    clean, faulty = _Stage(), _Stage()
    run([_Flaky("video", 30), _Flaky("imu", 30, imu=True)], clean)
    video = _Flaky("video", 30, raise_at={12})
    imu = _Flaky("imu", 30, imu=True, raise_at={20})
    sink = _Closed()
    with caplog.at_level(logging.WARNING, logger="roadpreview.loop"):
        summary = run([video, imu], faulty, [sink])
    # nothing lost, nothing twice, in the same order: the fault costs no sample here
    assert [s.t_s for s in faulty.pushed] == [s.t_s for s in clean.pushed]
    assert len(_times(faulty, CameraFrame)) == 30
    assert summary.frames == 30
    assert summary.frames_out_of_order == 0
    assert not summary.interrupted
    assert summary.error == ""
    assert video.iterations == imu.iterations == 2
    assert summary.thread_deaths == {"video": 1, "imu": 1}
    assert summary.source_problems["video"] == {
        "corrupt_frame": 1,
        "restarted": 1,
        "thread_died": 1,
    }
    died = [r.getMessage() for r in caplog.records if "event=thread_died" in r.getMessage()]
    assert len(died) == 2
    assert "source=video" in died[0]
    assert "decoder crashed at sample 12" in died[0]
    assert sink.summary is summary


def test_a_live_source_that_raises_once_is_restarted_and_the_run_goes_on() -> None:
    camera = _Flaky("camera", 40, raise_at={10}, live=True)
    stage = _Stage()
    stop = threading.Event()
    box: list[RunSummary] = []
    thread = threading.Thread(
        target=lambda: box.append(
            run([camera], stage, stop=stop, supervision=FAST, keep_running=True)
        )
    )
    thread.start()
    deadline = time.monotonic() + 5.0
    while camera.iterations < 2 or len(_times(stage, CameraFrame)) < 40:
        assert time.monotonic() < deadline, "the camera was not restarted"
        time.sleep(0.01)
    stop.set()
    thread.join(timeout=5.0)
    assert not thread.is_alive()
    summary = box[0]
    assert summary.frames == 40  # 10 before the death, 30 after the restart
    assert summary.thread_deaths == {"camera": 1}
    assert summary.source_problems["camera"]["restarted"] == 1
    # the death is also an input error on CAN (StatusInputErrors), until the run ends
    assert stage.input_errors == 1


def test_a_live_source_that_fails_forever_ends_the_run_with_an_error() -> None:
    camera = _Flaky("camera", 0, always=True, live=True)
    imu = _Flaky("imu", 10_000, imu=True, live=True)
    sink = _Closed()
    t0 = time.monotonic()
    with pytest.raises(SourceFailed, match=r"^camera: the source failed 4 times in a row") as exc:
        run([camera, imu], _Stage(), [sink], supervision=FAST, keep_running=True)
    assert time.monotonic() - t0 < 3.0  # backoffs of 10-20 ms, not a hang
    assert camera.iterations == FAST.max_restarts + 1
    summary = exc.value.summary
    assert summary is not None
    assert sink.summary is summary
    assert summary.interrupted
    assert summary.error.startswith("camera: the source failed")
    assert "OSError: camera: device gone" in summary.error
    assert summary.thread_deaths == {"camera": 4}
    assert summary.source_problems["camera"] == {"restarted": 3, "thread_died": 4}
    assert "\n" not in str(exc.value)  # one line for the CLI


def test_a_file_source_failing_at_the_same_sample_gives_up() -> None:
    """A deterministic fault: every re-read dies at the same place; no endless loop."""

    class Stuck(_Flaky):
        def __iter__(self) -> Iterator[Sample]:
            self.iterations += 1
            for i in range(self.n):
                if i == 5:
                    raise ValueError("bad sample 5")
                yield CameraFrame(self.t0 + 0.1 * i, None, i)

    source = Stuck("video", 20)
    with pytest.raises(SourceFailed, match="bad sample 5") as exc:
        run([source], _Stage(), supervision=FAST)
    assert source.iterations == FAST.max_restarts + 1
    summary = exc.value.summary
    assert summary is not None
    assert summary.frames == 5
    assert math.isclose(summary.last_t, 100.4)


def test_supervision_refuses_nonsense() -> None:
    with pytest.raises(ValueError, match="max_restarts"):
        Supervision(max_restarts=-1)
    with pytest.raises(ValueError, match="backoff_s"):
        Supervision(backoff_s=3.0, max_backoff_s=1.0)
