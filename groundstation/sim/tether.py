"""A lumped-mass tether: the ``realistic`` profile's own tether model (no catenary code).

The tether is ``n_segments`` straight elastic segments between ``n_segments + 1`` nodes.
Node 0 is the base exit point (fixed), node N the drone's attachment (moved with the drone,
kinematically); the N − 1 interior nodes each carry one segment's mass ``m = ω·l0/g``
(``l0 = L/N`` the segment's rest length). Forces on the nodes:

- stretch: a segment pulls its two ends together with ``t = EA·(l − l0)/l0 + c·dl/dt``,
  never pushes (``t >= 0``: a slack segment carries nothing); ``c = 2ζ·sqrt(k·m)`` with
  ``k = EA/l0`` (axial damping ratio ζ);
- gravity ``−m·g·e3``; an effective linear drag ``−c_air·l0·v`` (air and internal friction);
- the floor: a stiff penalty spring-damper below ``floor_z_m`` and Coulomb friction
  ``μ·N`` regularised below ``friction_speed_mps`` (so the rest state is the frictionless
  one the catenary describes, and the floor still damps the motion).

The force on the drone is the last segment's pull plus the weight of the half segment that
hangs at the drone end (its inertia is neglected: 0.4 g beside a 30 g drone). Integration is
semi-implicit Euler with as many sub-steps as the stiffest mode needs (ω_max·h <= 1), so a
stiffer tether costs time, never stability.

Pure: numpy and the stdlib only; no global state; time is a parameter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["GRAVITY_MPS2", "LumpedTether", "TetherParams"]

GRAVITY_MPS2 = 9.81


@dataclass(frozen=True)
class TetherParams:
    """Physical parameters of the lumped-mass tether.

    Attributes:
        weight_n_per_m: ω, weight per rest length, N/m.
        n_segments: number of segments N (>= 2).
        stretch_stiffness_n: EA, axial stiffness, N (force per unit strain).
        axial_damping_ratio: ζ of each segment's stretch mode.
        air_damping_n_s_per_m2: linear drag per metre of tether, N·s/m per m.
        floor_friction: Coulomb friction coefficient μ on the floor.
        friction_speed_mps: below this sliding speed the friction is viscous, m/s.
        floor_stiffness_n_per_m: penalty stiffness of the floor per node, N/m.
    """

    weight_n_per_m: float = 0.05
    n_segments: int = 10
    stretch_stiffness_n: float = 100.0
    axial_damping_ratio: float = 0.25
    air_damping_n_s_per_m2: float = 1e-3
    floor_friction: float = 0.4
    friction_speed_mps: float = 0.01
    floor_stiffness_n_per_m: float = 50.0


class LumpedTether:
    """State and stepping of one lumped-mass tether (see the module docstring).

    Args:
        params: the tether's physics.
        base_world_m: (3,) base exit point, world frame, m.
        drone_world_m: (3,) drone end, world frame, m.
        length_m: rest length L, m.
        floor_z_m: floor height, m (``-inf``: no floor).
    """

    def __init__(
        self,
        params: TetherParams,
        base_world_m: np.ndarray,
        drone_world_m: np.ndarray,
        length_m: float,
        floor_z_m: float = -math.inf,
    ) -> None:
        if params.n_segments < 2:
            raise ValueError(f"n_segments must be >= 2, got {params.n_segments}")
        if not length_m > 0.0:
            raise ValueError(f"length_m must be > 0, got {length_m!r}")
        self.params = params
        self.length_m = float(length_m)
        self.floor_z_m = float(floor_z_m)
        self.base_world_m = np.array(base_world_m, dtype=float)
        n = params.n_segments
        self.x_world_m = _initial_shape(
            self.base_world_m, np.array(drone_world_m, dtype=float), self.length_m, n, floor_z_m
        )
        self.v_world_mps = np.zeros((n + 1, 3))
        self.force_on_drone_world_n = np.zeros(3)
        self._tension_n = np.zeros(n)
        self._const_for_m = math.nan
        self._const = (0.0, 0.0, 0.0, 0.0)
        self._update_forces()

    # ------------------------------------------------------------------ properties

    @property
    def segment_rest_m(self) -> float:
        return self.length_m / self.params.n_segments

    @property
    def node_mass_kg(self) -> float:
        return self.params.weight_n_per_m * self.segment_rest_m / GRAVITY_MPS2

    @property
    def floor_contact(self) -> bool:
        """An interior node rests on (within 2 mm of) the floor."""
        return bool(np.any(self.x_world_m[1:-1, 2] < self.floor_z_m + 2e-3))

    @property
    def taut(self) -> bool:
        """The chord base → drone is at least the rest length (the tether is stretched)."""
        chord = float(np.linalg.norm(self.x_world_m[-1] - self.x_world_m[0]))
        return chord >= self.length_m

    def energy_j(self) -> float:
        """Kinetic + gravitational + elastic energy of the interior nodes and segments, J."""
        m = self.node_mass_kg
        inner_v = self.v_world_mps[1:-1]
        kinetic = 0.5 * m * float(np.sum(inner_v * inner_v))
        potential = m * GRAVITY_MPS2 * float(np.sum(self.x_world_m[1:-1, 2]))
        d = np.diff(self.x_world_m, axis=0)
        stretch = np.maximum(np.linalg.norm(d, axis=1) - self.segment_rest_m, 0.0)
        k = self.params.stretch_stiffness_n / self.segment_rest_m
        return kinetic + potential + 0.5 * k * float(np.sum(stretch * stretch))

    def substeps(self, dt_s: float) -> int:
        """Sub-steps that keep the stiffest mode stable: ω_max·h <= 1.5 and γ_max·h <= 1.

        The zig-zag mode of the chain has ``ω_max = 2·sqrt(k/m)`` and damping rate
        ``γ_max = 4c/m = 8ζ·sqrt(k/m)``; a node pressed into the floor adds ``k_floor/m`` to
        ω² (semi-implicit Euler is stable up to ω·h = 2 undamped, ~1.8 at ζ = 0.1).
        """
        m = self.node_mass_kg
        k = self.params.stretch_stiffness_n / self.segment_rest_m
        root = math.sqrt(k / m)
        omega_max = math.sqrt(4.0 * root * root + self.params.floor_stiffness_n_per_m / m)
        gamma_max = 8.0 * self.params.axial_damping_ratio * root
        return max(1, math.ceil(dt_s * max(omega_max / 1.5, gamma_max)))

    # ------------------------------------------------------------------ stepping

    def set_length(self, length_m: float) -> None:
        """Reel in or out: the rest length changes, the nodes stay where they are."""
        if not length_m > 0.0:
            raise ValueError(f"length_m must be > 0, got {length_m!r}")
        self.length_m = float(length_m)

    def step(
        self,
        dt_s: float,
        drone_world_m: np.ndarray,
        drone_velocity_world_mps: np.ndarray,
        length_m: float | None = None,
    ) -> np.ndarray:
        """Advance by ``dt_s`` with the drone end at ``drone_world_m``.

        The drone end moves linearly from its last position to ``drone_world_m`` over the
        sub-steps, and the rest length to ``length_m`` (reeling; None: unchanged), so a reel
        does not jerk the stiff segments once per step.

        Returns:
            (3,) force of the tether on the drone at the end of the step, world frame, N.
        """
        n_sub = self.substeps(dt_s)
        h = dt_s / n_sub
        start = self.x_world_m[-1].copy()
        end = np.asarray(drone_world_m, dtype=float)
        self.v_world_mps[-1] = drone_velocity_world_mps
        self.v_world_mps[0] = 0.0
        h_per_m = h / self.node_mass_kg
        inner_x, inner_v = self.x_world_m[1:-1], self.v_world_mps[1:-1]
        step_m = (end - start) / n_sub
        length0 = self.length_m
        reel_m = 0.0 if length_m is None else (float(length_m) - length0) / n_sub
        for i in range(n_sub):
            if reel_m != 0.0:
                self.set_length(length0 + reel_m * (i + 1))
                h_per_m = h / self.node_mass_kg
            self.x_world_m[-1] += step_m
            force = self._update_forces()
            # semi-implicit Euler: v += F/m·h, then x += v·h (interior nodes only)
            inner_v += force[1:-1] * h_per_m
            inner_x += inner_v * h
        self.x_world_m[-1] = end
        return self.force_on_drone_world_n.copy()

    def _constants(self) -> tuple[float, float, float, float]:
        """(l0, m, k, c_axial) for the current length (cached: the length rarely changes)."""
        if self._const_for_m != self.length_m:
            p = self.params
            l0 = self.segment_rest_m
            m = self.node_mass_kg
            k = p.stretch_stiffness_n / l0
            self._const = (l0, m, k, 2.0 * p.axial_damping_ratio * math.sqrt(k * m))
            self._const_for_m = self.length_m
        return self._const

    def _update_forces(self) -> np.ndarray:
        """Node forces (N+1, 3) of the current state; sets the force on the drone."""
        p = self.params
        x, v = self.x_world_m, self.v_world_mps
        l0, m, k, c_axial = self._constants()
        d = x[1:] - x[:-1]
        length = np.sqrt(np.einsum("ij,ij->i", d, d))
        u = d / np.maximum(length, 1e-12)[:, None]
        rate = np.einsum("ij,ij->i", u, v[1:] - v[:-1])
        # t = EA·strain + c·dl/dt while stretched; a slack segment carries nothing. The damper
        # acts in full while stretched (clipping it at zero feeds a slack-taut chatter).
        tension = (k * (length - l0) + c_axial * rate) * (length > l0)
        self._tension_n = tension
        pull = tension[:, None] * u
        # gravity and the effective drag, then the segments' pulls
        force = v * -(p.air_damping_n_s_per_m2 * l0)
        force[:, 2] -= m * GRAVITY_MPS2
        force[:-1] += pull
        force[1:] -= pull
        if float(x[:, 2].min()) < self.floor_z_m:
            pen = np.maximum(self.floor_z_m - x[:, 2], 0.0)
            c_floor = 2.0 * math.sqrt(p.floor_stiffness_n_per_m * m)
            normal = np.maximum(p.floor_stiffness_n_per_m * pen - c_floor * v[:, 2], 0.0)
            normal *= pen > 0.0
            force[:, 2] += normal
            vt = v[:, :2]
            speed = np.sqrt(np.einsum("ij,ij->i", vt, vt) + p.friction_speed_mps**2)
            force[:, :2] -= (p.floor_friction * normal / speed)[:, None] * vt
        # On the drone: the last segment's pull toward the previous node, and the weight of
        # the half segment that hangs at the drone's end.
        on_drone = -pull[-1]
        on_drone[2] -= 0.5 * m * GRAVITY_MPS2
        self.force_on_drone_world_n = on_drone
        return force

    def settle(
        self, duration_s: float, dt_s: float = 1e-3, extra_damping_per_s: float = 0.0
    ) -> None:
        """Let the tether come to rest with both ends held (drone end at its node).

        Args:
            duration_s: simulated time, s.
            dt_s: step, s.
            extra_damping_per_s: added velocity damping ``v ← v·(1 − k·dt)`` to settle faster.
        """
        drone = self.x_world_m[-1].copy()
        zero = np.zeros(3)
        for _ in range(max(1, round(duration_s / dt_s))):
            self.step(dt_s, drone, zero)
            if extra_damping_per_s > 0.0:
                self.v_world_mps *= max(0.0, 1.0 - extra_damping_per_s * dt_s)


def _initial_shape(
    base: np.ndarray, drone: np.ndarray, length_m: float, n: int, floor_z_m: float
) -> np.ndarray:
    """Nodes evenly spaced along a sagging curve of the tether's length (clipped at the floor).

    A parabola-like sag ``depth·4s(1 − s)`` under the chord, ``depth`` by bisection so that
    the curve is as long as the tether; the dynamics then settle it on the real shape.
    """
    s_node = np.linspace(0.0, 1.0, n + 1)
    if float(np.linalg.norm(drone - base)) >= length_m * (1.0 - 1e-9):
        return base[None, :] + s_node[:, None] * (drone - base)[None, :]
    s = np.linspace(0.0, 1.0, 401)
    chord = base[None, :] + s[:, None] * (drone - base)[None, :]

    def shape(depth: float) -> np.ndarray:
        pts = chord.copy()
        pts[:, 2] -= depth * 4.0 * s * (1.0 - s)
        if math.isfinite(floor_z_m):
            pts[:, 2] = np.maximum(pts[:, 2], floor_z_m)
        return pts

    def arc(pts: np.ndarray) -> np.ndarray:
        return np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))))

    lo, hi = 0.0, 4.0 * length_m
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if arc(shape(mid))[-1] < length_m:
            lo = mid
        else:
            hi = mid
    pts = shape(lo)
    cum = arc(pts)
    # Even spacing along the curve (a pile that is still too short spreads in the dynamics).
    target = s_node * cum[-1]
    return np.stack([np.interp(target, cum, pts[:, i]) for i in range(3)], axis=1)
