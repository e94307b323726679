"""3-D drone position from the estimated tether tension (paper sec. pos_est).

Pure physics: numpy and :mod:`groundstation.catenary` only.

The tension at the drone end of a hanging tether fixes the catenary: its parameter
``a = H / omega`` (``eq:a_param``) and the signed arc length from the lowest point to
the drone ``s2 = T_v / omega`` (``eq:s2_param``), with H the horizontal magnitude of
the tension and ``T_v = -T_z`` its downward pull. With the tether length these give
the drone's radial distance r and height z relative to the base
(``eq:posfull_radial``, ``eq:posfull_z``, in the closed form of NOTES;
:func:`groundstation.catenary.locate`). Where part of the tether rests on the floor,
:func:`groundstation.catenary.locate_with_floor` gives r only within an interval.

Departures from the paper:

* **Azimuth from the estimate.** The paper took beta from motion capture. The
  horizontal tension on the drone points from the drone to the base, so the drone
  lies at ``base + r * (-T_xy / |T_xy|)``: the estimate carries its own azimuth.
* **Near-plumb tether.** When H is within its noise the azimuth is undetermined; the
  result says so (``azimuth_determined=False``), places the drone straight above or
  below the base, and widens the horizontal uncertainty to the radius the tether
  could reach at a horizontal tension ``plumb_k`` standard deviations above zero.
  The paper's filter, started from T = 0, was always in this case at first and
  reported z = 0.754 - 1.6 = -0.846 m (``eq:in_instants``); the tension filter of
  this project starts from the first observation instead.
* **Uncertainty.** The tension covariance is carried to the position with the
  unscented transform (7 sigma points, kappa = 0) through one vectorised catenary
  call, so the large non-linearity of r in H near a taut tether is respected.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from groundstation import catenary

__all__ = [
    "PLUMB_K",
    "LocalizationFailure",
    "PositionEstimate",
    "localize",
    "try_localize",
]

FloatArray = NDArray[np.float64]

PLUMB_K = 3.0
"""H below this many standard deviations of H leaves the azimuth undetermined.

