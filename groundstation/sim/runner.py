"""Runs scenarios on a bus in (scaled) real time: the simulator as an edge.

:class:`Simulator` publishes ``tether/{drone}/telemetry``, ``tether/{drone}/reel`` and the
ground truth ``tether/{drone}/truth``, and obeys ``cmd/setpoint`` and ``cmd/stop``. With
``[sim] untethered`` the drones fly without a tether: no tether force and no Reel.

Lock-step API (benchmarks, no bus, no clock), the same for both profiles::

    sim = Simulator(settings, bus=None_or_any, scenario="hover")   # [sim] profile picks
    while sim.t_s < 10.0:
        samples = sim.step()          # advances sim.dt_s = 1/[sim] rate_hz
        ...                           # Sample(key, payload): telemetry, truth, reel, follow
    sim.drones["cf1"].position_world_m, sim.drawn_errors("cf1")
    sim.handle_command(sample)        # a cmd/setpoint or cmd/stop Sample from the service

``ideal``: one Telemetry + Truth per drone per step, at the step's stamp. ``realistic``: the
drone runs at ``[sim.realistic] physics_rate_hz`` inside the step and a step returns the IMU
samples whose stamps fell in it (0, 1 or more per drone at the default 250 Hz stepping and
~100 Hz IMU), each with a Truth at the same stamp; Reel at 10 Hz in both.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from groundstation.bus import Bus, Sample, Subscription
from groundstation.config import ConfigError, Settings
from groundstation.messages import InvalidMessage, SetpointIn, StopIn, Truth
from groundstation.sim.scenarios import PAPER_BASE_M, SCENARIOS, scenario_names

if TYPE_CHECKING:
    from groundstation.sim.ideal import DroneSim
    from groundstation.sim.realistic import RealisticDrone

__all__ = ["Simulator"]

_log = logging.getLogger("groundstation.sim")

MIN_HEIGHT_M = 0.05
"""Scripted targets shifted with a low base stay this far above the floor, m."""


class Simulator:
    """Runs a scenario for the configured drones on a bus (scaled real time).

    Args:
        settings: root configuration (``[sim]``, and per-drone ``[tether]``/``[base]``).
        bus: where to publish and listen for commands.
        scenario: scenario name (default ``settings.sim.scenario``).
    """

    def __init__(self, settings: Settings, bus: Bus, scenario: str | None = None) -> None:
        name = scenario or settings.sim.scenario
        if name not in SCENARIOS:
            raise ValueError(f"unknown scenario {name!r}; known: {', '.join(scenario_names())}")
        self.settings = settings
        self.bus = bus
        self.scenario = SCENARIOS[name]
        self.untethered = settings.sim.untethered
        if self.untethered and self.scenario.coin_mass_kg is not None:
            raise ConfigError(
                f"[sim] untethered: scenario {name!r} hangs a coin on a thread in place of "
                "the tether, it has no untethered flight"
            )
        self.rng = np.random.default_rng(settings.sim.seed)
        # The base sensor draws from its own stream: switching it on changes no other noise.
        self._base_rng = np.random.default_rng([settings.sim.seed, 0xBA5E])
        self.dt_s = 1.0 / settings.sim.rate_hz
        self.t_s = 0.0
        self.seq = 0
        self.profile = settings.sim.profile
        self.drones: dict[str, DroneSim | RealisticDrone] = {}
        self._operator_done: set[int] = set()
        self._handles: list[Subscription] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._commands: list[tuple[str, str, bytes]] = []
        self._cmd_lock = threading.Lock()
        self.stops_received: dict[str, str] = {}
        self._errors_sent_s: dict[str, float] = {}
        for i, drone_id in enumerate(settings.sim.drones):
            if self.profile == "realistic":
                self.drones[drone_id] = self._make_realistic(drone_id, i)
            else:
                self.drones[drone_id] = self._make_drone(drone_id, i)

    def drawn_errors(self, drone_id: str) -> dict[str, Any] | None:
        """The flight's drawn sensor errors and their equivalent ``[calibration]`` values
        (``calibration`` key; realistic profile), None for the ideal profile."""
        drone = self.drones[drone_id]
        if self.profile != "realistic":
            return None
        return drone.drawn_errors()  # type: ignore[union-attr]

    def truth_calibration(self, drone_id: str, *, use_vbat: bool = True) -> dict[str, Any]:
        """``[calibration]`` values equal to this flight's truth ("calibration = truth").

        The keys of :class:`~groundstation.config.CalibrationSection`, ready for
        ``{"calibration": ...}`` or ``{"drones": {id: {"calibration": ...}}}``. ``use_vbat``
        False: the exact thrust scale at the first hover voltage and no voltage slope (for an
        estimator that ignores ``vbat_v``). The ideal profile: the defaults, but
        ``thrust_scale = 1/(1 + [sim] thrust_bias_ratio)``.
        """
        if self.profile != "realistic":
            return {
                "thrust_scale": 1.0 / (1.0 + self.settings.sim.thrust_bias_ratio),
                "source": "sim truth (ideal)",
            }
        cal = self._errors_of(drone_id)["calibration"]
        out = {
            "thrust_scale": cal["thrust_scale"],
            "thrust_vbat_slope_per_v": cal["thrust_vbat_slope_per_v"],
            "thrust_vbat_ref_v": cal["thrust_vbat_ref_v"],
            "thrust_axis_rad": tuple(cal["thrust_axis_rad"]),
            "accel_bias_mps2": tuple(cal["accel_bias_mps2"]),
            "source": f"sim truth (realistic, seed {self.settings.sim.seed}, {drone_id})",
        }
        if not use_vbat:
            out["thrust_scale"] = cal["thrust_scale_hover_start"]
            out["thrust_vbat_slope_per_v"] = 0.0
        return out

    def _errors_of(self, drone_id: str) -> dict[str, Any]:
        errors = self.drawn_errors(drone_id)
        if errors is None:
            raise ValueError(f"{drone_id}: the {self.profile} profile draws no errors")
        return errors

    def _placement(
        self, drone_id: str, index: int
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
        """Base, start, script offset, tether length and floor of one drone.

        A scenario's positions are relative to its base: they are written for the paper's base
        at :data:`~groundstation.sim.scenarios.PAPER_BASE_M` (or the scenario's own
        ``base_m``), and each drone flies them shifted by its own base's displacement from
        the paper's (its ``[drones.<id>.base]``, or, for drones without a table of their own,
        the root ``[base]`` spread 3 m apart in y). The default base flies them unshifted.
        """
        params = self.settings.for_drone(drone_id)
        sc = self.scenario
        own_base = np.array(params.base.position_m, float)
        if drone_id not in self.settings.drones:
            # Several drones fly the same script, each about its own base: spread them out.
            own_base = own_base + np.array([0.0, 3.0 * index, 0.0])
        offset = own_base - np.array(PAPER_BASE_M, float)
        base = own_base if sc.base_m is None else np.array(sc.base_m, float) + offset
        floor = params.base.floor_z_m
        start = np.array(sc.start_m, float) + offset
        if sc.start_on_ground:
            start[2] = floor
        else:
            start[2] = max(start[2], floor + MIN_HEIGHT_M)
        length = sc.length_m if sc.length_m is not None else params.tether.length_m
        return base, start, offset, length, floor

    def _make_realistic(self, drone_id: str, index: int) -> RealisticDrone:
        from groundstation.sim.realistic import RealisticDrone

        params = self.settings.for_drone(drone_id)
        sc = self.scenario
        base, start, offset, length, floor = self._placement(drone_id, index)
        drone = RealisticDrone(
            self.settings.sim.realistic,
            base_world_m=base,
            start_world_m=start,
            length_m=length,
            weight_n_per_m=params.tether.weight_n_per_m,
            floor_z_m=floor,
            mass_kg=params.drone.mass_kg,
            seed=(self.settings.sim.seed, index),
            armed=not sc.start_on_ground,
            start_on_ground=sc.start_on_ground,
            thrust_ramp_s=sc.thrust_ramp_s,
            coin_mass_kg=sc.coin_mass_kg,
            coin_arm_m=np.array(sc.coin_arm_m, float) + offset
            if sc.coin_mass_kg is not None
            else None,
            mocap=self.settings.sim.mocap,
            tethered=not self.untethered,
        )
        drone.offset_m = offset
        return drone

    def _make_drone(self, drone_id: str, index: int) -> DroneSim:
        from groundstation.sim.ideal import DroneSim

        params = self.settings.for_drone(drone_id)
        sc = self.scenario
        base, start, offset, length, floor = self._placement(drone_id, index)
        drone = DroneSim(
            base_world_m=base,
            length_m=length,
            weight_n_per_m=params.tether.weight_n_per_m,
            floor_z_m=floor,
            mass_kg=params.drone.mass_kg,
            position_world_m=start,
            target_world_m=start.copy(),
            armed=not sc.start_on_ground,
            thrust_ramp_s=sc.thrust_ramp_s,
            coin_mass_kg=sc.coin_mass_kg,
            coin_arm_m=np.array(sc.coin_arm_m, float) + offset
            if sc.coin_mass_kg is not None
            else None,
            tethered=not self.untethered,
        )
        drone.offset_m = offset
        if not sc.start_on_ground:
            # Start in equilibrium: pre-load the integral with the tether's pull.
            tension = drone.tether_at(start)
            drone.integral_m_s = -tension / (drone.mass_kg * drone.ki_per_s3)
        drone.on_ground = sc.start_on_ground
        return drone

    # ------------------------------------------------------------------ commands

    def start(self) -> None:
        """Subscribe to commands and run the scenario on a thread."""
        for drone_id in self.drones:
            for kind in ("cmd/setpoint", "cmd/stop"):
                self._handles.append(
                    self.bus.subscribe(f"tether/{drone_id}/{kind}", self._on_command)
                )
        self._thread = threading.Thread(target=self.run, name="groundstation-sim", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        for handle in self._handles:
            handle.close()
        self._handles.clear()

    def wait(self, timeout_s: float | None = None) -> bool:
        """Wait for the scenario thread to finish (True when it did)."""
        if self._thread is None:
            return True
        self._thread.join(timeout_s)
        return not self._thread.is_alive()

    def handle_command(self, sample: Sample) -> None:
        """Take a ``cmd/setpoint`` or ``cmd/stop`` Sample (applied at the next step)."""
        self._on_command(sample)

    def _on_command(self, sample: Sample) -> None:
        drone_id = sample.key.split("/")[1]
        kind = "stop" if sample.key.endswith("/cmd/stop") else "setpoint"
        with self._cmd_lock:
            self._commands.append((drone_id, kind, sample.payload))

    def _apply_commands(self) -> None:
        with self._cmd_lock:
            commands, self._commands = self._commands, []
        for drone_id, kind, payload in commands:
            drone = self.drones.get(drone_id)
            if drone is None:
                continue
            try:
                if kind == "stop":
                    stop = StopIn.parse(payload)
                    if drone.armed:
                        _log.info("%s: Stop (%s): motors off", drone_id, stop.reason)
                    drone.armed = False
                    self.stops_received[drone_id] = stop.reason
                else:
                    sp = SetpointIn.parse(payload)
                    drone.target_world_m = np.array(sp.position_m, float)
            except InvalidMessage as exc:
                _log.warning("%s: ignoring bad %s: %s", drone_id, kind, exc)

    # ------------------------------------------------------------------ stepping

    def _scripted(self, drone: DroneSim | RealisticDrone) -> np.ndarray:
        """Apply the scenario's script at ``self.t_s``; return the external force."""
        sc = self.scenario
        t = self.t_s
        period = sc.duration_s if sc.name == "hover_spots" and sc.duration_s else None
        t_wp = t % period if period else t
        offset = drone.offset_m
        for wp in sc.waypoints:
            if wp.at_s <= t_wp < wp.at_s + self.dt_s * 0.999 or (t == 0.0 and wp.at_s == 0.0):
                target = np.array(wp.position_m, float) + offset
                if not (sc.start_on_ground and wp.position_m[2] <= 0.0):
                    target[2] = max(target[2], drone.floor_z_m + MIN_HEIGHT_M)
                drone.target_world_m = target
        if sc.start_on_ground and not drone.armed and sc.arm_at_s <= t < sc.arm_at_s + self.dt_s:
            drone.armed = True
        if sc.reel_rate_mps and sc.reel_window_s[0] <= t < sc.reel_window_s[1]:
            drone.length_m = max(0.05, drone.length_m + sc.reel_rate_mps * self.dt_s)
        force = np.zeros(3)
        for pull in sc.pulls:
            if pull.start_s <= t < pull.end_s:
                force += np.array(pull.force_world_n, float)
        return force

    def step(self) -> list[Sample]:
        """Advance every drone by one period; return the samples to publish."""
        out: list[Sample] = []
        sim_cfg = self.settings.sim
        for i, (at_s, payload) in enumerate(self.scenario.operator):
            if i not in self._operator_done and self.t_s >= at_s:
                self._operator_done.add(i)
                for drone_id in self.drones:
                    out.append(Sample(f"tether/{drone_id}/follow", json.dumps(payload).encode()))
        publish_reel = self.seq % max(1, round(sim_cfg.rate_hz / 10.0)) == 0
        # The script first, then the service's commands, which override its waypoints.
        externals = {drone_id: self._scripted(drone) for drone_id, drone in self.drones.items()}
        self._apply_commands()
        for drone_id, drone in self.drones.items():
            external = externals[drone_id]
            if self.profile == "realistic":
                due = drone.step(self.dt_s, external)
                out.extend(self._realistic_messages(drone_id, drone, due, publish_reel))  # type: ignore[arg-type]
            else:
                drone.step(self.dt_s, external)
                out.extend(self._messages(drone_id, drone, external, publish_reel))  # type: ignore[arg-type]
        self.seq += 1
        self.t_s = self.seq * self.dt_s
        return out

    def _messages(
        self, drone_id: str, drone: DroneSim, external: np.ndarray, publish_reel: bool
    ) -> list[Sample]:
        cfg = self.settings.sim
        rng = self.rng
        accel = drone.specific_force_body_mps2 + rng.normal(0.0, cfg.accel_noise_mps2, 3)
        thrust = drone.thrust_n * (1.0 + cfg.thrust_bias_ratio)
        thrust = max(0.0, thrust + rng.normal(0.0, cfg.thrust_noise_n)) if drone.armed else 0.0
        telemetry: dict[str, object] = {
            "seq": self.seq,
            "stamp_s": round(self.t_s, 9),
            "accel_mps2": accel.tolist(),
            "quat_wxyz": drone.quat_wxyz.tolist(),
            "thrust_n": thrust,
            "gyro_rps": rng.normal(0.0, 0.01, 3).tolist(),
            "armed": drone.armed,
        }
        if cfg.mocap:
            telemetry["position_m"] = drone.position_world_m.tolist()
        out = [Sample(f"tether/{drone_id}/telemetry", json.dumps(telemetry).encode())]
        truth = Truth(
            stamp_s=round(self.t_s, 9),
            position_m=_v3(drone.position_world_m),
            velocity_mps=_v3(drone.velocity_world_mps),
            tension_n=_v3(drone.tension_world_n + external),
            length_m=0.0 if self.untethered else drone.length_m,
            base_m=_v3(drone.base_world_m),
            floor_contact=drone.floor_contact,
            taut=drone.taut,
            armed=drone.armed,
            on_ground=drone.on_ground,
            phase=self.scenario.name,
        )
        out.append(Sample(f"tether/{drone_id}/truth", truth.to_json()))
        if publish_reel and self.scenario.coin_mass_kg is None and not self.untethered:
            reel: dict[str, object] = {
                "stamp_s": round(self.t_s, 9),
                "length_m": drone.length_m,
                "base_m": drone.base_world_m.tolist(),
            }
            if cfg.exit_angles:
                from groundstation.catenary import tether_points

                pts = tether_points(
                    drone.base_world_m, drone.position_world_m, drone.length_m, drone.floor_z_m, 257
                )
                reel |= self._exit_angles(pts)
            out.append(Sample(f"tether/{drone_id}/reel", json.dumps(reel).encode()))
        return out

    def _exit_angles(self, points_world_m: np.ndarray) -> dict[str, float]:
        """The base sensor's Reel fields ([sim] exit_angles; groundstation/sim/base_sensor.py)."""
        from groundstation.sim.base_sensor import exit_angle_fields

        cfg = self.settings.sim
        return exit_angle_fields(
            points_world_m, self._base_rng, cfg.exit_azimuth_noise_rad, cfg.exit_elevation_noise_rad
        )

    def _realistic_messages(
        self,
        drone_id: str,
        drone: RealisticDrone,
        due: list[dict[str, Any]],
        publish_reel: bool,
    ) -> list[Sample]:
        out: list[Sample] = []
        for item in due:
            payload = json.dumps(item["telemetry"]).encode()
            out.append(Sample(f"tether/{drone_id}/telemetry", payload))
            tr = item["truth"]
            errors = None
            last = self._errors_sent_s.get(drone_id)
            if last is None or tr["stamp_s"] >= last + 1.0:
                self._errors_sent_s[drone_id] = tr["stamp_s"]
                errors = drone.drawn_errors()
            truth = Truth(
                stamp_s=tr["stamp_s"],
                position_m=_v3(tr["position_m"]),
                velocity_mps=_v3(tr["velocity_mps"]),
                tension_n=_v3(tr["tension_n"]),
                length_m=tr["length_m"],
                base_m=_v3(tr["base_m"]),
                floor_contact=tr["floor_contact"],
                taut=tr["taut"],
                armed=tr["armed"],
                on_ground=tr["on_ground"],
                phase=self.scenario.name,
                profile="realistic",
                errors=errors,
            )
            out.append(Sample(f"tether/{drone_id}/truth", truth.to_json()))
        if publish_reel and self.scenario.coin_mass_kg is None and not self.untethered:
            reel: dict[str, object] = {
                "stamp_s": round(self.t_s, 9),
                "length_m": drone.length_m,
                "base_m": drone.base_world_m.tolist(),
            }
            if self.settings.sim.exit_angles:
                reel |= self._exit_angles(drone.tether.x_world_m)
            out.append(Sample(f"tether/{drone_id}/reel", json.dumps(reel).encode()))
        return out

    def run(self, on_step: Callable[[float], None] | None = None) -> None:
        """Run in scaled real time until stopped or the duration is over."""
        cfg = self.settings.sim
        duration = cfg.duration_s if cfg.duration_s is not None else None
        period_s = self.dt_s / cfg.speed
        next_wall = time.monotonic()
        while not self._stop.is_set():
            if duration is not None and self.t_s >= duration:
                return
            for sample in self.step():
                self.bus.publish(sample.key, sample.payload)
            if on_step is not None:
                on_step(self.t_s)
            next_wall += period_s
            delay = next_wall - time.monotonic()
            if delay > 0:
                self._stop.wait(delay)
            elif delay < -0.5:
                next_wall = time.monotonic()  # fell behind: do not burst to catch up


def _v3(a: Any) -> tuple[float, float, float]:
    return (float(a[0]), float(a[1]), float(a[2]))
