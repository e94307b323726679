"""The seam between messages and math: validate a sample, route it to its drone.

Data flows one way (STYLE.md)::

    Telemetry ─▶ observation ─▶ gate ─▶ contact ─▶ filter ─▶ localization ─▶ follow ─▶ outputs

:class:`Pipeline` is synchronous and single-threaded: :meth:`Pipeline.validate` turns bytes
into a model (or an :class:`~groundstation.messages.InvalidMessage`) and may run on any
thread; :meth:`Pipeline.process` routes a validated input to its drone's
:class:`~groundstation.estimator.DroneEstimator` (telemetry) or applies it (reel, tether
params, follow command, someone's Stop), and returns the samples to publish.
:meth:`Pipeline.handle` does both. The estimation itself, stage by stage, is in
:mod:`groundstation.estimator`; the Pipeline counts what it refuses and tells the operator
log. Time is a parameter (``now_s``, the receive clock), so the same code runs live
(:mod:`groundstation.service`) and offline on a recording.
"""

from __future__ import annotations

import math
import threading
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from groundstation import follow as follow_mod
from groundstation.bus import Sample
from groundstation.config import Settings
from groundstation.estimator import localize_control
from groundstation.estimator.drone import (
    MOCAP_HOLD_S,
    DroneEstimator,
    calibration_from_config,
)
from groundstation.estimator.follow_control import (
    UNTRUSTED_POSITION_REASON,
    FollowCommandState,
    apply_command,
    follow_stamped,
    refuse_command,
)
from groundstation.estimator.localize_control import exit_azimuth_default_std_rad
from groundstation.localization import AngleObservation
from groundstation.messages import (
    Event,
    FollowCommand,
    InvalidMessage,
    Reel,
    StopIn,
    Telemetry,
    TetherParams,
    parse_key,
)

__all__ = [
    "FOLLOW_OFF",
    "FOLLOW_ON",
    "MOCAP_HOLD_S",
    "UNTRUSTED_POSITION_REASON",
    "DroneRuntime",
    "Parsed",
    "Pipeline",
    "calibration_from_config",
    "exit_azimuth_default_std_rad",
]

DroneRuntime = DroneEstimator
"""The per-drone state's former name (``Pipeline.drones`` holds DroneEstimators)."""
_follow_stamped = follow_stamped  # (benchmarks/bench_pipeline.py times it under this name)

_INPUT_MODELS: dict[str, type[Telemetry] | type[Reel] | type[FollowCommand] | type[TetherParams]]
_INPUT_MODELS = {
    "telemetry": Telemetry,
    "reel": Reel,
    "follow": FollowCommand,
    "params": TetherParams,
}
MAX_DRONES = 256
"""Drones tracked at most; more ids are dropped (kind ``too_many_drones``), bounding memory."""

FOLLOW_ON = "follow on"
"""The ``reason`` of the follow Event that an operator's command switched follow on."""
FOLLOW_OFF = "follow off"
"""... and switched it off (the service's own switch-off has ``input`` "service")."""
_KEY_CACHE_SIZE = 4 * MAX_DRONES
"""Parsed keys remembered (each drone has four input kinds)."""
_COMMAND_KINDS = frozenset({"follow", "params"})
"""Inputs from operators: every rejection of one is told on ``tether/{drone}/events``."""


@dataclass(frozen=True, slots=True)
class Parsed:
    """A validated input: the drone, the kind (``telemetry``, ``reel``, ...), the model."""

    drone: str
    kind: str
    message: Telemetry | Reel | FollowCommand | TetherParams | StopIn
    received_s: float
    source: str | None = None
    """The sender's zenoh session id, where the sample carried it."""
    ignored: tuple[str, ...] = ()
    """Unknown fields of a follow/params command (ignored, but told to the sender)."""


