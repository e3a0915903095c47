"""Write and read CAN log files (Vector BLF and ASC, candump ``-L`` .log, PEAK TRC, CSV,
ASAM MDF4, python-can's SQLite).

The format follows the file suffix: ``.blf``, ``.asc``, ``.log``, ``.trc``,
``.csv``, ``.mf4``, ``.db`` and, for the text formats, their gzip variants
(``.asc.gz``, ``.log.gz``, ``.trc.gz``, ``.csv.gz``; python-can cannot gzip
BLF, MF4 or SQLite). These are every format ``can.LogReader`` reads. MF4
goes through python-can's ``mf4`` extra (asammdf); without it, opening an
``.mf4`` raises `MissingDependencyError` naming the install command.

Writing goes through ``can.Logger``. Reading uses python-can's own readers
(the ones ``can.LogReader`` picks by suffix) but never dies on bad data: **a
garbled CAN frame is logged and skipped, never a crash**, as a replay or a
daemon needs. For the text formats the reader is resumed on the line after
the bad one, so frames after the garbage are not lost; each problem is
recorded as a `LogProblem` naming the file and line. A BLF file is
resynchronised after corrupt bytes on the next intact container
(`roadpreview.canbus.blfscan`): only the frames of the damaged container(s)
are lost, and the problem names the byte offset and the bytes skipped. A
truncated BLF (a logger that lost power) delivers every complete frame and
reports the truncation. Problems are counted by kind in ``counts``
(``skipped_bad_line``, ``resynced``, ``truncated``, ...); the first
`MAX_LOGGED_PROBLEMS` of a file are logged one line each, the rest only
counted and summed up in one line at the end. With ``errors="raise"`` every
valid frame is still delivered first and an `InputDataError` summarising the
problems is raised at the end.

Timestamps are what the logger stored, in seconds (normally Unix time):

* candump .log: absolute, 1 µs resolution.
* BLF: start of measurement as a calendar date (1 ms, UTC) plus offsets in
  ns; python-can takes timestamps before 1990 for "not a date" and drops
  the start, so `write_can_log` refuses them for BLF.
* TRC (version 2.1 as python-can writes it): start as a day count, offsets
  in ms with 3 decimals; about 1 µs.
* CSV (python-can's layout: time, hex ID, flags, DLC, base64 data): the full
  float, exact. It has no channel column: channels read back as None.
* MF4 (python-can's writer: a CAN bus-logging group, start time plus float
  offsets): Unix times come back exact; times near 0 lose precision (float32
  offsets, about 1e-8 s at 1 s).
* SQLite (``.db``, python-can's ``messages`` table): the full float, exact. It
  has no channel column: channels read back as None.
* ASC: the start of measurement as a *local-time* calendar date (1 ms)
  plus offsets in µs. We start the measurement on the whole second before
  the first frame (as CANoe does, the first frame need not be at 0), so the
  absolute times survive to 1 µs, and read them back as absolute times
  (``relative_timestamp=False``); both ends must use the same time zone.
  python-can's own ASC reader defaults to times relative to the start.

Channels: the simulator writes channel 0, which ASC, BLF and TRC store as
channel 1 (their numbering starts at 1) and candump as ``can0``.
`read_can_log` turns every one of these back into the integer 0
(``canN``/``vcanN`` -> N), so one bus has one channel number whatever the
format.
"""

from __future__ import annotations

import contextlib
import gzip
import logging
import math
import os
import re
import struct
import time
import zlib
from collections import Counter
from collections.abc import Callable, Generator, Iterable, Iterator
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import IO, Any, Literal, TextIO, cast

import can
from can.io.blf import BLFParseError, BLFWriter
from can.io.generic import MessageWriter

from roadpreview.canbus.blfscan import BlfScanner, Resync
from roadpreview.errors import (
    ConfigError,
    InputDataError,
    MissingDependencyError,
    OperationError,
)

log = logging.getLogger(__name__)

#: suffixes `write_can_log` and `read_can_log` understand
LOG_SUFFIXES = (
    ".blf",
    ".asc",
    ".log",
    ".trc",
    ".csv",
    ".mf4",
    ".db",
    ".asc.gz",
    ".log.gz",
    ".trc.gz",
    ".csv.gz",
)
_BASE_FORMATS = (".blf", ".asc", ".log", ".trc", ".csv", ".mf4", ".db")
#: binary formats: no gzip variant, read as a whole by python-can's reader
_BINARY_FORMATS = (".blf", ".mf4", ".db")

#: python-can's BLF code treats earlier timestamps as "not a Unix time" (1990-01-01)
_BLF_MIN_TIMESTAMP = 631152000.0

