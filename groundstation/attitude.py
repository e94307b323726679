"""Gravity and the attitude's rotation: the one definition the estimator uses.

Pure physics: Python floats for one sample (the per-message path: numpy's per-call
overhead would cost more than the arithmetic on a 3×3), numpy for a batch (calibration and
offline work). Both are the same formula, tested equal (tests/test_attitude.py).

The rotation of a body→world attitude quaternion ``q = [w, x, y, z]`` (scalar first, unit)
is the standard one (``R_world_body``, ``v_world = R·v_body``)::

    R = [[1 − 2(y² + z²),  2(xy − wz),      2(xz + wy)    ],
         [2(xy + wz),      1 − 2(x² + z²),  2(yz − wx)    ],
         [2(xz − wy),      2(yz + wx),      1 − 2(x² + y²)]]

its third row ``Rᵀ·e3`` is gravity's direction in the body frame (the specific force at
rest is ``g·Rᵀ·e3``; ``eq:NE_tether``). The simulator keeps its own copy
(groundstation/sim/rotation.py): a simulator that imported the code it checks would prove
nothing.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "GRAVITY_MPS2",
    "QUAT_MIN_NORM",
    "Rows",
    "rotations_world_body",
    "rows_from_quat_wxyz",
    "rows_from_unit_quat",
]

GRAVITY_MPS2 = 9.81
"""Standard gravity, m/s² (physical; 9.80665 rounded to the accelerometers' precision:
the 0.02 % difference is 6 µN of a 30 g drone's weight). The one g of the estimator,
calibration and dashboard."""

STILL_WINDOW_S = 1.0
"""The one window over which stillness is judged, s (hand-set): on the floor the rest
detector's shortest still window (whose mean is the rest offset and the slow stage's β at
rest) and the contact stage's averaging of the resting vertical bias and height; in the air
the hover test's mean acceleration (``slow_accel.HOVER_MEAN_S`` is this value). At least
1 s of rest for an offset; long enough that the vibration's mean is small beside a
manoeuvre's acceleration, short beside a hover."""

Vec3 = tuple[float, float, float]
Rows = tuple[Vec3, Vec3, Vec3]
"""``R_world_body`` as three rows of floats."""


def rows_from_unit_quat(w: float, x: float, y: float, z: float) -> Rows:
    """``R_world_body`` (module doc) of a unit quaternion, as three rows.

    Args:
        w, x, y, z: The attitude, body→world, scalar first, already of norm 1.
    """
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz, wx, wy, wz = x * y, x * z, y * z, w * x, w * y, w * z
    return (
        (1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)),
        (2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)),
        (2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)),
    )


QUAT_MIN_NORM = 1e-6
"""A quaternion whose norm is below this cannot be normalised: the message is refused
(``groundstation.tension.DegenerateQuaternionError``) and the rest detector skips it.
A numerical guard, not a tunable (docs/constants.md, *Not counted*): a unit quaternion
read with any plausible error has a norm near 1."""


def rows_from_quat_wxyz(quat_wxyz: tuple[float, ...] | list[float]) -> Rows:
    """``R_world_body`` of a body→world ``[w, x, y, z]`` quaternion, normalised here.

    The caller has refused degenerate quaternions (``groundstation.tension`` raises
    ``DegenerateQuaternionError`` for a norm below :data:`QUAT_MIN_NORM` or a non-finite
    entry).
    """
    w, x, y, z = quat_wxyz
    n = math.sqrt(((w * w + x * x) + y * y) + z * z)
    return rows_from_unit_quat(w / n, x / n, y / n, z / n)


def rotations_world_body(quat_wxyz: NDArray[np.float64]) -> NDArray[np.float64]:
    """``R_world_body`` of each quaternion (normalised here), shape (n, 3, 3).

    Args:
        quat_wxyz: Attitudes, body→world, scalar first, shape (n, 4), none degenerate.
    """
    q = quat_wxyz / np.linalg.norm(quat_wxyz, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )
