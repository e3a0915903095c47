"""Live CAN on python-can's virtual bus: alerts and periodic status between two bus objects."""

from __future__ import annotations

import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import can
import pytest

from roadpreview.anomaly import Alert, Side, SuppressionReason
from roadpreview.canbus import (
    BoundedQueueListener,
    CanInputDecoder,
    CanOutput,
    CanReceiver,
    OutputDecoder,
    ReceivedAlert,
    ReceivedStatus,
    Status,
    decode_log,
    load_database,
    load_mapping,
    open_bus,
    read_can_log,
    replay,
    write_can_log,
)
from roadpreview.errors import ConfigError
from roadpreview.fusion.mode import FusionMode


@pytest.fixture
def buses() -> Iterator[tuple[can.BusABC, can.BusABC]]:
    channel = f"roadpreview-test-{uuid.uuid4().hex}"  # private to this test
    tx = open_bus("virtual", channel)
    rx = open_bus("virtual", channel)
    yield tx, rx
    tx.shutdown()
    rx.shutdown()


def _receive(receiver: CanReceiver, decoder: OutputDecoder, want: int) -> list[object]:
    """Decode frames until ``want`` decoded ones arrived (or 5 s without a frame)."""
    out: list[object] = []
    while len(out) < want:
        msg = receiver.recv(timeout=5.0)
        if msg is None:
            break
        decoded = decoder.decode(msg)
        if decoded is not None:
            out.append(decoded)
    return out


def test_alerts_and_status_from_one_bus_object_to_another(
    buses: tuple[can.BusABC, can.BusABC],
) -> None:
    tx, rx = buses
    alert = Alert(
        t_s=10.0,
        t_emit_s=11.0,
        distance_m=32.4,
        time_to_arrival_s=2.16,
        severity_px=3.4,
        height_mm=48.0,
        side=Side.RIGHT,
        confidence=0.82,
        mode=FusionMode.VISUAL_ONLY,
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
    )
    decoder = OutputDecoder()
    with CanReceiver(rx) as receiver:
        out = CanOutput(tx, keep_sent=True)
        out.send_alert(alert)
        out.start_status(status, period_s=0.01)
        statuses = _receive(receiver, decoder, 1 + 5)
        out.update_status(Status(mode=FusionMode.DEGRADED, frames_processed=124))
        later: list[object] = []
        while not any(
            isinstance(s, ReceivedStatus) and s.mode == FusionMode.DEGRADED for s in later
        ):
            got = _receive(receiver, decoder, 1)
            assert got, "the updated status never arrived"
            later += got
        out.stop()
    first, *periodic = statuses
    assert isinstance(first, ReceivedAlert)
    assert first.distance_m == pytest.approx(32.4, abs=0.1)
    assert first.time_to_arrival_s == pytest.approx(2.16, abs=0.01)
    assert first.event_age_s == pytest.approx(1.0, abs=0.025)
    assert first.severity_px == pytest.approx(3.4, abs=0.1)
    assert first.height_mm == pytest.approx(48.0, abs=1.0)
    assert first.side == Side.RIGHT
    assert first.mode == FusionMode.VISUAL_ONLY
    assert first.confidence == pytest.approx(0.82, abs=0.01)
    assert all(isinstance(s, ReceivedStatus) for s in periodic)
    assert [s.counter for s in periodic] == list(range(5))  # type: ignore[attr-defined]
    s0 = periodic[0]
    assert isinstance(s0, ReceivedStatus)
    assert s0.pitch_rad == pytest.approx(0.01, abs=0.0025 * 3.1416 / 180)
    assert s0.texture_quality == pytest.approx(0.7)
    assert s0.time_offset_s == pytest.approx(0.042)
    assert s0.heartbeat == 123 % 8
    last = later[-1]
    assert isinstance(last, ReceivedStatus)
    assert last.pitch_rad is None  # not available
    assert decoder.problems == {}
    assert decoder.lost == 0
    assert receiver.dropped == 0
    assert [m.arbitration_id for m in out.sent[:2]] == [0x200, 0x201]


def test_sent_frames_can_be_logged(buses: tuple[can.BusABC, can.BusABC], tmp_path) -> None:  # type: ignore[no-untyped-def]
    tx, _ = buses
    out = CanOutput(tx, keep_sent=True)
    for k in range(3):
        out.send_status(Status(mode=FusionMode.FUSED, alerts_sent=k), timestamp=1.7e9 + 0.1 * k)
    path = tmp_path / "status.blf"
    assert write_can_log(path, out.sent) == 3
    decoder = OutputDecoder()
    back = [decoder.decode(m) for m in read_can_log(path, errors="raise")]
    assert [b.alert_count for b in back] == [0, 1, 2]  # type: ignore[union-attr]


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
