"""One clock for a drive whose inputs each keep their own: decided from first time stamps,
before any frame is processed (``docs/inputs.md``, "Clocks").

Every input has a clock. The camera's is relative (frame times from ``frames.csv`` or
index / fps) unless ``--video-start`` pins it, ``frames.csv`` holds Unix times, or the
camera is a bag topic stamped by its header. A log (CAN, IMU CSV, bag) keeps the clock
its recorder stamped: Unix time (first stamp > `UNIX_MIN_S`) or a clock near 0 (since
power-on, since the start). `plan_clocks` puts them on one clock:

1. *Fixed* clocks: the camera when pinned, every log on Unix time, every log given an
   explicit offset (added to its stamps). One Unix and one non-Unix fixed clock, or a
   log on Unix time and a log near 0 without offset, are *mixed clocks*: refused
   (`InputDataError` naming both inputs and their first stamps and the flag to give).
2. A log near 0 without an offset *floats*: its first sample is put at the camera's
   first frame (a coarse guess; the pipeline's camera-IMU offset estimator refines the
   IMU within its bounded range).
3. The camera's time 0 is the pinned one, else the first sample of the first log on
   Unix time *as recorded* (the camera starts with the log; an offset given to that log
   then shifts it against the camera), else 0 s (the camera's own clock: an offset
   given to a log near 0 says where it lies on it).
4. A drive with no Unix clock at all is shifted as a whole so that frame 0 falls at
   the camera's own time (`VideoTime`: the container's creation time, or the file's
   mtime minus its duration): outputs (BLF) need Unix times; alignment is kept.

This module only decides; the sources apply the offsets. `mp4_creation_time` reads the
``mvhd`` box of an MP4/QuickTime file (no decoder needed).
"""

from __future__ import annotations

import logging
import math
import struct
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from roadpreview.errors import InputDataError

log = logging.getLogger(__name__)

#: a first time stamp above this is Unix time (1973-03-03); below, a clock near 0 (a
#: recorder's time since power-on or since its start: 1e8 s is over three years)
UNIX_MIN_S = 1e8
#: the MP4/QuickTime epoch (1904-01-01 UTC) in Unix time
_MP4_EPOCH_UNIX_S = -2082844800.0
#: a container creation time before this (2000-01-01) is a camera without a clock
_PLAUSIBLE_SINCE_UNIX_S = 946684800.0
#: a log whose first sample is further than this from frame 0 is reported (not refused)
FAR_FROM_FRAME0_S = 600.0


def is_unix_time(t_s: float) -> bool:
    """True when a first time stamp reads as Unix time (module docstring)."""
    return math.isfinite(t_s) and t_s > UNIX_MIN_S


def clock_kind(t_s: float) -> str:
    """``"Unix time"`` or ``"a clock near 0"``, for messages."""
    return "Unix time" if is_unix_time(t_s) else "a clock near 0"


# --- the camera's own time -------------------------------------------------------------------


def _boxes(data: bytes, start: int, end: int) -> dict[bytes, tuple[int, int]]:
    """The MP4 boxes between ``start`` and ``end``: type -> (payload start, box end)."""
    found: dict[bytes, tuple[int, int]] = {}
    pos = start
    while pos + 8 <= end:
        size, kind = struct.unpack_from(">I4s", data, pos)
        header = 8
        if size == 1 and pos + 16 <= end:
            size = struct.unpack_from(">Q", data, pos + 8)[0]
            header = 16
        elif size == 0:
            size = end - pos
        if size < header:
            break
        found.setdefault(kind, (pos + header, min(pos + size, end)))
        pos += size
    return found


