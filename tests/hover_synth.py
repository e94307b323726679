"""A drone holding still against a given tether tension, as Telemetry bodies (tests only).

Shared by the tests that feed the pipeline synthetic hover (test_perf_equivalence,
test_pipeline_batch). The noise is the ideal simulator's: 0.3 m/s² on the accelerometer,
3 mN on the thrust, drawn in that order from the caller's generator.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

GRAVITY_MPS2 = 9.81
E3 = np.array([0.0, 0.0, 1.0])


def quat_aligning_e3(direction: np.ndarray) -> np.ndarray:
    """Scalar-first quaternion whose body +z points along ``direction`` (world)."""
    d = direction / np.linalg.norm(direction)
    axis = np.cross(E3, d)
    s = float(np.linalg.norm(axis))
    if s < 1e-12:
        return np.array([1.0, 0.0, 0.0, 0.0])
    angle = math.atan2(s, float(d[2]))
    return np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * axis / s])


def rotation(q: np.ndarray) -> np.ndarray:
    """R_world_body of a scalar-first quaternion (normalised here)."""
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def hover_body(
    seq: int,
    tension_n: np.ndarray,
    rng: np.random.Generator,
    *,
    mass_kg: float,
    dt_s: float,
    armed: bool = True,
    thrust_scale: float = 1.0,
    position_m: list[float] | None = None,
    quat: list[float] | None = None,
    vbat_v: float | None = None,
) -> dict[str, Any]:
    """The Telemetry body of a drone holding still against ``tension_n`` (world, N).

    ``quat`` overrides the attitude reported (the true one still sets the accelerometer).
    """
    thrust_vec = -(tension_n + mass_kg * np.array([0.0, 0.0, -GRAVITY_MPS2]))
    q = quat_aligning_e3(thrust_vec)
    accel = rotation(q).T @ np.array([0.0, 0.0, GRAVITY_MPS2]) + rng.normal(0.0, 0.3, 3)
    thrust = thrust_scale * float(np.linalg.norm(thrust_vec)) + float(rng.normal(0.0, 0.003))
    body: dict[str, Any] = {
        "seq": seq,
        "stamp_s": seq * dt_s,
        "accel_mps2": accel.tolist(),
        "quat_wxyz": quat if quat is not None else q.tolist(),
        "thrust_n": max(thrust, 0.0),
        "armed": armed,
    }
    if position_m is not None:
        body["position_m"] = position_m
    if vbat_v is not None:
        body["vbat_v"] = vbat_v
    return body
