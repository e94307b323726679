"""The ``realistic`` profile's drone: rigid body + lumped-mass tether + a real drone's sensors.

:class:`RealisticDrone` ties :class:`~groundstation.sim.drone.RigidDrone`,
:class:`~groundstation.sim.tether.LumpedTether` and the error models of
:mod:`~groundstation.sim.sensors` together and steps them at ``physics_rate_hz``. It has the
attributes the runner and the benchmarks read on the ``ideal`` drone (``position_world_m``,
``tension_world_n``, ``armed``, ``length_m``, ...), and :meth:`step` returns the messages
that became due: one Telemetry per IMU sample (its own stamps, 6–27 ms apart), each with
the true state at the same stamp.

Motion capture in Telemetry (``mocap_attach``): ``"latest"`` (default) attaches to every
Telemetry the latest motion-capture frame that has *arrived* by the IMU sample's stamp (its
position is the one at capture, ``mocap_latency_s`` and any burst hold older; absent until
the first frame arrives); ``"new"`` attaches ``position_m`` only to the first Telemetry after
a new frame arrived (several frames arriving between two IMU samples: the latest). The
default keeps ``position_m`` present on every message, so a consumer does not flip between
"motion capture" and "none" with the bursts.

It imports no estimator code and not :mod:`groundstation.catenary` (a test asserts it).
"""

from __future__ import annotations

import math
from dataclasses import fields, replace
from typing import Any

import numpy as np

from groundstation.config import RealisticSection
from groundstation.sim.drone import AirframeParams, RigidDrone
from groundstation.sim.rotation import quat_multiply_wxyz
from groundstation.sim.sensors import (
    Battery,
    DrawnErrors,
    ImuNoise,
    MocapStream,
    SensorParams,
    draw_errors,
    imu_spacing_s,
)
from groundstation.sim.tether import GRAVITY_MPS2, LumpedTether, TetherParams

__all__ = ["RealisticDrone", "sensor_params"]


def sensor_params(cfg: RealisticSection) -> SensorParams:
    """The sensor-error part of ``[sim.realistic]``."""
    return SensorParams(**{f.name: getattr(cfg, f.name) for f in fields(SensorParams)})


def draw_levels(
    cfg: RealisticSection, sensors: SensorParams, rng: np.random.Generator
) -> SensorParams:
    """This flight's vibration level, its lag-1 and the battery's start charge, each uniform
    in its ``[sim.realistic]`` range (``draw_levels``); always three draws, in this order."""
    u = rng.uniform(size=3)
    (n0, n1), (l0, l1), (s0, s1) = (
        cfg.accel_noise_range_mps2,
        cfg.accel_noise_lag1_range,
        cfg.battery_soc_range,
    )
    return replace(
        sensors,
        accel_noise_mps2=float(n0 + (n1 - n0) * u[0]),
        accel_noise_lag1=float(l0 + (l1 - l0) * u[1]),
        battery_soc_start=float(s0 + (s1 - s0) * u[2]),
    )


class RealisticDrone:
    """One drone of the ``realistic`` profile (see the module docstring).

    Args:
        cfg: ``[sim.realistic]``.
        base_world_m: (3,) base exit point, m.
        start_world_m: (3,) initial position, m (on the floor when ``start_on_ground``).
        length_m: tether length, m.
        weight_n_per_m: tether weight per length ω, N/m.
        floor_z_m: floor height, m.
        mass_kg: drone mass, kg.
        seed: this drone's seed (its flight constants and noise streams derive from it).
        armed: armed at t = 0.
        start_on_ground: sits on the floor at t = 0 (no warm-up).
        thrust_ramp_s: spool-up after arming, s.
        coin_mass_kg, coin_arm_m: the coin bench instead of a tether.
        mocap: publish motion capture (``[sim] mocap``); False: no ``position_m``.
        tethered: False: no tether (``[sim] untethered``): no tether force, Truth's
            ``length_m`` 0, no floor contact, never taut.
    """

    def __init__(
        self,
        cfg: RealisticSection,
        *,
        base_world_m: np.ndarray,
        start_world_m: np.ndarray,
        length_m: float,
        weight_n_per_m: float,
        floor_z_m: float,
        mass_kg: float,
        seed: int | tuple[int, ...],
        armed: bool = True,
        start_on_ground: bool = False,
        thrust_ramp_s: float = 0.0,
        coin_mass_kg: float | None = None,
        coin_arm_m: np.ndarray | None = None,
        mocap: bool = True,
        tethered: bool = True,
    ) -> None:
        self.cfg = cfg
        self.sensors = sensor_params(cfg)
        ss = np.random.SeedSequence(seed)
        # A fifth stream for the drawn levels: spawn(5)'s first four are spawn(4)'s, so the
        # other draws do not move when draw_levels is switched.
        flight_ss, noise_ss, timing_ss, mocap_ss, levels_ss = ss.spawn(5)
        if cfg.draw_levels:
            self.sensors = draw_levels(cfg, self.sensors, np.random.default_rng(levels_ss))
        flight_rng = np.random.default_rng(flight_ss)
        self._noise_rng = np.random.default_rng(noise_ss)
        self._timing_rng = np.random.default_rng(timing_ss)
        self.base_world_m = np.array(base_world_m, dtype=float)
        self.floor_z_m = float(floor_z_m)
        self.mass_kg = float(mass_kg)
        self.offset_m = np.zeros(3)
        self.coin_mass_kg = coin_mass_kg
        self.publish_mocap = mocap
        self.tethered = tethered
        self._attitude_offset_wxyz: np.ndarray | None = None
        self.coin_arm_m = coin_arm_m
        self.battery = Battery(self.sensors)
        self.errors: DrawnErrors = draw_errors(self.sensors, flight_rng, self.battery.voltage(1.0))
        yaw0 = float(flight_rng.uniform(-math.pi, math.pi)) if cfg.yaw_motion else 0.0
        self._yaw0_rad = yaw0
        airframe = AirframeParams(
            mass_kg=mass_kg,
            inertia_kg_m2=cfg.inertia_kg_m2,
            arm_m=cfg.arm_m,
            max_thrust_ratio=cfg.max_thrust_ratio,
            motor_tau_s=cfg.motor_tau_s if cfg.motor_lag else 0.0,
            rotor_drag_n_s_per_m=cfg.rotor_drag_n_s_per_m if cfg.rotor_drag else 0.0,
            thrust_axis_rad=self.errors.thrust_axis_rad,
            thrust_ramp_s=thrust_ramp_s,
        )
        start = np.array(start_world_m, dtype=float)
        self.body = RigidDrone(airframe, start, floor_z_m=floor_z_m, yaw_rad=yaw0, armed=armed)
        self.body.on_ground = start_on_ground
        self.tether = LumpedTether(
            TetherParams(
                weight_n_per_m=weight_n_per_m,
                n_segments=cfg.tether_segments,
                stretch_stiffness_n=cfg.tether_stretch_stiffness_n,
                axial_damping_ratio=cfg.tether_axial_damping_ratio,
                air_damping_n_s_per_m2=cfg.tether_air_damping_n_s_per_m2,
                floor_friction=cfg.floor_friction,
            ),
            self.base_world_m,
            start,
            length_m,
            floor_z_m,
        )
        self._length_target_m: float | None = None
        self.physics_dt_s = 1.0 / cfg.physics_rate_hz
        self.t_s = 0.0
        self.tension_world_n = np.zeros(3)
        self.external_world_n = np.zeros(3)
        self._imu_noise = ImuNoise(self.sensors, self._noise_rng)
        self._next_imu_s = 0.0
        self.mocap = MocapStream(
            self.sensors, self.errors.mocap_rate_hz, np.random.default_rng(mocap_ss)
        )
        self._mocap_latest: tuple[float, float, np.ndarray] | None = None
        self._mocap_new = False
        self.seq = 0
        # Start in equilibrium: the tether at rest, the controller holding against it.
        if coin_mass_kg is None and tethered:
            self.tether.settle(4.0, dt_s=self.physics_dt_s, extra_damping_per_s=3.0)
        self.tension_world_n = self._tether_force()
        if not start_on_ground and armed:
            self.body.preload_integral(self.tension_world_n)
            self._warm_up(cfg.warmup_s)
            # the hover voltage with this flight's real hover thrust (tether included)
            ratio = self.body.thrust_n / self.body.hover_thrust_n
            f_h = self.body.specific_force_body_mps2
            self.errors = replace(
                self.errors,
                hover_vbat_v=self.battery.voltage(ratio),
                hover_specific_force_body_mps2=(float(f_h[0]), float(f_h[1]), float(f_h[2])),
            )

    # ------------------------------------------------------------------ runner interface

    @property
    def position_world_m(self) -> np.ndarray:
        return self.body.position_world_m

    @property
    def velocity_world_mps(self) -> np.ndarray:
        return self.body.velocity_world_mps

    @property
    def target_world_m(self) -> np.ndarray:
        return self.body.target_world_m

    @target_world_m.setter
    def target_world_m(self, value: np.ndarray) -> None:
        self.body.target_world_m = np.array(value, dtype=float)

    @property
    def armed(self) -> bool:
        return self.body.armed

    @armed.setter
    def armed(self, value: bool) -> None:
        self.body.armed = bool(value)

    @property
    def length_m(self) -> float:
        """Tether length, m; a new value is reached gradually over the next step (reeling)."""
        return self._length_target_m if self._length_target_m is not None else self.tether.length_m

    @length_m.setter
    def length_m(self, value: float) -> None:
        if not value > 0.0:
            raise ValueError(f"length_m must be > 0, got {value!r}")
        self._length_target_m = float(value)

    @property
    def on_ground(self) -> bool:
        return self.body.on_ground

    @property
    def floor_contact(self) -> bool:
        return self.coin_mass_kg is None and self.tethered and self.tether.floor_contact

    @property
    def taut(self) -> bool:
        return self.coin_mass_kg is None and self.tethered and self.tether.taut

    @property
    def thrust_n(self) -> float:
        return self.body.thrust_n

    @property
    def quat_wxyz(self) -> np.ndarray:
        return self.body.q_world_body

    @property
    def specific_force_body_mps2(self) -> np.ndarray:
        return self.body.specific_force_body_mps2

    def drawn_errors(self) -> dict[str, Any]:
        """This flight's error constants and their equivalent ``[calibration]`` values."""
        out = self.errors.as_dict()
        out["airframe_equivalent"] = self.errors.airframe_equivalent(self.sensors.attitude_levelled)
        out["yaw0_rad"] = self._yaw0_rad
        out["profile"] = "realistic"
        out["classes"] = {
            name: bool(getattr(self.cfg, name))
            for name in (
                "vibration",
                "misalignment",
                "accel_scale",
                "accel_bias",
                "attitude_levelled",
                "thrust_axis",
                "thrust_map",
                "battery",
                "motor_lag",
                "rotor_drag",
                "yaw_motion",
                "imu_timing",
                "mocap_timing",
            )
        }
        out["accel_noise_mps2"] = self.sensors.accel_noise_mps2 if self.cfg.vibration else 0.0
        out["accel_noise_lag1"] = self.sensors.accel_noise_lag1 if self.cfg.vibration else 0.0
        out["battery_soc_start"] = self.sensors.battery_soc_start
        return out

    # ------------------------------------------------------------------ physics

    def _tether_force(self) -> np.ndarray:
        if self.coin_mass_kg is not None and self.coin_arm_m is not None:
            # The coin bench: a weightless thread over an arm, T = m_coin·g toward the arm.
            d = self.coin_arm_m - self.body.position_world_m
            return d / np.linalg.norm(d) * (self.coin_mass_kg * GRAVITY_MPS2)
        if not self.tethered:
            return np.zeros(3)
        return self.tether.force_on_drone_world_n.copy()

    def _tick(self, h: float, length_m: float | None = None) -> None:
        body = self.body
        if self.cfg.yaw_motion and self.cfg.yaw_period_s > 0.0:
            body.yaw_target_rad = self._yaw0_rad + self.cfg.yaw_amplitude_rad * math.sin(
                2.0 * math.pi * self.t_s / self.cfg.yaw_period_s
            )
        body.step(h, self.tension_world_n + self.external_world_n)
        if self.coin_mass_kg is None and self.tethered:
            self.tether.step(h, body.position_world_m, body.velocity_world_mps, length_m)
        self.tension_world_n = self._tether_force()

    def _warm_up(self, seconds: float) -> None:
        for _ in range(round(seconds / self.physics_dt_s)):
            self._tick(self.physics_dt_s)

    def step(self, dt_s: float, external_world_n: np.ndarray) -> list[dict[str, Any]]:
        """Advance by ``dt_s`` under a constant external pull; the samples that became due.

        Returns:
            One dict per IMU sample, in time order: ``{"telemetry": {...contract fields},
            "truth": {...}}`` (truth at the same stamp).
        """
        self.external_world_n = np.asarray(external_world_n, dtype=float)
        n = max(1, math.ceil(dt_s / self.physics_dt_s - 1e-9))
        h = dt_s / n
        out: list[dict[str, Any]] = []
        length0 = self.tether.length_m
        target = self._length_target_m
        for i in range(n):
            reel = None if target is None else length0 + (target - length0) * (i + 1) / n
            self._tick(h, reel)
            self.t_s += h
            ratio = self.body.thrust_n / self.body.hover_thrust_n
            self.battery.step(h, ratio)
            self.mocap.capture(self.t_s, self.body.position_world_m)
            for frame in self.mocap.arrived(self.t_s + 1e-9):
                self._mocap_latest = frame
                self._mocap_new = True
            while self._next_imu_s <= self.t_s + 1e-9:
                out.append(self._sample(round(self._next_imu_s, 6), ratio))
                spacing = imu_spacing_s(self.sensors, self._timing_rng)
                # stamps on the IMU's 1 ms clock
                spacing = max(round(spacing * 1000.0), 1) / 1000.0
                self._next_imu_s += spacing
        if target is not None:
            self.tether.set_length(target)
            self._length_target_m = None
        return out

    def _reported_quat_wxyz(self) -> np.ndarray:
        """The attitude as reported: true, or levelled on the accelerometer (true ⊗ Q)."""
        if not self.sensors.attitude_levelled:
            return self.body.q_world_body
        if self._attitude_offset_wxyz is None:
            self._attitude_offset_wxyz = self.errors.attitude_offset_wxyz()
        return quat_multiply_wxyz(self.body.q_world_body, self._attitude_offset_wxyz)

    def _sample(self, stamp_s: float, thrust_ratio: float) -> dict[str, Any]:
        s, e, body = self.sensors, self.errors, self.body
        f_body = body.specific_force_body_mps2
        accel = (1.0 + e.accel_scale_error) * (e.R_body_accel.T @ f_body)
        accel = accel + np.array(e.accel_bias_mps2) + self._imu_noise.sample(thrust_ratio)
        gyro = body.omega_body_rps + self._noise_rng.normal(0.0, s.gyro_noise_rps, 3)
        vbat = self.battery.vbat_v
        thrust = body.command_thrust_n * e.report_factor(vbat) if body.armed else 0.0
        telemetry: dict[str, Any] = {
            "seq": self.seq,
            "stamp_s": stamp_s,
            "accel_mps2": [float(v) for v in accel],
            "quat_wxyz": [float(v) for v in self._reported_quat_wxyz()],
            "thrust_n": max(0.0, float(thrust)),
            "gyro_rps": [float(v) for v in gyro],
            "armed": bool(body.armed),
        }
        if s.battery and s.publish_vbat:
            telemetry["vbat_v"] = float(vbat)
        frame = self._mocap_latest
        if (
            self.publish_mocap
            and frame is not None
            and (self.cfg.mocap_attach == "latest" or self._mocap_new)
        ):
            telemetry["position_m"] = [float(v) for v in frame[2]]
        self._mocap_new = False
        self.seq += 1
        truth = {
            "stamp_s": stamp_s,
            "position_m": [float(v) for v in body.position_world_m],
            "velocity_mps": [float(v) for v in body.velocity_world_mps],
            "tension_n": [float(v) for v in self.tension_world_n + self.external_world_n],
            "length_m": self.tether.length_m if self.tethered else 0.0,
            "base_m": [float(v) for v in self.base_world_m],
            "floor_contact": self.floor_contact,
            "taut": self.taut,
            "armed": bool(body.armed),
            "on_ground": bool(body.on_ground),
            # beyond Truth (the Python API only): what the sensors saw before their errors
            "specific_force_body_mps2": [float(v) for v in f_body],
            "motor_thrust_n": float(body.thrust_n),
            "vbat_v": float(vbat),
        }
        return {"telemetry": telemetry, "truth": truth}