def mp4_creation_time(path: str | Path) -> float | None:
    """The ``mvhd`` creation time of an MP4/MOV file as Unix time, s; None when the file
    has none (not an MP4, no ``moov`` box, a zero or implausible time)."""
    path = Path(path)
    try:
        with path.open("rb") as fh:
            size = path.stat().st_size
            pos = 0
            while pos + 8 <= size:  # top-level boxes: seek over mdat, read only moov
                fh.seek(pos)
                head = fh.read(16)
                if len(head) < 8:
                    return None
                box, kind = struct.unpack_from(">I4s", head)
                header = 8
                if box == 1 and len(head) == 16:
                    box, header = struct.unpack_from(">Q", head, 8)[0], 16
                elif box == 0:
                    box = size - pos
                if box < header:
                    return None
                if kind == b"moov":
                    fh.seek(pos + header)
                    moov = fh.read(min(box - header, 1 << 24))
                    return _mvhd_time(moov)
                pos += box
    except OSError:
        return None
    return None


def _mvhd_time(moov: bytes) -> float | None:
    mvhd = _boxes(moov, 0, len(moov)).get(b"mvhd")
    if mvhd is None or mvhd[1] - mvhd[0] < 12:
        return None
    version = moov[mvhd[0]]
    if version == 1:
        created = struct.unpack_from(">Q", moov, mvhd[0] + 4)[0]
    else:
        created = struct.unpack_from(">I", moov, mvhd[0] + 4)[0]
    t = float(created) + _MP4_EPOCH_UNIX_S
    if not _PLAUSIBLE_SINCE_UNIX_S <= t <= time.time() + 86400.0:
        return None
    return t


@dataclass(frozen=True)
class VideoTime:
    """The Unix time of a camera's frame 0 by its own account, and the rule that gave it."""

    t_s: float
    rule: str


def video_file_time(path: str | Path, duration_s: float) -> VideoTime:
    """Frame 0 of a video file: the container's creation time when it has one, else the
    file's modification time minus ``duration_s`` (a camera closes the file at the end)."""
    created = mp4_creation_time(path)
    if created is not None:
        return VideoTime(created, "the container's creation time")
    mtime = Path(path).stat().st_mtime
    return VideoTime(
        mtime - duration_s, f"the file's modification time minus its duration ({duration_s:.2f} s)"
    )


# --- the plan ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class CameraClock:
    """The camera input as `plan_clocks` sees it."""

    name: str  #: for messages, e.g. "video drive.mp4"
    #: the camera's own times are ``start + rel``; this is the first ``rel``, s
    first_rel_s: float
    #: ``start`` when pinned (``--video-start``, Unix ``frames.csv``, a bag's stamps), s
    start_s: float | None
    own: VideoTime  #: the camera's own Unix time of frame 0, for a drive without Unix clock
    flag: str = "--video-start"  #: the option that pins it


@dataclass(frozen=True)
class LogClock:
    """A time-stamped log (CAN log, IMU CSV, ...) as `plan_clocks` sees it."""

    name: str  #: for messages, e.g. "CAN log drive.blf"
    first_s: float  #: its first time stamp as stored, s
    offset_s: float | None  #: explicit offset added to its stamps; None: not given
    flag: str  #: the option that gives the offset, e.g. "--can-offset"


@dataclass(frozen=True)
class ClockPlan:
    """Where every input lands on the drive's clock."""

    camera_start_s: float  #: added to the camera's own times
    offsets_s: dict[str, float]  #: log name -> offset added to its stamps
    notes: list[str] = field(default_factory=list)  #: the rules used, for the log
    #: inputs that land far from frame 0 (a wrong offset or another drive), for the log
    warnings: list[str] = field(default_factory=list)


def _mixed(a_name: str, a_first: float, b_name: str, b_first: float, flag: str) -> InputDataError:
    return InputDataError(
        f"mixed clocks: {a_name} starts at {a_first:.6f} s ({clock_kind(a_first)}) but"
        f" {b_name} starts at {b_first:.6f} s ({clock_kind(b_first)}); give {flag} SECONDS"
        f" (added to {b_name}'s time stamps) to put both on one clock"
    )


