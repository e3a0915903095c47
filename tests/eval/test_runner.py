"""The evaluation's runner and clip scoring: the score window, the hard flag, one vision
pass shared by every method, and the trace cache."""

from __future__ import annotations

import json
import math
from dataclasses import astuple, replace
from pathlib import Path

import numpy as np
import pytest

from roadpreview.apps.replay import ReplayInputs, replay
from roadpreview.errors import ConfigError, OperationError
from roadpreview.eval.clips import (
    SCORE_WINDOW_S,
    Scores,
    background_windows,
    box_iou,
    clip_scores,
    hard_window,
    mean_abs_rate,
    window_max,
)
from roadpreview.eval.methods import METHODS, method_config, select_methods
from roadpreview.eval.runner import (
    MethodSet,
    RecordingJob,
    RecordingOutcome,
    load_traces,
    process_all,
    process_recording,
    run_methods,
)
from roadpreview.pipeline.config import PipelineConfig
from roadpreview.pipeline.pipeline import Pipeline
from roadpreview.sim.dataset import clips_of_recording
from roadpreview.sim.presets import controlled
from roadpreview.types import FusionMode


# -- clip scores ---------------------------------------------------------------------------------
def _trace(t: np.ndarray, s: np.ndarray) -> Scores:
    return Scores(t, s)


def test_window_max_takes_the_largest_s_in_the_window_and_skips_nan() -> None:
    t = np.arange(0.0, 10.0, 1 / 30)
    s = np.zeros_like(t)
    a, b = SCORE_WINDOW_S
    assert (a, b) == (-0.2, 1.2)
    s[np.argmin(np.abs(t - 5.0 - 1.1))] = 3.0  # inside [5 - 0.2, 5 + 1.2]
    s[np.argmin(np.abs(t - 5.0 - 1.4))] = 9.0  # after the window: not counted
    s[np.argmin(np.abs(t - 5.0 + 0.4))] = 8.0  # before the window: not counted
    s[np.argmin(np.abs(t - 5.0 - 0.5))] = np.nan  # no lead in one frame: skipped
    assert window_max(t, s, 5.0) == (3.0, True)
    # the same window for every clip, positive or not
    scores, found = clip_scores(_trace(t, s), [5.0, 2.0])
    np.testing.assert_array_equal(scores, [3.0, 0.0])
    np.testing.assert_array_equal(found, [True, True])
    # scores that describe other times than their frames' (the two-axle detector's
    # hypothesised crossings) need not be in time order: the same maximum
    order = np.random.default_rng(0).permutation(t.size)
    assert window_max(t[order], s[order], 5.0) == (3.0, True)


def test_a_window_without_any_s_scores_zero_and_says_no_lead() -> None:
    t = np.arange(0.0, 4.0, 1 / 30)
    s = np.full_like(t, np.nan)
    assert window_max(t, s, 2.0) == (0.0, False)
    # past the end of the recording
    assert window_max(t, np.zeros_like(t), 10.0) == (0.0, False)


def test_hard_window_covers_what_the_score_depends_on() -> None:
    # s at t_c + a uses y_c from t_c + a - 1 s (the detector window)
    assert hard_window((-0.2, 1.2)) == pytest.approx((-1.2, 1.2))


def _write_truth(folder: Path, events: list[dict[str, object]], duration_s: float) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    base = {
        "kind": "bump",
        "height_m": 0.05,
        "lead_distance_m": 15.0,
        "lead_side": "both",
        "hard": False,
    }
    full = [{**base, "index": i, **e} for i, e in enumerate(events)]
    (folder / "truth.json").write_text(json.dumps({"duration_s": duration_s, "events": full}))


