"""Issue 17: faults injected into the running daemon on python-can ``virtual`` buses. The
camera is a short recording's video (paced), its CAN log is played onto the input bus by
`CanLogPlayer` after an edit (an IMU outage, a clock step, a garbage burst), and the output
is read back from the bus: RP_STATUS (mode, E2E counter, period) and RP_ALERT. Each case:
no traceback, the fault counted and logged, no false alert, the status keeps going out
every period, and the mode recovers. The daemon runs on virtual time (`VirtualRun`): the
periods and times asserted are the daemon's clock's, the same on any machine's load (the
status's period on the wall clock under the garbage burst: ``roadpreview bench status``)."""

from __future__ import annotations

import itertools
import logging
import random
import threading
import uuid
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import can
import numpy as np
import pytest
from tests.daemon.conftest import SETTLE_S, VIRTUAL_T0, BusRecorder, ClockDriver, VirtualRun

from roadpreview.apps.daemon import Daemon, DaemonOptions, DaemonSummary
from roadpreview.canbus import read_can_log
from roadpreview.canbus.logio import CanLogWriter
from roadpreview.canbus.received import OutputDecoder, ReceivedStatus
from roadpreview.cli.main import main
from roadpreview.clock import VirtualClock
from roadpreview.loop import Supervision
from roadpreview.pipeline import PipelineConfig
from roadpreview.types import FusionMode

if TYPE_CHECKING:
    from roadpreview.sim.recording import Recording

RP_STATUS = 0x201
RP_ROAD_STATUS = 0x202
PERIOD_S = PipelineConfig().can.status_period_s


@pytest.fixture(scope="module")
def drive(make_recording: Callable[..., Recording]) -> Recording:
    # the arguments of tests/daemon/conftest.py's small_drive: the session's cache reuses it
    return make_recording("controlled", seed=0, duration_s=3.0, width=320, height=180)


@dataclass
class Played:
    """What one daemon run did, as the bus and the log saw it."""

    summary: DaemonSummary
    daemon: Daemon
    statuses: list[ReceivedStatus]  #: RP_STATUS as received, t_rx_s on the frames' clock
    road_statuses: int
    alerts: list[Any]
    log: list[str]

    def rel(self, t: float) -> float:
        return t - float(getattr(self.daemon.camera, "start_s", 0.0))

    def modes(self) -> list[tuple[float, FusionMode]]:
        """(seconds from frame 0, mode) of every status received."""
        return [(self.rel(s.t_rx_s), s.mode) for s in self.statuses]


def _edited_log(drive: Recording, folder: Path, edit: Callable[[list[can.Message]], Any]) -> Path:
    """The drive's CAN log after ``edit`` (frames on the recording's clock, in order)."""
    frames = list(read_can_log(drive.can_log()))
    frames = sorted(edit(frames), key=lambda m: m.timestamp)
    path = folder / "played.log"
    writer = CanLogWriter(path)
    for msg in frames:
        writer.write(msg)
    writer.close()
    return path


class _Capture(logging.Handler):
    """The log records of a run (roadpreview's at INFO and above), and any traceback."""

    def __init__(self) -> None:
        super().__init__(logging.INFO)
        self.records: list[logging.LogRecord] = []
        self.logger = logging.getLogger("roadpreview")

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)

    def __enter__(self) -> _Capture:
        self.level = self.logger.level
        self.logger.setLevel(logging.INFO)
        self.logger.addHandler(self)
        return self

    def __exit__(self, *exc: object) -> None:
        self.logger.removeHandler(self)
        self.logger.setLevel(self.level)


def _play(
    drive: Recording,
    tmp_path: Path,
    *,
    edit: Callable[[list[can.Message]], Any] | None = None,
    video: Path | None = None,
    stop_after_s: float | None = None,
    patch: Callable[[Daemon], None] | None = None,
) -> Played:
    """Run the daemon over the drive (``video`` instead of its own, the log ``edit``-ed) on
    virtual time; it stops at the video's end, or ``stop_after_s`` after frame 0."""
    cfg = PipelineConfig()
    channel = f"rp-fault-{uuid.uuid4().hex}"
    cfg = replace(cfg, can=replace(cfg.can, input_interface="virtual", input_channel=channel))
    log_path = _edited_log(drive, tmp_path, edit or (lambda f: f))
    clock = VirtualClock(VIRTUAL_T0, settle_timeout_s=SETTLE_S)
    options = DaemonOptions(
        camera_source=str(video or drive.video),
        can_log=log_path,
        video_start_s=drive.t0_unix_s,
        stop_at_end=stop_after_s is None,
        clock=clock,
    )
    rx = BusRecorder(channel, preserve_timestamps=True)
    daemon = Daemon(drive.camera, cfg, options)
    if patch is not None:
        patch(daemon)
    with _Capture() as capture:
        run = VirtualRun(daemon, clock)
        if stop_after_s is None:
            summary = run.finish()
        else:
            start = float(getattr(daemon.camera, "start_s", VIRTUAL_T0))
            run.advance(start + stop_after_s - clock.now())
            summary = run.stop()
    got = rx.close()
    decoder = OutputDecoder()
    statuses, alerts, road = [], [], 0
    for msg in got:
        out = decoder.decode(msg)
        if isinstance(out, ReceivedStatus):
            statuses.append(replace(out, t_rx_s=msg.timestamp))
        elif msg.arbitration_id == RP_ROAD_STATUS and out is not None:
            road += 1
        elif msg.arbitration_id == 0x200 and out is not None:
            alerts.append(replace(out, t_rx_s=msg.timestamp))
    lines = [r.getMessage() for r in capture.records]
    assert not [r for r in capture.records if r.exc_info], "a traceback was logged"
    return Played(summary, daemon, statuses, road, alerts, lines)


