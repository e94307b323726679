"""The simulator's own rotation math (it shares none with the estimator it checks)."""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "quat_multiply_wxyz",
    "quat_wxyz_from_rotation",
    "quat_wxyz_from_rotvec",
    "quat_wxyz_from_z_axis",
    "rot_x",
    "rot_y",
    "rot_z",
    "rotation_world_body_wxyz",
]


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


def quat_multiply_wxyz(p_wxyz: np.ndarray, q_wxyz: np.ndarray) -> np.ndarray:
    """Hamilton product ``p ⊗ q`` of two ``[w, x, y, z]`` quaternions (q applied first)."""
    pw, px, py, pz = (float(v) for v in p_wxyz)
    qw, qx, qy, qz = (float(v) for v in q_wxyz)
    return np.array(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ]
    )


def quat_wxyz_from_rotvec(rotvec: np.ndarray) -> np.ndarray:
    """Unit quaternion of the rotation by ``|rotvec|`` radians about ``rotvec`` (exp map)."""
    x, y, z = (float(v) for v in rotvec)
    angle = math.sqrt(x * x + y * y + z * z)
    if angle < 1e-12:
        return np.array([1.0, 0.5 * x, 0.5 * y, 0.5 * z])
    s = math.sin(0.5 * angle) / angle
    return np.array([math.cos(0.5 * angle), s * x, s * y, s * z])


def quat_wxyz_from_rotation(R: np.ndarray) -> np.ndarray:
    """Unit quaternion ``[w, x, y, z]`` (w >= 0) of a rotation matrix (Shepperd's method)."""
    m = np.asarray(R, dtype=float)
    tr = float(m[0, 0] + m[1, 1] + m[2, 2])
    diag = (tr, float(m[0, 0]), float(m[1, 1]), float(m[2, 2]))
    k = int(np.argmax(diag))
    if k == 0:
        s = 2.0 * math.sqrt(1.0 + tr)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif k == 1:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif k == 2:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    out = np.array(q, dtype=float)
    out /= np.linalg.norm(out)
    return out if out[0] >= 0.0 else -out


def rot_x(angle_rad: float) -> np.ndarray:
    """Right-handed rotation matrix about +x by ``angle_rad``."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle_rad: float) -> np.ndarray:
    """Right-handed rotation matrix about +y by ``angle_rad``."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle_rad: float) -> np.ndarray:
    """Right-handed rotation matrix about +z by ``angle_rad``."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
