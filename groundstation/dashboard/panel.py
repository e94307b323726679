"""The operator's panel: drone selector, emergency stop, follow controls, readouts, charts,
tether parameters and link health.

One :class:`Panel` per browser tab (built on ``client.gui``, so each tab has its own selected
drone), or one shared by every tab (``[web] panel = "shared"``, built on ``server.gui``).
Truth is the service: the follow checkbox and the settings show what the service reports, so
every tab sees a change made from anywhere; a click publishes a command and the input holds
the requested value for at most :data:`PENDING_HOLD_S` until the report catches up.

Follow inputs are checked where they are typed (:class:`~.commands.FollowLimits`): a value
the panel refuses is said on the panel and not sent; nothing is clamped silently. What the
service answers (``tether/{drone}/events``: refused, with its reason, or applied) is said in
the same place, and a request nobody answers is said too when it expires.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import viser

from groundstation.config import Settings
from groundstation.dashboard.charts import Charts
from groundstation.dashboard.commands import (
    LAND_HELP,
    THRESHOLD_HELP,
    FollowLimits,
    check_tether,
)
from groundstation.dashboard.model import HISTORY_S, DroneState, FollowOutcome, Pending, reconcile
from groundstation.dashboard.readouts import (
    SMOOTH_VIEW_NOTE,
    BusView,
    LinkStats,
    follow_html,
    health_html,
    link_warning_html,
    note_html,
    stop_html,
    tension_html,
    warning_html,
)

__all__ = [
    "EDIT_HOLD_S",
    "NO_DRONE",
    "PENDING_HOLD_S",
    "STOP_HOTKEY",
    "Panel",
    "PanelHost",
]

PENDING_HOLD_S = 3.0
"""A clicked setting shows the requested value this long at most while the service's report
still says otherwise; then the report wins again."""
EDIT_HOLD_S = 30.0
"""A number being edited (not yet applied) is not overwritten by reports for this long."""
FOREIGN_EDIT_WAIT_S = 1.0
"""Longest wait for a browser edit's callback before the report wins again, s."""
NO_DRONE = "(no drone yet)"
STOP_HOTKEY = "Shift+S"
"""Keyboard shortcut of the emergency stop (viser's command hotkeys; not while typing in a
field, where the browser keeps the keys)."""


FOLLOW_HELP = (
    "Follow mode: the drone yields when the tether is pulled. Tug-to-land: after a tug, "
    "stop the motors below the land height."
)
"""Said below the follow controls, not as their tooltips (which stayed over the emergency
stop buttons after a click)."""


class PanelHost(Protocol):
    """What a panel asks of the dashboard (commands go on the bus there)."""

    gui_lock: threading.RLock

    def request_follow(
        self,
        drone_id: str,
        enabled: bool,
        *,
        threshold_n: float | None = None,
        land: bool | None = None,
        land_below_m: float | None = None,
    ) -> bytes: ...

    def request_params(
        self, drone_id: str, *, weight_n_per_m: float | None = None, length_m: float | None = None
    ) -> bytes: ...

    def request_stop(self, drone_id: str, reason: str = "operator") -> bytes: ...

    def stop_all(self, reason: str = "operator: stop all") -> list[str]: ...

    def forget_stale(self) -> list[str]: ...

    def frame(self, client: viser.ClientHandle) -> None: ...

    def follow_limits(self, drone_id: str) -> FollowLimits: ...


def _set_value(handle: Any, value: Any) -> None:
    """Set a GUI input's value if it differs (viser's ``value`` setter is generic over
    ``T | ndarray``, which mypy reads as read-only through a subclass)."""
    if handle.value != value:
        handle.value = value


