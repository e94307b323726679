"""Tether tension from IMU + thrust, and the tension filter (paper sec. tens_estimate).

Pure physics: numpy and Python floats only (the filter is three scalar Kalman filters in
closed form, :class:`DiagonalKalman`); time enters as ``dt_s``. Two parts:

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
import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from groundstation.attitude import GRAVITY_MPS2, QUAT_MIN_NORM, Rows, rows_from_unit_quat
from groundstation.tension_change import (
    ChangeTest,
    LazyChangeStatistic,
    exceedance_chi2,
    exceedance_sigmas,
    level_samples,
    level_scatter_factor,
    noise_warmup_samples,
    scan_threshold,
    youth_factor,
)
from groundstation.tension_change import _Ring as _Ring
from groundstation.tension_drift import RESCALE_TOLERANCE, DriftAdaptation
from groundstation.tension_kalman import DiagonalKalman, HoverVelocity, MovingTension
from groundstation.tension_noise import NoiseEstimate, NoiseStatus
from groundstation.thrust_model import (
    MOTORS,
    NOMINAL_PWM_MAP,
    PWM_FULL_SCALE,
    ROTOR_EXPONENT,
    THRUST_MODELS,
    ThrustModel,
)

__all__ = [
    "GAP_S",
    "GRAVITY_MPS2",
    "NO_CALIBRATION",
    "DegenerateQuaternionError",
    "DiagonalKalman",
    "FilterStep",
    "HoverStep",
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
    "rotation_rows",
    "rotation_world_body",
    "scan_threshold",
    "thrust_axis_body",
]

GAP_S = NoiseEstimate.BLOCK_S
"""A stamp gap longer than this breaks a stream's chain of samples, s: the tension
filter's noise model and change windows (:class:`TensionFilter`), the rest detector's still
window (:class:`~groundstation.calibration.RestCalibrator`) and a hover run of
``calibrate`` (:class:`~groundstation.calibration.HoverCriteria`). One block of the noise
estimate (0.25 s): a stream silent for a whole block leaves a block without samples, and
the chain of block means the noise's shape is read from needs every block. 25 samples at
100 Hz, longer than real telemetry's own gaps (motion capture's up to 150 ms)."""
_EYE3 = np.eye(3)
_EYE3.setflags(write=False)

FloatArray = NDArray[np.float64]

# The per-message results, made without numpy's and the frozen dataclass's per-call
# overhead (a read-only array on an immutable buffer; the instance dict set at once):
# the same values, types, shapes and read-only flags as the plain constructors give.
_PACK3 = struct.Struct("3d").pack
_PACK15 = struct.Struct("15d").pack
_ndarray = np.ndarray
_F64 = np.dtype(np.float64)
_SHAPE3 = (3,)
_SHAPE33 = (3, 3)
_new_object = object.__new__
_object_setattr = object.__setattr__


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
            if norm >= QUAT_MIN_NORM:
                return w / norm, x / norm, y / norm, z / norm
    # Degenerate, overflowing or an unusual type: the array code raises or copes.
    w, x, y, z = _unit_quaternion_array(quat_wxyz).tolist()
    return w, x, y, z


def _unit_quaternion_array(quat_wxyz: ArrayLike) -> FloatArray:
    q = np.asarray(quat_wxyz, dtype=np.float64)
    if q.shape != (4,):
        raise DegenerateQuaternionError(f"quat_wxyz must have shape (4,), got shape {q.shape}")
    norm = float(np.sqrt(q @ q)) if np.all(np.isfinite(q)) else math.nan
    if not (norm >= QUAT_MIN_NORM):  # also catches nan/inf
        raise DegenerateQuaternionError(
            f"quat_wxyz={q.tolist()} cannot be normalised (norm {norm!r} < {QUAT_MIN_NORM})"
        )
    out: FloatArray = q / norm
    return out


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
    return np.array(rows_from_unit_quat(*_unit_quaternion(quat_wxyz)))


def rotation_rows(quat_wxyz: ArrayLike) -> Rows:
    """``R_world_body`` as three rows of floats
    (:func:`groundstation.attitude.rows_from_unit_quat`), the quaternion normalised and
    checked as in :func:`rotation_world_body`.

    Raises:
        DegenerateQuaternionError: As :func:`rotation_world_body`.
    """
    return rows_from_unit_quat(*_unit_quaternion(quat_wxyz))


def thrust_axis_body(about_x_rad: float, about_y_rad: float) -> tuple[float, float, float]:
    """The thrust axis ``R_x(about_x) · R_y(about_y) · e3`` in the body frame, unit.

    ``R_y(β)·e3 = (sin β, 0, cos β)``; then ``R_x(α)`` gives
    ``(sin β, −sin α·cos β, cos α·cos β)``. Exactly ``(0, 0, 1)`` for zero angles, so the
    default calibration leaves eq:NE_tether bit for bit as it was.

    Args:
        about_x_rad: Rotation about body x, rad.
        about_y_rad: Rotation about body y, rad.
    """
    if about_x_rad == 0.0 and about_y_rad == 0.0:
        return (0.0, 0.0, 1.0)
    return (
        math.sin(about_y_rad),
        -math.sin(about_x_rad) * math.cos(about_y_rad),
        math.cos(about_x_rad) * math.cos(about_y_rad),
    )


@dataclass(frozen=True)
class ObservationCalibration:
    """Sensor corrections applied in :func:`observe_tension` (config ``[calibration]``).

    The model, in the body frame of the attitude that Telemetry reports::

        f   = accel_mps2 - accel_bias_mps2
        F   = thrust_n * (thrust_scale + thrust_vbat_slope_per_v * (vbat_v - thrust_vbat_ref_v))
                                              # thrust_model "vbat_linear"
        F   = thrust_scale * 4 f_ref (v / v_ref)^n,   v = vbat_v pwm(thrust_n) / 65535
                                              # thrust_model "motor_voltage"
        b   = R_x(about_x) R_y(about_y) e3
            = (sin about_y, -sin about_x cos about_y, cos about_x cos about_y)
        T   = m R f - R b F + R D R^T v          # eq:NE_tether with the corrections

    ``D = diag(D_xy, D_xy, 0)`` is the rotors' momentum drag in the body frame (the drag force
    ``-R D R^T v`` would otherwise read as tension; :mod:`groundstation.slow_accel` says where
    ``v`` comes from). The linear voltage term applies only when the sample carries
    ``vbat_v``; the motor-voltage model (:mod:`groundstation.thrust_model`) takes
    ``thrust_vbat_ref_v`` for a sample without one. The drag term applies only with a
    velocity. The defaults change nothing (``T = m R f - R e3 F``, bit for bit the
    uncalibrated formula).

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
        rotor_drag_n_s_per_m: ``D_xy``, the rotors' drag per body-horizontal speed,
            N·s/m, >= 0.
        thrust_model: ``"vbat_linear"`` or ``"motor_voltage"`` (the model above).
        thrust_pwm_map: ``(a, b, c)``: the per-motor map ``a·pwm² + b·pwm + c`` N that
            made ``thrust_n`` (motor-voltage model; ``a > 0``, ``b >= 0``).
        thrust_motor_ref_n: ``f_ref``, one motor's thrust at ``thrust_motor_ref_v``, N > 0;
            None (not calibrated): the motor model is not in force, the straight line's
            terms apply.
        thrust_motor_ref_v: ``v_ref``, the reference motor voltage, V > 0.
        thrust_motor_exponent: ``n``, dimensionless, > 0.
    """

    thrust_scale: float = 1.0
    thrust_axis_rad: tuple[float, float] = (0.0, 0.0)
    accel_bias_mps2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    thrust_vbat_slope_per_v: float = 0.0
    thrust_vbat_ref_v: float = 3.9
    rotor_drag_n_s_per_m: float = 0.0
    thrust_model: ThrustModel = "vbat_linear"
    thrust_pwm_map: tuple[float, float, float] = NOMINAL_PWM_MAP
    thrust_motor_ref_n: float | None = None
    thrust_motor_ref_v: float = 3.0
    thrust_motor_exponent: float = ROTOR_EXPONENT
    thrust_axis_body: tuple[float, float, float] = field(init=False, repr=False)
    """``b = R_x(about_x) R_y(about_y) e3``, body frame, unit (derived)."""
    thrust_n: Callable[[float, float | None], float] = field(init=False, repr=False, compare=False)
    """``thrust_n(thrust_n, vbat_v)``: the calibrated collective thrust ``F`` of
    :attr:`thrust_model`, N, from Telemetry's ``thrust_n`` (N, >= 0) and ``vbat_v`` (V, or
    None); the model's method, chosen once here rather than on every message."""
    _motor: tuple[float, float, float, float, float, float] = field(init=False, repr=False)
    """The motor-voltage model folded into ``(k, a, c4, b², b, n)`` (derived, module
    groundstation.thrust_model): ``F = k·(vbat·(√(b² + a·thrust_n − c4) − b))^n`` with
    ``k = s·4·f_ref / (2a·65535·v_ref)^n``, ``c4 = 4ac``: the map's inversion and the power
    in one expression, as cheap per message as the straight line."""

    def __post_init__(self) -> None:
        values = (
            self.thrust_scale,
            *self.thrust_axis_rad,
            *self.accel_bias_mps2,
            self.thrust_vbat_slope_per_v,
            self.thrust_vbat_ref_v,
            self.rotor_drag_n_s_per_m,
        )
        if len(self.thrust_axis_rad) != 2 or len(self.accel_bias_mps2) != 3:
            raise ValueError(
                "ObservationCalibration needs thrust_axis_rad of 2 and accel_bias_mps2 of 3 "
                f"values, got {self.thrust_axis_rad!r} and {self.accel_bias_mps2!r}"
            )
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f"ObservationCalibration values must be finite, got {self!r}")
        if self.rotor_drag_n_s_per_m < 0.0:
            raise ValueError(
                "ObservationCalibration.rotor_drag_n_s_per_m must be >= 0, got "
                f"{self.rotor_drag_n_s_per_m!r}"
            )
        if not (self.thrust_scale > 0.0 and self.thrust_vbat_ref_v > 0.0):
            raise ValueError(
                "ObservationCalibration.thrust_scale and thrust_vbat_ref_v must be > 0, got "
                f"{self.thrust_scale!r} and {self.thrust_vbat_ref_v!r}"
            )
        object.__setattr__(self, "thrust_axis_body", thrust_axis_body(*self.thrust_axis_rad))
        a, b, c = self.thrust_pwm_map
        ref_n = self.thrust_motor_ref_n
        motor = (
            1.0 if ref_n is None else ref_n,
            self.thrust_motor_ref_v,
            self.thrust_motor_exponent,
            a,
            b,
            c,
        )
        if self.thrust_model not in THRUST_MODELS:
            raise ValueError(f"ObservationCalibration.thrust_model {self.thrust_model!r}")
        if not all(math.isfinite(v) for v in motor) or min(motor[:4]) <= 0.0 or b < 0.0:
            raise ValueError(
                "ObservationCalibration: thrust_motor_ref_n, thrust_motor_ref_v, "
                "thrust_motor_exponent and the map's a must be finite and > 0, b >= 0, got "
                f"{motor!r}"
            )
        n = self.thrust_motor_exponent
        k = (
            self.thrust_scale
            * MOTORS
            * motor[0]
            / (2.0 * a * PWM_FULL_SCALE * self.thrust_motor_ref_v) ** n
        )
        object.__setattr__(self, "_motor", (k, a, 4.0 * a * c, b * b, b, n))
        linear = not self.motor_model_in_force
        object.__setattr__(self, "thrust_n", self._thrust_linear if linear else self._thrust_motor)

    @property
    def motor_model_in_force(self) -> bool:
        """``motor_voltage`` with its constants (``thrust_motor_ref_n`` fitted); without them
        the straight line's terms apply (the defaults: none)."""
        return self.thrust_model == "motor_voltage" and self.thrust_motor_ref_n is not None

    @property
    def is_identity(self) -> bool:
        """True when the corrections change nothing (the defaults, any ``vbat_v``)."""
        return (
            not self.motor_model_in_force
            and self.thrust_scale == 1.0
            and self.thrust_axis_rad == (0.0, 0.0)
            and self.accel_bias_mps2 == (0.0, 0.0, 0.0)
            and self.thrust_vbat_slope_per_v == 0.0
            and self.rotor_drag_n_s_per_m == 0.0
        )

    def _thrust_linear(self, thrust_n: float, vbat_v: float | None) -> float:
        """:attr:`thrust_n` of ``vbat_linear``, N."""
        if vbat_v is None or self.thrust_vbat_slope_per_v == 0.0:
            return thrust_n * self.thrust_scale
        return thrust_n * (
            self.thrust_scale + self.thrust_vbat_slope_per_v * (vbat_v - self.thrust_vbat_ref_v)
        )

    def _thrust_motor(self, thrust_n: float, vbat_v: float | None) -> float:
        """:attr:`thrust_n` of ``motor_voltage``, N: groundstation.thrust_model's
        ``motor_voltage_thrust_n`` times the scale, folded (``_motor``; tested equal)."""
        k, a, c4, b2, b, n = self._motor
        d = b2 + a * thrust_n - c4  # b² + 4a·(thrust_n/4 − c)
        if d <= b2:  # the mean command at or below 0: the motors are off
            return 0.0
        if vbat_v is None:
            vbat_v = self.thrust_vbat_ref_v
        return k * (vbat_v * (d**0.5 - b)) ** n


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
    ground_thrust_ratio: float = 0.5,
    velocity_world_mps: tuple[float, float, float] | None = None,
    rotation_rows_world_body: Rows | None = None,
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
    ``ground_thrust_ratio`` of the weight (``[filter] ground_thrust_ratio``, 0.5), yields
    no tension, flagged with the reason. Between that and the weight the floor may still
    carry the drone: :mod:`groundstation.contact` decides that, with hysteresis.

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
        ground_thrust_ratio: Below this fraction of the weight the floor carries the
            drone, in (0, 1).
        velocity_world_mps: The drone's velocity, world frame, m/s, for the calibration's
            rotor drag (None: no drag term).
        rotation_rows_world_body: ``quat_wxyz``'s rotation already computed by
            :func:`rotation_rows` (the per-message path computes it once for every
            stage), or None to compute it here.

    Returns:
        The observation (tension in the world frame, N) or the ground-contact reason.

    Raises:
        DegenerateQuaternionError: If the quaternion cannot be normalised.
        InvalidObservationError: If the acceleration is not a finite 3-vector, or the
            thrust, mass, gravity or battery voltage is not finite or out of range.
    """
    if rotation_rows_world_body is None:
        rotation_rows_world_body = rotation_rows(quat_wxyz)  # raises first
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
    drag = 0.0
    if calibration is not None:
        drag = calibration.rotor_drag_n_s_per_m
        thrust_n = calibration.thrust_n(thrust_n, vbat_v)
        ax, ay, az = calibration.accel_bias_mps2
        accel = [accel[0] - ax, accel[1] - ay, accel[2] - az]
        bx, by, bz = calibration.thrust_axis_body
    # R in scalars (numpy's per-call overhead is most of the cost for a 3-vector;
    # docs/pipeline_benchmark.md).
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = rotation_rows_world_body
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
    if thrust_n < ground_thrust_ratio * mass_kg * gravity_mps2:
        return TensionObservation(None, True, "low_thrust", axis_world, thrust_n)
    # T = R (m f - b F): one rotation instead of two.
    fx = mass_kg * accel[0] - bx * thrust_n
    fy = mass_kg * accel[1] - by * thrust_n
    fz = mass_kg * accel[2] - bz * thrust_n
    if drag > 0.0 and velocity_world_mps is not None:
        # + D (R^T v)_xy in the body frame: the rotors' drag added back (it is no tension).
        vx, vy, vz = velocity_world_mps
        fx += drag * (r00 * vx + r10 * vy + r20 * vz)
        fy += drag * (r01 * vx + r11 * vy + r21 * vz)
    # Read-only, as np.array + setflags(write=False) made it, at a third of the cost.
    tension = _ndarray(
        _SHAPE3,
        _F64,
        _PACK3(
            r00 * fx + r01 * fy + r02 * fz,
            r10 * fx + r11 * fy + r12 * fz,
            r20 * fx + r21 * fy + r22 * fz,
        ),
    )
    obs = _new_object(TensionObservation)  # TensionObservation(...) without __init__
    _object_setattr(
        obs,
        "__dict__",
        {
            "tension_world_n": tension,
            "on_ground": False,
            "reason": "ok",
            "thrust_axis_world": axis_world,
            "thrust_n": thrust_n,
        },
    )
    return obs


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
    """Noise prior and tuning of :class:`TensionFilter`.

    Every window and time constant is in seconds, so the filter behaves the same at any
    rate from 50 to 500 Hz and with jittered stamps; the derivation and the numbers are in
    the :class:`TensionFilter` docstring.

    Attributes:
        mass_kg: Drone mass, kg.
        accel_noise_mps2: Prior accelerometer noise std per axis and sample, m/s^2: the
            observation noise until the on-line estimate has data (and for good with
            ``estimate_noise=False``).
        thrust_noise_n: Prior thrust noise std per sample, N (added along world z).
        estimate_noise: Estimate the observation noise (variance and lag-1
            autocorrelation per axis) on line; False keeps the prior, white.
        noise_time_constant_s: Memory of the noise estimate, s.
        noise_prior_samples: Weight of the prior in the noise estimate, samples.
        hover_time_constant_s: Shortest time constant of the filter at hover, s: the
            process noise is ``Q = r dt_mean / tau^2 * dt`` per axis (r the observation
            noise, dt_mean the mean sample spacing), tau at least this whatever the noise
            level and the rate.
        hover_wander_n2_per_s: Spectral density of the tension's own wander at hover (a
            random walk: tether swing, hover motion), N^2/s. The hover time constant is
            ``sqrt(r dt_mean / q)`` (the steady-state Kalman filter of a random walk in
            noise), at least ``hover_time_constant_s``: longer memory where the noise is
            larger. 0: tau = ``hover_time_constant_s``.
        false_alarms_per_h: False detections per hour of hover the change test is set
            for, 1/h: its threshold is derived from it
            (:func:`~groundstation.tension_change.scan_threshold` over the test's
            windows at the measured sample spacing); 0: no change test. The test's one knob.
        change_min_window: Shortest window of the change test, samples (a single outlier
            cannot trigger a detection).
        change_min_step_weight_ratio: The smallest step the change test's windows are
            sized for, as a fraction of the weight ``m·g`` (20 mN at 30 g), dimensionless:
            its longest window is the one in which that step's samples reach the threshold
            as applied, ``h·youth·r / step²`` samples (class docstring). With the noise
            variance r, which scales as m², the windows do not depend on the mass.
        change_max_window_s: Cap on the change test's longest window, s: long enough for
            a 30 mN step at 2 m/s^2 of vibration, 100 Hz, to reach the threshold (~4 s at
            the information limit, class docstring).
        drift_time_constant_s: Time constant of the innovation-bias average that drives
            the drift adaptation, s.
        drift_threshold: Level of the normalised innovation-bias statistic (chi-square,
            3 dof, under no drift) above which the process noise is raised.
        drift_min_time_constant_s: Shortest time constant the drift adaptation may
            reach, s.
        drift_exponent: Exponent of the drift adaptation, dimensionless.
        drift_memory_s: Decay of the drift adaptation once the drift is gone, s.
        hover_velocity_std_mps: σ_v, the hovering drone's velocity scatter per world
            axis, m/s: the thrust balance enters the filter through the velocity
            (:class:`~groundstation.tension_kalman.HoverVelocity`) while the caller says
            the drone hovers (``update(hover_model_world_n=...)``).
        hover_velocity_time_s: T_c, that velocity's correlation time, s: ``v = 0`` is
            observed with variance ``σ_v²·T_c/dt`` per sample.
        hover_balance_density_n2s: D, the thrust balance's white noise at hover as a
            force density, N²·s: the velocity state's process noise is ``D/m²`` per
            second (``groundstation calibrate`` fits it with ``hover_wander_n2_per_s``,
            groundstation.hover_fit.fit_hover_balance). None: ``thrust_noise_n²·dt_mean``,
            the prior's per-sample noise at the measured spacing.
    """

    mass_kg: float = 0.030
    accel_noise_mps2: float = 0.3
    thrust_noise_n: float = 0.003
    estimate_noise: bool = True
    noise_time_constant_s: float = 5.0
    noise_prior_samples: float = 2.0
    hover_time_constant_s: float = 6.0
    hover_wander_n2_per_s: float = 4.5e-8
    false_alarms_per_h: float = 0.005
    change_min_window: int = 4
    change_min_step_weight_ratio: float = 0.068
    change_max_window_s: float = 8.0
    drift_time_constant_s: float = 0.5
    drift_threshold: float = 9.0
    drift_min_time_constant_s: float = 0.1
    drift_exponent: float = 3.0
    drift_memory_s: float = 1.0
    hover_velocity_std_mps: float = 0.02
    hover_velocity_time_s: float = 0.5
    hover_balance_density_n2s: float | None = None

    def __post_init__(self) -> None:
        positive = {
            "mass_kg": self.mass_kg,
            "accel_noise_mps2": self.accel_noise_mps2,
            "noise_time_constant_s": self.noise_time_constant_s,
            "noise_prior_samples": self.noise_prior_samples,
            "hover_time_constant_s": self.hover_time_constant_s,
            "change_min_step_weight_ratio": self.change_min_step_weight_ratio,
            "change_max_window_s": self.change_max_window_s,
            "drift_time_constant_s": self.drift_time_constant_s,
            "drift_threshold": self.drift_threshold,
            "drift_min_time_constant_s": self.drift_min_time_constant_s,
            "hover_velocity_std_mps": self.hover_velocity_std_mps,
            "hover_velocity_time_s": self.hover_velocity_time_s,
        }
        for name, value in positive.items():
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(
                    f"TensionFilterParams.{name} must be finite and > 0, got {value!r}"
                )
        non_negative = {
            "thrust_noise_n": self.thrust_noise_n,
            "false_alarms_per_h": self.false_alarms_per_h,
            "hover_wander_n2_per_s": self.hover_wander_n2_per_s,
            "drift_exponent": self.drift_exponent,
            "drift_memory_s": self.drift_memory_s,
        }
        for name, value in non_negative.items():
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(
                    f"TensionFilterParams.{name} must be finite and >= 0, got {value!r}"
                )
        d = self.hover_balance_density_n2s
        if d is not None and not (math.isfinite(d) and d > 0.0):
            raise ValueError(
                f"TensionFilterParams.hover_balance_density_n2s must be finite and > 0, got {d!r}"
            )
        if self.drift_min_time_constant_s > self.hover_time_constant_s:
            raise ValueError(
                "TensionFilterParams needs drift_min_time_constant_s <= hover_time_constant_s, "
                f"got {self.drift_min_time_constant_s} and {self.hover_time_constant_s}"
            )
        if not self.change_min_window >= 1:
            raise ValueError(
                f"TensionFilterParams.change_min_window must be >= 1, got {self.change_min_window}"
            )


_DEFERRED = (LazyChangeStatistic, NoiseStatus)
"""The zero-argument callables a :class:`_Lazy` field may be given."""


class _Lazy:
    """A field of a frozen dataclass that may be given as a zero-argument callable
    (one of ``_DEFERRED``, called with the field's name), called on first read and replaced
    by its value.

    A data descriptor (the dataclass's ``__init__`` stores through ``__set__``; reading,
    ``==``, ``repr``, ``dataclasses.replace`` and ``asdict`` all go through ``__get__``), so
    every reader sees the float; only the work is deferred, for the fields that nobody on
    the per-message path reads.
    """

    def __init__(self, default: Any) -> None:
        self._default = default
        self._name = self._key = ""

    def __set_name__(self, owner: type, name: str) -> None:
        self._name = name
        self._key = "_lazy_" + name

    def __get__(self, obj: object, objtype: type | None = None) -> Any:
        if obj is None:
            return self._default  # the dataclass's default
        value = obj.__dict__[self._key]
        if isinstance(value, _DEFERRED):
            value = obj.__dict__[self._key] = value(self._name)
        return value

    def __set__(self, obj: object, value: Any) -> None:
        obj.__dict__[self._key] = value


@dataclass(frozen=True)
class TensionEstimate:
    """Filtered tension after one filter step.

    Attributes:
        tension_world_n: Force of the tether on the drone, world frame, N, shape (3,).
        cov_n2: Its covariance (the Kalman filter's P), N^2, shape (3, 3).
        std_n: Standard deviation per axis, ``sqrt(diag(P))``, N, shape (3,).
        converged: True once the noise estimate's warm-up of observations
            (:func:`~groundstation.tension_change.noise_warmup_samples`, 19) has been taken
            since start or :meth:`TensionFilter.reset`.
        change_detected: True when this step detected a change of tension (a tug) and
            re-initialised the filter from the samples since the change.
        samples: Observations taken since start or reset.
        change_statistic: Largest windowed chi-square statistic of this step's change
            test, dimensionless: a detection is a value above
            :attr:`TensionFilter.change_threshold`.
        process_noise_scale: Factor on the process noise applied this step by the drift
            adaptation (1 at hover).
        noise_std_n: Estimated observation noise std per world axis and sample, N,
            shape (3,).
        noise_autocorrelation: Estimated lag-1 autocorrelation of that noise per axis,
            shape (3,).
        time_constant_s: The filter's time constant this step, s (the hover one at
            hover; shorter after a change or during a drift).
    """

    tension_world_n: FloatArray
    cov_n2: FloatArray
    std_n: FloatArray
    converged: bool
    change_detected: bool
    samples: int
    change_statistic: float = _Lazy(0.0)  # type: ignore[assignment]
    process_noise_scale: float = 1.0
    noise_std_n: tuple[float, float, float] = _Lazy((math.nan, math.nan, math.nan))  # type: ignore[assignment]
    noise_autocorrelation: tuple[float, float, float] = _Lazy((0.0, 0.0, 0.0))  # type: ignore[assignment]
    time_constant_s: float = math.nan


@dataclass(frozen=True, slots=True)
class HoverStep:
    """The hover's part of one update step, as the trace records it for the smoother.

    While the drone hovers the filter's state per world axis is (T, v)
    (:class:`~groundstation.tension_kalman.HoverVelocity`): ``v = v_prev + d·(T_prev − h)``
    plus noise of variance ``velocity_noise_m2ps2``, and ``0 = v`` observed with variance
    ``rest_var_m2ps2``; a hover that begins at this step starts from v = 0 with variance
    ``start_var_m2ps2`` (so ``v = d·(T_prev − h)`` plus noise of variance ``start_var +
    velocity_noise``).
    """

    hover_model_n: tuple[float, float, float]
    """h, the thrust balance ``m·g·e3 − R·u·F`` of this sample, world, N."""
    gain_s_per_kg: float
    """d = dt / m, s/kg."""
    velocity_noise_m2ps2: float
    """The velocity's process noise over this step, (m/s)^2."""
    rest_var_m2ps2: float
    """The variance of the observation ``v = 0``, (m/s)^2."""
    start_var_m2ps2: float
    """σ_v², the velocity's variance when a hover begins, (m/s)^2."""
    started: bool
    """The hover began at this step."""


@dataclass(frozen=True, slots=True)
class FilterStep:
    """One step of :class:`TensionFilter`, as its trace records it for offline smoothing.

    ``kind``: ``"start"`` (the trace began on a running filter, or the filter merged its
    two hypotheses after a change into its state,
    :class:`~groundstation.tension_kalman.MovingTension`: ``x_n``, ``p_n2`` that state,
    from which the next update predicts), ``"reset"`` (the regime ends; ``x_n``, ``p_n2``
    the prior the next update starts from, or None), ``"init"`` (first sample after a
    reset without prior: x = z, P = R),
    ``"update"`` (x- = x, P- = P + Q, then the update with z and R; Q = 0 right after a
    reset with a prior) or ``"coast"`` (the prediction alone).
    """

    kind: Literal["start", "reset", "init", "update", "coast"]
    x_n: tuple[float, float, float] | None
    """The state after the step, world, N (for a reset: its prior, or None)."""
    p_n2: tuple[float, float, float] | None
    """The diagonal of P after the step, N^2 (for a reset: the prior's, or None)."""
    z_n: tuple[float, float, float] | None = None
    """The observation, world, N (init and update)."""
    q_n2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """The process noise of the prediction into this step, diagonal, N^2."""
    r_n2: tuple[float, float, float] | None = None
    """The observation noise, diagonal, N^2 (init and update)."""
    restart: int = 0
    """A change detected here: the filter restarted from the last ``restart`` updates
    (this one included), so the new regime began at the ``restart``-th last update."""
    hover: HoverStep | None = None
    """The hover's part of an update step (None: the drone did not hover)."""


class TensionFilter:
    """Constant-tension Kalman filter that learns its noise, with tug detection.

    **Where each part lives.** This class sequences one step (:meth:`update`) and holds the
    state of a regime; each part is its own small piece, readable alone:

    * the Kalman core, ``eq:sysk1``, ``eq:sysk2``, ``eq:Kalman_vars`` in closed form:
      :class:`~groundstation.tension_kalman.DiagonalKalman`;
    * the observation noise R, measured on line:
      :class:`~groundstation.tension_noise.NoiseEstimate`;
    * the process noise Q's drift adaptation:
      :class:`~groundstation.tension_drift.DriftAdaptation`;
    * the change test that restarts the filter after a tug, and its threshold:
      :class:`~groundstation.tension_change.ChangeTest`,
      :func:`~groundstation.tension_change.scan_threshold`.

    The design, its reasoning and its numbers follow.

    **Model** (``eq:sysk1``, ``eq:sysk2``, ``eq:Kalman_vars``): state x = (Tx, Ty, Tz),
    A = C = I, B = D = 0, and Q, R and P diagonal: three scalar filters, one per world
    axis, in closed form (:class:`DiagonalKalman`; equal to filterpy's ``KalmanFilter``
    stepped with the same Q and R, to 1e-12). Each step sets Q and R, predicts and updates
    (x- = x, P- = P + Q; K = P- / (P- + R); x = x- + K(y - x-); Joseph-form P). Where the
    paper's filter is told its noise, this one measures it, colour included.

    **Noise, measured on line** (:class:`~groundstation.tension_noise.NoiseEstimate`). Real
    Crazyflie hover noise is 0.7-2.0 m/s^2 per axis (20-60 mN per sample on 30 g), not the
    0.3 m/s^2 of the default, and propeller vibration colours it (lag-1 autocorrelation up
    to 0.3). What any average suffers is the *long-run* variance r (``Var(mean of n) -> r /
    n``), 1.86 times the per-sample variance for AR(1) noise with rho = 0.3 and 2.0 times
    for the realistic simulator's white + AR(0.6) mix (lag-1 0.2), so R = diag(r) with r
    measured per world axis: its level from lag-1 differences over ``noise_time_constant_s``
    = 5 s (500 samples at 100 Hz: +-6 %), its shape (r over the level) from second
    differences of 0.25 s block means over 30 s. Both are blind to the tension itself: a 10
    mN/s ramp moves y by 0.1 mN per sample at 100 Hz against 20-60 mN of noise, and second
    differences cancel it altogether. The configured noise is only the prior of the first
    samples; as R is revised, P is rescaled with it (P is proportional to R when Q is and P0
    = R), so the first samples are not held as precise as a wrong prior says. Fed R = the
    per-sample variance instead, the filter would report a P 1.86-2.0 times too small and
    its change test would read its threshold of ~50 as 25-27 on long windows.

    **The hover's thrust balance** (``update(hover_model_world_n=...)``). While the caller
    says the drone hovers, the drone's velocity joins the state on each axis,
    ``m dv/dt = T - h`` with h the thrust balance ``m g e3 - R u F``, and ``v = 0`` is
    observed with variance ``hover_velocity_std_mps^2 hover_velocity_time_s / dt``
    (:class:`~groundstation.tension_kalman.HoverVelocity`): the accelerometer model (the
    observation) and the thrust balance are weighed by what each can be off. A restart, a
    reset, a gap or a coast stops it; the next hovering sample starts it at v = 0.

    **Process noise in seconds, memory from the noise.** A constant-tension filter in
    steady state is an exponential average with time constant tau = sqrt(r dt / q) (dt
    the sample spacing, q the process noise per second), so Q = q dt with
    ``q = r dt_mean / tau^2`` per axis holds a chosen tau at any rate (dt_mean an average
    of the measured spacing); an irregular or missing sample widens P in proportion to the
    time elapsed. Hover error per axis is then ``sqrt(r dt_mean / (2 tau))``. The tau
    itself follows the noise (:meth:`hover_time_constant`): the tension at hover wanders
    (tether swing, the drone's own hover motion) as a random walk of spectral density
    ``hover_wander_n2_per_s`` = q_w = 4.5e-8 N^2/s (0.67 mN over 10 s), and for a random
    walk in noise of long-run variance r the steady-state Kalman filter has exactly
    ``tau = sqrt(r dt / q_w)``: the noisier the observation, the longer the memory that
    pays. At least ``hover_time_constant_s`` = 6 s: 6 s on the ideal profile (0.3 m/s^2,
    250 Hz: sqrt(r dt / q_w) = 2.7 s; 0.16 mN per axis; its results are those of a fixed
    6 s), 9.6 s at 0.5 m/s^2, 19 s at 1 m/s^2 and 39 s at 2 m/s^2 (100 Hz, lag-1 0.3). No
    cap above it: the wander model sets the memory. (A cap of 40 s moved no figure at 20 or
    80 s, docs/sensitivity.md, and none but the 2 m/s^2 tug's t90 when removed:
    docs/estimator_design.md, *The drift adaptation where the model holds*.) Where that
    came from: a fixed 6 s held the hover
    target (within 1.2x the oracle below) on one seed only; over four seeds x six spots
    x 20 s (realistic simulator, calibration = truth, seeds 100-400) the oracle's best
    time constant of 6-40 s was 10-20 s at 1 m/s^2 and 10-40 s at 2 m/s^2, and a fixed
    6 s filter reached 1.38x (1 m/s^2) and 2.0x (2 m/s^2, p95, near plumb, where the
    plumb blend of the localization reads the filter's P) of it; with tau from q_w every
    seed was within 1.07x (docs/realistic_benchmark.md has the same on other seeds).
    Ramps and tugs are the drift adaptation's and the change test's, whose statistics do
    not depend on tau (a 10 mN/s ramp on the ideal profile: 2.3 mN RMS,
    docs/filter_benchmark.md). The price: a step the test has not (yet) found is taken
    in at the hover gain, so more slowly (a fixed 6 s against this on the realistic
    simulator's tug: docs/realistic_benchmark.md, its reading).
    ``hover_wander_n2_per_s`` = 0 gives a fixed tau (the benchmarks' oracles,
    ``bench_realistic --fixed-tau``).

    **Tug detection (GLR on whitened innovations).** Each innovation nu is whitened by
    the Cholesky factor of S = P- + R, so that at constant tension w ~ N(0, I). A step
    Delta k samples ago shifts the mean of the last k whitened innovations. For every
    window n in [``change_min_window``, n_max] (below) the
    statistic ``|sum of the last n w|^2 / n`` is chi-square with 3 dof under no change
    when the noise is white, and *smaller* for positively correlated noise on short
    windows, since R is the long-run variance: a window of n samples counts as its
    effective sample size, never more, so the test errs toward silence on vibration.
    While the noise estimate is young the statistic is divided by an upper bound on its
    error (``1 + 3 sqrt(2 / k)`` after k samples, fading out as k reaches the level's
    equilibrium count, 2τ/dt − 1), and never by less than
    the warm estimate's own scatter allows for
    (:func:`~groundstation.tension_change.level_scatter_factor`, 1.26 at ~95 Hz: without
    it thresholds set for a known noise fired 4 times in 90 h of simulated hover); and
    the test waits for the noise estimate's warm-up
    (:func:`~groundstation.tension_change.noise_warmup_samples`, 19 samples: before it the
    estimate is not bounded away from zero at ``ESTIMATE_SIGMAS`` standard errors). The
    largest statistic is compared with the threshold h that
    :func:`~groundstation.tension_change.scan_threshold` gives for
    ``false_alarms_per_h`` (0.005/h) over the windows [``change_min_window``,
    ``change_max_window_s`` = 8 s] at the measured spacing (the Brownian scan
    approximation of the crossing rate of a sliding chi-square scan: 49.7 at 100 Hz,
    51.7 at 250 Hz; infinite before a spacing is known; the history grows to hold the
    longest window at the spacing, :meth:`ChangeTest.reserve`). The rate per sample goes
    as ``1/n_lo - 1/n_hi``: long windows add few independent looks, so 8 s costs a
    threshold 0.1 above a 1 s test's. The false detections are counted in
    docs/change_test_benchmark.md.

    *The longest window, from the noise.* With the level before it known exactly, a GLR
    at threshold h detects a step delta about half the time once ``n delta^2 / r = h``
    (the information limit): a 30 mN step at 0.3 m/s^2 and 250 Hz (non-centrality ~10 per
    sample) within a few samples, at 1 and 2 m/s^2, 100 Hz, r = 2 s2 (0.5 and 0.125 per
    sample) after ~100 and ~400 samples, 1 s and 4 s: any detector that fires on noise as
    rarely needs that much data. So the longest window is where the smallest step of
    interest, ``change_min_step_weight_ratio`` of the weight (20 mN at 30 g), reaches the
    threshold as applied: ``n_max = h youth r_max / step^2`` samples (r_max the largest
    axis's long-run variance), at most ``change_max_window_s`` = 8 s (the history holds it), set at
    each full evaluation: 12 samples (50 ms) on the ideal profile, 2.6 s at 1 m/s^2 and
    100 Hz (r = 2 s2), 8 s at 2 m/s^2 (10.5 s uncapped; a 30 mN step needs ~4 s). Longer
    windows would find no step of interest sooner, and on a ramp (a drone moving) they
    fire where the drift adaptation is already following and restart from a window mean
    that lags the ramp by half the window (the 10 mN/s ramp on the ideal profile of
    tests/test_tension.py: no restart and 2.1 mN RMS; with windows up to 8 s whatever
    the noise, 13 restarts and 2.7 mN). Meanwhile the hover filter (tau 19-40 s there)
    takes in a few per cent of the step, which the innovations then no longer show; the
    drift adaptation (below) takes in more when the step is large. Where the thrust
    balance is fused (a hovering drone) it sees the step sooner than the accelerometer
    does (docs/realistic_benchmark.md: the tug's t90 and its first detection).

    **Re-initialisation by replay.** On detection the window with the largest statistic
    is the maximum-likelihood change point. The filter restarts from the observations
    since then: x = their mean, P = R / n, which is what the Kalman filter itself would
    give from an uninformative prior with Q = 0 over those samples. So after a tug the
    estimate is the mean of every post-tug sample and the detection delay costs nothing;
    the gain then decays by itself to the hover gain as P shrinks.

    **After a change: is the tension still moving?** The restart is the best estimate if
    the tension stays where it jumped; a tug often does not (the reel runs for a tenth of a
    second, the drone answers the pull, the tether swings: in the estimator issue's reel tug
    the truth relaxes by ~20 mN over half a second after the jump, and a mean since the
    change lags it by 7 mN for that long). So a second hypothesis runs beside the restarted
    filter (:class:`~groundstation.tension_kalman.MovingTension`): a random walk whose time
    constant starts at the detection window's span (the data said the tension moved on that
    scale) and relaxes to the hover's as the drift adaptation's raised noise does
    (``drift_memory_s``, never below ``drift_min_time_constant_s``). Both are filtered
    from the same restart; each scores its one-step predictive likelihood, and the
    estimate (and its P) is their posterior mixture from even odds (a change found while
    the moving hypothesis was winning keeps its odds): a step that stays is
    won by the constant model (its weight below 0.2 within a second, the 30 mN step still
    settles as before, tests/test_tension.py), a tension that keeps moving by the other
    within a few tenths of a second (tests/test_moving_tension.py: the error 0.1-1 s after
    the change about half the mean-since-the-change's). No new constant: the window is
    the detection's, the relaxation the drift adaptation's. A new hover (the tension is
    constant from there), a gap or a coast ends it; once relaxed to the hover's time
    constant (or its weight below 1e-9) the filter takes the mixture as its state, and the
    trace marks it for the smoother (a ``start`` step).

    **The 30 mN tug target and the rate.** "Within 10 % (3 mN) in 0.3 s" is an
    information limit before it is a filter property: 0.3 s holds 0.3 / dt samples, and
    even the mean of exactly the post-step samples (the change time known) has
    ``sqrt(r dt / 0.3)`` per axis. At 250 Hz and 0.3 m/s^2 that is 1.04 mN, and that
    oracle stays within 3 mN (error norm) from median 0.12 s / p95 0.32 s; at 100 Hz (the
    Crazyflie's IMU rate) it is 1.64 mN and the oracle needs median 0.29 s / p90 0.65 s /
    p95 0.80 s (400 trials, ``python -m benchmarks.step_oracle``); this filter's replay *is*
    that mean, and docs/filter_benchmark.md measures it at 250 Hz (norm median 0.12 s,
    p95 0.28 s). An independent check's 0.68-0.73 s for "within 10 %" matches the 100 Hz
    tail of the oracle (p90-p95), i.e. the Crazyflie's rate, not a filter lag.

    **Slow drifts.** A tension that ramps (the drone moving) makes the slow filter lag by
    rate * tau. An exponential average b of the whitened innovations over
    ``drift_time_constant_s`` = 0.5 s measures that lag; its normalised square
    D = |b|^2 / Var(b) is chi-square with 3 dof at constant tension (divided by the same
    youth factor as the change test). Above
    ``drift_threshold`` = 9 the process noise is scaled by (D / 9)^3, down to a time
    constant of ``drift_min_time_constant_s`` = 0.1 s, which shortens tau until the lag
    falls back to the threshold; the scale then decays with ``drift_memory_s`` = 1 s.
    The bias is evidence of a moving tension only where the observation model holds: while
    the caller's hover test says the drone manoeuvres (``update(manoeuvring=True)``, the
    pipeline's slow stage) the bias is as much the model's error (drag, the thrust's and
    the attitude's dynamics) and the hover's Q applies. On real untethered flights (zero
    tension, NanoBench: trajectories, quasi-static 1-5 % of the time) the raised noise
    published that error: median of flight medians 6.7 mN with the adaptation throughout,
    4.8 mN with it held to hovers and the filter alone (docs/estimator_design.md, *The
    drift adaptation where the model holds*); the realistic simulator's hover and tugs,
    which happen in a hover, are unchanged.

    **Gaps and rates.** A step longer than :data:`GAP_S` = 0.25 s breaks the noise model's
    sample chain and clears the change test's windows (a window across a gap mixes two
    regimes); the state is kept, P grows by Q times the gap, and a tension that changed
    meanwhile is found by the change test on the samples after the gap (the pipeline
    restarts the filter altogether after a second of silence). Everything else is in
    seconds, so 50-500 Hz and 6-27 ms jitter need no tuning.

    **DC offsets: calibration and the rest offset, not a bias state.** At hover every
    constant sensor error is a constant tension error, and none of them can be averaged
    away: a 3 deg accelerometer misalignment (per boot on a Crazyflie: the firmware
    re-levels at power-on) reads 0.51 m/s^2, 15 mN on 30 g, where the real horizontal
    tension at the paper's spots is 8-27 mN; a 2 deg thrust axis offset is 11 mN on
    0.33 N; a 10 % thrust-map error is 33 mN of vertical tension, 0.66 m of s2 at
    omega = 0.05 N/m. A bias state (x = (T, b)) is unobservable from this one observation
    while the drone holds still: T and b enter it as the sum T + b, so the filter would
    only split a constant arbitrarily. What does separate them is a second route to the
    tension. At hover p'' averages to zero, so with the attitude R there are two:
    ``m (R f + g)`` (the accelerometer, no thrust) and ``-R F t - m g`` (attitude x
    thrust, no accelerometer). Their difference at DC is the accelerometer's offset minus
    the thrust's errors: one equation for two sets of unknowns. Where the attitude is
    independent of the accelerometer (the motion-capture body of the real tethered flights; the
    realistic simulator's reported attitude, which is the true one) the difference is
    informative, but weighing the two routes only moves the per-boot accelerometer error
    into the thrust's: solving for the accelerometer offset needs the thrust scale and
    axis known to the accuracy wanted (2 % of scale is 6.6 mN of T_z, 1 deg of axis 5.8 mN
    sideways), i.e. calibrated; and with the onboard attitude (levelled on that same
    accelerometer) the difference does not see the misalignment at all. So each error is
    taken where it can be measured without the others: the airframe's thrust scale, its
    battery slope and thrust axis, and an accelerometer bias from ``[calibration]``
    (:class:`ObservationCalibration`, fitted once by ``groundstation calibrate`` where
    motion capture gives the tension); the per-boot accelerometer x/y offset by the rest
    calibration at every boot (``[calibration] rest``,
    :class:`groundstation.calibration.RestCalibrator`: the disarmed, still drone on the
    floor feels exactly ``R^T (0, 0, g)``, no thrust involved, so the misalignment's
    offset is read before every take-off; it assumes the floor is as level as the
    attitude says, 0.17 m/s^2 per degree otherwise); and this filter handles what can be
    learned on line: the noise, its colour, the rate, the memory.

    *Detection against false alarms.* What a higher rate would buy, by
    :func:`~groundstation.tension_change.scan_threshold` over the change test's windows
    at 100 Hz: h = 49.6 at 0.005 false alarms per hour, 44.5 at 0.05, 38.5 at 0.7, 33.9
    at 5; a detection needs that much evidence, so the delay at the information limit
    scales with h (0.7 per hour: 22 % sooner). 0.005 per hour (``false_alarms_per_h``)
    because a false detection is not harmless: with following on it moves the drone,
    with ``land_below_m`` it can stop the motors. 0.005 per hour is one per 200 h of
    hover per drone (1700 seven-minute battery packs), and with eight drones one per 25 h
    of flying; 0.7 per hour would be one every 11 minutes of an eight-drone hover.

    **Initialisation.** The first observation initialises the state (x = y, P = R),
    unlike the paper, whose filter started from T = 0: with H = 0 and s2 = 0 the
    localization then returned the plumb-line limit z = z_i - L = 0.754 - 1.6 =
    -0.846 m (``eq:in_instants``) until the filter converged.

    **Cost.** One step runs per telemetry message (2000/s for 8 drones), on 3-vectors
    and 3x3 matrices, where numpy's per-call overhead outweighs the arithmetic. So the
    Kalman step is three scalar filters in Python floats (:class:`DiagonalKalman`; it was
    filterpy's ``KalmanFilter``, ~20 µs a step), as are the noise estimate, the whitening
    and the innovation bias. The change test keeps the running sum of the whitened
    innovations (any window's sum one difference) and a certificate that no window can
    cross its threshold (:class:`~groundstation.tension_change.ChangeTest`), so at hover it
    evaluates its windows about one step in ten. What nobody on the per-message path
    reads is computed when read (the estimate's ``change_statistic``, ``noise_std_n`` and
    ``noise_autocorrelation``), and the estimate's three arrays share one read-only
    buffer. Outputs are those of the plain computation to rounding
    (tests/test_tension_equivalence.py recomputes them from scratch).
    """

    def __init__(self, params: TensionFilterParams | None = None) -> None:
        self.params = params if params is not None else TensionFilterParams()
        self._kf = DiagonalKalman()  # A = C = I, Q and R diagonal (eq:Kalman_vars)
        self._hover_v = HoverVelocity()  # v beside T while the drone hovers
        p = self.params
        # The history's capacity follows the spacing (ChangeTest.reserve): a few windows'
        # room until the first spacing is measured, whose threshold is infinite till then.
        self._change = ChangeTest(
            p.change_min_window,
            p.change_max_window_s,
            1 << p.change_min_window.bit_length(),
            self.fast_threshold(None),
        )
        # Spacings within 1 % of the one the change test's threshold was derived at.
        self._fast_band = (math.nan, math.nan)
        min_step_n = p.change_min_step_weight_ratio * p.mass_kg * GRAVITY_MPS2
        self._inv_min_step_n2 = 1.0 / (min_step_n * min_step_n)
        self._drift = DriftAdaptation(
            p.drift_time_constant_s,
            p.drift_threshold,
            p.drift_exponent,
            p.drift_min_time_constant_s,
            p.drift_memory_s,
        )
        prior = observation_cov_n2(None, p.mass_kg, p.accel_noise_mps2, p.thrust_noise_n)
        self._prior_var = (float(prior[0, 0]), float(prior[1, 1]), float(prior[2, 2]))
        v0, v1, v2 = self._prior_var
        self._prior_std = (math.sqrt(v0), math.sqrt(v1), math.sqrt(v2))
        self._noise = NoiseEstimate(self._prior_var, p.noise_prior_samples, p.false_alarms_per_h)
        self._warmup = noise_warmup_samples()  # the noise estimate's warm-up, derived
        self._dt_mean = math.nan
        # The mean spacing over the noise level's memory: the spacings' and the samples'
        # sums, each weighed by exp(-age / noise_time_constant_s).
        self._spacing_sum_s = 0.0
        self._spacing_count = 0.0
        self.noise_density_n2s: float | None = None
        """The observation's noise as a density, N²·s: the long-run variance r (the mean of
        the three axes') times the mean sample spacing, as of the last observation (or
        floor sample, :meth:`learn_noise`); None before a spacing is known. The slow stage
        takes it over m² as the accelerometer's, for its hover test's thresholds and its
        velocity filter (``groundstation.bias_kalman``): the same vibration, measured once.
        Kept as a value, not computed when read: the slow stage reads it every message."""
        # (dt_mean, the test's youth floor at it, the youth factor's fade-out count at it)
        self._allowances = (math.nan, 1.0, math.inf)
        self.sample_chi2 = math.inf
        """The threshold a 3-degree-of-freedom chi-square statistic judged at every sample
        exceeds by chance at ``false_alarms_per_h`` at the measured spacing, dimensionless
        (:func:`~groundstation.tension_change.exceedance_chi2`: 39.5 at 100 Hz; derived
        again with the change test's threshold once the spacing has moved by
        ``RESCALE_TOLERANCE``; infinite before a spacing is known): the slow stage's hover
        test takes it, one false-alarm rate for every test of the estimator."""
        self.sample_sigmas = math.inf
        """The one-sided counterpart of :attr:`sample_chi2`: the standard deviations a
        per-sample Gaussian test exceeds by chance at ``false_alarms_per_h`` at the measured
        spacing (:func:`~groundstation.tension_change.exceedance_sigmas`: 5.55 at 100 Hz),
        derived with it; the contact stage's climb and height tests (:meth:`sigmas_at`)."""
        self.trace: list[FilterStep] | None = None
        """Every step from :meth:`start_trace` on (None: not recorded, the default)."""
        self._restart_pending = 0
        """A :meth:`new_hover` restart the next update's trace step records (its updates)."""
        self._moving: MovingTension | None = None
        """After a detected change, the hypothesis that the tension still moves."""
        self._merged: tuple[list[float], list[float]] | None = None
        """The state the filter took from the two hypotheses, for the next trace step."""
        self.reset()

    # -- state -------------------------------------------------------------------------

    def reset(
        self,
        prior_world_n: tuple[float, float, float] | None = None,
        prior_std_n: tuple[float, float, float] | None = None,
    ) -> None:
        """Forgets the tension: the next observation initialises the filter again.

        The noise estimate (a property of the drone, not of the regime) is kept.

        Args:
            prior_world_n: Optional prior tension, world frame, N. Without it the first
                observation alone initialises the state (x = y, P = R); with it the first
                observation updates ``N(prior, diag(prior_std_n^2))`` like any other, so a
                restart is not one raw sample when the tension is known to be near the
                prior, e.g. at lift-off, when the tether rests on the floor and pulls on
                the drone with next to nothing. A wrong prior shows in the innovations and
                the change test restarts from the samples alone.
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
            self._prior = (x0.tolist(), (std * std).tolist())  # x0, diag(P0)
        self._initialized = False
        self._samples = 0
        self._r_prev: tuple[float, ...] | None = None
        self._merged = None
        if self.trace is not None:
            prior = self._prior if self._prior is not None else (None, None)
            self.trace.append(FilterStep("reset", _tuple3(prior[0]), _tuple3(prior[1])))
        self._new_regime()
        self._last: TensionEstimate | None = None

    def new_hover(self, window_s: float) -> None:
        """A hover began after a manoeuvre: the tension is constant from here on, and what
        the filter averaged before belongs to another one.

        The new regime starts from the mean of the observations over the hover test's own
        window (``window_s``: the span the test found quasi-static, so of this tension),
        P = R / n, as a detected change restarts the filter; the next samples average on
        from there. Fewer than ``change_min_window`` observations in it: P is raised to one
        sample's R (the estimate so far counts as one sample). Either way the change and
        drift windows start again.

        Args:
            window_s: The hover test's window, s (``slow_accel.HOVER_MEAN_S``).
        """
        r = self._r_prev
        if not self._initialized or r is None:
            return
        self._moving = None  # the tension is constant from here on
        n = self._change.ring.count
        dt_mean = self._dt_mean
        if dt_mean == dt_mean and dt_mean > 0.0:
            n = min(n, int(window_s / dt_mean))
        if n >= self.params.change_min_window:
            self._restart(self._change.mean_of_window(n), n, r)
            self._restart_pending = n + 1  # the trace: the regime began n updates ago
            return
        P = self._kf.P
        self._kf.P = [max(P[0], r[0]), max(P[1], r[1]), max(P[2], r[2])]
        self._clear_windows()

    @property
    def dt_mean_s(self) -> float:
        """The mean sample spacing, s (NaN before two samples)."""
        return self._dt_mean

    def _new_regime(self) -> None:
        """Clears what belongs to one stretch of samples (not the noise statistics)."""
        self._noise.break_chain()
        self._clear_windows()

    def _clear_windows(self) -> None:
        """Starts the drift, change and step windows again (what they averaged belongs
        to another tension)."""
        self._drift.new_regime()
        self._change.clear()
        self._hover_v.active = False
        self._moving = None

    def learn_noise(self, tension_obs_world_n: ArrayLike, dt_s: float) -> None:
        """Learns the observation noise from a sample whose mean is no tension.

        On the floor with the propellers spinning (thrust at or above ``[filter]
        ground_thrust_ratio``) the observation's mean is the floor's push, not tension, but
        its noise is the flight's vibration. The noise estimate measures it from successive
        differences and second differences of block means, blind to a slowly moving mean
        (a thrust ramp), so it can learn there. Without this the first flight's filter
        restarts at lift-off from the floor prior (5 mN) weighing its first samples with
        the prior noise (0.3 m/s^2: 9 mN per sample) where the realistic profile has
        2 m/s^2 (60 mN): the first dozen samples moved the estimate by 35-50 mN of
        horizontal noise (the tether, resting on the floor, pulled with 4 mN).

        Consecutive calls continue one chain of differences, and the first :meth:`update`
        after them continues it too (lift-off is no jump in the noise); :meth:`reset`
        breaks it, as does a call with ``dt_s`` 0 or longer than :data:`GAP_S`. The state is
        not touched. Does nothing with ``estimate_noise=False``.

        Args:
            tension_obs_world_n: Raw observation, world frame, N, shape (3,).
            dt_s: Time since the previous sample, s, >= 0.

        Raises:
            InvalidObservationError: If the observation is not a finite 3-vector.
            InvalidTimeStepError: If ``dt_s`` is negative or not finite.
        """
        p = self.params
        y = _finite3(tension_obs_world_n, "tension_obs_world_n")
        dt = _check_dt(dt_s)
        if not p.estimate_noise:
            return
        if not 0.0 < dt <= GAP_S:
            self._noise.break_chain()
        tau = p.noise_time_constant_s
        r0, r1, r2 = self._noise.push(y, dt, math.exp(-dt / tau), tau, self._warmup)
        spacing = self._dt_mean
        if spacing == spacing:  # the spacing of the flight (the floor's is not tracked)
            self.noise_density_n2s = (r0 + r1 + r2) / 3.0 * spacing

    def start_trace(self) -> list[FilterStep]:
        """Records every step from now on in :attr:`trace` (for :mod:`groundstation.smoother`).

        Returns:
            The trace: a ``"start"`` step with the current state if the filter is running.
        """
        self.trace = []
        if self._initialized:
            self.trace.append(FilterStep("start", _tuple3(self._kf.x), _tuple3(self._kf.P)))
        return self.trace

    @property
    def initialized(self) -> bool:
        """Whether an observation has initialised the state since start or reset."""
        return self._initialized

    @property
    def estimate(self) -> TensionEstimate | None:
        """The latest estimate, or None before the first observation."""
        return self._last

    def noise_model(self) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]:
        """The observation noise in force: ``(s2, rho, r)`` per world axis.

        Returns:
            The per-sample variance s2 (N^2), the lag-1 autocorrelation rho, and the
            long-run variance r (N^2), which the filter takes as its R.
        """
        if not self.params.estimate_noise:
            return self._prior_var, (0.0, 0.0, 0.0), self._prior_var
        return self._noise.model()

    def vertical_noise_var_n2(self) -> float | None:
        """The observation's vertical noise as a test of it must allow for, N^2, or None
        before the noise estimate has taken a difference.

        The long-run variance r of the world z axis (what any average of the observation
        suffers) times the change test's allowance for the estimate's own error: the youth
        factor while it is young, at least the warm estimate's scatter
        (:func:`~groundstation.tension_change.level_scatter_factor`) once the spacing is
        known. The contact stage's climb test reads it on the floor, where
        :meth:`learn_noise` measures the spinning propellers' vibration: one measure of
        the vibration, not one per stage. With ``estimate_noise=False`` the prior, as is.
        """
        p = self.params
        if not p.estimate_noise:
            return self._prior_var[2]
        noise = self._noise
        k = noise.samples
        if k < 1:
            return None
        floor, fade = self._noise_allowances()
        factor = youth_factor(k, fade)
        if floor > factor:
            factor = floor
        return noise.long_run()[2] * factor

    def sigmas_at(self, dt_s: float) -> float:
        """The standard deviations a per-sample test must ask so that it fires by chance at
        most ``false_alarms_per_h``, dimensionless: the contact stage's climb test
        (:func:`~groundstation.tension_change.exceedance_sigmas`, one false-alarm rate for
        every test of the estimator; 5.55 at 100 Hz). At the flight's mean spacing
        (:attr:`sample_sigmas`, derived with the change test's threshold), or at the
        sample's ``dt_s`` before any flight measured one (:meth:`learn_noise` does not
        track the floor's spacing); infinite with neither.
        """
        if self._dt_mean > 0.0:  # False for NaN: no flight yet
            return self.sample_sigmas
        return exceedance_sigmas(self.params.false_alarms_per_h, dt_s)

    # -- steps -------------------------------------------------------------------------

    def update(
        self,
        tension_obs_world_n: ArrayLike,
        dt_s: float,
        quat_wxyz: ArrayLike | None = None,
        thrust_axis_world: tuple[float, float, float] | None = None,
        hover_model_world_n: Sequence[float] | None = None,
        manoeuvring: bool = False,
    ) -> TensionEstimate:
        """One filter step with an observation (``eq:sysk1``, ``eq:sysk2``).

        The stages, in order: the sample spacing and the noise estimate
        (:class:`~groundstation.tension_noise.NoiseEstimate`) give R; the time constant
        (hover, shortened by :class:`~groundstation.tension_drift.DriftAdaptation`) gives
        Q; the Kalman step (:class:`~groundstation.tension_kalman.DiagonalKalman`) gives x,
        P and the whitened innovation; the change tests
        (:mod:`groundstation.tension_change`) may restart x and P from the samples since
        a tug.

        Args:
            tension_obs_world_n: Raw tension observation, world frame, N, shape (3,)
                (``TensionObservation.tension_world_n``).
            dt_s: Time since the previous observation, s, >= 0 (ignored for the first
                observation after start or reset).
            quat_wxyz: Unused; kept for callers of the earlier signature (the noise is
                now measured per world axis, not derived from the thrust axis).
            thrust_axis_world: Unused, as ``quat_wxyz``.
            hover_model_world_n: The thrust balance ``m·g·e3 − R·u·F`` of this sample,
                world frame, N, while the drone hovers (None: it does not): the velocity
                joins the state (:class:`~groundstation.tension_kalman.HoverVelocity`) and
                ``v = 0`` is observed beside the tension.
            manoeuvring: The caller's hover test ran and says the drone is not hovering
                (the slow stage's quasi-static test): the drift adaptation takes no
                evidence from the innovations this step and the hover's process noise
                applies. False where no test runs (the filter alone): the adaptation as
                always.

        Returns:
            The estimate after this step.

        Raises:
            InvalidObservationError: If the observation is not a finite 3-vector.
            InvalidTimeStepError: If ``dt_s`` is negative or not finite.
        """
        p = self.params
        z = _finite3(tension_obs_world_n, "tension_obs_world_n")
        dt = _check_dt(dt_s)
        kf = self._kf
        first = not self._initialized
        if first:
            dt = 0.0
        gap = dt > GAP_S
        keep = 1.0  # exp(-dt / noise_time_constant_s): the noise level's decay too
        if not first and not gap and dt > 0.0:
            # Mean sample spacing, s (a gap is not a sample spacing): the time the last
            # noise_time_constant_s of samples took over their number, each sample weighed
            # by exp(-age / noise_time_constant_s). Over the memory of the noise level r,
            # since Q and the change test take r dt_mean, the noise's density: one
            # measurement over one memory. A late sample is one of some 500 (100 Hz): no cap.
            keep = math.exp(-dt / p.noise_time_constant_s)
            self._spacing_sum_s = total_s = self._spacing_sum_s * keep + dt
            self._spacing_count = count = self._spacing_count * keep + 1.0
            self._dt_mean = total_s / count
        if gap:
            self._new_regime()  # the state stays; P grows by Q dt below
        noise = self._noise
        estimate_noise = p.estimate_noise
        if estimate_noise:
            r = noise.push(z, dt, keep, p.noise_time_constant_s, self._warmup)
        else:
            r = self._prior_var
        # R = the long-run variance r, not the per-sample s2: what the filter averages.
        r0, r1, r2 = r
        spacing = self._dt_mean
        if spacing == spacing:  # known (NaN before the first spacing)
            self.noise_density_n2s = (r0 + r1 + r2) / 3.0 * spacing

        if first:
            self._initialized = True
            if self._prior is None:
                # First sample: x = y, P = R (see the class docstring).
                kf.set(z, [r0, r1, r2])
                self._samples = 1
                self._r_prev = r
                if self.trace is not None:
                    self._record("init", z, (0.0, 0.0, 0.0), r, 0)
                return self._publish(False, 0.0, 1.0, math.nan)
            # First sample after a reset with a prior: x- = prior, P- = its covariance,
            # then the usual update (no prediction step: no time has passed).
            x0, P0 = self._prior
            kf.set(x0, P0)
            self._prior = None
            self._samples = 0

        r_prev = self._r_prev
        if estimate_noise and r_prev is not None:
            # P follows the noise estimate: with P0 = R and Q proportional to R, P is
            # proportional to R, so a revised R rescales it (P = D P D, D = sqrt(r / r_prev));
            # otherwise the first samples, weighed with the prior noise, would be held as
            # precise as that prior says. Applied once R has moved by 1 % (cost).
            d0, d1, d2 = r0 / r_prev[0], r1 / r_prev[1], r2 / r_prev[2]
            tol = RESCALE_TOLERANCE
            if abs(d0 - 1.0) > tol or abs(d1 - 1.0) > tol or abs(d2 - 1.0) > tol:
                kf.rescale([d0, d1, d2])
                if self._hover_v.active:
                    self._hover_v.rescale([d0, d1, d2])
                if self._moving is not None:
                    self._moving.kf.rescale([d0, d1, d2])
                self._r_prev = r
        else:
            self._r_prev = r
        # The youth factor of the drift statistic, >= 1; the change test's never falls
        # below the noise estimate's own scatter once warm (level_scatter_factor).
        k = noise.samples
        youth = test_youth = 1.0
        if estimate_noise:
            floor, fade = self._noise_allowances()
            if k < fade:
                youth = test_youth = youth_factor(k, fade)
            if floor > youth:
                test_youth = floor
        # The change test's threshold follows the spacing (log of its longest window):
        # derived again once the spacing has moved by 1 %.
        lo, hi = self._fast_band
        spacing = self._dt_mean
        if not lo < spacing < hi and spacing > 0.0:  # False for a NaN spacing
            tol = RESCALE_TOLERANCE
            self._fast_band = ((1.0 - tol) * spacing, (1.0 + tol) * spacing)
            # Room for the longest window at any spacing in the band (window_cap's).
            self._change.reserve(int(p.change_max_window_s / self._fast_band[0]) + 1)
            self._change.set_threshold(self.fast_threshold(spacing))
            self.sample_chi2 = exceedance_chi2(p.false_alarms_per_h, spacing)
            self.sample_sigmas = exceedance_sigmas(p.false_alarms_per_h, spacing)
        # This step's time constant: the hover one, shortened by the drift adaptation.
        dt_mean = self._dt_mean
        tau_hover = self.hover_time_constant(r, dt_mean)
        scale = self._drift.process_noise_scale(dt, tau_hover, youth, not manoeuvring)
        tau = tau_hover / math.sqrt(scale)
        if dt_mean != dt_mean:
            dt_mean = dt
        # Q = q dt I per axis, q = r dt_mean / tau^2 (tau: hover, restart or drift).
        c = dt_mean / (tau * tau) * dt
        q = (r0 * c, r1 * c, r2 * c)
        x_prev = kf.x
        kf.predict(q)  # x- = x,  P- = P + Q
        a_pred = kf.P
        # K = P- / (P- + R), x = x- + K (y - x-), Joseph P; w = (y - x-) / sqrt(S)
        w = kf.update(z, r)
        hv = self._hover_v
        hover_step: HoverStep | None = None
        if hover_model_world_n is None or dt <= 0.0:
            hv.active = False
        else:
            # The velocity beside the tension (HoverVelocity): m dv/dt = T - h, and v = 0
            # observed with variance sigma_v^2 T_c / dt.
            vv = p.hover_velocity_std_mps * p.hover_velocity_std_mps
            started = not hv.active
            if started:
                hv.start(vv)
            # q_v: the thrust balance's noise as an acceleration density (fitted, or the
            # prior's per-sample noise at the measured spacing).
            balance = p.hover_balance_density_n2s
            if balance is None:
                a_noise = p.thrust_noise_n / p.mass_kg
                accel_density = a_noise * a_noise * dt_mean
            else:
                accel_density = balance / (p.mass_kg * p.mass_kg)
            rest_var = vv * p.hover_velocity_time_s / dt
            hv.step(
                kf, x_prev, a_pred, q, hover_model_world_n, r, w, dt, p.mass_kg,
                accel_density, rest_var,
            )  # fmt: skip
            if self.trace is not None:
                h = hover_model_world_n
                hover_step = HoverStep(
                    (float(h[0]), float(h[1]), float(h[2])),
                    dt / p.mass_kg, accel_density * dt, rest_var, vv, started,
                )  # fmt: skip
        moving = self._moving
        mixed: tuple[list[float], list[float]] | None = None
        if moving is not None and dt > 0.0:
            # The tension as still moving since the last change, beside the filter's own
            # (MovingTension): the estimate is their posterior mixture until the two agree.
            mixed = moving.mixture(kf) if moving.step(z, r, dt, dt_mean, tau, a_pred, w) else None
            if mixed is None:
                kf.set(*moving.mixture(kf))
                self._moving = None
                if self.trace is not None:
                    self._merged = (list(kf.x), list(kf.P))
        self._samples += 1
        warming = estimate_noise and noise.samples < self._warmup
        lazy: LazyChangeStatistic | None = None
        if warming:
            # Innovations whitened with a noise estimate of a few samples are not evidence
            # (of a tug or of a drift).
            self._change.clear()
            stat, window = 0.0, 0
        else:
            self._drift.push(w, dt)
            if self._change.push(z, w):
                # No window can be above the threshold: the statistic is computed if read.
                lazy = self._change.lazy_statistic(self._dt_mean, test_youth)
                stat, window = 0.0, 0
            else:
                # The longest window: where the smallest step of interest reaches the
                # threshold as applied (h youth) at the long-run noise, h youth r / step^2.
                r_max = r0 if r0 > r1 else r1
                r_max = r_max if r_max > r2 else r2
                n_cap = self._change.threshold * test_youth * r_max * self._inv_min_step_n2
                size = self._change.ring.size
                self._change.set_cap(int(n_cap) if n_cap < size else size)
                stat, window = self._change.evaluate(self._dt_mean, test_youth)
        change = stat > self._change.threshold
        if change:
            # Restart from the observations since the change (x = their mean, P = R / n).
            self._restart(self._change.mean_of_window(window), window, r)
            self._start_moving(window, tau_hover)
            mixed = None
        if self.trace is not None:
            restart = window if change else self._restart_pending
            self._record("update", z, q, r, restart, hover_step, mixed)
        self._restart_pending = 0
        return self._publish(change, stat if lazy is None else lazy, scale, tau, mixed)

    def coast(self, dt_s: float) -> TensionEstimate | None:
        """One filter step without an observation (ground contact, dropped sample).

        Only the prediction runs (x- = x, P- = P + Q with the hover Q), so the
        uncertainty grows with the time elapsed. Before the first observation there is
        nothing to coast.

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
        r = self._noise.long_run() if self.params.estimate_noise else self._prior_var
        dt_mean = self._dt_mean if self._dt_mean == self._dt_mean else 0.0
        tau = self.hover_time_constant(r, dt_mean)
        q = (
            r[0] * dt_mean / (tau * tau) * dt,
            r[1] * dt_mean / (tau * tau) * dt,
            r[2] * dt_mean / (tau * tau) * dt,
        )
        self._kf.predict(q)  # P = P + Q
        self._hover_v.active = False  # no observation: the hover's velocity is not followed
        self._moving = None
        if self.trace is not None:
            self._record("coast", None, q, None, 0)
        return self._publish(False, 0.0, 1.0, tau)

    # -- internals ---------------------------------------------------------------------

    def _noise_allowances(self) -> tuple[float, float]:
        """The noise estimate's allowances at the measured spacing, cached per spacing: the
        warm estimate's scatter (:func:`~groundstation.tension_change.level_scatter_factor`,
        the change test's floor) and the count where the youth factor has faded out
        (:func:`~groundstation.tension_change.level_samples`, the level's equilibrium
        count). ``(1, inf)`` before a spacing is known: no floor, no fade."""
        spacing = self._dt_mean
        if not (spacing == spacing and spacing > 0.0):
            return 1.0, math.inf
        cached = self._allowances
        if cached[0] != spacing:
            memory = self.params.noise_time_constant_s / spacing
            cached = self._allowances = (
                spacing,
                level_scatter_factor(memory),
                level_samples(memory),
            )
        return cached[1], cached[2]

    def hover_time_constant(self, r_n2: tuple[float, ...], dt_mean_s: float) -> float:
        """The time constant at hover for a noise r and a sample spacing, s.

        ``sqrt(rbar dt_mean / q)`` (rbar the mean of the axes' long-run variances, q =
        ``hover_wander_n2_per_s``), at least ``hover_time_constant_s``;
        ``hover_time_constant_s`` while q is 0 or dt_mean unknown. Class docstring:
        *Process noise in seconds*.
        """
        p = self.params
        tau = p.hover_time_constant_s
        q = p.hover_wander_n2_per_s
        if q > 0.0 and dt_mean_s == dt_mean_s and dt_mean_s > 0.0:
            r0, r1, r2 = r_n2
            tau_w = math.sqrt((r0 + r1 + r2) / 3.0 * dt_mean_s / q)
            if tau_w > tau:
                tau = tau_w
        return tau

    @property
    def change_threshold(self) -> float:
        """The change test's threshold now (:meth:`fast_threshold` at the measured
        spacing), dimensionless: a ``change_statistic`` above it is a detection."""
        return self._change.threshold

    def fast_threshold(self, dt_mean_s: float | None) -> float:
        """The change test's threshold at a mean sample spacing, dimensionless.

        :func:`~groundstation.tension_change.scan_threshold` for ``false_alarms_per_h``
        over the windows
        [``change_min_window``, ``change_max_window_s`` / dt] samples (the history grows to
        hold them, :meth:`ChangeTest.reserve`). Infinite with no spacing known (nothing can
        be judged before one) and when ``false_alarms_per_h`` is 0.
        """
        p = self.params
        if p.false_alarms_per_h == 0.0:
            return math.inf
        if not (dt_mean_s is not None and dt_mean_s == dt_mean_s and dt_mean_s > 0.0):
            return math.inf
        dt = dt_mean_s
        n_lo = float(p.change_min_window)
        n_hi = max(n_lo, float(int(p.change_max_window_s / dt)))
        return scan_threshold(p.false_alarms_per_h, n_lo, max(n_hi, n_lo + 1.0), dt)

    def _restart(self, mean_n: list[float], window: int, r: tuple[float, ...]) -> None:
        """x = the mean of the last ``window`` observations, P = R / window."""
        self._kf.set(mean_n, [r[0] / window, r[1] / window, r[2] / window])  # P = R / n
        self._merged = None  # the restart starts the regime (and the smoother's segment)
        self._hover_v.active = False
        self._change.clear()
        self._drift.clear()

    def _start_moving(self, window: int, tau_hover: float) -> None:
        """After a detected change ``window`` samples ago: the hypothesis that the tension
        still moves on that time scale joins the filter's own (:class:`MovingTension`),
        from the same restarted state, at even odds, or at the odds it had where it was
        winning when this change was found. Not while the window spans a hover time
        constant or more (the two would be one model)."""
        dt_mean = self._dt_mean
        if not (dt_mean == dt_mean and dt_mean > 0.0):
            return
        window_s = window * dt_mean
        if window_s < tau_hover:
            p = self.params
            prev = self._moving
            kf = self._kf
            self._moving = MovingTension(
                kf.x, kf.P, window_s, tau_hover, p.drift_memory_s, p.drift_min_time_constant_s
            )
            if prev is not None and prev.log_odds > 0.0:
                # A change found while the tension was shown to move: that evidence stands
                # (a new change is no evidence against motion); after a constant stretch the
                # two start again at even odds.
                self._moving.log_odds = prev.log_odds

    def _record(
        self,
        kind: Literal["init", "update", "coast"],
        z: tuple[float, float, float] | list[float] | None,
        q: tuple[float, float, float],
        r: tuple[float, ...] | None,
        restart: int,
        hover: HoverStep | None = None,
        mixed: tuple[list[float], list[float]] | None = None,
    ) -> None:
        assert self.trace is not None
        x, P = (self._kf.x, self._kf.P) if mixed is None else mixed
        step = FilterStep(
            kind, _tuple3(x), _tuple3(P), _tuple3(z), q, _tuple3(r), int(restart), hover
        )
        self.trace.append(step)
        merged = self._merged
        if merged is not None:
            # The filter took the two hypotheses' mixture as its state in this step: the
            # smoother's next segment starts from it (kind "start").
            self.trace.append(FilterStep("start", _tuple3(merged[0]), _tuple3(merged[1])))
            self._merged = None

    def _publish(
        self,
        change: bool,
        stat: float | LazyChangeStatistic,
        scale: float,
        tau: float,
        mixed: tuple[list[float], list[float]] | None = None,
    ) -> TensionEstimate:
        kf = self._kf
        x0, x1, x2 = kf.x if mixed is None else mixed[0]
        p00, p11, p22 = kf.P if mixed is None else mixed[1]
        noise_std: tuple[float, float, float] | NoiseStatus
        noise_rho: tuple[float, float, float] | NoiseStatus
        if self.params.estimate_noise:
            noise_std = noise_rho = self._noise.status()  # computed if read
        else:
            noise_std, noise_rho = self._prior_std, (0.0, 0.0, 0.0)
        # One immutable buffer for the three arrays (read-only, as results are): a third
        # of the cost of three np.array calls and setflags.
        buf = _PACK15(
            x0,
            x1,
            x2,
            _sqrt_clipped(p00),  # std = sqrt(clip(diag(P), 0))
            _sqrt_clipped(p11),
            _sqrt_clipped(p22),
            p00,  # cov = diag(P)
            0.0,
            0.0,
            0.0,
            p11,
            0.0,
            0.0,
            0.0,
            p22,
        )
        samples = self._samples
        est = _estimate(
            {
                "tension_world_n": _ndarray(_SHAPE3, _F64, buf, 0),
                "cov_n2": _ndarray(_SHAPE33, _F64, buf, 48),
                "std_n": _ndarray(_SHAPE3, _F64, buf, 24),
                "converged": samples >= self._warmup,
                "change_detected": change,
                "samples": samples,
                "_lazy_change_statistic": stat,
                "process_noise_scale": scale,
                "_lazy_noise_std_n": noise_std,
                "_lazy_noise_autocorrelation": noise_rho,
                "time_constant_s": tau,
            }
        )
        self._last = est
        return est


def _estimate(attributes: dict[str, Any]) -> TensionEstimate:
    """``TensionEstimate(**fields)`` given its instance ``__dict__`` (the lazy fields under
    their descriptors' keys), without the frozen ``__init__``'s one ``object.__setattr__``
    per field: half the cost of the result. TensionEstimate has no ``__post_init__``;
    tests/test_tension_equivalence.py checks that the two make equal estimates."""
    est = _new_object(TensionEstimate)
    _object_setattr(est, "__dict__", attributes)
    return est


def _finite3(value: ArrayLike, name: str) -> tuple[float, float, float]:
    """The 3 entries of a finite 3-vector as Python floats; raises as :func:`_vector3`."""
    if type(value) is np.ndarray and value.dtype is _F64 and value.shape == _SHAPE3:
        a, b, c = value.tolist()
        if _isfinite(a) and _isfinite(b) and _isfinite(c):
            return a, b, c
    elif type(value) is tuple and len(value) == 3:
        a, b, c = value
        if (
            type(a) is float
            and type(b) is float
            and type(c) is float
            and _isfinite(a)
            and _isfinite(b)
            and _isfinite(c)
        ):
            return a, b, c
    a, b, c = _vector3(value, name).tolist()
    return a, b, c


_isfinite = math.isfinite


def _tuple3(v: ArrayLike | None) -> tuple[float, float, float] | None:
    if v is None:
        return None
    a, b, c = (float(e) for e in np.asarray(v, dtype=np.float64).ravel())
    return (a, b, c)


def _sqrt_clipped(v: float) -> float:
    """``np.sqrt(np.clip(v, 0.0, None))`` for one value (NaN stays NaN)."""
    return math.sqrt(v) if v > 0.0 else (v if v != v else 0.0)


def _check_dt(dt_s: float) -> float:
    dt = float(dt_s)
    if not (math.isfinite(dt) and dt >= 0.0):
        raise InvalidTimeStepError(f"dt_s must be finite and >= 0, got {dt_s!r}")
    return dt
