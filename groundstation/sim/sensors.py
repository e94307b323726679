"""Error models of the ``realistic`` profile: what a real Crazyflie reports instead of the truth.

Every class can be switched off and sized (:class:`SensorParams`); the per-flight ("per boot")
constants are drawn once per drone from a seeded generator (:func:`draw_errors`), independent
of the per-sample noise stream, so changing a noise level does not change the drawn offsets.

Frames and sign conventions (the calibration model of ``[calibration]`` is stated in the same
terms, so a fitted calibration can be checked against :meth:`DrawnErrors.equivalent`):

- B, the *reference body frame*: the frame whose attitude Telemetry reports (``quat_wxyz``,
  body → world; the motion-capture body). ``f_B`` is the true specific force in B.
- Accelerometer (``accel_mps2``)::

      accel = (1 + s) · R_B_Aᵀ · f_B + b + n,     R_B_A = R_x(m_x) · R_y(m_y)

  ``s`` the scale error (``accel_scale_error``, uniform in ±``accel_scale_max``), ``m_x, m_y``
  the misalignment of the accelerometer frame A in B (``misalignment_rad``; magnitude uniform
  in [0, ``misalignment_max_rad``], direction uniform), ``b`` the bias in A
  (``accel_bias_mps2``, normal with std ``accel_bias_std_mps2`` per axis), ``n`` the noise.
  ``R_x(a)``, ``R_y(a)``: right-handed rotations about +x, +y by ``a``.
- Thrust axis: the rotors push along ``n_B = R_x(a_x) · R_y(a_y) · e3`` in B
  (``thrust_axis_rad = (a_x, a_y)``, an airframe constant, default (−0.037, −0.016) rad).
- Reported thrust (``thrust_n``): the commanded collective thrust ``F_cmd`` (what the motor
  PWM encodes; before the motor lag) read through a nominal map that is off::

      thrust_n = F_cmd · (1 + e) · (V_ref / V)^γ

  ``e = thrust_report_error`` (+ a per-flight normal spread ``thrust_report_error_std``;
  reported/true − 1 at ``V = V_ref``; −0.091 is the paper's flights' "1.10 too low",
  +0.6..+0.9 newer firmware's "too high"), ``V`` the battery voltage, ``γ`` the voltage
  exponent (motor thrust at a fixed PWM grows with V², so the map reads ever higher as the
  battery sags).
- Equivalent calibration (what ``[calibration]`` must hold for the estimator to be exactly
  right at hover): ``accel_bias_mps2 = (1 + s)·R_B_Aᵀ·f_h − f_h + b`` with ``f_h`` the true
  specific force in B at the start of the hover (``accel_bias_level_mps2``: the same at
  ``f_h = g·e3``);
  ``thrust_axis_rad = (a_x, a_y)``; ``thrust_scale = 1/(1 + e)``, ``thrust_vbat_slope_per_v =
  γ/((1 + e)·V_ref)``, ``thrust_vbat_ref_v = V_ref`` (the first-order expansion of
  ``(V/V_ref)^γ/(1 + e)``; 0.2 % off at 0.16 V from V_ref); ``thrust_scale_hover_start``: the
  exact ``1/((1 + e)(V_ref/V)^γ)`` at the flight's first hover voltage (for an estimator that
  does not use ``vbat_v``). With γ = 2 the law is exactly the estimator's motor-voltage model
  (``thrust_model = "motor_voltage"``) read through a map quadratic in the motor command,
  ``thrust_n/4 = a·pwm²``: a motor's true thrust is ``f_ref·(v/v_ref)²`` in its voltage
  ``v = V·pwm/65535``, so ``F = thrust_n·(V/V_ref)²/(1 + e)`` for ``f_ref = a·65535²/(1 + e)``
  and ``v_ref = V_ref`` (one motor's true thrust at full duty on a battery at ``V_ref``; any
  ``a > 0`` gives the same ``F``: :meth:`DrawnErrors.airframe_equivalent`).

Noise: per IMU sample and axis ``n_k = σ_k·(√β·c_k + √(1 − β)·w_k)`` with ``c_k = a·c_{k−1} +
√(1 − a²)·ε_k`` a unit AR(1) (vibration, coloured) and ``w_k`` white; ``β = lag1/a`` so the lag-1
autocorrelation is ``accel_noise_lag1``; ``σ_k = sqrt(σ_floor² + (σ_vib·r_k)²)`` with ``r_k``
the motors' thrust over the weight, capped at 1 (so at hover the std is ``accel_noise_mps2``,
with the motors off the sensor's own ``accel_noise_floor_mps2``).

Timing: IMU messages every ``1/imu_rate_hz`` plus a normal jitter, with probability
``imu_late_prob`` a late one (uniform up to ``imu_spacing_max_s``), clipped to
[``imu_spacing_min_s``, ``imu_spacing_max_s``]. Motion capture: frames captured at a per-flight
rate uniform in [``mocap_rate_min_hz``, ``mocap_rate_max_hz``], delivered after
``mocap_latency_s`` (+ up to 1 ms); with probability ``mocap_burst_prob`` a frame is held back
and delivered with the next one (< 1 ms apart: bursts); outages (Poisson,
``mocap_outage_rate_per_s``) drop every frame for up to ``mocap_outage_max_s`` minus a frame.

Battery: open-circuit voltage linear in the state of charge from ``battery_full_v`` to
``battery_empty_v``, minus ``battery_internal_ohm`` times a current ``battery_hover_current_a ·
(F/F_hover)^1.5``; the charge drains with that current.

Pure: numpy and the stdlib; time is a parameter.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from groundstation.sim.rotation import (
    quat_wxyz_from_z_axis,
    rot_x,
    rot_y,
    rotation_world_body_wxyz,
)

__all__ = [
    "Battery",
    "DrawnErrors",
    "ImuNoise",
    "MocapStream",
    "SensorParams",
    "draw_errors",
    "imu_spacing_s",
]

GRAVITY_MPS2 = 9.81

PWM_FULL_SCALE = 65535.0
"""The Crazyflie's motor command at full duty (its 16-bit ratio)."""
QUADRATIC_MAP_FULL_DUTY_N = 0.16
"""One motor's reported thrust at full duty in the map of the motor-voltage equivalent,
N (about the Crazyflie 2.x nominal map's at pwm 65535; any value > 0 gives the same
thrust, it only sets the scale of ``thrust_pwm_map`` and ``thrust_motor_ref_n``)."""