#: problems of one log logged one line each; the rest are counted, summed up at the end
MAX_LOGGED_PROBLEMS = 10

_CHANNEL_NAME = re.compile(r"^[a-z]*can(\d+)$", re.IGNORECASE)


def log_format(path: str | Path) -> tuple[str, bool]:
    """The format of a CAN log from its suffix: (one of `_BASE_FORMATS`, gzipped).

    Raises `InputDataError` for anything else.
    """
    suffixes = [s.lower() for s in Path(path).suffixes]
    gz = bool(suffixes) and suffixes[-1] == ".gz"
    base = suffixes[-2] if gz and len(suffixes) >= 2 else (suffixes[-1] if suffixes else "")
    if base not in _BASE_FORMATS or (gz and base in _BINARY_FORMATS):
        raise InputDataError(
            f"{path}: unknown CAN log format; use one of {', '.join(LOG_SUFFIXES)}"
        )
    return base, gz


class _ASCWriter(can.ASCWriter):
    """python-can's ASC writer with the measurement starting on a whole second.

    python-can starts the measurement at the first frame and writes the start
    date with millisecond resolution, so the sub-millisecond part of every
    absolute time is lost, and it writes 5 ms as ``.5`` (read back as 500 ms).
    Starting on the whole second and writing three digits keeps every
    timestamp exact to the file's 1 µs.
    """

    def _format_header_datetime(self, dt: datetime) -> str:
        return f"{dt.strftime('%a %b %d %H:%M:%S')}.{dt.microsecond // 1000:03d} {dt.year}"

    def log_event(self, message: str, timestamp: float | None = None) -> None:
        if not self.header_written and timestamp is not None:
            self.started = self.last_timestamp = float(math.floor(timestamp))
            start = self._format_header_datetime(datetime.fromtimestamp(self.started))
            self.file.write(f"Begin Triggerblock {start}\n")
            self.header_written = True
            super().log_event("Start of measurement", self.started)
        super().log_event(message, timestamp)


class _SqliteWriter(can.SqliteWriter):
    """python-can's SQLite writer, waiting at ``stop`` until its queue is drained.

    Its writer thread takes at most 501 frames per batch and leaves its loop at the
    first batch after ``stop``: frames still queued behind a full batch were lost (a
    1232-frame drive came back with 501).
    """

    def stop(self) -> None:
        while not self.buffer.empty() and self._writer_thread.is_alive():
            time.sleep(0.01)
        super().stop()


def _needs_asammdf(path: str | Path) -> MissingDependencyError:
    return MissingDependencyError(
        f"{path}: MF4 needs asammdf; install it with: pip install 'python-can[mf4]'"
    )


def _open_writer(path: str | Path, fmt: str, gz: bool) -> MessageWriter:
    if fmt == ".asc":
        if gz:
            return _ASCWriter(gzip.open(path, mode="wt", encoding="utf-8"))
        return _ASCWriter(os.fspath(path))
    if fmt == ".db":
        Path(path).unlink(missing_ok=True)  # python-can would append to an existing table
        return _SqliteWriter(os.fspath(path))
    try:
        return can.Logger(os.fspath(path))
    except NotImplementedError:  # python-can's answer when asammdf is missing
        raise _needs_asammdf(path) from None


class CanLogWriter:
    """A CAN log written as frames come (format by suffix), for sinks that stream.

    Timestamps must not decrease (a logger stores frames as they arrive); for
    BLF they must be Unix times (>= 1990). A frame that breaks either rule is
    refused with `InputDataError` naming the file and the frame's index; the
    file keeps what was written before it. ``close`` flushes and closes.
    """

    def __init__(self, path: str | Path) -> None:
        try:
            self.format, gz = log_format(path)
        except InputDataError as exc:
            raise ConfigError(str(exc)) from None
        self.path = Path(path)
        self._writer: MessageWriter | None = _open_writer(path, self.format, gz)
        self.count = 0  #: frames written
        self._last = -math.inf

    def write(self, msg: can.Message) -> None:
        """Append one frame (module rules)."""
        if self._writer is None:
            raise OperationError(f"{self.path}: the CAN log is closed")
        ts = float(msg.timestamp)
        if ts < self._last:
            raise InputDataError(
                f"{self.path}: message {self.count} has timestamp {ts:.6f} s, earlier than the"
                f" previous {self._last:.6f} s; a CAN log is in reception order"
            )
        if self.format == ".blf" and self.count == 0 and ts < _BLF_MIN_TIMESTAMP:
            raise InputDataError(
                f"{self.path}: first timestamp {ts:.6f} s is not a Unix time; BLF stores the"
                " start as a calendar date and python-can would read these frames back"
                " shifted (add a Unix epoch offset)"
            )
        self._writer.on_message_received(msg)
        self._last = ts
        self.count += 1

    def flush(self) -> None:
        """Put every frame written so far into the file, so that a reader sees it while
        the log is still open: a BLF writer's open container is compressed and written
        (python-can otherwise waits for 128 KiB of frames), a text log's buffer flushed."""
        writer = self._writer
        if writer is None:
            return
        if isinstance(writer, BLFWriter):
            writer._flush()  # python-can's own container write; no public call does it
        file = getattr(writer, "file", None)
        if file is not None and not file.closed:
            file.flush()

    def close(self) -> None:
        """Flush and close (idempotent)."""
        if self._writer is not None:
            writer, self._writer = self._writer, None
            writer.stop()


