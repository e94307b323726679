"""The ``realistic`` profile's quadrotor: a rigid body with motors, rotor drag and a controller.

State: position and velocity (world frame, z up), attitude ``q_world_body`` (``wxyz``, the
*reference* body frame B, the frame whose attitude Telemetry reports, as motion capture sees
it), body rates ``omega_body_rps``, four motor thrusts. Per step of ``dt_s``:

- controller: position PID (integral held on the floor) → desired force
  ``F_des = m·(a_des + g·e3)`` with a tilt limit → desired attitude (body z along F_des, yaw
  from the yaw setpoint) → geometric attitude control on SO(3), ``τ = −k_R·e_R − k_ω·ω +
  ω × Jω``, ``e_R = ½·vee(R_dᵀR − RᵀR_d)`` (Lee, Leok & McClamroch 2010) → an X-mixer
  gives four motor commands, clipped to [0, max];
- motors: first-order lag ``τ_m`` from command to thrust (``motor_tau_s``; 0: none);
- forces: thrust ``F`` along the *thrust axis* ``n_B = R_x(a_x)·R_y(a_y)·e3`` in B (an
  airframe constant; the controller aims body z, so the drone hovers tilted until its integral
  absorbs the offset, as a real one does), rotor drag ``−F/F_hover·D·v_B`` (horizontal body
  velocity, proportional to thrust, like blade flapping), the tether and external pulls;
- the floor: while the drone rests on it (net force down) it is held level and still, and
  the floor's push is part of the specific force the accelerometer feels;
- spool-up: for ``thrust_ramp_s`` after arming, collective thrust ramps 0 → weight, level.

Semi-implicit Euler for the translation, the exponential map for the attitude. Pure: numpy and
the stdlib; no state outside the object.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from groundstation.sim.rotation import rot_x, rot_y, rotation_world_body_wxyz

__all__ = ["AirframeParams", "RigidDrone"]

GRAVITY_MPS2 = 9.81
_E3 = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class AirframeParams:
    """The airframe and its controller (Crazyflie 2.1 defaults).

    Attributes:
        mass_kg: drone mass, kg.
        inertia_kg_m2: principal moments of inertia (body x, y, z), kg·m².
        arm_m: distance from the centre to each motor, m (X configuration).
        yaw_moment_per_n: rotor drag torque per newton of thrust, m.
        max_thrust_ratio: maximum collective thrust over the weight.
        motor_tau_s: motor time constant, s (0: thrust follows the command at once).
        rotor_drag_n_s_per_m: horizontal rotor drag at hover thrust, N per m/s of body
            velocity (0: none).
        thrust_axis_rad: thrust axis as ``[about_x, about_y]`` rotation of body +z, rad.
        kp_per_s2, kd_per_s, ki_per_s3: position PID gains (per unit mass).
        attitude_bandwidth_rps: natural frequency of the attitude loop, rad/s.
        attitude_damping: damping ratio of the attitude loop.
        max_tilt_rad: tilt limit of the position controller, rad.
        thrust_ramp_s: spool-up time after arming (0: none), s.
    """

    mass_kg: float = 0.030
    inertia_kg_m2: tuple[float, float, float] = (1.66e-5, 1.66e-5, 2.93e-5)
    arm_m: float = 0.046
    yaw_moment_per_n: float = 0.006
    max_thrust_ratio: float = 2.0
    motor_tau_s: float = 0.030
    rotor_drag_n_s_per_m: float = 0.0073
    thrust_axis_rad: tuple[float, float] = (0.0, 0.0)
    kp_per_s2: float = 16.0
    kd_per_s: float = 7.0
    ki_per_s3: float = 8.0
    attitude_bandwidth_rps: float = 18.0
    attitude_damping: float = 0.8
    max_tilt_rad: float = math.radians(35.0)
    thrust_ramp_s: float = 0.0


def _mixer(arm_m: float, yaw_moment_per_n: float) -> np.ndarray:
    """``[F, τx, τy, τz] = M·f`` for motors at (±d, ±d), d = arm/√2 (X configuration)."""
    d = arm_m / math.sqrt(2.0)
    k = yaw_moment_per_n
    # motors 1..4 at (d, −d), (−d, −d), (−d, d), (d, d); τx = Σ y·f, τy = −Σ x·f
    return np.array(
        [
            [1.0, 1.0, 1.0, 1.0],
            [-d, -d, d, d],
            [-d, d, d, -d],
            [-k, k, -k, k],
        ]
    )


@dataclass
class RigidDrone:
    """One quadrotor (see the module docstring). Units SI, world frame z up."""

    params: AirframeParams
    position_world_m: np.ndarray
    floor_z_m: float = 0.0
    yaw_rad: float = 0.0
    armed: bool = True
    velocity_world_mps: np.ndarray = field(default_factory=lambda: np.zeros(3))
    q_world_body: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))
    omega_body_rps: np.ndarray = field(default_factory=lambda: np.zeros(3))
    target_world_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    yaw_target_rad: float = 0.0
    integral_m_s: np.ndarray = field(default_factory=lambda: np.zeros(3))
    armed_for_s: float = 0.0
    on_ground: bool = False
    # outputs of the last step
    motor_thrust_n: np.ndarray = field(default_factory=lambda: np.zeros(4))
    command_thrust_n: float = 0.0
    """Collective thrust the controller commanded (what the motor PWM encodes), N."""
    thrust_n: float = 0.0
    """Collective thrust the motors deliver, N."""
    specific_force_body_mps2: np.ndarray = field(
        default_factory=lambda: np.array([0.0, 0.0, GRAVITY_MPS2])
    )
    """True specific force (non-gravitational force / mass) in the reference body frame."""

    def __post_init__(self) -> None:
        p = self.params
        self.position_world_m = np.array(self.position_world_m, dtype=float)
        self._J = np.array(p.inertia_kg_m2, dtype=float)
        self._M = _mixer(p.arm_m, p.yaw_moment_per_n)
        self._M_inv = np.linalg.inv(self._M)
        self._weight_n = p.mass_kg * GRAVITY_MPS2
        self._f_max = p.max_thrust_ratio * self._weight_n / 4.0
        self._thrust_axis_body = rot_x(p.thrust_axis_rad[0]) @ rot_y(p.thrust_axis_rad[1]) @ _E3
        wn, zeta = p.attitude_bandwidth_rps, p.attitude_damping
        self._J_t = tuple(float(v) for v in self._J)
        self._k_R_t = tuple(float(v) * wn * wn for v in self._J)
        self._k_w_t = tuple(float(v) * 2.0 * zeta * wn for v in self._J)
        self._M_t = self._M.tolist()
        self._M_inv_t = self._M_inv.tolist()
        self._thrust_axis_t = tuple(float(v) for v in self._thrust_axis_body)
        self._tan_tilt = math.tan(p.max_tilt_rad)
        self._alpha_dt_s = -1.0
        self._alpha = 0.0
        if not self.target_world_m.any():
            self.target_world_m = self.position_world_m.copy()
        self.q_world_body = _yaw_quat(self.yaw_rad)
        self.yaw_target_rad = self.yaw_rad

    @property
    def R_world_body(self) -> np.ndarray:
        return rotation_world_body_wxyz(self.q_world_body)

    @property
    def hover_thrust_n(self) -> float:
        return self._weight_n

    def preload_integral(self, external_world_n: np.ndarray) -> None:
        """Start in equilibrium against a constant external force (e.g. the tether)."""
        self.integral_m_s = -np.asarray(external_world_n, float) / (
            self.params.mass_kg * self.params.ki_per_s3
        )
        self.motor_thrust_n[:] = self._weight_n / 4.0
        self.command_thrust_n = self.thrust_n = self._weight_n

    # ------------------------------------------------------------------ control
    # Plain floats below: numpy's per-call cost on 3-vectors is most of a step's time.

    def _control(self, dt_s: float, R: list[float]) -> list[float]:
        """Motor commands (4), N; ``R`` row-major ``R_world_body``."""
        p = self.params
        if not self.armed:
            self.integral_m_s[:] = 0.0
            return [0.0, 0.0, 0.0, 0.0]
        if self.armed_for_s < p.thrust_ramp_s:
            # Spool-up: collective thrust grows with time, level, whatever the position error.
            self.integral_m_s[:] = 0.0
            collective = self._weight_n * self.armed_for_s / p.thrust_ramp_s
            return self._mix(collective, self._attitude_torque(R, (0.0, 0.0, 1.0)))
        px, py, pz = self.position_world_m.tolist()
        tx, ty, tz = self.target_world_m.tolist()
        vx, vy, vz = self.velocity_world_mps.tolist()
        ex, ey, ez = tx - px, ty - py, tz - pz
        ix, iy, iz = self.integral_m_s.tolist()
        if not self.on_ground:
            ix = min(max(ix + ex * dt_s, -2.0), 2.0)
            iy = min(max(iy + ey * dt_s, -2.0), 2.0)
            iz = min(max(iz + ez * dt_s, -2.0), 2.0)
            self.integral_m_s[:] = (ix, iy, iz)
        m, kp, kd, ki = p.mass_kg, p.kp_per_s2, p.kd_per_s, p.ki_per_s3
        fx = m * (kp * ex - kd * vx + ki * ix)
        fy = m * (kp * ey - kd * vy + ki * iy)
        fz = m * (kp * ez - kd * vz + ki * iz) + self._weight_n
        horiz = math.hypot(fx, fy)
        max_horiz = max(fz, 0.0) * self._tan_tilt
        if horiz > max_horiz and horiz > 0.0:
            fx, fy = fx * max_horiz / horiz, fy * max_horiz / horiz
        norm = math.sqrt(fx * fx + fy * fy + fz * fz)
        z_des = (fx / norm, fy / norm, fz / norm) if norm > 1e-9 else (0.0, 0.0, 1.0)
        # Collective thrust: the desired force along the current body z (Lee et al.).
        collective = max(0.0, fx * R[2] + fy * R[5] + fz * R[8])
        return self._mix(collective, self._attitude_torque(R, z_des))

    def _attitude_torque(
        self, R: list[float], z_des: tuple[float, float, float]
    ) -> tuple[float, float, float]:
        yaw = self.yaw_target_rad
        cx, cy = math.cos(yaw), math.sin(yaw)
        zx, zy, zz = z_des
        # y_des = z × x_c, x_c = (cos ψ, sin ψ, 0); x_des = y_des × z
        yx, yy, yz = -zz * cy, zz * cx, zx * cy - zy * cx
        n = math.sqrt(yx * yx + yy * yy + yz * yz)
        yx, yy, yz = yx / n, yy / n, yz / n
        xx, xy, xz = yy * zz - yz * zy, yz * zx - yx * zz, yx * zy - yy * zx
        D = (xx, yx, zx, xy, yy, zy, xz, yz, zz)  # R_des row-major
        # e_R = ½ vee(R_dᵀR − RᵀR_d): vee of A − Aᵀ, A = R_dᵀR
        a = [
            D[i] * R[j] + D[3 + i] * R[3 + j] + D[6 + i] * R[6 + j]
            for i in range(3)
            for j in range(3)
        ]
        erx = 0.5 * (a[7] - a[5])
        ery = 0.5 * (a[2] - a[6])
        erz = 0.5 * (a[3] - a[1])
        wx, wy, wz = self.omega_body_rps.tolist()
        Jx, Jy, Jz = self._J_t
        kRx, kRy, kRz = self._k_R_t
        kwx, kwy, kwz = self._k_w_t
        # τ = −k_R e_R − k_ω ω + ω × Jω
        return (
            -kRx * erx - kwx * wx + (wy * Jz * wz - wz * Jy * wy),
            -kRy * ery - kwy * wy + (wz * Jx * wx - wx * Jz * wz),
            -kRz * erz - kwz * wz + (wx * Jy * wy - wy * Jx * wx),
        )

    def _mix(self, collective_n: float, torque: tuple[float, float, float]) -> list[float]:
        w = (collective_n, *torque)
        f_max = self._f_max
        Mi = self._M_inv_t
        return [
            min(
                max(Mi[r][0] * w[0] + Mi[r][1] * w[1] + Mi[r][2] * w[2] + Mi[r][3] * w[3], 0.0),
                f_max,
            )
            for r in range(4)
        ]

    # ------------------------------------------------------------------ dynamics

    def step(self, dt_s: float, external_world_n: np.ndarray) -> None:
        """Advance by ``dt_s`` under ``external_world_n`` (tether + pulls), world frame, N."""
        p = self.params
        self.armed_for_s = self.armed_for_s + dt_s if self.armed else 0.0
        R = _rotation_rows(self.q_world_body)
        command = self._control(dt_s, R)
        self.command_thrust_n = sum(command)
        motors = self.motor_thrust_n.tolist()
        if not self.armed:
            motors = [0.0, 0.0, 0.0, 0.0]
        elif p.motor_tau_s > 0.0:
            alpha = self._motor_alpha(dt_s)
            motors = [f + (c - f) * alpha for f, c in zip(motors, command, strict=True)]
        else:
            motors = command
        self.motor_thrust_n[:] = motors
        M = self._M_t
        thrust = motors[0] + motors[1] + motors[2] + motors[3]
        f1, f2, f3, f4 = motors
        tau = [M[r][0] * f1 + M[r][1] * f2 + M[r][2] * f3 + M[r][3] * f4 for r in (1, 2, 3)]
        self.thrust_n = thrust
        vx, vy, vz = self.velocity_world_mps.tolist()
        # body-frame force: thrust along the thrust axis, rotor drag on horizontal body velocity
        nx, ny, nz = self._thrust_axis_t
        bx, by, bz = thrust * nx, thrust * ny, thrust * nz
        if p.rotor_drag_n_s_per_m > 0.0 and thrust > 0.0:
            drag = p.rotor_drag_n_s_per_m * thrust / self._weight_n
            vbx = R[0] * vx + R[3] * vy + R[6] * vz
            vby = R[1] * vx + R[4] * vy + R[7] * vz
            bx -= drag * vbx
            by -= drag * vby
        ex, ey, ez = (float(v) for v in external_world_n)
        # non-gravitational force, world frame
        Fx = R[0] * bx + R[1] * by + R[2] * bz + ex
        Fy = R[3] * bx + R[4] * by + R[5] * bz + ey
        Fz = R[6] * bx + R[7] * by + R[8] * bz + ez
        m = p.mass_kg
        on_floor = float(self.position_world_m[2]) <= self.floor_z_m + 1e-9
        if on_floor and Fz - self._weight_n <= 0.0:
            # Resting on the floor: it pushes back and friction holds the drone (level); the
            # accelerometer feels exactly the weight.
            self.velocity_world_mps[:] = 0.0
            self.omega_body_rps[:] = 0.0
            self.q_world_body = _yaw_quat(math.atan2(R[3], R[0]))
            self.on_ground = True
            Rl = _rotation_rows(self.q_world_body)
            g = GRAVITY_MPS2
            self.specific_force_body_mps2[:] = (Rl[6] * g, Rl[7] * g, Rl[8] * g)
            return
        self.on_ground = False
        vx += Fx / m * dt_s
        vy += Fy / m * dt_s
        vz += (Fz / m - GRAVITY_MPS2) * dt_s
        pos = self.position_world_m
        pos += (vx * dt_s, vy * dt_s, vz * dt_s)
        if pos[2] < self.floor_z_m:
            pos[2] = self.floor_z_m
            vz = max(0.0, vz)
        self.velocity_world_mps[:] = (vx, vy, vz)
        # Attitude: Jω' = τ − ω × Jω, then q ← q ⊗ exp(ω·dt)
        wx, wy, wz = self.omega_body_rps.tolist()
        Jx, Jy, Jz = self._J_t
        wx += (tau[0] - (wy * Jz * wz - wz * Jy * wy)) / Jx * dt_s
        wy += (tau[1] - (wz * Jx * wx - wx * Jz * wz)) / Jy * dt_s
        wz += (tau[2] - (wx * Jy * wy - wy * Jx * wx)) / Jz * dt_s
        self.omega_body_rps[:] = (wx, wy, wz)
        self.q_world_body = _integrate_quat(self.q_world_body, wx * dt_s, wy * dt_s, wz * dt_s)
        # f = Rᵀ(F_non-gravitational)/m, in the reference body frame of the step's start
        self.specific_force_body_mps2[:] = (
            (R[0] * Fx + R[3] * Fy + R[6] * Fz) / m,
            (R[1] * Fx + R[4] * Fy + R[7] * Fz) / m,
            (R[2] * Fx + R[5] * Fy + R[8] * Fz) / m,
        )

    def _motor_alpha(self, dt_s: float) -> float:
        if dt_s != self._alpha_dt_s:
            self._alpha_dt_s = dt_s
            self._alpha = 1.0 - math.exp(-dt_s / self.params.motor_tau_s)
        return self._alpha


def _rotation_rows(q_wxyz: np.ndarray) -> list[float]:
    """``R_world_body`` row-major as 9 floats: ``I + 2w[v]× + 2[v]×²`` written out
    (:func:`~groundstation.sim.rotation.rotation_world_body_wxyz` in plain floats)."""
    w, x, y, z = q_wxyz.tolist()
    n = 1.0 / math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w * n, x * n, y * n, z * n
    return [
        1.0 - 2.0 * (y * y + z * z),
        2.0 * (x * y - w * z),
        2.0 * (x * z + w * y),
        2.0 * (x * y + w * z),
        1.0 - 2.0 * (x * x + z * z),
        2.0 * (y * z - w * x),
        2.0 * (x * z - w * y),
        2.0 * (y * z + w * x),
        1.0 - 2.0 * (x * x + y * y),
    ]


def _integrate_quat(q_wxyz: np.ndarray, rx: float, ry: float, rz: float) -> np.ndarray:
    """``q ⊗ exp(r)`` for a body rotation vector ``r`` (rad), normalised."""
    angle = math.sqrt(rx * rx + ry * ry + rz * rz)
    if angle < 1e-12:
        dw, dx, dy, dz = 1.0, 0.5 * rx, 0.5 * ry, 0.5 * rz
    else:
        k = math.sin(0.5 * angle) / angle
        dw, dx, dy, dz = math.cos(0.5 * angle), k * rx, k * ry, k * rz
    w, x, y, z = q_wxyz.tolist()
    q = np.array(
        (
            w * dw - x * dx - y * dy - z * dz,
            w * dx + x * dw + y * dz - z * dy,
            w * dy - x * dz + y * dw + z * dx,
            w * dz + x * dy - y * dx + z * dw,
        )
    )
    return q / math.sqrt(float(q @ q))


def _yaw_quat(yaw_rad: float) -> np.ndarray:
    return np.array([math.cos(0.5 * yaw_rad), 0.0, 0.0, math.sin(0.5 * yaw_rad)])
