"""The simulator's own rotation math (it shares none with the estimator it checks)."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["quat_wxyz_from_z_axis", "rotation_world_body_wxyz"]


def rotation_world_body_wxyz(quat_wxyz: np.ndarray) -> np.ndarray:
    """``R_world_body`` of a body->world unit quaternion ``[w, x, y, z]`` (normalised here).

    Written from the axis-angle form R = I + 2w[v]x + 2[v]x^2 (v = [x, y, z]), not the
    element-wise table the estimator uses, so a sign slip in one is not repeated in the other.
    """
    q = np.asarray(quat_wxyz, dtype=float)
    q = q / np.linalg.norm(q)
    w, v = q[0], q[1:]
    vx = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + 2.0 * w * vx + 2.0 * (vx @ vx)


def quat_wxyz_from_z_axis(z_world: np.ndarray) -> np.ndarray:
    """Body→world quaternion (zero yaw) whose body +z is the unit vector ``z_world``."""
    z = z_world / np.linalg.norm(z_world)
    w = math.sqrt(max(0.0, (1.0 + z[2]) / 2.0))
    if w < 1e-9:  # upside down: rotate pi about x
        return np.array([0.0, 1.0, 0.0, 0.0])
    # q = [cos(θ/2), sin(θ/2)·axis], axis = e3 × z / |e3 × z|, cosθ = z_z
    return np.array([w, -z[1] / (2.0 * w), z[0] / (2.0 * w), 0.0])
