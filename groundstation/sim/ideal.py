"""The ``ideal`` profile's drone: the estimator's own assumptions, made flesh.

A point-mass quadrotor whose attitude follows its thrust vector, a position controller with
integral action (so it holds position against the tether), the quasi-static catenary force of
:func:`groundstation.catenary.tether_force` (floor contact included) with a taut stop, a floor
and scripted external pulls. It shares the catenary with the estimator on purpose (the
``ideal`` profile checks the code against itself); the ``realistic`` profile does not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from groundstation.catenary import TetherTooShortError, tether_force
from groundstation.sim.rotation import quat_wxyz_from_z_axis, rotation_world_body_wxyz

__all__ = ["GRAVITY_MPS2", "DroneSim"]

GRAVITY_MPS2 = 9.81
_G_WORLD = np.array([0.0, 0.0, -GRAVITY_MPS2])
_E3 = np.array([0.0, 0.0, 1.0])


@dataclass
class DroneSim:
    """One drone on its tether, stepped with a fixed ``dt_s`` (semi-implicit Euler).

    Units: SI; world frame z up. The tether force is quasi-static (the tether's own
    dynamics are ignored, as in the paper). Near taut the catenary force grows steeply; it is
    capped at ``tension_cap_n`` (the real tether stretches) and the drone cannot leave the
    sphere of radius ``length_m`` around the base (taut stop).
    """

    base_world_m: np.ndarray
    length_m: float
    weight_n_per_m: float
    floor_z_m: float
    mass_kg: float = 0.030
    position_world_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    velocity_world_mps: np.ndarray = field(default_factory=lambda: np.zeros(3))
    target_world_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    armed: bool = True
    kp_per_s2: float = 16.0
    kd_per_s: float = 7.0
    ki_per_s3: float = 8.0
    max_tilt_rad: float = math.radians(35.0)
    max_thrust_ratio: float = 2.5
    tension_cap_n: float = 2.0
    substeps: int = 2
    coin_mass_kg: float | None = None
    coin_arm_m: np.ndarray | None = None
    offset_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """Where the scenario's script is shifted to (several drones fly side by side)."""
    thrust_ramp_s: float = 0.0
    """After arming, thrust ramps linearly 0 → weight over this time (level) before the
    position controller takes over (:attr:`Scenario.thrust_ramp_s`)."""
    armed_for_s: float = 0.0
    """Time since the last arming, s."""
    # outputs of the last step
    integral_m_s: np.ndarray = field(default_factory=lambda: np.zeros(3))
    thrust_n: float = 0.0
    quat_wxyz: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))
    specific_force_body_mps2: np.ndarray = field(
        default_factory=lambda: np.array([0.0, 0.0, GRAVITY_MPS2])
    )
    tension_world_n: np.ndarray = field(default_factory=lambda: np.zeros(3))
    floor_contact: bool = False
    taut: bool = False
    on_ground: bool = False

    def _tether(self, position_world_m: np.ndarray) -> tuple[np.ndarray, bool, bool]:
        if self.coin_mass_kg is not None and self.coin_arm_m is not None:
            # The coin bench: a weightless thread over an arm, T = m_coin·g toward the arm.
            d = self.coin_arm_m - position_world_m
            return d / np.linalg.norm(d) * (self.coin_mass_kg * GRAVITY_MPS2), False, False
        chord = position_world_m - self.base_world_m
        if float(np.linalg.norm(chord)) >= self.length_m * (1.0 - 1e-6):
            return self._taut_force(chord), False, True
        try:
            tf = tether_force(
                self.base_world_m,
                position_world_m,
                self.length_m,
                self.weight_n_per_m,
                self.floor_z_m,
            )
        except TetherTooShortError:
            return self._taut_force(chord), False, True
        force = np.asarray(tf.force_world_n, dtype=float)
        norm = float(np.linalg.norm(force))
        if norm > self.tension_cap_n:
            return force * (self.tension_cap_n / norm), bool(tf.floor_contact), True
        return force, bool(tf.floor_contact), False

    def _taut_force(self, chord: np.ndarray) -> np.ndarray:
        n = float(np.linalg.norm(chord))
        return -chord / n * self.tension_cap_n if n > 0 else np.zeros(3)

    def _control(self, dt_s: float) -> tuple[float, np.ndarray]:
        """Thrust (N) and body z axis (world) from the position controller."""
        if not self.armed:
            self.integral_m_s[:] = 0.0
            return 0.0, self.quat_axis()
        if self.armed_for_s < self.thrust_ramp_s:
            # Spool-up: thrust grows with time, level, whatever the position error.
            self.integral_m_s[:] = 0.0
            ramp = self.armed_for_s / self.thrust_ramp_s
            return ramp * self.mass_kg * GRAVITY_MPS2, _E3.copy()
        err = self.target_world_m - self.position_world_m
        if not self.on_ground:
            self.integral_m_s += err * dt_s
            np.clip(self.integral_m_s, -2.0, 2.0, out=self.integral_m_s)
        acc = self.kp_per_s2 * err - self.kd_per_s * self.velocity_world_mps
        acc += self.ki_per_s3 * self.integral_m_s
        force = self.mass_kg * (acc - _G_WORLD)
        # Limit the tilt: keep the vertical part, shrink the horizontal part.
        horiz = math.hypot(force[0], force[1])
        max_horiz = max(force[2], 0.0) * math.tan(self.max_tilt_rad)
        if horiz > max_horiz and horiz > 0:
            force[:2] *= max_horiz / horiz
        thrust = float(np.linalg.norm(force))
        max_thrust = self.max_thrust_ratio * self.mass_kg * GRAVITY_MPS2
        if thrust < 1e-9:
            return 0.0, _E3.copy()
        return min(thrust, max_thrust), force / thrust

    def quat_axis(self) -> np.ndarray:
        return rotation_world_body_wxyz(self.quat_wxyz)[:, 2]

    def step(self, dt_s: float, external_force_world_n: np.ndarray) -> None:
        """Advance by ``dt_s``: control, forces, contact, integration, sensor truth."""
        h = dt_s / self.substeps
        for _ in range(self.substeps):
            self.armed_for_s = self.armed_for_s + h if self.armed else 0.0
            thrust, z_axis = self._control(h)
            if self.armed:
                self.quat_wxyz = quat_wxyz_from_z_axis(z_axis)
            tension, floor_contact, taut = self._tether(self.position_world_m)
            force = thrust * z_axis + tension + external_force_world_n
            force = force + self.mass_kg * _G_WORLD
            # The floor: it pushes back while the drone rests on it.
            on_floor = self.position_world_m[2] <= self.floor_z_m + 1e-9
            normal = np.zeros(3)
            if on_floor and force[2] <= 0.0:
                normal[2] = -force[2]
                force = force + normal
                self.velocity_world_mps[:] = 0.0
                # friction holds it in place horizontally
                normal[:2] = -force[:2]
                force[:2] = 0.0
            accel = force / self.mass_kg
            self.velocity_world_mps += accel * h
            self.position_world_m += self.velocity_world_mps * h
            if self.position_world_m[2] < self.floor_z_m:
                self.position_world_m[2] = self.floor_z_m
                self.velocity_world_mps[2] = max(0.0, self.velocity_world_mps[2])
            chord = self.position_world_m - self.base_world_m
            dist = float(np.linalg.norm(chord))
            reach = self.length_m * (1.0 - 1e-6)
            if dist > reach and self.coin_mass_kg is None:
                # Taut stop: the tether does not stretch; drop the outward velocity.
                u = chord / dist
                self.position_world_m = self.base_world_m + u * reach
                radial = float(self.velocity_world_mps @ u)
                if radial > 0:
                    self.velocity_world_mps -= radial * u
                taut = True
            self.on_ground = bool(on_floor and normal[2] > 0.0)
            self.thrust_n = thrust
            self.tension_world_n = tension
            self.floor_contact = floor_contact
            self.taut = taut
            # Specific force f = R'(p'' - g) = R'(F_total_non_gravity)/m (NOTES.md).
            R = rotation_world_body_wxyz(self.quat_wxyz)
            self.specific_force_body_mps2 = R.T @ (accel - _G_WORLD)
