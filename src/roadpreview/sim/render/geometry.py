"""Geometry of the simulated camera and vehicles: world to camera, the camera's mount,
near-plane clipping, and a vehicle's box and tyres as quads in its body frame.

Frames are those of ``docs/method.md``: world and body X forward, Y left, Z up;
camera x right, y down, z forward.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from roadpreview.sim.frames import body_to_world
from roadpreview.sim.types import CameraPose, VehiclePose, VehicleShape

F64 = NDArray[np.float64]

#: world (X fwd, Y left, Z up) -> camera (x right, y down, z forward) for a level camera
R_BASE = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


def mount_rotation(forward: F64) -> F64:
    """Smallest rotation M taking the optical axis (0, 0, 1) to the calibrated forward t
    (camera coordinates): p_cam = M p_aligned, where the aligned frame has the body's
    forward direction on its z axis, so that the body's forward direction images at K t."""
    z = np.array([0.0, 0.0, 1.0])
    t = forward / np.linalg.norm(forward)
    axis = np.cross(z, t)
    s, c = float(np.linalg.norm(axis)), float(np.dot(z, t))
    if s < 1e-12:
        return np.eye(3)
    rvec = axis / s * math.atan2(s, c)
    m, _ = cv2.Rodrigues(rvec)
    return np.asarray(m, np.float64)


def world_to_camera(mount: F64, cam: CameraPose) -> tuple[F64, F64]:
    """(R, C) with p_cam = R @ (p_world - C) for a camera on ``mount`` at pose ``cam``."""
    rb = body_to_world(cam.pitch_rad, cam.roll_rad, cam.yaw_rad)
    R = mount @ R_BASE @ rb.T
    return R, np.array([cam.x_m, cam.y_m, cam.z_m])


def vehicle_points_world(pose: VehiclePose, body_points: F64) -> F64:
    """Body-frame points (relative to the CG) of a vehicle to world coordinates, (N, 3)."""
    rb = body_to_world(pose.pitch_rad, pose.roll_rad, pose.yaw_rad)
    pts = np.asarray(body_points, np.float64).reshape(-1, 3)
    out: F64 = pts @ rb.T + np.array([pose.x_m, pose.y_m, pose.z_m])
    return out


