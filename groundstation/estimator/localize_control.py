"""Localization stage: which inputs a converged tension is localized with.

Control around :func:`groundstation.localization.localize` (the equations: the catenary's
``eq:catenary_*`` and the azimuth sources). The stage decides *what* it is given: the
tension and its covariance, the tether (weight, length, base, floor), the reel's exit
angles only while fresh (``[localization] reel_stale_after_s``: the reel reports at its own
rate; the elevation only with ``[localization] elevation``), and the motion-capture
position of the message (the ``mocap`` azimuth source).

Localization holds no state: :func:`localize_one` is a function of the message's
:class:`LocalizeIn` alone.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from groundstation.config import LocalizationSection
from groundstation.localization import (
    AngleObservation,
    PositionEstimate,
    localize,
)

__all__ = [
    "LocalizeIn",
    "exit_azimuth_default_std_rad",
    "fresh_angle",
    "localize_one",
]

Vec3 = tuple[float, float, float]


class LocalizeIn(NamedTuple):
    """What one message is localized from.

    Attributes:
        tension_world_n: the filtered tension, world frame, N, shape (3,).
        cov_n2: its covariance, N², shape (3, 3).
        weight_n_per_m: the tether's weight per length, N/m.
        length_m: the tether's length out, m.
        base_world_m: where it leaves the base, world frame, m, shape (3,).
        floor_z_m: the floor's height, m.
        exit_azimuth: the reel's exit azimuth while fresh (None: none).
        exit_elevation: the reel's exit elevation while fresh and used (None: none).
        mocap_world_m: this message's motion-capture position, m (None: none).
        model_var_n2: the calibration's misfit per world axis, N² (None: none): widens
            the position's covariance (``localization.try_localize``).
    """

    tension_world_n: np.ndarray
    cov_n2: np.ndarray
    weight_n_per_m: float
    length_m: float
    base_world_m: np.ndarray
    floor_z_m: float
    exit_azimuth: AngleObservation | None
    exit_elevation: AngleObservation | None
    mocap_world_m: Vec3 | None
    model_var_n2: tuple[float, float, float] | None = None


def exit_azimuth_default_std_rad(std_rad: float, elevation_rad: float | None) -> float:
    """σ of a Reel ``exit_azimuth_rad`` sent without ``exit_azimuth_std_rad``, rad.

    ``[localization] exit_azimuth_std_rad`` is the σ of the tether's *direction* at the
    exit, across it; the azimuth of that direction is the angle of its horizontal
    projection, which shrinks as ``cos(elevation)``: the same sideways error is
    ``std / cos(elevation)`` of azimuth, and near plumb (elevation ±90°) any azimuth is
    noise. So ``std / cos(elevation)`` with the exit elevation known (this Reel message's,
    or the last one received within ``reel_stale_after_s``), without a floor: near plumb
    the σ grows past the plumb blend's limit and the azimuth carries no weight, as it
    should (inverse-variance fusion; at or beyond plumb, ``cos <= 0``, it is infinite: no
    azimuth). A floor on the cosine would state a σ smaller than the geometry's.
    Without an elevation it stays ``std``, as for a tether leaving level: a reel that sends
    an azimuth without elevation and may point up steeply should send its own σ.

    Args:
        std_rad: The configured σ, rad.
        elevation_rad: The exit elevation, rad, or None when unknown.

    Returns:
        The σ to fuse the exit azimuth with, rad.
    """
    if elevation_rad is None or not math.isfinite(elevation_rad):
        return std_rad
    cos_elevation = math.cos(elevation_rad)
    return std_rad / cos_elevation if cos_elevation > 0.0 else math.inf


def fresh_angle(
    angle: AngleObservation | None, received_s: float, now_s: float, stale_after_s: float
) -> AngleObservation | None:
    """A reel's exit angle received at ``received_s``, if still in use at ``now_s``."""
    return angle if received_s >= now_s - stale_after_s else None


def localize_one(section: LocalizationSection, x: LocalizeIn) -> PositionEstimate | None:
    """The drone's position from one message's inputs (None: not determined)."""
    return localize(
        x.tension_world_n,
        x.cov_n2,
        x.weight_n_per_m,
        x.length_m,
        x.base_world_m,
        x.floor_z_m,
        azimuth=section.azimuth,
        exit_azimuth=x.exit_azimuth,
        exit_elevation=x.exit_elevation,
        mocap_world_m=x.mocap_world_m,
        mocap_std_m=section.mocap_std_m,
        model_var_n2=x.model_var_n2,
    )