def plan_clocks(camera: CameraClock, logs: Sequence[LogClock]) -> ClockPlan:
    """The drive's clock from first time stamps (module docstring); raises
    `InputDataError` for mixed clocks."""
    names = [lg.name for lg in logs]
    if len(set(names)) != len(names):
        raise InputDataError(f"the same input is given twice: {names}")
    # (name, first stamp on the common clock, flag, is a log)
    fixed: list[tuple[str, float, str, bool]] = []
    if camera.start_s is not None:
        fixed.append((camera.name, camera.start_s + camera.first_rel_s, camera.flag, False))
    floating: list[LogClock] = []
    for lg in logs:
        if lg.offset_s is not None:
            fixed.append((lg.name, lg.first_s + lg.offset_s, lg.flag, True))
        elif is_unix_time(lg.first_s):
            fixed.append((lg.name, lg.first_s, lg.flag, True))
        else:
            floating.append(lg)
    unix = [c for c in fixed if is_unix_time(c[1])]
    near0 = [c for c in fixed if not is_unix_time(c[1])]
    if unix and near0:
        u, r = unix[0], near0[0]
        raise _mixed(u[0], u[1], r[0], r[1], r[2])
    unix_logs = [c for c in unix if c[3]]
    if unix_logs and floating:
        u, f = unix_logs[0], floating[0]
        raise _mixed(u[0], u[1], f.name, f.first_s, f.flag)

    notes: list[str] = []
    as_recorded = [lg for lg in logs if is_unix_time(lg.first_s)]
    shifted_unix = [c for c in unix_logs if c[0] not in {lg.name for lg in as_recorded}]
    if camera.start_s is not None:
        start = camera.start_s
        notes.append(f"{camera.name}: frame 0 at {start + camera.first_rel_s:.6f} s (pinned)")
    elif as_recorded:
        # the camera starts with the log, as recorded: an offset given to that log then
        # shifts it against the camera
        start = as_recorded[0].first_s - camera.first_rel_s
        notes.append(
            f"{camera.name}: frame 0 at the first sample of {as_recorded[0].name} as recorded"
            f" ({as_recorded[0].first_s:.6f} s; {camera.flag} overrides)"
        )
    elif shifted_unix:
        start = shifted_unix[0][1] - camera.first_rel_s
        notes.append(
            f"{camera.name}: frame 0 at the first sample of {shifted_unix[0][0]}"
            f" ({shifted_unix[0][1]:.6f} s)"
        )
    else:
        start = 0.0  # the camera's own clock; logs given an offset are on it
    shift = 0.0
    if not is_unix_time(start + camera.first_rel_s):
        # no Unix clock anywhere: move the whole drive so that frame 0 is at the camera's
        # own time (outputs need Unix times; relative alignment is kept)
        shift = camera.own.t_s - (start + camera.first_rel_s)
        moved = f": no log is on Unix time, every clock moved by {shift:+.6f} s" if logs else ""
        notes.append(f"{camera.name}: frame 0 at {camera.own.t_s:.6f} s ({camera.own.rule}){moved}")
    camera_start = start + shift
    frame0 = camera_start + camera.first_rel_s
    offsets: dict[str, float] = {}
    warnings: list[str] = []
    for lg in logs:
        if lg in floating:
            offsets[lg.name] = frame0 - lg.first_s
            notes.append(
                f"{lg.name}: its clock starts near 0 ({lg.first_s:.6f} s); its first sample is"
                f" put at frame 0 (coarse; {lg.flag} SECONDS overrides)"
            )
        else:
            offsets[lg.name] = (lg.offset_s or 0.0) + shift
        gap = lg.first_s + offsets[lg.name] - frame0
        if abs(gap) > FAR_FROM_FRAME0_S:
            warnings.append(
                f"{lg.name} starts {gap:+.1f} s from the camera's first frame: check its"
                f" clock ({lg.flag})"
            )
    return ClockPlan(camera_start, offsets, notes, warnings)


__all__ = [
    "UNIX_MIN_S",
    "CameraClock",
    "ClockPlan",
    "LogClock",
    "VideoTime",
    "clock_kind",
    "is_unix_time",
    "mp4_creation_time",
    "plan_clocks",
    "video_file_time",
]
