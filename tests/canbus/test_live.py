"""Live CAN on python-can's virtual bus: alerts, confirmations and the periodic status messages
between two bus objects."""

from __future__ import annotations

import time
import uuid
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from types import SimpleNamespace
from typing import TypeVar, cast

import can
import pytest

from roadpreview.canbus import (
    BoundedQueueListener,
    CanInputDecoder,
    CanReceiver,
    OutputDecoder,
    ReceivedAlert,
    ReceivedAlertDetail,
    ReceivedConfirm,
    ReceivedOutput,
    ReceivedRoadStatus,
    ReceivedStatus,
    decode_log,
    load_database,
    load_mapping,
    open_bus,
    read_can_log,
    replay,
)
from roadpreview.canbus.received import ReceivedAlertEnd
from roadpreview.canbus.repetition import EndReason
from roadpreview.errors import ConfigError
from roadpreview.loop import RunSummary
from roadpreview.pipeline import FrameResult
from roadpreview.sinks.can import CanBusSink
from roadpreview.types import (
    Alert,
    CameraFrame,
    Confirmation,
    ConfirmationResult,
    FusionMode,
    RoadState,
    Side,
    Status,
    SuppressionReason,
)

T = TypeVar("T")


@pytest.fixture
def buses() -> Iterator[tuple[can.BusABC, can.BusABC]]:
    channel = f"roadpreview-test-{uuid.uuid4().hex}"  # private to this test
    tx = open_bus("virtual", channel)
    rx = open_bus("virtual", channel)
    yield tx, rx
    tx.shutdown()
    rx.shutdown()


def _receive_until(
    receiver: CanReceiver, decoder: OutputDecoder, done: Callable[[list[ReceivedOutput]], bool]
) -> list[ReceivedOutput]:
    """Decode frames until ``done(decoded so far)`` (or 5 s without a frame)."""
    out: list[ReceivedOutput] = []
    while not done(out):
        msg = receiver.recv(timeout=5.0)
        if msg is None:
            break
        decoded = decoder.decode(msg)
        if decoded is not None:
            out.append(decoded)
    return out


def _of(kind: type[T], got: list[ReceivedOutput]) -> list[T]:
    return [g for g in got if isinstance(g, kind)]


def _result(
    t: float,
    alerts: Sequence[Alert] = (),
    confirms: Sequence[ConfirmationResult] = (),
    speed: float | None = 15.0,
) -> FrameResult:
    """The part of a `FrameResult` the CAN sinks read."""
    return cast(
        FrameResult,
        SimpleNamespace(
            t=t,
            alerts=tuple(alerts),
            provisional=(),
            cancelled=(),
            preview=None,
            confirmations=confirms,
            ego_speed_mps=speed,
        ),
    )


