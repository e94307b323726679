"""One drone's 3D scene as plain data: what Foxglove draws, before any Foxglove type.

Pure (numpy and the contract's models; no foxglove, no I/O, no clock): from the latest
Estimate, the Telemetry's attitude and motion-capture position, the simulator's truth and
the drone's configuration, :func:`build_drone_scene` decides where the base, the drone, the
tether, the tension arrow and the uncertainty ellipsoid are and in which colour. The
Foxglove messages are made from it in :mod:`groundstation.foxglove.schemas`; the tests check
this module without a server.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

from groundstation.catenary import CatenaryError
from groundstation.catenary import tether_points as catenary_tether_points
from groundstation.config import DroneParams
from groundstation.messages import Estimate

__all__ = [
    "ARROW_M_PER_N",
    "MODE_RGBA",
    "DroneInputs",
    "DroneMode",
    "DroneScene",
    "TensionArrow",
    "build_drone_scene",
    "drone_mode",
    "tether_points",
]

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]
RGBA = tuple[float, float, float, float]

ARROW_M_PER_N = 4.0
"""Drawn length of the tension arrow per newton (the dashboard's scale), m/N."""
TETHER_POINTS = 64
"""Points along the drawn tether."""
ELLIPSOID_SIGMAS = 2.0
"""The uncertainty ellipsoid spans ± this many standard deviations per axis."""
ELLIPSOID_MIN_M, ELLIPSOID_MAX_M = 0.005, 3.0
"""Its drawn diameter per axis is clipped to this range, m (a converged σ of 0.1 mm would be
invisible, an unconverged one of metres would hide the room)."""
FLOOR_TOLERANCE_M = 1e-3
"""A tether point this close to the floor is part of the floor run, m."""

DroneMode = Literal["no_estimate", "on_ground", "flying", "following", "landing", "stopped"]
"""What the drone's colour says: no Estimate yet; on the floor; flying with follow off;
following the pull; tug-to-land armed (below the landing height the motors stop); stopped."""

MODE_RGBA: dict[DroneMode, RGBA] = {
    "no_estimate": (0.6, 0.6, 0.6, 0.6),
    "on_ground": (0.53, 0.56, 0.59, 1.0),
    "flying": (0.13, 0.55, 0.9, 1.0),
    "following": (0.22, 0.7, 0.3, 1.0),
    "landing": (0.94, 0.55, 0.0, 1.0),
    "stopped": (0.88, 0.19, 0.19, 1.0),
}
"""Colour of the drone's body per mode, RGBA in [0, 1]."""
TETHER_RGBA: RGBA = (0.16, 0.16, 0.16, 1.0)
FLOOR_RUN_RGBA: RGBA = (0.59, 0.43, 0.24, 1.0)
TENSION_RGBA: RGBA = (0.88, 0.19, 0.19, 1.0)
MOCAP_RGBA: RGBA = (0.0, 0.8, 0.85, 1.0)
"""Motion capture's marker: cyan, apart from every mode's colour (the dashboard's green is
the body's "following" here)."""
TRUTH_RGBA: RGBA = (0.9, 0.3, 0.85, 1.0)
BASE_RGBA: RGBA = (0.53, 0.56, 0.59, 1.0)


@dataclass(frozen=True, slots=True)
class DroneInputs:
    """What is known of one drone when its scene is built (each the latest received)."""

    drone_id: str
    estimate: Estimate | None = None
    quat_wxyz: Quat | None = None
    """Attitude from the Telemetry, body → world, scalar first (unit or not)."""
    mocap_m: Vec3 | None = None
    """Motion-capture position from the Telemetry, world frame, m."""
    truth_m: Vec3 | None = None
    """The simulator's true position, world frame, m."""
    truth_base_m: Vec3 | None = None
    """The simulator's base exit point, world frame, m (before the first Estimate)."""
    truth_length_m: float | None = None
    """The simulator's tether length, m (before the first Estimate)."""


@dataclass(frozen=True, slots=True)
class TensionArrow:
    """The tension drawn at the drone: along ``tension_n``, ``length_m`` long."""

    start_m: Vec3
    """Its tail (the drone), world frame, m."""
    direction: Vec3
    """Unit vector along the tension, world frame."""
    length_m: float
    """|T| × the scale (``arrow_m_per_n``), m."""
    tension_n: float
    """|T|, newtons."""


@dataclass(frozen=True, slots=True)
class DroneScene:
    """One drone's scene, world frame (x, y, z up), metres.

    ``tether_m`` are the catenary's points from the base to the drone (floor run included,
    :func:`groundstation.catenary.tether_points`), ``floor_run_m`` those of them that rest
    on the floor (None when fewer than two do). Quantities the inputs do not determine are
    None.
    """

    drone_id: str
    seq: int | None
    """The Estimate's ``seq`` (None before the first)."""
    stamp_s: float | None
    """The Estimate's ``stamp_s``, drone clock, seconds."""
    mode: DroneMode
    body_rgba: RGBA
    base_m: Vec3
    floor_z_m: float
    length_m: float
    body_m: Vec3 | None
    """Where the drone is drawn: the estimate, else motion capture, else truth."""
    body_source: Literal["estimate", "mocap", "truth"] | None
    quat_wxyz: Quat
    """Attitude, unit, body → world (identity when unknown)."""
    tether_m: npt.NDArray[np.float64] | None
    """(n, 3) points, base first."""
    floor_run_m: npt.NDArray[np.float64] | None
    arrow: TensionArrow | None
    """None on the ground, without a body, or with no tension."""
    ellipsoid_center_m: Vec3 | None
    ellipsoid_size_m: Vec3 | None
    """Diameters per world axis: 2 × ``ELLIPSOID_SIGMAS`` × ``position_std_m``, clipped."""
    mocap_m: Vec3 | None
    truth_m: Vec3 | None
    label: str


def tether_points(
    base_world_m: Sequence[float],
    drone_world_m: Sequence[float],
    length_m: float,
    floor_z_m: float,
    n: int = TETHER_POINTS,
) -> npt.NDArray[np.float64]:
    """Points (n, 3) of the tether, world frame, m: ``catenary.tether_points`` as drawn.

    As the dashboard draws it: an end a little below the floor (estimate noise) is drawn on
    it, and where the catenary has no curve for these inputs (it raises for a bad length),
    the chord.
    """
    base = np.asarray(base_world_m, dtype=np.float64)
    drone = np.asarray(drone_world_m, dtype=np.float64)
    if math.isfinite(floor_z_m):
        base = np.array([base[0], base[1], max(base[2], floor_z_m)])
        drone = np.array([drone[0], drone[1], max(drone[2], floor_z_m)])
    try:
        return catenary_tether_points(base, drone, float(length_m), floor_z_m=floor_z_m, n=n)
    except CatenaryError:
        s = np.linspace(0.0, 1.0, n)[:, None]
        return np.asarray(base + s * (drone - base), dtype=np.float64)


def drone_mode(estimate: Estimate | None) -> DroneMode:
    """The mode the drone's colour shows (see :data:`DroneMode`)."""
    if estimate is None:
        return "no_estimate"
    follow = estimate.follow
    if follow.stopped:
        return "stopped"
    if estimate.on_ground:
        return "on_ground"
    if follow.enabled and follow.landing_armed:
        return "landing"
    if follow.enabled:
        return "following"
    return "flying"


def _unit_quat(quat_wxyz: Quat | None) -> Quat:
    if quat_wxyz is None:
        return (1.0, 0.0, 0.0, 0.0)
    norm = math.sqrt(sum(q * q for q in quat_wxyz))
    if not (norm > 1e-9 and math.isfinite(norm)):
        return (1.0, 0.0, 0.0, 0.0)
    w, x, y, z = (q / norm for q in quat_wxyz)
    return (w, x, y, z)


def _arrow(body_m: Vec3, tension_n: Vec3, m_per_n: float) -> TensionArrow | None:
    norm_n = math.sqrt(sum(t * t for t in tension_n))
    if not norm_n > 0.0:
        return None
    direction = (tension_n[0] / norm_n, tension_n[1] / norm_n, tension_n[2] / norm_n)
    return TensionArrow(body_m, direction, norm_n * m_per_n, norm_n)


def _label(inputs: DroneInputs, mode: DroneMode) -> str:
    est = inputs.estimate
    lines = [f"{inputs.drone_id} ({mode.replace('_', ' ')})"]
    if est is not None and not est.on_ground:
        norm_n = math.sqrt(sum(t * t for t in est.tension_n))
        lines.append(f"|T| {norm_n:.3f} N")
    if est is not None and est.position_m is None:
        lines.append("position undetermined")
    return "\n".join(lines)


def build_drone_scene(
    inputs: DroneInputs,
    params: DroneParams,
    *,
    arrow_m_per_n: float = ARROW_M_PER_N,
    n_points: int = TETHER_POINTS,
) -> DroneScene:
    """The scene of one drone from what is known of it.

    Base and tether length are the Estimate's (what the service used), else the truth's,
    else the configuration's. The tether is drawn through base and body
    (:func:`tether_points`); the arrow starts at the body along ``tension_n`` with
    ``|T| · arrow_m_per_n`` metres, none on the ground; the ellipsoid is centred on the
    estimated position with ± ``ELLIPSOID_SIGMAS`` σ per axis.

    Args:
        inputs: the drone's latest Estimate, attitude, motion capture, truth.
        params: the drone's resolved configuration (base, floor, tether).
        arrow_m_per_n: arrow scale, m/N.
        n_points: points along the tether, ≥ 2.

    Returns:
        The scene, world frame, metres.
    """
    est = inputs.estimate
    floor_z_m = params.base.floor_z_m
    base_m: Vec3 = params.base.position_m
    length_m = params.tether.length_m
    if est is not None and est.base_m is not None:
        base_m = est.base_m
    elif inputs.truth_base_m is not None:
        base_m = inputs.truth_base_m
    if est is not None and est.length_m is not None and est.length_m > 0.0:
        length_m = est.length_m
    elif inputs.truth_length_m is not None and inputs.truth_length_m > 0.0:
        length_m = inputs.truth_length_m

    body_m: Vec3 | None = None
    source: Literal["estimate", "mocap", "truth"] | None = None
    for candidate, name in (
        (est.position_m if est is not None else None, "estimate"),
        (inputs.mocap_m, "mocap"),
        (inputs.truth_m, "truth"),
    ):
        if candidate is not None:
            body_m, source = candidate, name  # type: ignore[assignment]
            break

    tether = floor_run = None
    if body_m is not None:
        tether = tether_points(base_m, body_m, length_m, floor_z_m, n_points)
        on_floor = np.abs(tether[:, 2] - floor_z_m) < FLOOR_TOLERANCE_M
        if int(on_floor.sum()) >= 2:
            floor_run = tether[on_floor]

    arrow = None
    if est is not None and body_m is not None and not est.on_ground:
        arrow = _arrow(body_m, est.tension_n, arrow_m_per_n)

    center = size = None
    if est is not None and est.position_m is not None and est.position_std_m is not None:
        center = est.position_m
        sx, sy, sz = (
            float(np.clip(2.0 * ELLIPSOID_SIGMAS * s, ELLIPSOID_MIN_M, ELLIPSOID_MAX_M))
            for s in est.position_std_m
        )
        size = (sx, sy, sz)

    mode = drone_mode(est)
    return DroneScene(
        drone_id=inputs.drone_id,
        seq=est.seq if est is not None else None,
        stamp_s=est.stamp_s if est is not None else None,
        mode=mode,
        body_rgba=MODE_RGBA[mode],
        base_m=base_m,
        floor_z_m=floor_z_m,
        length_m=length_m,
        body_m=body_m,
        body_source=source,
        quat_wxyz=_unit_quat(inputs.quat_wxyz),
        tether_m=tether,
        floor_run_m=floor_run,
        arrow=arrow,
        ellipsoid_center_m=center,
        ellipsoid_size_m=size,
        mocap_m=inputs.mocap_m,
        truth_m=inputs.truth_m,
        label=_label(inputs, mode),
    )
