"""3-D drone position from the estimated tether tension and the base (paper sec. pos_est).

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

* **Azimuth from every source.** The paper took beta from motion capture. The horizontal
  tension on the drone points from the drone to the base, so the estimate carries its own
  azimuth, ``-T_xy / |T_xy|``, with a standard deviation of the sideways tension noise over
  H. A base that measures the tether's exit azimuth gives another, independent of the
  drone's sensors. ``azimuth="auto"`` fuses the two by inverse variance; ``"tension"``,
  ``"reel"`` and ``"mocap"`` (the paper's: beta from the motion-capture position) use one.
* **Exit elevation.** With L known, the slope where the tether leaves the base,
  ``theta = atan2(s2 - L, a)``, is one more equation in (a, s2): the base alone fixes the
  catenary up to its sag, and the tension fixes the rest; both are fused by their
  covariance (:func:`_fuse_elevation`) while no tether rests on the floor.
* **Near-plumb tether, continuously.** When the azimuth's standard deviation exceeds
  ``1 / plumb_k`` rad (for the tension alone: H within ``plumb_k`` standard deviations of
  its noise) the result says so (``azimuth_determined=False``). The horizontal offset
  ``r u(beta)`` is blended toward the base's xy as that standard deviation grows (1 at
  ``1 / (2 k)``, 0 at ``2 / k``, smoothstep between), and the horizontal uncertainty widens
  with it to the radius the tether could reach at a horizontal tension ``plumb_k``
  standard deviations above zero: no jump between the two near r = 0.2 m. The paper's
  filter, started from T = 0, was always in this case at first and reported z = 0.754 -
  1.6 = -0.846 m (``eq:in_instants``); the tension filter of this project starts from the
  first observation instead.
* **Uncertainty.** The tension covariance is carried to (r, z), and with the tension's
  azimuth to the horizontal position, by the unscented transform (7 sigma points,
  kappa = 0) through the closed-form catenary of each, so the large non-linearity of r in H
  near a taut tether, and the correlation of r with the direction under an anisotropic
  noise, are respected; the other azimuth sources add their variance across.

Cost: :func:`try_localize` runs once per telemetry message, on 3-vectors and a 3x3, all in
Python floats (numpy's ~1 us per call would cost more than the arithmetic): the catenary of
each sigma point is ``catenary.locate_free_floats`` (``locate_with_floor_floats`` near the
floor), the body of :func:`catenary.locate` without its input checks, which this module has
already made. The common case (a freely hanging tether, the azimuth from the tension alone
and certain) is ``_localize_tension_free``: the general path's operations less those whose
result it knows (terms weighted by 0, the reach at ``k sigma_H``), the same floats
(``tests/test_localization_fast.py``). :func:`try_localize_batch` does many messages at once
over arrays (the service's batched drain), with the same results to the bit (its ``hypot``
is ``math.hypot``'s, :func:`_hypot`); numpy's per-call overhead is then paid once per batch.
"""

from __future__ import annotations

import math
import struct
import sys
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from groundstation import catenary

