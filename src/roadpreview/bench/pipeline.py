"""``roadpreview bench pipeline``: end-to-end replay frames per second beside decode-only.

A simulated ``demo`` drive is written at 1280x720 and 1920x1080 (video, CAN
log, truth). For each size, in the same run: the decode-only speed of the
video (``cv2.VideoCapture.grab`` + ``retrieve`` over every frame) and the
end-to-end replay (decode + vision + pitch + fusion + detector + CAN encode,
no files written), medians over repeats, and their ratio.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import cv2

from roadpreview.bench._timing import format_table, package_logs_at_errors

SIZES = ((1280, 720), (1920, 1080))


def _decode_only(video: Path) -> tuple[float, int]:
    cap = cv2.VideoCapture(str(video))
    n = 0
    t0 = time.perf_counter()
    while cap.grab():
        cap.retrieve()
        n += 1
    dt = time.perf_counter() - t0
    cap.release()
    return dt, n


def run(repeats: int | None = None, quick: bool = False, seed: int = 0) -> str:
    from roadpreview.apps.replay import ReplayInputs, replay
    from roadpreview.sim.dataset import drive_config
    from roadpreview.sim.recording import write_recording

    repeats = repeats or (1 if quick else 3)
    seconds = 4.0 if quick else 10.0
    rows: list[list[str]] = []
    with package_logs_at_errors(), tempfile.TemporaryDirectory() as tmp:
        for w, h in SIZES:
            cfg = drive_config("demo", seed, duration_s=seconds, width=w, height=h)
            cfg = replace(cfg, output=replace(cfg.output, imu_csv=False))
            folder = Path(tmp) / f"demo_{w}x{h}"
            write_recording(cfg, folder)
            decode, pipe = [], []
            n = 0
            for _ in range(repeats):
                dt, n = _decode_only(folder / "video.mp4")
                decode.append(n / dt)
                result = replay(ReplayInputs.from_recording(folder))
                pipe.append(result.fps)
            d, p = statistics.median(decode), statistics.median(pipe)
            rows.append(
                [
                    f"{w}x{h}",
                    str(n),
                    f"{d:.1f}",
                    f"{p:.1f}",
                    f"{p / d:.2f}",
                    "yes" if p >= 30.0 else "no",
                ]
            )
    head = (
        f"roadpreview bench pipeline: simulated 'demo' drive, {seconds:.0f} s per size, "
        f"median of {repeats} repeat(s); replay = decode + vision + pitch + fusion + detector"
    )
    table = format_table(
        ["size", "frames", "decode-only fps", "pipeline fps", "pipeline/decode", ">= 30 fps"],
        rows,
    )
    return f"{head}\n\n{table}"