def write_can_log(path: str | Path, messages: Iterable[can.Message]) -> int:
    """Write ``messages`` (in reception order) to a CAN log chosen by suffix; return the count.

    The rules of `CanLogWriter`; on an error the partly written file is removed
    and `InputDataError` names the message index.
    """
    writer = CanLogWriter(path)
    try:
        for msg in messages:
            writer.write(msg)
    except BaseException:
        writer.close()
        Path(path).unlink(missing_ok=True)
        raise
    writer.close()
    return writer.count


@dataclass(frozen=True)
class LogProblem:
    """One bad spot in a CAN log: where, why, and whether reading stopped there (or
    resumed further on: ``resumed_at``, a byte offset). ``kind`` is the counter's key."""

    path: str
    reason: str
    line: int | None = None
    byte_offset: int | None = None
    fatal: bool = False
    kind: str = "skipped_bad_line"
    resumed_at: int | None = None

    def __str__(self) -> str:
        where = self.path
        if self.line is not None:
            where += f":{self.line}"
        elif self.byte_offset is not None:
            where += f" (byte {self.byte_offset})"
        if self.fatal:
            what = "reading stopped"
        elif self.resumed_at is not None:
            what = f"reading resumed at byte {self.resumed_at}"
        else:
            what = "frame skipped"
        return f"{where}: {self.reason}; {what}"


def channel_number(channel: Any) -> Any:
    """``canN``/``vcanN`` -> N; integers stay; other names are kept as they are."""
    if isinstance(channel, str):
        m = _CHANNEL_NAME.match(channel.strip())
        if m:
            return int(m.group(1))
    return channel


class _CountingLines:
    """A text file seen line by line, counting lines, surviving a reader's ``close()``.

    python-can's text readers iterate over their file and close it when done;
    we hand each (possibly resumed) reader this object instead, so that the
    line number of a bad line is known and the next reader continues after it.
    Errors of the file itself (a truncated gzip stream) end the iteration and
    are kept in ``broken``.
    """

    def __init__(self, f: IO[str]) -> None:
        self._f = f
        self.line_no = 0
        self.broken: BaseException | None = None
        self._pending: list[str] = []

    def push_back(self, line: str) -> None:
        """Hand out ``line`` next (not counted: it is not in the file)."""
        self._pending.append(line)

    def __iter__(self) -> _CountingLines:
        return self

    def __next__(self) -> str:
        if self._pending:
            return self._pending.pop()
        if self.broken is not None:
            raise StopIteration
        try:
            line = next(self._f)
        except (OSError, EOFError, zlib.error) as exc:
            self.broken = exc
            raise StopIteration from None
        self.line_no += 1
        return line

    def close(self) -> None:
        """Ignored: the file belongs to `CanLogReader`."""


class _ResumableASCReader(can.ASCReader):
    """python-can's ASC reader, able to continue a file after a bad line.

    A resumed reader keeps the number base and the start of measurement of
    the reader it replaces and does not look for the file header again.
    """

    def __init__(self, file: _CountingLines, previous: object = None) -> None:
        if not isinstance(previous, _ResumableASCReader):
            previous = None
        base = previous.base if previous is not None else "hex"
        super().__init__(cast("TextIO", file), base=base, relative_timestamp=False)
        self._resumed = previous is not None
        if previous is not None:
            self.start_time = previous.start_time
            self.date = previous.date

    def _extract_header(self) -> None:
        if not self._resumed:
            super()._extract_header()


