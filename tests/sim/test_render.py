"""The simulator's renderer: geometry measured on the rendered images, texture, degradations.

Every geometric check measures the rendered pixels (ECC alignment, phase
correlation) against the pinhole prediction; the texture checks count corners a
tracking front end would use. Tolerances are stated next to each assertion.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from roadpreview.camera import CameraModel
from roadpreview.configtools import from_mapping
from roadpreview.errors import ConfigError
from roadpreview.sim.render import RenderConfig, SceneRenderer, rear_face_center_body
from roadpreview.sim.scene import SceneConfig, generate_scene
from roadpreview.sim.types import CameraPose, Conditions, VehiclePose, VehicleShape

pytestmark = pytest.mark.slow  # a simulated drive rendered and replayed: scheduled first

W, H = 1280, 720
CAM_H = 1.3  # camera height above the (flat) road
X0 = 50.0  # camera X in the tests
LEAD = 7
SHAPE = VehicleShape()


@pytest.fixture(scope="module")
def camera() -> CameraModel:
    return CameraModel.from_fov(W, H, 45.0)


@pytest.fixture(scope="module")
def renderer(camera: CameraModel) -> SceneRenderer:
    return SceneRenderer(camera, generate_scene(SceneConfig(), seed=3, length_m=150.0))


def lead_at(d: float, dz: float = 0.0) -> VehiclePose:
    """The lead in the ego lane with its rear face d metres ahead of the camera."""
    return VehiclePose(
        LEAD,
        X0 + d + SHAPE.cg_to_rear_m,
        0.0,
        SHAPE.cg_height_m + dz,
        0.0,
        0.0,
        0.0,
        SHAPE,
        appearance=5,
        is_lead=True,
    )


def oncoming(x: float) -> VehiclePose:
    return VehiclePose(8, x, 3.5, SHAPE.cg_height_m, 0.0, 0.0, math.pi, SHAPE, appearance=9)


def pose(pitch: float = 0.0, x: float = X0) -> CameraPose:
    return CameraPose(x, 0.0, CAM_H, pitch)


def gray(img: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)


# -- geometry, measured on the render ---------------------------------------------------
@pytest.mark.parametrize(("delta", "d"), [(0.05, 10.0), (0.10, 25.0), (0.02, 6.0)])
def test_lead_rise_moves_rear_up_by_f_delta_over_d(
    renderer: SceneRenderer, camera: CameraModel, delta: float, d: float
) -> None:
    f = camera.fy
    a = renderer.render(pose(), [lead_at(d)], Conditions(), np.random.default_rng(1))
    b = renderer.render(pose(), [lead_at(d, delta)], Conditions(), np.random.default_rng(2))
    # the rear face's pixels in frame a (mask rows between the face's top and bottom edge)
    top = camera.cy + f * (CAM_H - SHAPE.height_m) / d
    bottom = camera.cy + f * (CAM_H - SHAPE.ground_clearance_m) / d
    m: np.ndarray = np.where(a.vehicle_mask == LEAD, 255, 0).astype(np.uint8)
    m[: math.ceil(top) + 1] = 0
    m[int(bottom) - 1 :] = 0
    m = cv2.erode(m, np.ones((5, 5), np.uint8))
    assert np.count_nonzero(m) > 500
    warp: np.ndarray = np.eye(2, 3, dtype=np.float32)
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-6)
    _, warp = cv2.findTransformECC(
        gray(a.image).astype(np.float32),
        gray(b.image).astype(np.float32),
        warp,
        cv2.MOTION_TRANSLATION,
        criteria,
        m,
        1,
    )
    expected = -f * delta / d  # up: v decreases (docs/method.md)
    # measured (seed 3): -4.356 vs -4.346, -3.527 vs -3.476, -2.902 vs -2.897 px
    assert warp[1, 2] == pytest.approx(expected, abs=0.5)
    assert abs(warp[0, 2]) < 0.2


@pytest.mark.parametrize("pitch_deg", [1.0, -0.5])
def test_camera_pitch_shifts_image_by_f_tan_phi(
    renderer: SceneRenderer, camera: CameraModel, pitch_deg: float
) -> None:
    phi = math.radians(pitch_deg)
    vehicles = [lead_at(15.0), oncoming(X0 + 40.0)]
    a = renderer.render(pose(0.0), vehicles, Conditions(), np.random.default_rng(1))
    b = renderer.render(pose(phi), vehicles, Conditions(), np.random.default_rng(2))
    # rows around the principal point, where a pitch is a uniform shift (to 1 + y^2 ~ 0.5 %)
    cy = round(camera.cy)
    band = (slice(cy - 64, cy + 64), slice(0, W))
    ga = gray(a.image)[band].astype(np.float32)
    gb = gray(b.image)[band].astype(np.float32)
    (dx, dy), _ = cv2.phaseCorrelate(ga, gb, cv2.createHanningWindow(ga.shape[::-1], cv2.CV_32F))
    expected = camera.fy * math.tan(phi)  # nose up -> content moves down
    # measured (seed 3): 15.208 vs 15.170, -7.591 vs -7.585 px
    assert dy == pytest.approx(expected, abs=0.5)
    assert abs(dx) < 0.3
    # the ground truth follows the same rule
    assert b.lead_rear_center_px is not None
    assert a.lead_rear_center_px is not None
    dv_truth = b.lead_rear_center_px[1] - a.lead_rear_center_px[1]
    assert dv_truth == pytest.approx(expected, rel=0.02)


def _rot(pitch: float, roll: float, yaw: float) -> np.ndarray:
    """Body -> world rotation written from docs/method.md (independently of the renderer)."""
    cp, sp = math.cos(pitch), math.sin(pitch)
    cr, sr = math.cos(roll), math.sin(roll)
    cy, sy = math.cos(yaw), math.sin(yaw)
    yaw_m = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    pitch_m = np.array([[cp, 0, -sp], [0, 1, 0], [sp, 0, cp]])  # nose (+X) up to +Z
    roll_m = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])  # left (+Y) up to +Z
    rot: np.ndarray = yaw_m @ pitch_m @ roll_m
    return rot


def test_lead_ground_truth_is_the_projected_rear_centre_and_mask_covers_box(
    renderer: SceneRenderer, camera: CameraModel
) -> None:
    lead = VehiclePose(
        LEAD,
        X0 + 14.0,
        0.3,
        SHAPE.cg_height_m + 0.02,
        0.01,
        -0.015,
        0.02,
        SHAPE,
        appearance=5,
        is_lead=True,
    )
    cam = CameraPose(X0, 0.1, CAM_H, 0.004, 0.003, -0.002)
    fr = renderer.render(cam, [lead, oncoming(X0 + 35.0)], Conditions(), np.random.default_rng(0))
    # rear centre: body point (-cg_to_rear, 0, mid-height of the body box) -> world -> camera
    zc = 0.5 * (SHAPE.ground_clearance_m + SHAPE.height_m) - SHAPE.cg_height_m
    p_body = np.array([-SHAPE.cg_to_rear_m, 0.0, zc])
    np.testing.assert_allclose(rear_face_center_body(SHAPE), p_body)
    p_world = _rot(lead.pitch_rad, lead.roll_rad, lead.yaw_rad) @ p_body + [
        lead.x_m,
        lead.y_m,
        lead.z_m,
    ]
    r_cam = _rot(cam.pitch_rad, cam.roll_rad, cam.yaw_rad)
    to_cv = np.array([[0, -1, 0], [0, 0, -1], [1, 0, 0]])  # X fwd, Y left, Z up -> x right, y down
    p_cam = to_cv @ r_cam.T @ (p_world - [cam.x_m, cam.y_m, cam.z_m])
    uv = camera.project(p_cam)[0]
    assert fr.lead_rear_center_px == pytest.approx((uv[0], uv[1]), abs=1e-6)
    # the mask: the lead fills its box (rear face + tyres; the road shows between the
    # tyres under the body) and stays inside it
    assert fr.lead_box is not None
    x0, y0, x1, y1 = fr.lead_box
    m = fr.vehicle_mask == LEAD
    inside = m[math.ceil(y0) : int(y1) + 1, math.ceil(x0) : int(x1) + 1]
    assert inside.mean() > 0.8
    ys, xs = np.nonzero(m)
    assert xs.min() >= x0 - 1.0
    assert xs.max() <= x1 + 1.0
    assert ys.min() >= y0 - 1.0
    assert ys.max() <= y1 + 1.0
    assert fr.lead_rear_center_px is not None
    u, v = fr.lead_rear_center_px
    assert fr.vehicle_mask[round(v), round(u)] == LEAD
    assert set(np.unique(fr.vehicle_mask)) == {0, LEAD, 8}


# -- texture and its degradation ----------------------------------------------------------
PHI_TRACK = math.radians(0.3)  # camera pitch between the two frames of a tracking pair


def _usable_corners(
    renderer: SceneRenderer, camera: CameraModel, cond: Conditions, tau: float | None
) -> tuple[int, float]:
    """Background corners above the absolute threshold tau that LK tracks to their true place.

    Between the two frames the camera pitches by 0.3 deg, a pure rotation, so the
    true flow of every pixel is known regardless of depth; a corner counts when
    pyramidal LK lands within 0.5 px of it. Returns (count, tau used).
    """
    vehicles = [lead_at(14.0), oncoming(X0 + 40.0)]
    a = renderer.render(pose(0.0), vehicles, cond, np.random.default_rng(1))
    b = renderer.render(pose(PHI_TRACK), vehicles, cond, np.random.default_rng(2))
    ga, gb = gray(a.image), gray(b.image)
    bg = cv2.erode(
        np.where(a.vehicle_mask == 0, 255, 0).astype(np.uint8), np.ones((15, 15), np.uint8)
    )
    eig = cv2.cornerMinEigenVal(ga, 5, ksize=3)
    top = float(eig[bg > 0].max())
    tau = 0.01 * top if tau is None else tau  # goodFeaturesToTrack's qualityLevel 0.01
    if top < tau:
        return 0, tau
    pts = cv2.goodFeaturesToTrack(ga, 5000, tau / top, 8, mask=bg, blockSize=5)
    if pts is None:
        return 0, tau
    # nextPts: without OPTFLOW_USE_INITIAL_FLOW only its buffer is used (the stubs take no None)
    p1, st, _ = cv2.calcOpticalFlowPyrLK(ga, gb, pts, pts.copy(), winSize=(21, 21), maxLevel=3)
    ra, _ = renderer.world_to_camera(pose(0.0))
    rb, _ = renderer.world_to_camera(pose(PHI_TRACK))
    truth = camera.project((camera.rays(pts.reshape(-1, 2)) @ ra) @ rb.T)
    ok = (st.ravel() == 1) & (np.linalg.norm(p1.reshape(-1, 2) - truth, axis=1) < 0.5)
    return int(ok.sum()), tau


@pytest.fixture(scope="module")
def clear_corners(renderer: SceneRenderer, camera: CameraModel) -> tuple[int, float]:
    return _usable_corners(renderer, camera, Conditions(), None)


def test_clear_background_has_trackable_corners(
    renderer: SceneRenderer, camera: CameraModel, clear_corners: tuple[int, float]
) -> None:
    fr = renderer.render(
        pose(), [lead_at(14.0), oncoming(X0 + 40.0)], Conditions(), np.random.default_rng(1)
    )
    bg = np.where(fr.vehicle_mask == 0, 255, 0).astype(np.uint8)
    pts = cv2.goodFeaturesToTrack(gray(fr.image), 5000, 0.01, 8, mask=bg, blockSize=5)
    assert pts is not None
    assert len(pts) > 200  # measured 1203
    n, _ = clear_corners
    assert n > 200  # measured 1039 tracked to within 0.5 px


@pytest.mark.parametrize(
    "cond",
    [
        pytest.param(Conditions(fog_density_per_m=0.1), id="dense-fog-visibility-30m"),
        pytest.param(Conditions(light=0.0005), id="night-unlit-road-5lx"),
        pytest.param(Conditions(tunnel=True), id="tunnel"),
    ],
)
def test_fog_night_tunnel_remove_background_texture(
    renderer: SceneRenderer, camera: CameraModel, clear_corners: tuple[int, float], cond: Conditions
) -> None:
    n_clear, tau = clear_corners
    n, _ = _usable_corners(renderer, camera, cond, tau)
    # measured (seed 3): fog V=30 m 99, night 5 lx 63, tunnel 137 of 1039
    assert n < 0.2 * n_clear, f"{n} usable corners vs {n_clear} in clear weather"


def test_fog_sky_takes_the_airlight_colour(renderer: SceneRenderer) -> None:
    """Koschmieder: at infinite distance only the airlight A remains."""
    fr = renderer.render(pose(), [], Conditions(fog_density_per_m=0.05), np.random.default_rng(0))
    sky = np.median(fr.image[:40].reshape(-1, 3), axis=0)
    np.testing.assert_allclose(sky, renderer.cfg.airlight_bgr, atol=2.0)


def test_motion_blur_is_f_times_pitch_rate_times_exposure_vertically(
    renderer: SceneRenderer, camera: CameraModel
) -> None:
    quiet = SceneRenderer(camera, renderer.scene, RenderConfig(noise=False))
    vehicles = [lead_at(12.0)]
    sharp = quiet.render(pose(), vehicles, Conditions(), np.random.default_rng(0)).image
    rate = 1.0  # rad/s
    blurred = quiet.render(
        pose(), vehicles, Conditions(), np.random.default_rng(0), pitch_rate_rad_s=rate
    ).image
    length = camera.fy * rate * quiet.cfg.exposure_time_s  # 6.95 px

    def smear(img: np.ndarray, n: float) -> np.ndarray:
        r = math.ceil(n / 2 + 0.5)
        x = np.arange(-r, r + 1, dtype=np.float64)
        w = np.clip(np.minimum(x + 0.5, n / 2) - np.maximum(x - 0.5, -n / 2), 0, None)
        k = (w / w.sum()).astype(np.float32)
        return cv2.sepFilter2D(img, -1, np.ones(1, np.float32), k)

    core = (slice(20, H - 20), slice(20, W - 20))

    def err(n: float) -> float:
        return float(np.abs(smear(sharp, n)[core].astype(np.float32) - blurred[core]).mean())

    # a box of the predicted length reproduces the render; half or double the length do not
    assert err(length) < 0.6
    assert err(length / 2) > 2 * err(length)
    assert err(length * 2) > 2 * err(length)


# -- determinism and robustness -----------------------------------------------------------
def test_same_seed_gives_identical_frames(camera: CameraModel) -> None:
    small = CameraModel.from_fov(320, 180, 45.0)
    cfg = SceneConfig(n_facade_styles=2, n_tree_styles=1, n_parked_models=2, margin_m=100.0)
    frames = []
    for seed in (11, 11, 12):
        r = SceneRenderer(small, generate_scene(cfg, seed=seed, length_m=50.0))
        frames.append(
            r.render(pose(x=10.0), [lead_at(12.0)], Conditions(), np.random.default_rng(4))
        )
    assert np.array_equal(frames[0].image, frames[1].image)
    assert np.array_equal(frames[0].vehicle_mask, frames[1].vehicle_mask)
    assert not np.array_equal(frames[0].image, frames[2].image)


def test_objects_behind_or_across_the_camera_are_clipped(
    renderer: SceneRenderer, camera: CameraModel
) -> None:
    behind = VehiclePose(LEAD, X0 - 6.0, 0.0, SHAPE.cg_height_m, 0, 0, 0, SHAPE, 5, is_lead=True)
    alongside = VehiclePose(8, X0 + 1.0, 2.0, SHAPE.cg_height_m, 0, 0, 0.0, SHAPE, 9)
    touching = VehiclePose(
        9, X0 + 0.05 + SHAPE.cg_to_rear_m - 2.0, -3.6, SHAPE.cg_height_m, 0, 0, 0, SHAPE, 2
    )
    for cond in (Conditions(), Conditions(fog_density_per_m=0.05), Conditions(light=0.001)):
        fr = renderer.render(pose(), [behind, alongside, touching], cond, np.random.default_rng(0))
        assert fr.image.shape == (H, W, 3)
        assert fr.image.dtype == np.uint8
        assert fr.lead_box is None
        assert fr.lead_rear_center_px is None
        ids = set(np.unique(fr.vehicle_mask))
        assert LEAD not in ids
        # the car overtaking on the left (Y = +2, spanning the camera's plane) shows only in
        # the left part of the image
        cols = np.nonzero((fr.vehicle_mask == 8).any(axis=0))[0]
        assert cols.size > 0
        assert cols.max() < W / 2
    # a camera inside a building or looking straight down still renders
    fr = renderer.render(
        CameraPose(X0, -13.0, 2.0, -1.5, 0.5, 1.0), [], Conditions(), np.random.default_rng(0)
    )
    assert fr.image.shape == (H, W, 3)


def test_render_config_is_checked() -> None:
    with pytest.raises(ConfigError, match="max_gain"):
        from_mapping(RenderConfig, {"max_gain": 0.5})
    with pytest.raises(ConfigError, match="unknown key"):
        from_mapping(RenderConfig, {"fog": 1})
    assert from_mapping(RenderConfig, {"gamma": 2.4}).gamma == 2.4
