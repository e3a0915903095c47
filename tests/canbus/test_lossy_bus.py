"""Alerts over a lossy bus (issue 16): with 10 % of roadpreview's output frames dropped at
random, a chassis ECU still gets every alert, and at every receipt its time to arrival is
close to the true time the ego's front axle reaches the anomaly.

The receiver here is what ``docs/can-interface.md`` tells a chassis ECU to do, built on
plain cantools (the DBC file), autosar-e2e for the CRC and its own counter check and alert
table, not on roadpreview's `OutputDecoder`. Two drives:

* a synthetic one (fast): 60 s at 11.5-12.5 m/s (0.16 m/s^2 at most), 24 anomalies
  measured exactly when the lead crosses them, at 25-45 m. The only error left is the constant
  speed the time to arrival assumes: a TTA^2 / 2v, plus half an LSB (0.01 s); asserted per
  receipt.
* the simulator's 8 s demo drive (slow, 1280x720), replayed through the whole pipeline
  into ``alerts.blf``: one alert (the 60 mm bump), 20 drop seeds. Its time to arrival is
  off by what the lead-distance measurement is off (-0.07 s at the emission); the repeated
  sends must keep that error, not add to it.

Measured (docs/can-interface.md): synthetic, 5 seeds: 120 of 120 alerts, 2145 of 2375
RP_ALERT frames, TTA error median -0.000 s, max 0.032 s; demo, 20 seeds: 20 of 20 alerts,
147 of 160 frames, -0.069 s at every receipt.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import cast

import can
import cantools
import e2e.p01
import numpy as np
import pytest
from cantools.database.can import Database
from cantools.database.can import Message as MessageDef
from cantools.database.namedsignalvalue import NamedSignalValue

from roadpreview.apps.replay import ReplayInputs, replay
from roadpreview.canbus import read_can_log
from roadpreview.loop import RunSummary
from roadpreview.pipeline import FrameResult
from roadpreview.sim.recording import Recording
from roadpreview.sinks.can import CanMemorySink
from roadpreview.types import Alert, CameraFrame, FusionMode, Side, Status

REPO_DBC = Path(__file__).resolve().parents[2] / "data" / "roadpreview.dbc"
DROP = 0.10  #: share of frames lost on the bus
STALE_S = 0.5  #: the receiver forgets an alert it heard nothing of for 5 periods
TTA_LSB = 0.02


# --- the receiver: a chassis ECU on plain cantools -------------------------------------------


@dataclass
class Receipt:
    """One RP_ALERT that arrived."""

    t_s: float
    alert_id: int
    distance_m: float | None
    tta_s: float | None


@dataclass
class ChassisReceiver:
    """Checks CRC and counter per message, keeps the active alerts by id, ends them on
    RP_ALERT_END or after ``stale_s`` of silence (docs/can-interface.md, "What a receiver
    does")."""

    db: Database
    stale_s: float = STALE_S
    receipts: list[Receipt] = field(default_factory=list)
    active: dict[int, float] = field(default_factory=dict)  #: id -> last heard
    started: list[tuple[float, int]] = field(default_factory=list)  #: new alerts
    ended: list[tuple[float, int, str]] = field(default_factory=list)  #: (t, id, why)
    problems: Counter[str] = field(default_factory=Counter)
    lost: int = 0  #: frames the counters say were missed
    _last_counter: dict[int, int] = field(default_factory=dict)

    def _message(self, frame_id: int) -> MessageDef | None:
        try:
            return self.db.get_message_by_frame_id(frame_id)
        except KeyError:
            return None

    def expire(self, t: float) -> None:
        """The clock says ``t``: alerts not heard of for ``stale_s`` are dropped."""
        for alert_id, heard in list(self.active.items()):
            if t - heard > self.stale_s:
                del self.active[alert_id]
                self.ended.append((t, alert_id, "stale"))

    def receive(self, msg: can.Message) -> None:
        t = float(msg.timestamp)
        self.expire(t)
        m = self._message(msg.arbitration_id)
        if m is None or m.senders != ["ROADPREVIEW"]:
            return
        data = bytes(msg.data)
        data_id = int(m.dbc.attributes["E2E_DataID"].value) if m.dbc is not None else -1
        if len(data) != m.length or not e2e.p01.e2e_p01_check(bytearray(data), data_id):
            self.problems["crc"] += 1
            return
        counter = data[1] & 0x0F
        last = self._last_counter.get(m.frame_id)
        if last is not None:
            jump = (counter - last) % 15
            if jump == 0:
                self.problems["counter_repeated"] += 1
                return
            self.lost += jump - 1
        self._last_counter[m.frame_id] = counter
        values = cast(dict[str, object], m.decode(data))
        if m.name == "RP_ALERT":
            alert_id = cast(int, values["AlertId"])
            if alert_id not in self.active:
                self.started.append((t, alert_id))
            self.active[alert_id] = t
            self.receipts.append(
                Receipt(
                    t,
                    alert_id,
                    _value(values["AlertDistance"]),
                    _value(values["AlertTimeToArrival"]),
                )
            )
        elif m.name == "RP_ALERT_END":
            alert_id = cast(int, values["EndAlertId"])
            if self.active.pop(alert_id, None) is not None:
                self.ended.append((t, alert_id, str(values["EndReason"])))


def _value(x: object) -> float | None:
    return None if isinstance(x, NamedSignalValue) else float(cast(float, x))


def _lossy(frames: Sequence[can.Message], seed: int) -> list[can.Message]:
    keep = np.random.default_rng(seed).random(len(frames)) >= DROP
    return [f for f, k in zip(frames, keep, strict=True) if k]


def _receive(db: Database, frames: Iterable[can.Message]) -> ChassisReceiver:
    """The frames in, then a second of silence."""
    rx = ChassisReceiver(db)
    t = -math.inf
    for f in frames:
        rx.receive(f)
        t = float(f.timestamp)
    rx.expire(t + 1.0)
    return rx


@pytest.fixture(scope="module")
def plain_db() -> Database:
    db = cantools.database.load_file(REPO_DBC, strict=True)
    assert isinstance(db, Database)
    return db


# --- a synthetic drive ------------------------------------------------------------------------

FPS = 30.0
V0, DV, PERIOD_V = 12.0, 0.5, 20.0  #: ego speed V0 + DV sin(2 pi t / PERIOD_V), m/s
A_MAX = DV * 2 * math.pi / PERIOD_V  #: its largest acceleration, 0.16 m/s^2
CAM_TO_FRONT = 0.2


def _x_cam(t: np.ndarray | float) -> np.ndarray:
    """The ego camera's position along the road, m (the integral of the speed)."""
    w = 2 * math.pi / PERIOD_V
    return np.asarray(V0 * np.asarray(t) + DV / w * (1 - np.cos(w * np.asarray(t))))


def _speed(t: float) -> float:
    return V0 + DV * math.sin(2 * math.pi * t / PERIOD_V)


@dataclass(frozen=True)
class _Synthetic:
    frames: list[can.Message]
    alerts: list[Alert]
    arrival_s: dict[int, float]  #: alert id (mod 256) -> true front-axle arrival


@pytest.fixture(scope="module")
def synthetic() -> _Synthetic:
    """60 s, 24 anomalies; each measured exactly when the lead crosses it 25-45 m ahead,
    confirmed 0.9-1.5 s later (0.5-2.8 s before the ego gets there). The loop's calls:
    every frame, the status every 100 ms, the close at the end."""
    rng = np.random.default_rng(7)
    duration = 60.0
    t_fine = np.arange(0.0, duration + 10.0, 1e-4)
    x_front = _x_cam(t_fine) + CAM_TO_FRONT
    alerts_at: dict[int, list[Alert]] = {}
    alerts: list[Alert] = []
    arrival: dict[int, float] = {}
    t_cross = 1.0
    for k in range(1, 25):
        t_cross += float(rng.uniform(1.5, 3.0))
        ahead = float(rng.uniform(25.0, 45.0))
        t_emit_frame = round((t_cross + float(rng.uniform(0.9, 1.5))) * FPS)
        x_anomaly = float(_x_cam(t_cross)) + ahead
        alert = Alert(
            t_s=t_cross,
            t_emit_s=t_emit_frame / FPS,
            distance_m=ahead,
            time_to_arrival_s=(ahead - CAM_TO_FRONT) / _speed(t_cross),
            severity_px=8.0,
            height_mm=float(rng.choice([60.0, -60.0])),
            side=Side.BOTH,
            confidence=0.9,
            mode=FusionMode.FUSED,
            alert_id=k,
            length_m=float(rng.uniform(0.5, 3.0)),
        )
        alerts_at.setdefault(t_emit_frame, []).append(alert)
        alerts.append(alert)
        arrival[k] = float(np.interp(x_anomaly, x_front, t_fine))
    sink = CanMemorySink()
    status = Status(mode=FusionMode.FUSED)
    next_status = -math.inf
    for i in range(round(duration * FPS) + 1):
        t = i / FPS
        result = SimpleNamespace(
            t=t,
            alerts=tuple(alerts_at.get(i, ())),
            provisional=(),
            cancelled=(),
            preview=None,
            confirmations=(),
            ego_speed_mps=_speed(t),
        )
        sink.on_frame(CameraFrame(t, None), cast(FrameResult, result), status)
        if t >= next_status:
            sink.on_status(t, status)
            next_status = t + 0.1
    sink.close(RunSummary())  # the last alert is still active: CANCELLED
    return _Synthetic(sink.messages, alerts, arrival)


def _errors(
    rx: ChassisReceiver,
    arrival_s: Callable[[int], float | None],
    since_s: Callable[[int], float] = lambda _: -math.inf,
    until_s: Callable[[int], float] = lambda _: math.inf,
) -> np.ndarray:
    """TTA at receipt minus the truth, for every receipt with a TTA (s) received in
    [since_s, until_s) of its alert (default: all)."""
    out = []
    for r in rx.receipts:
        truth = arrival_s(r.alert_id)
        inside = since_s(r.alert_id) - 1e-6 <= r.t_s < until_s(r.alert_id) - 1e-6
        if r.tta_s is not None and truth is not None and inside:
            out.append(r.tta_s - (truth - r.t_s))
    return np.array(out)


@pytest.mark.parametrize("seed", range(5))
def test_every_alert_arrives_through_a_lossy_bus_with_its_time_to_arrival(
    plain_db: Database, synthetic: _Synthetic, seed: int
) -> None:
    sent = synthetic.frames
    got = _lossy(sent, seed)
    assert len(got) == pytest.approx((1 - DROP) * len(sent), rel=0.05)
    rx = _receive(plain_db, got)
    assert rx.problems == {}
    # the E2E counters see every lost frame but a message's first and last ones
    assert len(sent) - len(got) - 12 <= rx.lost <= len(sent) - len(got)
    ids = [a.alert_id % 256 for a in synthetic.alerts]
    # every alert arrives, once: repetition, not luck (each is sent about 25 times)
    assert sorted(i for _, i in rx.started) == sorted(ids)
    assert {r.alert_id for r in rx.receipts} == set(ids)
    # ... and ends: by its RP_ALERT_END (3 of them), or by the silence rule if all 3 were lost
    assert sorted(i for _, i, _ in rx.ended) == sorted(ids)
    assert sum(why == "PASSED" for _, _, why in rx.ended) >= len(ids) - 2
    # at each receipt the TTA is the truth within the constant-speed assumption's error,
    # a TTA^2 / (2 v), and half an LSB
    by_id = {r.alert_id: r for r in rx.receipts}
    assert by_id
    for r in rx.receipts:
        if r.tta_s is None:
            continue
        truth = synthetic.arrival_s[r.alert_id] - r.t_s
        bound = TTA_LSB / 2 + A_MAX * truth**2 / (2 * (V0 - DV)) + 2e-3
        assert abs(r.tta_s - truth) <= bound, (r, truth, bound)
    err = _errors(rx, synthetic.arrival_s.get)
    assert len(err) >= 0.85 * sum(m.arbitration_id == 0x200 for m in sent)
    assert np.max(np.abs(err)) <= 0.1


# --- the simulator's demo drive through the whole pipeline ------------------------------------


@pytest.fixture(scope="module")
def demo_blf(make_recording: Callable[..., Recording], tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    """The 8 s demo drive (the session's recording of test_replay.py and test_daemon.py)
    replayed into ``alerts.blf``, with the true front-axle arrival of each alert's anomaly."""
    rec = make_recording("demo", seed=0, duration_s=8.0, width=1280, height=720)
    out = tmp_path_factory.mktemp("lossy_replay")
    result = replay(ReplayInputs.from_recording(rec.folder), out=out)
    assert result.match is not None
    arrival = {}
    events = {int(e["index"]): e for e in rec.info["events"]}
    for row in result.match.rows:
        if row.alert is not None and events[row.event_index].get("ego_front_t_s") is not None:
            t_ego = float(events[row.event_index]["ego_front_t_s"])
            arrival[row.alert.alert_id % 256] = result.video_start_s + t_ego
    frames = list(read_can_log(out / "alerts.blf"))
    return frames, result.alerts, arrival


@pytest.mark.slow
def test_the_demo_drive_alerts_arrive_through_a_lossy_bus(plain_db: Database, demo_blf) -> None:  # type: ignore[no-untyped-def]
    frames, alerts, arrival = demo_blf
    assert alerts, "the demo's first bump is detected (test_demo_detection.py)"
    assert set(arrival) == {a.alert_id % 256 for a in alerts}  # every alert is a true one
    clean = _receive(plain_db, frames)
    # an alert may go out PROVISIONAL first (issue 27): its crossing is the early fit's,
    # coarser; the CONFIRMED sends carry the two-axle fit's
    confirmed_at = {a.alert_id % 256: a.t_emit_s for a in alerts}
    err0 = _errors(clean, arrival.get, confirmed_at.__getitem__)
    early = _errors(clean, arrival.get, until_s=confirmed_at.__getitem__)
    assert len(err0) >= 5
    # the emission's own error: the lead-distance measurement over the speed
    assert np.max(np.abs(err0)) <= 0.1, err0
    # later sends keep it: odometry and quantisation add at most 0.03 s
    assert np.ptp(err0) <= 0.03, err0
    # the provisional sends: their crossing within a third of a second (the early fit fires
    # when its evidence suffices, up to the rear axle's lag after the front axle)
    assert early.size == 0 or np.max(np.abs(early)) <= 0.35, early
    received, errs = [], []
    for seed in range(20):
        rx = _receive(plain_db, _lossy(frames, seed))
        assert rx.problems == {}
        assert {i for _, i in rx.started} == set(arrival), seed  # every alert, every seed
        received.append(len(rx.started))
        errs.append(_errors(rx, arrival.get, confirmed_at.__getitem__))
    err = np.concatenate(errs)
    assert np.max(np.abs(err)) <= 0.1
    print(  # the figures of the report (pytest -s)
        f"\ndemo drive, 10 % loss, 20 seeds: alerts received {sum(received)} of"
        f" {20 * len(arrival)}; RP_ALERT receipts {len(err)} of {20 * len(err0)} sent;"
        f" TTA error at receipt median {np.median(err):+.3f} s, |max| {np.max(np.abs(err)):.3f} s"
        f" (at emission {err0[0]:+.3f} s)"
    )