class _ResumableTRCReader(can.TRCReader):
    """python-can's TRC reader, able to continue after a bad line, channels from 0.

    A line python-can cannot split into its columns raises here (python-can
    would only log it), so that the bad line is recorded with its number.
    A resumed reader keeps the version, start time and columns of the
    header that the first reader read.
    """

    def __init__(self, file: _CountingLines, previous: object = None) -> None:
        super().__init__(cast("TextIO", file))
        self._previous = previous if isinstance(previous, _ResumableTRCReader) else None

    def _extract_header(self) -> str | None:  # type: ignore[override]
        prev = self._previous
        if prev is None:
            return super()._extract_header()
        self.file_version = prev.file_version
        self._start_time = prev._start_time
        self.columns = prev.columns
        self._num_columns = prev._num_columns
        self._parse_cols = getattr(self, prev._parse_cols.__name__)
        for line in self.file:
            text = line.strip()
            if text and not text.startswith(";"):
                return text
        return None

    def _parse_line(self, line: str) -> can.Message | None:
        return self._parse_cols(tuple(line.split(maxsplit=self._num_columns)))

    def __iter__(self) -> Generator[can.Message, None, None]:
        for msg in super().__iter__():
            if isinstance(msg.channel, int):
                msg.channel -= 1  # TRC numbers buses from 1
            yield msg


def _csv_reader(lines: _CountingLines, previous: object) -> can.CSVReader:
    """python-can's CSV reader; a resumed one is given a stand-in for the header it skips."""
    if previous is not None:
        lines.push_back("timestamp,arbitration_id,extended,remote,error,dlc,data\n")
    return can.CSVReader(cast("TextIO", lines))


