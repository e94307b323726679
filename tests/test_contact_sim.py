"""The contact latch: the simulator ⇄ pipeline closed loop, no bus, no clock.

The demo's estimator latched "on the ground" in mid-air at the hover_spots scenario's jump to
its fourth spot (t = 45 s: the simulated controller cuts the thrust to 0.02 N at 1.2 m) and
never came back. These run the demo's own configuration (``DEMO_DEFAULTS``) and both
simulator profiles, faster than real time through :func:`groundstation.evaluation.closed_loop`.
"""

from __future__ import annotations

import bisect
import json
from collections.abc import Callable
from typing import Any

import pytest

from groundstation.cli import DEMO_DEFAULTS
from groundstation.config import Settings, load_settings
from groundstation.evaluation import ClosedLoop, Run, closed_loop


def _demo(**sim: Any) -> Settings:
    data = json.loads(json.dumps(DEMO_DEFAULTS))
    data.pop("zenoh")
    data.pop("web")
    data["sim"].update(sim)
    return load_settings(None, data, use_env=False)


def _truths(run: Run) -> Callable[[float], dict[str, Any]]:
    """The latest truth at or before a stamp (the realistic IMU's stamps jitter)."""
    stamps = sorted(run.truth)

    def at(stamp_s: float) -> dict[str, Any]:
        return run.truth[stamps[max(0, bisect.bisect_right(stamps, stamp_s) - 1)]]

    return at


START_S = 0.15
"""A service started with the drone in the air and no motion capture (yet: the realistic
profile's first frames come later) takes it for on the ground until the floor is seen to
carry nothing for ``floor_time_s`` (0.1 s): the initial guess, not a latch."""


def _check_airborne(run: Run, status: dict[str, Any] | None, seconds: float) -> None:
    assert run.estimates, "no estimates"
    assert run.estimates[-1]["stamp_s"] > seconds - 1.0
    truth = _truths(run)
    assert not any(truth(e["stamp_s"])["on_ground"] for e in run.estimates[::50]), (
        "the premise: the simulated drone never touches the floor"
    )
    grounded = [e["stamp_s"] for e in run.estimates if e["on_ground"] and e["stamp_s"] > START_S]
    assert not grounded, f"{len(grounded)} estimates on the ground, from {grounded[0]} s"
    assert status is not None and status["contact"]["on_ground"] is False, status
    # Not frozen: the position is determined at the end (the latch left it undetermined).
    assert run.estimates[-1].get("position_m") is not None, run.estimates[-1]


class _Tour:
    """One flight of the demo's hover_spots read at several times: :meth:`at` flies on to
    ``seconds`` (from where the flight is) and returns the run and the status as they were
    then. The lock-step loop is deterministic, so the first 75 s of the three-minute flight
    are the 75 s flight: the module flies it once for both tests."""

    def __init__(self, settings: Settings, checkpoints: tuple[float, ...]) -> None:
        self.loop = ClosedLoop(settings, "hover_spots")
        self.checkpoints = checkpoints
        self.seen: dict[float, tuple[Run, dict[str, Any] | None]] = {}

    def at(self, seconds: float) -> tuple[Run, dict[str, Any] | None]:
        assert seconds in self.checkpoints
        for s in self.checkpoints:
            if s > seconds:
                break
            if s not in self.seen:
                self.loop.run_to(s)
                run = self.loop.run
                snapshot = Run(estimates=list(run.estimates), truth=dict(run.truth))
                self.seen[s] = snapshot, self.loop.pipe.status("cf1", self.loop.sim.t_s)
        return self.seen[seconds]


@pytest.fixture(scope="module")
def demo_tour() -> _Tour:
    """The demo's own settings (motion capture on, its default)."""
    return _Tour(_demo(), (75.0, 185.0))


@pytest.mark.parametrize("mocap", [True, False])
def test_demo_hover_spots_past_the_fourth_spot_stays_airborne(
    mocap: bool, demo_tour: _Tour
) -> None:
    """The demo's scenario through its first dip (45 s) and two spots more: every estimate
    airborne, from the first (the drone starts in the air) to the last."""
    if mocap:  # the demo's default: the first 75 s of the module's three-minute flight
        run, status = demo_tour.at(75.0)
    else:
        run, pipe, sim = closed_loop(_demo(mocap=mocap), "hover_spots", 75.0)
        status = pipe.status("cf1", sim.t_s)
    dips = [e for e in run.estimates if 44.9 < e["stamp_s"] < 45.2]
    assert dips, "the premise: the dip is in the run"
    _check_airborne(run, status, 75.0)


@pytest.mark.slow
def test_demo_hover_spots_for_three_minutes(demo_tour: _Tour) -> None:
    """Two tours of the six spots and then some (its dips at 45 s and 135 s)."""
    run, status = demo_tour.at(185.0)
    _check_airborne(run, status, 185.0)


@pytest.mark.slow
@pytest.mark.parametrize("mocap", [True, False])
def test_realistic_profile_hover_spots_stays_airborne(mocap: bool) -> None:
    """The realistic profile (vibration, biases, motor lag: the thrust reads 0.06 N some
    10 ms before the drone starts to fall) through the same dip."""
    run, pipe, sim = closed_loop(_demo(profile="realistic", mocap=mocap), "hover_spots", 60.0)
    _check_airborne(run, pipe.status("cf1", sim.t_s), 60.0)


@pytest.mark.parametrize("profile", ["ideal", "realistic"])
@pytest.mark.parametrize("mocap", [True, False])
def test_take_off_from_the_floor_is_on_the_ground_until_it_lifts(profile: str, mocap: bool) -> None:
    """takeoff_ramp: disarmed on the floor for 2 s, 2 s of spool-up, then a climb. On the
    ground while the simulator's drone rests there, in the air within 5 cm of lifting."""
    settings = load_settings(None, {"sim": {"profile": profile, "mocap": mocap}}, use_env=False)
    run, _, _ = closed_loop(settings, "takeoff_ramp", 8.0)
    seen_air = False
    truth_at = _truths(run)
    for e in run.estimates:
        truth = truth_at(e["stamp_s"])
        z = truth["position_m"][2]
        if e["stamp_s"] < 3.5:
            assert e["on_ground"], (e["stamp_s"], truth)  # spooling up, far from hover
        if z > 0.05:
            assert not e["on_ground"], (e["stamp_s"], z)
            seen_air = True
    assert seen_air


@pytest.mark.parametrize("profile", ["ideal", "realistic"])
def test_tug_to_land_ends_on_the_ground(profile: str) -> None:
    """tug_landing: pulled down, the service stops the drone, which falls to the floor:
    the ground from the Stop (disarmed) to the end, airborne before."""
    settings = load_settings(None, {"sim": {"profile": profile}}, use_env=False)
    run, pipe, sim = closed_loop(settings, "tug_landing", 12.0)
    assert run.stops, "the premise: tug-to-land stops the drone"
    stop_s = run.stops[0]["stamp_s"]
    for e in run.estimates:
        if START_S < e["stamp_s"] < stop_s - 0.05:
            assert not e["on_ground"], e["stamp_s"]
        elif e["stamp_s"] > stop_s + 0.05:
            assert e["on_ground"], e["stamp_s"]
    assert _truths(run)(run.estimates[-1]["stamp_s"])["on_ground"]
    status = pipe.status("cf1", sim.t_s)
    assert status is not None and status["contact"] == {"on_ground": True, "reason": "disarmed"}
