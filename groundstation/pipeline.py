"""The seam between messages and math: validate a sample, step the per-drone estimators.

Data flows one way (STYLE.md)::

    Telemetry ─▶ tension observation ─▶ tension filter ─▶ localization ─▶ follow ─▶ outputs

:class:`Pipeline` is synchronous and single-threaded: :meth:`Pipeline.validate` turns bytes
into a model (or an :class:`~groundstation.messages.InvalidMessage`) and may run on any
thread; :meth:`Pipeline.process` steps the drone's state and returns the samples to publish.
:meth:`Pipeline.handle` does both. Time is a parameter (``now_s``, the receive clock), so the
same code runs live (:mod:`groundstation.service`) and offline on a recording.
"""

from __future__ import annotations

import math
import threading
from collections import Counter, deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from groundstation import contact as contact_mod
from groundstation import follow as follow_mod
from groundstation import slow_accel as slow_mod
from groundstation.bus import Sample
from groundstation.calibration import RestCalibrator
from groundstation.config import CalibrationSection, DroneParams, Settings
from groundstation.localization import (
    AngleObservation,
    PositionEstimate,
    localize,
    localize_batch,
)
from groundstation.messages import (
    Estimate,
    Event,
    FollowCommand,
    FollowInfo,
    InvalidMessage,
    Reel,
    Setpoint,
    Stop,
    StopIn,
    Telemetry,
    TetherParams,
    encode_estimate_ordered,
    parse_key,
)
from groundstation.tension import (
    DegenerateQuaternionError,
    ObservationCalibration,
    TensionError,
    TensionFilter,
    TensionFilterParams,
    observe_tension,
)

__all__ = [
    "FOLLOW_OFF",
    "FOLLOW_ON",
    "DroneRuntime",
    "Parsed",
    "Pipeline",
    "calibration_from_config",
    "exit_azimuth_default_std_rad",
]

_INPUT_MODELS: dict[str, type[Telemetry] | type[Reel] | type[FollowCommand] | type[TetherParams]]
_INPUT_MODELS = {
    "telemetry": Telemetry,
    "reel": Reel,
    "follow": FollowCommand,
    "params": TetherParams,
}
LIFTOFF_PRIOR_STD_N = (0.005, 0.005, 0.005)
"""Prior standard deviation of the tension at lift-off, N (per world axis)."""
MAX_DRONES = 256
"""Drones tracked at most; more ids are dropped (kind ``too_many_drones``), bounding memory."""

FOLLOW_ON = "follow on"
"""The ``reason`` of the follow Event that an operator's command switched follow on."""
FOLLOW_OFF = "follow off"
"""... and switched it off (the service's own switch-off has ``input`` "service")."""
_KEY_CACHE_SIZE = 4 * MAX_DRONES
"""Parsed keys remembered (each drone has four input kinds)."""
_MAX_GAP_S = 1.0
"""A telemetry gap longer than this restarts the filter (the tension may have changed)."""
MOCAP_HOLD_S = 0.3
"""A motion-capture position stays the drone's external position for this long (telemetry
stamp) after the frame that brought it, s. Real motion capture reaches a drone's telemetry
at 70-116 Hz against the IMU's 100 Hz, in bursts, with gaps up to 150 ms (the realistic
profile draws the same): without the hold, follow would switch to the tether-based position
on every telemetry message without a fresh frame."""
UNTRUSTED_POSITION_REASON = (
    "no motion capture and no calibration: the tether-based position of an uncalibrated "
    "drone is off by up to ~1 m, so it is not followed"
)
"""The follow ``reason`` while following is held off for want of a position it may fly to."""
_COMMAND_KINDS = frozenset({"follow", "params"})
"""Inputs from operators: every rejection of one is told on ``tether/{drone}/events``."""
BATCH_LOCALIZE_MIN = 12
"""Localizations in a batch from which :meth:`Pipeline.process_batch` computes them in one
vectorised call (:func:`localization.localize_batch`: numpy's per-call overhead is paid
once, ~300 us on the shared 2-core machine, then ~5 us per case, against ~45 us per case
one by one; docs/service_profile.md)."""


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


class _Rate:
    """Messages per second over a sliding window of receive times."""

    def __init__(self, window_s: float = 2.0) -> None:
        self.window_s = window_s
        self.times: deque[float] = deque()

    def add(self, now_s: float) -> None:
        self.times.append(now_s)
        cutoff = now_s - self.window_s
        while self.times and self.times[0] < cutoff:
            self.times.popleft()

    def hz(self, now_s: float) -> float:
        cutoff = now_s - self.window_s
        n = sum(1 for t in self.times if t >= cutoff)
        return n / self.window_s