def test_hard_flag_of_background_clips_and_ego_crossing_backgrounds(tmp_path: Path) -> None:
    events: list[dict[str, object]] = [
        # the lead hits it at 10 s, the ego 1.5 s later
        {"lead_front_t_s": 10.0, "ego_front_t_s": 11.5, "lead_hits": True, "ego_hits": True},
        # the lead hits it while the ego crosses another one: the paper's hard positive
        {
            "lead_front_t_s": 30.0,
            "ego_front_t_s": 31.0,
            "lead_hits": True,
            "ego_hits": True,
            "hard": True,
        },
        # the lead passes beside it, the ego hits it at 50 s: the ego pitches, no lead event
        {"lead_front_t_s": 48.0, "ego_front_t_s": 50.0, "lead_hits": False, "ego_hits": True},
        {"lead_front_t_s": 29.8, "ego_front_t_s": 30.2, "lead_hits": False, "ego_hits": True},
    ]
    _write_truth(tmp_path, events, duration_s=60.0)
    rng = np.random.default_rng(0)
    clips = clips_of_recording(
        tmp_path,
        "rec",
        rng,
        clip_half_s=2.5,
        clearance_s=2.0,
        background_per_positive=2.0,
        hard_window_s=hard_window(),
        ego_crossing_share=0.5,
        clear_of_hits_only=True,
    )
    pos = [c for c in clips if c.label]
    bg = [c for c in clips if not c.label]
    assert [(c.t_center_s, c.hard) for c in pos] == [(10.0, False), (30.0, True)]
    assert len(bg) == 4
    ego = [c for c in bg if c.kind == "ego-crossing"]
    # the ego crossing at 50 s is clear of the lead's hits (48 s is a miss); the others are
    # within the clearance of the lead's hits at 10 and 30 s
    assert [c.t_center_s for c in ego] == [50.0]
    ego_t = np.array([11.5, 31.0, 50.0, 30.2])
    lo, hi = hard_window()
    for c in bg:
        assert abs(c.t_center_s - 10.0) >= 2.0
        assert abs(c.t_center_s - 30.0) >= 2.0
        expected = bool(np.any((ego_t >= c.t_center_s + lo) & (ego_t <= c.t_center_s + hi)))
        assert c.hard == expected, c


def test_clips_of_recording_defaults_are_unchanged(tmp_path: Path) -> None:
    """Without the new options: no hard background, clearance from every lead crossing."""
    events: list[dict[str, object]] = [
        {"lead_front_t_s": 10.0, "ego_front_t_s": 11.5, "lead_hits": True, "ego_hits": True},
        {"lead_front_t_s": 20.0, "ego_front_t_s": 21.0, "lead_hits": False, "ego_hits": True},
    ]
    _write_truth(tmp_path, events, duration_s=40.0)
    clips = clips_of_recording(tmp_path, "rec", np.random.default_rng(3))
    again = clips_of_recording(tmp_path, "rec", np.random.default_rng(3))
    assert clips == again
    bg = [c for c in clips if not c.label]
    assert bg
    assert not any(c.hard for c in bg)
    assert all(c.kind == "" for c in bg)
    assert all(min(abs(c.t_center_s - 10.0), abs(c.t_center_s - 20.0)) >= 1.5 for c in bg)


def test_background_windows_keep_clear_of_the_lead_response() -> None:
    t = background_windows(30.0, [10.0, 20.0], step_s=0.5)
    assert t.size
    a, b = SCORE_WINDOW_S
    for tl in (10.0, 20.0):
        # the lead's response [tl - 0.3, tl + 1.0] never meets [t + a - 1, t + b]
        assert np.all((tl + 1.0 < t + a - 1.0) | (tl - 0.3 > t + b))
    assert 15.0 in t  # far from both


def test_mean_abs_rate_and_box_iou() -> None:
    t = np.arange(0.0, 3.0, 0.5)
    rate = np.array([1.0, -1.0, 2.0, -2.0, 3.0, -3.0])
    np.testing.assert_allclose(
        mean_abs_rate(t, rate, np.array([0.0, 1.0]), np.array([0.5, 2.0])), [1.0, 7.0 / 3.0]
    )
    a = np.array([[0.0, 0.0, 2.0, 2.0], [0.0, 0.0, 1.0, 1.0], [np.nan] * 4])
    b = np.array([[1.0, 0.0, 3.0, 2.0], [0.0, 0.0, 1.0, 1.0], [0.0, 0.0, 1.0, 1.0]])
    np.testing.assert_allclose(box_iou(a, b), [2.0 / 6.0, 1.0, 0.0])


