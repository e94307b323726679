"""The paper's scenarios, scripted for the simulator (pure data, no physics)."""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = [
    "PAPER_BASE_M",
    "PAPER_HOVER_SPOTS_M",
    "SCENARIOS",
    "Pull",
    "Scenario",
    "Waypoint",
    "scenario_names",
]

PAPER_BASE_M: tuple[float, float, float] = (0.0, 0.0, 0.754)
"""The paper's base exit point, world frame, m: the scenarios' positions are written for it
and each drone flies them shifted by its own base's displacement from it."""

PAPER_HOVER_SPOTS_M: tuple[tuple[float, float, float], ...] = (
    (1.2, 0.0, 1.0),
    (1.0, -0.3, 1.0),
    (1.0, 0.0, 1.2),
    (1.0, -0.3, 0.5),
    (0.5, -0.6, 1.0),
    (0.9, 0.6, 1.0),
)
"""The paper's hovering flights (NOTES.md), world frame, base at (0, 0, 0.754)."""


@dataclass(frozen=True)
class Pull:
    """An external force on the drone over ``[start_s, end_s)``: a hand pulling the tether."""

    start_s: float
    end_s: float
    force_world_n: tuple[float, float, float]


@dataclass(frozen=True)
class Waypoint:
    """From ``at_s`` on, the controller's target is ``position_m``."""

    at_s: float
    position_m: tuple[float, float, float]


@dataclass(frozen=True)
class Scenario:
    """A scripted flight.

    Attributes:
        name: scenario name.
        description: one line for ``groundstation sim --list``.
        start_m: initial drone position (on the floor when ``start_on_ground``). Every
            position here is for a base at :data:`PAPER_BASE_M` (or at ``base_m``); the
            simulator shifts them with each drone's base.
        waypoints: controller targets over time (the service's Setpoints override them).
        pulls: external pulls (tugs).
        base_m: base exit point for the default base (shifted like the positions), or None
            for the drone's configured base.
        length_m: tether length at t = 0, or None for the configured one.
        reel_rate_mps: reel speed (negative reels in) over ``reel_window_s``.
        arm_at_s: arming time (before it the drone sits disarmed on the floor).
        coin_mass_kg: the paper's horizontal-tension bench: a thread over an arm at
            ``coin_arm_m`` with this mass hanging replaces the tether.
        operator: scripted FollowCommands ``(at_s, payload)``, published by the simulator
            as an operator would.
        duration_s: natural length of the scenario (None: run until stopped).
        thrust_ramp_s: after arming, the thrust ramps linearly from 0 to the drone's weight
            over this time, level, before the position controller takes over (a real
            spool-up on the floor); 0 switches the controller on at once.
    """

    name: str
    description: str
    start_m: tuple[float, float, float]
    waypoints: tuple[Waypoint, ...] = ()
    pulls: tuple[Pull, ...] = ()
    base_m: tuple[float, float, float] | None = None
    length_m: float | None = None
    reel_rate_mps: float = 0.0
    reel_window_s: tuple[float, float] = (0.0, 0.0)
    start_on_ground: bool = False
    arm_at_s: float = 0.0
    coin_mass_kg: float | None = None
    coin_arm_m: tuple[float, float, float] = (0.3, 0.0, 1.0)
    operator: tuple[tuple[float, dict[str, object]], ...] = ()
    duration_s: float | None = None
    thrust_ramp_s: float = 0.0


def _climb(
    start_m: tuple[float, float, float],
    goal_m: tuple[float, float, float],
    at_s: float,
    speed_mps: float,
    step_s: float = 0.2,
) -> tuple[Waypoint, ...]:
    """Waypoints from ``start_m`` to ``goal_m`` at ``speed_mps`` from ``at_s`` (a gentle climb)."""
    dist = sum((g - s) ** 2 for s, g in zip(start_m, goal_m, strict=True)) ** 0.5
    n = max(1, math.ceil(dist / (speed_mps * step_s)))
    return tuple(
        Waypoint(
            at_s + k * step_s,
            (
                start_m[0] + (goal_m[0] - start_m[0]) * k / n,
                start_m[1] + (goal_m[1] - start_m[1]) * k / n,
                start_m[2] + (goal_m[2] - start_m[2]) * k / n,
            ),
        )
        for k in range(n + 1)
    )


def _calibration_flight(
    floor_m: tuple[float, float, float],
    arm_at_s: float,
    ramp_s: float,
    speed_mps: float,
    dwell_s: float,
) -> tuple[tuple[Waypoint, ...], float]:
    """The calibration protocol's waypoints, and when the flight ends.

    On the floor at ``floor_m`` until ``arm_at_s + ramp_s``; then up to the first of the
    paper's hover spots and through all six at ``speed_mps``, ``dwell_s`` at each: hovers for
    the tethered fit, legs in between for the rotor drag of the untethered one.
    """
    waypoints = [Waypoint(0.0, floor_m)]
    at_s, here = arm_at_s + ramp_s, floor_m
    for spot in PAPER_HOVER_SPOTS_M:
        leg = _climb(here, spot, at_s, speed_mps)
        waypoints.extend(leg)
        at_s, here = leg[-1].at_s + dwell_s, spot
    return tuple(waypoints), at_s