@dataclass
class DroneRuntime:
    """Everything the pipeline keeps about one drone (owned by the processing thread)."""

    drone: str
    params: DroneParams
    filter: TensionFilter
    follow_params: follow_mod.FollowParams
    follow_state: follow_mod.FollowState
    length_m: float
    base_world_m: np.ndarray
    weight_n_per_m: float
    length_source: str = "config"
    contact_params: contact_mod.ContactParams = field(default_factory=contact_mod.ContactParams)
    contact: contact_mod.ContactState = field(default_factory=contact_mod.ContactState)
    slow_params: slow_mod.SlowAccelParams | None = None
    """``[calibration] accel_slow``: the accelerometer's slow content replaced (None: off)."""
    slow: slow_mod.SlowAccelState = field(default_factory=slow_mod.SlowAccelState)
    """The accelerometer's slow error and the drag velocity (groundstation.slow_accel)."""
    """Ground/air state (groundstation.contact): on the floor no tension is published."""
    rested: bool = False
    """Seen certainly on the ground (disarmed, low thrust) since the last lift-off: the filter
    then restarts from the lift-off prior."""
    filter_prior: bool | None = None
    """The filter was reset for this stay on the ground with (True) or without (False) the
    lift-off prior; None: not since its last step or reset elsewhere."""
    exit_azimuth: AngleObservation | None = None
    """The reel's last exit azimuth (with its σ) and when it was received."""
    exit_azimuth_received_s: float = -math.inf
    exit_elevation: AngleObservation | None = None
    """The reel's last exit elevation (with its σ) and when it was received."""
    exit_elevation_received_s: float = -math.inf
    last_seq: int | None = None
    last_stamp_s: float | None = None
    last_seen_s: float | None = None
    stale: bool = True
    received: int = 0
    accepted: int = 0
    estimates: int = 0
    setpoints: int = 0
    stops: int = 0
    seq_gaps: int = 0
    change_detections: int = 0
    drops: Counter[str] = field(default_factory=Counter)
    telemetry_rate: _Rate = field(default_factory=_Rate)
    estimate_rate: _Rate = field(default_factory=_Rate)
    last_estimate_fields: dict[str, Any] | None = None
    """The last Estimate's fields, ``follow`` as its ``model_dump()`` (see
    :attr:`last_estimate`)."""
    follow_json_cache: tuple[FollowInfo, dict[str, Any]] | None = None
    """The last FollowInfo and its ``model_dump()`` (FollowInfo is frozen and reused)."""
    land_below_m_memory: float | None = None
    """Last tug-to-land height, restored when tug-to-land is switched back on."""
    follow_info_cache: tuple[follow_mod.FollowParams, tuple[Any, ...], FollowInfo] | None = None
    """The last Estimate's FollowInfo, with the params and flags it was made from."""
    calibration: ObservationCalibration | None = None
    """Sensor corrections applied in the observation (None: none in force)."""
    calibration_source: str = "none"
    """Which calibration is in force (Estimate and status ``calibration``)."""
    mocap_m: tuple[float, float, float] | None = None
    """The last motion-capture ``position_m`` received in Telemetry, m, world frame."""
    mocap_stamp_s: float = -math.inf
    """The telemetry ``stamp_s`` that brought :attr:`mocap_m`, s."""
    position_untrusted_told: bool = False
    """The one ``warning`` Event for a position too uncertain to use was sent."""
    vbat_range_v: tuple[float, float] | None = None
    """``[calibration] thrust_vbat_range_v``: the battery range the thrust map was calibrated
    over (None: not recorded)."""
    last_vbat_v: float | None = None
    """The last accepted Telemetry's ``vbat_v`` (None: absent)."""
    calibration_extrapolated: bool | None = None
    """The last Telemetry's ``vbat_v`` outside :attr:`vbat_range_v` (None: unknown)."""
    extrapolation_told: bool = False
    """The one ``warning`` Event for flying outside the calibrated battery range was sent."""
    rest: RestCalibrator | None = None
    """The rest calibration (``[calibration] rest``): the accelerometer's x/y offset found
    while the drone sat still and disarmed, added to the configured bias until the next
    disarm."""
    rest_missing: bool = False
    """``[calibration] rest_required`` and the drone armed without a rest offset in force
    (until the next disarm): its x/y accelerometer bias is not what was calibrated."""
    rest_missing_told: bool = False
    """The one ``warning`` Event for arming without the required rest offset was sent."""
    estimate_key: str = field(init=False, default="")
    """``tether/{drone}/estimate`` (made once, not per message)."""
    base_cache: tuple[np.ndarray, tuple[float, float, float]] | None = None
    """``base_world_m`` and its floats, for the Estimate (the array is replaced, never
    written, when the base moves)."""

    def __post_init__(self) -> None:
        self.estimate_key = f"tether/{self.drone}/estimate"

    @property
    def last_estimate(self) -> Estimate | None:
        """The last published Estimate as a model (built on demand, not per message)."""
        if self.last_estimate_fields is None or self.follow_json_cache is None:
            return None
        return Estimate(**{**self.last_estimate_fields, "follow": self.follow_json_cache[0]})


def _fresh_mocap(runtime: DroneRuntime, stamp_s: float) -> tuple[float, float, float] | None:
    """The drone's motion-capture position if a frame came within :data:`MOCAP_HOLD_S`."""
    if runtime.mocap_m is not None and 0.0 <= stamp_s - runtime.mocap_stamp_s <= MOCAP_HOLD_S:
        return runtime.mocap_m
    return None


def _no_trusted_position(runtime: DroneRuntime, mocap: tuple[float, float, float] | None) -> bool:
    """Nothing follow may fly to: no fresh motion capture and no calibration in force."""
    return mocap is None and runtime.calibration_source == "none"


EXIT_AZIMUTH_MIN_COS = 0.02
"""Floor of ``cos(elevation)`` in :func:`exit_azimuth_default_std_rad` (at most 50 times the
configured σ: some 1.5 rad for 0.03 rad, i.e. no azimuth)."""


def exit_azimuth_default_std_rad(std_rad: float, elevation_rad: float | None) -> float:
    """σ of a Reel ``exit_azimuth_rad`` sent without ``exit_azimuth_std_rad``, rad.

    ``[localization] exit_azimuth_std_rad`` is the σ of the tether's *direction* at the
    exit, across it; the azimuth of that direction is the angle of its horizontal
    projection, which shrinks as ``cos(elevation)``: the same sideways error is
    ``std / cos(elevation)`` of azimuth, and near plumb (elevation ±90°) any azimuth is
    noise. So ``std / max(cos(elevation), EXIT_AZIMUTH_MIN_COS)`` with the exit elevation
    known (this Reel message's, or the last one received within ``reel_stale_after_s``).
    Without an elevation it stays ``std``, as for a tether leaving level: a reel that sends
    an azimuth without elevation and may point up steeply should send its own σ.

    Args:
        std_rad: The configured σ, rad.
        elevation_rad: The exit elevation, rad, or None when unknown.

    Returns:
        The σ to fuse the exit azimuth with, rad.
    """
    if elevation_rad is None or not math.isfinite(elevation_rad):
        return std_rad
    return std_rad / max(math.cos(elevation_rad), EXIT_AZIMUTH_MIN_COS)


