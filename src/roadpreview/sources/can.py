"""CAN sources: a log file (any format python-can reads) or a live bus, decoded *here*
through the DBC and the input mapping into `ImuSample` / `SpeedSample`.

Frames of unknown IDs are ignored; garbled frames, failed integrity checks and
values out of the DBC's range are logged (once per kind) and counted in
``errors`` (and by kind in ``problems``); nothing downstream sees ``can.Message``.
A sample stamped before its predecessor in a log is dropped and counted (the log's
order is kept).
"""

from __future__ import annotations

import logging
import math
import threading
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path

import can

from roadpreview.canbus.dbc import load_database
from roadpreview.canbus.decode import CanInputDecoder
from roadpreview.canbus.live import CanReceiver
from roadpreview.canbus.logio import CanLogReader, read_can_log
from roadpreview.canbus.mapping import load_mapping
from roadpreview.clock import Clock, SystemClock
from roadpreview.errors import InputDataError
from roadpreview.plausibility import PlausibilityConfig
from roadpreview.sources import shifted
from roadpreview.types import InputSample

log = logging.getLogger(__name__)

#: a frame-level clock check: frames in, frames out (`roadpreview.sources.clockguard`)
StampFilter = Callable[[Iterable[can.Message]], Iterator[can.Message]]


def make_decoder(
    dbc: str = "", mapping: str = "roadpreview", plausibility: PlausibilityConfig | None = None
) -> CanInputDecoder:
    """The input decoder for a DBC file and a mapping (a file or a shipped name); without
    a DBC, the one the mapping names when that file lies beside the mapping file, else
    roadpreview's own. Quantities the car does not provide are logged once."""
    input_mapping = load_mapping(mapping)
    if not dbc and input_mapping.header.dbc not in ("", "roadpreview.dbc"):
        beside = Path(input_mapping.source).parent / input_mapping.header.dbc
        if beside.is_file():
            dbc = str(beside)
    db = load_database(dbc or None, strict=not dbc)
    decoder = CanInputDecoder(
        db, input_mapping, db_name=dbc or "roadpreview.dbc", plausibility=plausibility
    )
    for quantity, why in decoder.missing.items():
        log.warning("CAN input: %s is not available (%s)", quantity, why)
    return decoder


class CanLogSource:
    """The samples of one CAN log, decoded (module docstring)."""

    live = False
    #: the frames' clock check before decoding (a `ClockGuard` installs one); None: a frame
    #: stamped before its predecessor is dropped
    stamp_filter: StampFilter | None = None

    def __init__(
        self, path: str | Path, decoder: CanInputDecoder, *, offset_s: float = 0.0
    ) -> None:
        self.path = Path(path)
        self.name = str(self.path)
        if not self.path.is_file():
            raise InputDataError(f"{self.path}: CAN log not found")
        self.decoder = decoder
        self.offset_s = offset_s
        self.out_of_order = 0  #: samples stamped before their predecessor (dropped)
        self.frames = 0  #: frames read
        self.samples = 0  #: samples decoded from them
        self._reader: CanLogReader | None = None
        self._closed = False

    @property
    def errors(self) -> int:
        garbled = len(self._reader.problems) if self._reader is not None else 0
        return self.decoder.stats.skipped + garbled + self.out_of_order

    @property
    def problems(self) -> Counter[str]:
        """Problems by kind -> count: the log reader's (``skipped_bad_line``,
        ``resynced``, ``truncated``, ...), the decoder's and this source's
        (``out_of_order``)."""
        counts: Counter[str] = Counter()
        if self._reader is not None:
            counts.update(self._reader.counts)
        decoded = getattr(self.decoder, "problems", None)
        if not isinstance(decoded, Mapping):  # the decoder's reasons by their names
            decoded = {str(k.value): n for k, n in self.decoder.stats.problems.items()}
        counts.update(decoded)
        if self.out_of_order:
            counts["out_of_order"] += self.out_of_order
        return counts

    def __iter__(self) -> Iterator[InputSample]:
        self._reader = CanLogReader(self.path)
        last = -math.inf
        self.frames = self.samples = 0
        check = self.stamp_filter
        for msg in self._reader if check is None else check(self._reader):
            if self._closed:
                return
            self.frames += 1
            if check is None and msg.timestamp < last:
                self.out_of_order += 1
                log.warning(
                    "%s: time stamp goes back %.3f s at %.6f; frame dropped",
                    self.path,
                    last - msg.timestamp,
                    msg.timestamp,
                )
                continue
            last = msg.timestamp
            for sample in self.decoder.decode(msg):
                self.samples += 1
                yield shifted(sample, self.offset_s)
        if self.frames and not self.samples:
            log.warning(
                "%s: 0 of %d frames matched the DBC/mapping (%s, mapping %s): no IMU or speed"
                " from this log; for another car give --dbc and --mapping",
                self.path,
                self.frames,
                self.decoder.db_name,
                self.decoder.mapping.source,
            )

    def close(self) -> None:
        self._closed = True


