"""``roadpreview bench vision``: ms per frame of each part of the vision step.

A short simulated drive (the ``demo`` preset: lead 9-14 m ahead, rough road,
oncoming traffic) is rendered at 640x360, 1280x720 and 1920x1080, then the
front end with the built-in motion finder processes it; the front end times
each part with ``time.perf_counter`` (given to it as its clock). Reported per
size: the median over repeats of the per-part mean ms per frame (finder
amortised over all frames, lead tracker, background tracker, total), the 95th
percentile of the total, and the finder's cost on the frames where it runs.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from roadpreview.bench._timing import format_table
from roadpreview.camera import CameraModel

SIZES = ((640, 360), (1280, 720), (1920, 1080))


def _render(
    width: int, height: int, seconds: float, seed: int, folder: Path
) -> tuple[CameraModel, list[np.ndarray], np.ndarray]:
    from roadpreview.sim.dataset import drive_config
    from roadpreview.sim.recording import Recording, write_recording

    cfg = drive_config("demo", seed, duration_s=seconds, width=width, height=height)
    cfg = replace(cfg, output=replace(cfg.output, can_formats=[], imu_csv=False))
    out = folder / f"demo_{width}x{height}"
    write_recording(cfg, out)
    rec = Recording.open(out)
    cap = cv2.VideoCapture(str(rec.video))
    frames: list[np.ndarray] = []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        frames.append(frame)
    cap.release()
    return rec.camera, frames, rec.truth["frame_t_s"]


def run(repeats: int | None = None, quick: bool = False, seed: int = 0) -> str:
    from roadpreview.vision.frontend import VisionConfig, VisionFrontEnd

    repeats = repeats or (1 if quick else 3)
    seconds = 2.0 if quick else 4.0
    sizes = SIZES[:2] if quick else SIZES
    rows: list[list[str]] = []
    with tempfile.TemporaryDirectory() as tmp:
        for w, h in sizes:
            camera, frames, t = _render(w, h, seconds, seed, Path(tmp))
            parts: dict[str, list[float]] = {
                k: [] for k in ("finder", "lead", "background", "total")
            }
            p95: list[float] = []
            per_run: list[float] = []
            found = 0
            for _ in range(repeats):
                fe = VisionFrontEnd(camera, VisionConfig(), clock=time.perf_counter)
                outs = [fe.process(float(t[i]), f) for i, f in enumerate(frames)]
                timed = outs[1:]  # the first frame only initialises
                for k in parts:
                    parts[k].append(statistics.fmean(o.timings_ms[k] for o in timed))
                p95.append(float(np.percentile([o.timings_ms["total"] for o in timed], 95)))
                per_run += [o.timings_ms["finder"] for o in timed if o.finder_ran]
                found = sum(bool(o.lead) for o in outs)
            med = {k: statistics.median(v) for k, v in parts.items()}
            rows.append(
                [
                    f"{w}x{h}",
                    f"{med['finder']:.2f}",
                    f"{statistics.median(per_run) if per_run else float('nan'):.2f}",
                    f"{med['lead']:.2f}",
                    f"{med['background']:.2f}",
                    f"{med['total']:.2f}",
                    f"{statistics.median(p95):.2f}",
                    f"{found}/{len(frames)}",
                ]
            )
    head = (
        f"roadpreview bench vision: simulated 'demo' drive, {len(frames)} frames per size, "
        f"motion finder every {VisionConfig().redetect_s:g} s, {repeats} repeat(s); "
        "ms per frame (median over repeats "
        "of the per-frame mean); budget 12 ms at 1280x720 on 2 cores"
    )
    table = format_table(
        ["size", "finder", "finder/run", "lead", "background", "total", "total p95", "lead found"],
        rows,
    )
    return "\n".join([head, "", table])