def _assert_status_every_period(played: Played, *, lost: int = 0) -> None:
    """RP_STATUS every period on the daemon's clock (its cyclic sender, whatever the loop
    does): no gap a receiver's timeout of 3 periods would see; in fact every gap one
    period, two exactly ``lost`` times (a frame the bus refused), the last one (the status
    sent at close) at most one; and its E2E counter +1 per frame encoded: +2 exactly
    ``lost`` times (a frame encoded but not sent)."""
    times = [s.t_rx_s for s in played.statuses]
    gaps = [b - a for a, b in itertools.pairwise(times)]
    assert len(gaps) > 10, "the status did not go out"
    limit = (3.0 + lost) * PERIOD_S
    long = [
        (round(played.rel(t), 2), round(g, 3))
        for t, g in zip(times[:-1], gaps, strict=True)
        if g >= limit
    ]
    assert not long, f"status gaps over {limit:.2f} s (after s: gap s): {long}"
    periods = Counter(round(g / PERIOD_S, 4) for g in gaps[:-1])
    expected = Counter({1.0: len(gaps) - 1 - lost, 2.0: lost})
    assert periods == +expected
    assert 0.0 <= gaps[-1] <= PERIOD_S + 1e-6
    counters = [s.counter for s in played.statuses]
    steps = Counter((b - a) % 15 for a, b in itertools.pairwise(counters))
    assert steps == Counter({1: len(gaps) - lost, 2: lost} if lost else {1: len(gaps)})


def _clean_fused_from(played: Played) -> float:
    return next(t for t, m in played.modes() if m is FusionMode.FUSED)


@pytest.fixture(scope="module")
def clean(drive: Recording, tmp_path_factory: pytest.TempPathFactory) -> Played:
    """The drive without a fault (the reference for modes and alerts)."""
    return _play(drive, tmp_path_factory.mktemp("clean"))


def test_clean_run_fuses_and_sends_every_status(clean: Played) -> None:
    _assert_status_every_period(clean)
    assert clean.alerts == []  # the lead reaches the first bump after 4 s: nothing to alert
    assert clean.modes()[-1][1] is FusionMode.FUSED
    assert _clean_fused_from(clean) < 2.5


def test_a_send_error_on_rp_status_costs_that_frame_only(drive: Recording, tmp_path: Path) -> None:
    class RefusesOnce:
        """The output bus; the 10th RP_STATUS send raises (a driver's ENOBUFS)."""

        def __init__(self, bus: can.BusABC) -> None:
            self.bus = bus
            self.channel_info = bus.channel_info
            self.status_sends = 0

        def send(self, msg: can.Message, timeout: float | None = None) -> None:
            if msg.arbitration_id == RP_STATUS:
                self.status_sends += 1
                if self.status_sends == 10:
                    raise OSError(105, "No buffer space available")
            self.bus.send(msg, timeout)

    def patch(daemon: Daemon) -> None:
        daemon.output.bus = RefusesOnce(daemon.output_bus)  # type: ignore[assignment]

    played = _play(drive, tmp_path, patch=patch)
    s = played.summary
    assert s.alert_send_errors == 1
    assert s.send_failures == {RP_STATUS: 1}
    _assert_status_every_period(played, lost=1)  # one period without RP_STATUS, no more
    assert played.road_statuses == len(played.statuses) + 1  # its RP_ROAD_STATUS went out
    failed = [line for line in played.log if line.startswith("event=can_send_failed")]
    assert len(failed) == 1
    assert "id=0x201" in failed[0]
    assert "OSError" in failed[0]
    assert any(line.startswith("event=can_send_recovered") for line in played.log)
    assert played.alerts == []
    assert played.modes()[-1][1] is FusionMode.FUSED


