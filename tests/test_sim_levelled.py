"""The simulator's ``attitude_levelled`` class: the reported attitude levelled on the same
misaligned, biased accelerometer, as a Crazyflie's estimators level it."""

from __future__ import annotations

import json

import numpy as np

from groundstation.config import load_settings
from groundstation.sim.rotation import rotation_world_body_wxyz
from groundstation.sim.runner import Simulator
from groundstation.sim.sensors import SensorParams, draw_errors


class _NullBus:
    def publish(self, key: str, payload: bytes) -> None:  # pragma: no cover - unused
        pass


def test_the_offset_takes_the_still_reading_for_up() -> None:
    for seed in range(5):
        e = draw_errors(SensorParams(), np.random.default_rng(seed), 4.0)
        a = e.level_reading_mps2()
        Q = rotation_world_body_wxyz(e.attitude_offset_wxyz())
        # reported = true ⊗ Q; level and still, "up" in the reported body frame is â
        assert np.allclose(Q.T @ np.array([0.0, 0.0, 1.0]), a / np.linalg.norm(a), atol=1e-12)
        eq = e.airframe_equivalent(True)
        plain = e.airframe_equivalent(False)
        assert plain["thrust_axis_rad"] == [-0.037, -0.016]
        # the axis seen in the levelled frame differs by the per-boot tilt (≤ ~3.5°)
        tilt = np.hypot(*np.subtract(eq["thrust_axis_rad"], plain["thrust_axis_rad"]))
        assert 0.0 < tilt < 0.07


def test_levelled_attitude_reads_gravity_along_the_reported_up_at_rest() -> None:
    """On the floor, disarmed: R_repᵀ·e3 is the accelerometer's own direction (the
    accelerometer and the attitude err together), unlike the true attitude's."""
    over = {
        "sim": {
            "profile": "realistic",
            "seed": 7,
            "scenario": "takeoff_ramp",
            "realistic": {"attitude_levelled": True, "vibration": False},
        }
    }
    sim = Simulator(load_settings(None, over, use_env=False), _NullBus(), scenario="takeoff_ramp")  # type: ignore[arg-type]
    acc, up_rep = [], []
    while sim.t_s < 1.5:  # disarmed until 2 s
        for s in sim.step():
            if s.key.endswith("/telemetry"):
                m = json.loads(s.payload)
                acc.append(m["accel_mps2"])
                R = rotation_world_body_wxyz(np.array(m["quat_wxyz"]))
                up_rep.append(R.T @ np.array([0.0, 0.0, 1.0]))
    a = np.mean(acc, axis=0)
    up = np.mean(up_rep, axis=0)
    assert np.allclose(up / np.linalg.norm(up), a / np.linalg.norm(a), atol=2e-3)
    errors = sim.drawn_errors("cf1")
    assert errors is not None and errors["classes"]["attitude_levelled"] is True
    assert "airframe_equivalent" in errors
