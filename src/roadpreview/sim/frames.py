"""The simulator's body-to-world rotation, one definition for the vehicles and the camera.

Body and world: X forward, Y left, Z up; pitch positive nose up, roll positive
left side up, yaw positive to the left (``docs/method.md``). The rotation is
yaw, then pitch, then roll (ISO 8855 order) with ISO's pitch angle equal to
minus ours: R = Rz(yaw) Ry(-pitch) Rx(roll).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation


def body_to_world(pitch: ArrayLike, roll: ArrayLike, yaw: ArrayLike) -> NDArray[np.float64]:
    """Rotations (..., 3, 3) taking body vectors to the world, for angles (rad) of any
    common shape (scalars give one (3, 3) matrix); p_world = R @ p_body."""
    p, r, y = np.broadcast_arrays(
        np.asarray(pitch, np.float64), np.asarray(roll, np.float64), np.asarray(yaw, np.float64)
    )
    angles = np.stack([y, -p, r], axis=-1).reshape(-1, 3)
    # intrinsic z-y'-x'': R = Rz(angles[0]) Ry(angles[1]) Rx(angles[2])
    mats = np.asarray(Rotation.from_euler("ZYX", angles).as_matrix(), np.float64)
    out: NDArray[np.float64] = mats.reshape(*p.shape, 3, 3)
    return out