def test_the_camera_ending_degrades_the_status_and_says_so(
    drive: Recording,
    tmp_path: Path,
    first_frames: Callable[[Path, Path, int], Path],
) -> None:
    video = first_frames(drive.video, tmp_path / "first_60.avi", 60)  # 2 s, then silence
    timeout = PipelineConfig().daemon.camera_timeout_s
    played = _play(drive, tmp_path, video=video, stop_after_s=2.0 + timeout + 1.5)
    s = played.summary
    assert s.camera_timeouts == 1
    assert s.camera_gap_frames >= 10
    assert any(line.startswith("event=camera_timeout") for line in played.log)
    _assert_status_every_period(played)  # the watchdog's image-less frames keep it going
    after = [m for t, m in played.modes() if t > 2.0 + timeout + 0.3]
    assert after, "no status after the camera was declared lost"
    assert all(m in (FusionMode.IMU_ONLY, FusionMode.DEGRADED) for m in after)
    assert after[-1] is FusionMode.DEGRADED  # no vision for over a second: nothing to trust
    assert played.alerts == []


def test_a_garbage_burst_of_10000_frames_in_one_second(
    drive: Recording, clean: Played, tmp_path: Path
) -> None:
    rng = random.Random(17)

    def burst(frames: list[can.Message]) -> list[can.Message]:
        t0 = drive.t0_unix_s + 1.0
        garbage = [
            can.Message(
                timestamp=t0 + k * 1e-4,
                arbitration_id=rng.randrange(0x800),
                data=bytes(rng.randrange(256) for _ in range(8)),
            )
            for k in range(10_000)
        ]
        return [*frames, *garbage]

    played = _play(drive, tmp_path, edit=burst)
    s = played.summary
    assert s.can_log_sent >= 10_000 + 0.95 * clean.summary.can_log_sent
    assert s.can_log_errors == 0
    assert s.can_frames + s.can_queue_drops >= 10_000  # every frame received or counted
    assert s.can_input_errors >= 9_000  # garbage: counted, not decoded
    # it kept up: the frames processed or, had it fallen behind, dropped for a newer one
    assert s.frames_processed >= 0.5 * clean.summary.frames_processed
    assert s.frames_processed + s.frames_dropped >= clean.summary.frames_processed - 2
    assert played.alerts == []  # no false alert from the garbage
    _assert_status_every_period(played)  # the burst holds up the loop, not the status
    assert played.modes()[-1][1] is FusionMode.FUSED