def calibration_from_config(
    section: CalibrationSection,
) -> tuple[ObservationCalibration | None, str]:
    """The observation's corrections from ``[calibration]``, and the label reported for them.

    The label is the section's ``source``; values that differ from the defaults without a
    source are labelled ``config`` (never ``none`` while something is applied).

    Returns:
        ``(calibration or None when it changes nothing, label)``.
    """
    cal = ObservationCalibration(
        thrust_scale=section.thrust_scale,
        thrust_axis_rad=section.thrust_axis_rad,
        accel_bias_mps2=section.accel_bias_mps2,
        thrust_vbat_slope_per_v=section.thrust_vbat_slope_per_v,
        thrust_vbat_ref_v=section.thrust_vbat_ref_v,
        rotor_drag_n_s_per_m=section.rotor_drag_n_s_per_m,
    )
    if cal.is_identity:
        return None, section.source
    return cal, section.source if section.source != "none" else "config"


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
        self.drones: dict[str, DroneRuntime] = {}
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

    def _warn(self, runtime: DroneRuntime, now_s: float, text: str, *, field: str) -> None:
        """A ``warning`` Event about this drone's telemetry (the callers send each once)."""
        self._emit(runtime.drone, "warning", "telemetry", now_s, self.self_id, text, field=field)

    def _usable_position(self, runtime: DroneRuntime, msg: Telemetry, now_s: float) -> Telemetry:
        """``msg`` without its ``position_m`` when the position's own σ (an onboard estimator's,
        ``position_std_m``) exceeds ``[localization] position_max_std_m`` on any axis: it is
        then no position to follow, tug-to-land, contact or the azimuth (issue 21). Below it,
        an onboard position is used as motion capture is."""
        std = msg.position_std_m
        limit = self.settings.localization.position_max_std_m
        if msg.position_m is None or std is None or max(std) <= limit:
            return msg
        if not runtime.position_untrusted_told:
            runtime.position_untrusted_told = True
            self._warn(
                runtime,
                now_s,
                f"{runtime.drone}'s position_m ({msg.position_source or 'mocap'}) has σ "
                f"{[round(v, 3) for v in std]} m, above [localization] position_max_std_m "
                f"{limit:g} m: not used (follow flies on the tether's position)",
                field="position_std_m",
            )
        return msg.model_copy(update={"position_m": None})

    def _reel_fresh(self, received_s: float, now_s: float) -> bool:
        """An exit angle received at ``received_s`` is still in use at ``now_s``: the reel
        reports at its own rate, and angles older than ``[localization]
        reel_stale_after_s`` are not used."""
        return received_s >= now_s - self.settings.localization.reel_stale_after_s

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
        """Step the drone's state with a validated input; return the samples to publish."""
        runtime = self.drones.get(parsed.drone)
        if runtime is None:
            if len(self.drones) >= MAX_DRONES:
                self.count_drop(None, "too_many_drones", f"drone {parsed.drone!r} not tracked")
                return []
            runtime = self._new_runtime(parsed.drone)
        msg = parsed.message
        if isinstance(msg, Telemetry):
            return self._telemetry(runtime, msg, now_s)
        if isinstance(msg, Reel):
            runtime.length_m = msg.length_m
            runtime.length_source = "reel"
            if msg.base_m is not None:
                runtime.base_world_m = np.array(msg.base_m, dtype=float)
            loc = self.settings.localization
            if msg.exit_elevation_rad is not None:
                runtime.exit_elevation = AngleObservation(
                    msg.exit_elevation_rad,
                    msg.exit_elevation_std_rad or loc.exit_elevation_std_rad,
                )
                runtime.exit_elevation_received_s = parsed.received_s
            if msg.exit_azimuth_rad is not None:
                std = msg.exit_azimuth_std_rad
                if std is None:
                    std = exit_azimuth_default_std_rad(
                        loc.exit_azimuth_std_rad,
                        runtime.exit_elevation.value_rad
                        if runtime.exit_elevation is not None
                        and self._reel_fresh(runtime.exit_elevation_received_s, now_s)
                        else None,
                    )
                runtime.exit_azimuth = AngleObservation(msg.exit_azimuth_rad, std)
                runtime.exit_azimuth_received_s = parsed.received_s
            return []
        if isinstance(msg, TetherParams):
            changes: dict[str, Any] = {}
            if msg.weight_n_per_m is not None:
                runtime.weight_n_per_m = msg.weight_n_per_m
                changes["weight_n_per_m"] = msg.weight_n_per_m
            if msg.length_m is not None:
                if runtime.length_source == "reel":
                    self.count_drop(runtime.drone, "length_from_reel", "a reel reports length")
                    self._emit(
                        runtime.drone,
                        "warning",
                        "params",
                        now_s,
                        parsed.source,
                        f"length_m {msg.length_m} ignored: a reel reports the length "
                        f"({runtime.length_m:.3f} m)",
                        field="length_m",
                    )
                else:
                    runtime.length_m = msg.length_m
                    runtime.length_source = "operator"
                    changes["length_m"] = msg.length_m
            self._tell_ignored(runtime.drone, parsed, now_s)
            if changes:
                self._emit(
                    runtime.drone,
                    "params",
                    "params",
                    now_s,
                    parsed.source,
                    "applied",
                    changes=changes,
                )
            return []
        if isinstance(msg, StopIn):
            self._seen_stop(runtime, msg, parsed, now_s)
            return []
        assert isinstance(msg, FollowCommand)
        self._follow_command(runtime, msg, parsed, now_s)
        return []

    def process_batch(
        self, batch: Sequence[Parsed], on_error: Callable[[Parsed], None] | None = None
    ) -> list[Sample]:
        """:meth:`process` of each input in order (at its ``received_s``), the outputs
        concatenated: the same outputs, with the localizations of a run of telemetry
        (any drones) computed in one vectorised call.

        Localization holds no state and reads nothing a later telemetry message changes,
        so a run is stepped in three passes: every message up to its localization
        (:meth:`_telemetry_front`: checks, observation, contact, filter), the
        localizations together (:meth:`_localize_many`), then every message's follow step
        and Estimate in order (:meth:`_telemetry_back`). Any other input (reel, params,
        follow, stop) changes what localization or follow read, so it ends the run: the
        run is finished first, then that input is processed. What the front pass sets for
        the back pass of the same message (``calibration_extrapolated``) travels with it.
        The published samples are those of :meth:`process`, in its order; only the
        operator-log Events told from the front pass (the battery warning) may come before
        those of an earlier message's back pass (a Stop) in the same batch.

        Args:
            batch: Validated inputs, each drone's in their order.
            on_error: Called inside the ``except`` of an input whose processing raised
                (its outputs are lost, the rest go on); None re-raises.
        """
        out: list[Sample] = []
        run: list[tuple[_Front, Parsed]] = []

        def finish_run() -> None:
            inputs = [f[8] for f, _ in run if f[8] is not None]
            try:
                located = iter(self._localize_many(inputs))
            except Exception:  # never expected (localize returns failures): one by one
                located = iter([self._localize_one(x) for x in inputs])
            for front, parsed in run:
                position = next(located) if front[8] is not None else None
                try:
                    out.extend(self._telemetry_back(front, position))
                except Exception:
                    if on_error is None:
                        raise
                    on_error(parsed)
            run.clear()

        for parsed in batch:
            try:
                runtime = self.drones.get(parsed.drone)
                if runtime is not None and isinstance(parsed.message, Telemetry):
                    front = self._telemetry_front(runtime, parsed.message, parsed.received_s)
                    if front is not None:
                        run.append((front, parsed))
                    continue
                if run:
                    finish_run()
                out.extend(self.process(parsed, parsed.received_s))
            except Exception:
                if on_error is None:
                    raise
                on_error(parsed)
        if run:
            finish_run()
        return out

    def _seen_stop(self, runtime: DroneRuntime, stop: StopIn, parsed: Parsed, now_s: float) -> None:
        """Someone else's Stop on ``cmd/stop``: switch follow off, log who stopped the drone.

        Follow must not be on when the drone flies again after a Stop (re-armed, taken off):
        the operator enables it again, as after a stale drone.
        """
        changes: dict[str, Any] = {}
        if runtime.follow_state.enabled:
            state = follow_mod.set_enabled(runtime.follow_state, False)
            runtime.follow_state = replace(state, reason=f"Stop ({stop.reason}): follow off")
            changes["enabled"] = False
        self._emit(
            runtime.drone, "stop", "cmd/stop", now_s, parsed.source, stop.reason, changes=changes
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

    def _refuse_follow(
        self, runtime: DroneRuntime, cmd: FollowCommand, now_s: float
    ) -> tuple[str, str] | None:
        """Why a FollowCommand must not be applied, as ``(field, reason)``, or None.

        Checked at the command boundary, before :func:`follow.set_enabled`:

        - a threshold below ``[service] follow_threshold_min_n``;
        - a tug-to-land height ``land_below_m`` at or below the floor (``[base] floor_z_m``:
          tug-to-land would never stop the motors) or at or above base + tether length (out
          of reach: the first tug would stop them at any height);
        - enabling follow on a drone that is stale or has never sent telemetry (the README's
          rule: a stale drone drops follow and the operator enables it again; an unknown drone
          is the most stale of all, and would otherwise fly off in follow mode the moment it
          starts);
        - enabling follow on a drone with no motion capture (none within
          :data:`MOCAP_HOLD_S`) while no calibration is in force: follow would fly it to its
          tether-based position, which uncalibrated is off by up to a metre (on the
          realistic simulator a tug-to-land Stop came at 0.9 m instead of 0.25 m;
          docs/realistic_benchmark.md). The same condition while following holds the goal
          (:meth:`_telemetry_back`).

        That a threshold is not below the tether's own pull is :mod:`groundstation.follow`'s
        business: the threshold applies to the pull beyond the tether's own tension there.
        """
        floor_n = self.settings.service.follow_threshold_min_n
        if cmd.threshold_n is not None and cmd.threshold_n < floor_n:
            return "threshold_n", (
                f"threshold_n {cmd.threshold_n:g} N is below the service's floor {floor_n:g} N "
                "([service] follow_threshold_min_n): that low a threshold follows the sensor "
                "noise and any error in the tether's own tension; not applied"
            )
        if cmd.land_below_m is not None:
            # A height outside (floor, base + tether) is no landing height: above the reach
            # the first tug stops the motors at any height, at or below the floor never.
            floor_z_m = runtime.params.base.floor_z_m
            reach_top_m = float(runtime.base_world_m[2]) + runtime.length_m
            if not floor_z_m < cmd.land_below_m < reach_top_m:
                return "land_below_m", (
                    f"land_below_m {cmd.land_below_m:g} m is outside the tether's reach: it "
                    f"must lie above the floor ({floor_z_m:g} m, [base] floor_z_m) and below "
                    f"base + tether ({reach_top_m:.3f} m); not applied"
                )
        if not cmd.enabled:
            return None
        if runtime.last_seen_s is None:
            return "enabled", (
                f"{runtime.drone} has sent no telemetry: follow stays off (enable it once the "
                "drone is flying); not applied"
            )
        if runtime.stale:
            return "enabled", (
                f"{runtime.drone} is stale (silent for {now_s - runtime.last_seen_s:.1f} s): "
                "follow stays off until it is heard again; not applied"
            )
        if runtime.last_stamp_s is not None and _no_trusted_position(
            runtime, _fresh_mocap(runtime, runtime.last_stamp_s)
        ):
            return "enabled", (
                f"{runtime.drone} has no motion capture (position_m) and no calibration "
                "([calibration] source = none): following and tug-to-land would fly it to "
                "its tether-based position, which uncalibrated is off by up to ~1 m (a "
                "tug-to-land Stop at 0.9 m instead of 0.25 m, docs/realistic_benchmark.md)"
                "; calibrate it (groundstation calibrate, docs/calibration.md) or send "
                "position_m; not applied"
            )
        return None

    def tick(self, now_s: float) -> list[Sample]:
        """Mark drones silent for ``stale_after_s`` as stale; disengage their follow mode."""
        stale_after = self.settings.service.stale_after_s
        for runtime in self.drones.values():
            if runtime.stale or runtime.last_seen_s is None:
                continue
            heard_s = max(runtime.last_seen_s, self.last_received_s.get(runtime.drone, -math.inf))
            if now_s - heard_s > stale_after:
                runtime.stale = True
                was_on = runtime.follow_state.enabled
                runtime.follow_state = follow_mod.mark_stale(runtime.follow_state)
                if was_on:
                    self._emit(
                        runtime.drone,
                        "follow",
                        "service",
                        now_s,
                        self.self_id,
                        f"{runtime.drone} silent for {now_s - heard_s:.2f} s: follow off; "
                        "enable it again once the drone is heard",
                        changes={"enabled": False},
                    )
        return []

    # ---------------------------------------------------------------- internals

    def _new_runtime(self, drone: str) -> DroneRuntime:
        params = self.settings.for_drone(drone)
        fparams = TensionFilterParams(
            mass_kg=params.drone.mass_kg,
            accel_noise_mps2=params.drone.accel_noise_mps2,
            thrust_noise_n=params.drone.thrust_noise_n,
        )
        fcfg = params.follow
        calibration, calibration_source = calibration_from_config(params.calibration)
        runtime = DroneRuntime(
            drone=drone,
            params=params,
            filter=TensionFilter(fparams),
            # [follow] and FollowParams share their field names (a new key fails loudly).
            follow_params=follow_mod.FollowParams(**fcfg.model_dump()),
            follow_state=follow_mod.FollowState(),
            length_m=params.tether.length_m,
            base_world_m=np.array(params.base.position_m, dtype=float),
            weight_n_per_m=params.tether.weight_n_per_m,
            calibration=calibration,
            calibration_source=calibration_source,
            vbat_range_v=params.calibration.thrust_vbat_range_v,
            rest=(
                RestCalibrator(bias_body_mps2=params.calibration.accel_bias_mps2)
                if params.calibration.rest
                else None
            ),
            contact_params=contact_mod.ContactParams(
                ground_thrust_ratio=params.filter.ground_thrust_ratio
            ),
            slow_params=(
                slow_mod.SlowAccelParams(
                    time_constant_s=params.filter.accel_slow_time_constant_s,
                    velocity_time_constant_s=params.filter.drag_velocity_time_constant_s,
                    hover_crossover_s=params.filter.accel_hover_crossover_s,
                )
                if params.calibration.accel_slow
                else None
            ),
        )
        with self._lock:
            self.drones[drone] = runtime
        return runtime

    def _follow_command(
        self, runtime: DroneRuntime, cmd: FollowCommand, parsed: Parsed, now_s: float
    ) -> None:
        self._tell_ignored(runtime.drone, parsed, now_s)
        refusal = self._refuse_follow(runtime, cmd, now_s)
        if refusal is not None:
            field, reason = refusal
            self.count_drop(runtime.drone, "follow_refused", reason)
            self._emit(
                runtime.drone, "rejected", "follow", now_s, parsed.source, reason, field=field
            )
            return
        before = self._follow_info(runtime)
        self._apply_follow(runtime, cmd)
        after = self._follow_info(runtime)
        changes: dict[str, Any] = {"enabled": after.enabled}
        for name in ("threshold_n", "land_below_m"):
            if getattr(after, name) != getattr(before, name):
                changes[name] = getattr(after, name)
        if before.enabled != after.enabled:
            reason = FOLLOW_ON if after.enabled else FOLLOW_OFF
        else:
            reason = "re-tuned" if len(changes) > 1 else "no change"
        self._emit(runtime.drone, "follow", "follow", now_s, parsed.source, reason, changes=changes)

    def _apply_follow(self, runtime: DroneRuntime, cmd: FollowCommand) -> None:
        fp = runtime.follow_params
        if cmd.threshold_n is not None:
            fp = replace(fp, threshold_n=cmd.threshold_n)
        if cmd.land_below_m is not None:
            fp = replace(fp, land_below_m=cmd.land_below_m)
        if fp.land_below_m is not None:
            runtime.land_below_m_memory = fp.land_below_m
        if cmd.land is False:
            fp = replace(fp, land_below_m=None)
        elif cmd.land is True and fp.land_below_m is None:
            fp = replace(fp, land_below_m=runtime.land_below_m_memory)
        runtime.follow_params = fp
        runtime.follow_state = follow_mod.set_enabled(runtime.follow_state, cmd.enabled)

    def _telemetry(self, runtime: DroneRuntime, msg: Telemetry, now_s: float) -> list[Sample]:
        front = self._telemetry_front(runtime, msg, now_s)
        if front is None:
            return []
        loc_in = front[8]
        position = self._localize_one(loc_in) if loc_in is not None else None
        return self._telemetry_back(front, position)

    def _telemetry_front(
        self, runtime: DroneRuntime, msg: Telemetry, now_s: float
    ) -> _Front | None:
        """A telemetry message up to its localization: checks, observation, contact, filter.

        Returns None for a dropped message, else what :meth:`_telemetry_back` needs, with
        the localization's inputs (None when there is nothing to localize).
        """
        runtime.received += 1
        msg = self._usable_position(runtime, msg, now_s)
        accel = msg.accel_mps2
        offset = runtime.rest.offset if runtime.rest is not None else None
        if offset is not None and runtime.slow_params is None:
            # (With the slow stage on, it owns the accelerometer's per-power-on error, x/y at
            # rest included: the rest offset is still measured and reported, not applied.)
            # Rest calibration: the offset found at rest is extra accelerometer bias (the one
            # in force; this sample enters the rest window only once accepted, below).
            ox, oy, _ = offset.offset_body_mps2.tolist()
            accel = (accel[0] - ox, accel[1] - oy, accel[2])
        accel_read = accel  # before the slow correction, which learns from it below
        velocity = None
        if runtime.slow_params is not None:
            # The accelerometer's slow error learnt so far (groundstation.slow_accel).
            accel = slow_mod.correct_accel_body_mps2(runtime.slow, accel)
            velocity = slow_mod.drag_velocity_world_mps(runtime.slow)
        # Malformed content first (whatever its seq), then the stream's order.
        try:
            obs = observe_tension(
                accel,
                msg.quat_wxyz,
                msg.thrust_n,
                runtime.params.drone.mass_kg,
                armed=msg.armed,
                calibration=runtime.calibration,
                vbat_v=msg.vbat_v,
                ground_thrust_ratio=runtime.contact_params.ground_thrust_ratio,
                velocity_world_mps=velocity,
            )
        except DegenerateQuaternionError as exc:
            self.count_drop(runtime.drone, "bad_quaternion", str(exc))
            return None
        except TensionError as exc:
            self.count_drop(runtime.drone, "bad_observation", str(exc))
            return None
        resumed = runtime.stale or (
            runtime.last_seen_s is not None and now_s - runtime.last_seen_s > _MAX_GAP_S
        )
        if runtime.last_seq is not None and msg.seq <= runtime.last_seq and not resumed:
            kind = "seq_repeated" if msg.seq == runtime.last_seq else "seq_backwards"
            self.count_drop(
                runtime.drone, kind, f"seq {msg.seq} after {runtime.last_seq} on {runtime.drone}"
            )
            return None
        if runtime.last_stamp_s is not None and msg.stamp_s <= runtime.last_stamp_s and not resumed:
            self.count_drop(
                runtime.drone,
                "stamp_backwards",
                f"stamp_s {msg.stamp_s} after {runtime.last_stamp_s} on {runtime.drone}",
            )
            return None

        if runtime.last_seq is not None and msg.seq > runtime.last_seq + 1 and not resumed:
            runtime.seq_gaps += msg.seq - runtime.last_seq - 1
        if resumed:
            runtime.filter.reset()
            runtime.filter_prior = None
        dt_s = (
            0.0 if runtime.last_stamp_s is None or resumed else msg.stamp_s - runtime.last_stamp_s
        )
        runtime.last_seq = msg.seq
        runtime.last_stamp_s = msg.stamp_s
        runtime.last_seen_s = now_s
        if msg.position_m is not None:
            runtime.mocap_m = msg.position_m
            runtime.mocap_stamp_s = msg.stamp_s
        runtime.stale = False
        runtime.accepted += 1
        runtime.telemetry_rate.add(now_s)
        if runtime.rest is not None:
            self._feed_rest(runtime, msg, now_s)

        # Ground or air, with hysteresis: between ground_thrust_ratio and the weight the
        # floor may still carry the drone (its push is no tension) until lift-off is seen.
        runtime.contact = contact_mod.contact_step(
            runtime.contact,
            runtime.contact_params,
            dt_s=dt_s,
            armed=msg.armed,
            thrust_n=obs.thrust_n,  # calibrated
            mass_kg=runtime.params.drone.mass_kg,
            vertical_accel_mps2=contact_mod.vertical_accel_mps2(msg.accel_mps2, msg.quat_wxyz),
            height_m=msg.position_m[2] if msg.position_m is not None else None,
            floor_z_m=runtime.params.base.floor_z_m,
        )
        # Issue 23: a low thrust alone (no observation) is no ground; the contact decides.
        on_ground = runtime.contact.on_ground or not msg.armed
        self._check_vbat_range(runtime, msg.vbat_v, on_ground, now_s)
        if runtime.slow_params is not None:
            self._learn_slow(runtime, msg, accel_read, dt_s, on_ground, obs.tension_world_n)
        ext = runtime.calibration_extrapolated  # this sample's (a later front moves it)
        mocap = _fresh_mocap(runtime, msg.stamp_s)  # likewise
        tail = (ext, mocap)  # the last two fields of the front, as they are now

        tension: Sequence[float] = _ZEROS3
        std: Sequence[float] = _ZEROS3
        converged = False
        if on_ground:
            # On the ground the floor carries the drone: no tension estimate. The filter
            # restarts at lift-off rather than from the floor's reaction, from the prior
            # that a tether resting on the floor pulls on the drone with next to nothing:
            # if the drone was seen resting (disarmed or below the thrust ratio). Found in
            # the air without that (a service started mid-flight) it starts from its first
            # observation instead.
            if runtime.contact.reason in ("disarmed", "low_thrust"):
                runtime.rested = True
            # Reset once on the ground (again if the prior changes), not per sample: the
            # noise estimate learns the propellers' vibration from the floor's samples in
            # between (TensionFilter.learn_noise), so the restart at lift-off weighs its
            # first samples with the flight's noise rather than the prior's.
            if runtime.filter.initialized or runtime.filter_prior != runtime.rested:
                if runtime.rested:
                    runtime.filter.reset(
                        prior_world_n=(0.0, 0.0, 0.0), prior_std_n=LIFTOFF_PRIOR_STD_N
                    )
                else:
                    runtime.filter.reset()
                runtime.filter_prior = runtime.rested
            if obs.tension_world_n is not None:
                runtime.filter.learn_noise(obs.tension_world_n, dt_s)
        else:
            runtime.rested = False
            runtime.filter_prior = None
            if obs.tension_world_n is None:
                # Low thrust in the air (a dip, a hard descent, a touch-down not yet seen at
                # rest): the floor may carry part of the weight, so no observation is taken
                # and the filter coasts on its last estimate.
                coasted = runtime.filter.coast(dt_s)
                if coasted is None:  # nothing to coast before the first observation
                    return (runtime, msg, now_s, tension, std, False, False, True, None, *tail)
                est = coasted
            else:
                est = runtime.filter.update(
                    obs.tension_world_n, dt_s, thrust_axis_world=obs.thrust_axis_world
                )
            if est.change_detected:
                runtime.change_detections += 1
            # Python floats from here on: a handful of numbers per message, for which
            # numpy's per-call overhead would cost more than the arithmetic.
            tension = est.tension_world_n.tolist()
            std = est.std_n.tolist()
            converged = est.converged
            if not (_finite(tension) and _finite(std)):
                # Checked here, not with the Estimate: the reset must come before the
                # drone's next message is filtered (in a batch, before its localization).
                self.count_drop(runtime.drone, "non_finite_estimate", "filter produced NaN/inf")
                runtime.filter.reset()
                runtime.filter_prior = None
                return (runtime, msg, now_s, tension, std, on_ground, converged, False, None, *tail)
            if converged:
                # Exit angles only while fresh: the reel reports at its own rate.
                loc_in = (
                    est.tension_world_n,
                    est.cov_n2,
                    runtime.weight_n_per_m,
                    runtime.length_m,
                    runtime.base_world_m,
                    runtime.params.base.floor_z_m,
                    runtime.exit_azimuth
                    if self._reel_fresh(runtime.exit_azimuth_received_s, now_s)
                    else None,
                    runtime.exit_elevation
                    if self.settings.localization.elevation
                    and self._reel_fresh(runtime.exit_elevation_received_s, now_s)
                    else None,
                    msg.position_m,
                )
                return (
                    runtime,
                    msg,
                    now_s,
                    tension,
                    std,
                    on_ground,
                    converged,
                    True,
                    loc_in,
                    *tail,
                )
        return (runtime, msg, now_s, tension, std, on_ground, converged, True, None, *tail)

    def _localize_one(self, loc_in: _LocalizeIn) -> PositionEstimate | None:
        loc = self.settings.localization
        tension_n, cov_n2, weight, length, base, floor, exit_az, exit_el, mocap = loc_in
        return localize(
            tension_n,
            cov_n2,
            weight,
            length,
            base,
            floor,
            azimuth=loc.azimuth,
            exit_azimuth=exit_az,
            exit_elevation=exit_el,
            mocap_world_m=mocap,
            mocap_std_m=loc.mocap_std_m,
        )

    def _localize_many(self, inputs: list[_LocalizeIn]) -> list[PositionEstimate | None]:
        """:meth:`_localize_one` of each: computed together once there are enough to pay
        for it (:func:`localization.localize_batch`, which gives the same floats)."""
        if len(inputs) < BATCH_LOCALIZE_MIN:
            return [self._localize_one(x) for x in inputs]
        loc = self.settings.localization
        cols = list(zip(*inputs, strict=True))
        exit_az, exit_el = list(cols[6]), list(cols[7])
        return localize_batch(
            np.array(cols[0]),
            np.array(cols[1]),
            np.array(cols[2], dtype=float),
            np.array(cols[3], dtype=float),
            np.array(cols[4]),
            np.array(cols[5], dtype=float),
            azimuth=loc.azimuth,
            exit_azimuth=exit_az if any(v is not None for v in exit_az) else None,
            exit_elevation=exit_el if any(v is not None for v in exit_el) else None,
            mocap_world_m=list(cols[8]) if loc.azimuth == "mocap" else None,
            mocap_std_m=loc.mocap_std_m,
        )

    def _telemetry_back(self, front: _Front, position: PositionEstimate | None) -> list[Sample]:
        """A telemetry message from its localization on: follow, the Estimate, commands."""
        runtime, msg, now_s, tension, std, on_ground, converged, finite, _, ext, mocap = front
        # This sample's flag, as the front pass left it (in a batch, later messages' front
        # passes have moved it since).
        runtime.calibration_extrapolated = ext
        fs = runtime.follow_state
        if not (fs.enabled or fs.active) and math.isfinite(msg.stamp_s):
            # Follow off: follow_step's steps 1 and 2 would only move the stamp (no
            # setpoint, no stop), at the cost of two dataclasses.replace (~10 us).
            runtime.follow_state = _follow_stamped(fs, msg.stamp_s)
            decision = None
        else:
            follow_position = (
                np.array(mocap, dtype=float)
                if mocap is not None
                else (position.position_world_m if position is not None else None)
            )
            untrusted = _no_trusted_position(runtime, mocap)
            decision = follow_mod.follow_step(
                fs,
                runtime.follow_params,
                stamp_s=msg.stamp_s,
                tension_norm_n=_norm3(tension) if converged else None,
                # Uncalibrated and without motion capture there is no position to fly to
                # (follow's rule 3: no setpoint, no Stop, landing not armed).
                position_world_m=None if untrusted else follow_position,
                base_world_m=runtime.base_world_m,
                length_m=runtime.length_m,
                floor_z_m=runtime.params.base.floor_z_m,
                tension_world_n=tension if converged else None,
                position_is_external=mocap is not None,
                weight_n_per_m=runtime.weight_n_per_m,
                on_ground=on_ground,
            )
            if untrusted and decision.state.enabled and not decision.state.stopped:
                decision = replace(
                    decision, state=replace(decision.state, reason=UNTRUSTED_POSITION_REASON)
                )
            runtime.follow_state = decision.state
        out: list[Sample] = []
        estimate = (
            self._estimate(runtime, msg, tension, std, position, on_ground, converged)
            if finite
            else None
        )
        if estimate is not None:
            runtime.estimates += 1
            runtime.estimate_rate.add(now_s)
            out.append(Sample(runtime.estimate_key, estimate))
        if decision is None:
            return out
        if decision.setpoint_world_m is not None and _finite(decision.setpoint_world_m):
            sp = Setpoint(stamp_s=msg.stamp_s, position_m=_vec3(decision.setpoint_world_m))
            runtime.setpoints += 1
            out.append(Sample(f"tether/{runtime.drone}/cmd/setpoint", sp.to_json()))
        if decision.stop_reason is not None:
            runtime.stops += 1
            stop = Stop(stamp_s=msg.stamp_s, reason=decision.stop_reason, kind="land")
            out.append(Sample(f"tether/{runtime.drone}/cmd/stop", stop.to_json()))
            self._emit(runtime.drone, "stop", "service", now_s, self.self_id, decision.stop_reason)
        return out

    def _learn_slow(
        self,
        runtime: DroneRuntime,
        msg: Telemetry,
        accel_read: tuple[float, float, float],
        dt_s: float,
        on_ground: bool,
        tension_obs: object,
    ) -> None:
        """One sample into the slow-accelerometer state: at rest (disarmed, still), in the
        air (observing), or held (spool-up, landing, a dip)."""
        phase: slow_mod.Phase
        if not msg.armed and slow_mod.is_still(accel_read, msg.gyro_rps):
            phase = "rest"
        elif not on_ground and tension_obs is not None:
            phase = "air"
        else:
            phase = "hold"
        assert runtime.slow_params is not None
        if runtime.calibration is not None:
            # β is what remains beyond a configured bias, which observe_tension subtracts.
            bx, by, bz = runtime.calibration.accel_bias_mps2
            accel_read = (accel_read[0] - bx, accel_read[1] - by, accel_read[2] - bz)
        runtime.slow = slow_mod.slow_accel_step(
            runtime.slow,
            runtime.slow_params,
            dt_s=dt_s,
            stamp_s=msg.stamp_s,
            accel_body_mps2=accel_read,
            R_world_body=slow_mod.rows_from_quat_wxyz(msg.quat_wxyz),
            phase=phase,
            mocap_world_m=msg.position_m,
        )

    def _feed_rest(self, runtime: DroneRuntime, msg: Telemetry, now_s: float) -> None:
        """Feed an accepted sample to the rest calibration; warn when a calibration that
        relies on it arms without a rest offset.

        Only after the seq/stamp checks: a repeated or out-of-order message must not enter
        the still window (a repeat's stamp alone restarts it). With ``[calibration]
        rest_required`` (``groundstation calibrate`` kept the x/y bias as configured because
        the rest offset replaces it) a drone that arms with no rest offset in force flies with
        an x/y bias nobody calibrated: ``status`` says so until the next disarm, and the
        ``warning`` Event is sent the first time only.
        """
        rest = runtime.rest
        assert rest is not None
        was_armed = rest.armed
        rest.update(msg.stamp_s, msg.accel_mps2, msg.quat_wxyz, msg.armed, msg.gyro_rps)
        if not runtime.params.calibration.rest_required:
            return
        if not msg.armed:
            runtime.rest_missing = False
        elif not was_armed and rest.offset is None:
            runtime.rest_missing = True
            if not runtime.rest_missing_told:
                runtime.rest_missing_told = True
                self._warn(
                    runtime,
                    now_s,
                    f"{runtime.drone}: armed without a rest offset in force, but its calibration "
                    "relies on one ([calibration] rest_required: the thrust axis was fitted with "
                    "the x/y accelerometer bias left to the rest calibration): the x/y bias is "
                    "the configured one, not this power-on's. Let the drone sit disarmed and "
                    "still on the floor for 1 s before arming (status rest_calibration; told "
                    "once)",
                    field="armed",
                )

    def _check_vbat_range(
        self, runtime: DroneRuntime, vbat_v: float | None, on_ground: bool, now_s: float
    ) -> None:
        """Flag a battery voltage outside the calibrated range; tell it once per drone.

        The thrust map (``thrust_scale``, ``thrust_vbat_slope_per_v``) holds where it was
        fitted; outside ``[calibration] thrust_vbat_range_v`` it is an extrapolation, which a
        battery effect on thrust turns into a position error of tens of cm (docs/calibration.md).
        The flag follows every sample; the ``warning`` Event (logged by the service) is sent
        the first time only. On the ground no tension is estimated from the thrust, and an
        unloaded battery reads well above its voltage in flight (0.5–0.6 V on the NanoBench
        Crazyflie 2.1 flights), so there the flag is None rather than a false alarm.
        """
        runtime.last_vbat_v = vbat_v
        rng = runtime.vbat_range_v
        if rng is None or vbat_v is None or on_ground:
            runtime.calibration_extrapolated = None
            return
        outside = not (rng[0] <= vbat_v <= rng[1])
        runtime.calibration_extrapolated = outside
        if outside and not runtime.extrapolation_told:
            runtime.extrapolation_told = True
            self._warn(
                runtime,
                now_s,
                f"{runtime.drone}: battery {vbat_v:.3f} V outside the range the thrust map was "
                f"calibrated over ({rng[0]:.3f}–{rng[1]:.3f} V, [calibration] "
                "thrust_vbat_range_v): thrust, tension and position are extrapolated "
                "(calibration_extrapolated in Estimate and status; told once)",
                field="vbat_v",
            )

    def _estimate(
        self,
        runtime: DroneRuntime,
        msg: Telemetry,
        tension: np.ndarray | Sequence[float],
        std: np.ndarray | Sequence[float],
        position: PositionEstimate | None,
        on_ground: bool,
        converged: bool,
    ) -> bytes | None:
        """The Estimate's JSON (:func:`encode_estimate`: no model per message), or None.

        ``tension`` and ``std`` are finite (:meth:`_telemetry_front` has checked them).
        """
        tension = _vec3(tension)
        std = _vec3(std)
        follow = self._follow_info(runtime)
        cached = runtime.follow_json_cache
        if cached is None or cached[0] is not follow:
            cached = runtime.follow_json_cache = (follow, follow.model_dump())
        base = runtime.base_cache
        if base is None or base[0] is not runtime.base_world_m:
            base = runtime.base_cache = (runtime.base_world_m, _vec3(runtime.base_world_m))
        position_m = position_std_m = None
        if position is not None:
            position_m = _vec3(position.position_world_m)
            position_std_m = _vec3(position.std_world_m)
            if not (_finite(position_m) and _finite(position_std_m)):
                position = position_m = position_std_m = None
        # In the model's order (ESTIMATE_FIELD_ORDER): encode_estimate_ordered takes it as is.
        radial_m = radial_interval_m = azimuth_determined = azimuth_source = None
        floor_contact = None
        if position is not None:
            lo, hi = position.radial_interval_m
            radial_m = float(position.radial_m)
            radial_interval_m = (float(lo), float(hi))
            azimuth_determined = position.azimuth_determined
            azimuth_source = position.azimuth_source
            floor_contact = bool(position.floor_contact)
        fields: dict[str, Any] = {
            "seq": msg.seq,
            "stamp_s": msg.stamp_s,
            "tension_n": tension,
            "tension_std_n": std,
            "horizontal_n": math.hypot(tension[0], tension[1]),
            "vertical_n": -tension[2],
            "position_m": position_m,
            "follow": cached[1],
            "position_std_m": position_std_m,
            "radial_m": radial_m,
            "radial_interval_m": radial_interval_m,
            "azimuth_determined": azimuth_determined,
            "azimuth_source": azimuth_source,
            "floor_contact": floor_contact,
            "on_ground": on_ground,
            "converged": converged,
            "length_m": runtime.length_m,
            "base_m": base[1],
            "calibration": runtime.calibration_source,
            "calibration_extrapolated": runtime.calibration_extrapolated,
        }
        try:
            payload = encode_estimate_ordered(fields)
        except ValueError as exc:  # a non-finite field the checks above did not cover
            self.count_drop(runtime.drone, "non_finite_estimate", str(exc))
            return None
        runtime.last_estimate_fields = fields
        return payload

    def _follow_info(self, runtime: DroneRuntime) -> FollowInfo:
        """The Estimate's ``follow`` object (also the status's)."""
        fs = runtime.follow_state
        fp = runtime.follow_params
        # FollowInfo changes only when follow changes state: reuse it (it is frozen). The
        # params are compared by identity, so their floats are the very same objects.
        flags = (fs.enabled, fs.active, fs.landing_armed, fs.stopped, fs.reason)
        cached = runtime.follow_info_cache
        if cached is not None and cached[0] is fp and cached[1] == flags:
            follow = cached[2]
        else:
            follow = FollowInfo(
                enabled=fs.enabled,
                active=fs.active,
                threshold_n=fp.threshold_n,
                land_below_m=fp.land_below_m,
                landing_armed=fs.landing_armed,
                stopped=fs.stopped,
                reason=fs.reason,
            )
            runtime.follow_info_cache = (fp, flags, follow)
        return follow

    # ---------------------------------------------------------------- health

    def status(self, drone: str, now_s: float) -> dict[str, Any] | None:
        """Health of one drone as a JSON-ready dict (``tether/{drone}/status``)."""
        with self._lock:
            runtime = self.drones.get(drone)
            if runtime is None:
                return None
            drops = dict(runtime.drops)
        return {
            "drone": drone,
            "stale": runtime.stale,
            "telemetry_hz": runtime.telemetry_rate.hz(now_s),
            "estimate_hz": runtime.estimate_rate.hz(now_s),
            "last_seen_age_s": None
            if runtime.last_seen_s is None
            else max(0.0, now_s - runtime.last_seen_s),
            "received": runtime.received,
            "accepted": runtime.accepted,
            "estimates": runtime.estimates,
            "setpoints": runtime.setpoints,
            "stops": runtime.stops,
            "seq_gaps": runtime.seq_gaps,
            "drops": drops,
            "invalid": sum(v for k, v in drops.items() if k != "queue_overflow"),
            "queue_overflow": drops.get("queue_overflow", 0),
            "filter": {
                "initialized": runtime.filter.initialized,
                "change_detections": runtime.change_detections,
                **_noise_status(runtime.filter),
            },
            "follow": self._follow_info(runtime).model_dump(),
            "contact": {"on_ground": runtime.contact.on_ground, "reason": runtime.contact.reason},
            "length_m": runtime.length_m,
            "length_source": runtime.length_source,
            "base_m": list(map(float, runtime.base_world_m)),
            "weight_n_per_m": runtime.weight_n_per_m,
            "calibration": runtime.calibration_source,
            "calibration_extrapolated": runtime.calibration_extrapolated,
            "calibration_vbat_range_v": (
                None if runtime.vbat_range_v is None else list(runtime.vbat_range_v)
            ),
            "vbat_v": runtime.last_vbat_v,
            "rest_calibration": _rest_status(runtime),
        }

    def drone_ids(self) -> Iterable[str]:
        with self._lock:
            return list(self.drones)


_ZEROS3 = (0.0, 0.0, 0.0)

_LocalizeIn = tuple[
    np.ndarray,
    np.ndarray,
    float,
    float,
    np.ndarray,
    float,
    AngleObservation | None,
    AngleObservation | None,
    "tuple[float, float, float] | None",
]
"""localize()'s inputs for one message: tension, its covariance, weight, length, base,
floor, exit azimuth, exit elevation, motion-capture position."""
_Front = tuple[
    DroneRuntime,
    Telemetry,
    float,
    Sequence[float],
    Sequence[float],
    bool,
    bool,
    bool,
    "_LocalizeIn | None",
    "bool | None",
    "tuple[float, float, float] | None",
]
"""A telemetry message stepped up to its localization (:meth:`Pipeline._telemetry_front`):
runtime, message, receive time, tension, its std, on the ground, converged, finite, the
localization's inputs (None: nothing to localize), calibration_extrapolated, the motion
capture position held for it (:func:`_fresh_mocap`)."""


def _follow_stamped(state: follow_mod.FollowState, stamp_s: float) -> follow_mod.FollowState:
    """``dataclasses.replace(state, last_stamp_s=stamp_s)`` in a fifth of its time.

    The per-message step while follow is off; FollowState is frozen, so the new one is
    filled the way a frozen dataclass fills itself, through its ``__dict__``.
    """
    new = object.__new__(follow_mod.FollowState)
    fields = new.__dict__
    fields.update(state.__dict__)
    fields["last_stamp_s"] = stamp_s
    return new


def _rest_status(runtime: DroneRuntime) -> dict[str, Any] | None:
    """Status of the rest calibration: off (None), or the offset in force (or none yet);
    with ``[calibration] rest_required``, whether the drone armed without one."""
    rest = runtime.rest
    if rest is None:
        return None
    off = rest.offset
    out: dict[str, Any] = {"in_force": False}
    if off is not None:
        out = {
            "in_force": True,
            "offset_mps2": [float(v) for v in off.offset_body_mps2[:2]],
            "std_mps2": [float(v) for v in off.std_mps2[:2]],
            "duration_s": off.duration_s,
            "stamp_s": off.stamp_s,
        }
    if runtime.params.calibration.rest_required:
        out["required"] = True
        out["missing_at_arming"] = runtime.rest_missing
    return out


def _noise_status(filt: TensionFilter) -> dict[str, Any]:
    """The filter's measured observation noise for ``status`` (None before any sample)."""
    s2, rho, _ = filt.noise_model()
    est = filt.estimate
    tau = est.time_constant_s if est is not None else math.nan
    return {
        "noise_std_n": [math.sqrt(v) for v in s2],
        "noise_autocorrelation": list(rho),
        "time_constant_s": tau if math.isfinite(tau) else None,
    }


def _finite(values: np.ndarray | Iterable[float]) -> bool:
    # The per-message cases, 3 floats in a list, tuple or float64 array, without numpy's
    # per-call overhead; anything else as before.
    if type(values) is np.ndarray and values.dtype == np.float64 and values.ndim == 1:
        return all(map(math.isfinite, values.tolist()))
    if type(values) is tuple or type(values) is list:
        try:
            return all(map(math.isfinite, values))
        except TypeError:
            pass
    return bool(np.all(np.isfinite(np.asarray(values, dtype=float))))


def _norm3(v: Sequence[float]) -> float:
    """``float(np.linalg.norm(v))`` of 3 floats: sqrt of the dot in numpy's order."""
    return math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


def _vec3(values: np.ndarray | Iterable[float]) -> tuple[float, float, float]:
    if type(values) is np.ndarray and values.dtype == np.float64 and values.shape == (3,):
        x, y, z = values.tolist()
        return (x, y, z)
    if (type(values) is tuple or type(values) is list) and len(values) == 3:
        x, y, z = values
        if type(x) is float and type(y) is float and type(z) is float:
            return (x, y, z)
    a = np.asarray(values, dtype=float)
    return (float(a[0]), float(a[1]), float(a[2]))
