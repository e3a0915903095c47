"""Issue 17, items 4-6. The run loop supervises its sources: a source whose iterator raises
is logged, counted and restarted (a file source resumes after its last sample, a live one
after a backoff); one that keeps failing ends the run with `SourceFailed` after the sinks
are closed. The replay's summary lists every input's problems and the inputs that gave
nothing (exit 1 unless ``--allow-missing``); a TOML that is no TOML text is a config
error; ``simulate --duration`` sizes the road. Live sources and the supervisor's backoffs
run on virtual time (`VirtualClock`)."""

from __future__ import annotations

import ctypes.util
import json
import logging
import math
import re
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import can
import numpy as np
import pytest

from roadpreview.camera import CameraModel
from roadpreview.canbus.logio import CanLogWriter
from roadpreview.canbus.mapping import load_mapping
from roadpreview.cli.main import main
from roadpreview.clock import VirtualClock
from roadpreview.errors import ConfigError
from roadpreview.loop import RunSummary, SourceFailed, Supervision, run
from roadpreview.pipeline import FrameResult
from roadpreview.sim.dataset import drive_config
from roadpreview.sim.presets import PRESETS
from roadpreview.sim.road import generate_road
from roadpreview.sim.scenario import ScenarioConfig
from roadpreview.sinks import Sink
from roadpreview.types import Alert, CameraFrame, FusionMode, ImuSample, Sample, Status

if TYPE_CHECKING:
    from roadpreview.sim.recording import Recording

FAST = Supervision(max_restarts=3, backoff_s=0.01, max_backoff_s=0.02, healthy_s=60.0)


