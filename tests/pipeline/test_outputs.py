"""The CAN sinks (`roadpreview.sinks.can`) as the run loop drives them: per alert RP_ALERT
then RP_ALERT_DETAIL with the same AlertId, RP_CONFIRM at the frame that decided it,
RP_STATUS + RP_ROAD_STATUS every period; everything E2E-valid and decoded back by cantools
and by `OutputDecoder`."""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import cast

import cantools
import e2e.p01
import pytest
from cantools.database.can import Database
from cantools.typechecking import DecodeResultType, SignalDictType

from roadpreview.canbus import (
    OutputDecoder,
    ReceivedAlert,
    ReceivedAlertDetail,
    ReceivedConfirm,
    ReceivedRoadStatus,
    ReceivedStatus,
    read_can_log,
    write_can_log,
)
from roadpreview.errors import ConfigError
from roadpreview.pipeline import FrameResult
from roadpreview.pipeline.run_summary import RunSummary
from roadpreview.sinks.can import CanMemorySink
from roadpreview.types import (
    Alert,
    CameraFrame,
    Confirmation,
    ConfirmationResult,
    FusionMode,
    RoadState,
    Side,
    Status,
)

REPO_DBC = Path(__file__).resolve().parents[2] / "data" / "roadpreview.dbc"
T0 = 1.7e9  # Unix time, as the replay stamps frames


def _alert(alert_id: int, t: float, height_mm: float) -> Alert:
    return Alert(
        t_s=t - 0.6,
        t_emit_s=t,
        distance_m=25.0,
        time_to_arrival_s=1.8,
        severity_px=7.4,
        height_mm=height_mm,
        side=Side.BOTH,
        confidence=0.9,
        mode=FusionMode.FUSED,
        alert_id=alert_id,
        height_std_mm=8.0,
        length_m=0.5,
        lead_speed_mps=12.0,
    )


def _status(k: int, precision: float | None = None, confirmed: int = 0) -> Status:
    return Status(
        mode=FusionMode.FUSED,
        alerts_sent=k,
        frames_processed=k,
        road=RoadState("B", 60e-6, "B", 60e-6, "C", 200e-6),
        precision=precision,
        confirmed=confirmed,
    )


@pytest.fixture(scope="module")
def plain_db() -> Database:
    db = cantools.database.load_file(REPO_DBC, strict=True)
    assert isinstance(db, Database)
    return db


def _signals(decoded: DecodeResultType) -> SignalDictType:
    """cantools decodes a plain (non-container) message to a signal dict: narrow to it."""
    assert isinstance(decoded, dict)
    return decoded


@dataclass(frozen=True)
class _Result:
    """The part of a `FrameResult` the CAN sinks read."""

    t: float
    alerts: list[Alert]
    confirmations: list[ConfirmationResult]
    ego_speed_mps: float | None = 13.8
    provisional: tuple[Alert, ...] = ()
    cancelled: tuple[Alert, ...] = ()
    preview: None = None


class _Log(CanMemorySink):
    """The sink driven as the run loop drives it: each frame, then the status when due."""

    def __init__(self, period_s: float = 0.1, *, detector: str = "two-axle") -> None:
        super().__init__(detector=detector)
        self.period_s = period_s
        self.next_status = -math.inf

    def frame(
        self,
        t: float,
        status: Status,
        alerts: list[Alert],
        confirmations: list[ConfirmationResult] | None = None,
    ) -> None:
        result = cast(FrameResult, _Result(t, alerts, confirmations or []))
        self.on_frame(CameraFrame(t, None), result, status)
        if t >= self.next_status:
            self.on_status(t, status)
            self.next_status = t + self.period_s

    def write(self, path: Path) -> int:
        count: int = write_can_log(path, self.messages)
        return count