class _Synced:
    """A GUI input that shows a reported value unless the operator has just changed it."""

    def __init__(self, handle: Any) -> None:
        self.handle = handle
        self.pending: Pending | None = None
        self.editing_until_s = -math.inf
        self.written: Any = handle.value
        """The value this class last wrote (an operator's edit makes the handle differ)."""
        self.foreign_since_s: float | None = None

    def reset(self) -> None:
        self.pending = None
        self.editing_until_s = -math.inf

    def revert(self) -> None:
        """Show the last reported value again (a refused edit)."""
        self.reset()
        _set_value(self.handle, self.written)

    def show(self, reported: Any, now_s: float) -> bool:
        """Show ``reported`` unless a request or an edit holds the input.

        Returns:
            True when a request expired without the report ever confirming it.
        """
        if reported is None or now_s < self.editing_until_s:
            return False
        if self.pending is None and self.handle.value != self.written:
            # viser stores a browser's edit before it calls our callback, which then turns
            # it into a pending request. Overwriting it in between would make the callback
            # read back the old value and send the opposite of the click; wait for it.
            if self.foreign_since_s is None:
                self.foreign_since_s = now_s
            if now_s - self.foreign_since_s < FOREIGN_EDIT_WAIT_S:
                return False
        self.foreign_since_s = None
        before = self.pending
        value, self.pending = reconcile(reported, self.pending, now_s)
        _set_value(self.handle, value)
        self.written = value
        return before is not None and self.pending is None and reported != before.value


@dataclass
class _StopAsk:
    """A stop confirmation open in one browser."""

    drones: tuple[str, ...]
    finish: Callable[[bool], None]