@dataclass
class _Result:
    """The fields of a `FrameResult` the loop reads."""

    t: float
    mode: FusionMode = FusionMode.FUSED
    pitch_reason: str = ""
    alerts: list[Alert] = field(default_factory=list)
    provisional: tuple[Alert, ...] = ()
    cancelled: tuple[Alert, ...] = ()
    preview: None = None
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
    sample numbers (counted over all iterations); ``problems`` as the shared contract.
    A live one gives a sample every 10 ms of ``clock``, stamped with its time."""

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
        clock: VirtualClock | None = None,
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
        self.clock = clock or VirtualClock()
        self._closed = self.clock.event()

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
            t = self.t0 + 0.1 * i if not self.live else self.clock.now()
            if self.imu:
                yield ImuSample(t + 0.05, (0.0, 0.0, 0.0), (0.0, 0.0, 9.81))
            else:
                yield CameraFrame(t, None, i)
            if self.live and self.clock.wait(self._closed, 0.01):
                return

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


def _in_thread(clock: VirtualClock, call: Callable[[], RunSummary]) -> threading.Thread:
    """``call`` (a run) in a thread, started once it waits on ``clock``."""
    box: list[Any] = []

    def target() -> None:
        try:
            box.append(call())
        except BaseException as exc:
            box.append(exc)

    thread = threading.Thread(target=target, name="loop", daemon=True)
    thread.box = box  # type: ignore[attr-defined]
    thread.start()
    deadline = time.monotonic() + 60.0  # the threads starting, not a timing
    while clock.waiting < 2 and thread.is_alive():
        assert time.monotonic() < deadline
        time.sleep(0.001)
    return thread


def _ended(clock: VirtualClock, thread: threading.Thread, limit_s: float) -> Any:
    """Move the clock on until ``thread`` ended (at most ``limit_s`` of virtual time); what
    its call returned or raised."""
    end = clock.now() + limit_s
    while thread.is_alive() and clock.now() < end:
        clock.advance(0.005)
    thread.join(timeout=60.0)
    assert not thread.is_alive()
    return thread.box[0]  # type: ignore[attr-defined]


def test_a_live_source_that_raises_once_is_restarted_and_the_run_goes_on() -> None:
    clock = VirtualClock(1000.0)
    camera = _Flaky("camera", 40, raise_at={10}, live=True, clock=clock)
    stage = _Stage()
    stop = clock.event()
    thread = _in_thread(
        clock,
        lambda: run(
            [camera], stage, stop=stop, supervision=FAST, keep_running=True, clock=clock
        ),
    )
    end = clock.now() + 5.0
    while camera.iterations < 2 or len(_times(stage, CameraFrame)) < 40:
        assert clock.now() < end, "the camera was not restarted"
        clock.advance(0.005)
    # frames 0-9 every 10 ms, the death at 0.1 s, a 10 ms backoff, frames 10-39: the
    # 40th at 0.4 s of the camera's clock (the clock moves in steps of 5 ms)
    assert clock.now() - 1000.0 == pytest.approx(0.1 + FAST.backoff_s + 0.29, abs=0.006)
    stop.set()
    summary = _ended(clock, thread, 1.0)
    assert summary.frames == 40  # 10 before the death, 30 after the restart
    assert summary.thread_deaths == {"camera": 1}
    assert summary.source_problems["camera"]["restarted"] == 1
    # the death is also an input error on CAN (StatusInputErrors), until the run ends
    assert stage.input_errors == 1


def test_a_live_source_that_fails_forever_ends_the_run_with_an_error() -> None:
    clock = VirtualClock(1000.0)
    camera = _Flaky("camera", 0, always=True, live=True, clock=clock)
    imu = _Flaky("imu", 10_000, imu=True, live=True, clock=clock)
    sink = _Closed()
    thread = _in_thread(
        clock,
        lambda: run(
            [camera, imu], _Stage(), [sink], supervision=FAST, keep_running=True, clock=clock
        ),
    )
    error = _ended(clock, thread, 10.0)
    assert isinstance(error, SourceFailed)
    assert str(error).startswith("camera: the source failed 4 times in a row")
    # the backoffs, 10 + 20 + 20 ms of the run's clock, and not a hang
    assert clock.now() - 1000.0 == pytest.approx(0.05, abs=0.011)
    assert camera.iterations == FAST.max_restarts + 1
    summary = error.summary
    assert summary is not None
    assert sink.summary is summary
    assert summary.interrupted
    assert summary.error.startswith("camera: the source failed")
    assert "OSError: camera: device gone" in summary.error
    assert summary.thread_deaths == {"camera": 4}
    assert summary.source_problems["camera"] == {"restarted": 3, "thread_died": 4}
    assert "\n" not in str(error)  # one line for the CLI


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


# -- honest summaries and exit codes (issue 17, item 5) ---------------------------------
@pytest.fixture(scope="module")
def drive(make_recording: Callable[..., Recording]) -> Recording:
    # the arguments of tests/daemon/conftest.py's small_drive: the session's cache reuses it
    return make_recording("controlled", seed=0, duration_s=3.0, width=320, height=180)


def _replay(drive: Recording, out: Path, *extra: str) -> tuple[int, dict[str, Any], list[Any]]:
    """``roadpreview replay`` of the drive's video (its calibration and clock) with the
    ``extra`` inputs: exit code, summary.json, the alerts as (id, crossing time, height)."""
    args = ["replay", str(drive.video), "--camera", str(drive.folder / "camera.toml")]
    args += ["--frames-csv", str(drive.frames_csv), "--video-start", repr(drive.t0_unix_s)]
    code = main([*args, *extra, "--out", str(out), "-q"])
    summary = json.loads((out / "summary.json").read_text())
    lines = (out / "alerts.jsonl").read_text().splitlines()
    alerts = [(a["alert_id"], a["t_s"], a["height_mm"]) for a in map(json.loads, lines)]
    return code, summary, alerts


@pytest.fixture(scope="module")
def without_imu(drive: Recording, tmp_path_factory: pytest.TempPathFactory) -> Any:
    """The clean run of the part that is intact: the video without any IMU input."""
    return _replay(drive, tmp_path_factory.mktemp("video_only") / "out")


def test_an_empty_can_log_is_reported_and_fails_the_replay_unless_allowed(
    drive: Recording, without_imu: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    empty = tmp_path / "empty.blf"
    empty.write_bytes(b"")
    code, summary, alerts = _replay(drive, tmp_path / "strict", "--can", str(empty))
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1
    assert err[-1] == (
        f"roadpreview replay: error: unusable input {empty}: the CAN log holds no frame "
        "(the drive ran without it; --allow-missing to accept)"
    )
    assert summary["unusable_inputs"] == [
        {"path": str(empty), "reason": f"{empty}: the CAN log holds no frame"}
    ]
    assert summary["frames"] == without_imu[1]["frames"] == 90  # the whole drive ran
    assert "no IMU input: vision-only fusion (VISUAL_ONLY)" in summary["clock"]["rules"]
    assert summary["modes"]["FUSED"]["seconds"] == 0.0
    assert alerts == without_imu[2]  # the intact part gives what it gives alone
    allowed = ("--can", str(empty), "--allow-missing", "--end", "1")  # 1 s is enough here
    code, summary, _ = _replay(drive, tmp_path / "allowed", *allowed)
    assert code == 0
    assert summary["unusable_inputs"][0]["path"] == str(empty)


def test_a_can_log_of_which_no_frame_maps_is_unusable(
    drive: Recording, without_imu: Any, tmp_path: Path
) -> None:
    foreign = tmp_path / "other_car.log"
    writer = CanLogWriter(foreign)  # another car's ids: nothing the mapping knows
    for i in range(300):
        t = drive.t0_unix_s + 0.01 * i
        writer.write(can.Message(timestamp=t, arbitration_id=0x7A0 + i % 3, data=[i % 256] * 8))
    writer.close()
    code, summary, alerts = _replay(drive, tmp_path / "out", "--can", str(foreign))
    assert code == 1
    (bad,) = summary["unusable_inputs"]
    assert bad["path"] == str(foreign)
    assert "none of its 300 frames maps to an IMU or speed sample" in bad["reason"]
    assert summary["modes"]["FUSED"]["seconds"] == 0.0
    assert alerts == without_imu[2]


def test_an_imu_csv_without_a_valid_row_is_unusable(
    drive: Recording, without_imu: Any, tmp_path: Path
) -> None:
    imu = tmp_path / "imu.csv"
    imu.write_text("t_s,gyro_x\n")
    code, summary, alerts = _replay(drive, tmp_path / "out", "--imu-csv", str(imu))
    assert code == 1
    (bad,) = summary["unusable_inputs"]
    assert bad["path"] == str(imu)
    assert bad["reason"].startswith(f"{imu}:1: header")
    assert alerts == without_imu[2]


def test_the_summary_lists_every_input_problem_and_the_mode_shares(
    drive: Recording, tmp_path: Path
) -> None:
    code, summary, _ = _replay(drive, tmp_path / "out", "--can", str(drive.can_log()))
    assert code == 0
    assert summary["unusable_inputs"] == []
    can_log = str(drive.can_log())
    assert (
        set(summary["inputs_problems"])
        == set(summary["source_errors"])
        == {
            str(drive.video),
            can_log,
        }
    )
    assert summary["source_errors"][can_log] == 0
    assert all(n > 0 for p in summary["inputs_problems"].values() for n in p.values())
    assert summary["thread_deaths"] == {}
    shares = summary["modes"]
    assert sum(m["share"] for m in shares.values()) == pytest.approx(1.0, abs=1e-3)
    drive_s = summary["clock"]["last_frame_rel_s"] - summary["clock"]["first_frame_rel_s"]
    assert sum(m["seconds"] for m in shares.values()) == pytest.approx(drive_s, abs=2e-3)
    # the log's IMU fuses once its time offset is estimated, and stays fused to the end
    fused_at = next(c["t_rel_s"] for c in summary["mode_changes"] if c["mode"] == "FUSED")
    assert summary["mode_changes"][-1]["mode"] == "FUSED"
    last = summary["clock"]["last_frame_rel_s"]
    assert shares["FUSED"]["seconds"] == pytest.approx(last - fused_at, abs=2e-3)
    assert 0 < shares["FUSED"]["share"] < 1


# -- configuration files and long drives (issue 17, items 5 and 6) ----------------------
@pytest.mark.parametrize("kind", ["binary", "folder", "latin-1"])
def test_a_camera_toml_that_is_no_toml_text_is_a_config_error(kind: str, tmp_path: Path) -> None:
    path = tmp_path / "camera.toml"
    if kind == "binary":
        path.write_bytes(bytes(range(256)) * 4)
    elif kind == "folder":
        path.mkdir()
    else:
        path.write_bytes("[camera]\nname = 'Kamera für vorne'\n".encode("latin-1"))
    with pytest.raises(ConfigError) as exc:
        CameraModel.load(path)
    message = str(exc.value)
    assert message.startswith(f"{path}: ")
    assert "\n" not in message
    with pytest.raises(ConfigError, match=re.escape(str(path))):
        load_mapping(path)  # the other TOMLs share the loader


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_every_preset_sizes_its_road_for_a_300_s_drive(name: str) -> None:
    base = drive_config(name, 0)
    with pytest.raises(ConfigError, match="too short"):  # what the CLI did before
        replace(base, motion=replace(base.motion, duration_s=300.0)).validate()
    cfg = base.with_duration(300.0)
    cfg.validate()
    assert cfg.motion.duration_s == 300.0
    assert cfg.with_duration(300.0) == cfg  # long enough: unchanged
    assert base.with_duration(base.motion.duration_s).motion.road == base.motion.road
    # the road holds the whole drive: at least the ego's planned distance ahead of its start
    v_min = min([k.speed_kmh for k in cfg.motion.ego_speed_knots] or [cfg.motion.ego_speed_kmh])
    assert cfg.motion.road.length_m > cfg.motion.ego_start_x_m + 300.0 * v_min / 3.6
    road = generate_road(cfg.motion.road, np.random.default_rng(0))
    if cfg.motion.road.anomaly_density_per_km > 0:  # random anomalies spread over all of it
        far = [a for a in road.anomalies if a.start_x_m > base.motion.road.length_m]
        assert len(far) >= 0.5 * cfg.motion.road.anomaly_density_per_km * (
            (cfg.motion.road.length_m - base.motion.road.length_m) / 1000
        )


def test_simulate_duration_on_the_command_line(tmp_path: Path) -> None:
    out = tmp_path / "rec"
    args = ["simulate", "--preset", "controlled", "--duration", "120", "--resolution", "160x90"]
    assert main([*args, "--write-scenario", "--out", str(out), "-q"]) == 0
    written = ScenarioConfig.load(out / "scenario.toml")
    assert written.motion.duration_s == 120.0
    assert written.motion.road.length_m > drive_config("controlled", 0).motion.road.length_m
    short = ["simulate", "--preset", "controlled", "--duration", "0.5", "--resolution", "160x90"]
    assert main([*short, "--out", str(tmp_path / "short"), "-q"]) == 0
    frames = (tmp_path / "short" / "frames.csv").read_text().splitlines()
    assert len(frames) - 1 == 15  # 0.5 s at 30 fps


def test_the_loop_releases_the_c_heap_every_ten_seconds_of_frames(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A long run's resident set must not creep with freed image buffers left in glibc's
    heap (docs/robustness.md, the soak): the loop hands the free heap back every
    `HEAP_TRIM_PERIOD_S` of the frames' clock, at the first frame and then once a period."""
    import roadpreview.loop as loop_module

    times: list[float] = []
    stage = _Stage()

    def release() -> bool:
        times.append(stage.pushed[-1].t_s)  # the frame it ran after
        return True

    monkeypatch.setattr(loop_module, "release_free_heap", release)

    camera = _Flaky("camera", 351, t0=100.0)  # 35 s of frames at 10 Hz
    run([camera], stage)
    assert loop_module.HEAP_TRIM_PERIOD_S == 10.0
    assert times == pytest.approx([100.0, 110.0, 120.0, 130.0], abs=1e-9)
    # the real call: glibc's malloc_trim on Linux (elsewhere there is nothing to call)
    monkeypatch.undo()
    assert loop_module.release_free_heap() is (ctypes.util.find_library("c") is not None)