def _run() -> _Log:
    """1 s at 30 fps: two alerts at frame 3 (a bump and a pothole), a confirmation of the first
    at frame 20, the status of each frame."""
    log = _Log(0.1, detector="std")
    bump, hole = _alert(1, T0 + 0.1, 42.0), _alert(2, T0 + 0.1, -66.0)
    confirmed = ConfirmationResult(
        1, Confirmation.CONFIRMED, T0 + 20 / 30, T0 + 20 / 30 - 0.8, 3.1, 0.6
    )
    for k in range(30):
        t = T0 + k / 30
        alerts = [bump, hole] if k == 3 else []
        confirmations = [confirmed] if k == 20 else []
        status = _status(k, 2 / 3 if k >= 20 else None, 1 if k >= 20 else 0)
        log.frame(t, status, alerts, confirmations)
    return log


def test_the_log_writes_every_output_in_order() -> None:
    log = _run()
    ids = [m.arbitration_id for m in log.messages]
    # status and road status together, at the first frame of every 100 ms
    assert ids[:2] == [0x201, 0x202]
    k = ids.index(0x200)
    assert ids[k : k + 4] == [0x200, 0x203, 0x200, 0x203]  # each alert, then its details
    assert ids.count(0x201) == ids.count(0x202) == 10
    assert ids.count(0x204) == 1
    for m in log.messages:  # every frame protected with its own message's data ID
        assert e2e.p01.e2e_p01_check(bytearray(m.data), m.arbitration_id)
    status_t = [m.timestamp for m in log.messages if m.arbitration_id == 0x201]
    road_t = [m.timestamp for m in log.messages if m.arbitration_id == 0x202]
    assert status_t == road_t
    gaps = [b - a for a, b in itertools.pairwise(status_t)]
    assert min(gaps) >= 0.1 - 1e-6  # one per period
    assert max(gaps) <= 0.1 + 1 / 30 + 1e-6


def test_the_log_decodes_to_what_was_sent(plain_db: Database) -> None:
    log = _run()
    rx = OutputDecoder()
    back = [rx.decode(m) for m in log.messages]
    assert rx.problems == {}
    assert rx.lost == 0
    alerts = [b for b in back if isinstance(b, ReceivedAlert)]
    details = [b for b in back if isinstance(b, ReceivedAlertDetail)]
    # both alerts, each repeated every 100 ms (the first at frame 3, then frames 6, 9, ...)
    assert [a.alert_id for a in alerts] == [d.alert_id for d in details] == [1, 2] * 9
    assert alerts[0].height_mm == pytest.approx(42.0, abs=1.0)
    assert alerts[1].height_mm == pytest.approx(-66.0, abs=1.0)  # the pothole: negative
    assert all(d.detector == "std" for d in details)
    assert details[0].score == pytest.approx(7.4, abs=0.1)
    assert details[0].lead_speed_mps == pytest.approx(12.0, abs=0.25 / 3.6)
    (confirm,) = [b for b in back if isinstance(b, ReceivedConfirm)]
    assert confirm.alert_id == 1
    assert confirm.outcome == Confirmation.CONFIRMED
    assert confirm.t_rx_s == pytest.approx(T0 + 20 / 30)  # at the frame that decided it
    assert confirm.arrival_age_s == pytest.approx(0.8, abs=0.01)
    assert confirm.peak_mps2 == pytest.approx(3.1, abs=0.01)
    assert confirm.precision == pytest.approx(2 / 3, abs=0.005)  # the status after the frame
    roads = [b for b in back if isinstance(b, ReceivedRoadStatus)]
    statuses = [b for b in back if isinstance(b, ReceivedStatus)]
    assert len(roads) == len(statuses) == 10
    assert all((r.iso_class, r.ego_class, r.lead_class) == ("B", "B", "C") for r in roads)
    assert roads[0].precision is None  # before any confirmation: not available
    assert roads[-1].precision == pytest.approx(2 / 3, abs=0.005)
    assert (roads[0].confirmed, roads[-1].confirmed) == (0, 1)
    # a plain cantools database reads the same log
    by_id = {m.frame_id: m for m in plain_db.messages}
    heads = [m for m in log.messages if m.arbitration_id in (0x200, 0x203)]
    pairs = [_signals(by_id[m.arbitration_id].decode(bytes(m.data))) for m in heads]
    assert [p["AlertId"] for p in pairs[:4]] == [1, 1, 2, 2]
    assert str(pairs[1]["DetailDetector"]) == "STD"
    assert pairs[2]["AlertHeight"] == pytest.approx(-66.0, abs=1.0)


