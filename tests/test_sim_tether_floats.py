"""The realistic profile's lumped tether, stepped on Python floats, is the numpy step it replaced.

``groundstation/sim/tether.py`` writes :meth:`LumpedTether.step` node by node on floats
(numpy's per-call cost on 11 × 3 arrays was most of a realistic simulation's time).
:class:`NumpyLumpedTether` below is the numpy version it replaced (commit e3cf038), kept as the
reference. Both are stepped through the same motions — hanging free, lying on the floor and
sliding on it, reeled in and out, pulled taut, kicked sideways — and must give the same
nodes, velocities and force on the drone: to the bit where this machine's ``einsum`` sums a
3-vector dot product in the order the float step writes out, else to a few ulps per step.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from groundstation.sim.tether import GRAVITY_MPS2, LumpedTether, TetherParams

BASE = np.array([0.0, 0.0, 0.1])
L_M = 1.6


class NumpyLumpedTether(LumpedTether):
    """The tether's step on numpy arrays, as it was before it was written on floats."""

    def step(
        self,
        dt_s: float,
        drone_world_m: np.ndarray,
        drone_velocity_world_mps: np.ndarray,
        length_m: float | None = None,
    ) -> np.ndarray:
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
            inner_v += force[1:-1] * h_per_m
            inner_x += inner_v * h
        self.x_world_m[-1] = end
        return self.force_on_drone_world_n.copy()

    def _update_forces(self) -> np.ndarray:
        p = self.params
        x, v = self.x_world_m, self.v_world_mps
        l0, m, k, c_axial = self._constants()
        d = x[1:] - x[:-1]
        length = np.sqrt(np.einsum("ij,ij->i", d, d))
        u = d / np.maximum(length, 1e-12)[:, None]
        rate = np.einsum("ij,ij->i", u, v[1:] - v[:-1])
        tension = (k * (length - l0) + c_axial * rate) * (length > l0)
        pull = tension[:, None] * u
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
        on_drone = -pull[-1]
        on_drone[2] -= 0.5 * m * GRAVITY_MPS2
        self.force_on_drone_world_n = on_drone
        return force


def _einsum_sums_as_written() -> bool:
    """Whether this numpy's ``einsum("ij,ij->i")`` on 3 columns is (a0·b0 + a2·b2) + a1·b1."""
    rng = np.random.default_rng(7)
    a = rng.normal(size=(500, 3)) * 10.0 ** rng.uniform(-6, 3, size=(500, 3))
    b = rng.normal(size=(500, 3)) * 10.0 ** rng.uniform(-6, 3, size=(500, 3))
    got = np.einsum("ij,ij->i", a, b).tolist()
    want = [
        (x[0] * y[0] + x[2] * y[2]) + x[1] * y[1]
        for x, y in zip(a.tolist(), b.tolist(), strict=True)
    ]
    return got == want


BITWISE = _einsum_sums_as_written()


def _motion(kind: str, t_s: float) -> tuple[np.ndarray, np.ndarray, float | None]:
    """The drone end's position, velocity and the reel's length at ``t_s``."""
    if kind == "hover":
        return np.array([1.2, 0.0, 1.0]), np.zeros(3), None
    if kind == "circle":  # swinging the tether round, 0.3 m at 0.5 Hz
        w = math.pi
        pos = np.array([1.0 + 0.3 * math.cos(w * t_s), 0.3 * math.sin(w * t_s), 0.9])
        vel = np.array([-0.3 * w * math.sin(w * t_s), 0.3 * w * math.cos(w * t_s), 0.0])
        return pos, vel, None
    if kind == "floor":  # low and sliding sideways: a run of tether lies on the floor
        pos = np.array([0.9, 0.2 * math.sin(2.0 * t_s), 0.25])
        return pos, np.array([0.0, 0.4 * math.cos(2.0 * t_s), 0.0]), None
    if kind == "reel":  # reeled in from 1.6 m to 1.2 m and out again
        length = L_M - 0.4 * math.sin(math.pi * t_s / 2.0) ** 2
        return np.array([0.8, 0.0, 0.8]), np.zeros(3), length
    if kind == "taut":  # climbing until the tether is stretched past its rest length
        z = 0.6 + 0.5 * t_s
        return np.array([1.0, 0.0, z]), np.array([0.0, 0.0, 0.5]), None
    raise ValueError(kind)


@pytest.mark.parametrize("kind", ["hover", "circle", "floor", "reel", "taut"])
def test_float_step_is_the_numpy_step(kind: str) -> None:
    pos0 = _motion(kind, 0.0)[0]
    ours = LumpedTether(TetherParams(), BASE, pos0, L_M, 0.0)
    ref = NumpyLumpedTether(TetherParams(), BASE, pos0, L_M, 0.0)
    assert ours.force_on_drone_world_n.tolist() == ref.force_on_drone_world_n.tolist()
    dt_s = 0.002
    saw_floor = saw_taut = False
    for i in range(1000):  # 2 s
        t_s = (i + 1) * dt_s
        pos, vel, length = _motion(kind, t_s)
        if kind == "circle" and i == 500:  # a sideways kick mid-way, both alike
            for t in (ours, ref):
                t.v_world_mps[3:6, 2] += 0.5
        if not BITWISE:
            # Another summation order: compare one step from the same state each time.
            ours.x_world_m[:] = ref.x_world_m
            ours.v_world_mps[:] = ref.v_world_mps
            ours.set_length(ref.length_m)
        f_ours = ours.step(dt_s, pos, vel, length)
        f_ref = ref.step(dt_s, pos, vel, length)
        saw_floor |= ref.floor_contact
        saw_taut |= ref.taut
        if BITWISE:
            assert f_ours.tolist() == f_ref.tolist(), (kind, i)
            assert ours.x_world_m.tolist() == ref.x_world_m.tolist(), (kind, i)
            assert ours.v_world_mps.tolist() == ref.v_world_mps.tolist(), (kind, i)
        else:
            np.testing.assert_allclose(f_ours, f_ref, rtol=1e-12, atol=1e-15)
            np.testing.assert_allclose(ours.x_world_m, ref.x_world_m, rtol=1e-13, atol=1e-15)
            np.testing.assert_allclose(ours.v_world_mps, ref.v_world_mps, rtol=1e-12, atol=1e-15)
        assert ours.length_m == ref.length_m
    # The motions exercise what they are named for.
    if kind == "floor":
        assert saw_floor
    if kind == "hover":
        assert not saw_floor
    if kind == "taut":
        assert saw_taut


def test_a_different_step_is_told_apart() -> None:
    """The comparison above can fail: a reference with 1 % more drag differs."""
    params = TetherParams()
    draggy = TetherParams(air_damping_n_s_per_m2=params.air_damping_n_s_per_m2 * 1.01)
    pos, vel, _ = _motion("circle", 0.0)
    ours = LumpedTether(params, BASE, pos, L_M, 0.0)
    ref = NumpyLumpedTether(draggy, BASE, pos, L_M, 0.0)
    for i in range(50):
        pos, vel, _ = _motion("circle", (i + 1) * 0.002)
        ours.step(0.002, pos, vel)
        ref.step(0.002, pos, vel)
    assert ours.x_world_m.tolist() != ref.x_world_m.tolist()
