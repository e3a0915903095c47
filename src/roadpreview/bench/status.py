"""``roadpreview bench status``: how steady RP_STATUS's 100 ms cycle is on the wall clock
while the daemon's input is hammered.

The daemon (`roadpreview.apps.daemon.Daemon`) runs as ``roadpreview run --can-log`` does:
python-can ``virtual`` buses, a small simulated drive's video as the camera (paced on the
wall clock), its CAN log played onto the input bus by `CanLogPlayer`. Two cases, each
``repeats`` times:

* **clean**: the drive as recorded;
* **burst**: 10,000 garbage frames (random ids and payloads) in one second from 1 s on,
  the fault of ``tests/faults/test_daemon_faults.py``, which holds the loop's thread up.

A receiver on the output bus takes every RP_STATUS whose E2E CRC and counter check out
(`OutputDecoder`: the burst's random identifiers hit 0x201 too) with its time stamp: the
moment it was sent on the wall clock (the daemon's stamp on the virtual bus, which keeps it, or the
bus's own ``time.time()``). The **jitter** of a period is ``|gap - period|`` between
consecutive RP_STATUS frames; the last frame of a run, the status the daemon sends once
more when it stops, is off the cycle and left out. Reported per case, pooled over the
repeats: the number of periods, the median, 99th percentile and largest jitter (ms), the
largest gap, and, for context, the loop's per-frame processing time (99th percentile)
and the camera frames it had to drop. Wall clock, so the figures depend on the machine's
load: this is a benchmark, not a test (the deterministic check of the schedule runs on
virtual time in ``tests/canbus/test_cyclic.py``).
"""

from __future__ import annotations

import random
import shutil
import tempfile
import threading
import time
import uuid
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from roadpreview.bench._timing import format_table, package_logs_at_errors

BURST_FRAMES = 10_000
BURST_AT_S = 1.0  #: seconds after the log's first frame
BURST_S = 1.0


@dataclass
class _Run:
    gaps_s: list[float]  #: between consecutive RP_STATUS frames (sender's wall clock)
    frame_ms_p99: float
    frames: int
    dropped: int


def _drive(root: Path, seconds: float) -> Path:
    """The simulated drive (rendered once; reused from ``root`` when there)."""
    from roadpreview.sim.dataset import drive_config
    from roadpreview.sim.recording import write_recording

    folder = root / f"controlled_320x180_{seconds:.0f}s_seed0"
    if not (folder / "truth.json").is_file():
        shutil.rmtree(folder, ignore_errors=True)
        cfg = drive_config("controlled", 0, duration_s=seconds, width=320, height=180)
        write_recording(cfg, folder)
    return folder


def _log(folder: Path, out: Path, *, burst: bool, seed: int) -> Path:
    """The drive's CAN log as a candump file, with the garbage burst in it if asked."""
    import can

    from roadpreview.canbus import read_can_log
    from roadpreview.canbus.logio import CanLogWriter
    from roadpreview.sim.recording import Recording

    frames = list(read_can_log(Recording.open(folder).can_log()))
    if burst:
        rng = random.Random(seed)
        t0 = frames[0].timestamp + BURST_AT_S
        frames += [
            can.Message(
                timestamp=t0 + k * BURST_S / BURST_FRAMES,
                arbitration_id=rng.randrange(0x800),
                data=bytes(rng.randrange(256) for _ in range(8)),
            )
            for k in range(BURST_FRAMES)
        ]
        frames.sort(key=lambda m: m.timestamp)
    path = out / ("burst.log" if burst else "clean.log")
    writer = CanLogWriter(path)
    for msg in frames:
        writer.write(msg)
    writer.close()
    return path


def _play(folder: Path, log_path: Path) -> _Run:
    """One daemon run over the drive with ``log_path`` played onto its input bus."""
    import can

    from roadpreview.apps.daemon import Daemon, DaemonOptions
    from roadpreview.canbus.live import open_bus
    from roadpreview.canbus.received import OutputDecoder, ReceivedStatus
    from roadpreview.pipeline.config import PipelineConfig
    from roadpreview.sim.recording import Recording

    rec = Recording.open(folder)
    cfg = PipelineConfig()
    channel = f"rp-bench-status-{uuid.uuid4().hex}"
    cfg = replace(cfg, can=replace(cfg.can, input_interface="virtual", input_channel=channel))
    options = DaemonOptions(
        camera_source=str(rec.video), can_log=log_path, video_start_s=rec.t0_unix_s
    )
    rx = open_bus("virtual", channel)
    reader = can.BufferedReader()
    notifier = can.Notifier(rx, [reader], timeout=0.02)
    daemon = Daemon(rec.camera, cfg, options)
    box = []
    thread = threading.Thread(target=lambda: box.append(daemon.run()), name="daemon")
    thread.start()
    thread.join(timeout=120.0)
    time.sleep(0.1)
    notifier.stop()
    rx.shutdown()
    if thread.is_alive() or not box:
        raise RuntimeError("the daemon did not finish")
    stamps = []
    decoder = OutputDecoder()
    while (msg := reader.get_message(timeout=0.0)) is not None:
        if isinstance(decoder.decode(msg), ReceivedStatus):
            stamps.append(float(msg.timestamp))
    summary = box[0]
    return _Run(
        gaps_s=list(np.diff(stamps[:-1])),  # the last: sent at close, off the cycle
        frame_ms_p99=summary.frame_ms.quantile(0.99),
        frames=summary.frames_processed,
        dropped=summary.frames_dropped,
    )


def run(
    repeats: int | None = None,
    quick: bool = False,
    seed: int = 0,
    *,
    cache: str | Path | None = None,
    seconds: float = 6.0,
) -> str:
    """Both cases ``repeats`` times (default 3, 1 with ``quick``); the table (module
    docstring)."""
    from roadpreview.pipeline.config import PipelineConfig

    repeats = repeats or (1 if quick else 3)
    period = PipelineConfig().can.status_period_s
    tmp = Path(tempfile.mkdtemp(prefix="rp-bench-status-"))
    try:
        folder = _drive(Path(cache) if cache is not None else tmp, seconds)
        logs = {c: _log(folder, tmp, burst=c == "burst", seed=seed) for c in ("clean", "burst")}
        runs: dict[str, list[_Run]] = {c: [] for c in logs}
        with package_logs_at_errors():
            for _ in range(repeats):
                for case, path in logs.items():
                    runs[case].append(_play(folder, path))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    rows = []
    for case, case_runs in runs.items():
        gaps = np.array([g for r in case_runs for g in r.gaps_s])
        jitter_ms = np.abs(gaps - period) * 1e3
        rows.append(
            [
                case,
                str(len(gaps)),
                f"{np.median(jitter_ms):.1f}",
                f"{np.percentile(jitter_ms, 99):.1f}",
                f"{jitter_ms.max():.1f}",
                f"{gaps.max() * 1e3:.0f}",
                f"{max(r.frame_ms_p99 for r in case_runs):.1f}",
                str(sum(r.dropped for r in case_runs)),
            ]
        )
    header = [
        "case",
        "periods",
        "jitter p50 ms",
        "jitter p99 ms",
        "jitter max ms",
        "max gap ms",
        "frame ms p99",
        "frames dropped",
    ]
    title = (
        f"RP_STATUS period ({period * 1e3:.0f} ms) on the wall clock, the daemon on virtual "
        f"buses, {seconds:.0f} s drive at 320x180, {repeats} run(s) per case; burst: "
        f"{BURST_FRAMES} garbage frames in {BURST_S:.0f} s"
    )
    return title + "\n" + format_table(header, rows)
