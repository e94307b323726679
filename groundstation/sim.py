"""Simulator of tethered drones that speaks the public contract (an edge: bus only).

Physics (:class:`DroneSim`, pure apart from its random generator): a point-mass quadrotor
whose attitude follows its thrust vector, a position controller with integral action (so it
holds position against the tether), the quasi-static catenary force of
:func:`groundstation.catenary.tether_force` (floor contact included) with a taut stop, a
floor, scripted external pulls (tugs), and sensor models: accelerometer noise, thrust noise
and bias, optional motion-capture position.

:class:`Simulator` runs scenarios in (scaled) real time on a :class:`~groundstation.bus.Bus`:
it publishes ``tether/{drone}/telemetry``, ``tether/{drone}/reel`` and the ground truth
``tether/{drone}/truth``, and obeys ``cmd/setpoint`` and ``cmd/stop``.
"""

from __future__ import annotations

import json
import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from groundstation.bus import Bus, Sample, Subscription
from groundstation.catenary import TetherTooShortError, tether_force
from groundstation.config import Settings
from groundstation.messages import InvalidMessage, SetpointIn, StopIn, Truth
from groundstation.tension import rotation_world_body

__all__ = [
    "PAPER_HOVER_SPOTS_M",
    "SCENARIOS",
    "DroneSim",
    "Pull",
    "Scenario",
    "Simulator",
    "scenario_names",
]

