"""The thrust and battery model: collective thrust from the reported thrust and the battery.

Pure physics: numpy and Python floats only (docs/battery_model.md, docs/calibration.md).

Two models turn Telemetry's ``thrust_n`` (the bridge's nominal thrust) and ``vbat_v`` into
the thrust the observation uses (``[calibration] thrust_model``):

* ``vbat_linear``: ``F = thrust_n·(s + k·(vbat_v − v_ref))``, a straight line in the
  battery voltage, fitted over the calibration's battery range. It holds there and nowhere
  else: below the range it extrapolates a line through a curve.
* ``motor_voltage``: the physics of a brushed motor behind a PWM duty. The bridge's nominal
  thrust is a known map of the motor command ``pwm`` (``[crazyflie] thrust_map``, per motor
  ``a·pwm² + b·pwm + c``), so the mean command is that map inverted at ``thrust_n/4``; the
  motor sees the duty times the battery, ``v = vbat_v·pwm/65535`` (the motor's voltage,
  what the firmware's own battery compensation works in); and one motor's thrust is a power
  of it::

      pwm = (sqrt(b² + 4a·(thrust_n/4 − c)) − b) / (2a)      # the map inverted, 0..65535
      v   = vbat_v · pwm / 65535                               # motor voltage, V
      F   = s · 4 · f_ref · (v / v_ref)^n                      # N

  ``f_ref`` (N, one motor's thrust at motor voltage ``v_ref``) and ``n`` are fitted by
  ``groundstation calibrate``; ``n = 2`` is the textbook rotor (thrust ∝ ω², ω ∝ v with a
  light load). A lower battery needs a larger duty for the same motor voltage, and the
  model reads the same thrust from it, as the firmware intends; the straight line reads the
  larger duty as more thrust, less and less right as the battery drops.

The four motors are taken as equal (the mean command): the map summed over four commands
exceeds four times the map at their mean by ``a·Σ(pwm_i − mean)²``, 0.6 mN (0.1 % of the
thrust) for commands 5 % apart at a hover command of 55 000 (derived).
:func:`motor_voltage_thrust_n` is the per-message equation in Python floats;
:func:`motor_voltage_thrust_n_array` the same equation over arrays for the fit, tested
equal to it.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "EXPONENT_BOUNDS",
    "MOTORS",
    "NOMINAL_PWM_MAP",
    "PWM_FULL_SCALE",
    "ROTOR_EXPONENT",
    "THRUST_MODELS",
    "ThrustModel",
    "mean_motor_voltage_v",
    "mean_motor_voltage_v_array",
    "motor_voltage_thrust_n",
    "motor_voltage_thrust_n_array",
]

FloatArray = NDArray[np.float64]

ThrustModel = Literal["vbat_linear", "motor_voltage"]
THRUST_MODELS: tuple[ThrustModel, ...] = ("vbat_linear", "motor_voltage")

NOMINAL_PWM_MAP: tuple[float, float, float] = (2.130295e-11, 1.032633e-6, 5.484560e-4)
"""``[crazyflie] thrust_map``'s default, the widely used Crazyflie 2.x fit (physical: a
measured map, per motor ``a·pwm² + b·pwm + c`` N); the bridge's nominal thrust."""
MOTORS = 4
"""Motors of a quadrotor (physical): ``thrust_n`` is their sum."""
PWM_FULL_SCALE = 65535.0
"""The Crazyflie's motor command at full duty (physical: its 16-bit ratio, ``motor.m*``)."""
ROTOR_EXPONENT = 2.0
"""Thrust ∝ (motor voltage)^2 (physical: thrust ∝ ω², ω ∝ v for a lightly loaded motor);
what ``calibrate`` uses when the data do not determine the exponent."""
EXPONENT_BOUNDS = (1.0, 2.0)
"""Where ``calibrate`` looks for the exponent (derived): a brushed motor under a propeller
has ``v = R·I + k_e·ω`` and ``k_t·I = k_q·ω²``, so ``v = (R·k_q/k_t)·ω² + k_e·ω`` and
thrust ∝ ω². Back-EMF-limited (light load) ``ω ∝ v``: ``n = 2``; resistance-limited
(heavy load) ``ω² ∝ v``: ``n = 1``; ``d ln F / d ln v`` lies between."""


def mean_motor_voltage_v(
    thrust_n: float, vbat_v: float, pwm_map: tuple[float, float, float]
) -> float:
    """Mean motor voltage from the nominal collective thrust and the battery, V (module doc).

    Args:
        thrust_n: nominal collective thrust (the bridge's map summed over the motors), N.
        vbat_v: battery voltage, V.
        pwm_map: ``(a, b, c)`` of that map, one motor ``a·pwm² + b·pwm + c`` N.
    """
    a, b, c = pwm_map
    q = thrust_n / MOTORS - c
    # the map inverted: a·pwm² + b·pwm − q = 0, the positive root (a linear map: q / b)
    if a > 0.0:
        d = b * b + 4.0 * a * q
        pwm = (math.sqrt(d) - b) / (2.0 * a) if d > 0.0 else 0.0
    else:
        pwm = q / b
    return vbat_v * pwm / PWM_FULL_SCALE if pwm > 0.0 else 0.0


def motor_voltage_thrust_n(
    thrust_n: float,
    vbat_v: float,
    pwm_map: tuple[float, float, float],
    motor_ref_n: float,
    motor_ref_v: float,
    exponent: float,
) -> float:
    """Collective thrust by the motor-voltage model (module doc), before the scale, N.

    ``F = 4 · f_ref · (v / v_ref)^n`` with ``v`` from :func:`mean_motor_voltage_v`.

    Args:
        thrust_n: nominal collective thrust, N, >= 0.
        vbat_v: battery voltage, V, > 0.
        pwm_map: ``(a, b, c)`` of the bridge's map, per motor, N.
        motor_ref_n: one motor's thrust at ``motor_ref_v``, N (fitted).
        motor_ref_v: reference motor voltage, V (the calibration's median).
        exponent: ``n``, dimensionless (fitted).
    """
    v = mean_motor_voltage_v(thrust_n, vbat_v, pwm_map)
    return MOTORS * motor_ref_n * (v / motor_ref_v) ** exponent


def mean_motor_voltage_v_array(
    thrust_n: FloatArray, vbat_v: FloatArray, pwm_map: tuple[float, float, float]
) -> FloatArray:
    """:func:`mean_motor_voltage_v` over arrays (the fit's), V, shape of ``thrust_n``."""
    a, b, c = pwm_map
    q = np.asarray(thrust_n, float) / MOTORS - c
    root = np.sqrt(np.maximum(b * b + 4.0 * a * q, 0.0))
    pwm = (root - b) / (2.0 * a) if a > 0.0 else q / b
    return np.where(pwm > 0.0, np.asarray(vbat_v, float) * pwm / PWM_FULL_SCALE, 0.0)


def motor_voltage_thrust_n_array(
    thrust_n: FloatArray,
    vbat_v: FloatArray,
    pwm_map: tuple[float, float, float],
    motor_ref_n: float,
    motor_ref_v: float,
    exponent: float,
) -> FloatArray:
    """:func:`motor_voltage_thrust_n` over arrays (the fit's), N, shape of ``thrust_n``."""
    v = mean_motor_voltage_v_array(thrust_n, vbat_v, pwm_map)
    return MOTORS * motor_ref_n * (v / motor_ref_v) ** exponent
