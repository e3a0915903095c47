"""``roadpreview bench vision``: ms per frame of each part of the vision step.

A short simulated drive (the ``demo`` preset: lead 9-14 m ahead, rough road,
oncoming traffic) is rendered at 640x360, 1280x720 and 1920x1080, then the
front end with the built-in motion finder processes it; the front end times
each part with ``time.perf_counter`` (given to it as its clock). Reported per
size: the median over repeats of the per-part mean ms per frame (finder
amortised over all frames, lead tracker, background tracker, total), the
distribution of the total per frame (median, 95th and 99th percentiles, max:
what decides whether a live camera's frames are dropped), the finder's cost on
the frames where it works (a slice of a run spread over frames), and the frames
whose lead box holds the true lead's rear centre.
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
) -> tuple[CameraModel, list[np.ndarray], np.ndarray, np.ndarray]:
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
    return rec.camera, frames, rec.truth["frame_t_s"], rec.truth["lead_rear_px"]


def run(repeats: int | None = None, quick: bool = False, seed: int = 0) -> str:
    from roadpreview.vision.frontend import VisionConfig, VisionFrontEnd

    repeats = repeats or (1 if quick else 3)
    seconds = 2.0 if quick else 4.0
    sizes = SIZES[:2] if quick else SIZES
    rows: list[list[str]] = []
    with tempfile.TemporaryDirectory() as tmp:
        for w, h in sizes:
            camera, frames, t, rear = _render(w, h, seconds, seed, Path(tmp))
            parts: dict[str, list[float]] = {
                k: [] for k in ("finder", "lead", "background", "total")
            }
            dist: dict[str, list[float]] = {k: [] for k in ("p50", "p95", "p99", "max")}
            per_run: list[float] = []
            found = 0
            for _ in range(repeats):
                fe = VisionFrontEnd(camera, VisionConfig(), clock=time.perf_counter)
                outs = [fe.process(float(t[i]), f) for i, f in enumerate(frames)]
                timed = outs[1:]  # the first frame only initialises
                for k in parts:
                    parts[k].append(statistics.fmean(o.timings_ms[k] for o in timed))
                total = np.array([o.timings_ms["total"] for o in timed])
                for k, q in (("p50", 50), ("p95", 95), ("p99", 99)):
                    dist[k].append(float(np.percentile(total, q)))
                dist["max"].append(float(total.max()))
                per_run += [o.timings_ms["finder"] for o in timed if o.finder_ran]
                found = sum(_holds_rear(o.lead.box, rear[i]) for i, o in enumerate(outs))
            med = {k: statistics.median(v) for k, v in parts.items()}
            qs = {k: statistics.median(v) for k, v in dist.items()}
            rows.append(
                [
                    f"{w}x{h}",
                    f"{med['finder']:.2f}",
                    f"{statistics.median(per_run) if per_run else float('nan'):.2f}",
                    f"{med['lead']:.2f}",
                    f"{med['background']:.2f}",
                    f"{med['total']:.2f}",
                    f"{qs['p50']:.1f}",
                    f"{qs['p95']:.1f}",
                    f"{qs['p99']:.1f}",
                    f"{qs['max']:.1f}",
                    f"{found}/{len(frames)}",
                ]
            )
    cfg = VisionConfig()
    head = (
        f"roadpreview bench vision: simulated 'demo' drive, {len(frames)} frames per size, "
        f"motion finder every {cfg.redetect_s:g} s spread over {cfg.finder_spread_s:g} s, "
        f"{repeats} repeat(s); ms per frame (per-part means, total per frame: median, p95, "
        "p99, max; median over repeats); 'finder/slice': on the frames where the finder "
        "works; 'lead found': lead box holds the true rear centre"
    )
    table = format_table(
        [
            "size",
            "finder",
            "finder/slice",
            "lead",
            "background",
            "total",
            "p50",
            "p95",
            "p99",
            "max",
            "lead found",
        ],
        rows,
    )
    return "\n".join([head, "", table])


def _holds_rear(box: tuple[float, float, float, float] | None, rear: np.ndarray) -> bool:
    if box is None:
        return False
    return bool(box[0] <= rear[0] <= box[2] and box[1] <= rear[1] <= box[3])