_log = logging.getLogger("groundstation.sim")
GRAVITY_MPS2 = 9.81
_G_WORLD = np.array([0.0, 0.0, -GRAVITY_MPS2])
_E3 = np.array([0.0, 0.0, 1.0])

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
        start_m: initial drone position (on the floor when ``start_on_ground``).
        waypoints: controller targets over time (the service's Setpoints override them).
        pulls: external pulls (tugs).
        base_m: base exit point, or None for the configured one.
        length_m: tether length at t = 0, or None for the configured one.
        reel_rate_mps: reel speed (negative reels in) over ``reel_window_s``.
        arm_at_s: arming time (before it the drone sits disarmed on the floor).
        coin_mass_kg: the paper's horizontal-tension bench: a thread over an arm at
            ``coin_arm_m`` with this mass hanging replaces the tether.
        operator: scripted FollowCommands ``(at_s, payload)``, published by the simulator
            as an operator would.
        duration_s: natural length of the scenario (None: run until stopped).
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


def quat_wxyz_from_z_axis(z_world: np.ndarray) -> np.ndarray:
    """Body→world quaternion (zero yaw) whose body +z is the unit vector ``z_world``."""
    z = z_world / np.linalg.norm(z_world)
    w = math.sqrt(max(0.0, (1.0 + z[2]) / 2.0))
    if w < 1e-9:  # upside down: rotate pi about x
        return np.array([0.0, 1.0, 0.0, 0.0])
    # q = [cos(θ/2), sin(θ/2)·axis], axis = e3 × z / |e3 × z|, cosθ = z_z
    return np.array([w, -z[1] / (2.0 * w), z[0] / (2.0 * w), 0.0])


@dataclass
class DroneSim:
    """One drone on its tether, stepped with a fixed ``dt_s`` (semi-implicit Euler).

    Units: SI; world frame z up. The tether force is quasi-static (the tether's own
    dynamics are ignored, as in the paper). Near taut the catenary force grows steeply; it is
    capped at ``tension_cap_n`` (the real tether stretches) and the drone cannot leave the
    sphere of radius ``length_m`` around the base (taut stop).
    """

    base_world_m: np.ndarray
    length_m: float
    weight_n_per_m: float
    floor_z_m: float
    mass_kg: float = 0.030
    position_world_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    velocity_world_mps: np.ndarray = field(default_factory=lambda: np.zeros(3))
    target_world_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    armed: bool = True
    kp_per_s2: float = 16.0
    kd_per_s: float = 7.0
    ki_per_s3: float = 8.0
    max_tilt_rad: float = math.radians(35.0)
    max_thrust_ratio: float = 2.5
    tension_cap_n: float = 2.0
    substeps: int = 2
    coin_mass_kg: float | None = None
    coin_arm_m: np.ndarray | None = None
    offset_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """Where the scenario's script is shifted to (several drones fly side by side)."""
    # outputs of the last step
    integral_m_s: np.ndarray = field(default_factory=lambda: np.zeros(3))
    thrust_n: float = 0.0
    quat_wxyz: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))
    specific_force_body_mps2: np.ndarray = field(
        default_factory=lambda: np.array([0.0, 0.0, GRAVITY_MPS2])
    )
    tension_world_n: np.ndarray = field(default_factory=lambda: np.zeros(3))
    floor_contact: bool = False
    taut: bool = False
    on_ground: bool = False

    def _tether(self, position_world_m: np.ndarray) -> tuple[np.ndarray, bool, bool]:
        if self.coin_mass_kg is not None and self.coin_arm_m is not None:
            # The coin bench: a weightless thread over an arm, T = m_coin·g toward the arm.
            d = self.coin_arm_m - position_world_m
            return d / np.linalg.norm(d) * (self.coin_mass_kg * GRAVITY_MPS2), False, False
        chord = position_world_m - self.base_world_m
        if float(np.linalg.norm(chord)) >= self.length_m * (1.0 - 1e-6):
            return self._taut_force(chord), False, True
        try:
            tf = tether_force(
                self.base_world_m,
                position_world_m,
                self.length_m,
                self.weight_n_per_m,
                self.floor_z_m,
            )
        except TetherTooShortError:
            return self._taut_force(chord), False, True
        force = np.asarray(tf.force_world_n, dtype=float)
        norm = float(np.linalg.norm(force))
        if norm > self.tension_cap_n:
            return force * (self.tension_cap_n / norm), bool(tf.floor_contact), True
        return force, bool(tf.floor_contact), False

    def _taut_force(self, chord: np.ndarray) -> np.ndarray:
        n = float(np.linalg.norm(chord))
        return -chord / n * self.tension_cap_n if n > 0 else np.zeros(3)

    def _control(self, dt_s: float) -> tuple[float, np.ndarray]:
        """Thrust (N) and body z axis (world) from the position controller."""
        if not self.armed:
            self.integral_m_s[:] = 0.0
            return 0.0, self.quat_axis()
        err = self.target_world_m - self.position_world_m
        if not self.on_ground:
            self.integral_m_s += err * dt_s
            np.clip(self.integral_m_s, -2.0, 2.0, out=self.integral_m_s)
        acc = self.kp_per_s2 * err - self.kd_per_s * self.velocity_world_mps
        acc += self.ki_per_s3 * self.integral_m_s
        force = self.mass_kg * (acc - _G_WORLD)
        # Limit the tilt: keep the vertical part, shrink the horizontal part.
        horiz = math.hypot(force[0], force[1])
        max_horiz = max(force[2], 0.0) * math.tan(self.max_tilt_rad)
        if horiz > max_horiz and horiz > 0:
            force[:2] *= max_horiz / horiz
        thrust = float(np.linalg.norm(force))
        max_thrust = self.max_thrust_ratio * self.mass_kg * GRAVITY_MPS2
        if thrust < 1e-9:
            return 0.0, _E3.copy()
        return min(thrust, max_thrust), force / thrust

    def quat_axis(self) -> np.ndarray:
        return rotation_world_body(self.quat_wxyz)[:, 2]

    def step(self, dt_s: float, external_force_world_n: np.ndarray) -> None:
        """Advance by ``dt_s``: control, forces, contact, integration, sensor truth."""
        h = dt_s / self.substeps
        for _ in range(self.substeps):
            thrust, z_axis = self._control(h)
            if self.armed:
                self.quat_wxyz = quat_wxyz_from_z_axis(z_axis)
            tension, floor_contact, taut = self._tether(self.position_world_m)
            force = thrust * z_axis + tension + external_force_world_n
            force = force + self.mass_kg * _G_WORLD
            # The floor: it pushes back while the drone rests on it.
            on_floor = self.position_world_m[2] <= self.floor_z_m + 1e-9
            normal = np.zeros(3)
            if on_floor and force[2] <= 0.0:
                normal[2] = -force[2]
                force = force + normal
                self.velocity_world_mps[:] = 0.0
                # friction holds it in place horizontally
                normal[:2] = -force[:2]
                force[:2] = 0.0
            accel = force / self.mass_kg
            self.velocity_world_mps += accel * h
            self.position_world_m += self.velocity_world_mps * h
            if self.position_world_m[2] < self.floor_z_m:
                self.position_world_m[2] = self.floor_z_m
                self.velocity_world_mps[2] = max(0.0, self.velocity_world_mps[2])
            chord = self.position_world_m - self.base_world_m
            dist = float(np.linalg.norm(chord))
            reach = self.length_m * (1.0 - 1e-6)
            if dist > reach and self.coin_mass_kg is None:
                # Taut stop: the tether does not stretch; drop the outward velocity.
                u = chord / dist
                self.position_world_m = self.base_world_m + u * reach
                radial = float(self.velocity_world_mps @ u)
                if radial > 0:
                    self.velocity_world_mps -= radial * u
                taut = True
            self.on_ground = bool(on_floor and normal[2] > 0.0)
            self.thrust_n = thrust
            self.tension_world_n = tension
            self.floor_contact = floor_contact
            self.taut = taut
            # Specific force f = R'(p'' - g) = R'(F_total_non_gravity)/m (NOTES.md).
            R = rotation_world_body(self.quat_wxyz)
            self.specific_force_body_mps2 = R.T @ (accel - _G_WORLD)


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
        self.rng = np.random.default_rng(settings.sim.seed)
        self.dt_s = 1.0 / settings.sim.rate_hz
        self.t_s = 0.0
        self.seq = 0
        self.drones: dict[str, DroneSim] = {}
        self._operator_done: set[int] = set()
        self._handles: list[Subscription] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._commands: list[tuple[str, str, bytes]] = []
        self._cmd_lock = threading.Lock()
        self.stops_received: dict[str, str] = {}
        for i, drone_id in enumerate(settings.sim.drones):
            self.drones[drone_id] = self._make_drone(drone_id, i)

    def _make_drone(self, drone_id: str, index: int) -> DroneSim:
        params = self.settings.for_drone(drone_id)
        sc = self.scenario
        base = np.array(sc.base_m if sc.base_m is not None else params.base.position_m, float)
        # Several drones fly the same script, each about its own base: spread them out.
        offset = np.array([0.0, 3.0 * index, 0.0])
        if drone_id in self.settings.drones:
            offset[:] = 0.0  # placed by its own [drones.<id>] table
        base = base + offset
        start = np.array(sc.start_m, float) + offset
        floor = params.base.floor_z_m
        if sc.start_on_ground:
            start[2] = floor
        drone = DroneSim(
            base_world_m=base,
            length_m=sc.length_m if sc.length_m is not None else params.tether.length_m,
            weight_n_per_m=params.tether.weight_n_per_m,
            floor_z_m=floor,
            mass_kg=params.drone.mass_kg,
            position_world_m=start,
            target_world_m=start.copy(),
            armed=not sc.start_on_ground,
            coin_mass_kg=sc.coin_mass_kg,
            coin_arm_m=np.array(sc.coin_arm_m, float) + offset
            if sc.coin_mass_kg is not None
            else None,
        )
        drone.offset_m = offset
        if not sc.start_on_ground:
            # Start in equilibrium: pre-load the integral with the tether's pull.
            tension, _, _ = drone._tether(start)
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

    def _scripted(self, drone: DroneSim) -> np.ndarray:
        """Apply the scenario's script at ``self.t_s``; return the external force."""
        sc = self.scenario
        t = self.t_s
        period = sc.duration_s if sc.name == "hover_spots" and sc.duration_s else None
        t_wp = t % period if period else t
        offset = drone.offset_m
        for wp in sc.waypoints:
            if wp.at_s <= t_wp < wp.at_s + self.dt_s * 0.999 or (t == 0.0 and wp.at_s == 0.0):
                drone.target_world_m = np.array(wp.position_m, float) + offset
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
            drone.step(self.dt_s, external)
            out.extend(self._messages(drone_id, drone, external, publish_reel))
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
            length_m=drone.length_m,
            base_m=_v3(drone.base_world_m),
            floor_contact=drone.floor_contact,
            taut=drone.taut,
            armed=drone.armed,
            on_ground=drone.on_ground,
            phase=self.scenario.name,
        )
        out.append(Sample(f"tether/{drone_id}/truth", truth.to_json()))
        if publish_reel and self.scenario.coin_mass_kg is None:
            reel = {
                "stamp_s": round(self.t_s, 9),
                "length_m": drone.length_m,
                "base_m": drone.base_world_m.tolist(),
            }
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


def _v3(a: np.ndarray) -> tuple[float, float, float]:
    return (float(a[0]), float(a[1]), float(a[2]))
