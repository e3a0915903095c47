"""A simulated drive written as a recording folder, read back and regenerated bit for bit."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import cantools
import cv2
import numpy as np
import pytest

from roadpreview.canbus import load_database, read_can_log
from roadpreview.cli.main import main
from roadpreview.errors import ConfigError
from roadpreview.sim.dataset import drive_config
from roadpreview.sim.presets import PRESETS, preset
from roadpreview.sim.recording import Recording, write_recording
from roadpreview.sim.scenario import ScenarioConfig


def _short_demo(seed: int = 0) -> ScenarioConfig:
    cfg = drive_config("demo", seed, duration_s=3.0, width=480, height=270)
    return replace(cfg, output=replace(cfg.output, can_formats=["blf", "asc"], masks=True))


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Recording:
    folder = tmp_path_factory.mktemp("rec")
    write_recording(_short_demo(), folder)
    return Recording.open(folder)


def _frames(video: Path) -> list[np.ndarray]:
    cap = cv2.VideoCapture(str(video))
    out = []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        out.append(frame)
    cap.release()
    return out


def test_recording_has_every_file_and_consistent_sizes(recording: Recording) -> None:
    for name in (
        "video.mp4",
        "frames.csv",
        "can.blf",
        "can.asc",
        "imu.csv",
        "camera.toml",
        "scenario.toml",
        "truth.npz",
        "truth.json",
    ):
        assert (recording.folder / name).is_file(), name
    frames = _frames(recording.video)
    n = recording.info["n_frames"]
    assert n == 90  # 3 s at 30 fps
    assert len(frames) == n
    assert frames[0].shape == (270, 480, 3)
    assert recording.truth["frame_t_s"].shape == (n,)
    assert recording.camera.size == (480, 270)
    assert recording.config == _short_demo()


def test_truth_lead_position_is_inside_its_box_and_on_the_mask(recording: Recording) -> None:
    box = recording.truth["lead_box_px"]
    rear = recording.truth["lead_rear_px"]
    assert np.isfinite(rear).all()
    assert (rear[:, 0] > box[:, 0]).all()
    assert (rear[:, 0] < box[:, 2]).all()
    assert (rear[:, 1] > box[:, 1]).all()
    assert (rear[:, 1] < box[:, 3]).all()
    mask = recording.mask(10)
    u, v = (round(float(c)) for c in rear[10])
    assert mask[v, u] != 0  # a vehicle id, not background
    # the truth distance agrees with the pinhole size of the box: width ~ f W / d
    width_px = box[:, 2] - box[:, 0]
    expected = recording.camera.fx * 1.8 / recording.truth["lead_distance_m"]
    np.testing.assert_allclose(width_px, expected, rtol=0.1)


def test_can_log_decodes_to_the_true_pitch_rate(recording: Recording) -> None:
    db = load_database()
    rates = db.get_message_by_name("IMU_RATES")
    t, pitch_rate = [], []
    for msg in read_can_log(recording.folder / "can.blf"):
        if msg.arbitration_id == rates.frame_id:
            sig = rates.decode(bytes(msg.data))
            assert isinstance(sig, dict)
            t.append(msg.timestamp - recording.info["can_t0_unix_s"])
            value = sig["PitchRate"]
            assert isinstance(value, float | int)
            pitch_rate.append(math.radians(value))
    assert len(t) == pytest.approx(3.0 * recording.info["imu_rate_hz"], abs=3)  # 3 s of IMU
    true_rate = np.interp(
        t, recording.truth["imu_t_stamp_s"], recording.truth["imu_true_rates_rad_s"][:, 1]
    )
    bias = np.interp(
        t, recording.truth["imu_t_stamp_s"], recording.truth["imu_gyro_bias_rad_s"][:, 1]
    )
    # measured = true + bias + white noise (smartphone preset): the residual is noise-sized
    residual = np.asarray(pitch_rate) - true_rate + bias  # ISO y is minus our pitch rate
    assert np.std(residual) < math.radians(0.3)
    assert abs(np.mean(residual)) < math.radians(0.1)
    # the ASC copy holds the same frames
    blf = [(m.arbitration_id, bytes(m.data)) for m in read_can_log(recording.folder / "can.blf")]
    asc = [(m.arbitration_id, bytes(m.data)) for m in read_can_log(recording.folder / "can.asc")]
    assert blf == asc
    assert isinstance(db, cantools.database.can.Database)


def test_same_seed_gives_identical_truth_and_frames(recording: Recording, tmp_path: Path) -> None:
    write_recording(_short_demo(), tmp_path)
    again = Recording.open(tmp_path)
    for key, value in recording.truth.items():
        np.testing.assert_array_equal(again.truth[key], value, err_msg=key)
    a, b = _frames(recording.video), _frames(again.video)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    # and a different seed gives a different drive
    other = tmp_path / "other"
    cfg = replace(
        _short_demo(seed=1), output=replace(_short_demo().output, video=False, masks=False)
    )
    write_recording(cfg, other)
    assert not np.array_equal(
        Recording.open(other).truth["cam_pitch_rad"], recording.truth["cam_pitch_rad"]
    )


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_presets_are_valid_and_round_trip(name: str, tmp_path: Path) -> None:
    cfg = preset(name, seed=4)
    cfg.validate()
    cfg.save(tmp_path / "s.toml")
    assert ScenarioConfig.load(tmp_path / "s.toml") == cfg


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        ("[motion]\nspeed = 3\n", r"motion\.speed"),
        ("[motion]\nego_speed_kmh = -20.0\n", r"motion\.ego_speed_kmh"),
        ("[motion]\ngap_m = 1.0\n", r"motion\.gap_m"),
        ("[camera]\nfps = 0.0\n", r"camera\.fps"),
        ("[[conditions]]\nkind = 'snow'\n", r"conditions\[0\]\.kind"),
    ],
)
def test_invalid_scenario_file_is_rejected_naming_the_field(
    edit: str, field: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "scenario.toml"
    path.write_text(edit)
    with pytest.raises(ConfigError, match=field):
        ScenarioConfig.load(path)
    assert main(["simulate", "--scenario", str(path), "--out", str(tmp_path / "o")]) == 1
    assert "scenario.toml" in capsys.readouterr().err


def test_cli_writes_a_scenario_that_loads(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert (
        main(
            [
                "simulate",
                "--preset",
                "wild",
                "--seed",
                "7",
                "--write-scenario",
                "--out",
                str(tmp_path),
            ]
        )
        == 0
    )
    cfg = ScenarioConfig.load(tmp_path / "scenario.toml")
    assert cfg == preset("wild", 7)
    assert "scenario.toml" in capsys.readouterr().out


def test_random_presets_are_feasible_for_many_seeds() -> None:
    # random manoeuvres never make a car reverse or close the gap below the minimum
    events = 0
    for seed in range(60):
        cfg = preset("wild", seed)
        cfg.validate()  # raises ConfigError naming the field if infeasible
        preset("texture-loss", seed).validate()
        events += len(cfg.motion.lead_events)
    assert events > 20  # the manoeuvres were kept, not all dropped