def clip_near(poly: F64, near: float) -> F64:
    """Sutherland-Hodgman clip of a convex (n, 3) camera-frame polygon to z >= near."""
    d = poly[:, 2] - near
    nxt = np.roll(poly, -1, axis=0)
    dn = np.roll(d, -1)
    inside = d >= 0.0
    cross = inside != (dn >= 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(cross, d / (d - dn), 0.0)
    inter = poly + t[:, None] * (nxt - poly)
    pts = np.stack([poly, inter], axis=1)
    keep = np.stack([inside, cross], axis=1)
    out: F64 = pts[keep]
    return out


def box_corners(shape: VehicleShape) -> F64:
    """The 8 corners of the vehicle's box relative to the CG (body frame), from the
    road at rest (the tyres' contact) up to the roof; corner index = 4 ix + 2 iy + iz."""
    r, f = -shape.cg_to_rear_m, shape.cg_to_front_m
    w = shape.width_m / 2
    zb = -shape.cg_height_m
    zt = shape.height_m - shape.cg_height_m
    return np.array([[x, y, z] for x in (r, f) for y in (-w, w) for z in (zb, zt)], np.float64)


def rear_face_center_body(shape: VehicleShape) -> F64:
    """Centre of the rear face of the body box in the body frame (relative to the CG).

    The body box spans from the ground clearance up to ``height_m`` (the overall
    height above the road) and its full width and length.
    """
    zc = 0.5 * (shape.ground_clearance_m + shape.height_m) - shape.cg_height_m
    return np.array([-shape.cg_to_rear_m, 0.0, zc])


def footprint(pose: VehiclePose, z: float) -> F64:
    """Contact-shadow quad under a vehicle (10 cm larger than the body), at height z."""
    shape = pose.shape
    rr, ff = -shape.cg_to_rear_m - 0.1, shape.cg_to_front_m + 0.1
    w = shape.width_m / 2 + 0.1
    foot: F64 = np.array([[rr, w, 0.0], [ff, w, 0.0], [ff, -w, 0.0], [rr, -w, 0.0]])
    foot = foot @ body_to_world(0.0, 0.0, pose.yaw_rad).T + np.array([pose.x_m, pose.y_m, 0.0])
    foot[:, 2] = z
    return foot


@dataclass(frozen=True)
class VehicleGeometry:
    """Body-frame quads of a vehicle shape: four tyres, then the body box's faces.

    Corners P0..P3 run top-left, top-right, bottom-right, bottom-left as seen
    from outside; ``face_tex`` is 0 rear, 1 front, 2 side, -1 flat (tyres, roof);
    ``rect_frac`` the texture rectangle as fractions of the texture size.
    """

    quads: F64  # (N, 4, 3)
    face_tex: NDArray[np.int64]
    rect_frac: F64  # (N, 4)
    shade: F64
    is_tyre: NDArray[np.bool_]
    rear_face: int
    front_face: int

    @classmethod
    def build(cls, shape: VehicleShape) -> VehicleGeometry:
        r, f = -shape.cg_to_rear_m, shape.cg_to_front_m
        w = shape.width_m / 2
        g = -shape.cg_height_m  # the road at rest
        zb = shape.ground_clearance_m + g
        zt = shape.height_m + g
        quads: list[list[list[float]]] = []
        shade: list[float] = []
        tl, tw_, tz = 0.62, 0.22, zb + 0.06
        for xc in (r + 0.9, f - 0.9):
            for ys in (-1.0, 1.0):
                y0, y1 = ys * (w - 0.17) - tw_ / 2, ys * (w - 0.17) + tw_ / 2
                x0, x1 = xc - tl / 2, xc + tl / 2
                quads += [
                    [[x0, y1, tz], [x0, y0, tz], [x0, y0, g], [x0, y1, g]],  # rear (-X)
                    [[x1, y0, tz], [x1, y1, tz], [x1, y1, g], [x1, y0, g]],  # front (+X)
                    [[x1, y1, tz], [x0, y1, tz], [x0, y1, g], [x1, y1, g]],  # left (+Y)
                    [[x0, y0, tz], [x1, y0, tz], [x1, y0, g], [x0, y0, g]],  # right (-Y)
                ]
                shade += [0.8, 1.0, 0.9, 0.9]
        n_tyre = len(quads)
        quads += [
            [[r, w, zt], [r, -w, zt], [r, -w, zb], [r, w, zb]],  # rear
            [[f, -w, zt], [f, w, zt], [f, w, zb], [f, -w, zb]],  # front
            [[f, w, zt], [r, w, zt], [r, w, zb], [f, w, zb]],  # left side (front at left)
            [[r, -w, zt], [f, -w, zt], [f, -w, zb], [r, -w, zb]],  # right side
            [[r, w, zt], [f, w, zt], [f, -w, zt], [r, -w, zt]],  # roof, seen from above
        ]
        shade += [1.0, 0.95, 0.8, 0.9, 1.08]
        face_tex = [-1] * n_tyre + [0, 1, 2, 2, -1]
        rect = [[0.0, 0.0, 1.0, 1.0]] * n_tyre + [
            [0.0, 0.0, 1.0, 1.0],
            [0.0, 0.0, 1.0, 1.0],
            [1.0, 0.0, 0.0, 1.0],
            [0.0, 0.0, 1.0, 1.0],
            [0.0, 0.0, 1.0, 1.0],
        ]
        return cls(
            quads=np.array(quads, np.float64),
            face_tex=np.array(face_tex, np.int64),
            rect_frac=np.array(rect, np.float64),
            shade=np.array(shade, np.float64),
            is_tyre=np.arange(len(quads)) < n_tyre,
            rear_face=n_tyre,
            front_face=n_tyre + 1,
        )