_CALIBRATION_WAYPOINTS, _CALIBRATION_END_S = _calibration_flight(
    (0.5, 0.0, 0.0), arm_at_s=3.0, ramp_s=1.0, speed_mps=0.5, dwell_s=4.0
)


def _spots_tour(dwell_s: float) -> tuple[Waypoint, ...]:
    return tuple(Waypoint(i * dwell_s, spot) for i, spot in enumerate(PAPER_HOVER_SPOTS_M))


SCENARIOS: dict[str, Scenario] = {
    s.name: s
    for s in (
        Scenario(
            "hover",
            "hover at the paper's first spot (1.2, 0, 1) m",
            start_m=PAPER_HOVER_SPOTS_M[0],
            waypoints=(Waypoint(0.0, PAPER_HOVER_SPOTS_M[0]),),
        ),
        Scenario(
            "hover_spots",
            "visit the paper's six hover spots, 15 s each, then repeat",
            start_m=PAPER_HOVER_SPOTS_M[0],
            waypoints=_spots_tour(15.0),
            duration_s=90.0,
        ),
        Scenario(
            "takeoff_0.3",
            "vertical take-off to 0.3 m straight above a base on the floor",
            start_m=(0.0, 0.0, 0.0),
            waypoints=(Waypoint(0.0, (0.0, 0.0, 0.3)),),
            base_m=(0.0, 0.0, 0.0),
            start_on_ground=True,
            arm_at_s=2.0,
            duration_s=20.0,
        ),
        Scenario(
            "takeoff_1.3",
            "vertical take-off to 1.3 m straight above a base on the floor",
            start_m=(0.0, 0.0, 0.0),
            waypoints=(Waypoint(0.0, (0.0, 0.0, 1.3)),),
            base_m=(0.0, 0.0, 0.0),
            start_on_ground=True,
            arm_at_s=2.0,
            duration_s=20.0,
        ),
        Scenario(
            "takeoff_ramp",
            "disarmed on the floor at (0.5, 0, 0) m; armed at 2 s, thrust ramps 0 → weight over "
            "2 s on the floor, then climbs to (1, 0, 1) m",
            start_m=(0.5, 0.0, 0.0),
            waypoints=(
                Waypoint(0.0, (0.5, 0.0, 0.0)),
                *_climb((0.5, 0.0, 0.0), (1.0, 0.0, 1.0), at_s=4.0, speed_mps=0.5),
            ),
            start_on_ground=True,
            arm_at_s=2.0,
            thrust_ramp_s=2.0,
            duration_s=15.0,
        ),
        Scenario(
            "calibration",
            "calibration protocol: 3 s disarmed on the floor at (0.5, 0, 0) m, then the six "
            "spots at 0.5 m/s, 4 s each, 38 s (--untethered: for calibrate --untethered)",
            start_m=(0.5, 0.0, 0.0),
            waypoints=_CALIBRATION_WAYPOINTS,
            start_on_ground=True,
            arm_at_s=3.0,
            thrust_ramp_s=1.0,
            duration_s=_CALIBRATION_END_S,
        ),
        Scenario(
            "coin",
            "horizontal-tension bench: a 4.1 g coin on a thread over an arm at (0.3, 0, 1) m",
            start_m=(0.0, 0.0, 0.9),
            waypoints=(Waypoint(0.0, (0.0, 0.0, 0.9)),),
            coin_mass_kg=0.0041,
            duration_s=20.0,
        ),
        Scenario(
            "tug",
            "hover at (1, 0, 1) m; a 30 mN step pull toward the base at 10 s for 5 s",
            start_m=(1.0, 0.0, 1.0),
            waypoints=(Waypoint(0.0, (1.0, 0.0, 1.0)),),
            pulls=(Pull(10.0, 15.0, (-0.03, 0.0, 0.0)),),
            duration_s=20.0,
        ),
        Scenario(
            "follow",
            "tension following: the operator enables follow at 3 s, pulls at 6 s and 14 s",
            start_m=(1.0, 0.0, 1.0),
            waypoints=(Waypoint(0.0, (1.0, 0.0, 1.0)),),
            pulls=(
                Pull(6.0, 8.0, (-0.20, 0.05, 0.0)),
                Pull(14.0, 16.0, (0.0, -0.20, 0.0)),
            ),
            operator=((3.0, {"enabled": True, "threshold_n": 0.15}),),
            duration_s=22.0,
        ),
        Scenario(
            "tug_landing",
            "tug-to-land: follow with land_below_m 0.25 enabled at 3 s, pulled down at 6 s",
            start_m=(0.6, 0.0, 0.9),
            waypoints=(Waypoint(0.0, (0.6, 0.0, 0.9)),),
            pulls=(Pull(6.0, 12.0, (-0.05, 0.0, -0.22)),),
            operator=((3.0, {"enabled": True, "threshold_n": 0.15, "land_below_m": 0.25}),),
            duration_s=16.0,
        ),
        Scenario(
            "reel_in",
            "hover at (1, 0, 1) m; the reel pulls in 0.3 m between 8 s and 14 s",
            start_m=(1.0, 0.0, 1.0),
            waypoints=(Waypoint(0.0, (1.0, 0.0, 1.0)),),
            reel_rate_mps=-0.05,
            reel_window_s=(8.0, 14.0),
            duration_s=20.0,
        ),
    )
}


def scenario_names() -> list[str]:
    return sorted(SCENARIOS)