def test_alerts_and_status_from_one_bus_object_to_another(
    buses: tuple[can.BusABC, can.BusABC], tmp_path: Path
) -> None:
    tx, rx = buses
    alert = Alert(
        t_s=10.0,
        t_emit_s=11.0,
        distance_m=32.4,
        time_to_arrival_s=2.16,
        severity_px=3.4,
        height_mm=-48.0,  # a pothole
        side=Side.RIGHT,
        confidence=0.82,
        mode=FusionMode.VISUAL_ONLY,
        alert_id=259,
        height_std_mm=12.0,
        length_m=0.6,
        lead_speed_mps=15.0,
    )
    confirmation = ConfirmationResult(
        alert_id=259,
        outcome=Confirmation.CONFIRMED,
        t_s=14.0,
        t_arrival_s=13.1,
        peak_mps2=4.2,
        background_mps2=0.8,
    )
    status = Status(
        mode=FusionMode.FUSED,
        pitch_rad=0.01,
        gyro_bias_rad_s=0.001,
        texture_quality=0.7,
        time_offset_s=0.042,
        suppressed=SuppressionReason.NONE,
        alerts_sent=1,
        frames_processed=123,
        road=RoadState("C", 300e-6, "C", 300e-6, "B", 100e-6),
        precision=0.75,
        confirmed=1,
        not_felt=0,
    )
    decoder = OutputDecoder()

    def five_each(got: list[ReceivedOutput]) -> bool:
        return len(_of(ReceivedStatus, got)) >= 5 and len(_of(ReceivedRoadStatus, got)) >= 5

    degraded = Status(mode=FusionMode.DEGRADED, frames_processed=124)
    with CanReceiver(rx) as receiver:
        out = CanBusSink(tx, detector="std", record=tmp_path / "sent.asc")
        # as the run loop drives it: the frame that emitted the alert, the one that decided
        # the confirmation, the status every period
        out.on_frame(CameraFrame(11.0, None), _result(11.0, alerts=[alert]), status)
        out.on_frame(CameraFrame(14.0, None), _result(14.0, confirms=[confirmation]), status)
        for k in range(5):
            out.on_status(14.0 + 0.1 * k, status)
        got = _receive_until(receiver, decoder, five_each)
        out.on_status(14.6, degraded)
        later = _receive_until(
            receiver,
            decoder,
            lambda g: (
                any(s.mode == FusionMode.DEGRADED for s in _of(ReceivedStatus, g))
                and any(r.iso_class is None for r in _of(ReceivedRoadStatus, g))
            ),
        )
        out.close(RunSummary())
    sent = list(read_can_log(tmp_path / "sent.asc"))
    assert out.send_errors == 0
    assert [m.arbitration_id for m in sent[:2]] == [0x200, 0x203]  # RP_ALERT, then details
    first, detail, end, confirm = got[:4]
    assert isinstance(first, ReceivedAlert)
    assert first.alert_id == 259 % 256
    # as of the send: the front axle (0.2 m ahead of the camera) drove 15 m at 15 m/s since
    # the crossing 1 s before
    assert first.distance_m == pytest.approx(32.4 - 0.2 - 15.0, abs=0.1)
    assert first.time_to_arrival_s == pytest.approx((32.4 - 0.2 - 15.0) / 15.0, abs=0.01)
    assert first.height_mm == pytest.approx(-48.0, abs=1.0)
    assert first.side == Side.RIGHT
    assert first.mode == FusionMode.VISUAL_ONLY
    assert first.confidence == pytest.approx(0.82, abs=0.02)  # 4 % steps
    assert isinstance(detail, ReceivedAlertDetail)
    assert detail.alert_id == first.alert_id
    assert detail.detector == "std"
    assert detail.score == pytest.approx(3.4, abs=0.1)
    assert detail.height_std_mm == pytest.approx(12.0, abs=1.0)
    assert first.length_m == pytest.approx(0.6, abs=0.05)
    assert detail.crossing_age_s == pytest.approx(1.0, abs=0.05)
    # 3 s later at 15 m/s the ego is long past the spot: the alert ended before its check
    assert isinstance(end, ReceivedAlertEnd)
    assert (end.alert_id, end.reason, end.sends) == (first.alert_id, EndReason.PASSED, 1)
    assert detail.lead_speed_mps == pytest.approx(15.0, abs=0.25 / 3.6)
    assert isinstance(confirm, ReceivedConfirm)
    assert confirm.alert_id == first.alert_id
    assert confirm.outcome == Confirmation.CONFIRMED
    assert confirm.peak_mps2 == pytest.approx(4.2, abs=0.01)
    assert confirm.background_mps2 == pytest.approx(0.8, abs=0.01)
    assert confirm.arrival_age_s == pytest.approx(0.9, abs=0.01)
    assert confirm.precision == pytest.approx(0.75, abs=0.005)
    periodic = _of(ReceivedStatus, got)
    roads = _of(ReceivedRoadStatus, got)
    assert len(got) == 4 + len(periodic) + len(roads)
    assert [s.counter for s in periodic[:5]] == list(range(5))
    assert [r.counter for r in roads[:5]] == list(range(5))
    s0 = periodic[0]
    assert s0.pitch_rad == pytest.approx(0.01, abs=0.0025 * 3.1416 / 180)
    assert s0.texture_quality == pytest.approx(0.7)
    assert s0.time_offset_s == pytest.approx(0.042)
    assert s0.heartbeat == 123 % 8
    r0 = roads[0]
    assert (r0.iso_class, r0.ego_class, r0.lead_class) == ("C", "C", "B")
    assert r0.ego_gd_n0 == pytest.approx(300e-6, rel=0.03)  # 0.125 dB is 3 %
    assert r0.lead_gd_n0 == pytest.approx(100e-6, rel=0.03)
    assert r0.precision == pytest.approx(0.75, abs=0.005)
    assert (r0.confirmed, r0.not_felt) == (1, 0)
    last = _of(ReceivedStatus, later)[-1]
    assert last.pitch_rad is None  # not available
    last_road = _of(ReceivedRoadStatus, later)[-1]
    assert last_road.iso_class is None
    assert last_road.precision is None
    assert decoder.problems == {}
    assert decoder.lost == 0
    assert receiver.dropped == 0
    assert [m.arbitration_id for m in sent[:4]] == [0x200, 0x203, 0x205, 0x204]
    # the end's two repetitions go out at close (no frame came after it)
    assert {m.arbitration_id for m in sent[4:]} == {0x201, 0x202, 0x205}
    assert sum(m.arbitration_id == 0x205 for m in sent) == 3


