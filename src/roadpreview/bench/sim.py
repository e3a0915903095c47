"""``roadpreview bench sim``: frames per second of the simulator's renderer.

Renders a short drive (ego at 15 m/s with a pitching camera, a bouncing lead
15 m ahead, an oncoming car passing and a car in the oncoming lane ahead, the
roadside of `generate_scene`) at 640x360 and 1280x720, clear and in fog, and
prints the median over repeats of the frame rate of each whole sequence. Scene
generation and renderer set-up (textures, one-off) are timed separately.
"""

from __future__ import annotations

import math
import statistics
import time

import cv2
import numpy as np

from roadpreview.camera import CameraModel
from roadpreview.sim.render import RenderConfig, SceneRenderer
from roadpreview.sim.scene import SceneConfig, generate_scene
from roadpreview.sim.types import CameraPose, Conditions, VehiclePose, VehicleShape

FPS = 30.0
SPEED = 15.0  # m/s


def _frame(k: int) -> tuple[CameraPose, list[VehiclePose], float]:
    """Camera pose, vehicles and camera pitch rate of frame k of the benchmark drive."""
    t = k / FPS
    x = 20.0 + SPEED * t
    w = 2 * math.pi * 1.3  # body pitch mode ~1.3 Hz
    pitch = 0.004 * math.sin(w * t)
    cam = CameraPose(x, 0.0, 1.3 + 0.005 * math.sin(w * t + 1.0), pitch)
    shape = VehicleShape()
    lead_x = x + 15.0 + shape.cg_to_rear_m
    vehicles = [
        VehiclePose(
            1,
            lead_x,
            0.0,
            shape.cg_height_m + 0.02 * math.sin(9.0 * t),
            0.01 * math.sin(9.0 * t),
            0.0,
            0.0,
            shape,
            appearance=3,
            is_lead=True,
        ),
        VehiclePose(2, x + 60.0 - 2 * SPEED * t, 3.5, shape.cg_height_m, 0, 0, math.pi, shape, 8),
        VehiclePose(
            3,
            x + 45.0 + 2.0 * t,
            3.5,
            shape.cg_height_m,
            0,
            0,
            0.0,
            VehicleShape(length_m=5.2, height_m=1.9),
            11,
        ),
    ]
    return cam, vehicles, 0.004 * w * math.cos(w * t)


def run(repeats: int | None = None, quick: bool = False, seed: int = 0) -> str:
    """Time the renderer; return the table that ``roadpreview bench sim`` prints."""
    repeats = repeats or (2 if quick else 5)
    n_frames = 10 if quick else 30
    t0 = time.perf_counter()
    scene = generate_scene(SceneConfig(), seed=seed, length_m=200.0 + SPEED * n_frames / FPS)
    t_scene = time.perf_counter() - t0
    cases = [("clear", Conditions()), ("fog V=60 m", Conditions(fog_density_per_m=0.05))]
    if not quick:
        cases += [("night", Conditions(light=0.001)), ("tunnel", Conditions(tunnel=True))]
    sizes = [(640, 360), (1280, 720)]
    lines = [
        f"bench sim: renderer frames per second, {n_frames} moving frames per sequence, "
        f"median of {repeats} repeats (seed {seed}, OpenCV threads {cv2.getNumThreads()})",
        f"scene generation (once): {t_scene:.2f} s",
        "",
        f"{'size':>10}  {'conditions':<12} {'setup s':>8} {'ms/frame':>9} {'fps':>7}"
        f" {'fps min..max':>14}",
    ]
    for w, h in sizes:
        camera = CameraModel.from_fov(w, h, 45.0)
        t0 = time.perf_counter()
        renderer = SceneRenderer(camera, scene, RenderConfig())
        renderer.render(*_frame(0)[:2], Conditions(), np.random.default_rng(seed))  # warm-up
        t_setup = time.perf_counter() - t0
        for name, cond in cases:
            rates = []
            for rep in range(repeats):
                rng = np.random.default_rng(seed + rep)
                start = time.perf_counter()
                for k in range(n_frames):
                    cam, vehicles, rate = _frame(k)
                    renderer.render(cam, vehicles, cond, rng, pitch_rate_rad_s=rate)
                rates.append(n_frames / (time.perf_counter() - start))
            med = statistics.median(rates)
            lines.append(
                f"{f'{w}x{h}':>10}  {name:<12} {t_setup:8.2f} {1000.0 / med:9.1f} {med:7.1f} "
                f"{min(rates):6.1f}..{max(rates):<6.1f}"
            )
    return "\n".join(lines)
