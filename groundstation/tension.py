"""Tether tension from IMU + thrust, and the tension filter (paper sec. tens_estimate).

Pure physics: numpy, scipy-free linear algebra and filterpy only; time enters as
``dt_s``. Two parts:

* :func:`observe_tension` turns one telemetry sample (body specific force, attitude,
  collective thrust) into one raw tension observation in the world frame, with the
  Newton-Euler balance of ``eq:NE_tether``. It refuses to report the floor's reaction
  as tension while the drone sits on the ground (disarmed, or thrust below half its
  weight), which the paper's own vertical-tension figure shows happening.
* :class:`TensionFilter` smooths those observations with the constant-tension Kalman
  filter of ``eq:sysk1``, ``eq:sysk2``, ``eq:Kalman_vars`` (A = C = I, B = D = 0),
  made both calm at hover and quick after a tug by a change detector on its
  innovations. The design, its reasoning and its numbers are in the class docstring.

Frames and conventions follow the public contract: world is right-handed with z up,
body is x forward / y left / z up, quaternions are scalar-first body->world
``[w, x, y, z]``. The tension is the force the tether applies to the drone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from filterpy.kalman import KalmanFilter
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "GRAVITY_MPS2",
    "NO_CALIBRATION",
    "DegenerateQuaternionError",
    "InvalidObservationError",
    "InvalidTimeStepError",
    "ObservationCalibration",
    "TensionError",
    "TensionEstimate",
    "TensionFilter",
    "TensionFilterParams",
    "TensionObservation",
    "observation_cov_n2",
    "observe_tension",
    "rotation_world_body",
]

GRAVITY_MPS2 = 9.81
"""Standard gravity used throughout the project, m/s^2 (world -z)."""

_QUAT_MIN_NORM = 1e-6
_EYE3 = np.eye(3)
_EYE3.setflags(write=False)

FloatArray = NDArray[np.float64]


class TensionError(ValueError):
    """Base class of the errors raised by this module."""


class DegenerateQuaternionError(TensionError):
    """A quaternion that cannot be normalised (norm below 1e-6, or not finite)."""


class InvalidObservationError(TensionError):
    """An input of the wrong shape, or with non-finite or out-of-range values."""


class InvalidTimeStepError(TensionError):
    """A time step that is negative or not finite."""


def _frozen(array: ArrayLike) -> FloatArray:
    """Returns a float64 copy that cannot be written to (results are immutable)."""
    out = np.array(array, dtype=np.float64)
    out.setflags(write=False)
    return out


def _floats(value: object, n: int) -> list[float] | None:
    """The ``n`` entries of a tuple, list or 1-D float64 array as Python floats.

    None when ``value`` is anything else (or holds something ``float`` refuses): the caller
    then takes its numpy path, which accepts or rejects it exactly as before. The per-message
    inputs (pydantic tuples, the observation array) are 3- and 4-vectors, for which scalar
    math costs a fraction of numpy's per-call overhead.
    """
    kind = type(value)
    if kind is tuple or kind is list:
        if len(value) != n:  # type: ignore[arg-type]
            return None
        try:
            return [float(v) for v in value]  # type: ignore[attr-defined]
        except (TypeError, ValueError):
            return None
    if kind is np.ndarray and value.shape == (n,) and value.dtype == np.float64:  # type: ignore[attr-defined]
        out: list[float] = value.tolist()  # type: ignore[attr-defined]
        return out
    return None


def _vector3(value: ArrayLike, name: str) -> FloatArray:
    if type(value) is np.ndarray and value.shape == (3,) and value.dtype == np.float64:
        a, b, c = value.tolist()
        if math.isfinite(a) and math.isfinite(b) and math.isfinite(c):
            return value  # what np.asarray returns for a float64 array
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (3,):
        raise InvalidObservationError(f"{name} must have shape (3,), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InvalidObservationError(f"{name} must be finite, got {arr.tolist()}")
    return arr


def _unit_quaternion(quat_wxyz: ArrayLike) -> tuple[float, float, float, float]:
    """``quat_wxyz / |quat_wxyz|`` as floats; raises as :func:`rotation_world_body`.

    The sum of squares is taken in the order of numpy's 4-term dot (``q @ q``), so the
    result is the one the array code gives, bit for bit.
    """
    q = _floats(quat_wxyz, 4)
    if q is not None:
        w, x, y, z = q
        ss = ((w * w + x * x) + y * y) + z * z
        if math.isfinite(ss):  # also: every entry is finite
            norm = math.sqrt(ss)
            if norm >= _QUAT_MIN_NORM:
                return w / norm, x / norm, y / norm, z / norm
    # Degenerate, overflowing or an unusual type: the array code raises or copes.
    w, x, y, z = _unit_quaternion_array(quat_wxyz).tolist()
    return w, x, y, z


def _unit_quaternion_array(quat_wxyz: ArrayLike) -> FloatArray:
    q = np.asarray(quat_wxyz, dtype=np.float64)
    if q.shape != (4,):
        raise DegenerateQuaternionError(f"quat_wxyz must have shape (4,), got shape {q.shape}")
    norm = float(np.sqrt(q @ q)) if np.all(np.isfinite(q)) else math.nan
    if not (norm >= _QUAT_MIN_NORM):  # also catches nan/inf
        raise DegenerateQuaternionError(
            f"quat_wxyz={q.tolist()} cannot be normalised (norm {norm!r} < {_QUAT_MIN_NORM})"
        )
    out: FloatArray = q / norm
    return out


def _thrust_axis(quat_wxyz: ArrayLike | None) -> tuple[float, float, float]:
    """Body +z in the world frame, ``R_world_body[:, 2]``; world +z for None."""
    if quat_wxyz is None:
        return 0.0, 0.0, 1.0
    w, x, y, z = _unit_quaternion(quat_wxyz)
    return 2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)


def rotation_world_body(quat_wxyz: ArrayLike) -> FloatArray:
    """Rotation matrix of a body->world attitude quaternion.

    The quaternion is normalised first, so a slightly denormalised telemetry value is
    accepted; one that cannot be normalised is rejected rather than turned into a
    meaningless rotation.

    Args:
        quat_wxyz: Attitude, scalar-first ``[w, x, y, z]``, body->world, shape (4,).

    Returns:
        ``R_world_body``, shape (3, 3), such that ``v_world = R_world_body @ v_body``.

    Raises:
        DegenerateQuaternionError: If the quaternion has the wrong shape, a non-finite
            entry or a norm below 1e-6.
    """
    w, x, y, z = _unit_quaternion(quat_wxyz)
    return np.array(
        [
            [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
            [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
            [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
        ]
    )


@dataclass(frozen=True)
class ObservationCalibration:
    """Sensor corrections applied in :func:`observe_tension` (config ``[calibration]``).

    The model, in the body frame of the attitude that Telemetry reports::

        f   = accel_mps2 - accel_bias_mps2
        F   = thrust_n * (thrust_scale + thrust_vbat_slope_per_v * (vbat_v - thrust_vbat_ref_v))
        b   = R_x(about_x) R_y(about_y) e3
            = (sin about_y, -sin about_x cos about_y, cos about_x cos about_y)
        T   = m R f - R b F                      # eq:NE_tether with the corrections

    The voltage term applies only when the sample carries ``vbat_v``. The defaults change
    nothing (``T = m R f - R e3 F``, bit for bit the uncalibrated formula).

    Attributes:
        thrust_scale: Factor on the reported thrust (the nominal PWM->thrust map's error),
            dimensionless, > 0.
        thrust_axis_rad: The thrust axis as a small rotation of body +z,
            ``(about_x, about_y)``, rad.
        accel_bias_mps2: Subtracted from the accelerometer reading, body frame, m/s^2,
            shape (3,).
        thrust_vbat_slope_per_v: Change of the thrust scale per volt above
            ``thrust_vbat_ref_v``, 1/V.
        thrust_vbat_ref_v: Battery voltage at which ``thrust_scale`` holds, V, > 0.
    """

    thrust_scale: float = 1.0
    thrust_axis_rad: tuple[float, float] = (0.0, 0.0)
    accel_bias_mps2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    thrust_vbat_slope_per_v: float = 0.0
    thrust_vbat_ref_v: float = 3.9
    thrust_axis_body: tuple[float, float, float] = field(init=False, repr=False)
    """``b = R_x(about_x) R_y(about_y) e3``, body frame, unit (derived)."""

    def __post_init__(self) -> None:
        values = (
            self.thrust_scale,
            *self.thrust_axis_rad,
            *self.accel_bias_mps2,
            self.thrust_vbat_slope_per_v,
            self.thrust_vbat_ref_v,
        )
        if len(self.thrust_axis_rad) != 2 or len(self.accel_bias_mps2) != 3:
            raise ValueError(
                "ObservationCalibration needs thrust_axis_rad of 2 and accel_bias_mps2 of 3 "
                f"values, got {self.thrust_axis_rad!r} and {self.accel_bias_mps2!r}"
            )
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f"ObservationCalibration values must be finite, got {self!r}")
        if not (self.thrust_scale > 0.0 and self.thrust_vbat_ref_v > 0.0):
            raise ValueError(
                "ObservationCalibration.thrust_scale and thrust_vbat_ref_v must be > 0, got "
                f"{self.thrust_scale!r} and {self.thrust_vbat_ref_v!r}"
            )
        about_x, about_y = self.thrust_axis_rad
        if about_x == 0.0 and about_y == 0.0:
            axis = (0.0, 0.0, 1.0)
        else:
            axis = (
                math.sin(about_y),
                -math.sin(about_x) * math.cos(about_y),
                math.cos(about_x) * math.cos(about_y),
            )
        object.__setattr__(self, "thrust_axis_body", axis)

    @property
    def is_identity(self) -> bool:
        """True when the corrections change nothing (the defaults, any ``vbat_v``)."""
        return (
            self.thrust_scale == 1.0
            and self.thrust_axis_rad == (0.0, 0.0)
            and self.accel_bias_mps2 == (0.0, 0.0, 0.0)
            and self.thrust_vbat_slope_per_v == 0.0
        )

    def thrust_factor(self, vbat_v: float | None) -> float:
        """Factor on ``thrust_n``: ``thrust_scale + slope * (vbat_v - ref)``, dimensionless.

        Args:
            vbat_v: Battery voltage of the sample, V, or None (then ``thrust_scale``).
        """
        if vbat_v is None or self.thrust_vbat_slope_per_v == 0.0:
            return self.thrust_scale
        return self.thrust_scale + self.thrust_vbat_slope_per_v * (vbat_v - self.thrust_vbat_ref_v)


NO_CALIBRATION = ObservationCalibration()
"""The identity calibration (immutable)."""


@dataclass(frozen=True)
class TensionObservation:
    """One raw tension observation, or the reason there is none.

    Attributes:
        tension_world_n: Force of the tether on the drone, world frame, N, shape (3,);
            None while the drone is on the ground.
        on_ground: True when the sample was taken in ground contact (no estimate).
        reason: ``"ok"``, ``"disarmed"`` (motors not armed) or ``"low_thrust"``
            (thrust below half the weight, so the floor carries the drone).
        thrust_axis_world: The (calibrated) thrust axis ``R b`` in the world frame, unit,
            3 floats; orients the thrust-noise part of the observation covariance.
        thrust_n: The calibrated collective thrust ``F``, N.
    """

    tension_world_n: FloatArray | None
    on_ground: bool
    reason: Literal["ok", "disarmed", "low_thrust"]
    thrust_axis_world: tuple[float, float, float] = (0.0, 0.0, 1.0)
    thrust_n: float = math.nan


def observe_tension(
    accel_body_mps2: ArrayLike,
    quat_wxyz: ArrayLike,
    thrust_n: float,
    mass_kg: float,
    armed: bool = True,
    gravity_mps2: float = GRAVITY_MPS2,
    calibration: ObservationCalibration | None = None,
    vbat_v: float | None = None,
) -> TensionObservation:
    """Raw tension observation from one IMU + thrust sample (``eq:NE_tether``).

    The IMU reads the specific force ``f = R_world_body^T (p'' - g)`` with
    ``g = (0, 0, -gravity)``. Newton-Euler for the drone,
    ``m p'' = R b F + T + m g + F_ext``, then gives::

        T = m R f - R b F           # eq:NE_tether with F_ext = 0

    with ``b = e3`` and ``f``, ``F`` as reported unless a ``calibration`` corrects them
    (:class:`ObservationCalibration`: accelerometer bias, thrust scale and its battery
    slope, thrust axis). The paper writes ``m(a + g) - R F``; with the IMU's specific
    force this is the same content (NOTES "Tension observation"). External forces (drag)
    are neglected, as in the paper: at hover they are far below the noise.

    On the ground the floor's reaction (about the weight, ~0.3 N) would show up as
    upward "tension". So a sample from a disarmed drone, or with (calibrated) thrust below
    half the weight ``m * gravity / 2``, yields no tension, flagged with the reason.

    Args:
        accel_body_mps2: IMU specific force in the body frame, m/s^2, shape (3,)
            (about ``[0, 0, 9.81]`` level at rest).
        quat_wxyz: Attitude, body->world ``[w, x, y, z]``, shape (4,).
        thrust_n: Collective rotor thrust along body +z, N, >= 0.
        mass_kg: Drone mass, kg, > 0.
        armed: Whether the motors are armed.
        gravity_mps2: Magnitude of gravity, m/s^2.
        calibration: Sensor corrections, or None for none.
        vbat_v: Battery voltage of the sample, V (> 0), or None; used only by the
            calibration's battery slope.

    Returns:
        The observation (tension in the world frame, N) or the ground-contact reason.

    Raises:
        DegenerateQuaternionError: If the quaternion cannot be normalised.
        InvalidObservationError: If the acceleration is not a finite 3-vector, or the
            thrust, mass, gravity or battery voltage is not finite or out of range.
    """
    w, x, y, z = _unit_quaternion(quat_wxyz)  # raises first, as rotation_world_body did
    accel = _floats(accel_body_mps2, 3)
    if accel is None or not all(map(math.isfinite, accel)):
        accel = _vector3(accel_body_mps2, "accel_body_mps2").tolist()  # raises
    if not (math.isfinite(thrust_n) and thrust_n >= 0.0):
        raise InvalidObservationError(f"thrust_n must be finite and >= 0, got {thrust_n!r}")
    if not (math.isfinite(mass_kg) and mass_kg > 0.0):
        raise InvalidObservationError(f"mass_kg must be finite and > 0, got {mass_kg!r}")
    if not (math.isfinite(gravity_mps2) and gravity_mps2 > 0.0):
        raise InvalidObservationError(f"gravity_mps2 must be finite and > 0, got {gravity_mps2!r}")
    if vbat_v is not None and not (math.isfinite(vbat_v) and vbat_v > 0.0):
        raise InvalidObservationError(f"vbat_v must be finite and > 0, got {vbat_v!r}")
    bx, by, bz = 0.0, 0.0, 1.0
    if calibration is not None:
        thrust_n = thrust_n * calibration.thrust_factor(vbat_v)
        ax, ay, az = calibration.accel_bias_mps2
        accel = [accel[0] - ax, accel[1] - ay, accel[2] - az]
        bx, by, bz = calibration.thrust_axis_body
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz, wx, wy, wz = x * y, x * z, y * z, w * x, w * y, w * z
    # R as in rotation_world_body, multiplied out in scalars (numpy's per-call overhead is
    # most of the cost for a 3-vector; docs/pipeline_benchmark.md).
    r00, r01, r02 = 1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)
    r10, r11, r12 = 2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)
    r20, r21, r22 = 2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)
    if bx == 0.0 and by == 0.0:
        axis_world = (r02, r12, r22)
    else:
        axis_world = (
            r00 * bx + r01 * by + r02 * bz,
            r10 * bx + r11 * by + r12 * bz,
            r20 * bx + r21 * by + r22 * bz,
        )
    if not (math.isfinite(thrust_n) and thrust_n >= 0.0):
        raise InvalidObservationError(
            f"calibrated thrust must be finite and >= 0, got {thrust_n!r} (vbat_v={vbat_v!r})"
        )
    if not armed:
        return TensionObservation(None, True, "disarmed", axis_world, thrust_n)
    if thrust_n < 0.5 * mass_kg * gravity_mps2:
        return TensionObservation(None, True, "low_thrust", axis_world, thrust_n)
    # T = R (m f - b F): one rotation instead of two.
    fx = mass_kg * accel[0] - bx * thrust_n
    fy = mass_kg * accel[1] - by * thrust_n
    fz = mass_kg * accel[2] - bz * thrust_n
    tension = np.array(
        [
            r00 * fx + r01 * fy + r02 * fz,
            r10 * fx + r11 * fy + r12 * fz,
            r20 * fx + r21 * fy + r22 * fz,
        ]
    )
    tension.setflags(write=False)
    return TensionObservation(tension, False, "ok", axis_world, thrust_n)


def observation_cov_n2(
    quat_wxyz: ArrayLike | None,
    mass_kg: float,
    accel_noise_mps2: float,
    thrust_noise_n: float,
) -> FloatArray:
    """Covariance of one raw observation from :func:`observe_tension`.

    With white accelerometer noise ``n_a`` (per body axis) and thrust noise ``n_F``,
    ``T = R (m f - e3 F)`` has error ``m R n_a - R e3 n_F``, whose covariance is::

        R_obs = (m sigma_a)^2 I + sigma_F^2 (R e3)(R e3)^T

    because ``R R^T = I``. Attitude error adds ``delta_theta x T``, below 1 mN for
    0.01 rad at 0.1 N, and is neglected.

    Args:
        quat_wxyz: Attitude body->world ``[w, x, y, z]``, shape (4,), or None to take
            the thrust axis as world +z (level hover).
        mass_kg: Drone mass, kg.
        accel_noise_mps2: Accelerometer noise standard deviation per axis and sample,
            m/s^2.
        thrust_noise_n: Thrust noise standard deviation per sample, N.

    Returns:
        Covariance, N^2, shape (3, 3).
    """
    if quat_wxyz is None:
        thrust_axis_world = np.array([0.0, 0.0, 1.0])
    else:
        thrust_axis_world = rotation_world_body(quat_wxyz)[:, 2]
    cov = np.eye(3) * (mass_kg * accel_noise_mps2) ** 2
    cov += thrust_noise_n**2 * np.outer(thrust_axis_world, thrust_axis_world)
    return cov


@dataclass(frozen=True)
class TensionFilterParams:
    """Noise model and tuning of :class:`TensionFilter`.

    The defaults are the simulator's noise model (30 g drone, accelerometer noise
    0.3 m/s^2 per axis at 250 Hz, thrust noise 3 mN) and the tuning derived in the
    :class:`TensionFilter` docstring.

    Attributes:
        mass_kg: Drone mass, kg.
        accel_noise_mps2: Accelerometer noise std per axis and sample, m/s^2.
        thrust_noise_n: Thrust noise std per sample, N.
        random_walk_n_per_sqrt_s: Process noise of the constant-tension model at hover:
            the tension is modelled as a random walk with this std after one second,
            N/sqrt(s) (``Q = random_walk^2 * dt * I``). Sets the hover time constant.
        change_threshold: Threshold on the change statistic (a chi-square with 3
            degrees of freedom per window under no change), dimensionless.
        change_min_window: Shortest window of the change test, samples. Windows below 4
            would let one outlier trigger a detection.
        change_max_window: Longest window of the change test (and of the replay
            buffer), samples.
        drift_time_constant_s: Time constant of the innovation-bias average that drives
            the drift adaptation, s.
        drift_threshold: Level of the normalised innovation-bias statistic (chi-square,
            3 dof, under no drift) above which the process noise is raised.
        drift_max_scale: Largest factor on the hover process noise variance during a
            drift, dimensionless.
        converged_min_samples: Samples after start or reset before an estimate is
            reported as converged.
    """

    mass_kg: float = 0.030
    accel_noise_mps2: float = 0.3
    thrust_noise_n: float = 0.003
    random_walk_n_per_sqrt_s: float = 0.23e-3
    change_threshold: float = 50.0
    change_min_window: int = 4
    change_max_window: int = 256
    drift_time_constant_s: float = 0.5
    drift_threshold: float = 9.0
    drift_max_scale: float = 600.0
    drift_exponent: float = 3.0
    drift_memory_s: float = 1.0
    converged_min_samples: int = 25

    def __post_init__(self) -> None:
        positive = {
            "mass_kg": self.mass_kg,
            "accel_noise_mps2": self.accel_noise_mps2,
            "random_walk_n_per_sqrt_s": self.random_walk_n_per_sqrt_s,
            "change_threshold": self.change_threshold,
            "drift_time_constant_s": self.drift_time_constant_s,
            "drift_threshold": self.drift_threshold,
        }
        for name, value in positive.items():
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(
                    f"TensionFilterParams.{name} must be finite and > 0, got {value!r}"
                )
        if not (math.isfinite(self.thrust_noise_n) and self.thrust_noise_n >= 0.0):
            raise ValueError(
                f"TensionFilterParams.thrust_noise_n must be finite and >= 0, "
                f"got {self.thrust_noise_n!r}"
            )
        if not (math.isfinite(self.drift_max_scale) and self.drift_max_scale >= 1.0):
            raise ValueError(
                f"TensionFilterParams.drift_max_scale must be >= 1, got {self.drift_max_scale!r}"
            )
        if not (1 <= self.change_min_window <= self.change_max_window):
            raise ValueError(
                "TensionFilterParams needs 1 <= change_min_window <= change_max_window, got "
                f"{self.change_min_window} and {self.change_max_window}"
            )
        if self.converged_min_samples < 1:
            raise ValueError(
                "TensionFilterParams.converged_min_samples must be >= 1, "
                f"got {self.converged_min_samples}"
            )


@dataclass(frozen=True)
class TensionEstimate:
    """Filtered tension after one filter step.

    Attributes:
        tension_world_n: Force of the tether on the drone, world frame, N, shape (3,).
        cov_n2: Its covariance (the Kalman filter's P), N^2, shape (3, 3).
        std_n: Standard deviation per axis, ``sqrt(diag(P))``, N, shape (3,).
        converged: True once ``converged_min_samples`` observations have been taken
            since start or :meth:`TensionFilter.reset`.
        change_detected: True when this step detected a change of tension (a tug) and
            re-initialised the filter from the samples since the change.
        samples: Observations taken since start or reset.
        change_statistic: Largest windowed chi-square statistic of this step
            (dimensionless; a detection when above ``change_threshold``).
        process_noise_scale: Factor on the hover process noise applied this step by the
            drift adaptation (1 at hover).
    """

    tension_world_n: FloatArray
    cov_n2: FloatArray
    std_n: FloatArray
    converged: bool
    change_detected: bool
    samples: int
    change_statistic: float = 0.0
    process_noise_scale: float = 1.0


@dataclass
class _Ring:
    """Fixed-size history of the last observations since the current regime began."""

    size: int
    obs_n: FloatArray = field(init=False)
    axis: FloatArray = field(init=False)  # thrust axis u of each observation (R^-1 from it)
    # Running sums of the whitened innovations (dimensionless), newest window first:
    # sums[:, start + n - 1] = w_t + w_(t-1) + ... + w_(t-n+1) for n = 1 .. count. A new
    # innovation moves ``start`` back by one and is added in place to every window that
    # survives, so the change statistic needs no cumulative sum over the history each step
    # (the sums agree with that cumulative sum to rounding; they add oldest first).
    # Laid out (3, n) so the in-place add runs along contiguous rows; 4 x size columns so
    # the live windows move back to the end only every 3 x size steps.
    sums: FloatArray = field(init=False)
    start: int = 0
    head: int = 0  # next slot to write
    count: int = 0  # valid entries (innovations) since the regime began

    def __post_init__(self) -> None:
        self.obs_n = np.zeros((self.size, 3))
        self.axis = np.zeros((self.size, 3))
        self.sums = np.zeros((3, 4 * self.size))
        self.start = 4 * self.size

    def push(self, obs_n: NDArray[Any], axis: tuple[float, ...], innov: list[float]) -> None:
        head = self.head
        self.obs_n[head] = obs_n
        self.axis[head] = axis
        self.head = head + 1 if head + 1 < self.size else 0
        # Windows 1 .. n_grow become 2 .. n_grow + 1; the longest drops out once full.
        n_grow = min(self.count, self.size - 1)
        sums, start = self.sums, self.start
        if start == 0:
            start = sums.shape[1] - n_grow
            sums[:, start:] = sums[:, :n_grow]
        start -= 1
        sums[0, start], sums[1, start], sums[2, start] = innov
        if n_grow:
            grown = sums[:, start + 1 : start + 1 + n_grow]
            np.add(grown, sums[:, start : start + 1], out=grown)
        self.start = start
        self.count = min(self.count + 1, self.size)

    def latest_first(self, n: int) -> NDArray[np.intp]:
        """Indices of the ``n`` most recent entries, newest first."""
        return (self.head - 1 - np.arange(n)) % self.size

    def window_sums(self, n: int) -> FloatArray:
        """Sums of the newest 1 .. ``n`` whitened innovations, shape (3, n) (a view)."""
        return self.sums[:, self.start : self.start + n]


class TensionFilter:
    """Constant-tension Kalman filter with tug detection and drift adaptation.

    **Model** (``eq:sysk1``, ``eq:sysk2``, ``eq:Kalman_vars``): state x = (Tx, Ty, Tz),
    A = C = I, B = D = 0, observation y = raw tension from :func:`observe_tension`. The
    state and covariance live in a ``filterpy.kalman.KalmanFilter`` (``kf.x``,
    ``kf.P``); each step sets ``kf.Q`` and ``kf.R`` and calls ``kf.predict()`` then
    ``kf.update()`` (x- = x, P- = P + Q; K = P-(P- + R)^-1; x = x- + K(y - x-);
    P = (I-K)P-(I-K)^T + K R K^T, Joseph form).

    **Noise.** R per step from :func:`observation_cov_n2`: (m sigma_a)^2 = (9 mN)^2 per
    axis plus (3 mN)^2 along the thrust axis. Q = q dt I with q the squared
    ``random_walk_n_per_sqrt_s``, so an irregular or missing sample only widens P in
    proportion to the time elapsed.

    **Why a fixed gain cannot do it.** A constant-tension filter in steady state is an
    exponential average with time constant tau = sqrt(r dt / q) (r the per-sample
    variance, dt = 4 ms). For a constant tension its error variance is r dt / (2 tau),
    so the hover target of 0.5 mN RMS per axis needs tau >= 0.65 s, and we take
    tau = 2.5 s (q = (0.23 mN)^2/s) for 0.25 mN x/y and 0.27 mN z. The margin is for
    the scatter of a slow average: over one 25 s hover the RMS of a 2.5 s average
    varies by about +-30 %, so single runs must not sit near the limit. After a 30 mN
    step the same filter still carries exp(-0.3/2.5) = 89 % of the step after 0.3 s, where
    the target is 10 %: that needs tau <= 0.13 s, whose hover noise is 1.1 mN RMS.
    The two targets are an order of magnitude apart, so the gain must change with what
    the innovations say.

    **Tug detection (GLR on whitened innovations).** Each innovation nu is whitened by
    the Cholesky factor of S = P- + R, so that at constant tension w ~ N(0, I) and
    the innovations are white (a Kalman filter property). A step Delta k samples ago
    shifts the mean of the last k whitened innovations. For every window length
    n in [change_min_window, min(history, change_max_window)] the statistic
    ``|sum of the last n w|^2 / n`` is chi-square with 3 dof under no change; the
    largest is compared with ``change_threshold`` = 50. Bonferroni over 256 windows
    and 900 000 samples per hour gives at most ~0.02 false detections per hour at
    hover (chi2_3 tail at 50 is 8e-11; the windows are strongly correlated, so the
    real rate is far lower; the benchmark counts them). A 30 mN step is 3.2 sigma per
    sample, i.e. a non-centrality of ~10 per sample, so it is detected a few samples
    after the step (median 16 ms, at most 40 ms in the benchmark). The shortest window
    of 4 samples keeps a single outlier (a vibration spike) from triggering.

    **Re-initialisation by replay.** On detection the window with the largest
    statistic is the maximum-likelihood change point. The filter restarts from the
    observations since then: x = (sum R_i^-1)^-1 sum R_i^-1 y_i, P = (sum R_i^-1)^-1,
    which is what the Kalman filter itself would give from an uninformative prior with
    Q = 0 over those few samples. So after a tug the estimate is the mean of every
    post-tug sample (error 9 mN / sqrt(n): 1.0 mN per axis 0.3 s after the step); the
    detection delay costs nothing. The gain then decays by itself back to the hover
    gain as P shrinks to its steady state. Innovation history is cleared, so the test
    starts again on the new regime.

    **Slow drifts.** A tension that ramps (the drone moving) makes the slow filter lag
    by rate * tau (25 mN at 10 mN/s with tau = 2.5 s). An exponential average b of the
    whitened innovations over ``drift_time_constant_s`` = 0.5 s measures that lag; its
    normalised square D = |b|^2 / Var(b) is chi-square with 3 dof at constant tension.
    Above ``drift_threshold`` = 9 the process noise variance is scaled by
    (D / 9)^``drift_exponent`` (cubed), capped at ``drift_max_scale`` = 600 (tau down to
    0.1 s), which shortens tau until the lag falls back to the threshold (about 2 mN).
    The scale then decays back to 1 with ``drift_memory_s`` = 1 s rather than at once,
    so a re-initialisation (which clears b) does not forget the motion. Measured
    (docs/filter_benchmark.md, error pooled over axes): at 10 mN/s RMS 2.0 mN, max
    4.6 mN, 3 re-initialisations in 15 s, against 13.9 mN for the same filter without
    adaptation; at 1 mN/s 0.9 mN against 1.5 mN. Ramps well above 10 mN/s are in
    effect steps and the tug detector takes them over with repeated re-initialisations
    (RMS 3.8 mN at 30 mN/s, 5.9 mN at 100 mN/s). At hover D exceeds 9 about 3 % of the
    time, briefly; the hover RMS rises by about 4 % against the fixed filter.

    **Initialisation.** The first observation initialises the state (x = y, P = R),
    unlike the paper, whose filter started from T = 0: with H = 0 and s2 = 0 the
    localization then returned the plumb-line limit z = z_i - L = 0.754 - 1.6 =
    -0.846 m (``eq:in_instants``) until the filter converged. Starting from the first
    sample gives an unbiased estimate with an honest covariance from the first step.

    **Cost.** One step runs per telemetry message (2000/s for 8 drones), on 3-vectors
    and 3x3 matrices, where numpy's per-call overhead outweighs the arithmetic. So the
    work around filterpy is done in Python floats (R, the whitening Cholesky, the
    innovation bias), S^-1 goes through filterpy's ``inv`` hook as a 3x3 adjugate, R^-1
    is formed only for a re-initialisation's window, and the windowed innovation sums
    of the tug test are kept as running sums (one in-place add per step instead of a
    cumulative sum over up to 256 samples). The results equal the array formulas to
    rounding (tests/test_perf_equivalence.py; docs/pipeline_benchmark.md for the cost).
    """

    def __init__(self, params: TensionFilterParams | None = None) -> None:
        self.params = params if params is not None else TensionFilterParams()
        self._kf = KalmanFilter(dim_x=3, dim_z=3)
        self._kf.F = np.eye(3)  # A = I (eq:Kalman_vars)
        self._kf.H = np.eye(3)  # C = I
        # filterpy's hook for the inverse of S = P- + R in update() (its default is
        # np.linalg.inv, whose per-call overhead is most of its cost on a 3x3).
        self._kf.inv = _inv3
        self._ring = _Ring(self.params.change_max_window)
        self._beta_cache: tuple[float, float] = (math.nan, math.nan)
        self._decay_cache: tuple[float, float] = (math.nan, math.nan)
        self._constants_for: TensionFilterParams | None = None
        self._s2 = self._f2 = self._k = self._random_walk2 = math.nan
        self._windows: FloatArray = np.zeros(0)
        self.reset()

    # -- state -------------------------------------------------------------------------

    def reset(
        self,
        prior_world_n: tuple[float, float, float] | None = None,
        prior_std_n: tuple[float, float, float] | None = None,
    ) -> None:
        """Forgets everything: the next observation initialises the filter again.

        Args:
            prior_world_n: Optional prior tension, world frame, N. Without it the first
                observation alone initialises the state (x = y, P = R); with it the first
                observation updates ``N(prior, diag(prior_std_n^2))`` like any other, so a
                restart is not one raw sample (9 mN noise per axis) when the tension is
                known to be near the prior, e.g. at lift-off, when the tether rests on the
                floor and pulls on the drone with next to nothing. A wrong prior shows in
                the innovations and the change test restarts from the samples alone.
            prior_std_n: Its standard deviation per axis, N (required with a prior).
        """
        if (prior_world_n is None) != (prior_std_n is None):
            raise ValueError("reset needs both prior_world_n and prior_std_n, or neither")
        self._prior = None
        if prior_world_n is not None and prior_std_n is not None:
            x0 = _vector3(prior_world_n, "prior_world_n")
            std = _vector3(prior_std_n, "prior_std_n")
            if not np.all(std > 0.0):
                raise ValueError(f"prior_std_n must be > 0, got {prior_std_n!r}")
            self._prior = (x0, np.diag(std * std))
        self._initialized = False
        self._samples = 0
        self._bias = [0.0, 0.0, 0.0]  # EWMA of whitened innovations
        self._bias_var = 0.0  # its variance per axis at no drift
        self._scale = 1.0
        self._ring.count = 0
        self._last: TensionEstimate | None = None

    @property
    def initialized(self) -> bool:
        """Whether an observation has initialised the state since start or reset."""
        return self._initialized

    @property
    def estimate(self) -> TensionEstimate | None:
        """The latest estimate, or None before the first observation."""
        return self._last

    @property
    def kalman_filter(self) -> KalmanFilter:
        """The underlying filterpy filter (read it; do not step it from outside)."""
        return self._kf

    # -- steps -------------------------------------------------------------------------

    def update(
        self,
        tension_obs_world_n: ArrayLike,
        dt_s: float,
        quat_wxyz: ArrayLike | None = None,
        thrust_axis_world: tuple[float, float, float] | None = None,
    ) -> TensionEstimate:
        """One filter step with an observation.

        Args:
            tension_obs_world_n: Raw tension observation, world frame, N, shape (3,)
                (``TensionObservation.tension_world_n``).
            dt_s: Time since the previous step, s, >= 0 (ignored for the first
                observation after start or reset).
            quat_wxyz: Attitude of the sample, body->world ``[w, x, y, z]``, to orient
                the thrust-noise part of R; None takes the thrust axis as world +z.
            thrust_axis_world: The thrust axis in the world frame, unit, 3 floats
                (``TensionObservation.thrust_axis_world``); when given it replaces the
                axis derived from ``quat_wxyz``.

        Returns:
            The estimate after this step.

        Raises:
            InvalidObservationError: If the observation is not a finite 3-vector.
            InvalidTimeStepError: If ``dt_s`` is negative or not finite.
            DegenerateQuaternionError: If the quaternion cannot be normalised.
        """
        p = self.params
        if p is not self._constants_for:
            self._set_constants()
        y = _vector3(tension_obs_world_n, "tension_obs_world_n")
        dt = _check_dt(dt_s)
        u = _thrust_axis(quat_wxyz) if thrust_axis_world is None else thrust_axis_world
        R = self._observation_cov(u)
        kf = self._kf
        if not self._initialized and self._prior is None:
            # First sample: x = y, P = R (see the class docstring).
            kf.x = y.reshape(3, 1).copy()
            kf.P = R.copy()
            self._initialized = True
            self._samples = 1
            self._bias = [0.0, 0.0, 0.0]
            self._bias_var = 0.0
            self._scale = 1.0
            self._ring.count = 0
            return self._publish(False, 0.0, 1.0)
        if not self._initialized:
            # First sample after a reset with a prior: x- = prior, P- = its covariance,
            # then the usual update (no prediction step: no time has passed).
            x0, P0 = self._prior  # type: ignore[misc]
            kf.x = x0.reshape(3, 1).copy()
            kf.P = P0.copy()
            self._prior = None
            self._initialized = True
            self._samples = 0
            self._bias = [0.0, 0.0, 0.0]
            self._bias_var = 0.0
            self._scale = 1.0
            self._ring.count = 0
            dt = 0.0

        scale = self._drift_scale(dt)
        kf.Q = _EYE3 * (scale * self._random_walk2 * dt)  # Q = q dt I
        kf.R = R
        kf.predict()  # x- = A x,  P- = A P A' + Q
        kf.update(y)  # K = P-C'(CP-C' + R)^-1,  x = x- + K(y - Cx-),  Joseph-form P
        self._samples += 1

        # Whitened innovation w = L^-1 nu with S = L L' (filterpy kept nu and S).
        innov = _whiten(kf.S, kf.y)
        self._update_bias(innov, dt)
        self._ring.push(y, u, innov)
        stat, window = self._change_statistic()
        if stat > p.change_threshold:
            self._reinitialize(window)
            return self._publish(True, stat, scale)
        return self._publish(False, stat, scale)

    def coast(self, dt_s: float) -> TensionEstimate | None:
        """One filter step without an observation (ground contact, dropped sample).

        Only the prediction runs (x- = x, P- = P + Q), so the uncertainty grows with
        the time elapsed. Before the first observation there is nothing to coast.

        Args:
            dt_s: Time since the previous step, s, >= 0.

        Returns:
            The predicted estimate, or None before the first observation.

        Raises:
            InvalidTimeStepError: If ``dt_s`` is negative or not finite.
        """
        dt = _check_dt(dt_s)
        if not self._initialized:
            return None
        self._kf.Q = np.eye(3) * (self.params.random_walk_n_per_sqrt_s**2 * dt)
        self._kf.predict()
        return self._publish(False, 0.0, 1.0)

    # -- internals ---------------------------------------------------------------------

    def _observation_cov(self, u: tuple[float, float, float]) -> FloatArray:
        """R of :func:`observation_cov_n2` for the thrust axis ``u``: R = s^2 I + f^2 u u'.

        In scalars, element for element the array expression (``np.eye(3) * s2 + f2 *
        np.outer(u, u)``), without numpy's per-call overhead.
        """
        ux, uy, uz = u
        s2, f2 = self._s2, self._f2
        oxy, oxz, oyz = 0.0 + f2 * (ux * uy), 0.0 + f2 * (ux * uz), 0.0 + f2 * (uy * uz)
        return np.array(
            [
                [s2 + f2 * (ux * ux), oxy, oxz],
                [oxy, s2 + f2 * (uy * uy), oyz],
                [oxz, oyz, s2 + f2 * (uz * uz)],
            ]
        )

    def _observation_info(self, axes: FloatArray) -> FloatArray:
        """R^-1 for observations with thrust axes ``axes`` (n, 3), by Sherman-Morrison.

        R = s^2 I + f^2 u u' with |u| = 1 gives R^-1 = (I - f^2 / (s^2 + f^2) u u') / s^2.
        Only a re-initialisation needs it, so it is computed then, for the window.

        Returns:
            Shape (n, 3, 3), 1/N^2.
        """
        uu = axes[:, :, None] * axes[:, None, :]  # np.outer per observation
        info: FloatArray = (_EYE3 - self._k * uu) / self._s2
        return info

    def _set_constants(self) -> None:
        """Per-parameter constants of the step (recomputed if ``params`` is replaced)."""
        p = self.params
        self._s2 = (p.mass_kg * p.accel_noise_mps2) ** 2
        self._f2 = p.thrust_noise_n**2
        self._k = self._f2 / (self._s2 + self._f2)
        self._random_walk2 = p.random_walk_n_per_sqrt_s**2
        self._beta_cache = (math.nan, math.nan)
        self._decay_cache = (math.nan, math.nan)
        # Window lengths of the change statistic; the ring keeps its size from construction.
        self._windows = np.arange(p.change_min_window, self._ring.size + 1, dtype=np.float64)
        self._constants_for = p

    def _update_bias(self, innov: list[float], dt: float) -> None:
        # EWMA b = (1 - beta) b + beta w, with beta from the time constant and dt.
        if self._beta_cache[0] != dt:
            beta = -math.expm1(-dt / self.params.drift_time_constant_s) if dt > 0 else 0.0
            self._beta_cache = (dt, beta)
        beta = self._beta_cache[1]
        b0, b1, b2 = self._bias
        w0, w1, w2 = innov
        self._bias = [b0 + beta * (w0 - b0), b1 + beta * (w1 - b1), b2 + beta * (w2 - b2)]
        # Var(b) = (1 - beta)^2 Var(b) + beta^2 per axis, for white unit w.
        self._bias_var = (1.0 - beta) ** 2 * self._bias_var + beta * beta

    def _drift_scale(self, dt: float) -> float:
        p = self.params
        inst = 1.0
        if self._bias_var > 0.0:
            b0, b1, b2 = self._bias
            d = ((b0 * b0 + b1 * b1) + b2 * b2) / self._bias_var  # |b|^2, numpy's dot order
            ratio = d / p.drift_threshold
            if ratio > 1.0:
                inst = min(ratio**p.drift_exponent, p.drift_max_scale)
        # The scale decays with drift_memory_s rather than dropping at once, so a re-initialisation
        # (which clears the innovation bias) does not forget that the tension was moving.
        if self._decay_cache[0] != dt:
            decay = math.exp(-dt / p.drift_memory_s) if p.drift_memory_s > 0 else 0.0
            self._decay_cache = (dt, decay)
        decay = self._decay_cache[1]
        self._scale = max(inst, 1.0 + (self._scale - 1.0) * decay)
        if self._scale < 1.0 + 1e-3:
            self._scale = 1.0
        return self._scale

    def _change_statistic(self) -> tuple[float, int]:
        """Largest windowed statistic |sum of last n whitened innovations|^2 / n."""
        p = self.params
        n_valid = self._ring.count
        if n_valid < p.change_min_window:
            return 0.0, 0
        # The ring keeps the window sums; the window lengths are floats made once.
        sums = self._ring.window_sums(n_valid)[:, p.change_min_window - 1 :]
        n = self._windows[: n_valid - p.change_min_window + 1]
        stats = np.einsum("ij,ij->j", sums, sums) / n
        best = int(stats.argmax())
        return float(stats[best]), int(n[best])

    def _reinitialize(self, window: int) -> None:
        """Restarts x, P from the observations of the last ``window`` samples."""
        idx = self._ring.latest_first(window)
        info_n2 = self._observation_info(self._ring.axis[idx])  # R_i^-1
        info = info_n2.sum(axis=0)  # sum R_i^-1
        info_obs = np.einsum("kij,kj->i", info_n2, self._ring.obs_n[idx])
        P = np.linalg.inv(info)  # P = (sum R_i^-1)^-1
        P = 0.5 * (P + P.T)
        self._kf.P = P
        self._kf.x = (P @ info_obs).reshape(3, 1)  # x = P sum R_i^-1 y_i
        self._ring.count = 0
        self._bias = [0.0, 0.0, 0.0]
        self._bias_var = 0.0

    def _publish(self, change: bool, stat: float, scale: float) -> TensionEstimate:
        kf = self._kf
        p00, p11, p22 = kf.P.diagonal().tolist()
        std = np.array([_sqrt_clipped(p00), _sqrt_clipped(p11), _sqrt_clipped(p22)])
        std.setflags(write=False)
        est = TensionEstimate(
            tension_world_n=_frozen(kf.x[:, 0]),
            cov_n2=_frozen(kf.P),
            std_n=std,  # sqrt(clip(diag(P), 0))
            converged=self._samples >= self.params.converged_min_samples,
            change_detected=change,
            samples=self._samples,
            change_statistic=stat,
            process_noise_scale=scale,
        )
        self._last = est
        return est


def _inv3(S: FloatArray) -> FloatArray:
    """Inverse of a 3x3 matrix by its adjugate: S^-1 = adj(S) / det(S).

    Installed as ``KalmanFilter.inv``, filterpy's hook for the inverse it needs in
    ``update`` (K = P- C' (C P- C' + R)^-1). There S is symmetric positive definite with
    eigenvalues at least (m sigma_a)^2 = (9 mN)^2, so the adjugate form is as accurate as
    np.linalg.inv's LU (agreement to rounding). A singular or non-finite S takes
    np.linalg.inv, which decides what happens, as before.

    Args:
        S: Shape (3, 3).

    Returns:
        The inverse, shape (3, 3).
    """
    (a, b, c), (d, e, f), (g, h, i) = S.tolist()
    c00, c01, c02 = e * i - f * h, c * h - b * i, b * f - c * e
    det = a * c00 + d * c01 + g * c02
    if not (det != 0.0 and math.isfinite(det)):
        return np.asarray(np.linalg.inv(S), dtype=np.float64)
    return (
        np.array(
            [
                [c00, c01, c02],
                [f * g - d * i, a * i - c * g, c * d - a * f],
                [d * h - e * g, b * g - a * h, a * e - b * d],
            ]
        )
        / det
    )


def _sqrt_clipped(v: float) -> float:
    """``np.sqrt(np.clip(v, 0.0, None))`` for one value (NaN stays NaN)."""
    return math.sqrt(v) if v > 0.0 else (v if v != v else 0.0)


def _whiten(S: FloatArray, nu: FloatArray) -> list[float]:
    """Whitened innovation ``L^-1 nu`` with ``S = L L'`` (Cholesky), in scalars.

    Equal to ``np.linalg.solve(np.linalg.cholesky(S), nu)`` up to rounding (numpy's cost
    for a 3x3 is mostly per-call overhead). Like numpy, reads the lower triangle of S and
    raises ``LinAlgError`` when S is not positive definite.

    Args:
        S: Innovation covariance, shape (3, 3).
        nu: Innovation, shape (3, 1) or (3,).

    Returns:
        The whitened innovation, 3 floats.
    """
    (s00, _, _), (s10, s11, _), (s20, s21, s22) = S.tolist()
    n0, n1, n2 = nu.ravel().tolist()
    if not s00 > 0.0:
        raise np.linalg.LinAlgError("Matrix is not positive definite")
    l00 = math.sqrt(s00)
    l10 = s10 / l00
    l20 = s20 / l00
    d1 = s11 - l10 * l10
    if not d1 > 0.0:
        raise np.linalg.LinAlgError("Matrix is not positive definite")
    l11 = math.sqrt(d1)
    l21 = (s21 - l20 * l10) / l11
    d2 = s22 - l20 * l20 - l21 * l21
    if not d2 > 0.0:
        raise np.linalg.LinAlgError("Matrix is not positive definite")
    l22 = math.sqrt(d2)
    w0 = n0 / l00
    w1 = (n1 - l10 * w0) / l11
    w2 = (n2 - l20 * w0 - l21 * w1) / l22
    return [w0, w1, w2]


def _check_dt(dt_s: float) -> float:
    dt = float(dt_s)
    if not (math.isfinite(dt) and dt >= 0.0):
        raise InvalidTimeStepError(f"dt_s must be finite and >= 0, got {dt_s!r}")
    return dt