# -- methods ------------------------------------------------------------------------------------
def test_method_configs_differ_only_in_the_strategy() -> None:
    base = PipelineConfig()
    cfgs = {m: method_config(base, s) for m, s in METHODS.items()}
    assert cfgs["fused-kalman"] == base  # the product default
    assert cfgs["uncompensated"].fusion.backend == "none"
    assert cfgs["essential"].pitch.estimator == "essential"
    assert cfgs["fused-fg"].fusion.backend == "factor-graph"
    for cfg in cfgs.values():
        assert cfg.vision == base.vision
        assert cfg.anomaly == base.anomaly
    if hasattr(base, "heave"):  # the paper's methods: eq. (4) only, no heave term
        for m in ("uncompensated", "essential", "visual", "imu-only"):
            assert not cfgs[m].heave.enabled, m
        assert cfgs["fused-fg"].heave == base.heave
    with pytest.raises(ConfigError, match="unknown"):
        select_methods(["nope"])


# -- the runner ---------------------------------------------------------------------------------
def test_every_method_gets_the_same_frames(make_recording) -> None:  # type: ignore[no-untyped-def]
    rec = make_recording("controlled", seed=0, duration_s=3.0, width=320, height=180)
    methods = MethodSet.build(PipelineConfig(), METHODS)
    traces = run_methods(rec.folder, methods)
    assert list(traces) == ["fused-kalman", *(m for m in METHODS if m != "fused-kalman")]
    t_ref = traces["fused-kalman"].t
    assert t_ref.size == rec.info["n_frames"]
    # the recording's clock: frame times as in frames.csv / truth.npz
    np.testing.assert_allclose(t_ref, rec.truth["frame_t_s"], atol=1e-5)
    for m, tr in traces.items():
        np.testing.assert_array_equal(tr.t, t_ref, err_msg=m)
        # one vision pass: the raw lead position is the same for every method
        np.testing.assert_array_equal(tr["y"], traces["fused-kalman"]["y"], err_msg=m)
    unc = traces["uncompensated"]
    np.testing.assert_array_equal(unc["phi"], 0.0)
    np.testing.assert_array_equal(unc["y_c"], unc["y"])
    assert set(np.unique(unc["mode"])) == {int(FusionMode.DEGRADED)}
    # the essential-matrix baseline does compensate (its NaN std is handled)
    ess = traces["essential"]
    assert np.nanmax(np.abs(ess["phi"])) > 0.0
    assert not np.all(ess["mode"] == int(FusionMode.DEGRADED))


def test_the_reference_trace_is_a_plain_replay(make_recording) -> None:  # type: ignore[no-untyped-def]
    """The evaluation runs the same loop as a replay: the fused-kalman trace equals the
    replay's per-frame results exactly (the other methods only add pipelines)."""
    rec = make_recording("controlled", seed=0, duration_s=3.0, width=320, height=180)
    methods = MethodSet.build(PipelineConfig(), select_methods(["uncompensated", "fused-kalman"]))
    trace = run_methods(rec.folder, methods)["fused-kalman"]
    inputs = ReplayInputs.from_recording(rec.folder)
    result = replay(inputs, methods.configs["fused-kalman"], keep_results=True)
    assert result.results is not None
    frames = result.results
    assert len(frames) == len(trace) == rec.info["n_frames"]
    t0 = result.video_start_s
    np.testing.assert_array_equal(trace.t, [r.t - t0 for r in frames])
    for col in ("y", "y_c", "phi", "phi_std", "lead_distance_m", "heave_px"):
        np.testing.assert_array_equal(trace[col], [getattr(r, col) for r in frames], err_msg=col)
    np.testing.assert_array_equal(trace["mode"], [int(r.mode) for r in frames])
    for a, b in zip(trace.samples(), frames, strict=True):  # the detector's input
        assert b.sample is not None
        np.testing.assert_equal(astuple(a), astuple(replace(b.sample, t=b.sample.t - t0)))