class Pipeline:
    """Per-drone estimation from validated messages (single-threaded; see module doc).

    Args:
        settings: the root configuration.
        on_drop: called as ``on_drop(drone_or_None, kind, detail)`` for every rejected
            input (the service logs the first of each kind).
        on_event: called as ``on_event(drone, event)`` with each
            :class:`~groundstation.messages.Event` for ``tether/{drone}/events`` (the operator
            action log): every rejected or applied command, follow switched off by staleness,
            a Stop issued; for rejected telemetry/reel only the first per drone and kind.
            Called from :meth:`validate`'s thread for rejections at validation, else from
            :meth:`process`'s / :meth:`tick`'s.
        wall_clock: UNIX seconds for the events' ``stamp_s``; None stamps them with the
            receive clock ``now_s`` (offline runs).
    """

    def __init__(
        self,
        settings: Settings,
        on_drop: Any = None,
        *,
        on_event: Any = None,
        wall_clock: Any = None,
    ) -> None:
        self.settings = settings
        self._on_event = on_event
        self._wall_clock = wall_clock
        self.self_id = "service"
        """``who`` of the events about the service's own actions (the service sets its id)."""
        self._told: set[tuple[str, str]] = set()  # (drone, kind) of rejections told once
        self.drones: dict[str, DroneEstimator] = {}
        self.global_drops: Counter[str] = Counter()
        self.last_received_s: dict[str, float] = {}
        """Receive time of each drone's latest valid telemetry, written by :meth:`validate`
        (so a backlog of queued samples is not mistaken for a silent drone)."""
        self._on_drop = on_drop
        self._lock = threading.Lock()  # guards drop counters touched from bus threads
        # Valid keys seen, parsed (a dict is safe to share between threads under the GIL;
        # bounded, so a flood of distinct keys costs memory only up to the limit).
        self._keys: dict[str, tuple[str, str]] = {}

    # ---------------------------------------------------------------- validation

    def validate(self, sample: Sample, now_s: float) -> Parsed | None:
        """Validate one bus sample; count and report it when rejected.

        Safe to call from any thread. Returns None for a rejected sample.
        """
        drone: str | None = None
        try:
            parsed_key = self._keys.get(sample.key)
            if parsed_key is None:
                parsed_key = parse_key(sample.key)
                if len(self._keys) < _KEY_CACHE_SIZE:
                    self._keys[sample.key] = parsed_key
            drone, kind = parsed_key
            model = _INPUT_MODELS.get(kind)
            if model is None:
                raise InvalidMessage("unexpected_key", f"{sample.key!r} is not an input")
            limit = self.settings.service.max_payload_bytes
            if len(sample.payload) > limit:
                raise InvalidMessage(
                    "too_large", f"{len(sample.payload)} bytes on {sample.key} (limit {limit})"
                )
            message = model.parse(sample.payload)
        except InvalidMessage as exc:
            self.count_drop(drone, exc.kind, exc.detail)
            if drone is not None and self._on_event is not None:
                self._tell_rejection(drone, sample, exc, now_s)
            return None
        if kind == "telemetry" and (
            drone in self.last_received_s or len(self.last_received_s) < MAX_DRONES
        ):
            self.last_received_s[drone] = now_s
        ignored = model.unknown_fields(sample.payload) if kind in _COMMAND_KINDS else ()
        return Parsed(drone, kind, message, now_s, sample.source, ignored)

    def _tell_rejection(
        self, drone: str, sample: Sample, exc: InvalidMessage, now_s: float
    ) -> None:
        kind = sample.key[len("tether/") + len(drone) + 1 :]
        if kind not in _COMMAND_KINDS:
            with self._lock:
                if (drone, exc.kind) in self._told or len(self._told) >= 16 * MAX_DRONES:
                    return
                self._told.add((drone, exc.kind))
        reason = exc.detail if kind in _COMMAND_KINDS else f"{exc.detail} (further ones counted)"
        self._emit(drone, "rejected", kind, now_s, sample.source, reason, field=exc.field)

    def _emit(
        self,
        drone: str,
        kind: str,
        input_kind: str,
        now_s: float,
        who: str | None,
        reason: str,
        *,
        field: str | None = None,
        changes: dict[str, Any] | None = None,
    ) -> None:
        """Hand one operator-log Event to ``on_event`` (nothing when there is no listener)."""
        if self._on_event is None:
            return
        event = Event(
            stamp_s=self._wall_clock() if self._wall_clock is not None else now_s,
            kind=kind,
            input=input_kind,
            who=who or "unknown",
            reason=reason[:500],
            field=field,
            changes=changes or {},
        )
        self._on_event(drone, event)

    def count_drop(self, drone: str | None, kind: str, detail: str) -> None:
        """Count a rejected input per drone and kind (thread-safe) and report it."""
        with self._lock:
            runtime = self.drones.get(drone) if drone is not None else None
            if runtime is not None:
                runtime.drops[kind] += 1
            else:
                self.global_drops[kind] += 1
        if self._on_drop is not None:
            self._on_drop(drone, kind, detail)

    # ---------------------------------------------------------------- processing

    def handle(self, sample: Sample, now_s: float) -> list[Sample]:
        """Validate and process one sample; return the samples to publish."""
        parsed = self.validate(sample, now_s)
        if parsed is None:
            return []
        return self.process(parsed, now_s)

    def process(self, parsed: Parsed, now_s: float) -> list[Sample]:
        """Route a validated input to its drone; return the samples to publish."""
        drone = self.drones.get(parsed.drone)
        if drone is None:
            if len(self.drones) >= MAX_DRONES:
                self.count_drop(None, "too_many_drones", f"drone {parsed.drone!r} not tracked")
                return []
            drone = self._new_drone(parsed.drone)
        msg = parsed.message
        if isinstance(msg, Telemetry):
            return drone.step(msg, now_s)
        if isinstance(msg, Reel):
            self._reel(drone, msg, parsed.received_s, now_s)
        elif isinstance(msg, TetherParams):
            self._tether_params(drone, msg, parsed, now_s)
        elif isinstance(msg, StopIn):
            self._seen_stop(drone, msg, parsed, now_s)
        else:
            assert isinstance(msg, FollowCommand)
            self._follow_command(drone, msg, parsed, now_s)
        return []

    def process_batch(
        self, batch: Sequence[Parsed], on_error: Callable[[Parsed], None] | None = None
    ) -> list[Sample]:
        """:meth:`process` of each input in order (at its ``received_s``), the outputs
        concatenated (the service's drain: it publishes them after the batch).

        Each message goes through its drone's whole step on its own: the localizations of
        a batch were once computed in one vectorised call, which stopped paying once
        :func:`localization.localize` was written in Python floats (docs/pipeline_benchmark.md).

        Args:
            batch: Validated inputs, each drone's in their order.
            on_error: Called inside the ``except`` of an input whose processing raised
                (its outputs are lost, the rest go on); None re-raises.
        """
        out: list[Sample] = []
        process = self.process
        for parsed in batch:
            try:
                out.extend(process(parsed, parsed.received_s))
            except Exception:
                if on_error is None:
                    raise
                on_error(parsed)
        return out

    def tick(self, now_s: float) -> list[Sample]:
        """Mark drones silent for ``stale_after_s`` as stale; disengage their follow mode."""
        stale_after = self.settings.service.stale_after_s
        for drone in self.drones.values():
            last_seen_s = drone.last_seen_s
            if drone.stale or last_seen_s is None:
                continue
            heard_s = max(last_seen_s, self.last_received_s.get(drone.drone, -math.inf))
            if now_s - heard_s > stale_after and drone.mark_stale():
                self._emit(
                    drone.drone,
                    "follow",
                    "service",
                    now_s,
                    self.self_id,
                    f"{drone.drone} silent for {now_s - heard_s:.2f} s: follow off; "
                    "enable it again once the drone is heard",
                    changes={"enabled": False},
                )
        return []

    # ---------------------------------------------------------------- commands

    def _new_drone(self, drone_id: str) -> DroneEstimator:
        drone = DroneEstimator(
            drone_id,
            self.settings,
            on_drop=self.count_drop,
            on_warning=self._warning,
            on_stop=self._stop_issued,
        )
        with self._lock:
            self.drones[drone_id] = drone
        return drone

    def _warning(self, drone: str, now_s: float, text: str, field: str) -> None:
        """A ``warning`` Event about a drone's telemetry (the estimator sends each once)."""
        self._emit(drone, "warning", "telemetry", now_s, self.self_id, text, field=field)

    def _stop_issued(self, drone: str, now_s: float, reason: str) -> None:
        """The estimator published a Stop (tug-to-land): the operator log says so."""
        self._emit(drone, "stop", "service", now_s, self.self_id, reason)

    def _reel(self, drone: DroneEstimator, msg: Reel, received_s: float, now_s: float) -> None:
        """The reel's length, base and exit angles (with their σ) for the drone."""
        drone.length_m = msg.length_m
        drone.length_source = "reel"
        if msg.base_m is not None:
            drone.base_world_m = np.array(msg.base_m, dtype=float)
        loc = self.settings.localization
        if msg.exit_elevation_rad is not None:
            drone.exit_elevation = AngleObservation(
                msg.exit_elevation_rad, msg.exit_elevation_std_rad or loc.exit_elevation_std_rad
            )
            drone.exit_elevation_received_s = received_s
        if msg.exit_azimuth_rad is not None:
            std = msg.exit_azimuth_std_rad
            if std is None:
                elevation = localize_control.fresh_angle(
                    drone.exit_elevation,
                    drone.exit_elevation_received_s,
                    now_s,
                    loc.reel_stale_after_s,
                )
                std = exit_azimuth_default_std_rad(
                    loc.exit_azimuth_std_rad,
                    elevation.value_rad if elevation is not None else None,
                )
            drone.exit_azimuth = AngleObservation(msg.exit_azimuth_rad, std)
            drone.exit_azimuth_received_s = received_s

    def _tether_params(
        self, drone: DroneEstimator, msg: TetherParams, parsed: Parsed, now_s: float
    ) -> None:
        """An operator's tether weight or length (a reel's length wins over the operator's)."""
        changes: dict[str, Any] = {}
        if msg.weight_n_per_m is not None:
            drone.weight_n_per_m = msg.weight_n_per_m
            changes["weight_n_per_m"] = msg.weight_n_per_m
        if msg.length_m is not None:
            if drone.length_source == "reel":
                self.count_drop(drone.drone, "length_from_reel", "a reel reports length")
                self._emit(
                    drone.drone,
                    "warning",
                    "params",
                    now_s,
                    parsed.source,
                    f"length_m {msg.length_m} ignored: a reel reports the length "
                    f"({drone.length_m:.3f} m)",
                    field="length_m",
                )
            else:
                drone.length_m = msg.length_m
                drone.length_source = "operator"
                changes["length_m"] = msg.length_m
        self._tell_ignored(drone.drone, parsed, now_s)
        if changes:
            self._emit(
                drone.drone, "params", "params", now_s, parsed.source, "applied", changes=changes
            )

    def _seen_stop(self, drone: DroneEstimator, stop: StopIn, parsed: Parsed, now_s: float) -> None:
        """Someone else's Stop on ``cmd/stop``: switch follow off, log who stopped the drone.

        Follow must not be on when the drone flies again after a Stop (re-armed, taken off):
        the operator enables it again, as after a stale drone.
        """
        changes: dict[str, Any] = {}
        if drone.follow_state.enabled:
            state = follow_mod.set_enabled(drone.follow_state, False)
            drone.follow_state = replace(state, reason=f"Stop ({stop.reason}): follow off")
            changes["enabled"] = False
        self._emit(
            drone.drone, "stop", "cmd/stop", now_s, parsed.source, stop.reason, changes=changes
        )

    def _tell_ignored(self, drone: str, parsed: Parsed, now_s: float) -> None:
        if parsed.ignored:
            model = type(parsed.message)
            self._emit(
                drone,
                "warning",
                parsed.kind,
                now_s,
                parsed.source,
                f"unknown fields ignored: {', '.join(map(repr, parsed.ignored))} "
                f"(a {model.__name__} has {', '.join(model.model_fields)})",
                field=parsed.ignored[0],
            )

    def _follow_command(
        self, drone: DroneEstimator, cmd: FollowCommand, parsed: Parsed, now_s: float
    ) -> None:
        """An operator's FollowCommand: refused with the reason, or applied and told."""
        self._tell_ignored(drone.drone, parsed, now_s)
        last_seen_s = drone.last_seen_s
        refusal = refuse_command(
            cmd,
            drone=drone.drone,
            threshold_min_n=self.settings.service.follow_threshold_min_n,
            floor_z_m=drone.params.base.floor_z_m,
            reach_top_m=float(drone.base_world_m[2]) + drone.length_m,
            last_seen_s=last_seen_s,
            stale=drone.stale,
            silent_s=now_s - last_seen_s if last_seen_s is not None else math.inf,
            trusted_position=drone.trusted_position(),
        )
        if refusal is not None:
            field, reason = refusal
            self.count_drop(drone.drone, "follow_refused", reason)
            self._emit(drone.drone, "rejected", "follow", now_s, parsed.source, reason, field=field)
            return
        before = drone.follow_info()
        applied = apply_command(
            FollowCommandState(drone.follow_params, drone.follow_state, drone.land_below_m_memory),
            cmd,
        )
        drone.follow_params = applied.params
        drone.follow_state = applied.state
        drone.land_below_m_memory = applied.land_below_m_memory
        after = drone.follow_info()
        changes: dict[str, Any] = {"enabled": after.enabled}
        for name in ("threshold_n", "land_below_m"):
            if getattr(after, name) != getattr(before, name):
                changes[name] = getattr(after, name)
        if before.enabled != after.enabled:
            reason = FOLLOW_ON if after.enabled else FOLLOW_OFF
        else:
            reason = "re-tuned" if len(changes) > 1 else "no change"
        self._emit(drone.drone, "follow", "follow", now_s, parsed.source, reason, changes=changes)

    # ---------------------------------------------------------------- health

    def status(self, drone: str, now_s: float) -> dict[str, Any] | None:
        """Health of one drone as a JSON-ready dict (``tether/{drone}/status``)."""
        with self._lock:
            estimator = self.drones.get(drone)
            if estimator is None:
                return None
            drops = dict(estimator.drops)
        return estimator.status(now_s, drops)

    def drone_ids(self) -> Iterable[str]:
        with self._lock:
            return list(self.drones)
