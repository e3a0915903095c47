"""The finder's cost per frame: the motion finder's run is spread over frames (slices),
and its fast paths give the numbers of the plain ones.

The schedule must depend only on the frames' time stamps, never on the time the work
takes (replay and daemon give the same results: a slow finder is slow on an injected
clock, not by sleeping); a detection of the tracked lead found on an earlier frame is
moved with the lead before it is used; a cut-in is still caught after two finder runs.
"""

from __future__ import annotations

import warnings
from collections.abc import Generator
from dataclasses import asdict

import cv2
import numpy as np
import pytest

from roadpreview.camera import CameraModel
from roadpreview.vision.base import U8, Detection, FrameContext
from roadpreview.vision.frontend import FrameVision, VisionConfig, VisionFrontEnd
from roadpreview.vision.motion import MotionFinderConfig, RearFitConfig, RearSearch, fit_rear
from roadpreview.vision.motion.window import masked_median

CAM = CameraModel.from_fov(320, 180, 54.0)
LEAD = (130.0, 70.0, 190.0, 120.0)  # spans the centre column, bottom below the horizon
CUT_IN = (110.0, 80.0, 210.0, 130.0)  # spans it too and is nearer (lower bottom, 5.6 m)


def _texture(seed: int = 0, width: int = 400) -> np.ndarray:
    rng = np.random.default_rng(seed)
    noise = rng.integers(0, 255, (180, width)).astype(np.uint8)
    grey = cv2.GaussianBlur(noise, (5, 5), 1.0)  # LK-friendly texture
    return np.asarray(cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR), np.uint8)


