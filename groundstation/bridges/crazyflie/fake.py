"""TEST SUPPORT, NOT A DRONE: a fake :class:`~groundstation.bridges.crazyflie.link.Link`.

It plays Crazyflie log packets (firmware units, 24-bit millisecond timestamps, one callback per
log block as cflib delivers them) and records every command it receives. Unit tests drive it
by hand (:meth:`FakeLink.emit`, :meth:`FakeLink.lose`); ``groundstation crazyflie --uri
fake://SCENARIO`` plays a scenario in real time so that integration tests can run the real
bridge process without a drone. Options ride on the URI's query::

    fake://hover?record=/tmp/cmds.jsonl&drop_after_s=2&down_s=1&missing=pm.vbat&ooo=1

``hover``: level, the tether pulling 0.05 N down, flying at ``start_m`` on the drone's own
(onboard) controller until the first low-level setpoint; ``tug``: the same pulled 0.2 N down;
``floor``: on the floor, motors off, until a setpoint spins them up.

What the firmware does with what it receives (:class:`FirmwareModel`, on the host's monotonic
clock): position setpoints are followed at the position controller's speed limit (1 m/s per
axis, ``PID_POS_VEL_*_MAX``); the commander watchdog levels the drone 0.5 s after the last
setpoint (x/y no longer controlled, z held) and 2 s after it switches the motors off and locks
the supervisor; the supervisor's emergency stop (``stop_motors``) switches the motors off and
locks until a power cycle (an arming request does not unlock); a stop setpoint switches the
motors off without a lock; motors off above the floor is a fall (the speed at the floor is
kept in ``impacts_mps``); the battery sags with flight time and under load.
``record`` appends one JSON line per call; ``drop_after_s`` loses the link once after that many
seconds of playback and refuses to reconnect for ``down_s``; ``firmware`` picks the log TOC of
:data:`FIRMWARE_TOCS` (``current``, the default, or ``2022``); ``missing`` drops variables
from it; ``refuse`` refuses (as the firmware's ``ENOMEM``) every log block holding one of the
named variables; ``ooo`` repeats an old timestamp every 25th period (out-of-order packets);
``positioning`` (``lighthouse``, ``loco``, ``flow``) gives the drone that deck, which its Kalman
estimator fuses (:class:`FirmwareModel`: a reset, variances that settle, ``stateEstimate``
following the position with the deck's noise). Parameters (:data:`FAKE_PARAMS`) are set with
``set_param``; several fakes run side by side, each its own drone.
"""

from __future__ import annotations

import json
import math
import threading
import time
from collections import deque
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlparse

import numpy as np

from groundstation.bridges.crazyflie.link import (
    DataHandler,
    LinkError,
    LogBlock,
    LogBlockRefused,
    LostHandler,
)

__all__ = [
    "FAKE_PARAMS",
    "FAKE_SCENARIOS",
    "FAKE_TOC",
    "FIRMWARE_TOCS",
    "FakeLink",
    "FirmwareModel",
    "pwm_for_thrust",
]

_COMMON_TOC: Mapping[str, str] = {
    **{f"acc.{a}": "float" for a in "xyz"},
    **{f"gyro.{a}": "float" for a in "xyz"},
    **{f"stateEstimate.q{a}": "float" for a in "wxyz"},
    **{f"motor.m{i}": "uint32_t" for i in range(1, 5)},
    "pm.vbat": "float",
    "supervisor.info": "uint16_t",
    **{f"stateEstimate.{a}": "float" for a in "xyz"},
    **{f"kalman.var{a}": "float" for a in ("X", "Y", "Z", "PX", "PY", "PZ")},
}
FIRMWARE_TOCS: Mapping[str, Mapping[str, str]] = {
    # motors.c logs ``motor.m*`` (the ratios written to the timers, after the stabilizer's
    # battery compensation); there is no ``pwm`` group.
    "current": dict(_COMMON_TOC),
    # ``motor.m*`` from the power distribution (the request, before the compensation in
    # motorsSetRatio) and ``pwm.m*_pwm`` from motors.c (the duty after it).
    "2022": {**_COMMON_TOC, **{f"pwm.m{i}_pwm": "uint32_t" for i in range(1, 5)}},
}
"""Crazyflie 2.x log TOCs, reduced to what the bridge may ask for (C types as in the firmware:
``motor.m*`` and ``pwm.m*_pwm`` are ``uint32_t``, ``supervisor.info`` ``uint16_t``): current
firmware, and firmware of about 2021–2022 (the bridge's docstring and docs/real-lab.md say
which battery compensation each motor variable carries)."""
FAKE_TOC: Mapping[str, str] = FIRMWARE_TOCS["current"]
"""The fake's default TOC: current firmware."""