def test_the_log_file_reads_back(tmp_path: Path) -> None:
    log = _run()
    path = tmp_path / "alerts.blf"
    assert log.write(path) == len(log.messages)
    rx = OutputDecoder()
    back = [rx.decode(m) for m in read_can_log(path, errors="raise")]
    assert [type(b) for b in back] == [type(OutputDecoder().decode(m)) for m in log.messages]
    assert rx.problems == {}


def test_a_status_at_its_defaults_and_no_confirmations_still_write() -> None:
    """What `Pipeline.status()` gives while it does not fill the road part, and the replay's
    call without confirmations."""
    log = _Log()
    log.frame(T0, Status(mode=FusionMode.DEGRADED), [_alert(7, T0, math.nan)])
    ids = [m.arbitration_id for m in log.messages]
    assert ids == [0x200, 0x203, 0x201, 0x202]
    back = [OutputDecoder().decode(m) for m in log.messages]
    detail, road = back[1], back[3]
    assert isinstance(detail, ReceivedAlertDetail)
    assert detail.detector == "two-axle"  # the default detector
    assert isinstance(road, ReceivedRoadStatus)
    assert road == ReceivedRoadStatus(T0, 0, None, None, None, None, None, None, 0, 0)


def test_an_unknown_detector_fails_when_the_log_is_built() -> None:
    with pytest.raises(ConfigError, match="'cnn'"):
        CanMemorySink(detector="cnn")


@pytest.mark.parametrize("suffix", [".blf", ".asc", ".log"])
def test_the_log_and_alerts_jsonl_are_on_disk_as_the_alerts_happen(
    tmp_path: Path, suffix: str
) -> None:
    """While the run goes on (the sinks still open), a reader already finds each alert in
    the CAN log and in alerts.jsonl: an interrupt or a crash cannot lose it."""
    from roadpreview.sinks.can import CanLogSink
    from roadpreview.sinks.files import AlertsJsonlSink

    log_path, jsonl_path = tmp_path / f"alerts{suffix}", tmp_path / "alerts.jsonl"
    can_sink, jsonl_sink = CanLogSink(log_path), AlertsJsonlSink(jsonl_path)
    alerts_on_disk = []
    for k in range(60):
        t = T0 + k / 30
        alerts = [_alert(1 + k // 20, t, 30.0)] if k % 20 == 5 else []
        result = cast(FrameResult, _Result(t, alerts, []))
        for sink in (can_sink, jsonl_sink):
            sink.on_frame(CameraFrame(t, None), result, _status(k))
        if k % 10 == 0:
            can_sink.on_status(t, _status(k))
        if alerts:  # each alert is repeated until passed: its id, once, in order
            sent = [m.data[2] for m in read_can_log(log_path) if m.arbitration_id == 0x200]
            ids = list(dict.fromkeys(sent))
            lines = jsonl_path.read_text().splitlines()
            alerts_on_disk.append((ids, [json.loads(x)["alert_id"] for x in lines]))
    assert alerts_on_disk == [([1], [1]), ([1, 2], [1, 2]), ([1, 2, 3], [1, 2, 3])]
    can_sink.close(RunSummary())
    jsonl_sink.close(RunSummary())
    ended = {m.data[2] for m in read_can_log(log_path) if m.arbitration_id == 0x205}
    assert ended == {1, 2, 3}  # every alert closed by an RP_ALERT_END (cancelled at close)
