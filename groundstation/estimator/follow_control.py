"""Follow stage: when follow runs, what position it may fly to, and the operator's commands.

Control around :func:`groundstation.follow.follow_step` (the state machine of tension
following and tug-to-land, ``eq:follow_*``):

- Follow off and idle: nothing but the stamp moves (:func:`follow_stamped`).
- The position follow flies to is the motion-capture position while fresh (an external
  position), else the tether-based one; a drone with neither motion capture nor a
  calibration has no position follow may use (uncalibrated, the tether-based position is
  off by up to ~1 m): no setpoint, no Stop, landing not armed, and the state says why
  (:data:`UNTRUSTED_POSITION_REASON`).
- Operator commands (FollowCommand) are checked (:func:`refuse_command`) before they are
  applied (:func:`apply_command`).

Pure functions of frozen states (FollowState, FollowParams) and plain inputs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from groundstation import follow as follow_mod
from groundstation.frozen import evolve
from groundstation.localization import PositionEstimate
from groundstation.messages import FollowCommand

__all__ = [
    "UNTRUSTED_POSITION_REASON",
    "FollowCommandState",
    "apply_command",
    "follow_decide",
    "follow_stamped",
    "refuse_command",
]

UNTRUSTED_POSITION_REASON = (
    "no motion capture and no calibration: the tether-based position of an uncalibrated "
    "drone is off by up to ~1 m, so it is not followed"
)
"""The follow ``reason`` while following is held off for want of a position it may fly to."""

Vec3 = tuple[float, float, float]


def follow_stamped(state: follow_mod.FollowState, stamp_s: float) -> follow_mod.FollowState:
    """``dataclasses.replace(state, last_stamp_s=stamp_s)`` in a fifth of its time
    (:func:`frozen.evolve`): the per-message step while follow is off."""
    return evolve(state, last_stamp_s=stamp_s)


def follow_decide(
    state: follow_mod.FollowState,
    params: follow_mod.FollowParams,
    *,
    stamp_s: float,
    tension_world_n: Sequence[float],
    converged: bool,
    position: PositionEstimate | None,
    mocap_world_m: Vec3 | None,
    trusted_without_mocap: bool,
    base_world_m: np.ndarray,
    length_m: float,
    floor_z_m: float,
    weight_n_per_m: float,
    on_ground: bool,
) -> tuple[follow_mod.FollowState, follow_mod.FollowDecision | None]:
    """One message's follow step (module doc).

    Args:
        state, params: follow's state and settings.
        stamp_s: the message's stamp, s.
        tension_world_n, converged: the filter's output.
        position: the tether-based position (None: not determined).
        mocap_world_m: the motion-capture position held for this message (None: none).
        trusted_without_mocap: a calibration is in force, so the tether-based position
            may be flown to.
        base_world_m, length_m, floor_z_m, weight_n_per_m: the tether and the floor.
        on_ground: the contact stage's decision.

    Returns:
        ``(next state, decision)``; the decision is None while follow is off and idle.
    """
    if not (state.enabled or state.active) and math.isfinite(stamp_s):
        return follow_stamped(state, stamp_s), None
    follow_position = (
        mocap_world_m
        if mocap_world_m is not None
        else (position.position_world_m if position is not None else None)
    )
    untrusted = mocap_world_m is None and not trusted_without_mocap
    decision = follow_mod.follow_step(
        state,
        params,
        stamp_s=stamp_s,
        tension_norm_n=_norm3(tension_world_n) if converged else None,
        # Uncalibrated and without motion capture there is no position to fly to
        # (follow's rule 3: no setpoint, no Stop, landing not armed).
        position_world_m=None if untrusted else follow_position,
        base_world_m=base_world_m,
        length_m=length_m,
        floor_z_m=floor_z_m,
        tension_world_n=tension_world_n if converged else None,
        position_is_external=mocap_world_m is not None,
        weight_n_per_m=weight_n_per_m,
        on_ground=on_ground,
    )
    if untrusted and decision.state.enabled and not decision.state.stopped:
        decision = replace(
            decision, state=replace(decision.state, reason=UNTRUSTED_POSITION_REASON)
        )
    return decision.state, decision


def _norm3(v: Sequence[float]) -> float:
    """``float(np.linalg.norm(v))`` of 3 floats: sqrt of the dot in numpy's order."""
    return math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