At H = 0 the estimated H is Rayleigh-distributed; it exceeds 3 sigma with probability
exp(-9/2) = 1.1 %, so a plumb tether is reported with a direction about once in 90
estimates (2 sigma would be 13.5 %)."""

MIN_HORIZONTAL_N = 1e-9
"""H at or below this is treated as zero whatever its covariance (a noise-free plumb
tether has H ~ 1e-17 N from rounding, with a meaningless direction)."""

_N = 3  # state dimension of the unscented transform
_SIGMA_SCALE = math.sqrt(_N)  # sqrt(n + kappa), kappa = 0
_SIGMA_WEIGHT = 1.0 / (2 * _N)


@dataclass(frozen=True)
class PositionEstimate:
    """Tether-based position of the drone.

    Attributes:
        position_world_m: Best position, world frame, m, shape (3,).
        std_world_m: Standard deviation per world axis, m, shape (3,).
        cov_world_m2: Position covariance, m^2, shape (3, 3).
        radial_m: Best horizontal distance from the base, m.
        radial_interval_m: Interval the horizontal distance is known to lie in beyond
            the noise in ``std_world_m``: ``(r, r)`` for a freely hanging tether,
            the slack-on-the-floor interval when part of it rests on the floor, and
            ``(0, r reachable at H = plumb_k sigma_H)`` when the azimuth is
            undetermined. m.
        azimuth_rad: Direction from the base to the drone, ``atan2(y, x)``, rad; None
            when undetermined.
        azimuth_determined: False when H is within its noise (tether near plumb).
        floor_contact: Part of the tether rests on the floor.
        floor_run_m: Length of tether on the floor, m (0 without contact).
        case: ``"free"``, ``"floor"`` or ``"plumb"``: which branch produced it.
    """

    position_world_m: FloatArray
    std_world_m: FloatArray
    cov_world_m2: FloatArray
    radial_m: float
    radial_interval_m: tuple[float, float]
    azimuth_rad: float | None
    azimuth_determined: bool
    floor_contact: bool
    floor_run_m: float
    case: Literal["free", "floor", "plumb"]


@dataclass(frozen=True)
class LocalizationFailure:
    """Why no position could be computed.

    Attributes:
        reason: Human-readable reason naming the offending values.
    """

    reason: str


def _frozen(a: ArrayLike) -> FloatArray:
    out = np.array(a, dtype=np.float64)
    out.setflags(write=False)
    return out


def _locate(
    horizontal_n: FloatArray,
    vertical_n: FloatArray,
    weight_n_per_m: float,
    length_m: float,
    base_z_m: float,
    floor_z_m: float,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """r, z, r_min, r_max, floor_contact (0/1), floor_run for arrays of (H, T_v).

    The free-hanging :func:`catenary.locate` runs first; the floor-aware
    :func:`catenary.locate_with_floor` (twice the cost) only when some free solution
    comes within 1 um of the floor. Away from the floor both give the same answer.
    """
    r, z = catenary.locate(horizontal_n, vertical_n, weight_n_per_m, length_m, base_z_m)
    r = np.asarray(r, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    if floor_z_m != -math.inf:
        # Lowest point of the free curve (NOTES): the drone when s2 < 0, the base when
        # s2 > L, else the vertex, sqrt(a^2 + s2^2) - a below the drone.
        a = horizontal_n / weight_n_per_m
        s2 = vertical_n / weight_n_per_m
        vertex = z - (np.hypot(a, s2) - a)
        lowest = np.where(s2 < 0.0, z, np.where(s2 > length_m, base_z_m, vertex))
        if not (lowest > floor_z_m + 1e-6).all():
            return _locate_floor(
                horizontal_n, vertical_n, weight_n_per_m, length_m, base_z_m, floor_z_m
            )
    zeros = np.zeros_like(r)
    return r, z, r, r, zeros, zeros


def _locate_floor(
    horizontal_n: FloatArray,
    vertical_n: FloatArray,
    weight_n_per_m: float,
    length_m: float,
    base_z_m: float,
    floor_z_m: float,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    loc = catenary.locate_with_floor(
        horizontal_n, vertical_n, weight_n_per_m, length_m, base_z_m, floor_z_m
    )
    r = np.asarray(loc.r_m, dtype=np.float64)

    def full(value: object) -> FloatArray:
        arr = np.asarray(value, dtype=np.float64)
        return arr if arr.shape == r.shape else np.broadcast_to(arr, r.shape)

    return (
        r,
        full(loc.z_m),
        full(loc.r_min_m),
        full(loc.r_max_m),
        full(loc.floor_contact),
        full(loc.floor_run_m),
    )


def _sqrt_psd(cov: FloatArray) -> FloatArray:
    """A matrix S with S S^T = cov for a symmetric positive semi-definite ``cov``."""
    try:
        return np.asarray(np.linalg.cholesky(cov), dtype=np.float64)
    except np.linalg.LinAlgError:  # singular (e.g. zero) covariance
        w, v = np.linalg.eigh(cov)
        return np.asarray(v * np.sqrt(np.clip(w, 0.0, None)), dtype=np.float64)


def try_localize(
    tension_world_n: ArrayLike | None,
    tension_cov_n2: ArrayLike,
    weight_n_per_m: float,
    length_m: float,
    base_world_m: ArrayLike,
    floor_z_m: float = -math.inf,
    plumb_k: float = PLUMB_K,
) -> PositionEstimate | LocalizationFailure:
    """Drone position and its uncertainty from the tension at the drone.

    Args:
        tension_world_n: Force of the tether on the drone, world frame, N, shape (3,),
            or None when there is no estimate.
        tension_cov_n2: Its covariance, N^2, shape (3, 3) (symmetric PSD; tiny
            negative eigenvalues from rounding are clipped).
        weight_n_per_m: Tether weight per unit length omega, N/m, > 0.
        length_m: Tether length from the base exit to the drone, m, > 0.
        base_world_m: Base (tether exit) position, world, m, shape (3,).
        floor_z_m: Height of the floor a slack tether rests on, m; ``-inf`` for none.
        plumb_k: H below ``plumb_k`` standard deviations of H leaves the azimuth
            undetermined (see :data:`PLUMB_K`).

    Returns:
        The estimate, or a :class:`LocalizationFailure` with the reason. Never NaN.
    """
    if tension_world_n is None:
        return LocalizationFailure("no tension estimate")
    T = np.asarray(tension_world_n, dtype=np.float64)
    cov = np.asarray(tension_cov_n2, dtype=np.float64)
    base = np.asarray(base_world_m, dtype=np.float64)
    if T.shape != (3,) or not np.isfinite(T).all():
        return LocalizationFailure(f"tension_world_n must be a finite 3-vector, got {T.tolist()}")
    if cov.shape != (3, 3) or not np.isfinite(cov).all():
        return LocalizationFailure(f"tension_cov_n2 must be a finite 3x3, got {cov.tolist()}")
    if base.shape != (3,) or not np.isfinite(base).all():
        return LocalizationFailure(f"base_world_m must be a finite 3-vector, got {base.tolist()}")
    if not (math.isfinite(weight_n_per_m) and weight_n_per_m > 0.0):
        return LocalizationFailure(f"weight_n_per_m must be finite and > 0, got {weight_n_per_m!r}")
    if not (math.isfinite(length_m) and length_m > 0.0):
        return LocalizationFailure(f"length_m must be finite and > 0, got {length_m!r}")
    if math.isnan(floor_z_m) or floor_z_m == math.inf:
        return LocalizationFailure(f"floor_z_m must be finite or -inf, got {floor_z_m!r}")
    if math.isfinite(floor_z_m) and base[2] < floor_z_m:
        return LocalizationFailure(f"base z {base[2]} m is below the floor {floor_z_m} m")
    cov = 0.5 * (cov + cov.T)

    # eq:a_param, eq:s2_param act through H and T_v (catenary.locate divides by omega).
    horizontal_n = math.hypot(T[0], T[1])
    vertical_n = -T[2]  # T_v: downward pull on the drone
    # sigma_H: the largest horizontal standard deviation, whatever the direction.
    cxx, cyy, cxy = cov[0, 0], cov[1, 1], cov[0, 1]
    lam_max = 0.5 * (cxx + cyy) + math.sqrt(max(0.25 * (cxx - cyy) ** 2 + cxy * cxy, 0.0))
    sigma_h_n = math.sqrt(max(lam_max, 0.0))
    plumb = horizontal_n <= max(plumb_k * sigma_h_n, MIN_HORIZONTAL_N)

    # All catenary evaluations in one vectorised call:
    #   0: the estimate; 1..6: sigma points T +- sqrt(3) S e_i; and when plumb,
    #   7: (k sigma_H, T_v), 8: (0, T_v).
    sqrt_cov = _sqrt_psd(cov)
    pts = np.empty((2 * _N + 1, 3))
    pts[0] = T
    pts[1 : _N + 1] = T + _SIGMA_SCALE * sqrt_cov.T
    pts[_N + 1 :] = T - _SIGMA_SCALE * sqrt_cov.T
    n_all = 2 * _N + 3 if plumb else 2 * _N + 1  # the plumb points only when needed
    h_all = np.empty(n_all)
    v_all = np.empty(n_all)
    h_pts = h_all[: 2 * _N + 1]
    np.hypot(pts[:, 0], pts[:, 1], out=h_pts)
    np.negative(pts[:, 2], out=v_all[: 2 * _N + 1])
    if plumb:
        h_all[2 * _N + 1 :] = (plumb_k * sigma_h_n, 0.0)
        v_all[2 * _N + 1 :] = vertical_n
    try:
        r, z, r_min, r_max, contact, run = _locate(
            h_all, v_all, weight_n_per_m, length_m, float(base[2]), floor_z_m
        )
    except (catenary.CatenaryError, ValueError, FloatingPointError) as exc:
        return LocalizationFailure(
            f"catenary failed for H={horizontal_n!r} N, T_v={vertical_n!r} N, "
            f"L={length_m!r} m: {exc}"
        )
    if not (np.isfinite(r).all() and np.isfinite(z).all()):
        return LocalizationFailure(
            f"non-finite catenary result for H={horizontal_n!r} N, T_v={vertical_n!r} N, "
            f"omega={weight_n_per_m!r} N/m, L={length_m!r} m"
        )

    if plumb:
        # Azimuth undetermined: straight above/below the base, horizontal std the
        # radius reachable at H = k sigma_H (including any slack on the floor).
        r_reach = float(max(r_max[2 * _N + 1], r[2 * _N + 1]))
        z_best = float(z[2 * _N + 2])
        dz = z[1 : 2 * _N + 1] - z[0]
        var_z = float(_SIGMA_WEIGHT * np.sum(dz * dz))
        position = np.array([base[0], base[1], z_best])
        pos_cov = np.diag([r_reach**2, r_reach**2, var_z])
        return PositionEstimate(
            position_world_m=_frozen(position),
            std_world_m=_frozen(np.sqrt(np.diag(pos_cov))),
            cov_world_m2=_frozen(pos_cov),
            radial_m=0.0,
            radial_interval_m=(0.0, r_reach),
            azimuth_rad=None,
            azimuth_determined=False,
            floor_contact=bool(contact[2 * _N + 2] > 0.5),
            floor_run_m=float(run[2 * _N + 2]),
            case="plumb",
        )

    # Direction from the base to the drone: opposite the horizontal pull.
    u0 = -T[:2] / horizontal_n
    positive = h_pts > 0.0
    u_pts = -pts[:, :2] / np.where(positive, h_pts, 1.0)[:, None]
    u_pts[~positive] = u0  # a sigma point at H = 0 keeps the estimate's direction
    n_pts = 2 * _N + 1
    p = np.empty((n_pts, 3))
    p[:, :2] = base[:2] + r[:n_pts, None] * u_pts
    p[:, 2] = z[:n_pts]
    d = p[1:] - p[0]
    pos_cov = _SIGMA_WEIGHT * (d.T @ d)  # unscented covariance about the estimate
    r0 = float(r[0])
    interval = (float(r_min[0]), float(r_max[0]))
    floor_contact = bool(contact[0] > 0.5)
    if floor_contact:
        # The 1-sigma radial extent covers the slack interval on either side.
        extent = max(r0 - interval[0], interval[1] - r0, 0.0)
        u3 = np.array([u0[0], u0[1], 0.0])
        pos_cov = pos_cov + extent**2 * np.outer(u3, u3)
    pos_cov = 0.5 * (pos_cov + pos_cov.T)
    position = p[0]
    std = np.sqrt(np.clip(np.diag(pos_cov), 0.0, None))
    if not (np.isfinite(position).all() and np.isfinite(pos_cov).all()):
        return LocalizationFailure(
            f"non-finite position for T={T.tolist()} N, L={length_m!r} m"
        )  # pragma: no cover - guarded above; kept so NaN can never leave
    return PositionEstimate(
        position_world_m=_frozen(position),
        std_world_m=_frozen(std),
        cov_world_m2=_frozen(pos_cov),
        radial_m=r0,
        radial_interval_m=interval,
        azimuth_rad=math.atan2(u0[1] + 0.0, u0[0]),  # + 0.0: no -pi from a -0.0
        azimuth_determined=True,
        floor_contact=floor_contact,
        floor_run_m=float(run[0]),
        case="floor" if floor_contact else "free",
    )


def localize(
    tension_world_n: ArrayLike | None,
    tension_cov_n2: ArrayLike,
    weight_n_per_m: float,
    length_m: float,
    base_world_m: ArrayLike,
    floor_z_m: float = -math.inf,
    plumb_k: float = PLUMB_K,
) -> PositionEstimate | None:
    """Like :func:`try_localize`, with None in place of a failure (never NaN).

    Args:
        tension_world_n: Force of the tether on the drone, world frame, N, shape (3,),
            or None.
        tension_cov_n2: Its covariance, N^2, shape (3, 3).
        weight_n_per_m: Tether weight per unit length, N/m.
        length_m: Tether length, m.
        base_world_m: Base exit position, world, m, shape (3,).
        floor_z_m: Floor height, m, or ``-inf``.
        plumb_k: See :data:`PLUMB_K`.

    Returns:
        The estimate, or None when there is no tension estimate or the math failed
        (:func:`try_localize` gives the reason).
    """
    out = try_localize(
        tension_world_n, tension_cov_n2, weight_n_per_m, length_m, base_world_m, floor_z_m, plumb_k
    )
    return out if isinstance(out, PositionEstimate) else None
