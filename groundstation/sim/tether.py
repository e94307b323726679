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
        self._const_for_m = math.nan
        self._const = (0.0, 0.0, 0.0, 0.0)
        (X, Y, Z), (VX, VY, VZ) = self.x_world_m.T.tolist(), self.v_world_mps.T.tolist()
        self.force_on_drone_world_n = np.array(self._forces(X, Y, Z, VX, VY, VZ)[3])

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

        The sub-steps run on Python floats, node by node (numpy's per-call cost on 11 × 3
        arrays was most of a step); ``tests/test_sim_tether_floats.py`` keeps the numpy step
        they replaced and checks both give the same floats.

        Returns:
            (3,) force of the tether on the drone at the end of the step, world frame, N.
        """
        n_sub = self.substeps(dt_s)
        h = dt_s / n_sub
        end_x, end_y, end_z = np.asarray(drone_world_m, dtype=float).tolist()
        self.v_world_mps[-1] = drone_velocity_world_mps
        self.v_world_mps[0] = 0.0
        # The columns of the nodes' positions (m) and velocities (m/s), as floats.
        (X, Y, Z), (VX, VY, VZ) = self.x_world_m.T.tolist(), self.v_world_mps.T.tolist()
        last = len(X) - 1
        # (end - start) / n_sub, per axis.
        sx, sy, sz = (end_x - X[last]) / n_sub, (end_y - Y[last]) / n_sub, (end_z - Z[last]) / n_sub
        h_per_m = h / self.node_mass_kg
        length0 = self.length_m
        reel_m = 0.0 if length_m is None else (float(length_m) - length0) / n_sub
        on_drone = (0.0, 0.0, 0.0)
        for i in range(n_sub):
            if reel_m != 0.0:
                self.set_length(length0 + reel_m * (i + 1))
                h_per_m = h / self.node_mass_kg
            X[last] += sx
            Y[last] += sy
            Z[last] += sz
            FX, FY, FZ, on_drone = self._forces(X, Y, Z, VX, VY, VZ)
            # semi-implicit Euler: v += F/m·h, then x += v·h (interior nodes only)
            for j in range(1, last):
                vx = VX[j] = VX[j] + FX[j] * h_per_m
                vy = VY[j] = VY[j] + FY[j] * h_per_m
                vz = VZ[j] = VZ[j] + FZ[j] * h_per_m
                X[j] += vx * h
                Y[j] += vy * h
                Z[j] += vz * h
        X[last], Y[last], Z[last] = end_x, end_y, end_z
        self.x_world_m[:] = np.array((X, Y, Z)).T
        self.v_world_mps[:] = np.array((VX, VY, VZ)).T
        self.force_on_drone_world_n = np.array(on_drone)
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

    def _forces(
        self,
        X: list[float],
        Y: list[float],
        Z: list[float],
        VX: list[float],
        VY: list[float],
        VZ: list[float],
    ) -> tuple[list[float], list[float], list[float], tuple[float, float, float]]:
        """Node forces (three columns of N + 1) of a state, and the force on the drone, N.

        The operations of the numpy form they replaced, in its order (a dot product of
        3-vectors as numpy's ``einsum`` sums it on x86-64: (x·x' + z·z') + y·y').

        Args:
            X, Y, Z: the nodes' world coordinates, base first, m (short names: the columns
                of ``x_world_m``, read in every line of the loops below).
            VX, VY, VZ: their velocities, world, m/s (the columns of ``v_world_mps``).

        Returns:
            ``(FX, FY, FZ, force on the drone)``: per node, world, N.
        """
        p = self.params
        l0, m, k, c_axial = self._constants()
        weight = m * GRAVITY_MPS2
        drag = -(p.air_damping_n_s_per_m2 * l0)
        # gravity and the effective drag
        FX = [vx * drag for vx in VX]
        FY = [vy * drag for vy in VY]
        FZ = [vz * drag - weight for vz in VZ]
        n = len(X) - 1
        PX, PY, PZ = [0.0] * n, [0.0] * n, [0.0] * n
        for i in range(n):
            dx, dy, dz = X[i + 1] - X[i], Y[i + 1] - Y[i], Z[i + 1] - Z[i]
            length = math.sqrt((dx * dx + dz * dz) + dy * dy)
            den = max(length, 1e-12)
            ux, uy, uz = dx / den, dy / den, dz / den
            rate = (ux * (VX[i + 1] - VX[i]) + uz * (VZ[i + 1] - VZ[i])) + uy * (VY[i + 1] - VY[i])
            # t = EA·strain + c·dl/dt while stretched; a slack segment carries nothing. The
            # damper acts in full while stretched (clipping it at zero feeds a slack-taut
            # chatter).
            tension = (k * (length - l0) + c_axial * rate) * (1.0 if length > l0 else 0.0)
            PX[i], PY[i], PZ[i] = tension * ux, tension * uy, tension * uz
        # Each segment pulls its two ends together: first every start node, then every end.
        for i in range(n):
            FX[i] += PX[i]
            FY[i] += PY[i]
            FZ[i] += PZ[i]
        for i in range(n):
            FX[i + 1] -= PX[i]
            FY[i + 1] -= PY[i]
            FZ[i + 1] -= PZ[i]
        floor = self.floor_z_m
        if min(Z) < floor:
            stiff = p.floor_stiffness_n_per_m
            c_floor = 2.0 * math.sqrt(stiff * m)
            friction, slip2 = p.floor_friction, p.friction_speed_mps**2
            for j, z in enumerate(Z):
                pen = max(floor - z, 0.0)
                normal = max(stiff * pen - c_floor * VZ[j], 0.0) * (1.0 if pen > 0.0 else 0.0)
                FZ[j] += normal
                vx, vy = VX[j], VY[j]
                g = friction * normal / math.sqrt((vx * vx + vy * vy) + slip2)
                FX[j] -= g * vx
                FY[j] -= g * vy
        # On the drone: the last segment's pull toward the previous node, and the weight of
        # the half segment that hangs at the drone's end.
        return FX, FY, FZ, (-PX[-1], -PY[-1], -PZ[-1] - 0.5 * m * GRAVITY_MPS2)

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
