"""Shipped examples fly: every shipped config × every scenario stays in reach.

Scenario positions are relative to each drone's base (PAPER_BASE_M), so a config that moves
a drone's base (config/sim.toml: cf2 at y = 3) flies the same flight about that base instead
of hanging at the end of its tether.
"""

from __future__ import annotations

import collections
import json
import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from groundstation.cli import DEMO_DEFAULTS
from groundstation.config import Settings, load_settings
from groundstation.sim import PAPER_BASE_M, SCENARIOS, Simulator

CONFIG_DIR = Path(__file__).resolve().parents[1] / "config"


def _shipped() -> list[tuple[str, dict[str, Any]]]:
    out: list[tuple[str, dict[str, Any]]] = [("demo (embedded)", DEMO_DEFAULTS)]
    for path in sorted(CONFIG_DIR.glob("*.toml")):
        data = tomllib.loads(path.read_text())
        if "sim" in data or "drones" in data:
            out.append((path.name, data))
    return out


SHIPPED = _shipped()


class _Bus:
    def publish(self, key: str, payload: bytes) -> None:
        pass


def _settings(data: dict[str, Any], **sim: Any) -> Settings:
    layered = {k: v for k, v in data.items() if k != "zenoh"}
    layered["sim"] = {**data.get("sim", {}), **sim}
    return load_settings(None, layered, use_env=False)


def test_sim_toml_is_among_the_shipped_configs() -> None:
    assert "sim.toml" in [name for name, _ in SHIPPED]


def _fly_and_check(
    settings: Settings, scenario: str, seconds: float, window_s: float = 0.0
) -> None:
    """Fly; assert each drone stays in reach and |T| (mean over ``window_s``) below its weight.

    ``window_s``: the realistic tether's nodes are picked up off the floor one by one, each
    with a snatch of a few milliseconds (≤ 0.5 N, < 1 mN·s: the lumped masses' artefact, a
    distributed tether feels ω/g·v² ≈ 3 mN); the check is on the 50 ms mean there.
    """
    sim = Simulator(settings, _Bus(), scenario=scenario)  # type: ignore[arg-type]
    assert len(sim.drones) >= 1
    weight_n = {d: settings.for_drone(d).drone.mass_kg * 9.81 for d in sim.drones}
    worst: dict[str, float] = {}
    recent: dict[str, collections.deque[tuple[float, float]]] = {}
    for _ in range(round(seconds / sim.dt_s)):
        for s in sim.step():
            if not s.key.endswith("/truth"):
                continue
            drone_id = s.key.split("/")[1]
            t = json.loads(s.payload)
            reach = math.dist(t["position_m"], t["base_m"])
            assert not t["taut"] and reach < t["length_m"], (drone_id, t["stamp_s"], reach)
            history = recent.setdefault(drone_id, collections.deque())
            history.append((t["stamp_s"], math.hypot(*t["tension_n"])))
            while history[0][0] < t["stamp_s"] - window_s:
                history.popleft()
            # The mean over the window, summed afresh (a running sum would drift).
            tension = math.fsum(v for _, v in history) / len(history)
            assert tension < weight_n[drone_id], (drone_id, t["stamp_s"], tension)
            worst[drone_id] = max(worst.get(drone_id, 0.0), tension)
    assert set(worst) == set(sim.drones)


@pytest.mark.parametrize("scenario", sorted(SCENARIOS))
@pytest.mark.parametrize(("name", "data"), SHIPPED, ids=[n for n, _ in SHIPPED])
def test_every_shipped_config_flies_every_scenario_in_reach(
    name: str, data: dict[str, Any], scenario: str
) -> None:
    settings = _settings(data, profile="ideal")
    duration = SCENARIOS[scenario].duration_s or 20.0
    _fly_and_check(settings, scenario, duration)


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["hover_spots", "follow", "takeoff_ramp"])
def test_sim_toml_flies_on_the_realistic_profile_too(scenario: str) -> None:
    data = dict(SHIPPED)["sim.toml"]
    settings = _settings(data, profile="realistic")
    duration = SCENARIOS[scenario].duration_s or 20.0
    _fly_and_check(settings, scenario, min(duration, 45.0), window_s=0.05)


def test_spots_are_relative_to_each_drones_base() -> None:
    settings = _settings(dict(SHIPPED)["sim.toml"], profile="ideal")
    sim = Simulator(settings, _Bus(), scenario="hover")  # type: ignore[arg-type]
    spot = np.array(SCENARIOS["hover"].start_m)
    for drone_id, drone in sim.drones.items():
        base = np.array(settings.for_drone(drone_id).base.position_m)
        np.testing.assert_allclose(drone.base_world_m, base)
        np.testing.assert_allclose(drone.position_world_m, spot + base - PAPER_BASE_M)
    # the default base flies the paper's spots unshifted (the results' numbers)
    default = Simulator(_settings({}), _Bus(), scenario="hover")  # type: ignore[arg-type]
    np.testing.assert_allclose(default.drones["cf1"].position_world_m, spot)
