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

Cost: :func:`try_localize` runs once per telemetry message. Its 3-vector and 3x3
arithmetic is done in Python floats, and the one catenary call on the 7 (or 9) points
goes to ``catenary.locate_free``, the body of :func:`catenary.locate` without its input
checks, which this module has already made (see :func:`_locate_points`).
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


def _finite_floats(value: object, shape: tuple[int, ...]) -> list[float] | None:
    """The entries of a float64 array (or flat tuple/list) of ``shape``, if all finite.

    None for anything else; the caller then validates with numpy as it always did (and
    names the offending values).
    """
    kind = type(value)
    if kind is np.ndarray:
        if value.shape != shape or value.dtype != np.float64:  # type: ignore[attr-defined]
            return None
        flat: list[float] = value.ravel().tolist()  # type: ignore[attr-defined]
    elif (kind is tuple or kind is list) and len(shape) == 1 and len(value) == shape[0]:  # type: ignore[arg-type]
        try:
            flat = [float(v) for v in value]  # type: ignore[attr-defined]
        except (TypeError, ValueError):
            return None
    else:
        return None
    return flat if _all_finite(flat) else None


def _all_finite(values: list[float]) -> bool:
    """Whether every value is finite (one sum decides the common case: NaN or inf in
    any term makes it non-finite; only an overflowing sum needs the element check)."""
    return math.isfinite(sum(values)) or all(map(math.isfinite, values))


def _cholesky3(c: list[float]) -> list[float] | None:
    """Lower Cholesky factor of a symmetric 3x3 (row-major 9 floats), or None if not PD.

    ``np.linalg.cholesky`` up to rounding, without its per-call overhead.
    """
    c00, _, _, c10, c11, _, c20, c21, c22 = c
    if not c00 > 0.0:
        return None
    l00 = math.sqrt(c00)
    l10 = c10 / l00
    l20 = c20 / l00
    d1 = c11 - l10 * l10
    if not d1 > 0.0:
        return None
    l11 = math.sqrt(d1)
    l21 = (c21 - l20 * l10) / l11
    d2 = c22 - l20 * l20 - l21 * l21
    if not d2 > 0.0:
        return None
    return [l00, 0.0, 0.0, l10, l11, 0.0, l20, l21, math.sqrt(d2)]


