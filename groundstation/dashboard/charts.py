"""The 20 s charts of the selected drone (uPlot through viser): tension, and position estimate
against motion capture.

Two position charts, one with and one without the motion-capture series, of which one is
visible: changing a live uPlot chart's series (as switching from a drone with motion capture
to one without once did) left it drawing dots at t = 0 on a 0–1 axis until the page was
reloaded, so the series of a chart never change.
"""

from __future__ import annotations

import numpy as np
import viser
import viser.uplot

from groundstation.dashboard.model import (
    H_EX,
    H_EZ,
    H_MX,
    H_MZ,
    H_T,
    H_THR,
    H_TX,
    HISTORY_S,
    DroneState,
    fill_gaps,
)

__all__ = ["Charts", "position_series", "tension_series"]

_AXIS_COLORS = ("#e03131", "#2f9e44", "#1c7ed6")


def tension_series() -> tuple[viser.uplot.Series, ...]:
    """t, Tx, Ty, Tz, |T| and the follow threshold."""
    return (
        {"label": "t (s)"},
        {"label": "Tx", "stroke": "#e03131", "width": 1.2},
        {"label": "Ty", "stroke": "#2f9e44", "width": 1.2},
        {"label": "Tz", "stroke": "#1c7ed6", "width": 1.2},
        {"label": "|T|", "stroke": "#212529", "width": 2.0},
        # Follow compares the threshold with the pull beyond the tether's own tension, not
        # with |T|: the line shows the setting, the panel's note says what it is compared to.
        {"label": "threshold (pull)", "stroke": "#f08c00", "width": 1.5, "dash": (6.0, 4.0)},
    )


def position_series(mocap: bool) -> tuple[viser.uplot.Series, ...]:
    """t and x, y, z of the estimate, then (with ``mocap``) x, y, z of motion capture."""
    series: list[viser.uplot.Series] = [{"label": "t (s)"}]
    for axis, color in zip("xyz", _AXIS_COLORS, strict=True):
        series.append({"label": f"{axis} est", "stroke": color, "width": 1.5})
    if mocap:
        for axis, color in zip("xyz", _AXIS_COLORS, strict=True):
            series.append(
                {"label": f"{axis} mocap", "stroke": color, "width": 1.0, "dash": (3.0, 3.0)}
            )
    return tuple(series)


class Charts:
    """The charts of one panel, in ``gui`` (inside the caller's folder)."""

    def __init__(self, gui: viser.GuiApi) -> None:
        x0 = np.array([-HISTORY_S, 0.0])
        zeros = np.zeros(2)
        scales: dict[str, viser.uplot.Scale] = {"x": {"time": False}}
        self.tension = gui.add_uplot(
            (x0, *[zeros] * 5),
            tension_series(),
            title="Tension (N)",
            scales=scales,
            height=170,
        )
        self.position_mocap = gui.add_uplot(
            (x0, *[zeros] * 6),
            position_series(mocap=True),
            title="Position (m): estimate vs motion capture",
            scales=scales,
            height=170,
            visible=False,
        )
        self.position = gui.add_uplot(
            (x0, *[zeros] * 3),
            position_series(mocap=False),
            title="Position (m): estimate (no motion capture)",
            scales=scales,
            height=170,
        )

    def update(self, drone: DroneState, now_s: float) -> None:
        """Push the last :data:`HISTORY_S` of ``drone`` (time relative to now, seconds)."""
        rows = drone.history.window(now_s - HISTORY_S)
        if len(rows) < 2:
            return
        t = rows[:, H_T] - now_s
        self.tension.data = (t, *(fill_gaps(rows[:, c])[0] for c in range(H_TX, H_THR + 1)))
        est = [fill_gaps(rows[:, c])[0] for c in range(H_EX, H_EZ + 1)]
        mocap = [fill_gaps(rows[:, c]) for c in range(H_MX, H_MZ + 1)]
        has_mocap = all(ok for _, ok in mocap)
        shown, hidden = (
            (self.position_mocap, self.position)
            if has_mocap
            else (self.position, self.position_mocap)
        )
        # Data first, then visibility: a chart shown again starts from this drone's window.
        if has_mocap:
            shown.data = (t, *est, *(col for col, _ in mocap))
        else:
            shown.data = (t, *est)
        if not shown.visible:
            shown.visible = True
            hidden.visible = False