def test_a_source_that_keeps_failing_exits_the_daemon_non_zero(
    drive: Recording,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The camera reader raises at every start: restarted with backoff (on the daemon's
    clock, virtual here), then the daemon gives up, so that systemd (Restart=on-failure)
    starts it anew."""
    import roadpreview.apps.daemon as daemon_module

    class DeadCamera:
        name = "camera 7"
        live = True
        errors = 0
        start_s = 0.0
        kind = "device"

        def __init__(self) -> None:
            self.started_at: list[float] = []  # the daemon's clock at each start

        def __iter__(self) -> Iterator[Any]:
            # the source's thread takes part in the virtual time from here: a thread that
            # waited once holds the clock until it waits again (its backoff), so that the
            # clock driver cannot move time on while a loaded machine runs the death's
            # handling (a thread new to the clock is not known to it)
            clock.wait(threading.Event(), 0.0)
            self.started_at.append(clock.now())
            raise OSError(19, "No such device")

        def close(self) -> None:
            pass

    dead = DeadCamera()
    monkeypatch.setattr(daemon_module, "open_camera", lambda *a, **k: dead)
    fast = Supervision(max_restarts=2, backoff_s=0.01, max_backoff_s=0.02)
    original = daemon_module.DaemonOptions
    clock = VirtualClock(VIRTUAL_T0, settle_timeout_s=SETTLE_S)

    def options(**kwargs: Any) -> DaemonOptions:
        return original(**kwargs, supervision=fast, clock=clock)

    monkeypatch.setattr(daemon_module, "DaemonOptions", options)
    args = ["run", "--camera", str(drive.folder / "camera.toml"), "--source", "7"]
    args += ["--can-interface", "virtual", "--can-channel", f"rp-dead-{uuid.uuid4().hex}"]
    with ClockDriver(clock, step_s=0.005, limit_s=10.0):  # main: the signal handlers
        code = main([*args, "-q"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1
    assert len(dead.started_at) == 3
    # restarted after the backoffs, 10 then 20 ms of the daemon's clock: the gaps between
    # the starts (the time at the exit is not: the clock moves on while the daemon shuts
    # down, by however long that takes in real time on a loaded machine)
    assert np.diff(dead.started_at) == pytest.approx([0.01, 0.02], abs=1e-6)
    assert err == [
        "roadpreview run: error: camera 7: the source failed 3 times in a row "
        "(last: OSError: [Errno 19] No such device); giving up"
    ]


# -- the IMU's faults: an 8 s drive (the lead crosses one bump at 6 s) -------------------
@pytest.fixture(scope="module")
def long_drive(make_recording: Callable[..., Recording]) -> Recording:
    # the arguments of tests/cli/conftest.py's tiny: the session's cache reuses it
    return make_recording("demo", seed=0, duration_s=8.0, width=640, height=360)


def _true_crossings(drive: Recording) -> list[float]:
    """Seconds from frame 0 at which the lead's front wheels cross an anomaly it hits."""
    return [
        float(e["lead_front_t_s"])
        for e in drive.events
        if e.get("lead_front_t_s") is not None and e.get("lead_hits")
    ]


def _assert_no_false_alert(played: Played, drive: Recording) -> None:
    """Each alert's first RP_ALERT (it repeats until the ego passed the spot) within 1.5 s
    after a true crossing of the lead (the detector's delay)."""
    truth = _true_crossings(drive)
    first: dict[int, float] = {}
    for a in played.alerts:
        first.setdefault(a.alert_id, played.rel(a.t_rx_s))
    for alert_id, t in first.items():
        assert any(0.0 <= t - c < 1.5 for c in truth), f"false alert {alert_id} at {t:.2f} s"


def _mode_at(played: Played, t_rel: float) -> FusionMode:
    return [m for t, m in played.modes() if t <= t_rel][-1]


OUTAGE = (3.0, 6.0)  #: seconds from frame 0 without any IMU frame on the bus


@pytest.mark.slow
def test_an_imu_outage_and_its_return(long_drive: Recording, tmp_path: Path) -> None:
    t0 = long_drive.t0_unix_s

    def outage(frames: list[can.Message]) -> list[can.Message]:
        imu_ids = {0x130, 0x131}  # IMU_RATES, IMU_ACCEL (the speed stays)
        lo, hi = t0 + OUTAGE[0], t0 + OUTAGE[1]
        return [m for m in frames if not (m.arbitration_id in imu_ids and lo <= m.timestamp < hi)]

    played = _play(long_drive, tmp_path, edit=outage)
    s = played.summary
    timeout = PipelineConfig().can.imu_timeout_s
    assert s.imu_timeouts == 1
    assert any(line.startswith("event=imu_timeout") for line in played.log)
    assert any(line.startswith("event=imu_recovered") for line in played.log)
    _assert_status_every_period(played)
    _assert_no_false_alert(played, long_drive)
    assert _mode_at(played, OUTAGE[0] - 0.1) is FusionMode.FUSED
    # the IMU is declared gone within its timeout (+ a status period): vision only
    lost = OUTAGE[0] + timeout + 2 * PERIOD_S
    during = [m for t, m in played.modes() if lost <= t < OUTAGE[1]]
    assert during
    assert set(during) == {FusionMode.VISUAL_ONLY}
    # the gyro's return is fused at once (its time offset is kept): FUSED within 1 s
    back = [t for t, m in played.modes() if t >= OUTAGE[1] and m is FusionMode.FUSED]
    assert back, "never FUSED again after the IMU returned"
    assert back[0] - OUTAGE[1] < 1.0
    assert set(m for t, m in played.modes() if t >= back[0]) == {FusionMode.FUSED}


STEP_AT_S, STEP_S = 4.0, 0.3  #: from 4 s on, the log's stamps (IMU, speed) jump 0.3 s ahead


@pytest.mark.slow
def test_a_clock_step_in_the_can_stamps(long_drive: Recording, tmp_path: Path) -> None:
    at = long_drive.t0_unix_s + STEP_AT_S

    def step(frames: list[can.Message]) -> list[can.Message]:
        for m in frames:
            if m.timestamp >= at:
                m.timestamp += STEP_S
        return frames

    played = _play(long_drive, tmp_path, edit=step)
    s = played.summary
    _assert_status_every_period(played)
    _assert_no_false_alert(played, long_drive)
    assert s.frames_processed >= 0.8 * 240
    assert _mode_at(played, STEP_AT_S - 0.1) is FusionMode.FUSED
    # the samples after the step are 0.3 s late on the frames' clock: more than the gyro
    # timeout, so at once vision only, never a pitch from the stepped gyro fused blindly
    after = [m for t, m in played.modes() if t > STEP_AT_S + 0.5]
    assert after
    assert FusionMode.DEGRADED not in after  # vision carries on
    step_counts = [p.get("clock_step", 0) for p in s.source_problems.values()]
    if not any(step_counts):
        pytest.xfail("the CAN decoder does not count clock_step yet (another part of issue 17)")
    assert sum(step_counts) == 1
