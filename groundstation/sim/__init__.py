"""Simulator of tethered drones that speaks the public contract (an edge: bus only).

- :mod:`~groundstation.sim.scenarios`: the paper's scripted flights (data).
- :mod:`~groundstation.sim.rotation`: the simulator's own attitude math.
- :mod:`~groundstation.sim.ideal`: the ``ideal`` profile's drone (quasi-static catenary,
  white noise: the estimator's assumptions).
- :mod:`~groundstation.sim.realistic`: the ``realistic`` profile's drone, built from
  :mod:`~groundstation.sim.drone` (rigid body, motors, controller),
  :mod:`~groundstation.sim.tether` (lumped-mass tether) and :mod:`~groundstation.sim.sensors`
  (error models); it does not use :mod:`groundstation.catenary`.
- :mod:`~groundstation.sim.runner`: :class:`Simulator`, scenarios on a bus in scaled real time,
  or in lock-step (:meth:`Simulator.step`; see the runner's docstring). docs/simulator.md.

The simulator imports none of ``tension``, ``localization``, ``pipeline`` or ``follow``
(tests/test_sim.py asserts it), so that a test against it checks the estimator instead of
repeating it.
"""

from typing import TYPE_CHECKING, Any

from groundstation.sim.rotation import quat_wxyz_from_z_axis, rotation_world_body_wxyz
from groundstation.sim.runner import Simulator
from groundstation.sim.scenarios import (
    PAPER_BASE_M,
    PAPER_HOVER_SPOTS_M,
    SCENARIOS,
    Pull,
    Scenario,
    Waypoint,
    scenario_names,
)

__all__ = [
    "GRAVITY_MPS2",
    "PAPER_BASE_M",
    "PAPER_HOVER_SPOTS_M",
    "SCENARIOS",
    "DroneSim",
    "Pull",
    "Scenario",
    "Simulator",
    "Waypoint",
    "quat_wxyz_from_z_axis",
    "rotation_world_body_wxyz",
    "scenario_names",
]

if TYPE_CHECKING:
    from groundstation.sim.ideal import GRAVITY_MPS2, DroneSim


def __getattr__(name: str) -> Any:
    # The ideal drone imports groundstation.catenary; load it only when asked for, so the
    # realistic profile runs without the catenary code (tests/test_sim_realistic.py).
    if name in ("DroneSim", "GRAVITY_MPS2"):
        from groundstation.sim import ideal

        return getattr(ideal, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
