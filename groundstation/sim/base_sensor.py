"""A base sensor for the simulator: the tether's exit azimuth and elevation at the base.

Kept apart from both profiles' physics: it only reads the simulated tether's shape where it
leaves the base (the first segment of the lumped-mass tether in the ``realistic`` profile,
the first 1/256 of the catenary drawn by :func:`groundstation.catenary.tether_points` in
the ``ideal`` one) and adds the sensor's noise. Switched on by ``[sim] exit_angles``; the
noise is ``[sim] exit_azimuth_noise_rad`` / ``exit_elevation_noise_rad``.

The azimuth of a tether leaving the base nearly vertically is ill-defined: a real angle
sensor's azimuth error grows as the horizontal part of the direction shrinks, so the
reported (and drawn) azimuth noise is ``noise / max(cos(elevation), 0.02)``.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["exit_angle_fields", "exit_direction_rad"]


def exit_direction_rad(points_world_m: np.ndarray) -> tuple[float, float]:
    """Azimuth (``atan2(y, x)`` of the horizontal part, base → drone) and elevation above
    horizontal of the tether's first segment, rad.

    Args:
        points_world_m: (n, 3) points along the tether, the base first, world frame, m.

    Returns:
        ``(azimuth_rad, elevation_rad)``; the azimuth is 0 for a segment that is exactly
        vertical.
    """
    d = np.asarray(points_world_m[1], dtype=float) - np.asarray(points_world_m[0], dtype=float)
    horizontal = math.hypot(float(d[0]), float(d[1]))
    azimuth = math.atan2(float(d[1]), float(d[0])) if horizontal > 0.0 else 0.0
    return azimuth, math.atan2(float(d[2]), horizontal)


def exit_angle_fields(
    points_world_m: np.ndarray,
    rng: np.random.Generator,
    azimuth_noise_rad: float,
    elevation_noise_rad: float,
) -> dict[str, float]:
    """The Reel fields ``exit_azimuth_rad``, ``exit_elevation_rad`` and their ``_std_rad``.

    Args:
        points_world_m: (n, 3) points along the tether, the base first, world frame, m.
        rng: The sensor's random generator.
        azimuth_noise_rad: Azimuth noise standard deviation for a horizontal exit, rad.
        elevation_noise_rad: Elevation noise standard deviation, rad.

    Returns:
        The four fields (noise drawn; stds as the sensor would state them; a std of 0
        becomes 1e-6 since the contract wants them > 0).
    """
    azimuth, elevation = exit_direction_rad(points_world_m)
    az_std = azimuth_noise_rad / max(math.cos(elevation), 0.02)
    azimuth += float(rng.normal(0.0, az_std)) if az_std > 0.0 else 0.0
    elevation += float(rng.normal(0.0, elevation_noise_rad)) if elevation_noise_rad > 0 else 0.0
    limit = 1.5708  # the contract's bound on exit_elevation_rad
    return {
        "exit_azimuth_rad": math.atan2(math.sin(azimuth), math.cos(azimuth)),
        "exit_azimuth_std_rad": max(az_std, 1e-6),
        "exit_elevation_rad": min(max(elevation, -limit), limit),
        "exit_elevation_std_rad": max(elevation_noise_rad, 1e-6),
    }