def _locate_points(
    horizontal_n: FloatArray,
    vertical_n: FloatArray,
    weight_n_per_m: float,
    length_m: float,
    base_z_m: float,
    floor_z_m: float,
) -> tuple[list[float], list[float], list[float], list[float], list[float], list[float]]:
    """r, z, r_min, r_max, floor_contact (0/1), floor_run for the few points of one
    estimate, as lists of floats.

    The free-hanging solution comes first, and the floor-aware
    :func:`catenary.locate_with_floor` (twice the cost) only when some free solution comes
    within 1 um of the floor; away from the floor both give the same answer. The
    free-hanging solution comes from ``catenary.locate_free``, the body of
    :func:`catenary.locate` after its input checks: ``try_localize`` has already checked
    omega, L and z_i, and the caller checks H >= 0 and T_v finite for every point, so the
    checks (about two thirds of ``locate``'s cost on 7 points) would only repeat them.
    """
    a = horizontal_n / weight_n_per_m  # eq:a_param
    s2 = vertical_n / weight_n_per_m  # eq:s2_param
    r_arr, z_arr = catenary.locate_free(
        a, s2, np.asarray(length_m, dtype=np.float64), np.asarray(base_z_m, dtype=np.float64)
    )
    r: list[float] = r_arr.tolist()
    z: list[float] = z_arr.tolist()
    if floor_z_m != -math.inf:
        # Lowest point of the free curve (NOTES): the drone when s2 < 0, the base when
        # s2 > L, else the vertex, sqrt(a^2 + s2^2) - a below the drone.
        limit = floor_z_m + 1e-6
        hyp = np.hypot(a, s2).tolist()
        for ai, si, zi, hi in zip(a.tolist(), s2.tolist(), z, hyp, strict=True):
            lowest = zi if si < 0.0 else (base_z_m if si > length_m else zi - (hi - ai))
            if not lowest > limit:
                floor = _locate_floor(
                    horizontal_n, vertical_n, weight_n_per_m, length_m, base_z_m, floor_z_m
                )
                r, z, r_min, r_max, contact, run = (v.tolist() for v in floor)
                return r, z, r_min, r_max, contact, run
    zeros = [0.0] * len(r)
    return r, z, r, r, zeros, zeros


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
    # This runs once per telemetry message on 3-vectors and a 3x3: the arithmetic is on
    # Python floats, and numpy is kept for the one vectorised catenary call (7 or 9
    # points), where it pays. The formulas are those of the array version line for line.
    if tension_world_n is None:
        return LocalizationFailure("no tension estimate")
    t_in = _finite_floats(tension_world_n, (3,))
    c_in = _finite_floats(tension_cov_n2, (3, 3))
    b_in = _finite_floats(base_world_m, (3,))
    if t_in is None or c_in is None or b_in is None:
        T = np.asarray(tension_world_n, dtype=np.float64)
        cov_a = np.asarray(tension_cov_n2, dtype=np.float64)
        base_a = np.asarray(base_world_m, dtype=np.float64)
        if T.shape != (3,) or not np.isfinite(T).all():
            return LocalizationFailure(
                f"tension_world_n must be a finite 3-vector, got {T.tolist()}"
            )
        if cov_a.shape != (3, 3) or not np.isfinite(cov_a).all():
            return LocalizationFailure(f"tension_cov_n2 must be a finite 3x3, got {cov_a.tolist()}")
        if base_a.shape != (3,) or not np.isfinite(base_a).all():
            return LocalizationFailure(
                f"base_world_m must be a finite 3-vector, got {base_a.tolist()}"
            )
        t_in, c_in, b_in = T.tolist(), cov_a.ravel().tolist(), base_a.tolist()
    tx, ty, tz = t_in
    bx, by, bz = b_in
    if not (math.isfinite(weight_n_per_m) and weight_n_per_m > 0.0):
        return LocalizationFailure(f"weight_n_per_m must be finite and > 0, got {weight_n_per_m!r}")
    if not (math.isfinite(length_m) and length_m > 0.0):
        return LocalizationFailure(f"length_m must be finite and > 0, got {length_m!r}")
    if math.isnan(floor_z_m) or floor_z_m == math.inf:
        return LocalizationFailure(f"floor_z_m must be finite or -inf, got {floor_z_m!r}")
    if math.isfinite(floor_z_m) and bz < floor_z_m:
        return LocalizationFailure(f"base z {bz} m is below the floor {floor_z_m} m")
    # cov = (cov + cov') / 2
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = c_in
    cxy, cxz, cyz = 0.5 * (c01 + c10), 0.5 * (c02 + c20), 0.5 * (c12 + c21)
    cxx, cyy, czz = 0.5 * (c00 + c00), 0.5 * (c11 + c11), 0.5 * (c22 + c22)
    cov = [cxx, cxy, cxz, cxy, cyy, cyz, cxz, cyz, czz]

    # eq:a_param, eq:s2_param act through H and T_v (catenary.locate divides by omega).
    horizontal_n = math.hypot(tx, ty)
    vertical_n = -tz  # T_v: downward pull on the drone
    # sigma_H: the largest horizontal standard deviation, whatever the direction.
    lam_max = 0.5 * (cxx + cyy) + math.sqrt(max(0.25 * (cxx - cyy) ** 2 + cxy * cxy, 0.0))
    sigma_h_n = math.sqrt(max(lam_max, 0.0))
    plumb = horizontal_n <= max(plumb_k * sigma_h_n, MIN_HORIZONTAL_N)

    # All catenary evaluations in one vectorised call:
    #   0: the estimate; 1..6: sigma points T +- sqrt(3) S e_i; and when plumb,
    #   7: (k sigma_H, T_v), 8: (0, T_v).
    sq = _cholesky3(cov)
    if sq is None:  # singular (e.g. zero) covariance
        sq = _sqrt_psd(np.array(cov).reshape(3, 3)).ravel().tolist()
    # Points T, T + sqrt(3) S[:, i], T - sqrt(3) S[:, i] (i = 0, 1, 2), per coordinate.
    a0, a1, a2, b0, b1, b2, c0, c1, c2 = [_SIGMA_SCALE * v for v in sq]
    px = [tx, tx + a0, tx + a1, tx + a2, tx - a0, tx - a1, tx - a2]
    py = [ty, ty + b0, ty + b1, ty + b2, ty - b0, ty - b1, ty - b2]
    pz = [tz, tz + c0, tz + c1, tz + c2, tz - c0, tz - c1, tz - c2]
    n_pts = 2 * _N + 1
    h_arr = np.hypot(px, py)
    h_pts: list[float] = h_arr.tolist()
    v_all = [-v for v in pz]
    if plumb:  # the plumb points only when needed
        h_all = [*h_pts, plumb_k * sigma_h_n, 0.0]
        v_all += [vertical_n, vertical_n]
        h_arr = np.array(h_all)
    else:
        h_all = h_pts
    try:
        if not (_all_finite(h_all) and _all_finite(v_all)):
            # Out of the fast path's preconditions (overflow): catenary.locate says why.
            catenary.locate(h_all, v_all, weight_n_per_m, length_m, bz)
        r, z, r_min, r_max, contact, run = _locate_points(
            h_arr, np.array(v_all), weight_n_per_m, length_m, bz, floor_z_m
        )
    except (catenary.CatenaryError, ValueError, FloatingPointError) as exc:
        return LocalizationFailure(
            f"catenary failed for H={horizontal_n!r} N, T_v={vertical_n!r} N, "
            f"L={length_m!r} m: {exc}"
        )
    if not (_all_finite(r) and _all_finite(z)):
        return LocalizationFailure(
            f"non-finite catenary result for H={horizontal_n!r} N, T_v={vertical_n!r} N, "
            f"omega={weight_n_per_m!r} N/m, L={length_m!r} m"
        )

    if plumb:
        # Azimuth undetermined: straight above/below the base, horizontal std the
        # radius reachable at H = k sigma_H (including any slack on the floor).
        r_reach = max(r_max[n_pts], r[n_pts])
        z_best = z[n_pts + 1]
        var_z = 0.0
        for zi in z[1:n_pts]:
            var_z += (zi - z[0]) * (zi - z[0])
        var_z = _SIGMA_WEIGHT * var_z
        pos_cov = [r_reach**2, 0.0, 0.0, 0.0, r_reach**2, 0.0, 0.0, 0.0, var_z]
        return PositionEstimate(
            position_world_m=_frozen([bx, by, z_best]),
            std_world_m=_frozen([math.sqrt(pos_cov[0]), math.sqrt(pos_cov[4]), math.sqrt(var_z)]),
            cov_world_m2=_frozen(np.array(pos_cov).reshape(3, 3)),
            radial_m=0.0,
            radial_interval_m=(0.0, r_reach),
            azimuth_rad=None,
            azimuth_determined=False,
            floor_contact=bool(contact[n_pts + 1] > 0.5),
            floor_run_m=float(run[n_pts + 1]),
            case="plumb",
        )

    # Direction from the base to the drone: opposite the horizontal pull.
    u0x, u0y = -tx / horizontal_n, -ty / horizontal_n
    # The estimate's position p_0 (h_pts[0] = H > 0 here), then the unscented covariance
    # about it, W sum_i d_i d_i' with d_i = p_i - p_0 over the sigma points (a sigma point
    # at H = 0 keeps the estimate's direction).
    r0 = r[0]
    x0, y0, z0 = bx + r0 * (-tx / h_pts[0]), by + r0 * (-ty / h_pts[0]), z[0]
    sxx = sxy = sxz = syy = syz = szz = 0.0
    for xi, yi, hi, ri, zi in zip(px[1:], py[1:], h_pts[1:], r[1:n_pts], z[1:n_pts], strict=True):
        if hi > 0.0:
            dx, dy = (bx + ri * (-xi / hi)) - x0, (by + ri * (-yi / hi)) - y0
        else:
            dx, dy = (bx + ri * u0x) - x0, (by + ri * u0y) - y0
        dz = zi - z0
        sxx += dx * dx
        sxy += dx * dy
        sxz += dx * dz
        syy += dy * dy
        syz += dy * dz
        szz += dz * dz
    w = _SIGMA_WEIGHT
    sxx, sxy, sxz, syy, syz, szz = w * sxx, w * sxy, w * sxz, w * syy, w * syz, w * szz
    interval = (r_min[0], r_max[0])
    floor_contact = bool(contact[0] > 0.5)
    if floor_contact:
        # The 1-sigma radial extent covers the slack interval on either side.
        extent2 = max(r0 - interval[0], interval[1] - r0, 0.0) ** 2
        sxx += extent2 * (u0x * u0x)
        sxy += extent2 * (u0x * u0y)
        syy += extent2 * (u0y * u0y)
    pos_cov = [sxx, sxy, sxz, sxy, syy, syz, sxz, syz, szz]
    position = [x0, y0, z0]
    if not (all(map(math.isfinite, position)) and all(map(math.isfinite, pos_cov))):
        return LocalizationFailure(
            f"non-finite position for T={[tx, ty, tz]} N, L={length_m!r} m"
        )  # pragma: no cover - guarded above; kept so NaN can never leave
    std = [math.sqrt(max(v, 0.0)) for v in (sxx, syy, szz)]
    return PositionEstimate(
        position_world_m=_frozen(position),
        std_world_m=_frozen(std),
        cov_world_m2=_frozen(np.array(pos_cov).reshape(3, 3)),
        radial_m=r0,
        radial_interval_m=interval,
        azimuth_rad=math.atan2(u0y + 0.0, u0x),  # + 0.0: no -pi from a -0.0
        azimuth_determined=True,
        floor_contact=floor_contact,
        floor_run_m=run[0],
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
