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
Vec3 = tuple[float, float, float]


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
    tethered: bool = True
    """False: no tether (``[sim] untethered``): no tether force, no taut stop."""
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

    def _tether(self, px: float, py: float, pz: float) -> tuple[Vec3, bool, bool]:
        """The tether's force on the drone at (px, py, pz), floor contact, taut."""
        if not self.tethered:
            return (0.0, 0.0, 0.0), False, False
        if self.coin_mass_kg is not None and self.coin_arm_m is not None:
            # The coin bench: a weightless thread over an arm, T = m_coin·g toward the arm.
            ax, ay, az = self.coin_arm_m.tolist()
            dx, dy, dz = ax - px, ay - py, az - pz
            n = math.sqrt(dx * dx + dy * dy + dz * dz)
            w = self.coin_mass_kg * GRAVITY_MPS2
            return (dx / n * w, dy / n * w, dz / n * w), False, False
        bx, by, bz = self.base_world_m.tolist()
        cx, cy, cz = px - bx, py - by, pz - bz
        if math.sqrt(cx * cx + cy * cy + cz * cz) >= self.length_m * (1.0 - 1e-6):
            return self._taut_force(cx, cy, cz), False, True
        try:
            tf = tether_force(
                self.base_world_m,
                np.array([px, py, pz]),
                self.length_m,
                self.weight_n_per_m,
                self.floor_z_m,
            )
        except TetherTooShortError:
            return self._taut_force(cx, cy, cz), False, True
        fx, fy, fz = (float(v) for v in tf.force_world_n)
        norm = math.sqrt(fx * fx + fy * fy + fz * fz)
        if norm > self.tension_cap_n:
            k = self.tension_cap_n / norm
            return (fx * k, fy * k, fz * k), bool(tf.floor_contact), True
        return (fx, fy, fz), bool(tf.floor_contact), False

    def tether_at(self, position_world_m: np.ndarray) -> np.ndarray:
        """The tether's force on the drone at a position, world, N (the starting pull)."""
        px, py, pz = (float(c) for c in position_world_m)
        return np.array(self._tether(px, py, pz)[0])

    def _taut_force(self, cx: float, cy: float, cz: float) -> Vec3:
        n = math.sqrt(cx * cx + cy * cy + cz * cz)
        cap = self.tension_cap_n
        return (-cx / n * cap, -cy / n * cap, -cz / n * cap) if n > 0 else (0.0, 0.0, 0.0)

    def _control(self, dt_s: float, p: Vec3, v: Vec3) -> tuple[float, Vec3]:
        """Thrust (N) and body z axis (world) from the position controller, the drone at
        ``p`` with velocity ``v``."""
        if not self.armed:
            self.integral_m_s[:] = 0.0
            zx, zy, zz = self.quat_axis().tolist()
            return 0.0, (zx, zy, zz)
        if self.armed_for_s < self.thrust_ramp_s:
            # Spool-up: thrust grows with time, level, whatever the position error.
            self.integral_m_s[:] = 0.0
            ramp = self.armed_for_s / self.thrust_ramp_s
            return ramp * self.mass_kg * GRAVITY_MPS2, (0.0, 0.0, 1.0)
        tx, ty, tz = self.target_world_m.tolist()
        ex, ey, ez = tx - p[0], ty - p[1], tz - p[2]
        ix, iy, iz = self.integral_m_s.tolist()
        if not self.on_ground:
            ix, iy, iz = ix + ex * dt_s, iy + ey * dt_s, iz + ez * dt_s
            ix = -2.0 if ix < -2.0 else (2.0 if ix > 2.0 else ix)  # clip to [-2, 2]
            iy = -2.0 if iy < -2.0 else (2.0 if iy > 2.0 else iy)
            iz = -2.0 if iz < -2.0 else (2.0 if iz > 2.0 else iz)
            self.integral_m_s[:] = (ix, iy, iz)
        kp, kd, ki, m = self.kp_per_s2, self.kd_per_s, self.ki_per_s3, self.mass_kg
        ax = kp * ex - kd * v[0] + ki * ix
        ay = kp * ey - kd * v[1] + ki * iy
        az = kp * ez - kd * v[2] + ki * iz
        fx, fy, fz = m * (ax - 0.0), m * (ay - 0.0), m * (az - -GRAVITY_MPS2)
        # Limit the tilt: keep the vertical part, shrink the horizontal part.
        horiz = math.hypot(fx, fy)
        max_horiz = max(fz, 0.0) * math.tan(self.max_tilt_rad)
        if horiz > max_horiz and horiz > 0:
            k = max_horiz / horiz
            fx, fy = fx * k, fy * k
        thrust = math.sqrt(fx * fx + fy * fy + fz * fz)
        max_thrust = self.max_thrust_ratio * self.mass_kg * GRAVITY_MPS2
        if thrust < 1e-9:
            return 0.0, (0.0, 0.0, 1.0)
        return min(thrust, max_thrust), (fx / thrust, fy / thrust, fz / thrust)

    def quat_axis(self) -> np.ndarray:
        return rotation_world_body_wxyz(self.quat_wxyz)[:, 2]

    def step(self, dt_s: float, external_force_world_n: np.ndarray) -> None:
        """Advance by ``dt_s``: control, forces, contact, integration, sensor truth.

        On Python floats (numpy's per-call cost on 3-vectors was most of the step), in
        numpy's order of operations, so the same numbers to the bit.
        """
        h = dt_s / self.substeps
        bx, by, bz = self.base_world_m.tolist()
        ex, ey, ez = (float(f) for f in external_force_world_n)
        p = self.position_world_m.tolist()
        v = self.velocity_world_mps.tolist()
        m = self.mass_kg
        floor_z = self.floor_z_m
        reach = self.length_m * (1.0 - 1e-6)
        tension: Vec3 = (0.0, 0.0, 0.0)
        acc: Vec3 = (0.0, 0.0, 0.0)
        thrust = 0.0
        floor_contact = taut = on_ground = False
        for _ in range(self.substeps):
            self.armed_for_s = self.armed_for_s + h if self.armed else 0.0
            thrust, (zx, zy, zz) = self._control(h, (p[0], p[1], p[2]), (v[0], v[1], v[2]))
            if self.armed:
                self.quat_wxyz = quat_wxyz_from_z_axis(np.array([zx, zy, zz]))
            tension, floor_contact, taut = self._tether(p[0], p[1], p[2])
            # + m·g with g = (0, 0, -9.81) as numpy added it (the 0.0 terms included, which
            # turn a -0.0 into 0.0): tests/test_sim_ideal_floats.py compares bit for bit.
            fx = thrust * zx + tension[0] + ex + m * 0.0
            fy = thrust * zy + tension[1] + ey + m * 0.0
            fz = thrust * zz + tension[2] + ez + m * -GRAVITY_MPS2
            # The floor: it pushes back while the drone rests on it.
            on_floor = p[2] <= floor_z + 1e-9
            normal_z = 0.0
            if on_floor and fz <= 0.0:
                normal_z = -fz
                fz = fz + normal_z
                v = [0.0, 0.0, 0.0]
                # friction holds it in place horizontally
                fx = fy = 0.0
            acc = (fx / m, fy / m, fz / m)
            v = [v[0] + acc[0] * h, v[1] + acc[1] * h, v[2] + acc[2] * h]
            p = [p[0] + v[0] * h, p[1] + v[1] * h, p[2] + v[2] * h]
            if p[2] < floor_z:
                p[2] = floor_z
                v[2] = max(0.0, v[2])
            cx, cy, cz = p[0] - bx, p[1] - by, p[2] - bz
            dist = math.sqrt(cx * cx + cy * cy + cz * cz)
            if dist > reach and self.coin_mass_kg is None and self.tethered:
                # Taut stop: the tether does not stretch; drop the outward velocity.
                ux, uy, uz = cx / dist, cy / dist, cz / dist
                p = [bx + ux * reach, by + uy * reach, bz + uz * reach]
                radial = v[0] * ux + v[1] * uy + v[2] * uz
                if radial > 0:
                    v = [v[0] - radial * ux, v[1] - radial * uy, v[2] - radial * uz]
                taut = True
            on_ground = bool(on_floor and normal_z > 0.0)
            self.on_ground = on_ground
            self.position_world_m[:] = p
            self.velocity_world_mps[:] = v
        self.thrust_n = thrust
        self.tension_world_n = np.array(tension)
        self.floor_contact = floor_contact
        self.taut = taut
        # Specific force f = R'(p'' - g) = R'(F_total_non_gravity)/m (NOTES.md).
        R = rotation_world_body_wxyz(self.quat_wxyz)
        self.specific_force_body_mps2 = R.T @ np.array(
            [acc[0] - 0.0, acc[1] - 0.0, acc[2] - -GRAVITY_MPS2]
        )
