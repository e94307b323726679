"""The operator's 3D web dashboard (viser): an edge that talks to the service over the bus only.

Parts, in the order data flows through them:

- :mod:`.model`: per-drone state, parsed from the bus with the contract's models;
- :mod:`.scene`: the 3D scene shared by every tab (drones, tethers, arrows, labels, axes);
- :mod:`.panel`: the operator's controls per tab (selection, stop, follow, parameters),
  with :mod:`.readouts` (HTML) and :mod:`.charts` (uPlot);
- :mod:`.commands`: what the panel publishes and the checks a follow setting passes;
- :mod:`.app`: wiring, bus client, threads, lifecycle.
"""

from groundstation.dashboard.app import Dashboard, DashboardStats
from groundstation.dashboard.commands import (
    FollowLimits,
    follow_command,
    params_command,
    stop_command,
)
from groundstation.dashboard.panel import Panel

__all__ = [
    "Dashboard",
    "DashboardStats",
    "FollowLimits",
    "Panel",
    "follow_command",
    "params_command",
    "stop_command",
]