FAKE_SCENARIOS: Mapping[str, float] = {"hover": 0.05, "tug": 0.20, "floor": 0.05}
"""Scenario → downward pull of the tether on the drone, N."""

COMMANDER_LEVEL_S = 0.5
"""Firmware ``COMMANDER_WDT_TIMEOUT_STABILIZE``: no setpoint for this long, the drone levels."""
COMMANDER_SHUTDOWN_S = 2.0
"""Firmware ``COMMANDER_WDT_TIMEOUT_SHUTDOWN``: no setpoint for this long, motors off (and, in
current firmware, the supervisor locks)."""
POS_VEL_MAX_MPS = 1.0
"""Firmware ``PID_POS_VEL_{X,Y,Z}_MAX``: the position controller's speed limit per axis."""
G_MPS2 = 9.81
_STEP_S = 0.002

FAKE_PARAMS: Mapping[str, float] = {
    "stabilizer.estimator": 0.0,
    "kalman.resetEstimation": 0.0,
    "kalman.initialX": 0.0,
    "kalman.initialY": 0.0,
    "kalman.initialZ": 0.0,
    "kalman.initialYaw": 0.0,
    "locSrv.extPosStdDev": 0.01,
    "locSrv.extQuatStdDev": 4.5e-3,
}
"""The writable parameters the fake has, with the firmware's defaults (``stabilizer.estimator``
0: automatic, the complementary estimator unless a positioning deck asks for the Kalman)."""

POSITIONING_STD_M: Mapping[str, tuple[float, float, float]] = {
    "lighthouse": (0.002, 0.002, 0.002),
    "loco": (0.04, 0.04, 0.06),
    "flow": (10.0, 10.0, 0.005),
}
"""What the fake's Kalman variance settles to with each deck, as σ per axis, m (a Flow deck
measures velocity and height: its x/y is odometry, the variance stays at the firmware's bound
of 100 m²)."""
KALMAN_MAX_VAR = 100.0
"""The firmware's covariance bound (kalman_core.c ``MAX_COVARIANCE``)."""
KALMAN_POS_TAU_S = 0.1
"""How fast the fake's position estimate and variance close on a measured position, s."""
KALMAN_POS_VAR_TAU_S = 0.05
"""How fast the position variance falls from the reset's 100 m² once positions are measured
(the first measurements collapse it), s."""
KALMAN_VEL_TAU_S = 0.5
"""How fast the fake's velocity variances settle once positions are measured, s."""
KALMAN_VEL_VAR_SS = 2e-4
"""The velocity variance they settle to, m²/s²."""
KALMAN_VEL_VAR_RESET = 0.01
"""The velocity variance just after a reset, once the first positions pull the state, m²/s²."""
KALMAN_VAR_GROWTH = 0.05
"""Growth of the variances per second without position measurements, m²(/s²) per s."""
EXTPOS_FRESH_S = 0.1
"""An external pose older than this is no measurement to the fake's estimator, s."""