@dataclass(frozen=True)
class SensorParams:
    """Sizes and switches of every error class (the ``[sim.realistic]`` keys of the same name)."""

    vibration: bool = True
    accel_noise_mps2: float = 1.0
    accel_noise_lag1: float = 0.2
    accel_noise_ar: float = 0.6
    accel_noise_floor_mps2: float = 0.02
    gyro_noise_rps: float = 0.01
    misalignment: bool = True
    misalignment_max_rad: float = 0.052
    accel_scale: bool = True
    accel_scale_max: float = 0.025
    accel_bias: bool = True
    accel_bias_std_mps2: float = 0.05
    attitude_levelled: bool = False
    thrust_axis: bool = True
    thrust_axis_rad: tuple[float, float] = (-0.037, -0.016)
    thrust_map: bool = True
    thrust_report_error: float = -0.0909
    thrust_report_error_std: float = 0.01
    thrust_vbat_exponent: float = 2.0
    thrust_vbat_ref_v: float = 4.05
    battery: bool = True
    publish_vbat: bool = True
    battery_full_v: float = 4.20
    battery_empty_v: float = 3.50
    battery_capacity_mah: float = 250.0
    battery_internal_ohm: float = 0.12
    battery_hover_current_a: float = 1.2
    battery_soc_start: float = 1.0
    imu_timing: bool = True
    imu_rate_hz: float = 100.0
    imu_jitter_std_s: float = 0.0015
    imu_late_prob: float = 0.05
    imu_spacing_min_s: float = 0.006
    imu_spacing_max_s: float = 0.027
    mocap_timing: bool = True
    mocap_rate_min_hz: float = 70.0
    mocap_rate_max_hz: float = 116.0
    mocap_latency_s: float = 0.010
    mocap_burst_prob: float = 0.175
    mocap_outage_rate_per_s: float = 0.2
    mocap_outage_max_s: float = 0.150
    mocap_noise_m: float = 0.0003


