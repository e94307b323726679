"""The Estimate of one message, encoded once (the contract's ``tether/{drone}/estimate``).

No model per message: the fields go to :func:`messages.encode_estimate_ordered` in the
model's order, as plain floats (a tension and position the earlier stages found finite;
anything non-finite that slipped through is refused by the encoder, and the message's
Estimate is dropped, never published with NaN).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from groundstation.localization import PositionEstimate
from groundstation.messages import encode_estimate_ordered

__all__ = ["encode", "estimate_fields", "vec3"]

Vec3 = tuple[float, float, float]


def vec3(values: np.ndarray | Iterable[float]) -> Vec3:
    """Three Python floats from a float64 array, list or tuple (without numpy's per-call
    overhead in the per-message cases)."""
    if type(values) is np.ndarray and values.dtype == np.float64 and values.shape == (3,):
        x, y, z = values.tolist()
        return (x, y, z)
    if (type(values) is tuple or type(values) is list) and len(values) == 3:
        x, y, z = values
        if type(x) is float and type(y) is float and type(z) is float:
            return (x, y, z)
    a = np.asarray(values, dtype=float)
    return (float(a[0]), float(a[1]), float(a[2]))


def _finite3(v: Vec3) -> bool:
    return math.isfinite(v[0]) and math.isfinite(v[1]) and math.isfinite(v[2])


def estimate_fields(
    *,
    seq: int,
    stamp_s: float,
    tension_world_n: Sequence[float],
    std_n: Sequence[float],
    position: PositionEstimate | None,
    follow_json: dict[str, Any],
    on_ground: bool,
    converged: bool,
    length_m: float,
    base_m: Vec3,
    calibration: str,
    calibration_extrapolated: bool | None,
) -> dict[str, Any]:
    """The Estimate's fields in the model's order (``ESTIMATE_FIELD_ORDER``).

    A position with a non-finite coordinate or σ is left out (position undetermined).
    """
    tension = vec3(tension_world_n)
    std = vec3(std_n)
    position_m = position_std_m = None
    radial_m = radial_interval_m = azimuth_determined = azimuth_source = None
    floor_contact = None
    if position is not None:
        position_m = vec3(position.position_world_m)
        position_std_m = vec3(position.std_world_m)
        if not (_finite3(position_m) and _finite3(position_std_m)):
            position = position_m = position_std_m = None
    if position is not None:
        lo, hi = position.radial_interval_m
        radial_m = float(position.radial_m)
        radial_interval_m = (float(lo), float(hi))
        azimuth_determined = position.azimuth_determined
        azimuth_source = position.azimuth_source
        floor_contact = bool(position.floor_contact)
    return {
        "seq": seq,
        "stamp_s": stamp_s,
        "tension_n": tension,
        "tension_std_n": std,
        "horizontal_n": math.hypot(tension[0], tension[1]),
        "vertical_n": -tension[2],
        "position_m": position_m,
        "follow": follow_json,
        "position_std_m": position_std_m,
        "radial_m": radial_m,
        "radial_interval_m": radial_interval_m,
        "azimuth_determined": azimuth_determined,
        "azimuth_source": azimuth_source,
        "floor_contact": floor_contact,
        "on_ground": on_ground,
        "converged": converged,
        "length_m": length_m,
        "base_m": base_m,
        "calibration": calibration,
        "calibration_extrapolated": calibration_extrapolated,
    }


def encode(fields: dict[str, Any]) -> bytes:
    """The Estimate's JSON. Raises ValueError for a non-finite field."""
    return encode_estimate_ordered(fields)