class FirmwareModel:
    """What a Crazyflie's firmware does with the setpoints it receives (module docstring).

    Args:
        start_m: where the drone is, world frame, m.
        flying: it flies there on its own (onboard) controller until the first setpoint.
        floor_z_m: the floor.
        clock: host monotonic clock, s.
        positioning: the deck the Kalman estimator fuses (``none``: only external poses).

    The Kalman estimator runs when ``stabilizer.estimator`` is 2 or a deck asks for it. A reset
    (``kalman.resetEstimation``) puts its position at ``kalman.initialX/Y/Z`` with variance
    100 m² (the firmware's bound) and its velocity variances at a transient of 0.01 m²/s²; while
    positions are measured (a deck, or an external pose within 0.1 s) the position closes on the
    measured one (its variance on the measurement's) and the velocity variances settle to
    2e-4 m²/s² (time constants 0.1 s, 0.05 s and 0.5 s); without measurements every variance
    grows by 0.05 per second. A Flow deck measures height and velocity: z closes on the truth,
    x/y follow the motion since the reset (odometry) and their variance stays at 100 m².
    ``stateEstimate`` jitters about the estimate with its σ, at most 1 cm.
    """

    def __init__(
        self,
        start_m: Sequence[float] = (0.0, 0.0, 0.5),
        *,
        flying: bool = True,
        floor_z_m: float = 0.0,
        clock: Any = time.monotonic,
        positioning: str = "none",
    ) -> None:
        if positioning not in ("none", *POSITIONING_STD_M):
            raise ValueError(
                f"positioning {positioning!r}: none or one of {sorted(POSITIONING_STD_M)}"
            )
        self._clock = clock
        self.floor_z_m = floor_z_m
        self.position_m = np.array(start_m, dtype=float)
        self.vz_mps = 0.0
        self.motors_on = flying
        self.locked = False
        self.target_m: np.ndarray | None = None
        self.last_setpoint_s: float | None = None
        self.mode = "onboard" if flying else "off"
        """``onboard``, ``position``, ``level``, ``off``."""
        self.impacts_mps: list[float] = []
        """Vertical speed at each arrival on the floor with the motors off (a fall), m/s."""
        self.track: deque[tuple[float, float, float, float]] = deque(maxlen=100_000)
        """``(t_s, x_m, y_m, z_m)`` at each update (the latest 100 000)."""
        self.flight_s = 0.0
        self.positioning = positioning
        """The deck the onboard estimator fuses: ``none``, ``lighthouse``, ``loco``, ``flow``."""
        self.params = dict(FAKE_PARAMS)
        self.kalman_position_m = np.zeros(3)
        """The Kalman estimator's position (``stateEstimate.x/y/z`` while it runs), m."""
        self.kalman_var_pos = np.full(3, KALMAN_MAX_VAR)
        self.kalman_var_vel = np.zeros(3)
        """Zero until the Kalman estimator runs (static memory), as ``kalman.var*`` read."""
        self.resets = 0
        self.extpos: tuple[float, np.ndarray] | None = None
        """``(t_s, position_m)`` of the latest external pose received."""
        self._odometry_origin_m = np.zeros(3)
        self._t = clock()
        self._lock = threading.Lock()

    def vbat_v(self) -> float:
        """Battery: 4.15 V at rest, 0.2 V less under hover load, 0.01 V less per flight
        minute (a 250 mAh cell over a 7-minute flight)."""
        load = 0.2 if self.motors_on else 0.0
        return 4.15 - load - 0.01 * self.flight_s / 60.0

    def advance(self) -> None:
        """Bring the state to the clock's now."""
        with self._lock:
            now = self._clock()
            while self._t < now:
                dt = min(_STEP_S, now - self._t)
                self._t += dt
                self._step(dt)
            x, y, z = self.position_m
            self.track.append((now, float(x), float(y), float(z)))

    @property
    def kalman_running(self) -> bool:
        return self.params["stabilizer.estimator"] == 2.0 or self.positioning != "none"

    def _measured_m(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The position measured now and its σ per axis, or None (no measurement)."""
        if self.positioning in ("lighthouse", "loco"):
            return self.position_m, np.array(POSITIONING_STD_M[self.positioning])
        if self.positioning == "flow":
            odometry = self._odometry_origin_m + self.position_m
            odometry[2] = self.position_m[2]
            return odometry, np.array(POSITIONING_STD_M["flow"])
        if self.extpos is not None and self._t - self.extpos[0] <= EXTPOS_FRESH_S:
            std = self.params["locSrv.extPosStdDev"]
            return self.extpos[1], np.array([std, std, std])
        return None

    def _step_kalman(self, dt: float) -> None:
        if not self.kalman_running:
            return
        measured = self._measured_m()
        if measured is None:
            self.kalman_var_pos = np.minimum(
                self.kalman_var_pos + KALMAN_VAR_GROWTH * dt, KALMAN_MAX_VAR
            )
            self.kalman_var_vel = np.minimum(
                self.kalman_var_vel + KALMAN_VAR_GROWTH * dt, KALMAN_MAX_VAR
            )
            return
        position_m, std_m = measured
        k = min(1.0, dt / KALMAN_POS_TAU_S)
        self.kalman_position_m = self.kalman_position_m + k * (position_m - self.kalman_position_m)
        var_ss = np.minimum(std_m * std_m, KALMAN_MAX_VAR)
        kp = min(1.0, dt / KALMAN_POS_VAR_TAU_S)
        self.kalman_var_pos = self.kalman_var_pos + kp * (var_ss - self.kalman_var_pos)
        kv = min(1.0, dt / KALMAN_VEL_TAU_S)
        self.kalman_var_vel = self.kalman_var_vel + kv * (KALMAN_VEL_VAR_SS - self.kalman_var_vel)

    def reset_estimator(self) -> None:
        """``kalman.resetEstimation``: the Kalman estimator starts again (class docstring)."""
        self.advance()
        with self._lock:
            p = self.params
            initial = np.array([p["kalman.initialX"], p["kalman.initialY"], p["kalman.initialZ"]])
            self.kalman_position_m = initial.copy()
            self.kalman_var_pos = np.array([KALMAN_MAX_VAR, KALMAN_MAX_VAR, 1.0])
            self.kalman_var_vel = np.full(3, KALMAN_VEL_VAR_RESET)
            # odometry from here: the initial position plus the motion since now
            self._odometry_origin_m = initial - self.position_m
            self.resets += 1

    def on_extpos(self, position_m: Sequence[float]) -> None:
        self.advance()
        with self._lock:
            self.extpos = (self._t, np.array(position_m, dtype=float))

    def _step(self, dt: float) -> None:
        self._step_kalman(dt)
        if self.motors_on and self.last_setpoint_s is not None:
            age = self._t - self.last_setpoint_s
            if age > COMMANDER_SHUTDOWN_S:
                self.motors_on, self.locked, self.mode = False, True, "off"
            elif age > COMMANDER_LEVEL_S:
                self.mode = "level"
        if not self.motors_on:
            z = self.position_m[2]
            if z > self.floor_z_m or self.vz_mps > 0:
                self.vz_mps -= G_MPS2 * dt
                self.position_m[2] = z + self.vz_mps * dt
                if self.position_m[2] <= self.floor_z_m:
                    self.impacts_mps.append(-self.vz_mps)
                    self.position_m[2] = self.floor_z_m
                    self.vz_mps = 0.0
            return
        self.flight_s += dt
        if self.target_m is None:
            self.vz_mps = 0.0
            return  # the onboard controller holds
        step = self.target_m - self.position_m
        if self.mode == "level":
            step[:2] = 0.0  # x/y no longer controlled; z still held
        step = np.clip(step, -POS_VEL_MAX_MPS * dt, POS_VEL_MAX_MPS * dt)
        self.position_m = self.position_m + step
        if self.position_m[2] < self.floor_z_m:
            self.position_m[2] = self.floor_z_m  # pushing into the floor
        self.vz_mps = float(step[2]) / dt

    def on_position_setpoint(self, x_m: float, y_m: float, z_m: float) -> None:
        self.advance()
        if self.locked:
            return
        self.target_m = np.array([x_m, y_m, z_m], dtype=float)
        self.last_setpoint_s = self._clock()
        self.motors_on, self.mode = True, "position"

    def on_stop_setpoint(self) -> None:
        self.advance()
        self.motors_on, self.mode, self.target_m = False, "off", None
        self.last_setpoint_s = None

    def on_emergency_stop(self) -> None:
        self.advance()
        self.motors_on, self.locked, self.mode, self.target_m = False, True, "off", None
        self.last_setpoint_s = None

    def power_cycle(self) -> None:
        """The only way out of Locked."""
        self.advance()
        self.locked = False

    @property
    def on_floor(self) -> bool:
        return bool(self.position_m[2] <= self.floor_z_m + 1e-9)


_ARMED_INFO = 0b1011  # can be armed, is armed, can fly
_DISARMED_INFO = 0b0001


def pwm_for_thrust(thrust_per_motor_n: float, thrust_map: Sequence[float]) -> float:
    """Inverse of ``a·pwm² + b·pwm + c``: the pwm giving this thrust per motor."""
    a, b, c = thrust_map
    if a == 0:
        return (thrust_per_motor_n - c) / b
    return (-b + math.sqrt(b * b - 4 * a * (c - thrust_per_motor_n))) / (2 * a)


class FakeLink:
    """A scripted Crazyflie for tests (see the module docstring).

    Args:
        uri: ``fake://SCENARIO[?options]`` (only used by :meth:`start_player`).
        mass_kg: the fake drone's mass.
        thrust_map: the map the bridge uses, inverted to produce motor values.
        toc: the TOC to report (default: the ``firmware`` option's, :data:`FAKE_TOC` without
            it, less ``missing``).
        seed: noise seed.
        realtime: play the scenario on a thread once logging starts (the CLI's fake).
    """

    def __init__(
        self,
        uri: str = "fake://hover",
        *,
        mass_kg: float = 0.030,
        thrust_map: Sequence[float] = (2.130295e-11, 1.032633e-6, 5.484560e-4),
        toc: Mapping[str, str] | None = None,
        seed: int = 0,
        realtime: bool = False,
        start_m: Sequence[float] = (0.0, 0.0, 0.5),
    ) -> None:
        self.uri = uri
        parsed = urlparse(uri)
        query = {k: v[-1] for k, v in parse_qs(parsed.query).items()}
        self.scenario = parsed.netloc or "hover"
        if self.scenario not in FAKE_SCENARIOS:
            raise LinkError(f"fake scenario {self.scenario!r}: one of {sorted(FAKE_SCENARIOS)}")
        firmware = query.get("firmware", "current")
        if firmware not in FIRMWARE_TOCS:
            raise LinkError(f"fake firmware {firmware!r}: one of {sorted(FIRMWARE_TOCS)}")
        missing = [m for m in query.get("missing", "").split(",") if m]
        self.toc = dict(toc if toc is not None else FIRMWARE_TOCS[firmware])
        for name in missing:
            self.toc.pop(name, None)
        self.refuse = frozenset(m for m in query.get("refuse", "").split(",") if m)
        self.record_path = Path(query["record"]) if "record" in query else None
        self.drop_after_s = float(query["drop_after_s"]) if "drop_after_s" in query else None
        self.down_s = float(query.get("down_s", "1.0"))
        self.out_of_order = query.get("ooo", "0") == "1"
        self.realtime = realtime
        self.mass_kg = mass_kg
        self.thrust_map = tuple(thrust_map)
        self.commands: list[tuple[str, tuple[Any, ...]]] = []
        self.opens = 0
        positioning = query.get("positioning", "none")
        try:
            self.firmware = FirmwareModel(
                start_m if self.scenario != "floor" else (start_m[0], start_m[1], 0.0),
                flying=self.scenario != "floor",
                positioning=positioning,
            )
        except ValueError as exc:
            raise LinkError(f"fake {exc}") from None
        self.extpos_times: list[float] = []
        """Host clock of each external pose received."""
        self._rng = np.random.default_rng(seed)
        self._lock = threading.Lock()
        self._on_lost: LostHandler | None = None
        self._on_data: DataHandler | None = None
        self._blocks: tuple[LogBlock, ...] = ()
        self._open = False
        self._down_until = -math.inf
        self._dropped = False
        self._player: threading.Thread | None = None
        self._stop_player = threading.Event()
        self._clock_ms = 5000

    # ------------------------------------------------------------------ Link interface

    def open(self, on_lost: LostHandler, timeout_s: float) -> Mapping[str, str]:
        self._record("open")
        if time.monotonic() < self._down_until:
            raise LinkError(f"no answer from {self.uri} (fake: link down)")
        with self._lock:
            self._on_lost = on_lost
            self._open = True
            self.opens += 1
        return dict(self.toc)

    def start_logging(
        self, blocks: Sequence[LogBlock], on_data: DataHandler, timeout_s: float = 10.0
    ) -> None:
        for block in blocks:
            for var in block.variables:
                if var not in self.toc:
                    raise LinkError(f"log block {block.name}: Variable {var} not in TOC")
            if block.size_bytes > 26 or block.period_ms % 10:
                raise LinkError(f"log block {block.name} too large or bad period")
            if self.refuse.intersection(block.variables):
                self._record("refused", block.name)
                raise LogBlockRefused(self.uri, block, "No more memory available")
        self._record("start_logging", *[b.name for b in blocks])
        with self._lock:
            self._blocks = tuple(blocks)
            self._on_data = on_data
        if self.realtime:
            self.start_player()

    def send_position_setpoint(self, x_m: float, y_m: float, z_m: float, yaw_deg: float) -> None:
        self.firmware.on_position_setpoint(x_m, y_m, z_m)
        self._record("send_position_setpoint", x_m, y_m, z_m, yaw_deg)

    def stop_motors(self) -> None:
        self.firmware.on_emergency_stop()
        self._record("stop_motors")

    def send_stop_setpoint(self) -> None:
        self.firmware.on_stop_setpoint()
        self._record("send_stop_setpoint")

    def arm(self) -> None:
        # An arming request: the supervisor stays Locked after an emergency stop.
        self._record("arm")

    @property
    def motors_stopped(self) -> bool:
        """The motors are off (a stop, a watchdog, or never started)."""
        return not self.firmware.motors_on

    def send_extpos(self, position_m: Sequence[float], quat_wxyz: Sequence[float] | None) -> None:
        self.extpos_times.append(time.monotonic())
        self.firmware.on_extpos(position_m)
        self._record("send_extpos", *position_m)

    def set_param(self, name: str, value: float) -> None:
        fw = self.firmware
        if name not in fw.params:
            raise LinkError(f"{self.uri}: cannot set parameter {name}: '{name} not in param TOC'")
        self._record("set_param", name, value)
        fw.advance()
        fw.params[name] = float(value)
        if name == "kalman.resetEstimation" and value:
            fw.reset_estimator()
            fw.params[name] = 0.0  # the firmware clears the flag once it has reset

    def close(self) -> None:
        with self._lock:
            if self._open:
                # cflib's close_link() sends a zero setpoint on an open link: motors off.
                self.firmware.on_stop_setpoint()
        self._stop_player.set()
        player = self._player
        if player is not None and player is not threading.current_thread():
            player.join(2.0)
        self._player = None
        with self._lock:
            was_open, self._open = self._open, False
        if was_open:
            self._record("close")

    # ------------------------------------------------------------------ test driving

    def emit(self, block: str, timestamp_ms: int, values: Mapping[str, float]) -> None:
        """Deliver one log packet of ``block`` (timestamp wraps at 24 bits, as on the wire)."""
        with self._lock:
            handler = self._on_data if self._open else None
        if handler is not None:
            handler(block, int(timestamp_ms) % (1 << 24), dict(values))

    def lose(self, reason: str = "fake: too many packets lost") -> None:
        """Drop the link, as cflib's ``connection_lost`` does."""
        with self._lock:
            handler, self._on_lost = self._on_lost, None
            self._open = False
        self._record("lost", reason)
        if handler is not None:
            handler(reason)

    def values(self) -> dict[str, float]:
        """One sample of every TOC variable for the scenario (firmware units)."""
        pull_n = FAKE_SCENARIOS[self.scenario]
        noise = self._rng.normal(0.0, 1.0, 6)
        fw = self.firmware
        fw.advance()
        if not fw.motors_on:
            pwm, info = 0.0, _DISARMED_INFO if fw.locked else _ARMED_INFO
        else:
            # At rest the specific force is (thrust + tether) / m = g up, so the thrust
            # carries the weight and the pull.
            pwm = pwm_for_thrust((self.mass_kg * 9.81 + pull_n) / 4.0, self.thrust_map)
            info = _ARMED_INFO
        out: dict[str, float] = {
            "acc.x": 0.002 * noise[0],
            "acc.y": 0.002 * noise[1],
            "acc.z": 1.0 + 0.002 * noise[2],
            "gyro.x": 0.05 * noise[3],
            "gyro.y": 0.05 * noise[4],
            "gyro.z": 0.05 * noise[5],
            "stateEstimate.qw": 1.0,
            "stateEstimate.qx": 0.0,
            "stateEstimate.qy": 0.0,
            "stateEstimate.qz": 0.0,
            "pm.vbat": fw.vbat_v(),
            "supervisor.info": float(info),
        }
        if fw.kalman_running:
            # stateEstimate is the Kalman's position, jittering with its σ but at most 1 cm (a
            # Flow deck's x/y are uncertain by metres, yet a smooth odometry)
            std = np.sqrt(fw.kalman_var_pos)
            est = fw.kalman_position_m + self._rng.normal(0.0, 1.0, 3) * np.minimum(std, 0.01)
        else:
            est = np.zeros(3)  # the complementary estimator gives no position
        for axis, value in zip("xyz", est, strict=True):
            out[f"stateEstimate.{axis}"] = float(value)
        for axis, var in zip(("X", "Y", "Z"), fw.kalman_var_pos, strict=True):
            out[f"kalman.var{axis}"] = float(var) if fw.kalman_running else 0.0
        for axis, var in zip(("PX", "PY", "PZ"), fw.kalman_var_vel, strict=True):
            out[f"kalman.var{axis}"] = float(var)
        for i in range(1, 5):
            # The same value for both: the fake models no battery compensation.
            out[f"motor.m{i}"] = float(round(pwm))
            out[f"pwm.m{i}_pwm"] = float(round(pwm))
        return {k: v for k, v in out.items() if k in self.toc}

    # ------------------------------------------------------------------ real-time player

    def start_player(self) -> None:
        """Play the scenario in real time on a thread until :meth:`close` (CLI use)."""
        self._stop_player.clear()
        self._player = threading.Thread(target=self._play, name="fake-crazyflie", daemon=True)
        self._player.start()

    def _play(self) -> None:
        with self._lock:
            blocks = self._blocks
        if not blocks:
            return
        period_ms = min(b.period_ms for b in blocks)
        start = time.monotonic()
        next_t = start
        periods = 0
        while not self._stop_player.is_set():
            if (
                self.drop_after_s is not None
                and not self._dropped
                and time.monotonic() - start > self.drop_after_s
            ):
                self._dropped = True
                self._down_until = time.monotonic() + self.down_s
                self.lose()
                return
            self._clock_ms += period_ms
            periods += 1
            sample = self.values()
            for i, block in enumerate(blocks):
                if (self._clock_ms // period_ms) % (block.period_ms // period_ms):
                    continue
                stamp = self._clock_ms + 2 * i  # each block runs on its own firmware timer
                if self.out_of_order and i == 0 and periods % 25 == 0:
                    self.emit(block.name, stamp - 3 * period_ms, _pick(sample, block))
                self.emit(block.name, stamp, _pick(sample, block))
            next_t += period_ms / 1000.0
            self._stop_player.wait(max(0.0, next_t - time.monotonic()))

    # ------------------------------------------------------------------ recording

    def _record(self, name: str, *args: Any) -> None:
        self.commands.append((name, args))
        if self.record_path is not None:
            fw = self.firmware
            line = json.dumps(
                {
                    "t": time.monotonic(),
                    "cmd": name,
                    "args": list(args),
                    # the firmware's state after the command (the CLI tests' ground truth)
                    "position_m": [float(v) for v in fw.position_m],
                    "motors_on": fw.motors_on,
                    "locked": fw.locked,
                    "falls": len(fw.impacts_mps),
                }
            )
            with self.record_path.open("a") as fh:
                fh.write(line + "\n")


def _pick(sample: Mapping[str, float], block: LogBlock) -> dict[str, float]:
    return {v: sample[v] for v in block.variables}