class CanLogReader:
    """Iterate over the frames of a CAN log, skipping and recording garbled ones.

    ``errors="log"`` (for replay and daemons) logs each problem and carries
    on; ``errors="raise"`` also delivers every valid frame, then raises
    `InputDataError` at the end if there was any problem. After (or during)
    an iteration ``problems`` lists what went wrong. Channels are normalised
    to integers (module docstring).
    """

    def __init__(self, path: str | Path, *, errors: Literal["log", "raise"] = "log") -> None:
        if errors not in ("log", "raise"):
            raise ConfigError(f"errors = {errors!r}: must be 'log' or 'raise'")
        self.path = Path(path)
        self.errors = errors
        self.format, self.gzipped = log_format(path)
        self.problems: list[LogProblem] = []
        self.bytes_skipped = 0  #: bytes of a BLF skipped to resynchronise

    @property
    def counts(self) -> Counter[str]:
        """Problems by kind (``LogProblem.kind``) -> count."""
        return Counter(p.kind for p in self.problems)

    def __iter__(self) -> Iterator[can.Message]:
        self.problems = []
        self.bytes_skipped = 0
        if not self.path.is_file():
            raise InputDataError(f"{self.path}: CAN log not found")
        if self.format == ".blf":
            frames = self._iter_blf()
        elif self.format in (".mf4", ".db"):
            frames = self._iter_whole()
        else:
            frames = self._iter_text()
        for msg in frames:
            msg.channel = channel_number(msg.channel)
            yield msg
        if len(self.problems) > MAX_LOGGED_PROBLEMS:
            counts = ", ".join(f"{k} {n}" for k, n in sorted(self.counts.items()))
            log.warning(
                "%s: %d problems in all (%s); the first %d were logged",
                self.path,
                len(self.problems),
                counts,
                MAX_LOGGED_PROBLEMS,
            )
        if self.problems and self.errors == "raise":
            first = self.problems[0]
            raise InputDataError(f"{first} ({len(self.problems)} problem(s) in this log)")

    def _problem(self, problem: LogProblem) -> None:
        self.problems.append(problem)
        n = len(self.problems)
        if n > MAX_LOGGED_PROBLEMS and not problem.fatal:
            return
        if problem.fatal:
            log.error("%s", problem)
        else:
            log.warning("%s", problem)
        if n == MAX_LOGGED_PROBLEMS:
            log.warning("%s: further problems of this log are only counted", self.path)

    def _open_text(self) -> IO[str]:
        if self.gzipped:
            return gzip.open(self.path, mode="rt", encoding="utf-8", errors="replace")
        return open(self.path, encoding="utf-8", errors="replace")

    def _iter_text(self) -> Iterator[can.Message]:
        make: Callable[[_CountingLines, Any], Any]
        if self.format == ".asc":
            make = _ResumableASCReader
        elif self.format == ".trc":
            make = _ResumableTRCReader
        elif self.format == ".csv":
            make = _csv_reader
        else:
            make = lambda lines, _previous: can.CanutilsLogReader(cast("TextIO", lines))  # noqa: E731
        with self._open_text() as f:
            lines = _CountingLines(f)
            reader = make(lines, None)
            failed_at = -1
            while True:
                try:
                    yield from reader
                    break
                # Any exception of a python-can parser here means a line it could
                # not make sense of; the contract is to log and skip it.
                except Exception as exc:
                    if lines.line_no == failed_at:  # nothing consumed: do not loop
                        self._problem(
                            LogProblem(
                                str(self.path),
                                f"reader stuck ({exc!r})",
                                fatal=True,
                                kind="reader_stuck",
                            )
                        )
                        return
                    failed_at = lines.line_no
                    self._problem(
                        LogProblem(
                            str(self.path), f"garbled CAN frame ({exc!r})", line=lines.line_no
                        )
                    )
                    reader = make(lines, reader)
            if lines.broken is not None:
                self._problem(
                    LogProblem(
                        str(self.path),
                        f"file ends abruptly ({lines.broken!r})",
                        line=lines.line_no + 1,
                        fatal=True,
                        kind="truncated",
                    )
                )

    def _iter_whole(self) -> Iterator[can.Message]:
        """MF4 and SQLite: python-can's reader over the whole file; a file it cannot
        open or finish is one fatal problem (frames before it are delivered)."""
        kind = "MF4" if self.format == ".mf4" else "SQLite CAN log"
        with contextlib.ExitStack() as stack:
            try:
                if self.format == ".mf4":
                    # an open file of ours: python-can leaks the one it opens when asammdf
                    # refuses the file
                    reader: Any = can.MF4Reader(stack.enter_context(open(self.path, "rb")))
                else:
                    reader = can.SqliteReader(os.fspath(self.path))
                stack.callback(reader.stop)
            except NotImplementedError:  # python-can's answer when asammdf is missing
                raise _needs_asammdf(self.path) from None
            # asammdf and sqlite3 raise many types for a damaged file; each is this problem
            except Exception as exc:
                self._problem(
                    LogProblem(
                        str(self.path),
                        f"not a readable {kind} ({exc!r})",
                        fatal=True,
                        kind="unreadable",
                    )
                )
                return
            try:
                yield from reader
            except Exception as exc:
                self._problem(
                    LogProblem(
                        str(self.path),
                        f"corrupt {kind} data ({exc!r})",
                        fatal=True,
                        kind="corrupt_data",
                    )
                )

    def _iter_blf(self) -> Iterator[can.Message]:
        actual_size = self.path.stat().st_size
        with open(self.path, "rb") as f:
            try:
                reader = can.BLFReader(f)  # the file header: size, start of measurement
            except (BLFParseError, struct.error, ValueError) as exc:
                self._problem(
                    LogProblem(
                        str(self.path),
                        f"not a BLF file ({exc!r})",
                        byte_offset=0,
                        fatal=True,
                        kind="unreadable",
                    )
                )
                return
            declared_size = int(reader.file_size)
            start_known = bool(reader.start_timestamp)
            scanner = BlfScanner(f, f.tell(), self._blf_resync)
            yield from scanner
        if actual_size < declared_size:
            reason = (
                f"truncated BLF: {actual_size} of {declared_size} bytes"
                " (frames in the missing part are lost)"
            )
            kind = "truncated"
        elif actual_size > declared_size and not scanner.resyncs:  # else: inserted bytes
            reason = (
                f"BLF header never finalised (it says {declared_size} bytes, the file has"
                f" {actual_size}): the logger was not closed, its last buffered frames"
                " are missing"
            )
            if not start_known:
                reason += " and, with no start date, times are relative to the start"
            kind = "unfinished"
        else:
            return
        self._problem(
            LogProblem(str(self.path), reason, byte_offset=actual_size, fatal=True, kind=kind)
        )

    def _blf_resync(self, event: Resync) -> None:
        self.bytes_skipped += event.skipped
        if event.resumed_at is None:
            reason = f"corrupt BLF data ({event.reason}); no intact container after it"
            self._problem(
                LogProblem(
                    str(self.path),
                    reason,
                    byte_offset=event.offset,
                    fatal=True,
                    kind="corrupt_data",
                )
            )
            return
        reason = f"corrupt BLF data ({event.reason}); {event.skipped} bytes skipped"
        self._problem(
            LogProblem(
                str(self.path),
                reason,
                byte_offset=event.offset,
                kind="resynced",
                resumed_at=event.resumed_at,
            )
        )


def read_can_log(
    path: str | Path, *, errors: Literal["log", "raise"] = "log"
) -> Iterator[can.Message]:
    """The frames of a CAN log (format by suffix), garbled frames logged and skipped.

    See `CanLogReader` for ``errors``; use the class to see the problems.
    """
    reader = CanLogReader(path, errors=errors)
    if not reader.path.is_file():
        raise InputDataError(f"{path}: CAN log not found")
    return iter(reader)
