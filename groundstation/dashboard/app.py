"""The dashboard: wiring, bus client and lifecycle of the viser scene and panels.

It is an edge, like the simulator: everything it shows comes from the bus and everything it
does is a message on the bus, so it can run in the service's process or in its own.

Reads (subscriptions): ``tether/*/estimate``, ``tether/*/telemetry``, ``tether/*/truth``,
``tether/*/reel``, ``tether/*/cmd/stop`` and ``tether/*/events`` (the service's answers to
commands: a refused follow command is said on the panel with the service's reason); about
once a second it queries ``tether/*/status`` (the service's health per drone, with its peer
count) and the liveliness tokens ``groundstation/service/*`` (a service is running even
before any drone has reported to it). Writes:
``tether/{drone}/follow`` (FollowCommand), ``tether/{drone}/params`` (tether ω and length)
and ``tether/{drone}/cmd/stop`` (the emergency Stop, after a confirmation).

The flow::

    bus callbacks ──▶ Inbox (latest bytes) ──▶ DroneState.ingest ──▶ Scene.draw  (every tab)
                                              (update thread)     └▶ Panel.update (per tab)
    Panel callbacks (viser's threads) ──▶ Dashboard.request_* ──▶ bus

Threads. Bus callbacks only store the latest payload bytes and count them (telemetry comes
at 250 Hz per drone); nothing is parsed there. The update thread parses the latest payloads
and pushes the scene at ``settings.web.scene_rate_hz`` (≤ 30 Hz), the panels' readouts at
≤ 10 Hz and their charts at 4 Hz; a second small thread polls the status. GUI callbacks run
on viser's thread pool and publish commands.

Everything is served by viser from the local package: no CDN, fonts or HDRIs from outside
(checked by the browser test).
"""

from __future__ import annotations

import contextlib
import functools
import logging
import math
import threading
import time
from dataclasses import dataclass

import numpy as np
import viser

from groundstation.attitude import GRAVITY_MPS2
from groundstation.bus import Bus, Sample, Subscription
from groundstation.config import Settings
from groundstation.dashboard.commands import (
    FollowLimits,
    follow_blocker,
    follow_command,
    params_command,
    stop_command,
)
from groundstation.dashboard.model import (
    HISTORY_S,
    STATUS_STALE_S,
    DroneState,
    Inbox,
    Throttle,
)
from groundstation.dashboard.panel import Panel
from groundstation.dashboard.readouts import BusView
from groundstation.dashboard.scene import PALETTE, Scene, camera_framing, panel_fraction
from groundstation.messages import DRONE_ID_RE

__all__ = [
    "CHART_RATE_HZ",
    "PANEL_RATE_HZ",
    "Dashboard",
    "DashboardStats",
]

_log = logging.getLogger(__name__)

PANEL_RATE_HZ = 10.0
"""Readouts of the selected drone are refreshed at most this often."""
CHART_RATE_HZ = 4.0
"""Charts are re-sent at this rate (each push carries the whole 20 s window)."""
STATUS_PERIOD_S = 1.0
"""How often ``tether/*/status`` is queried."""
STATUS_TIMEOUT_S = 0.5
SERVICE_TOKENS = "groundstation/service/*"
"""The services' liveliness tokens (:class:`groundstation.service.Service`)."""
SHARED = -1
"""Key of the shared panel in :attr:`Dashboard.panels` (``[web] panel = "shared"``)."""


@dataclass(frozen=True)
class DashboardStats:
    """Cost of the dashboard's own update thread."""

    ticks: int
    update_cpu_s: float
    """CPU time spent in update passes (``time.thread_time``), seconds."""
    wall_s: float
    """Wall time since start, seconds."""