__all__ = [
    "AZIMUTH_MODES",
    "PLUMB_K",
    "AngleObservation",
    "AzimuthMode",
    "LocalizationFailure",
    "PositionEstimate",
    "localize",
    "localize_batch",
    "try_localize",
    "try_localize_batch",
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

_FLOAT64 = np.dtype(np.float64)
_ndarray = np.ndarray
_N = 3  # state dimension of the unscented transform
_SIGMA_SCALE = math.sqrt(_N)  # sqrt(n + kappa), kappa = 0
_SIGMA_WEIGHT = 1.0 / (2 * _N)
_SIGMA_SCALE_2D = math.sqrt(2.0)  # the elevation fusion's: sqrt(n + kappa), n = 2, kappa = 0
_SIGMA_WEIGHT_2D = 1.0 / (2 * 2)  # 1 / (2 n), n = 2
PLUMB_BLEND_RATIO = 2.0
"""The plumb blend spans this factor either side of the determined limit ``1 / plumb_k``
(on a log scale, around it): full while the azimuth's standard deviation is at most
``1 / (ratio·plumb_k)`` rad (half the limit; the tension-free localization takes the
tension's direction only below the same), zero from ``ratio / plumb_k`` (twice it). One
value where there were two (0.5 and 2.0 over ``plumb_k``: the same band)."""


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
        case: ``"free"``, ``"floor"`` or ``"plumb"`` (azimuth undetermined).
        azimuth_std_rad: Standard deviation of the fused azimuth, rad (inf without a
            source); the horizontal offset is ``exp(-std^2 / 2) r`` along it.
        azimuth_source: The most certain source of the azimuth: ``"tension"``,
            ``"reel"``, ``"mocap"``, or ``"none"``.
        elevation_used: The reel's exit elevation was fused into (a, s2).
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
    azimuth_std_rad: float = math.inf
    azimuth_source: str = "tension"
    elevation_used: bool = False


@dataclass(frozen=True)
class LocalizationFailure:
    """Why no position could be computed.

    Attributes:
        reason: Human-readable reason naming the offending values.
    """

    reason: str


_new_object = object.__new__
_set_attr = object.__setattr__
_pack15 = struct.Struct("=15d").pack
_SHAPE_3X3 = (3, 3)


def _frozen_arrays(*values: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Position (3), std (3) and covariance (3x3, row-major) from 15 floats, read-only.

    Views of one array over an immutable bytes object, read-only from the start: where
    ``np.array`` and ``setflags`` per array cost ~1 us each on the per-message path, this
    is one array and three slices.
    """
    buf = np.frombuffer(_pack15(*values))
    return buf[:3], buf[3:6], buf[6:].reshape(_SHAPE_3X3)


def _estimate(fields: dict[str, object]) -> PositionEstimate:
    """``PositionEstimate(**fields)`` with every field given, without the frozen
    dataclass's ``__init__``, which sets each field through ``object.__setattr__`` (~0.1 us
    a field, 13 fields, once per message). The result is an ordinary, equal instance."""
    obj: PositionEstimate = _new_object(PositionEstimate)
    _set_attr(obj, "__dict__", fields)
    return obj


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
        # `is` first: the builtin dtypes are singletons (an unpickled array's is not), and
        # comparing with the dtype, not np.float64, spares a conversion.
        dtype = value.dtype  # type: ignore[attr-defined]
        if (dtype is not _FLOAT64 and dtype != _FLOAT64) or value.shape != shape:  # type: ignore[attr-defined]
            return None
        flat: list[float] = value.tolist() if len(shape) == 1 else value.ravel().tolist()  # type: ignore[attr-defined]
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
    horizontal_n: list[float],
    vertical_n: list[float],
    weight_n_per_m: float,
    length_m: float,
    base_z_m: float,
    floor_z_m: float,
) -> tuple[list[float], list[float], list[float], list[float], list[bool], list[float]]:
    """r, z, r_min, r_max, floor_contact, floor_run for the few points of one estimate.

    The free-hanging solution comes first, and the floor-aware one
    (:func:`catenary.locate_with_floor_floats`) only when some free solution comes within
    1 um of the floor; away from the floor both give the same answer. Both are the
    catenary's float versions, without input checks: ``try_localize`` has already checked
    omega, L and z_i, and the caller checks H >= 0 and T_v finite for every point.
    """
    a = [h / weight_n_per_m for h in horizontal_n]  # eq:a_param
    s2 = [v / weight_n_per_m for v in vertical_n]  # eq:s2_param
    r, z = catenary.locate_free_floats(a, s2, length_m, base_z_m)
    if floor_z_m != -math.inf:
        # Lowest point of the free curve (NOTES): the drone when s2 < 0, the base when
        # s2 > L, else the vertex, sqrt(a^2 + s2^2) - a below the drone.
        limit = floor_z_m + 1e-6
        hypot = math.hypot
        for ai, si, zi in zip(a, s2, z, strict=True):
            lowest = zi if si < 0.0 else (base_z_m if si > length_m else zi - (hypot(ai, si) - ai))
            if not lowest > limit:
                return catenary.locate_with_floor_floats(
                    horizontal_n, vertical_n, weight_n_per_m, length_m, base_z_m, floor_z_m
                )
    zeros = [0.0] * len(r)
    return r, z, r, r, [False] * len(r), zeros


@dataclass(frozen=True)
class AngleObservation:
    """An angle measured at the base, with its standard deviation.

    Attributes:
        value_rad: The angle, rad.
        std_rad: Its standard deviation, rad, > 0.
    """

    value_rad: float
    std_rad: float


AzimuthMode = Literal["auto", "tension", "reel", "mocap"]
"""Which sources give the azimuth: ``auto`` fuses the tension's direction and the reel's
exit azimuth by their uncertainty; ``tension``, ``reel``, ``mocap`` use that one alone
(``mocap``: the paper's method, beta from the motion-capture position)."""

AZIMUTH_MODES: tuple[AzimuthMode, ...] = ("auto", "tension", "reel", "mocap")


def _valid_angle(obs: AngleObservation | None) -> AngleObservation | None:
    if obs is None:
        return None
    if math.isfinite(obs.value_rad) and math.isfinite(obs.std_rad) and obs.std_rad > 0.0:
        return obs
    return None


def _wrap(angle_rad: float) -> float:
    """Angle wrapped to [-pi, pi)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


def _fuse_angles(
    sources: list[tuple[str, float, float]],
) -> tuple[float, float, str]:
    """Inverse-variance fusion of azimuths ``(name, value_rad, std_rad)``.

    In the tangent space about the most certain source (the azimuths agree to well within
    a radian whenever fusing them matters): ``beta = beta_0 + sum w_i wrap(beta_i - beta_0)
    / sum w_i``, ``w_i = 1 / std_i^2``, ``std = (sum w_i)^-1/2``.

    Returns:
        ``(beta_rad, std_rad, name of the most certain source)``; ``(0, inf, "none")``
        without a source.
    """
    usable = [s for s in sources if math.isfinite(s[1]) and s[2] < math.inf]
    if not usable:
        return 0.0, math.inf, "none"
    usable.sort(key=lambda s: s[2])
    name0, beta0, std0 = usable[0]
    if not std0 > 0.0:  # an exact source: nothing else counts
        return beta0, 0.0, name0
    # Weights relative to the best source's (w_0 = 1), so no 1 / std^2 overflows.
    w_sum = 0.0
    d_sum = 0.0
    for _, beta, std in usable:
        w = (std0 / std) ** 2
        w_sum += w
        d_sum += w * _wrap(beta - beta0)
    beta = beta0 + d_sum / w_sum
    return math.atan2(math.sin(beta), math.cos(beta)), std0 / math.sqrt(w_sum), name0


def _blend(x: float, full: float, none: float) -> float:
    """1 for ``x <= full``, 0 for ``x >= none``, smoothstep (3t^2 - 2t^3) between."""
    if x <= full:
        return 1.0
    if not x < none:
        return 0.0
    t = (none - x) / (none - full)
    return t * t * (3.0 - 2.0 * t)


def _fuse_elevation(
    a_m: float,
    s2_m: float,
    cov_as_m2: tuple[float, float, float],
    length_m: float,
    elevation: AngleObservation,
) -> tuple[float, float, tuple[float, float, float]] | None:
    """Catenary parameters ``(a, s2)`` from the tension, refined by the base's exit slope.

    The tether leaves the base at signed arc length ``s2 - L`` from the lowest point, so
    its slope there is ``(s2 - L) / a`` (eq:cat_expression differentiated; NOTES "Tension
    along the tether"): ``theta = atan2(s2 - L, a)``. With L known this is one equation in
    the two unknowns: the base alone fixes the catenary up to its sag (from the straight
    line at theta, a -> inf, to the plumb hang above the base, a -> 0), and the tension's
    ``(a, s2)`` (eq:a_param, eq:s2_param) with their covariance fix the rest. Gauss-Newton
    on ``|x - x_T|^2_{P_T^-1} + (theta(x) - theta_m)^2 / sigma_theta^2``, x = (a, s2).

    Args:
        a_m: ``H / omega`` from the tension, m.
        s2_m: ``T_v / omega`` from the tension, m.
        cov_as_m2: Covariance of (a, s2) from the tension, ``(var_a, cov, var_s2)``, m^2.
        length_m: Tether length, m.
        elevation: The measured exit elevation and its standard deviation, rad.

    Returns:
        ``(a, s2, (var_a, cov, var_s2))`` after fusion, or None when the tension's
        covariance is not positive definite (an exact tension needs no help) or the
        iteration leaves the domain.
    """
    paa, pas, pss = cov_as_m2
    det = paa * pss - pas * pas
    if not (paa > 0.0 and pss > 0.0 and det > 1e-30 * paa * pss):
        return None
    # P_T^-1
    iaa, ias, iss = pss / det, -pas / det, paa / det
    w_theta = 1.0 / (elevation.std_rad * elevation.std_rad)
    a, s2 = a_m, s2_m
    tiny = 1e-9 * length_m
    for _ in range(20):
        a = max(a, tiny)
        y = s2 - length_m
        d2 = a * a + y * y
        ja, js = -y / d2, a / d2  # d theta / d(a, s2)
        e = _wrap(elevation.value_rad - math.atan2(y, a))
        # (P_T^-1 + J' J w) dx = P_T^-1 (x_T - x) + J' w e
        naa, nas, nss = iaa + w_theta * ja * ja, ias + w_theta * ja * js, iss + w_theta * js * js
        da0, ds0 = a_m - a, s2_m - s2
        ga = iaa * da0 + ias * ds0 + w_theta * ja * e
        gs = ias * da0 + iss * ds0 + w_theta * js * e
        ndet = naa * nss - nas * nas
        if not (ndet > 0.0 and math.isfinite(ndet)):
            return None
        step_a = (nss * ga - nas * gs) / ndet
        step_s = (naa * gs - nas * ga) / ndet
        a, s2 = a + step_a, s2 + step_s
        if abs(step_a) + abs(step_s) < 1e-12 * length_m:
            break
    a = max(a, tiny)
    y = s2 - length_m
    d2 = a * a + y * y
    ja, js = -y / d2, a / d2
    naa, nas, nss = iaa + w_theta * ja * ja, ias + w_theta * ja * js, iss + w_theta * js * js
    ndet = naa * nss - nas * nas
    if not (ndet > 0.0 and math.isfinite(a) and math.isfinite(s2)):
        return None
    return a, s2, (nss / ndet, -nas / ndet, naa / ndet)


def try_localize(
    tension_world_n: ArrayLike | None,
    tension_cov_n2: ArrayLike,
    weight_n_per_m: float,
    length_m: float,
    base_world_m: ArrayLike,
    floor_z_m: float = -math.inf,
    plumb_k: float = PLUMB_K,
    *,
    azimuth: AzimuthMode = "auto",
    exit_azimuth: AngleObservation | None = None,
    exit_elevation: AngleObservation | None = None,
    mocap_world_m: ArrayLike | None = None,
    mocap_std_m: float = 0.002,
    model_var_n2: tuple[float, float, float] | None = None,
) -> PositionEstimate | LocalizationFailure:
    """Drone position and its uncertainty from the tension at the drone and the base.

    Args:
        tension_world_n: Force of the tether on the drone, world frame, N, shape (3,),
            or None when there is no estimate.
        tension_cov_n2: Its covariance, N^2, shape (3, 3) (symmetric PSD; tiny
            negative eigenvalues from rounding are clipped).
        weight_n_per_m: Tether weight per unit length omega, N/m, > 0.
        length_m: Tether length from the base exit to the drone, m, > 0.
        base_world_m: Base (tether exit) position, world, m, shape (3,).
        floor_z_m: Height of the floor a slack tether rests on, m; ``-inf`` for none.
        plumb_k: The azimuth counts as determined while its standard deviation is at
            most ``1 / plumb_k`` rad (for the tension's direction: H above ``plumb_k``
            standard deviations of H; see :data:`PLUMB_K`).
        azimuth: Which sources give the azimuth (:data:`AzimuthMode`).
        exit_azimuth: The reel's exit azimuth (base -> drone, world), or None.
        exit_elevation: The reel's exit elevation above horizontal, or None; fused with
            the tension in the catenary's parameters while no tether rests on the floor.
        mocap_world_m: Motion-capture position, world, m, shape (3,), for
            ``azimuth="mocap"``; None otherwise.
        mocap_std_m: Its horizontal standard deviation, m, > 0.
        model_var_n2: Variance per world axis of an error of the tension that holds still
            from sample to sample (the calibration's misfit, ``[calibration]
            tension_model_std_n`` squared), N², finite and >= 0; None: none. It widens the
            position's covariance (the sigma points are drawn from ``tension_cov_n2`` plus
            it) but not the azimuth's determination nor the blend to the base, which ask
            whether the *noise* turns the pull's direction from sample to sample; a still
            error's direction is a bias the blend would not take out (on the realistic
            simulator calibrated by ``calibrate``, blending on it too lost 5.7 cm of median
            position for nothing: ``python -m benchmarks.bench_powerons``).

    Returns:
        The estimate, or a :class:`LocalizationFailure` with the reason. Never NaN.
    """
    return _try_localize(
        tension_world_n,
        tension_cov_n2,
        weight_n_per_m,
        length_m,
        base_world_m,
        floor_z_m,
        plumb_k,
        azimuth,
        exit_azimuth,
        exit_elevation,
        mocap_world_m,
        mocap_std_m,
        model_var_n2,
    )


def _try_localize(
    tension_world_n: ArrayLike | None,
    tension_cov_n2: ArrayLike,
    weight_n_per_m: float,
    length_m: float,
    base_world_m: ArrayLike,
    floor_z_m: float,
    plumb_k: float,
    azimuth: AzimuthMode,
    exit_azimuth: AngleObservation | None,
    exit_elevation: AngleObservation | None,
    mocap_world_m: ArrayLike | None,
    mocap_std_m: float,
    model_var_n2: tuple[float, float, float] | None = None,
) -> PositionEstimate | LocalizationFailure:
    """:func:`try_localize`, its arguments by position (``localize`` calls it too)."""
    # This runs once per telemetry message on 3-vectors and a 3x3: the arithmetic is on
    # Python floats (numpy's ~1 us per call would cost more than the arithmetic), and the
    # common case (_localize_tension_free) leaves out what it knows the result of. Its
    # inputs as the pipeline gives them (float64 arrays, float scalars) are read and
    # checked here at the least cost; anything else takes the general path below.
    T = tension_world_n
    C = tension_cov_n2
    B = base_world_m
    mx = my = mz = 0.0
    model_ok = True
    if model_var_n2 is not None:
        mx, my, mz = model_var_n2
        model_ok = mx >= 0.0 and my >= 0.0 and mz >= 0.0 and math.isfinite(mx + my + mz)
    if (
        type(T) is _ndarray
        and type(C) is _ndarray
        and type(B) is _ndarray
        and T.dtype is _FLOAT64
        and C.dtype is _FLOAT64
        and B.dtype is _FLOAT64
        and T.shape == (3,)
        and C.shape == (3, 3)
        and B.shape == (3,)
        and isinstance(weight_n_per_m, float)  # float or np.float64
        and isinstance(length_m, float)
        and isinstance(floor_z_m, float)
        and isinstance(plumb_k, float)
        and (
            azimuth == "tension"
            or (azimuth == "auto" and (exit_azimuth is None or _valid_angle(exit_azimuth) is None))
        )
        and (exit_elevation is None or _valid_angle(exit_elevation) is None)
    ):
        tx, ty, tz = T.tolist()
        (c00, c01, c02), (c10, c11, c12), (c20, c21, c22) = C.tolist()
        bx, by, bz = B.tolist()
        # Python floats (an np.float64 omega would make every result an np.float64)
        weight_n_per_m, length_m = float(weight_n_per_m), float(length_m)
        floor_z_m, plumb_k = float(floor_z_m), float(plumb_k)
        # The general path's checks, all passed (a non-finite sum: some value is not
        # finite, or the sum overflows; the general path tells which).
        if (
            math.isfinite(
                tx + ty + tz + bx + by + bz + c00 + c01 + c02 + c10 + c11 + c12 + c20 + c21 + c22
            )
            and model_ok
            and 0.0 < weight_n_per_m < math.inf
            and 0.0 < length_m < math.inf
            and (floor_z_m == -math.inf or (math.isfinite(floor_z_m) and not bz < floor_z_m))
        ):
            common = _localize_tension_free(
                tx, ty, tz,
                0.5 * (c00 + c00), 0.5 * (c01 + c10), 0.5 * (c02 + c20),
                0.5 * (c11 + c11), 0.5 * (c12 + c21), 0.5 * (c22 + c22),
                weight_n_per_m, length_m, bx, by, bz, floor_z_m, plumb_k, mx, my, mz,
            )  # fmt: skip
            if common is not None:
                return common
    if tension_world_n is None:
        return LocalizationFailure("no tension estimate")
    if azimuth not in AZIMUTH_MODES:
        return LocalizationFailure(f"azimuth must be one of {AZIMUTH_MODES}, got {azimuth!r}")
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
    if not model_ok:
        return LocalizationFailure(f"model_var_n2 must be finite and >= 0, got {[mx, my, mz]!r}")
    # cov = (cov + cov') / 2
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = c_in
    cxy, cxz, cyz = 0.5 * (c01 + c10), 0.5 * (c02 + c20), 0.5 * (c12 + c21)
    cxx, cyy, czz = 0.5 * (c00 + c00), 0.5 * (c11 + c11), 0.5 * (c22 + c22)
    # Python floats from here on, as numpy's .tolist() gave them before (an np.float64
    # omega would make every result an np.float64).
    weight_n_per_m, length_m = float(weight_n_per_m), float(length_m)
    floor_z_m, plumb_k = float(floor_z_m), float(plumb_k)

    # eq:a_param, eq:s2_param act through H and T_v (catenary.locate divides by omega).
    horizontal_n = math.hypot(tx, ty)
    vertical_n = -tz  # T_v: downward pull on the drone
    # sigma_H: the largest horizontal standard deviation, whatever the direction.
    lam_max = 0.5 * (cxx + cyy) + math.sqrt(max(0.25 * (cxx - cyy) ** 2 + cxy * cxy, 0.0))
    sigma_h_n = math.sqrt(max(lam_max, 0.0))

    # All catenary evaluations in one vectorised call:
    #   0: the estimate; 1..6: sigma points T +- sqrt(3) S e_i (S S' = cov + the model's
    #   variance); 7: (k sigma_H, T_v), the reach of a tether whose azimuth is unknown.
    cov_points = [cxx + mx, cxy, cxz, cxy, cyy + my, cyz, cxz, cyz, czz + mz]
    sq = _cholesky3(cov_points)
    if sq is None:  # singular (e.g. zero) covariance
        sq = _sqrt_psd(np.array(cov_points).reshape(3, 3)).ravel().tolist()
    # Points T, T + sqrt(3) S[:, i], T - sqrt(3) S[:, i] (i = 0, 1, 2), per coordinate.
    a0, a1, a2, b0, b1, b2, c0, c1, c2 = [_SIGMA_SCALE * v for v in sq]
    px = [tx, tx + a0, tx + a1, tx + a2, tx - a0, tx - a1, tx - a2]
    py = [ty, ty + b0, ty + b1, ty + b2, ty - b0, ty - b1, ty - b2]
    pz = [tz, tz + c0, tz + c1, tz + c2, tz - c0, tz - c1, tz - c2]
    n_pts = 2 * _N + 1
    hypot = math.hypot
    h_pts = [hypot(x, y) for x, y in zip(px, py, strict=True)]
    h_all = [*h_pts, max(plumb_k * sigma_h_n, horizontal_n)]
    v_all = [-v for v in pz]
    v_all.append(vertical_n)
    try:
        if not (_all_finite(h_all) and _all_finite(v_all)):
            # Out of the fast path's preconditions (overflow): catenary.locate says why.
            catenary.locate(h_all, v_all, weight_n_per_m, length_m, bz)
        r, z, r_min, r_max, contact, run = _locate_points(
            h_all, v_all, weight_n_per_m, length_m, bz, floor_z_m
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

    # (r, z) and their covariance from the tension's sigma points (unscented transform).
    r0, z0 = max(r[0], 0.0), z[0]  # r >= 0 (rounding gives -1e-306 at H ~ 1e-308)
    var_r = cov_rz = var_z = 0.0
    for ri, zi in zip(r[1:n_pts], z[1:n_pts], strict=True):
        dr, dz = ri - r0, zi - z0
        var_r += dr * dr
        cov_rz += dr * dz
        var_z += dz * dz
    var_r, cov_rz, var_z = _SIGMA_WEIGHT * var_r, _SIGMA_WEIGHT * cov_rz, _SIGMA_WEIGHT * var_z
    r_reach = max(r_max[n_pts], r[n_pts])
    interval = (r_min[0], r_max[0])
    floor_contact = contact[0]
    floor_run_m = run[0]

    # The base's exit elevation refines (a, s2) while the tether hangs free.
    elevation = _valid_angle(exit_elevation)
    elevation_used = False
    if elevation is not None and not floor_contact:
        if horizontal_n > MIN_HORIZONTAL_N:
            hx, hy = tx / horizontal_n, ty / horizontal_n
            var_h = hx * hx * cxx + 2.0 * hx * hy * cxy + hy * hy * cyy
            cov_hv = -(hx * cxz + hy * cyz)
        else:
            var_h, cov_hv = lam_max, 0.0
        w2 = weight_n_per_m * weight_n_per_m
        fused = _fuse_elevation(
            horizontal_n / weight_n_per_m,
            vertical_n / weight_n_per_m,
            (var_h / w2, cov_hv / w2, czz / w2),
            length_m,
            elevation,
        )
        if fused is not None:
            stats = _free_stats(fused, weight_n_per_m, length_m, bz, floor_z_m)
            if stats is not None:
                r0, z0, var_r, cov_rz, var_z = stats
                interval = (r0, r0)
                elevation_used = True

    # The azimuth from every source asked for, fused by its uncertainty.
    sources: list[tuple[str, float, float]] = []
    source_t = azimuth in ("auto", "tension") and horizontal_n > MIN_HORIZONTAL_N
    beta_t = std_t = math.inf
    if source_t:
        # Opposite the horizontal pull; its std is the pull's sideways std over H.
        ux_t, uy_t = -tx / horizontal_n, -ty / horizontal_n
        var_side = uy_t * uy_t * cxx - 2.0 * ux_t * uy_t * cxy + ux_t * ux_t * cyy
        std_t = math.sqrt(max(var_side, 0.0)) / horizontal_n
        beta_t = math.atan2(uy_t + 0.0, ux_t)  # + 0.0: no -pi from a -0.0
        sources.append(("tension", beta_t, std_t))
    reel_az = _valid_angle(exit_azimuth)
    if azimuth in ("auto", "reel") and reel_az is not None:
        sources.append(("reel", reel_az.value_rad, reel_az.std_rad))
    if azimuth == "mocap" and mocap_world_m is not None:
        m_in = _finite_floats(mocap_world_m, (3,))
        if m_in is not None and math.isfinite(mocap_std_m) and mocap_std_m > 0.0:
            dx_m, dy_m = m_in[0] - bx, m_in[1] - by
            r_m = math.hypot(dx_m, dy_m)
            if r_m > 0.0:
                sources.append(("mocap", math.atan2(dy_m, dx_m), mocap_std_m / r_m))
    beta, std_beta, source = _fuse_angles(sources)
    determined = std_beta <= 1.0 / plumb_k

    # The horizontal offset: r u(beta_hat) while the azimuth is certain, blended to the
    # base's xy as it is lost, with a weight rho that falls smoothly (C1) from 1 at
    # std = 1 / (2 k) to 0 at std = 2 / k, so the position never jumps between the two at
    # a plumb threshold (a fixed threshold did, near r = 0.2 m). Not rho = exp(-std^2 / 2),
    # the mean of a wrapped normal: it would bias every determined estimate a little, and
    # the tension's linearised std (sideways sigma / H) says too little when H ~ sigma.
    rho = _blend(std_beta, 1.0 / (PLUMB_BLEND_RATIO * plumb_k), PLUMB_BLEND_RATIO / plumb_k)
    ux, uy = math.cos(beta), math.sin(beta)
    vx, vy = -uy, ux
    # Covariance with the azimuth known (cov_det): the unscented transform over the
    # tension's sigma points, each with its own r, z and (through the tension's share
    # w_t of the fused azimuth) its own azimuth, so the correlation of r with the
    # direction under an anisotropic tension noise is kept; the other sources' share of
    # the azimuth variance adds across.
    if source_t and std_t > 0.0:
        w_t = (std_beta / std_t) ** 2
        var_other = max(std_beta * std_beta - w_t * w_t * std_t * std_t, 0.0)
    elif source_t:
        # The tension's azimuth without noise across it holds all the weight (its sigma
        # points may still spread across it: the model's variance).
        w_t, var_other = 1.0, 0.0
    else:
        w_t = 0.0
        var_other = std_beta * std_beta if std_beta < math.inf else 0.0
    if elevation_used or not source_t:
        # (r, z) from the fused (a, s2): no sigma points to carry the direction with; the
        # whole azimuth variance goes across.
        k_uu = var_r
        k_vv = r0 * r0 * (std_beta * std_beta if std_beta < math.inf else 0.0)
        dxx = k_uu * ux * ux + k_vv * vx * vx
        dyy = k_uu * uy * uy + k_vv * vy * vy
        dxy = k_uu * ux * uy + k_vv * vx * vy
        dxz, dyz = cov_rz * ux, cov_rz * uy
    else:
        hx0, hy0 = r0 * ux, r0 * uy
        dxx = dxy = dyy = dxz = dyz = 0.0
        for xi, yi, hi, ri, zi in zip(
            px[1:], py[1:], h_pts[1:], r[1:n_pts], z[1:n_pts], strict=True
        ):
            if not hi > 0.0:
                cx, cy = ux, uy
            elif w_t == 1.0:
                # The tension alone (beta = beta_t): beta_i is the point's own azimuth,
                # whose cosine and sine are -x_i / h_i and -y_i / h_i.
                cx, cy = -xi / hi, -yi / hi
            else:
                beta_i = beta + w_t * _wrap(math.atan2(-yi + 0.0, -xi) - beta_t)
                cx, cy = math.cos(beta_i), math.sin(beta_i)
            dx, dy = ri * cx - hx0, ri * cy - hy0
            dz = zi - z[0]
            dxx += dx * dx
            dxy += dx * dy
            dyy += dy * dy
            dxz += dx * dz
            dyz += dy * dz
        w = _SIGMA_WEIGHT
        dxx, dxy, dyy, dxz, dyz = w * dxx, w * dxy, w * dyy, w * dxz, w * dyz
        k_vv = r0 * r0 * var_other
        dxx += k_vv * vx * vx
        dyy += k_vv * vy * vy
        dxy += k_vv * vx * vy
    if floor_contact:
        # The 1-sigma radial extent covers the slack interval on either side.
        extent2 = max(r0 - interval[0], interval[1] - r0, 0.0) ** 2
        dxx += extent2 * ux * ux
        dxy += extent2 * ux * uy
        dyy += extent2 * uy * uy
    # Covariance with the azimuth unknown: per axis, the radius the tether reaches at
    # H = k sigma_H (slack on the floor included). The two blend with rho, as the mean.
    undet = max(r_reach * r_reach, r0 * r0 + var_r)
    mean_r = rho * r0
    sxx = rho * dxx + (1.0 - rho) * undet
    syy = rho * dyy + (1.0 - rho) * undet
    sxy = rho * dxy
    sxz, syz = rho * dxz, rho * dyz
    pos_cov = [sxx, sxy, sxz, sxy, syy, syz, sxz, syz, var_z]
    position = [bx + mean_r * ux, by + mean_r * uy, z0]
    if not (all(map(math.isfinite, position)) and all(map(math.isfinite, pos_cov))):
        return LocalizationFailure(
            f"non-finite position for T={[tx, ty, tz]} N, L={length_m!r} m"
        )  # pragma: no cover - guarded above; kept so NaN can never leave
    std = [math.sqrt(max(v, 0.0)) for v in (sxx, syy, var_z)]
    if not determined:
        interval = (0.0, max(r_reach, interval[1]))
    position_arr, std_arr, cov_arr = _frozen_arrays(*position, *std, *pos_cov)
    return _estimate(
        {
            "position_world_m": position_arr,
            "std_world_m": std_arr,
            "cov_world_m2": cov_arr,
            "radial_m": r0,
            "radial_interval_m": interval,
            "azimuth_rad": beta if determined else None,
            "azimuth_determined": determined,
            "floor_contact": floor_contact,
            "floor_run_m": floor_run_m,
            "case": "plumb" if not determined else ("floor" if floor_contact else "free"),
            "azimuth_std_rad": std_beta,
            "azimuth_source": source,
            "elevation_used": elevation_used,
        }
    )


def _localize_tension_free(
    tx: float,
    ty: float,
    tz: float,
    cxx: float,
    cxy: float,
    cxz: float,
    cyy: float,
    cyz: float,
    czz: float,
    weight_n_per_m: float,
    length_m: float,
    bx: float,
    by: float,
    bz: float,
    floor_z_m: float,
    plumb_k: float,
    mx: float = 0.0,
    my: float = 0.0,
    mz: float = 0.0,
) -> PositionEstimate | None:
    """:func:`try_localize`'s common case, a freely hanging tether whose azimuth comes from
    the tension alone and is certain (rho = 1), with the very operations of its general
    path, in its order, less those whose result is known: the reach at H = k sigma_H and
    the azimuth-unknown covariance (weighted by 1 - rho = 0), the other sources' share of
    the azimuth variance (0 with one source), the cross-covariance of r and z (unused
    here). None when the case is not this one (a point within 1 um of the floor, a
    singular covariance, H near zero, an uncertain azimuth, anything not finite): the
    caller then takes the general path. ``tests/test_localization_fast.py`` checks that
    both give the same floats.

    Inputs as in :func:`try_localize` after its checks: the tension's components, the
    symmetrised covariance's, omega, L, the base, the floor and the model's variance per
    axis (``model_var_n2``: added to the covariance's diagonal for the sigma points only).
    """
    hypot, asinh, isfinite, sqrt = math.hypot, math.asinh, math.isfinite, math.sqrt
    horizontal_n = hypot(tx, ty)
    if not horizontal_n > MIN_HORIZONTAL_N:
        return None
    # The azimuth: opposite the horizontal pull; its std is the pull's sideways std over H
    # (_fuse_angles of one source: beta = atan2(sin, cos) of beta_t + 0 / 1).
    ux_t, uy_t = -tx / horizontal_n, -ty / horizontal_n
    var_side = uy_t * uy_t * cxx - 2.0 * ux_t * uy_t * cxy + ux_t * ux_t * cyy
    std_t = sqrt(0.0 if var_side < 0.0 else var_side) / horizontal_n  # max(var_side, 0.0)
    # rho = 1 (std <= 1 / (2 k)), which implies a determined azimuth (std <= 1 / k).
    if not (0.0 < std_t <= 1.0 / (PLUMB_BLEND_RATIO * plumb_k)):
        return None
    beta_t = math.atan2(uy_t + 0.0, ux_t)
    beta = beta_t + 0.0 / 1.0
    beta = math.atan2(math.sin(beta), math.cos(beta))
    ux, uy = math.cos(beta), math.sin(beta)

    # Sigma points T, T +- sqrt(3) S e_i, S the lower Cholesky factor (_cholesky3) of the
    # covariance plus the model's variance.
    exx = cxx + mx
    if not exx > 0.0:
        return None
    l00 = sqrt(exx)
    l10 = cxy / l00
    l20 = cxz / l00
    d1 = cyy + my - l10 * l10
    if not d1 > 0.0:
        return None
    l11 = sqrt(d1)
    l21 = (cyz - l20 * l10) / l11
    d2 = czz + mz - l20 * l20 - l21 * l21
    if not d2 > 0.0:
        return None
    if not (cxx < 1e150 and cyy < 1e150):
        # Keeps the general path's sigma_H (and the reach at k sigma_H that this path
        # leaves out) finite and its (cxx - cyy) ** 2 from raising OverflowError.
        return None
    k = _SIGMA_SCALE
    a0, b0, b1, c0, c1, c2 = k * l00, k * l10, k * l11, k * l20, k * l21, k * sqrt(d2)
    # -(x, y, z) of the points 1..6 (-(t + d) is -t - d to the bit); S's zero entries
    # add 0.0 as the general path does.
    nx, ny, nz = -tx, -ty, -tz
    pts = (
        (nx - a0, ny - b0, nz - c0),
        (nx - 0.0, ny - b1, nz - c1),
        (nx - 0.0, ny - 0.0, nz - c2),
        (nx + a0, ny + b0, nz + c0),
        (nx + 0.0, ny + b1, nz + c1),
        (nx + 0.0, ny + 0.0, nz + c2),
    )

    # catenary.locate_free_floats of point 0 and of each sigma point, with the floor test
    # of _locate_points; any point near the floor: the general path.
    omega, big_l = weight_n_per_m, length_m
    has_floor = floor_z_m != -math.inf
    limit = floor_z_m + 1e-6
    a = horizontal_n / omega  # eq:a_param
    s2 = -tz / omega  # eq:s2_param
    t = big_l - s2
    hyp_s = hypot(a, s2)
    # a * asinh(s / a) per term (catenary._a_asinh), finite exactly when the sum is (else
    # None below: the general path).
    r_0 = a * asinh(s2 / a) + a * asinh(t / a) if a > 0.0 else 0.0  # eq:posfull_radial
    z0 = bz + (2.0 * s2 - big_l) * big_l / (hyp_s + hypot(a, t))  # eq:posfull_z
    if has_floor and not ((z0 if s2 < 0.0 else (bz if s2 > big_l else z0 - (hyp_s - a))) > limit):
        return None
    r0 = r_0 if not r_0 < 0.0 else 0.0  # r >= 0
    var_r = var_z = 0.0
    dxx = dxy = dyy = dxz = dyz = 0.0
    hx0, hy0 = r0 * ux, r0 * uy
    for xi, yi, vi in pts:  # xi, yi: -x, -y; vi = -z = T_v
        hi = hypot(xi, yi)
        a = hi / omega
        s2 = vi / omega
        t = big_l - s2
        hyp_s = hypot(a, s2)
        ri = a * asinh(s2 / a) + a * asinh(t / a) if a > 0.0 else 0.0
        zi = bz + (2.0 * s2 - big_l) * big_l / (hyp_s + hypot(a, t))
        if has_floor and not (
            (zi if s2 < 0.0 else (bz if s2 > big_l else zi - (hyp_s - a))) > limit
        ):
            return None
        # The unscented transform: (r, z), and the horizontal offset along the point's
        # own azimuth (the tension is the only source), cos and sin of which are
        # -x_i / h_i and -y_i / h_i.
        dr, dz = ri - r0, zi - z0
        var_r += dr * dr
        var_z += dz * dz
        if hi > 0.0:
            dx, dy = ri * (xi / hi) - hx0, ri * (yi / hi) - hy0
        else:
            dx, dy = ri * ux - hx0, ri * uy - hy0
        dxx += dx * dx
        dxy += dx * dy
        dyy += dy * dy
        dxz += dx * dz
        dyz += dy * dz
    w = _SIGMA_WEIGHT
    var_z = w * var_z
    sxx, sxy, syy, sxz, syz = w * dxx, w * dxy, w * dyy, w * dxz, w * dyz
    values = [
        bx + r0 * ux,
        by + r0 * uy,
        z0,
        sqrt(sxx),
        sqrt(syy),
        sqrt(var_z),
        sxx,
        sxy,
        sxz,
        sxy,
        syy,
        syz,
        sxz,
        syz,
        var_z,
    ]
    # Every r and z finite (var_r, var_z and the rest), as the general path requires.
    if not (isfinite(sum(values)) and isfinite(r_0 + w * var_r)):
        return None
    position_arr, std_arr, cov_arr = _frozen_arrays(*values)
    return _estimate(
        {
            "position_world_m": position_arr,
            "std_world_m": std_arr,
            "cov_world_m2": cov_arr,
            "radial_m": r0,
            "radial_interval_m": (r_0, r_0),
            "azimuth_rad": beta,
            "azimuth_determined": True,
            "floor_contact": False,
            "floor_run_m": 0.0,
            "case": "free",
            "azimuth_std_rad": std_t,
            "azimuth_source": "tension",
            "elevation_used": False,
        }
    )


def _free_stats(
    fused: tuple[float, float, tuple[float, float, float]],
    weight_n_per_m: float,
    length_m: float,
    base_z_m: float,
    floor_z_m: float,
) -> tuple[float, float, float, float, float] | None:
    """``(r, z, var_r, cov_rz, var_z)`` of a free-hanging tether with parameters (a, s2)
    ~ N(x, P), by the unscented transform on 5 points (eq:posfull_radial, eq:posfull_z in
    the closed form); None if any point reaches the floor (the free model then no longer
    holds) or the result is not finite."""
    a, s2, (paa, pas, pss) = fused
    # Lower Cholesky factor of the 2x2 [[paa, pas], [pas, pss]] (PD from _fuse_elevation).
    l00 = math.sqrt(max(paa, 0.0))
    l10 = pas / l00 if l00 > 0.0 else 0.0
    l11 = math.sqrt(max(pss - l10 * l10, 0.0))
    k = _SIGMA_SCALE_2D  # sqrt(n + kappa), n = 2, kappa = 0
    da = [0.0, k * l00, 0.0, -k * l00, 0.0]
    ds = [0.0, k * l10, k * l11, -k * l10, -k * l11]
    a_pts = [abs(a + d) for d in da]  # H = omega |a| >= 0
    s_pts = [s2 + d for d in ds]
    r_l, z_l = catenary.locate_free_floats(a_pts, s_pts, length_m, base_z_m)
    if floor_z_m != -math.inf:
        limit = floor_z_m + 1e-6
        for ai, si, zi in zip(a_pts, s_pts, z_l, strict=True):
            vertex = zi - (math.hypot(ai, si) - ai)
            lowest = zi if si < 0.0 else (base_z_m if si > length_m else vertex)
            if not lowest > limit:
                return None
    if not (_all_finite(r_l) and _all_finite(z_l)):
        return None
    r0, z0 = r_l[0], z_l[0]
    w = _SIGMA_WEIGHT_2D  # 1 / (2 n)
    var_r = w * sum((ri - r0) ** 2 for ri in r_l[1:])
    cov_rz = w * sum((ri - r0) * (zi - z0) for ri, zi in zip(r_l[1:], z_l[1:], strict=True))
    var_z = w * sum((zi - z0) ** 2 for zi in z_l[1:])
    return r0, z0, var_r, cov_rz, var_z


def localize(
    tension_world_n: ArrayLike | None,
    tension_cov_n2: ArrayLike,
    weight_n_per_m: float,
    length_m: float,
    base_world_m: ArrayLike,
    floor_z_m: float = -math.inf,
    plumb_k: float = PLUMB_K,
    *,
    azimuth: AzimuthMode = "auto",
    exit_azimuth: AngleObservation | None = None,
    exit_elevation: AngleObservation | None = None,
    mocap_world_m: ArrayLike | None = None,
    mocap_std_m: float = 0.002,
    model_var_n2: tuple[float, float, float] | None = None,
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
        azimuth: See :func:`try_localize`.
        exit_azimuth: See :func:`try_localize`.
        exit_elevation: See :func:`try_localize`.
        mocap_world_m: See :func:`try_localize`.
        mocap_std_m: See :func:`try_localize`.
        model_var_n2: See :func:`try_localize`.

    Returns:
        The estimate, or None when there is no tension estimate or the math failed
        (:func:`try_localize` gives the reason).
    """
    out = _try_localize(
        tension_world_n,
        tension_cov_n2,
        weight_n_per_m,
        length_m,
        base_world_m,
        floor_z_m,
        plumb_k,
        azimuth,
        exit_azimuth,
        exit_elevation,
        mocap_world_m,
        mocap_std_m,
        model_var_n2,
    )
    return out if type(out) is PositionEstimate else None


def try_localize_batch(
    tension_world_n: ArrayLike,
    tension_cov_n2: ArrayLike,
    weight_n_per_m: ArrayLike,
    length_m: ArrayLike,
    base_world_m: ArrayLike,
    floor_z_m: ArrayLike = -math.inf,
    plumb_k: float = PLUMB_K,
    *,
    azimuth: AzimuthMode = "auto",
    exit_azimuth: list[AngleObservation | None] | None = None,
    exit_elevation: list[AngleObservation | None] | None = None,
    mocap_world_m: list[ArrayLike | None] | None = None,
    mocap_std_m: float = 0.002,
    model_var_n2: ArrayLike | None = None,
) -> list[PositionEstimate | LocalizationFailure]:
    """:func:`try_localize` of N independent cases at once, with the same results.

    Localization holds no state: each case depends only on its own inputs, so the cases of
    a batch (many drones, consecutive messages of one drone) are computed together, the
    arithmetic of :func:`try_localize` over arrays of N and the catenary in one call on
    8 N points. The common case is done so (a freely hanging tether, the azimuth from the
    tension alone); any other case (an azimuth from the reel or motion capture, an exit
    elevation, a point within 1 um of the floor, a singular covariance, H at or below
    :data:`MIN_HORIZONTAL_N`, anything not finite) goes through :func:`try_localize`
    itself. The operations are those of :func:`try_localize`, in its order, with the
    same functions where numpy's differ from Python's by an ulp (``atan2``, ``hypot``),
    so the results are the same floats; ``tests/test_localization.py`` checks it.

    Args:
        tension_world_n: Tensions, world, N, shape (N, 3).
        tension_cov_n2: Their covariances, N^2, shape (N, 3, 3).
        weight_n_per_m: omega per case, N/m, shape (N,) or a scalar.
        length_m: Tether length per case, m, shape (N,) or a scalar.
        base_world_m: Base exit per case, world, m, shape (N, 3) or (3,).
        floor_z_m: Floor height per case, m, shape (N,) or a scalar (``-inf``: none).
        plumb_k: See :data:`PLUMB_K`.
        azimuth: See :func:`try_localize` (one mode for the batch).
        exit_azimuth: Per case, or None for none in any.
        exit_elevation: Per case, or None for none in any.
        mocap_world_m: Per case, or None for none in any.
        mocap_std_m: See :func:`try_localize`.
        model_var_n2: Per case, N², shape (N, 3) or (3,), or None (:func:`try_localize`).

    Returns:
        One :class:`PositionEstimate` or :class:`LocalizationFailure` per case, in order.
    """
    T = np.asarray(tension_world_n, dtype=np.float64)
    n = T.shape[0] if T.ndim == 2 else 0
    cov_in = np.asarray(tension_cov_n2, dtype=np.float64)
    if T.shape != (n, 3) or cov_in.shape != (n, 3, 3):
        raise ValueError(
            f"tension_world_n must be (N, 3) and tension_cov_n2 (N, 3, 3), got {T.shape} "
            f"and {cov_in.shape}"
        )
    omega = np.broadcast_to(np.asarray(weight_n_per_m, dtype=np.float64), (n,))
    big_l = np.broadcast_to(np.asarray(length_m, dtype=np.float64), (n,))
    base = np.broadcast_to(np.asarray(base_world_m, dtype=np.float64), (n, 3))
    floor = np.broadcast_to(np.asarray(floor_z_m, dtype=np.float64), (n,))
    model = np.broadcast_to(
        np.asarray(0.0 if model_var_n2 is None else model_var_n2, dtype=np.float64), (n, 3)
    )

    def case(i: int) -> PositionEstimate | LocalizationFailure:
        return try_localize(
            T[i],
            cov_in[i],
            float(omega[i]),
            float(big_l[i]),
            base[i],
            float(floor[i]),
            plumb_k,
            azimuth=azimuth,
            exit_azimuth=exit_azimuth[i] if exit_azimuth is not None else None,
            exit_elevation=exit_elevation[i] if exit_elevation is not None else None,
            mocap_world_m=mocap_world_m[i] if mocap_world_m is not None else None,
            mocap_std_m=mocap_std_m,
            model_var_n2=None
            if model_var_n2 is None
            else (float(model[i, 0]), float(model[i, 1]), float(model[i, 2])),
        )

    out: list[PositionEstimate | LocalizationFailure | None] = [None] * n
    # Cases for the arrays: the tension's azimuth alone, no elevation, valid scalars (the
    # per-case numbers in Python: in a batch they are a drone's few configured values).
    fast = [azimuth in ("auto", "tension")] * n
    for obs_list, used in ((exit_azimuth, azimuth == "auto"), (exit_elevation, True)):
        if obs_list is not None and used:
            for i, obs in enumerate(obs_list):
                if _valid_angle(obs) is not None:
                    fast[i] = False
    model_ok = (np.isfinite(model.sum(axis=1)) & (model >= 0.0).all(axis=1)).tolist()
    for i, (w_i, l_i, bz_i, f_i) in enumerate(
        zip(omega.tolist(), big_l.tolist(), base[:, 2].tolist(), floor.tolist(), strict=True)
    ):
        if not (
            0.0 < w_i < math.inf
            and 0.0 < l_i < math.inf
            and (f_i == -math.inf or (math.isfinite(f_i) and bz_i >= f_i))
            and model_ok[i]
        ):
            fast[i] = False
    idx = [i for i, f in enumerate(fast) if f]
    if idx:
        sel = idx if len(idx) < n else slice(None)
        results = _localize_arrays(
            T[sel], cov_in[sel], omega[sel], big_l[sel], base[sel], floor[sel], plumb_k, model[sel]
        )
        for i, pos in zip(idx, results, strict=True):
            out[i] = pos
    return [o if o is not None else case(i) for i, o in enumerate(out)]


def _localize_arrays(
    T: FloatArray,
    c: FloatArray,
    omega: FloatArray,
    big_l: FloatArray,
    base: FloatArray,
    floor: FloatArray,
    plumb_k: float,
    model: FloatArray,
) -> list[PositionEstimate | None]:
    """:func:`try_localize`'s free-hanging, tension-azimuth case over arrays of M cases.

    The caller has checked omega, L, the base and the floor. None for a case outside this
    path (a non-finite input, a singular covariance, H <= MIN_HORIZONTAL_N, a point near
    the floor, a non-finite result): the caller computes it with :func:`try_localize`.
    The operations are :func:`try_localize`'s, in its order, over arrays (numpy's call
    overhead is paid once per batch, so the lines are few and wide).
    """
    m = T.shape[0]
    with np.errstate(all="ignore"):
        return _localize_arrays_body(m, T, c, omega, big_l, base, floor, plumb_k, model)


def _localize_arrays_body(
    m: int,
    T: FloatArray,
    c: FloatArray,
    omega: FloatArray,
    big_l: FloatArray,
    base: FloatArray,
    floor: FloatArray,
    plumb_k: float,
    model: FloatArray,
) -> list[PositionEstimate | None]:
    # Non-finite inputs make their case's sum non-finite (an overflowing sum only sends a
    # valid case to try_localize).
    ok = np.isfinite(T.sum(axis=1) + c.sum(axis=(1, 2)) + base.sum(axis=1))
    tx, ty, tz = T.T
    bx, by, bz = base.T
    # cov = (cov + cov') / 2
    sym = 0.5 * (c + c.transpose(0, 2, 1))
    cxx, cxy, cxz, _, cyy, cyz, _, _, czz = sym.reshape(m, 9).T
    # math.hypot, as try_localize (numpy's hypot differs from it by an ulp at times).
    horizontal_n = np.array(list(map(math.hypot, tx.tolist(), ty.tolist())))
    vertical_n = -tz
    lam_max = 0.5 * (cxx + cyy) + np.sqrt(np.maximum(0.25 * (cxx - cyy) ** 2 + cxy * cxy, 0.0))
    sigma_h_n = np.sqrt(np.maximum(lam_max, 0.0))
    # _cholesky3 of cov + the model's variance (a failing pivot: the case goes to try_localize)
    mx, my, mz = model.T
    exx = cxx + mx
    l00 = np.sqrt(exx)
    l10 = cxy / l00
    l20 = cxz / l00
    d1 = cyy + my - l10 * l10
    l11 = np.sqrt(d1)
    l21 = (cyz - l20 * l10) / l11
    d2 = czz + mz - l20 * l20 - l21 * l21
    ok &= (exx > 0.0) & (d1 > 0.0) & (d2 > 0.0) & (horizontal_n > MIN_HORIZONTAL_N)
    # Sigma points T, T + sqrt(3) S[:, i], T - sqrt(3) S[:, i], as (M, 3 coordinates, 7).
    zero = np.zeros(m)
    S = _SIGMA_SCALE * np.stack([l00, zero, zero, l10, l11, zero, l20, l21, np.sqrt(d2)], axis=1)
    S = S.reshape(m, 3, 3)
    P = np.concatenate([T[:, :, None], T[:, :, None] + S, T[:, :, None] - S], axis=2)
    px, py, pz = P[:, 0], P[:, 1], P[:, 2]
    n_pts = 2 * _N + 1
    h_pts = _hypot(px, py)
    h_all = np.concatenate([h_pts, np.maximum(plumb_k * sigma_h_n, horizontal_n)[:, None]], axis=1)
    v_all = np.concatenate([-pz, vertical_n[:, None]], axis=1)
    # _locate_points: the free-hanging solution of all 8 M points in one call ...
    a = h_all / omega[:, None]  # eq:a_param
    s2 = v_all / omega[:, None]  # eq:s2_param
    big_l1, bz1 = big_l[:, None], bz[:, None]
    hyp_s2 = _hypot(a, s2)
    r, z = _locate_free_arrays(a, s2, big_l1, bz1, hyp_s2)
    # ... where no lowest point comes within 1 um of the floor (else: try_localize's).
    lowest = np.where(s2 < 0.0, z, np.where(s2 > big_l1, bz1, z - (hyp_s2 - a)))
    ok &= (floor == -math.inf) | (lowest > (floor + 1e-6)[:, None]).all(axis=1)
    ok &= np.isfinite(h_all.sum(axis=1) + v_all.sum(axis=1) + r.sum(axis=1) + z.sum(axis=1))

    # The azimuth from the tension alone (_fuse_angles of one source), math's atan2.
    ux_t, uy_t = -tx / horizontal_n, -ty / horizontal_n
    var_side = uy_t * uy_t * cxx - 2.0 * ux_t * uy_t * cxy + ux_t * ux_t * cyy
    std_t = np.sqrt(np.maximum(var_side, 0.0)) / horizontal_n
    ok &= (std_t > 0.0) & (std_t < math.inf)
    beta_t = np.array(list(map(math.atan2, (uy_t + 0.0).tolist(), ux_t.tolist())))
    # One source: w = 1, beta = beta_0 + 1 * wrap(0) / 1, then atan2(sin, cos).
    beta = beta_t + (1.0 * _wrap_array(beta_t - beta_t)) / 1.0
    beta = np.array(list(map(math.atan2, np.sin(beta).tolist(), np.cos(beta).tolist())))
    std_beta = std_t / math.sqrt(1.0)
    determined = std_beta <= 1.0 / plumb_k
    rho = _blend_array(std_beta, 1.0 / (PLUMB_BLEND_RATIO * plumb_k), PLUMB_BLEND_RATIO / plumb_k)
    ux, uy = np.cos(beta), np.sin(beta)
    vx, vy = -uy, ux
    w_t = (std_beta / std_t) ** 2
    var_other = np.maximum(std_beta * std_beta - w_t * w_t * std_t * std_t, 0.0)

    # (r, z) by the unscented transform, and the horizontal offset of each sigma point
    # along its own azimuth (through the tension's share w_t of the fused one).
    r0, z0 = np.maximum(r[:, 0], 0.0), z[:, 0]
    hx0, hy0 = r0 * ux, r0 * uy
    # The tension is the only source (w_t = 1): each point's own azimuth, as try_localize.
    xi, yi, hi = px[:, 1:], py[:, 1:], h_pts[:, 1:]
    cx = np.where(hi > 0.0, -xi / hi, ux[:, None])
    cy = np.where(hi > 0.0, -yi / hi, uy[:, None])
    ri, zi = r[:, 1:n_pts], z[:, 1:n_pts]
    dr = ri - r0[:, None]
    dz = zi - z0[:, None]
    dx = ri * cx - hx0[:, None]
    dy = ri * cy - hy0[:, None]
    # The sums of products over the six points, left to right as try_localize adds them
    # (cov_rz is not needed here: only the elevation's branch uses it).
    left = np.stack([dr, dz, dx, dx, dy, dx, dy])
    right = np.stack([dr, dz, dx, dy, dy, dz, dz])
    w = _SIGMA_WEIGHT
    var_r, var_z, dxx, dxy, dyy, dxz, dyz = w * _colsum(left * right)
    k_vv = r0 * r0 * var_other
    dxx = dxx + k_vv * vx * vx
    dyy = dyy + k_vv * vy * vy
    dxy = dxy + k_vv * vx * vy
    # Covariance with the azimuth unknown (r_reach: r_max = r without floor contact),
    # blended with rho as the mean.
    r_reach = np.maximum(r[:, n_pts], r[:, n_pts])
    undet = np.maximum(r_reach * r_reach, r0 * r0 + var_r)
    mean_r = rho * r0
    one_minus = (1.0 - rho) * undet
    sxx = rho * dxx + one_minus
    syy = rho * dyy + one_minus
    sxy = rho * dxy
    sxz, syz = rho * dxz, rho * dyz
    position = np.stack([bx + mean_r * ux, by + mean_r * uy, z0], axis=1)
    pos_cov = np.stack([sxx, sxy, sxz, sxy, syy, syz, sxz, syz, var_z], axis=1).reshape(m, 3, 3)
    std = np.sqrt(np.maximum(np.stack([sxx, syy, var_z], axis=1), 0.0))
    ok &= np.isfinite(position.sum(axis=1) + pos_cov.sum(axis=(1, 2)))
    interval = r[:, 0]
    hi_undet = np.maximum(r_reach, interval)
    for arr in (position, std, pos_cov):
        arr.setflags(write=False)

    out: list[PositionEstimate | None] = []
    rows = zip(
        ok.tolist(),
        determined.tolist(),
        r0.tolist(),
        interval.tolist(),
        hi_undet.tolist(),
        beta.tolist(),
        std_beta.tolist(),
        strict=True,
    )
    for i, (good, det, r0_i, r_i, hi_u, beta_k, std_k) in enumerate(rows):
        if not good:
            out.append(None)
            continue
        out.append(
            PositionEstimate(
                position_world_m=position[i],
                std_world_m=std[i],
                cov_world_m2=pos_cov[i],
                radial_m=r0_i,
                radial_interval_m=(r_i, r_i) if det else (0.0, hi_u),
                azimuth_rad=beta_k if det else None,
                azimuth_determined=det,
                floor_contact=False,
                floor_run_m=0.0,
                case="free" if det else "plumb",
                azimuth_std_rad=std_k,
                azimuth_source="tension",
                elevation_used=False,
            )
        )
    return out


def _locate_free_arrays(
    a: FloatArray, s2: FloatArray, big_l: FloatArray, z_i: FloatArray, hyp_s2: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """``catenary.locate_free`` with ``math.hypot``'s floats (:func:`_hypot`), as
    ``catenary.locate_free_floats`` gives them to :func:`try_localize`; ``hyp_s2`` is
    ``hypot(a, s2)``, which the caller needs too."""
    t = big_l - s2
    r = catenary._a_asinh(a, s2) + catenary._a_asinh(a, t)  # eq:posfull_r_0 + eq:posfull_radial
    z = z_i + (2.0 * s2 - big_l) * big_l / (hyp_s2 + _hypot(a, t))  # eq:posfull_z
    return r, z


_SPLIT = 134217729.0  # 2^27 + 1: Dekker's split, x = hi + lo with 26-bit halves
_DBL_MIN = sys.float_info.min


def _hypot(x: FloatArray, y: FloatArray) -> FloatArray:
    """``math.hypot`` over arrays, to the bit (numpy's ``hypot`` is the C library's, which
    differs from it by an ulp at times, and the batch must give try_localize's floats).

    CPython's ``vector_norm`` for two coordinates: both scaled by the power of two that
    brings the larger into [0.5, 1), squared and summed without loss (Dekker's product,
    Knuth's fast two-sum), the square root corrected once by the residual, scaled back.
    Where the larger is below 2^-960 (subnormal ranges, which CPython handles with one
    more scaling) ``math.hypot`` itself is called on those elements. Inputs are finite or
    not; inf wins over NaN, as in ``math.hypot``.
    """
    x = np.abs(x)
    y = np.abs(y)
    m = np.maximum(x, y)
    _, e = np.frexp(m)
    scale = np.ldexp(1.0, -e)
    csum = np.ones_like(m)
    frac1 = np.zeros_like(m)
    frac2 = np.zeros_like(m)
    for v in (x * scale, y * scale):
        hi = v * v
        c = _SPLIT * v
        vh = c - (c - v)
        vl = v - vh
        lo = ((vh * vh - hi) + 2.0 * vh * vl) + vl * vl  # v^2 = hi + lo exactly
        total = csum + hi
        frac2 = frac2 + ((csum - total) + hi)  # csum + hi = total + this, exactly
        csum = total
        frac1 = frac1 + lo
    h = np.sqrt(csum - 1.0 + (frac1 + frac2))
    hi = -h * h
    c = _SPLIT * h
    hh = c - (c - h)
    hl = h - hh
    lo = ((-hh * hh - hi) - 2.0 * hh * hl) - hl * hl  # -h^2 = hi + lo exactly
    total = csum + hi
    frac2 = frac2 + ((csum - total) + hi)
    csum = total
    frac1 = frac1 + lo
    h = h + (csum - 1.0 + (frac1 + frac2)) / (2.0 * h)
    out = h / scale
    odd = ~(m > 2.0**-960) | ~(m < math.inf)  # tiny, zero, inf or NaN: math.hypot itself
    if odd.any():
        idx = np.nonzero(odd)
        out[idx] = list(map(math.hypot, x[idx].tolist(), y[idx].tolist()))
    return out


def _wrap_array(angle_rad: FloatArray) -> FloatArray:
    """:func:`_wrap` over an array (numpy's % is Python's on floats)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


def _colsum(v: FloatArray) -> FloatArray:
    """Sums over the last axis, left to right from 0.0, as try_localize's ``+=`` loops add
    (numpy's own sum adds in another order, so its last bits can differ)."""
    total = 0.0 + v[..., 0]
    for j in range(1, v.shape[-1]):
        total = total + v[..., j]
    return total


def _blend_array(x: FloatArray, full: float, none: float) -> FloatArray:
    """:func:`_blend` over an array."""
    t = (none - x) / (none - full)
    mid = t * t * (3.0 - 2.0 * t)
    return np.where(x <= full, 1.0, np.where(~(x < none), 0.0, mid))


def localize_batch(
    tension_world_n: ArrayLike,
    tension_cov_n2: ArrayLike,
    weight_n_per_m: ArrayLike,
    length_m: ArrayLike,
    base_world_m: ArrayLike,
    floor_z_m: ArrayLike = -math.inf,
    plumb_k: float = PLUMB_K,
    *,
    azimuth: AzimuthMode = "auto",
    exit_azimuth: list[AngleObservation | None] | None = None,
    exit_elevation: list[AngleObservation | None] | None = None,
    mocap_world_m: list[ArrayLike | None] | None = None,
    mocap_std_m: float = 0.002,
    model_var_n2: ArrayLike | None = None,
) -> list[PositionEstimate | None]:
    """:func:`try_localize_batch` with None in place of a failure (as :func:`localize`)."""
    outs = try_localize_batch(
        tension_world_n,
        tension_cov_n2,
        weight_n_per_m,
        length_m,
        base_world_m,
        floor_z_m,
        plumb_k,
        azimuth=azimuth,
        exit_azimuth=exit_azimuth,
        exit_elevation=exit_elevation,
        mocap_world_m=mocap_world_m,
        mocap_std_m=mocap_std_m,
        model_var_n2=model_var_n2,
    )
    return [o if isinstance(o, PositionEstimate) else None for o in outs]
