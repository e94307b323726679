"""Write ``web/quadrotor.stl``: a small X-configuration quadrotor for the dashboard.

    .venv/bin/python web/make_quadrotor.py          # rewrites web/quadrotor.stl

The geometry is a 30 g micro quadrotor at true size, in its body frame (x forward, y left,
z up, origin at the centre of the frame): a flat body plate, four arms at ±45°, four motor
cans and four propeller discs (92 mm motor to motor). Binary STL, numpy only, so the file is
reproducible byte for byte.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["quadrotor_triangles", "write_binary_stl"]

MOTOR_SPACING_M = 0.092
"""Distance between diagonally opposite motors."""


def _box(center: np.ndarray, size: np.ndarray, yaw_rad: float = 0.0) -> np.ndarray:
    """Triangles (12, 3, 3) of a box, rotated about z by ``yaw_rad``."""
    hx, hy, hz = np.asarray(size, dtype=np.float64) / 2.0
    corners = np.array(
        [[sx * hx, sy * hy, sz * hz] for sz in (-1, 1) for sy in (-1, 1) for sx in (-1, 1)]
    )
    quads = [
        (0, 2, 3, 1),  # bottom (-z)
        (4, 5, 7, 6),  # top (+z)
        (0, 1, 5, 4),  # -y
        (2, 6, 7, 3),  # +y
        (0, 4, 6, 2),  # -x
        (1, 3, 7, 5),  # +x
    ]
    tris = []
    for a, b, c, d in quads:
        tris.append(corners[[a, b, c]])
        tris.append(corners[[a, c, d]])
    cos, sin = np.cos(yaw_rad), np.sin(yaw_rad)
    R_world_box = np.array([[cos, -sin, 0.0], [sin, cos, 0.0], [0.0, 0.0, 1.0]])
    return np.asarray(tris) @ R_world_box.T + np.asarray(center)


def _cylinder(center: np.ndarray, radius_m: float, height_m: float, n: int = 20) -> np.ndarray:
    """Triangles (4n, 3, 3) of a closed z-aligned cylinder."""
    angles = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    ring = np.stack([radius_m * np.cos(angles), radius_m * np.sin(angles)], axis=1)
    z0, z1 = -height_m / 2.0, height_m / 2.0
    tris = []
    for i in range(n):
        j = (i + 1) % n
        p0 = np.array([*ring[i], z0])
        p1 = np.array([*ring[j], z0])
        q0 = np.array([*ring[i], z1])
        q1 = np.array([*ring[j], z1])
        tris.append([p0, p1, q1])
        tris.append([p0, q1, q0])
        tris.append([np.array([0.0, 0.0, z1]), q0, q1])
        tris.append([np.array([0.0, 0.0, z0]), p1, p0])
    return np.asarray(tris) + np.asarray(center)


def quadrotor_triangles() -> np.ndarray:
    """All triangles of the quadrotor, shape (T, 3, 3), metres, body frame."""
    arm_m = MOTOR_SPACING_M / 2.0
    parts = [_box(np.zeros(3), np.array([0.034, 0.034, 0.008]))]
    for k in range(4):
        yaw_rad = np.pi / 4.0 + k * np.pi / 2.0
        direction = np.array([np.cos(yaw_rad), np.sin(yaw_rad), 0.0])
        parts.append(_box(direction * arm_m / 2.0, np.array([arm_m, 0.006, 0.003]), yaw_rad))
        motor = direction * arm_m
        parts.append(_cylinder(motor + np.array([0.0, 0.0, 0.004]), 0.0045, 0.012))
        parts.append(_cylinder(motor + np.array([0.0, 0.0, 0.011]), 0.023, 0.0012, n=28))
    # A nose block so "forward" reads without the axes.
    parts.append(_box(np.array([0.021, 0.0, 0.0]), np.array([0.010, 0.010, 0.006])))
    return np.concatenate(parts, axis=0)


def write_binary_stl(path: Path, triangles: np.ndarray) -> None:
    """Write triangles (T, 3, 3) as a binary STL with per-face normals."""
    tris = np.asarray(triangles, dtype=np.float32)
    normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    norms = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = normals / np.where(norms > 0.0, norms, 1.0)
    record = np.zeros(
        len(tris),
        dtype=[("normal", "<f4", (3,)), ("vertices", "<f4", (3, 3)), ("attr", "<u2")],
    )
    record["normal"] = normals
    record["vertices"] = tris
    header = b"groundstation quadrotor (web/make_quadrotor.py)".ljust(80, b" ")
    path.write_bytes(header + np.uint32(len(tris)).astype("<u4").tobytes() + record.tobytes())


def main() -> None:
    out = Path(__file__).resolve().parent / "quadrotor.stl"
    tris = quadrotor_triangles()
    write_binary_stl(out, tris)
    print(f"wrote {out} ({len(tris)} triangles)")


if __name__ == "__main__":
    main()