@dataclass(frozen=True)
class DrawnErrors:
    """The per-flight constants of one drone (sign conventions: module docstring).

    Attributes:
        misalignment_rad: (m_x, m_y), accelerometer frame A in B, rad.
        accel_scale_error: s, dimensionless.
        accel_bias_mps2: b, in A, m/s².
        thrust_axis_rad: (a_x, a_y), rad.
        thrust_report_error: e, reported/true − 1 at ``thrust_vbat_ref_v``.
        thrust_vbat_exponent: γ.
        thrust_vbat_ref_v: V_ref, V.
        hover_vbat_v: battery voltage at hover thrust at the start of the flight, V.
        mocap_rate_hz: this flight's motion-capture frame rate, Hz.
        hover_specific_force_body_mps2: true specific force in B at the start of the hover
            (after the warm-up; ``g·e3`` for a start on the floor), where the equivalent
            accelerometer bias is exact.
    """

    misalignment_rad: tuple[float, float]
    accel_scale_error: float
    accel_bias_mps2: tuple[float, float, float]
    thrust_axis_rad: tuple[float, float]
    thrust_report_error: float
    thrust_vbat_exponent: float
    thrust_vbat_ref_v: float
    hover_vbat_v: float
    mocap_rate_hz: float
    hover_specific_force_body_mps2: tuple[float, float, float] = (0.0, 0.0, GRAVITY_MPS2)

    @property
    def R_body_accel(self) -> np.ndarray:
        """``R_B_A = R_x(m_x)·R_y(m_y)``."""
        return rot_x(self.misalignment_rad[0]) @ rot_y(self.misalignment_rad[1])

    def report_factor(self, vbat_v: float) -> float:
        """Reported over true thrust, ``(1 + e)·(V_ref/V)^γ``."""
        return (1.0 + self.thrust_report_error) * (
            self.thrust_vbat_ref_v / vbat_v
        ) ** self.thrust_vbat_exponent

    def accel_bias_at(self, f_body_mps2: np.ndarray) -> np.ndarray:
        """Equivalent accelerometer bias at true specific force ``f_B``:
        ``(1 + s)·R_B_Aᵀ·f_B − f_B + b``, m/s² (accel − this = f_B, noise aside)."""
        f = np.asarray(f_body_mps2, dtype=float)
        b = np.array(self.accel_bias_mps2)
        return np.asarray((1.0 + self.accel_scale_error) * self.R_body_accel.T @ f - f + b)

    def level_reading_mps2(self) -> np.ndarray:
        """What the accelerometer reads level and still: ``(1 + s)·R_B_Aᵀ·g·e3 + b``."""
        return np.asarray(
            (1.0 + self.accel_scale_error) * self.R_body_accel.T @ np.array([0, 0, GRAVITY_MPS2])
            + np.array(self.accel_bias_mps2)
        )

    def attitude_offset_wxyz(self) -> np.ndarray:
        """``Q`` of an attitude levelled on this accelerometer: reported = true ⊗ Q.

        A levelling estimator takes the still reading's direction ``â`` for "up", so the
        reported body frame satisfies ``R_repᵀ·e3 = â`` at level: ``Q = R_q^T`` with
        ``R_q·e3 = â`` (the shortest arc, zero yaw).
        """
        w, x, y, z = quat_wxyz_from_z_axis(self.level_reading_mps2())
        return np.array([w, -x, -y, -z])

    def airframe_equivalent(
        self, levelled: bool, thrust_model: str = "vbat_linear"
    ) -> dict[str, Any]:
        """The airframe constants as the airframe calibration sees them for this flight.

        Thrust scale and battery term as :meth:`equivalent` (``thrust_model = "vbat_linear"``:
        the straight line, first order in ``V − V_ref``) or, with ``thrust_model =
        "motor_voltage"``, the motor-voltage model that is this law exactly at every voltage
        (module docstring; γ must be 2, else ValueError); the thrust axis in the frame the
        attitude is reported in (``Qᵀ·n_B`` when the attitude is levelled on the
        accelerometer: then it differs from flight to flight by the per-boot tilt).
        """
        n_b = (
            rot_x(self.thrust_axis_rad[0])
            @ rot_y(self.thrust_axis_rad[1])
            @ np.array([0.0, 0.0, 1.0])
        )
        if levelled:
            Q = rotation_world_body_wxyz(self.attitude_offset_wxyz())
            n_b = Q.T @ n_b
        # n = (sin ay, −sin ax·cos ay, cos ax·cos ay)
        ay = math.asin(float(np.clip(n_b[0], -1.0, 1.0)))
        ax = math.atan2(-float(n_b[1]), float(n_b[2]))
        one_e = 1.0 + self.thrust_report_error
        if thrust_model == "motor_voltage":
            if self.thrust_vbat_exponent != 2.0:
                raise ValueError(
                    f"thrust_vbat_exponent {self.thrust_vbat_exponent!r}: the motor-voltage "
                    "model is this law only for an exponent of 2"
                )
            a = QUADRATIC_MAP_FULL_DUTY_N / PWM_FULL_SCALE**2
            return {
                "thrust_model": "motor_voltage",
                "thrust_pwm_map": [a, 0.0, 0.0],
                "thrust_motor_ref_n": QUADRATIC_MAP_FULL_DUTY_N / one_e,
                "thrust_motor_ref_v": self.thrust_vbat_ref_v,
                "thrust_motor_exponent": 2.0,
                "thrust_scale": 1.0,
                "thrust_vbat_ref_v": self.thrust_vbat_ref_v,
                "thrust_axis_rad": [ax, ay],
            }
        if thrust_model != "vbat_linear":
            raise ValueError(f"thrust_model {thrust_model!r}")
        return {
            "thrust_scale": 1.0 / one_e,
            "thrust_vbat_slope_per_v": self.thrust_vbat_exponent / (one_e * self.thrust_vbat_ref_v),
            "thrust_vbat_ref_v": self.thrust_vbat_ref_v,
            "thrust_axis_rad": [ax, ay],
        }

    def equivalent(self) -> dict[str, Any]:
        """The ``[calibration]`` values that make the estimator exact at hover.

        ``accel_bias_mps2`` at this flight's hover specific force
        (``hover_specific_force_body_mps2``), ``accel_bias_level_mps2`` at ``g·e3``; they
        differ by the misalignment and scale acting on the hover tilt (a few 0.01 m/s²).
        """
        bias = self.accel_bias_at(np.array(self.hover_specific_force_body_mps2))
        level = self.accel_bias_at(np.array([0.0, 0.0, GRAVITY_MPS2]))
        one_e = 1.0 + self.thrust_report_error
        return {
            "thrust_scale": 1.0 / one_e,
            "thrust_vbat_slope_per_v": self.thrust_vbat_exponent / (one_e * self.thrust_vbat_ref_v),
            "thrust_vbat_ref_v": self.thrust_vbat_ref_v,
            "thrust_scale_hover_start": 1.0 / self.report_factor(self.hover_vbat_v),
            "thrust_axis_rad": [float(v) for v in self.thrust_axis_rad],
            "accel_bias_mps2": [float(v) for v in bias],
            "accel_bias_level_mps2": [float(v) for v in level],
        }

    def as_dict(self) -> dict[str, Any]:
        """The drawn values and their equivalent calibration (``errors`` of Truth)."""
        out: dict[str, Any] = {
            k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()
        }
        out["calibration"] = self.equivalent()
        return out