class Dashboard:
    """The viser dashboard, talking to the service only over ``bus``.

    Args:
        settings: the root configuration (``[web]`` for host, port, scene rate, panel scope
            and forgetting; the per-drone defaults for base, floor, tether until the service
            reports them).
        bus: where Estimates etc. come from and where commands go.
        host: bind address; default ``settings.web.host`` (127.0.0.1).
        port: port; default ``settings.web.port`` (8080); 0 picks a free one. If the port is
            taken, viser tries the next ones; :attr:`url` tells the one bound.
        update_thread: False leaves the update passes to the caller (:meth:`update`,
            :meth:`poll_status`): tests and benchmarks drive it deterministically.
    """

    def __init__(
        self,
        settings: Settings,
        bus: Bus,
        *,
        host: str | None = None,
        port: int | None = None,
        update_thread: bool = True,
    ) -> None:
        self._settings = settings
        self._bus = bus
        self._host = settings.web.host if host is None else host
        self._port = settings.web.port if port is None else port
        self._use_thread = update_thread
        self._scene_rate_hz = min(30.0, settings.web.scene_rate_hz)
        self._scene_budget_hz = settings.web.scene_budget_hz
        self._capacity = math.ceil(HISTORY_S * self._scene_rate_hz * 1.25) + 8

        self._inbox_lock = threading.Lock()
        self._inboxes: dict[str, Inbox] = {}
        self._drones: dict[str, DroneState] = {}
        self._n_created = 0
        self.gui_lock = threading.RLock()
        """Held by the update pass and by every GUI callback that touches panel state."""
        self._panels: dict[int, Panel] = {}
        self.framed: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        """Client id → the (position, look_at) its camera was last framed with."""

        self._server: viser.ViserServer | None = None
        self._scene: Scene | None = None
        self._subs: list[Subscription] = []
        self._threads: list[threading.Thread] = []
        self._stop_event = threading.Event()
        self._closed = False
        self._close_lock = threading.Lock()
        self._started_s = 0.0
        self._ticks = 0
        self._cpu_s = 0.0
        self._polled = False
        self._status_rx_s = -math.inf
        self._services: tuple[str, ...] = ()
        """Services alive at the last poll (their liveliness tokens)."""
        count = getattr(bus, "peer_count", None)
        self._peer_count = count if callable(count) else None
        self._scene_throttle = Throttle(self._scene_rate_hz)
        self._panel_throttle = Throttle(min(PANEL_RATE_HZ, self._scene_rate_hz))
        self._chart_throttle = Throttle(min(CHART_RATE_HZ, self._scene_rate_hz))
        self._logged_kinds: set[str] = set()

    # ---------------------------------------------------------------- lifecycle

    def start(self) -> None:
        """Start the viser server, subscribe, and start the update thread; returns at once.

        Raises:
            RuntimeError: already started or closed.
        """
        if self._server is not None or self._closed:
            raise RuntimeError("Dashboard.start() may be called once")
        self._started_s = time.monotonic()
        server = viser.ViserServer(
            host=self._host, port=self._port, label="groundstation", verbose=False
        )
        self._server = server
        server.gui.configure_theme(control_width="large", show_share_button=False, show_logo=False)
        self._scene = Scene(server, self._settings)
        if self._settings.web.panel == "shared":
            self._panels[SHARED] = Panel(server.gui, self, self._settings, shared=True)
        server.on_client_connect(self._on_client_connect)
        server.on_client_disconnect(self._on_client_disconnect)
        for kind, keyexpr in (
            ("estimate", "tether/*/estimate"),
            ("telemetry", "tether/*/telemetry"),
            ("truth", "tether/*/truth"),
            ("reel", "tether/*/reel"),
            ("stop", "tether/*/cmd/stop"),
        ):
            self._subs.append(self._bus.subscribe(keyexpr, functools.partial(self._receive, kind)))
        self._subs.append(self._bus.subscribe("tether/*/events", self._receive_event))
        if self._use_thread:
            for target, name in (
                (self._run_updates, "dashboard-update"),
                (self._run_status, "dashboard-status"),
            ):
                thread = threading.Thread(target=target, name=name, daemon=True)
                thread.start()
                self._threads.append(thread)

    @property
    def url(self) -> str:
        """``http://HOST:PORT`` of the running dashboard (a wildcard host shows as loopback).

        Raises:
            RuntimeError: not started.
        """
        server = self.server
        host = server.get_host()
        if host in ("", "0.0.0.0"):
            host = "127.0.0.1"
        elif host == "::":
            host = "[::1]"
        elif ":" in host:
            host = f"[{host}]"
        return f"http://{host}:{server.get_port()}"

    @property
    def server(self) -> viser.ViserServer:
        """The viser server (for tests and embedding).

        Raises:
            RuntimeError: not started.
        """
        if self._server is None:
            raise RuntimeError("Dashboard not started")
        return self._server

    @property
    def scene(self) -> Scene:
        """The 3D scene (for tests).

        Raises:
            RuntimeError: not started.
        """
        if self._scene is None:
            raise RuntimeError("Dashboard not started")
        return self._scene

    @property
    def panels(self) -> list[Panel]:
        """The panels: one per connected tab, or the one shared panel."""
        with self.gui_lock:
            return list(self._panels.values())

    def close(self) -> None:
        """Stop the threads and the server; idempotent."""
        with self._close_lock:
            if self._closed:
                return
            self._closed = True
        self._stop_event.set()
        for sub in self._subs:
            sub.close()
        self._subs.clear()
        for thread in self._threads:
            thread.join(timeout=1.0)
        if self._server is not None:
            self._server.stop()

    def __enter__(self) -> Dashboard:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def stats(self) -> DashboardStats:
        """Ticks and CPU time of the update passes so far."""
        wall_s = time.monotonic() - self._started_s if self._started_s else 0.0
        return DashboardStats(ticks=self._ticks, update_cpu_s=self._cpu_s, wall_s=wall_s)

    @property
    def drones(self) -> list[str]:
        """Drone ids seen and not forgotten, sorted."""
        with self._inbox_lock:
            return sorted(self._inboxes)

    def drone(self, drone_id: str) -> DroneState | None:
        """The update thread's state of ``drone_id`` (for tests; None before its first pass)."""
        return self._drones.get(drone_id)

    def select(self, drone_id: str) -> None:
        """Show ``drone_id`` in every panel (as each selector does).

        Raises:
            KeyError: a drone not seen.
        """
        with self._inbox_lock:
            if drone_id not in self._inboxes:
                raise KeyError(f"drone {drone_id!r} has not been seen")
        with self.gui_lock:
            for panel in self._panels.values():
                panel.select(drone_id)

    # ---------------------------------------------------------------- bus callbacks (cheap)

    def _inbox(self, key: str) -> Inbox | None:
        parts = key.split("/", 2)
        if len(parts) < 3:
            return None
        inbox = self._inboxes.get(parts[1])
        if inbox is None:
            if not DRONE_ID_RE.fullmatch(parts[1]):
                return None
            with self._inbox_lock:
                inbox = self._inboxes.setdefault(parts[1], Inbox())
        return inbox

    def _receive(self, kind: str, sample: Sample) -> None:
        """Bus callback: keep the latest payload of ``kind``, count it (no parsing here)."""
        inbox = self._inbox(sample.key)
        if inbox is None:
            return
        now_s = time.monotonic()
        setattr(inbox, kind, sample.payload)
        setattr(inbox, f"n_{kind}", getattr(inbox, f"n_{kind}") + 1)
        inbox.last_rx_s = now_s
        if kind in ("telemetry", "stop"):  # link health, and when the Stop was seen
            setattr(inbox, f"{kind}_rx_s", now_s)

    def _receive_event(self, sample: Sample) -> None:
        """Bus callback: keep an Event for a drone seen here (no parsing here). An event
        neither creates a drone nor keeps one alive: the service answers a command for a
        drone that never flew, too."""
        parts = sample.key.split("/", 2)
        inbox = self._inboxes.get(parts[1]) if len(parts) == 3 else None
        if inbox is None:
            return
        inbox.n_events += 1
        inbox.events.append((inbox.n_events, sample.payload))

    # ---------------------------------------------------------------- status polling

    def poll_status(self) -> int:
        """Query ``tether/*/status`` once and store the replies of the drones seen here.

        Returns:
            How many replies were stored.
        """
        try:
            replies = self._bus.query("tether/*/status", timeout_s=STATUS_TIMEOUT_S)
        except Exception as exc:  # a bus error must not end the poller; logged once
            self._log_once("status-query", "status query failed: %s", exc)
            replies = []
        now_s = time.monotonic()
        count = 0
        for reply in replies:
            parts = reply.key.split("/")
            # A status reply updates a drone whose samples arrive here; it neither creates
            # one nor keeps one alive: the service answers for a long-dead drone too.
            inbox = self._inboxes.get(parts[1]) if len(parts) == 3 else None
            if inbox is None:
                continue
            inbox.status = reply.payload  # parsed by the update pass, as every payload
            inbox.status_rx_s = now_s
            count += 1
        if replies:
            self._status_rx_s = now_s
        try:
            self._services = tuple(self._bus.alive(SERVICE_TOKENS, timeout_s=STATUS_TIMEOUT_S))
        except Exception as exc:  # as above: the poller goes on, the page says no service
            self._log_once("liveliness-query", "service liveliness query failed: %s", exc)
            self._services = ()
        self._polled = True
        return count

    def bus_view(self, clock_s: float | None = None) -> BusView:
        """What the last polls found: a status reply lately, the services alive, and this
        dashboard's own peer count."""
        clock_s = time.monotonic() if clock_s is None else clock_s
        own_peers = None
        if self._peer_count is not None:
            try:
                own_peers = int(self._peer_count())
            except Exception:  # a closing session: not known
                own_peers = None
        return BusView(
            any_status=not self._polled or clock_s - self._status_rx_s <= STATUS_STALE_S,
            services=self._services if self._polled else (),
            own_peers=own_peers,
        )

    def _run_status(self) -> None:
        while not self._stop_event.is_set():
            self.poll_status()
            self._stop_event.wait(STATUS_PERIOD_S)

    # ---------------------------------------------------------------- commands

    def request_follow(
        self,
        drone_id: str,
        enabled: bool,
        *,
        threshold_n: float | None = None,
        land: bool | None = None,
        land_below_m: float | None = None,
    ) -> bytes:
        """Publish a FollowCommand to ``tether/{drone_id}/follow``; returns the payload."""
        payload = follow_command(
            enabled, threshold_n=threshold_n, land=land, land_below_m=land_below_m
        )
        self._bus.publish(f"tether/{drone_id}/follow", payload)
        return payload

    def request_params(
        self,
        drone_id: str,
        *,
        weight_n_per_m: float | None = None,
        length_m: float | None = None,
    ) -> bytes:
        """Publish tether parameters to ``tether/{drone_id}/params``; returns the payload."""
        payload = params_command(weight_n_per_m=weight_n_per_m, length_m=length_m)
        self._bus.publish(f"tether/{drone_id}/params", payload)
        return payload

    def request_stop(self, drone_id: str, reason: str = "operator") -> bytes:
        """Publish a Stop to ``tether/{drone_id}/cmd/stop`` at once; returns the payload.

        The panel calls this only after the operator confirmed.
        """
        payload = stop_command(time.time(), reason)
        self._bus.publish(f"tether/{drone_id}/cmd/stop", payload)
        _log.warning("emergency Stop published for %s (%s)", drone_id, reason)
        return payload

    def stop_all(self, reason: str = "operator: stop all") -> list[str]:
        """Publish a Stop to every drone seen and not forgotten, stale ones included (a
        drone whose telemetry is lost may still be flying). Returns the drones."""
        drones = self.drones
        for drone_id in drones:
            self.request_stop(drone_id, reason)
        return drones

    def follow_limits(self, drone_id: str) -> FollowLimits:
        """What a follow setting for ``drone_id`` must respect (the service's threshold
        floor, noise, floor, reach) and why follow cannot be switched on now, if so."""
        settings = self._settings
        params = settings.for_drone(drone_id)
        drone = self._drones.get(drone_id)
        blocked = None
        if drone is None:
            base_z_m, length_m, std_n = params.base.position_m[2], params.tether.length_m, None
        else:
            base_z_m = drone.base_m(params.base.position_m)[2]
            length_m = drone.length_m(params.tether.length_m)
            std_n = drone.estimate.tension_std_n if drone.estimate is not None else None
            now_s = time.monotonic()
            telemetry = drone.telemetry
            blocked = follow_blocker(
                drone_id,
                telemetry_age_s=drone.telemetry_age_s(now_s),
                stale_after_s=settings.service.stale_after_s,
                has_mocap=None if telemetry is None else telemetry.position_m is not None,
                calibration=drone.calibration(now_s),
            )
        return FollowLimits.for_drone(
            std_n,
            params.base.floor_z_m,
            base_z_m,
            length_m,
            min_threshold_n=settings.service.follow_threshold_min_n,
            follow_blocked=blocked,
        )

    # ---------------------------------------------------------------- forgetting

    def forget(self, drone_id: str) -> None:
        """Drop ``drone_id`` from the scene, the selectors and the inboxes. If it speaks
        again it comes back as a new drone (follow is then the service's business: off)."""
        with self._inbox_lock:
            self._inboxes.pop(drone_id, None)
        with self.gui_lock:
            self._drones.pop(drone_id, None)
            if self._scene is not None:
                self._scene.remove(drone_id)
            ids = sorted(self._drones)
            for panel in self._panels.values():
                panel.set_drones(ids)
        _log.info("dashboard forgot drone %s", drone_id)

    def forget_stale(self) -> list[str]:
        """Forget every drone that is stale now; returns them."""
        now_s = time.monotonic()
        stale_after_s = self._settings.service.stale_after_s
        with self.gui_lock:
            stale = [d.id for d in self._drones.values() if d.is_stale(now_s, stale_after_s)]
        for drone_id in stale:
            self.forget(drone_id)
        return stale

    # ---------------------------------------------------------------- clients

    def frame(self, client: viser.ClientHandle) -> None:
        """Point ``client``'s camera at every drone, base and motion-capture marker, in the
        part of its view that the control panel leaves free."""
        fov_rad, aspect, width_px = math.radians(60.0), 1.6, None
        with contextlib.suppress(AssertionError):  # no camera message from it yet
            camera = client.camera
            if camera.image_width > 0 and camera.image_height > 0 and camera.fov > 0.0:
                fov_rad, aspect = camera.fov, camera.image_width / camera.image_height
                width_px = float(camera.image_width)
        position, look_at = camera_framing(
            self.scene.framing_points(list(self._drones.values())),
            fov_rad,
            aspect=aspect,
            covered_right=panel_fraction(width_px),
        )
        self.framed[client.client_id] = (position, look_at)
        # viser moves look_at along with position; set look_at after to pin it.
        with client.atomic():
            client.camera.position = position
            client.camera.look_at = look_at

    def _on_client_connect(self, client: viser.ClientHandle) -> None:
        with self.gui_lock:
            if self._settings.web.panel == "tab":
                panel = Panel(client.gui, self, self._settings, shared=False)
                self._panels[client.client_id] = panel
                panel.set_drones(sorted(self._drones))
            if self._drones:
                self.frame(client)

    def _on_client_disconnect(self, client: viser.ClientHandle) -> None:
        with self.gui_lock:
            self._panels.pop(client.client_id, None)
            self.framed.pop(client.client_id, None)

    # ---------------------------------------------------------------- update thread

    def _run_updates(self) -> None:
        # Sleep until the next pass is due, so the pass's own work is inside the period.
        while not self._stop_event.wait(max(0.001, self._scene_throttle.next_s - time.monotonic())):
            try:
                self.update()
            except Exception:  # keep drawing; a bug here must not freeze the dashboard
                _log.exception("dashboard update failed")

    def update(self, now_s: float | None = None) -> None:
        """One update pass: parse the latest payloads, push scene, panels and charts.

        The update thread calls this at the scene rate; pushes are throttled by ``now_s``
        (``time.monotonic()`` when None), so calling it more often does not send more.
        Staleness and forgetting always use ``time.monotonic()`` (the clock of arrival).
        """
        if self._server is None:
            raise RuntimeError("Dashboard not started")
        cpu0_s = time.thread_time()
        now_s = time.monotonic() if now_s is None else now_s
        if self._scene_throttle.due(now_s):
            with self.gui_lock:
                self._update_all(now_s)
            self._ticks += 1
            # A bounded number of drone redraws per second in all (settings.web).
            per_drone_hz = self._scene_budget_hz / max(1, len(self._drones))
            self._scene_throttle.period_s = 1.0 / min(self._scene_rate_hz, per_drone_hz)
        self._cpu_s += time.thread_time() - cpu0_s

    def _new_drone(self, drone_id: str, inbox: Inbox) -> DroneState:
        color = PALETTE[self._n_created % len(PALETTE)]
        self._n_created += 1
        weight_n = self._settings.for_drone(drone_id).drone.mass_kg * GRAVITY_MPS2
        return DroneState(drone_id, inbox, color, self._capacity, weight_n)

    def _update_all(self, now_s: float) -> None:
        server, scene = self._server, self._scene
        assert server is not None and scene is not None
        clock_s = time.monotonic()
        with self._inbox_lock:
            inboxes = sorted(self._inboxes.items())  # colours follow the ids, not arrival
        changed_set = False
        for drone_id, inbox in inboxes:
            if drone_id not in self._drones:
                self._drones[drone_id] = self._new_drone(drone_id, inbox)
                changed_set = True
        forget_after_s = self._settings.web.forget_after_s
        if forget_after_s > 0.0:
            for drone in list(self._drones.values()):
                if drone.silent_s(clock_s) > forget_after_s:
                    self.forget(drone.id)
                    changed_set = True
        moved = False
        with server.atomic():
            for drone in self._drones.values():
                changed, new_stop = drone.ingest(now_s, self._log_once)
                if new_stop is not None:
                    self._notify_stop(drone.id, new_stop.reason)
                # Redraw on new data, and once a second anyway (staleness is time).
                if changed or now_s - drone.drawn_s >= 1.0:
                    scene.draw(drone, clock_s)
                    drone.drawn_s = now_s
                    moved = True
            if moved or changed_set:
                scene.place_labels(list(self._drones.values()))
        if changed_set:
            self._on_drone_set_changed(server)
        self._update_panels(now_s, clock_s)

    def _on_drone_set_changed(self, server: viser.ViserServer) -> None:
        ids = sorted(self._drones)
        for panel in self._panels.values():
            panel.set_drones(ids)
        if not ids:
            return
        position, look_at = camera_framing(
            self.scene.framing_points(list(self._drones.values())),
            covered_right=panel_fraction(None),
        )
        server.initial_camera.position = position
        server.initial_camera.look_at = look_at
        for client in server.get_clients().values():
            self.frame(client)

    def _update_panels(self, now_s: float, clock_s: float) -> None:
        panel_due = self._panel_throttle.due(now_s)
        chart_due = self._chart_throttle.due(now_s)
        any_changed = any(panel.selection_changed for panel in self._panels.values())
        view = self.bus_view(clock_s) if panel_due or any_changed else None
        for panel in self._panels.values():
            drone = self._drones.get(panel.selected) if panel.selected is not None else None
            if drone is None:
                if view is not None:
                    panel.show_no_drone(view)
                continue
            changed = panel.selection_changed
            if view is not None and (panel_due or changed):
                panel.update(drone, now_s, clock_s, view)
            if chart_due or changed:
                panel.update_charts(drone, now_s)
            panel.selection_changed = False

    def _notify_stop(self, drone_id: str, reason: str) -> None:
        if self._server is None:
            return
        for client in self._server.get_clients().values():
            client.add_notification(
                f"Stop: {drone_id}",
                f"A Stop was sent to {drone_id} ({reason}); the panel says when telemetry "
                "confirms it.",
                color="red",
                auto_close_seconds=15.0,
            )

    def _log_once(self, kind: str, msg: str, *args: object) -> None:
        if kind not in self._logged_kinds:
            self._logged_kinds.add(kind)
            _log.warning(msg + " (logged once)", *args)
