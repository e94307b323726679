"""The simulator's base sensor ([sim] exit_angles): exit azimuth and elevation in Reel."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from groundstation.catenary import solve
from groundstation.config import load_settings
from groundstation.messages import Reel
from groundstation.sim import Simulator
from groundstation.sim.base_sensor import exit_direction_rad


def _reels(profile: str, exit_angles: bool, noise: float, steps: int = 300) -> list[dict]:
    settings = load_settings(
        None,
        {
            "sim": {
                "profile": profile,
                "exit_angles": exit_angles,
                "exit_azimuth_noise_rad": noise,
                "exit_elevation_noise_rad": noise,
            }
        },
        use_env=False,
    )
    sim = Simulator(settings, None, scenario="hover")  # type: ignore[arg-type]
    out = []
    for _ in range(steps):
        for sample in sim.step():
            if sample.key.endswith("/reel"):
                Reel.parse(sample.payload)  # valid against the contract's model
                out.append(json.loads(sample.payload))
    return out


def test_off_by_default() -> None:
    assert all("exit_azimuth_rad" not in r for r in _reels("ideal", False, 0.02, 30))


@pytest.mark.parametrize("profile", ["ideal", "realistic"])
def test_exit_angles_match_the_tether_at_the_base(profile: str) -> None:
    """The hover scenario at (1.2, 0, 1) m, base (0, 0, 0.754), L = 1.6 m: azimuth 0; the
    elevation is the catenary's slope at the base (from catenary.solve, independently of
    the sensor), within the realistic profile's 10-segment discretisation."""
    reels = _reels(profile, True, 0.0)
    assert reels
    cat = solve(0.0, 0.754, 1.2, 1.0, 1.6)
    slope = math.atan(math.sinh(-cat.x0 / cat.a))
    last = reels[-1]
    assert last["exit_azimuth_rad"] == pytest.approx(0.0, abs=0.02)
    tol = 0.005 if profile == "ideal" else 0.15
    assert last["exit_elevation_rad"] == pytest.approx(slope, abs=tol)


def test_noise_is_drawn_and_stated() -> None:
    reels = _reels("ideal", True, 0.05, 1000)
    az = np.array([r["exit_azimuth_rad"] for r in reels])
    stated = reels[0]["exit_azimuth_std_rad"]
    assert stated >= 0.05  # grows as 1 / cos(elevation)
    assert float(np.std(az)) == pytest.approx(stated, rel=0.5)


def test_exit_direction_of_a_vertical_segment() -> None:
    az, el = exit_direction_rad(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
    assert az == 0.0 and el == pytest.approx(math.pi / 2)