class Panel:
    """The control panel in one GUI scope.

    Args:
        gui: ``client.gui`` (this tab only) or ``server.gui`` (shared by every tab).
        host: the dashboard (commands, limits, lock).
        settings: the root configuration (defaults shown until the service reports).
        shared: True when ``gui`` is the server's (the page then says the selection is shared).
    """

    def __init__(self, gui: viser.GuiApi, host: PanelHost, settings: Settings, shared: bool):
        self._gui = gui
        self._host = host
        self._settings = settings
        self.shared = shared
        self.selected: str | None = None
        self.selection_changed = False
        self._drones: tuple[str, ...] = ()
        self._asks: dict[int, _StopAsk] = {}
        self._asks_lock = threading.Lock()
        self._outcome_n = 0
        """The last of the selected drone's follow outcomes this panel has looked at."""

        self.warning = gui.add_html("")
        self.drone_select = gui.add_dropdown("Drone", (NO_DRONE,), initial_value=NO_DRONE)
        self.drone_select.on_update(self._on_select)
        self.stop_button = gui.add_button(
            "Emergency stop",
            color="red",
            icon=viser.Icon.HAND_STOP,
            disabled=True,
            hint=f"Stop the motors of the selected drone now (asks first; {STOP_HOTKEY})",
        )
        self.stop_button.on_click(lambda event: self._ask_stop(event.client, one=True))
        self.stop_all_button = gui.add_button(
            "Stop all drones",
            color="pink",
            icon=viser.Icon.HAND_STOP,
            disabled=True,
            hint="Stop the motors of every drone on this dashboard (asks first)",
        )
        self.stop_all_button.on_click(lambda event: self._ask_stop(event.client, one=False))
        self.stop_html = gui.add_html("")
        self._build_follow(gui)
        with gui.add_folder("Tension and position"):
            self.tension_html = gui.add_html(tension_html(None))
        with gui.add_folder(f"Charts (last {HISTORY_S:.0f} s)"):
            self.charts = Charts(gui)
            gui.add_html(
                note_html(
                    "The dashed threshold is a pull: follow engages when the tension beyond "
                    "the tether's own exceeds it, not when |T| does."
                )
            )
        self._build_tether(gui)
        with gui.add_folder("Link health"):
            self.health_html = gui.add_html(health_html(None, LinkStats(0.0, 0.0, None), 0.5))
        self._build_view(gui)
        self._stop_command = gui.add_command(
            "Emergency stop: selected drone",
            description="Asks for confirmation; the same shortcut again confirms",
            hotkey="S",
            modifier="shift",
            icon=viser.Icon.HAND_STOP,
        )
        self._stop_command.on_trigger(lambda event: self._ask_stop(event.client, one=True))
        self._stop_all_command = gui.add_command(
            "Emergency stop: all drones",
            description="Asks for confirmation",
            icon=viser.Icon.HAND_STOP,
        )
        self._stop_all_command.on_trigger(lambda event: self._ask_stop(event.client, one=False))

    # ---------------------------------------------------------------- building

    def _build_follow(self, gui: viser.GuiApi) -> None:
        settings = self._settings
        with gui.add_folder("Follow"):
            self.follow = _Synced(
                # No hint (tooltip) on these two: after a click it stayed over the emergency
                # stop buttons just above; the note below says what they do.
                gui.add_checkbox("Follow mode", False, disabled=True)
            )
            self.follow.handle.on_update(self._on_follow_toggled)
            self.land = _Synced(gui.add_checkbox("Tug-to-land", False, disabled=True))
            self.land.handle.on_update(self._on_land_toggled)
            with gui.add_form("Follow settings") as form:
                # No min= on purpose: the browser would clamp a typed -1 to it silently;
                # the panel refuses it with a sentence instead.
                self.threshold = _Synced(
                    gui.add_number(
                        "Threshold (N)",
                        settings.follow.threshold_n,
                        step=0.005,
                        disabled=True,
                        hint=THRESHOLD_HELP,
                    )
                )
                land_default_m = settings.follow.land_below_m
                self.land_height = _Synced(
                    gui.add_number(
                        "Land height (m)",
                        0.2 if land_default_m is None else land_default_m,
                        step=0.05,
                        disabled=True,
                        hint=LAND_HELP,
                    )
                )
                self.follow_apply = gui.add_button("Apply follow settings", disabled=True)
            self.follow_apply.on_click(lambda _event: form.submit())
            form.on_submit(self._on_follow_submit)
            self.threshold.handle.on_update(self._on_threshold_typed)
            self.land_height.handle.on_update(self._on_land_height_typed)
            self.follow_message = gui.add_html("")
            self.follow_help = gui.add_html(note_html(FOLLOW_HELP + " " + THRESHOLD_HELP))
            self.follow_html = gui.add_html(follow_html(None))

    def _build_tether(self, gui: viser.GuiApi) -> None:
        settings = self._settings
        with gui.add_folder("Tether", expand_by_default=False):
            with gui.add_form("Tether parameters") as form:
                # No min= (as for the threshold): a typed -1 is refused with a sentence.
                self.weight = _Synced(
                    gui.add_number(
                        "ω (N/m)",
                        settings.tether.weight_n_per_m,
                        step=0.005,
                        disabled=True,
                        hint="Tether weight per length, N/m, > 0",
                    )
                )
                self.length = _Synced(
                    gui.add_number(
                        "Length (m)",
                        settings.tether.length_m,
                        step=0.05,
                        disabled=True,
                        hint="Editable only while no reel reports the length",
                    )
                )
                self.tether_apply = gui.add_button("Apply tether parameters", disabled=True)
            self.tether_apply.on_click(lambda _event: form.submit())
            form.on_submit(self._on_tether_submit)
            for synced in (self.weight, self.length):
                synced.handle.on_update(self._tether_typed(synced))
            self.tether_message = gui.add_html("")
            self.tether_html = gui.add_html("")

    def _build_view(self, gui: viser.GuiApi) -> None:
        with gui.add_folder("View and drones", expand_by_default=False):
            frame = gui.add_button("Frame all", color="gray", icon=viser.Icon.FOCUS_CENTERED)
            frame.on_click(self._on_frame)
            forget = gui.add_button(
                "Forget stale drones",
                color="gray",
                hint="Drop drones that sent nothing for longer than the stale time",
            )
            forget.on_click(self._on_forget)
            selection = (
                'Shared panel ([web] panel = "shared"): every tab shows the same selected '
                "drone; a selection made here changes it for everyone."
                if self.shared
                else "This tab has its own selected drone. Follow state, settings and stops "
                "are the service's, shared by every tab."
            )
            gui.add_html(note_html(selection))
            gui.add_html(
                note_html(
                    f"Keyboard: {STOP_HOTKEY} asks to stop the selected drone, {STOP_HOTKEY} "
                    "again confirms. The browser keeps keys while a field or checkbox has the "
                    "focus: click the 3D view first. Ctrl+K lists the commands."
                )
            )
            gui.add_html(note_html(SMOOTH_VIEW_NOTE))

    def _all_synced(self) -> tuple[_Synced, ...]:
        return (self.follow, self.land, self.threshold, self.land_height, self.weight, self.length)

    # ---------------------------------------------------------------- drones

    def set_drones(self, drone_ids: Sequence[str]) -> None:
        """The drones to choose from (sorted); keeps the selection while it is there."""
        ids = tuple(drone_ids)
        if ids == self._drones:
            return
        self._drones = ids
        self.drone_select.options = ids if ids else (NO_DRONE,)
        if self.selected not in ids:
            self._set_selected(ids[0] if ids else None)
        _set_value(self.drone_select, self.selected if self.selected is not None else NO_DRONE)
        enabled = bool(ids)
        self.stop_button.disabled = not enabled
        self.stop_all_button.disabled = not enabled
        for synced in (self.follow, self.land, self.threshold, self.land_height, self.weight):
            synced.handle.disabled = not enabled
        self.follow_apply.disabled = not enabled
        self.tether_apply.disabled = not enabled

    def select(self, drone_id: str) -> None:
        """Show ``drone_id`` (as the selector does)."""
        self._set_selected(drone_id)
        _set_value(self.drone_select, drone_id)

    def _set_selected(self, drone_id: str | None) -> None:
        if drone_id != self.selected:
            self.selected = drone_id
            self.selection_changed = True
            for synced in self._all_synced():
                synced.reset()
            self.follow_message.content = ""
            self.tether_message.content = ""

    def _on_select(self, event: viser.GuiEvent[Any]) -> None:
        if event.client_id is None:
            return
        value = self.drone_select.value
        with self._host.gui_lock:
            if value != NO_DRONE and value in self._drones:
                self._set_selected(value)

    # ---------------------------------------------------------------- follow

    def _tether_typed(self, synced: _Synced) -> Callable[[viser.GuiEvent[Any]], None]:
        def typed(event: viser.GuiEvent[Any]) -> None:
            if event.client_id is None:
                return
            with self._host.gui_lock:
                synced.editing_until_s = time.monotonic() + EDIT_HOLD_S
                problem = self._check_tether()
                self.tether_message.content = "" if problem is None else warning_html(problem)

        return typed

    def _typed_length_m(self) -> float | None:
        return None if self.length.handle.disabled else float(self.length.handle.value)

    def _check_tether(self) -> str | None:
        return check_tether(float(self.weight.handle.value), self._typed_length_m())

    def _refuse(self, message: str) -> None:
        self.follow_message.content = warning_html(message)

    def _check_typed(self) -> str | None:
        """The first refusal of the typed threshold and (with tug-to-land) land height."""
        if self.selected is None:
            return None
        limits = self._host.follow_limits(self.selected)
        problem = limits.check_threshold(float(self.threshold.handle.value))
        if problem is None and self.land.handle.value:
            problem = limits.check_land_height(float(self.land_height.handle.value))
        return problem

    def _on_threshold_typed(self, event: viser.GuiEvent[Any]) -> None:
        if event.client_id is None:
            return
        with self._host.gui_lock:
            self.threshold.editing_until_s = time.monotonic() + EDIT_HOLD_S
            problem = self._check_typed()
            self.follow_message.content = "" if problem is None else warning_html(problem)

    def _on_land_height_typed(self, event: viser.GuiEvent[Any]) -> None:
        if event.client_id is None:
            return
        with self._host.gui_lock:
            self.land_height.editing_until_s = time.monotonic() + EDIT_HOLD_S
            if self.selected is None:
                return
            limits = self._host.follow_limits(self.selected)
            problem = limits.check_land_height(float(self.land_height.handle.value))
            self.follow_message.content = "" if problem is None else warning_html(problem)

    def _on_follow_toggled(self, event: viser.GuiEvent[Any]) -> None:
        if event.client_id is None:  # our own sync from the reports
            return
        with self._host.gui_lock:
            drone = self.selected
            if drone is None:
                return
            enabled = bool(self.follow.handle.value)
            blocked = self._host.follow_limits(drone).follow_blocked if enabled else None
            if blocked is not None:
                self._refuse(f"Follow mode not switched on: {blocked}")
                self.follow.revert()
                return
            self.follow_message.content = note_html(
                f"Sent: follow {'on' if enabled else 'off'}; the service's answer follows."
            )
            self.follow.pending = Pending(enabled, time.monotonic() + PENDING_HOLD_S)
            self._host.request_follow(drone, enabled)

    def _on_land_toggled(self, event: viser.GuiEvent[Any]) -> None:
        if event.client_id is None:
            return
        with self._host.gui_lock:
            drone = self.selected
            if drone is None:
                return
            land = bool(self.land.handle.value)
            height_m = float(self.land_height.handle.value) if land else None
            if height_m is not None:
                problem = self._host.follow_limits(drone).check_land_height(height_m)
                if problem is not None:
                    self._refuse(problem + " Tug-to-land not switched on.")
                    self.land.revert()
                    return
            self.follow_message.content = ""
            self.land.pending = Pending(land, time.monotonic() + PENDING_HOLD_S)
            self._host.request_follow(
                drone, bool(self.follow.handle.value), land=land, land_below_m=height_m
            )

    def _on_follow_submit(self, _event: Any) -> None:
        with self._host.gui_lock:
            drone = self.selected
            if drone is None:
                return
            problem = self._check_typed()
            if problem is not None:
                self._refuse(problem + " Nothing was sent.")
                return
            self.follow_message.content = note_html("Sent; the service's answer follows.")
            now_s = time.monotonic()
            threshold_n = float(self.threshold.handle.value)
            land = bool(self.land.handle.value)
            height_m = float(self.land_height.handle.value)
            self.threshold.editing_until_s = -math.inf
            self.threshold.pending = Pending(threshold_n, now_s + PENDING_HOLD_S)
            self.land_height.editing_until_s = -math.inf
            if land:
                self.land_height.pending = Pending(height_m, now_s + PENDING_HOLD_S)
            self._host.request_follow(
                drone,
                bool(self.follow.handle.value),
                threshold_n=threshold_n,
                land=land,
                land_below_m=height_m if land else None,
            )

    # ---------------------------------------------------------------- tether

    def _on_tether_submit(self, _event: Any) -> None:
        with self._host.gui_lock:
            drone = self.selected
            if drone is None:
                return
            now_s = time.monotonic()
            weight = float(self.weight.handle.value)
            length_m = self._typed_length_m()
            problem = self._check_tether()
            if problem is not None:
                self.tether_message.content = warning_html(problem + " Nothing was sent.")
                return
            try:
                self._host.request_params(drone, weight_n_per_m=weight, length_m=length_m)
            except ValueError as exc:
                self.tether_message.content = warning_html(f"Not sent: {exc}")
                return
            self.tether_message.content = note_html("Sent; the service's report follows.")
            self.weight.editing_until_s = -math.inf
            self.weight.pending = Pending(weight, now_s + PENDING_HOLD_S)
            self.length.editing_until_s = -math.inf
            if length_m is not None:
                self.length.pending = Pending(length_m, now_s + PENDING_HOLD_S)

    # ---------------------------------------------------------------- stop, view

    def _ask_stop(self, client: viser.ClientHandle | None, *, one: bool) -> None:
        """Open the stop confirmation in ``client``'s browser; a second ask confirms it."""
        if client is None:
            return
        drones = (self.selected,) if one and self.selected is not None else self._drones
        if (one and self.selected is None) or not drones:
            return
        with self._asks_lock:
            open_ask = self._asks.get(client.client_id)
        if open_ask is not None:
            if open_ask.drones == drones:
                open_ask.finish(True)  # the shortcut pressed again
            return
        names = ", ".join(f"**{d}**" for d in drones)
        title = f"Emergency stop: {drones[0]}" if one else "Emergency stop: all drones"
        done = threading.Lock()
        with client.gui.add_modal(title) as modal:
            client.gui.add_markdown(
                f"Stop the motors of {names} now? An airborne drone will fall."
                + (f" ({STOP_HOTKEY} again confirms.)" if one else "")
            )
            confirm = client.gui.add_button(
                "Confirm stop" if one else "Confirm stop all",
                color="red",
                icon=viser.Icon.HAND_STOP,
            )
            cancel = client.gui.add_button("Cancel")

        def finish(stop: bool) -> None:
            if not done.acquire(blocking=False):  # the other button was faster
                return
            with self._asks_lock:
                self._asks.pop(client.client_id, None)
            if stop:
                if one:
                    self._host.request_stop(drones[0])
                else:
                    self._host.stop_all()
            modal.close()

        with self._asks_lock:
            self._asks[client.client_id] = _StopAsk(drones, finish)
        confirm.on_click(lambda _event: finish(True))
        cancel.on_click(lambda _event: finish(False))

    def _on_frame(self, event: viser.GuiEvent[Any]) -> None:
        if event.client is not None:
            self._host.frame(event.client)

    def _on_forget(self, event: viser.GuiEvent[Any]) -> None:
        forgotten = self._host.forget_stale()
        if event.client is not None:
            event.client.add_notification(
                "Forget stale drones",
                f"Forgot {', '.join(forgotten)}." if forgotten else "No drone is stale.",
                auto_close_seconds=5.0,
            )

    # ---------------------------------------------------------------- update

    def update(self, drone: DroneState, now_s: float, clock_s: float, view: BusView) -> None:
        """Refresh the readouts and the synced inputs for the selected ``drone``.

        Args:
            drone: the selected drone.
            now_s: the pass's time (the clock of requests held by the inputs), seconds.
            clock_s: ``time.monotonic()`` (the clock of arrival: ages, staleness), seconds.
            view: what the dashboard's polls found (services, status replies, peers).
        """
        settings = self._settings
        params = settings.for_drone(drone.id)
        est = drone.estimate
        status = drone.current_status(clock_s)
        self.warning.content = link_warning_html(view, status)
        follow = drone.follow(clock_s)
        age_s = drone.telemetry_age_s(clock_s)
        self.tension_html.content = tension_html(est, drone.truth)
        self.follow_html.content = follow_html(follow)
        self.stop_html.content = stop_html(drone.last_stop, clock_s, age_s)
        self._show_outcome(drone.follow_outcome)
        if follow is not None:
            unconfirmed = [
                name
                for name, synced, reported in (
                    ("follow mode", self.follow, follow.enabled),
                    ("tug-to-land", self.land, follow.land_below_m is not None),
                    ("threshold", self.threshold, follow.threshold_n),
                    ("land height", self.land_height, follow.land_below_m),
                )
                if synced.show(reported, now_s)
            ]
            if unconfirmed:
                self._refuse(
                    f"Not confirmed: after {PENDING_HOLD_S:g} s the service still reports the "
                    f"old {' and '.join(unconfirmed)} and sent no answer on "
                    f"tether/{drone.id}/events. Is a service running for this drone?"
                )
        limits = self._host.follow_limits(drone.id)
        help_text = (
            f"{FOLLOW_HELP} {THRESHOLD_HELP} Accepted here: ≥ "
            f"{limits.threshold_floor_n:.3f} N. Land height between the floor "
            f"({limits.floor_z_m:.2f} m) and {limits.reach_top_m:.2f} m."
        )
        if limits.follow_blocked is not None and not (follow is not None and follow.enabled):
            self.follow_help.content = note_html(
                f"Follow mode cannot be switched on now: {limits.follow_blocked}", "#e8590c"
            ) + note_html(help_text)
        else:
            self.follow_help.content = note_html(help_text)

        length_source = status.length_source if status is not None else None
        from_reel = length_source == "reel" or drone.reel is not None
        self.length.handle.disabled = from_reel or not self._drones
        weight = status.weight_n_per_m if status is not None else None
        self.weight.show(weight if weight is not None else params.tether.weight_n_per_m, now_s)
        self.length.show(drone.length_m(params.tether.length_m), now_s)
        source = "reel" if from_reel else (length_source or "config")
        self.tether_html.content = note_html(
            f"length from {source}" + (" (not editable here)" if from_reel else "")
        )
        local = LinkStats(drone.telemetry_hz, drone.estimate_hz, age_s, dict(drone.invalid))
        self.health_html.content = health_html(status, local, settings.service.stale_after_s)

    def _show_outcome(self, outcome: FollowOutcome | None) -> None:
        """Say the service's latest answer about follow once, where the operator typed; a
        refusal ends the requests held by the inputs (nothing of the command was applied)."""
        if outcome is None or outcome.n == self._outcome_n:
            return
        self._outcome_n = outcome.n
        if self.selection_changed:
            return  # an answer from before this drone was chosen: not news here
        event = outcome.event
        if outcome.refused:
            for synced in (self.follow, self.land, self.threshold, self.land_height):
                if synced.pending is not None:
                    synced.revert()
            self._refuse(f"The service refused the follow command: {event.reason}")
        else:
            self.follow_message.content = note_html(f"The service: {event.reason}.")

    def update_charts(self, drone: DroneState, now_s: float) -> None:
        """Re-send the charts of the selected ``drone``."""
        self.charts.update(drone, now_s)

    def show_no_drone(self, view: BusView) -> None:
        """Readouts when no drone is known (yet, or all forgotten)."""
        self.warning.content = link_warning_html(view)
        self.tension_html.content = tension_html(None)
        self.stop_html.content = ""