def test_traces_are_cached_and_reused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    cfg = controlled(0, gap_m=8.0)
    cfg = replace(
        cfg,
        motion=replace(cfg.motion, duration_s=2.0),
        camera=replace(cfg.camera, width=320, height=180),
    )
    job = RecordingJob("controlled", "short", cfg, tmp_path)
    methods = MethodSet.build(PipelineConfig(), select_methods(["uncompensated", "fused-kalman"]))
    built = []
    original = Pipeline.__init__

    def counting_init(self, *args, **kwargs):  # type: ignore[no-untyped-def]
        built.append(1)
        original(self, *args, **kwargs)

    monkeypatch.setattr(Pipeline, "__init__", counting_init)
    first = process_recording(job, methods)
    assert first.generate_s > 0
    assert first.evaluate_s > 0
    assert len(built) == 2
    files = sorted(job.trace_dir.glob("*.npz"))
    assert len(files) == 2
    mtimes = [f.stat().st_mtime_ns for f in files]
    video_mtime = (job.folder / "video.mp4").stat().st_mtime_ns

    second = process_recording(job, methods)
    assert second.generate_s == 0.0
    assert second.evaluate_s == 0.0
    assert second.methods_run == ()
    assert len(built) == 2  # no pipeline constructed
    assert [f.stat().st_mtime_ns for f in files] == mtimes
    assert (job.folder / "video.mp4").stat().st_mtime_ns == video_mtime
    traces = load_traces(job, methods)
    assert set(traces) == {"uncompensated", "fused-kalman"}
    assert len(traces["fused-kalman"]) == job.n_frames

    # another detector setting: the traces hold the detector's input, nothing is redone
    detector_only = replace(
        methods,
        configs={
            **methods.configs,
            "uncompensated": replace(
                methods.configs["uncompensated"],
                anomaly=replace(
                    methods.configs["uncompensated"].anomaly,
                    std=replace(methods.configs["uncompensated"].anomaly.std, threshold_px=2.0),
                ),
            ),
        },
    )
    assert process_recording(job, detector_only).methods_run == ()
    # another trajectory setting of one method: only that trace (and the reference) is redone
    changed = replace(
        methods,
        configs={
            **methods.configs,
            "uncompensated": replace(
                methods.configs["uncompensated"],
                heave=replace(methods.configs["uncompensated"].heave, cutoff_hz=0.3),
            ),
        },
    )
    third = process_recording(job, changed)
    assert third.generate_s == 0.0
    assert set(third.methods_run) == {"uncompensated", "fused-kalman"}
    assert len(list(job.trace_dir.glob("uncompensated-*.npz"))) == 1  # the stale one is gone
    assert math.isfinite(third.fps)


@pytest.mark.slow
def test_the_engine_gives_the_serial_traces(tmp_path: Path) -> None:
    """Two recordings as tasks on a local Dask cluster of two single-thread workers: the
    same traces, to the bit, as run one after the other in this process; a task that
    fails is an error naming its recording."""
    from roadpreview.batch.engine import open_engine

    def tiny(seed: int) -> RecordingJob:
        cfg = controlled(seed, gap_m=8.0)
        cfg = replace(
            cfg,
            motion=replace(cfg.motion, duration_s=1.5),
            camera=replace(cfg.camera, width=320, height=180),
        )
        return RecordingJob("controlled", f"tiny-{seed}", cfg, tmp_path)

    jobs = [tiny(0), tiny(1)]
    methods = MethodSet.build(PipelineConfig(), select_methods(["uncompensated", "fused-kalman"]))
    process_all(jobs, methods)
    serial = [load_traces(j, methods) for j in jobs]

    seen: list[tuple[int, int, str]] = []

    def progress(n: int, total: int, o: RecordingOutcome) -> None:
        seen.append((n, total, o.key))

    with open_engine(workers=2, memory_limit=None, dashboard=False) as engine:
        outcomes = process_all(jobs, methods, engine=engine, fresh=True, progress=progress)
        assert [o.key for o in outcomes] == [j.key for j in jobs]
        assert all(
            o.generate_s == 0.0 and set(o.methods_run) == set(methods.configs) for o in outcomes
        )  # the recordings reused, every trace made again
        assert [(n, total) for n, total, _ in seen] == [(1, 2), (2, 2)]
        assert {k for _, _, k in seen} == {j.key for j in jobs}
        for job, before in zip(jobs, serial, strict=True):
            after = load_traces(job, methods)
            for m, tr in before.items():
                assert set(after[m].columns) == set(tr.columns)
                for col, values in tr.columns.items():
                    assert np.array_equal(
                        after[m][col], values, equal_nan=values.dtype.kind == "f"
                    ), (job.key, m, col)

        (tmp_path / "not-a-folder").write_text("")
        broken = RecordingJob("controlled", "broken", jobs[0].scenario, tmp_path / "not-a-folder")
        with pytest.raises(OperationError, match="controlled/broken"):
            process_all([broken], methods, engine=engine)