def draw_errors(p: SensorParams, rng: np.random.Generator, hover_vbat_v: float) -> DrawnErrors:
    """Draw one flight's constants (always the same number of draws, on or off)."""
    mag = float(rng.uniform(0.0, 1.0)) * p.misalignment_max_rad
    phi = float(rng.uniform(-math.pi, math.pi))
    scale = float(rng.uniform(-1.0, 1.0)) * p.accel_scale_max
    bias = rng.normal(0.0, 1.0, 3) * p.accel_bias_std_mps2
    e_spread = float(rng.normal(0.0, 1.0)) * p.thrust_report_error_std
    rate = float(rng.uniform(p.mocap_rate_min_hz, p.mocap_rate_max_hz))
    return DrawnErrors(
        misalignment_rad=(mag * math.cos(phi), mag * math.sin(phi)) if p.misalignment else (0, 0),
        accel_scale_error=scale if p.accel_scale else 0.0,
        accel_bias_mps2=(float(bias[0]), float(bias[1]), float(bias[2]))
        if p.accel_bias
        else (0.0, 0.0, 0.0),
        thrust_axis_rad=p.thrust_axis_rad if p.thrust_axis else (0.0, 0.0),
        thrust_report_error=p.thrust_report_error + e_spread if p.thrust_map else 0.0,
        thrust_vbat_exponent=p.thrust_vbat_exponent if p.thrust_map and p.battery else 0.0,
        thrust_vbat_ref_v=p.thrust_vbat_ref_v,
        hover_vbat_v=hover_vbat_v,
        mocap_rate_hz=rate if p.mocap_timing else p.imu_rate_hz,
    )