@dataclass(frozen=True, slots=True)
class FollowCommandState:
    """What an operator's FollowCommand changes: follow's settings and state, and the
    tug-to-land height remembered while landing is off (restored when switched back on)."""

    params: follow_mod.FollowParams
    state: follow_mod.FollowState
    land_below_m_memory: float | None


def apply_command(current: FollowCommandState, cmd: FollowCommand) -> FollowCommandState:
    """A FollowCommand applied (after :func:`refuse_command` found nothing against it)."""
    fp = current.params
    memory = current.land_below_m_memory
    if cmd.threshold_n is not None:
        fp = replace(fp, threshold_n=cmd.threshold_n)
    if cmd.land_below_m is not None:
        fp = replace(fp, land_below_m=cmd.land_below_m)
    if fp.land_below_m is not None:
        memory = fp.land_below_m
    if cmd.land is False:
        fp = replace(fp, land_below_m=None)
    elif cmd.land is True and fp.land_below_m is None:
        fp = replace(fp, land_below_m=memory)
    return FollowCommandState(fp, follow_mod.set_enabled(current.state, cmd.enabled), memory)


def refuse_command(
    cmd: FollowCommand,
    *,
    drone: str,
    threshold_min_n: float,
    floor_z_m: float,
    reach_top_m: float,
    last_seen_s: float | None,
    stale: bool,
    silent_s: float,
    trusted_position: bool | None,
) -> tuple[str, str] | None:
    """Why a FollowCommand must not be applied, as ``(field, reason)``, or None.

    Checked at the command boundary, before :func:`follow.set_enabled`:

    - a threshold below ``[service] follow_threshold_min_n``;
    - a tug-to-land height ``land_below_m`` at or below the floor (``[base] floor_z_m``:
      tug-to-land would never stop the motors) or at or above base + tether length (out of
      reach: the first tug would stop them at any height);
    - enabling follow on a drone that is stale or has never sent telemetry (a stale drone
      drops follow and the operator enables it again; an unknown drone is the most stale
      of all, and would otherwise fly off in follow mode the moment it starts);
    - enabling follow on a drone with no motion capture (none held for its last message)
      while no calibration is in force: follow would fly it to its tether-based position,
      which uncalibrated is off by up to a metre (on the realistic simulator a tug-to-land
      Stop came at 0.9 m instead of 0.25 m; docs/realistic_benchmark.md). The same
      condition while following holds the goal (:func:`follow_decide`).

    That a threshold is not below the tether's own pull is :mod:`groundstation.follow`'s
    business: the threshold applies to the pull beyond the tether's own tension there.

    Args:
        trusted_position: whether the drone's last message had a position follow may fly
            to (None: no message yet).
    """
    if cmd.threshold_n is not None and cmd.threshold_n < threshold_min_n:
        return "threshold_n", (
            f"threshold_n {cmd.threshold_n:g} N is below the service's floor "
            f"{threshold_min_n:g} N ([service] follow_threshold_min_n): that low a threshold "
            "follows the sensor noise and any error in the tether's own tension; not applied"
        )
    if cmd.land_below_m is not None and not floor_z_m < cmd.land_below_m < reach_top_m:
        return "land_below_m", (
            f"land_below_m {cmd.land_below_m:g} m is outside the tether's reach: it must lie "
            f"above the floor ({floor_z_m:g} m, [base] floor_z_m) and below base + tether "
            f"({reach_top_m:.3f} m); not applied"
        )
    if not cmd.enabled:
        return None
    if last_seen_s is None:
        return "enabled", (
            f"{drone} has sent no telemetry: follow stays off (enable it once the drone is "
            "flying); not applied"
        )
    if stale:
        return "enabled", (
            f"{drone} is stale (silent for {silent_s:.1f} s): follow stays off until it is "
            "heard again; not applied"
        )
    if trusted_position is False:
        return "enabled", (
            f"{drone} has no motion capture (position_m) and no calibration ([calibration] "
            "source = none): following and tug-to-land would fly it to its tether-based "
            "position, which uncalibrated is off by up to ~1 m (a tug-to-land Stop at 0.9 m "
            "instead of 0.25 m, docs/realistic_benchmark.md); calibrate it (groundstation "
            "calibrate, docs/calibration.md) or send position_m; not applied"
        )
    return None