class CanBusSource:
    """The samples of a live bus, decoded as frames arrive (python-can's notifier thread
    queues them, bounded; drops are counted). Live. The bus stays its owner's. Waits for
    frames on ``clock`` (at most ``poll_s`` at a time; default: the system's)."""

    live = True
    #: the frames' clock check before decoding (a `ClockGuard` installs one)
    stamp_filter: StampFilter | None = None

    def __init__(
        self,
        bus: can.BusABC,
        decoder: CanInputDecoder,
        *,
        queue_size: int = 10_000,
        poll_s: float = 0.05,
        clock: Clock | None = None,
    ) -> None:
        self.bus = bus
        self.clock = clock or SystemClock()
        self.name = f"CAN bus {bus.channel_info}"
        self.decoder = decoder
        self.queue_size = queue_size
        self.poll_s = poll_s
        self.frames = 0  #: frames received
        self.receiver: CanReceiver | None = None
        self._stop = threading.Event()
        self._arrived = self.clock.event()  # a frame was queued (or `close` was called)

    @property
    def dropped(self) -> int:
        """Frames lost because the receive queue was full."""
        return self.receiver.dropped if self.receiver is not None else 0

    @property
    def receive_errors(self) -> int:
        """Errors the bus reported."""
        return self.receiver.listener.errors if self.receiver is not None else 0

    @property
    def problems(self) -> Counter[str]:
        """The decoder's problem counts by reason."""
        return self.decoder.problems

    @property
    def errors(self) -> int:
        return self.decoder.stats.skipped + self.dropped + self.receive_errors

    def __iter__(self) -> Iterator[InputSample]:
        self.receiver = CanReceiver(self.bus, maxsize=self.queue_size, arrived=self._arrived)
        check = self.stamp_filter
        try:
            frames = self._received(self.receiver)
            for msg in frames if check is None else check(frames):
                yield from self.decoder.decode(msg)
        finally:
            self.receiver.stop()

    def _received(self, receiver: CanReceiver) -> Iterator[can.Message]:
        while not self._stop.is_set():
            self._arrived.clear()  # before looking: a frame queued after it sets it again
            msg = receiver.recv(timeout=0.0)
            if msg is None:
                self.clock.wait(self._arrived, self.poll_s)
                continue
            self.frames += 1
            yield msg

    def close(self) -> None:
        self._stop.set()
        self._arrived.set()  # a reader waiting for a frame looks again now


def first_timestamp(path: str | Path) -> float:
    """Time stamp of the first frame of a CAN log."""
    for msg in read_can_log(path):
        return float(msg.timestamp)
    raise InputDataError(f"{path}: the CAN log holds no frame")


__all__ = ["CanBusSource", "CanLogSource", "first_timestamp", "make_decoder"]