class ImuNoise:
    """Accelerometer noise per sample: white + AR(1) vibration (module docstring)."""

    def __init__(self, p: SensorParams, rng: np.random.Generator) -> None:
        if p.vibration and not 0.0 <= p.accel_noise_lag1 <= p.accel_noise_ar < 1.0:
            raise ValueError(
                f"accel_noise_lag1 {p.accel_noise_lag1!r} must be in [0, accel_noise_ar "
                f"{p.accel_noise_ar!r}] and accel_noise_ar < 1"
            )
        self.p = p
        self.rng = rng
        self._c = rng.normal(0.0, 1.0, 3)  # stationary start of the AR(1)

    def sample(self, thrust_ratio: float) -> np.ndarray:
        """(3,) noise, m/s², for motors at ``thrust_ratio`` of the weight."""
        p = self.p
        eps = self.rng.normal(0.0, 1.0, 6)
        if not p.vibration:
            return p.accel_noise_floor_mps2 * eps[:3]
        a = p.accel_noise_ar
        self._c = a * self._c + math.sqrt(1.0 - a * a) * eps[:3]
        beta = p.accel_noise_lag1 / a if a > 0.0 else 0.0
        r = min(max(thrust_ratio, 0.0), 1.0)
        sigma = math.sqrt(p.accel_noise_floor_mps2**2 + (p.accel_noise_mps2 * r) ** 2)
        return sigma * (math.sqrt(beta) * self._c + math.sqrt(1.0 - beta) * eps[3:])


def imu_spacing_s(p: SensorParams, rng: np.random.Generator) -> float:
    """The time to the next IMU message, s (always two draws, so streams stay aligned)."""
    u, z = float(rng.uniform()), float(rng.normal())
    nominal = 1.0 / p.imu_rate_hz
    if not p.imu_timing:
        return nominal
    if u < p.imu_late_prob:
        late = nominal + 0.004 + (p.imu_spacing_max_s - nominal - 0.004) * float(rng.uniform())
        return min(late, p.imu_spacing_max_s)
    return min(max(nominal + p.imu_jitter_std_s * z, p.imu_spacing_min_s), p.imu_spacing_max_s)


