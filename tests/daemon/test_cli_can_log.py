"""``roadpreview run --can-log``: the daemon exercised from the command line without hardware.
A recording's video is the camera and its CAN log is played onto a python-can ``virtual``
bus (the default with ``--can-log``) on the camera's clock; the result is the replay's. The
daemon the command line builds runs on virtual time (its options get a `VirtualClock`,
moved on in lockstep by a `ClockDriver`): no frame is dropped, however loaded the machine."""

from __future__ import annotations

import csv
import uuid
from pathlib import Path
from typing import Any

import pytest
from tests.daemon.conftest import SETTLE_S, VIRTUAL_T0, ClockDriver

import roadpreview.apps.daemon as daemon_module
from roadpreview.apps.daemon import Daemon, DaemonOptions
from roadpreview.apps.replay import ReplayInputs, replay
from roadpreview.canbus import read_can_log
from roadpreview.canbus.received import OutputDecoder, ReceivedAlert
from roadpreview.cli.main import main
from roadpreview.clock import VirtualClock


@pytest.fixture(scope="module")
def short_demo(make_recording):  # type: ignore[no-untyped-def]
    # the same arguments as tests/pipeline: the session's cached recording is reused
    return make_recording("demo", seed=0, duration_s=8.0, width=1280, height=720)


#: the frame table's columns that are times on the run's clock (Unix time)
TIME_COLUMNS = ("t_unix_s", "score_t_unix_s")


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.slow
def test_run_with_can_log_gives_the_replays_frames_and_alerts(
    short_demo: Any,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    clock = VirtualClock(VIRTUAL_T0, settle_timeout_s=SETTLE_S)
    made: list[Daemon] = []

    class OnTheClock(Daemon):
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            made.append(self)

    options = daemon_module.DaemonOptions

    def with_clock(**kwargs: Any) -> DaemonOptions:
        return options(**kwargs, clock=clock)

    monkeypatch.setattr(daemon_module, "Daemon", OnTheClock)
    monkeypatch.setattr(daemon_module, "DaemonOptions", with_clock)
    config = tmp_path / "daemon.toml"
    # CAN frames stamped before a frame reach the daemon within 0.2 s (sample clock)
    config.write_text("[daemon]\ncan_latency_s = 0.2\n")
    # the loop, the camera and CAN readers and the log player wait on the clock
    args = [
        "run",
        "--config", str(config),
        "--camera", str(short_demo.folder / "camera.toml"),
        "--source", str(short_demo.video),
        "--frames-csv", str(short_demo.folder / "frames.csv"),
        "--can-log", str(short_demo.can_log()),
        "--video-start", str(short_demo.info["can_t0_unix_s"]),
        "--can-channel", f"rp-cli-{uuid.uuid4().hex}",  # the interface: virtual
        "--rate", "0.5",  # half speed (on virtual time any rate gives these frames)
        "--alerts-log", str(tmp_path / "alerts.blf"),
        "--frame-table", str(tmp_path / "daemon_frames.csv"),
    ]  # fmt: skip
    # the loop, the camera and CAN readers and the log player wait on the clock
    driver = ClockDriver(clock, threads=4, daemon=lambda: made[0] if made else None)
    with driver:  # main in this thread: it installs signal handlers
        code = main(args)
    out = capsys.readouterr().out
    assert code == 0
    n_frames = int(short_demo.info["n_frames"])
    assert f"{n_frames} frames processed, 0 dropped, 0 out of order, 0 unreadable" in out
    assert "CAN log player:" in out
    assert ", 0 errors" in out

    ref = replay(ReplayInputs.from_recording(short_demo.folder), out=tmp_path / "replay")
    daemon_rows = _rows(tmp_path / "daemon_frames.csv")
    replay_rows = _rows(tmp_path / "replay" / "frames.csv")
    assert len(daemon_rows) == len(replay_rows) == n_frames
    # the daemon's clock is its own (frame 0 a second after the start), the replay's the
    # recording's: the time columns differ by one constant, nothing else does
    shift = float(daemon_rows[0]["t_unix_s"]) - float(replay_rows[0]["t_unix_s"])
    for k, (d, r) in enumerate(zip(daemon_rows, replay_rows, strict=True)):
        for name in d:
            if name in TIME_COLUMNS and d[name] not in ("", "nan"):
                assert float(d[name]) - float(r[name]) == pytest.approx(shift, abs=2e-6)
            elif name == "t_rel_s":  # both from frame 0
                assert float(d[name]) == pytest.approx(float(r[name]), abs=2e-6)
            else:
                assert d[name] == r[name], f"frame {k}: {name} differs"
    assert daemon_rows[-1]["mode"] == "FUSED"
    assert ref.alerts, "the drive has alerts to compare"
    sent = [OutputDecoder().decode(m) for m in read_can_log(tmp_path / "alerts.blf")]
    # each alert is repeated until the ego has passed it: its first send, in order
    first_sends: dict[int, ReceivedAlert] = {}
    for m in sent:
        if isinstance(m, ReceivedAlert):
            first_sends.setdefault(m.alert_id, m)
    alerts = list(first_sends.values())
    assert [(a.alert_id, a.side, a.mode) for a in alerts] == [
        (a.alert_id % 256, a.side, a.mode) for a in ref.alerts
    ]
    assert f"{len(ref.alerts)} alert(s) (0 send errors)" in out
