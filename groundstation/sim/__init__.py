"""Simulator of tethered drones that speaks the public contract (an edge: bus only).

- :mod:`~groundstation.sim.scenarios`: the paper's scripted flights (data).
- :mod:`~groundstation.sim.rotation`: the simulator's own attitude math.
- :mod:`~groundstation.sim.ideal`: the ``ideal`` profile's drone (quasi-static catenary,
  white noise: the estimator's assumptions).
- :mod:`~groundstation.sim.runner`: :class:`Simulator`, scenarios on a bus in scaled real time.

The simulator imports none of ``tension``, ``localization``, ``pipeline`` or ``follow``
(tests/test_sim.py asserts it), so that a test against it checks the estimator instead of
repeating it.
"""

from groundstation.sim.ideal import GRAVITY_MPS2, DroneSim
from groundstation.sim.rotation import quat_wxyz_from_z_axis, rotation_world_body_wxyz
from groundstation.sim.runner import Simulator
from groundstation.sim.scenarios import (
    PAPER_HOVER_SPOTS_M,
    SCENARIOS,
    Pull,
    Scenario,
    Waypoint,
    scenario_names,
)

__all__ = [
    "GRAVITY_MPS2",
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