class MocapStream:
    """Capture and delivery schedule of motion-capture frames (module docstring).

    The schedule is drawn ahead in blocks of ``block_s``; :meth:`capture` records the true
    position of frames captured by ``t_s``, :meth:`arrived` returns those delivered by ``t_s``.
    """

    def __init__(
        self,
        p: SensorParams,
        rate_hz: float,
        rng: np.random.Generator,
        block_s: float = 10.0,
    ) -> None:
        self.p = p
        self.rate_hz = rate_hz
        self.rng = rng
        self.block_s = block_s
        self._schedule: list[tuple[float, float]] = []  # (capture_s, arrival_s), by capture
        self._next_block_s = 0.0
        self._captured: list[tuple[float, float, np.ndarray]] = []  # (arrival, capture, pos)
        self._cursor = 0
        self.arrivals_s: list[float] = []
        """Arrival times of every delivered frame (for statistics)."""
        self._extend()

    def _extend(self) -> None:
        p, rng = self.p, self.rng
        t0, t1 = self._next_block_s, self._next_block_s + self.block_s
        period = 1.0 / self.rate_hz
        n = max(1, round(self.block_s * self.rate_hz))
        capture = t0 + period * np.arange(n)
        if not p.mocap_timing:
            self._schedule.extend((float(c), float(c)) for c in capture)
            self._next_block_s = t1
            return
        keep = np.ones(n, dtype=bool)
        t = t0 + float(rng.exponential(1.0 / p.mocap_outage_rate_per_s))
        while t < t1 and p.mocap_outage_rate_per_s > 0.0:
            length = float(rng.uniform(0.03, max(0.03, p.mocap_outage_max_s - period)))
            keep &= ~((capture >= t) & (capture < t + length))
            t += length + float(rng.exponential(1.0 / p.mocap_outage_rate_per_s))
        capture = capture[keep]
        arrival = capture + p.mocap_latency_s + rng.uniform(0.0, 0.001, capture.size)
        late = rng.uniform(size=capture.size) < p.mocap_burst_prob
        late[-1] = False
        # never hold a frame across an outage (the gap would outgrow mocap_outage_max_s)
        late[:-1] &= np.diff(capture) < 1.5 * period
        hold = rng.uniform(0.0, 0.0008, capture.size)
        for i in range(capture.size - 2, -1, -1):
            if late[i]:
                # held back: delivered just before the next frame (a burst)
                arrival[i] = max(arrival[i], arrival[i + 1] - hold[i])
        self._schedule.extend(zip(capture.tolist(), arrival.tolist(), strict=True))
        self._next_block_s = t1

    def capture(self, t_s: float, position_world_m: np.ndarray) -> None:
        """Record the frames captured by ``t_s`` at the true ``position_world_m``."""
        while self._cursor >= len(self._schedule) or self._schedule[-1][0] <= t_s:
            self._extend()
        while self._schedule[self._cursor][0] <= t_s:
            cap, arr = self._schedule[self._cursor]
            noise = self.rng.normal(0.0, self.p.mocap_noise_m, 3)
            self._captured.append((arr, cap, np.asarray(position_world_m, float) + noise))
            self._cursor += 1

    def arrived(self, t_s: float) -> list[tuple[float, float, np.ndarray]]:
        """Frames delivered by ``t_s`` since the last call, by arrival: (arrival, capture, pos)."""
        ready = [f for f in self._captured if f[0] <= t_s]
        if ready:
            self._captured = [f for f in self._captured if f[0] > t_s]
            ready.sort(key=lambda f: f[0])
            self.arrivals_s.extend(f[0] for f in ready)
        return ready


class Battery:
    """A sagging battery (module docstring); ``vbat_v`` after each :meth:`step`."""

    def __init__(self, p: SensorParams) -> None:
        self.p = p
        self.soc = p.battery_soc_start
        self.vbat_v = self.voltage(0.0)

    def voltage(self, thrust_ratio: float) -> float:
        p = self.p
        if not p.battery:
            return p.thrust_vbat_ref_v
        ocv = p.battery_empty_v + (p.battery_full_v - p.battery_empty_v) * self.soc
        return ocv - p.battery_internal_ohm * self.current_a(thrust_ratio)

    def current_a(self, thrust_ratio: float) -> float:
        return self.p.battery_hover_current_a * max(thrust_ratio, 0.0) ** 1.5

    def step(self, dt_s: float, thrust_ratio: float) -> float:
        if self.p.battery:
            drained = self.current_a(thrust_ratio) * dt_s / (3.6 * self.p.battery_capacity_mah)
            self.soc = max(0.0, self.soc - drained)
        self.vbat_v = self.voltage(thrust_ratio)
        return self.vbat_v