def test_an_unknown_detector_fails_when_the_output_is_built(
    buses: tuple[can.BusABC, can.BusABC],
) -> None:
    with pytest.raises(ConfigError, match="'cnn'"):
        CanBusSink(buses[0], detector="cnn")


def test_a_send_error_is_counted_and_the_sink_goes_on(tmp_path: Path) -> None:
    """A bus that refuses a frame: logged and counted, the next frames still go out."""

    class Flaky(can.BusABC):
        def __init__(self) -> None:
            super().__init__(channel="flaky")
            self.sent: list[can.Message] = []
            self.calls = 0

        def send(self, msg: can.Message, timeout: float | None = None) -> None:
            self.calls += 1
            if self.calls == 2:
                raise can.CanOperationError("transmit buffer full")
            self.sent.append(msg)

        def _recv_internal(self, timeout: float | None) -> tuple[None, bool]:
            return None, False

    bus = Flaky()
    sink = CanBusSink(bus)
    for k in range(3):
        sink.on_status(1.7e9 + 0.1 * k, Status(mode=FusionMode.FUSED, alerts_sent=k))
    assert sink.send_errors == 1
    assert len(bus.sent) == 5  # 3 x (RP_STATUS, RP_ROAD_STATUS), one refused
    decoder = OutputDecoder()
    back = [decoder.decode(m) for m in bus.sent]
    assert [b.alert_count for b in back if isinstance(b, ReceivedStatus)] == [0, 1, 2]
    bus.shutdown()


def test_the_listener_only_queues_and_counts_what_it_drops(
    buses: tuple[can.BusABC, can.BusABC],
) -> None:
    listener = BoundedQueueListener(maxsize=4)
    for k in range(10):
        listener.on_message_received(can.Message(arbitration_id=k))
    assert listener.dropped == 6
    assert [m.arbitration_id for m in listener.drain()] == [0, 1, 2, 3]
    # through the notifier thread: nobody reads, the queue fills, the rest is counted
    tx, rx = buses
    with CanReceiver(rx, maxsize=5) as receiver:
        for k in range(20):
            tx.send(can.Message(arbitration_id=0x100 + k, data=b"\x01"))
        deadline = time.monotonic() + 5.0  # waiting for the thread, not measuring it
        while receiver.dropped < 15 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert receiver.dropped == 15
        got = receiver.listener.drain()
    assert [m.arbitration_id for m in got] == [0x100 + k for k in range(5)]


def test_unknown_interface_is_a_clear_error() -> None:
    with pytest.raises(ConfigError, match="not-a-bus"):
        open_bus("not-a-bus", "x")


def test_a_recorded_log_replayed_on_a_bus_decodes_like_the_file(
    buses: tuple[can.BusABC, can.BusABC],
) -> None:
    """tests/files/imu_drive.log (50 frames over 0.19 s) at its recorded pace."""
    files = Path(__file__).resolve().parents[1] / "files"
    frames = list(read_can_log(files / "imu_drive.log", errors="raise"))
    tx, rx = buses
    with CanReceiver(rx) as receiver:
        assert replay(frames, tx) == len(frames)
        got = [receiver.recv(timeout=5.0) for _ in frames]
    assert [bytes(m.data) for m in got if m is not None] == [bytes(m.data) for m in frames]
    db = load_database()
    live = CanInputDecoder(db, load_mapping("roadpreview"))
    from_file = CanInputDecoder(db, load_mapping("roadpreview"))
    live_samples = list(live.decode_all(m for m in got if m is not None))
    file_samples = list(decode_log(files / "imu_drive.log", from_file))
    assert len(live_samples) == len(file_samples) == 50
    assert [s.source for s in live_samples] == [s.source for s in file_samples]
    assert live.stats.problems == {}
