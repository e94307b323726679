"""The ideal simulator's drone step on Python floats is the numpy step it replaced, to the bit.

``groundstation/sim/ideal.py`` writes :meth:`DroneSim.step` on floats (numpy's per-call cost on
3-vectors was most of a simulated step). :class:`NumpyDroneSim` below is the numpy version it
replaced (commit 557a840), kept as the reference: a simulator flown with either publishes the
same bytes, every message, over scenarios that take off, hover, tug, land on the floor, go taut
and hang a coin.
"""

from __future__ import annotations

import hashlib
import json
import math

import numpy as np
import pytest

from groundstation.catenary import TetherTooShortError, tether_force
from groundstation.cli import DEMO_DEFAULTS
from groundstation.config import load_settings
from groundstation.sim import Simulator, ideal
from groundstation.sim.ideal import GRAVITY_MPS2, DroneSim
from groundstation.sim.rotation import quat_wxyz_from_z_axis, rotation_world_body_wxyz

_G_WORLD = np.array([0.0, 0.0, -GRAVITY_MPS2])
_E3 = np.array([0.0, 0.0, 1.0])


class NumpyDroneSim(DroneSim):
    """The drone step on numpy 3-vectors, as it was before it was written on floats."""

    def tether_at(self, position_world_m: np.ndarray) -> np.ndarray:
        return self._tether(np.asarray(position_world_m, dtype=float))[0]

    def _tether(self, position_world_m: np.ndarray) -> tuple[np.ndarray, bool, bool]:  # type: ignore[override]
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

    def _taut_force(self, chord: np.ndarray) -> np.ndarray:  # type: ignore[override]
        n = float(np.linalg.norm(chord))
        return -chord / n * self.tension_cap_n if n > 0 else np.zeros(3)

    def _control(self, dt_s: float) -> tuple[float, np.ndarray]:  # type: ignore[override]
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


class _Bus:
    def publish(self, key: str, payload: bytes) -> None:
        pass


def _digest(scenario: str, seconds: float, drone_cls: type[DroneSim]) -> str:
    """SHA-256 of every message the demo's simulator publishes, its drones of ``drone_cls``."""
    data = json.loads(json.dumps(DEMO_DEFAULTS))
    data.pop("zenoh")
    data.pop("web")
    settings = load_settings(None, data, use_env=False)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(ideal, "DroneSim", drone_cls)  # the runner imports it when it builds one
        sim = Simulator(settings, _Bus(), scenario=scenario)  # type: ignore[arg-type]
    assert all(type(d) is drone_cls for d in sim.drones.values())
    h = hashlib.sha256()
    for _ in range(round(seconds / sim.dt_s)):
        for sample in sim.step():
            h.update(sample.key.encode())
            h.update(sample.payload)
    return h.hexdigest()


@pytest.mark.parametrize(
    ("scenario", "seconds"),
    [("takeoff_ramp", 8.0), ("tug_landing", 12.0), ("coin", 3.0), ("reel_in", 6.0)],
)
def test_the_float_step_publishes_what_the_numpy_step_did(scenario: str, seconds: float) -> None:
    assert _digest(scenario, seconds, DroneSim) == _digest(scenario, seconds, NumpyDroneSim)


def test_a_different_step_changes_the_digest() -> None:
    """The comparison can fail: a reference whose gain is 1e-12 larger publishes other bytes."""

    class Nudged(NumpyDroneSim):
        def _control(self, dt_s: float) -> tuple[float, np.ndarray]:  # type: ignore[override]
            self.kp_per_s2 = 16.0 + 1e-12
            return super()._control(dt_s)

    assert _digest("takeoff_ramp", 6.0, DroneSim) != _digest("takeoff_ramp", 6.0, Nudged)


def _pair(**kw: object) -> tuple[DroneSim, DroneSim]:
    def make(cls: type[DroneSim]) -> DroneSim:
        return cls(
            base_world_m=np.array([0.0, 0.0, 0.0]),
            length_m=1.0,
            weight_n_per_m=0.002,
            floor_z_m=0.0,
            position_world_m=np.array([0.2, 0.1, 0.5]),
            **kw,  # type: ignore[arg-type]
        )

    return make(DroneSim), make(NumpyDroneSim)


@pytest.mark.parametrize(
    ("target", "pull"),
    [
        ((3.0, 1.0, 1.5), (0.0, 0.0, 0.0)),  # beyond reach: taut stop, capped tension
        ((0.3, -0.2, 0.0), (0.01, 0.0, -0.05)),  # into the floor, pushed along it
        ((0.1, 0.4, 0.8), (0.0, 0.02, 0.0)),  # an ordinary flight with a side pull
    ],
)
def test_each_step_is_the_numpy_step_near_taut_and_on_the_floor(
    target: tuple[float, float, float], pull: tuple[float, float, float]
) -> None:
    floats, reference = _pair(target_world_m=np.array(target))
    seen_taut = seen_floor = False
    for _ in range(1500):
        floats.step(0.004, np.array(pull))
        reference.step(0.004, np.array(pull))
        for name in (
            "position_world_m",
            "velocity_world_mps",
            "integral_m_s",
            "quat_wxyz",
            "specific_force_body_mps2",
            "tension_world_n",
        ):
            assert getattr(floats, name).tolist() == getattr(reference, name).tolist(), name
        assert (floats.thrust_n, floats.taut, floats.floor_contact, floats.on_ground) == (
            reference.thrust_n,
            reference.taut,
            reference.floor_contact,
            reference.on_ground,
        )
        seen_taut |= floats.taut
        seen_floor |= floats.on_ground or floats.floor_contact
    if target[0] > 1.0:
        assert seen_taut, "the premise: the drone reached the end of its tether"
    if target[2] == 0.0:
        assert seen_floor, "the premise: the drone came down on the floor"