class Stopwatch:
    """A clock for the front end's profiling that moves only when told (``t``, s)."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


class ScriptedFinder:
    """A sliced finder (three slices, like the motion finder) with scripted detections;
    records which frame each slice ran on, and may be slow: each of its slices takes
    ``slice_s`` of ``clock``."""

    name = "scripted"

    def __init__(
        self,
        script: dict[int, list[Detection]],
        slice_s: float = 0.0,
        clock: Stopwatch | None = None,
    ) -> None:
        self.script = script  # start frame index -> detections (else the last entry before)
        self.slice_s = slice_s
        self.clock = clock or Stopwatch()
        self.last_reason = ""
        self.slices: list[tuple[int, int]] = []  # (start frame, slice 1..3)
        self.current = 0

    def _detections(self, index: int) -> list[Detection]:
        keys = [k for k in self.script if k <= index]
        return list(self.script[max(keys)]) if keys else []

    def find(self, frame_bgr: U8, context: FrameContext | None = None) -> list[Detection]:
        assert context is not None
        self.slices.append((context.index, 0))
        return self._detections(context.index)

    def find_steps(
        self, frame_bgr: U8, context: FrameContext | None = None
    ) -> Generator[None, None, list[Detection]]:
        assert context is not None
        start = context.index
        for k in (1, 2):
            self.slices.append((start, k))
            self.clock.t += self.slice_s
            yield
        self.slices.append((start, 3))
        return self._detections(start)

    def observe(self, frame_bgr: U8, context: FrameContext | None = None) -> None:
        pass

    def reset(self) -> None:
        pass


def _run(
    finder: ScriptedFinder, frames: list[np.ndarray], fps: float, **config: object
) -> list[FrameVision]:
    cfg = VisionConfig(**config)  # type: ignore[arg-type]
    fe = VisionFrontEnd(CAM, cfg, finder=finder, clock=finder.clock)
    return [fe.process(i / fps, f) for i, f in enumerate(frames)]


def test_a_run_is_spread_over_three_frames_at_30_fps_and_one_at_10_fps() -> None:
    img = _texture()[:, :320]
    script = {0: [Detection(LEAD, 0.9, "vehicle")]}
    f30 = ScriptedFinder(script)
    outs = _run(f30, [img] * 30, 30.0)
    # frame 0 has no frame interval: the whole run at once; then every 0.3 s (9 frames),
    # one slice per frame, the detections handed over on the third with their frame
    assert f30.slices[0] == (0, 0)
    assert f30.slices[1:7] == [(9, 1), (9, 2), (9, 3), (18, 1), (18, 2), (18, 3)]
    handed = [(o.index, o.detected_index) for o in outs if o.detected_index is not None]
    assert handed == [(0, 0), (11, 9), (20, 18), (29, 27)]
    assert [o.index for o in outs if o.finder_ran] == [0, 9, 10, 11, 18, 19, 20, 27, 28, 29]
    assert all(o.lead for o in outs)
    # 10 frames per second: the next frame is 0.1 s away, the run is done in its frame
    f10 = ScriptedFinder(script)
    outs = _run(f10, [img] * 10, 10.0)
    assert [(o.index, o.detected_index) for o in outs if o.detected_index is not None] == [
        (0, 0),
        (3, 3),
        (6, 6),
        (9, 9),
    ]
    # no spreading asked: every run in one frame
    f0 = ScriptedFinder(script)
    outs = _run(f0, [img] * 12, 30.0, finder_spread_s=0.0)
    assert [o.detected_index for o in outs if o.detected_index is not None] == [0, 9]


def test_the_schedule_does_not_depend_on_the_time_taken() -> None:
    frames = [_texture()[:, k : k + 320] for k in range(0, 40, 2)]
    script = {0: [Detection(LEAD, 0.9, "vehicle")]}
    fast = _run(ScriptedFinder(script), frames, 30.0)
    slow = _run(ScriptedFinder(script, slice_s=0.02), frames, 30.0)  # slices of 20 ms
    # the slow finder's first two slices of a run took 20 ms each on the front end's
    # clock (the whole first run and the last slices no time) ...
    finder_ms = [o.timings_ms["finder"] for o in slow if o.finder_ran]
    assert finder_ms == pytest.approx([0.0, 20.0, 20.0, 0.0, 20.0, 20.0])
    assert max(o.timings_ms["finder"] for o in fast) == 0.0
    # ... and the schedule is the fast finder's
    assert [(o.index, o.detected_index, o.finder_ran) for o in fast] == [
        (o.index, o.detected_index, o.finder_ran) for o in slow
    ]
    assert [o.lead.y for o in fast] == [o.lead.y for o in slow]
    assert [o.lead.box for o in fast] == [o.lead.box for o in slow]


def test_a_detection_of_the_lead_from_an_earlier_frame_is_moved_with_it() -> None:
    # the scene moves 2 px left per frame; the finder reports the lead where it was on
    # the frame its run started, and that box is used two frames later
    wide = _texture(width=420)
    frames = [wide[:, 2 * k : 2 * k + 320] for k in range(40)]

    def at(k: int) -> tuple[float, float, float, float]:
        return (LEAD[0] - 2 * k, LEAD[1], LEAD[2] - 2 * k, LEAD[3])

    script = {k: [Detection(at(k), 0.9, "vehicle")] for k in range(40)}
    outs = _run(ScriptedFinder(script), frames, 30.0)
    for o in outs:
        assert o.lead
        k = o.index
        assert o.lead.box is not None
        assert o.lead.box[0] == pytest.approx(at(k)[0], abs=0.3), (k, o.lead.box)
        assert o.lead.box[2] == pytest.approx(at(k)[2], abs=0.3), (k, o.lead.box)
        if o.detected_index is not None and o.detected_index != k:
            # the detection itself still says where the lead was 2 frames earlier
            assert o.detections[0].box[0] == pytest.approx(at(k - 2)[0])
    assert len({o.lead.track_id for o in outs}) == 1


def test_a_cut_in_is_caught_after_two_runs() -> None:
    img = _texture()[:, :320]
    lead = Detection(LEAD, 0.9, "vehicle")
    script = {0: [lead], 9: [lead, Detection(CUT_IN, 0.9, "vehicle")]}
    outs = _run(ScriptedFinder(script), [img] * 30, 30.0)
    changed = [o.index for o in outs if o.lead.target_changed]
    # seen by the runs started at frames 9 and 18, confirmed when the second is handed
    # over (frame 20): 2 redetect_s + 2 frames after the first run that saw it
    assert changed == [0, 20]
    assert outs[20].lead.box == pytest.approx(CUT_IN)
    assert outs[19].lead.box == pytest.approx(LEAD, abs=0.5)


# -- the fast paths give the numbers of the plain ones ------------------------------------
def _fit_rear_plain(
    img: U8, rough: tuple[float, float, float, float], **kw: float
) -> tuple[tuple[float, ...], float, float, float] | None:
    """The rear fit scored all at once over the whole image (the first implementation)."""
    h, w = img.shape
    x0, y0, x1, y1 = rough
    rw = max(x1 - x0, 4.0)
    xc0 = 0.5 * (x0 + x1)
    v_h = kw["v_horizon"]
    yb_lo = int(max(v_h + 2.0, y0 + 0.3 * (y1 - y0)))
    yb_hi = int(min(h - 1, y1 + kw["rows_below"] * rw))
    if yb_hi - yb_lo < 1:
        return None
    ys = np.arange(yb_lo, yb_hi + 1)
    d_c = kw["f"] * kw["height_m"] / np.maximum(ys - v_h, 1.0)
    u = np.linspace(0.0, 1.0, 24)
    wid = (kw["f"] * kw["min_width_m"] / d_c)[:, None] * (
        kw["max_width_m"] / kw["min_width_m"]
    ) ** u[None, :]
    wid = np.minimum(wid, 0.95 * w)
    shift = kw["centre_shift"] * rw
    cs = xc0 + np.arange(-shift, shift + 0.5, max(1.0, shift / 30.0))
    sm = cv2.GaussianBlur(img, (3, 3), 0)
    gx = cv2.dilate(np.abs(cv2.Sobel(sm, cv2.CV_32F, 1, 0, ksize=3)), np.ones((1, 3), np.uint8))
    gy = cv2.dilate(cv2.Sobel(sm, cv2.CV_32F, 0, 1, ksize=3), np.ones((3, 1), np.uint8))
    col = np.zeros((h + 1, w))
    np.cumsum(gx, axis=0, out=col[1:])
    row = np.zeros((h, w + 1))
    np.cumsum(gy, axis=1, out=row[:, 1:])
    sx = float(np.mean(gx[int(max(v_h, 0)) :, :])) + 1e-6
    sy = float(np.mean(np.abs(gy[int(max(v_h, 0)) :, :]))) + 1e-6
    Y, Wd, C = ys[:, None, None], wid[:, :, None], cs[None, None, :]
    xl = np.round(C - 0.5 * Wd).astype(np.int64)
    xr = np.round(C + 0.5 * Wd).astype(np.int64)
    ok = (xl >= 1) & (xr <= w - 2)
    xl, xr = np.clip(xl, 0, w - 1), np.clip(xr, 0, w - 1)
    r1 = np.broadcast_to(np.clip(np.round(Y - 0.15 * Wd).astype(np.int64) + 1, 1, h), xl.shape)
    r0 = np.broadcast_to(
        np.clip(np.round(Y - kw["aspect"] * Wd).astype(np.int64), 0, h - 1), xl.shape
    )
    n_r = np.maximum(r1 - r0, 1)
    edge = np.minimum((col[r1, xl] - col[r0, xl]) / n_r, (col[r1, xr] - col[r0, xr]) / n_r) / sx
    ia = np.clip(np.round(C - 0.4 * Wd).astype(np.int64), 0, w - 1)
    ib = np.maximum(np.clip(np.round(C + 0.4 * Wd).astype(np.int64), 1, w), ia + 1)
    yb = np.broadcast_to(Y, xl.shape)
    bottom = (row[yb, ib] - row[yb, ia]) / (ib - ia) / sy
    bottom = np.where(yb >= h - 2, 0.0, np.maximum(bottom, 0.0))
    score = np.where(ok, edge + bottom, -np.inf)
    best = score.reshape(score.shape[0], -1).max(axis=1)
    if not np.isfinite(best.max()):
        return None
    i = int(np.nonzero(best >= 0.7 * best.max())[0][-1])
    j, m = np.unravel_index(int(np.argmax(score[i])), score.shape[1:])
    ww, xc, yy = float(wid[i, j]), float(cs[m]), float(ys[i])
    box = (xc - 0.5 * ww, yy - 0.8 * ww, xc + 0.5 * ww, yy)
    return box, float(score[i, j, m]), float(edge[i, j, m]), float(bottom[i, j, m])


def _car_scene(seed: int) -> tuple[U8, tuple[float, float, float, float]]:
    rng = np.random.default_rng(seed)
    noise = rng.integers(60, 140, (360, 640)).astype(np.uint8)
    img = np.asarray(cv2.GaussianBlur(noise, (0, 0), 2.0), np.uint8)
    x0, y1 = int(rng.integers(200, 380)), int(rng.integers(230, 330))
    wd = int(rng.integers(40, 140))
    img[y1 - int(0.8 * wd) : y1, x0 : x0 + wd] = rng.integers(20, 60)  # a dark rear
    img[y1 : y1 + 4, x0 : x0 + wd] = 10  # its shadow
    jit = rng.normal(0.0, 0.1 * wd, 4)
    rough = (x0 + jit[0], y1 - 0.6 * wd + jit[1], x0 + wd + jit[2], y1 - 0.2 * wd + jit[3])
    return img, rough


@pytest.mark.parametrize("seed", range(8))
def test_rear_search_gives_the_plain_scoring_in_any_slicing(seed: int) -> None:
    img, rough = _car_scene(seed)
    geometry = dict(v_horizon=179.5, f=353.0, height_m=1.3)
    config = RearFitConfig()  # the plain scoring has its defaults built in
    plain = _fit_rear_plain(img, rough, **geometry, **asdict(config))
    fit = fit_rear(img, rough, **geometry, config=config)
    assert plain is not None
    assert fit is not None
    assert fit.box == plain[0]  # the same numbers, not just close ones
    assert (fit.score, fit.edge, fit.bottom) == plain[1:]
    search = RearSearch(img, rough, **geometry, config=config)
    while not search.done:
        assert search.result() is None  # rows left: no answer yet
        search.score_rows(7)
    assert search.result() == fit


def test_masked_median_is_nanmedian_of_the_members() -> None:
    rng = np.random.default_rng(1)
    for _ in range(300):
        n = int(rng.integers(0, 30))
        values = rng.normal(size=n) * 10.0 ** rng.integers(-4, 3)
        values[rng.random(n) < 0.2] = 0.25  # ties
        member = rng.random((5, 3, n)) < rng.random()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN windows
            expected = np.nanmedian(np.where(member, values, np.nan), axis=2)
        if n == 0:
            expected = np.full((5, 3), np.nan)
        assert np.array_equal(masked_median(values, member), expected, equal_nan=True)


def test_the_finder_builds_its_rear_fit_settings_from_its_config() -> None:
    assert MotionFinderConfig().rear_fit() == RearFitConfig()  # the same defaults
    cfg = MotionFinderConfig(rear_min_width_m=1.2, rear_edge_aspect=0.6, rear_rows_below=1.0)
    assert cfg.rear_fit() == RearFitConfig(min_width_m=1.2, aspect=0.6, rows_below=1.0)
