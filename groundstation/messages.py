"""Payloads of the public contract (``docs/contract.md``) as frozen pydantic v2 models.

Inputs are validated strictly: finite floats only, exact vector lengths, ranges (thrust ≥ 0,
length > 0, threshold > 0), no type coercion from strings or bools; unknown fields are
ignored, as the contract says. Outputs serialise to compact UTF-8 JSON.

Fields added beside the contract are marked "(added)". These models are the one definition of
each payload: the field tables of ``docs/contract.md`` are generated from them
(``python scripts/contract.py``; ``tests/test_contract.py`` fails when they disagree) and so
are the recorder's JSON schemas (:func:`groundstation.recording.schema_for_key`).
"""

from __future__ import annotations

import json
import math
import re
from typing import Annotated, Any, Literal, Self

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError

__all__ = [
    "DRONE_ID_RE",
    "EVENT_KINDS",
    "KEY_KINDS",
    "AttitudeSource",
    "Estimate",
    "EstimateSmoothed",
    "Event",
    "FollowCommand",
    "FollowInfo",
    "InvalidMessage",
    "LandIn",
    "MocapPoseIn",
    "Reel",
    "Setpoint",
    "Status",
    "Stop",
    "TakeoffIn",
    "Telemetry",
    "TetherParams",
    "Truth",
    "encode_estimate",
    "parse_key",
]

DRONE_ID_RE = re.compile(r"[A-Za-z0-9_-]{1,64}")
KEY_KINDS = (
    "telemetry",
    "reel",
    "estimate",
    "follow",
    "params",
    "status",
    "cmd/setpoint",
    "cmd/stop",
    "truth",
    "events",
)
_KEY_RE = re.compile(r"tether/([^/]+)/(" + "|".join(KEY_KINDS) + ")")

Finite = Annotated[float, Field(allow_inf_nan=False)]
Vec3 = tuple[Finite, Finite, Finite]
Vec4 = tuple[Finite, Finite, Finite, Finite]
PositiveStd = Annotated[float, Field(gt=0.0, allow_inf_nan=False)]


class InvalidMessage(ValueError):
    """A payload or key that the contract does not allow; ``kind`` names the reason.

    ``field`` names the first offending field (dotted, e.g. ``threshold_n`` or
    ``accel_mps2.2``) where one is to blame; ``ignored`` lists unknown top-level fields the
    payload carried (ignored, as the contract says, but often a typo worth telling).
    """

    def __init__(
        self,
        kind: str,
        detail: str,
        *,
        field: str | None = None,
        ignored: tuple[str, ...] = (),
    ) -> None:
        super().__init__(f"{kind}: {detail}")
        self.kind = kind
        self.detail = detail
        self.field = field
        self.ignored = ignored


def parse_key(key: str) -> tuple[str, str]:
    """Split ``tether/{drone}/{kind}`` into ``(drone, kind)``.

    Raises:
        InvalidMessage: ``bad_key`` for a key outside the contract, ``bad_drone_id`` for a
            drone id outside ``[A-Za-z0-9_-]{1,64}``.
    """
    m = _KEY_RE.fullmatch(key)
    if m is None:
        raise InvalidMessage("bad_key", f"key {key!r} is not tether/{{drone}}/<kind>")
    drone, kind = m.group(1), m.group(2)
    if not DRONE_ID_RE.fullmatch(drone):
        raise InvalidMessage("bad_drone_id", f"drone id {drone[:80]!r} is outside the contract")
    return drone, kind


class _In(BaseModel):
    """Base of inbound payloads: strict, finite, frozen, unknown fields ignored."""

    model_config = ConfigDict(
        frozen=True,
        strict=True,
        extra="ignore",
        allow_inf_nan=False,
        use_attribute_docstrings=True,
    )

    @classmethod
    def parse(cls, payload: bytes) -> Self:
        """Validate a JSON payload.

        Raises:
            InvalidMessage: ``not_json`` or ``invalid`` with pydantic's reasons, the first
                offending field, and the unknown fields the payload carried.
        """
        try:
            return cls.model_validate_json(payload)
        except ValidationError as exc:
            raise _invalid(cls.__name__, exc, ignored=cls.unknown_fields(payload)) from None

    @classmethod
    def unknown_fields(cls, payload: bytes) -> tuple[str, ...]:
        """Top-level keys of a JSON object payload that are not fields of this model.

        The contract ignores them; a command that carries one was often mistyped
        (``{"enable": true}``). Empty for anything that is not a JSON object.
        """
        try:
            obj = json.loads(payload)
        except ValueError:
            return ()
        if not isinstance(obj, dict):
            return ()
        return tuple(sorted(str(k) for k in obj if k not in cls.model_fields))[:8]


def _invalid(model: str, exc: ValidationError, *, ignored: tuple[str, ...] = ()) -> InvalidMessage:
    """The InvalidMessage for a failed validation: pydantic's reasons, the first offending
    field, and the unknown fields the payload carried (``ignored``)."""
    errors = exc.errors(include_url=False, include_input=False)
    if errors and errors[0]["type"] in {"json_invalid", "json_type"}:
        return InvalidMessage("not_json", errors[0]["msg"])
    detail = "; ".join(
        f"{'.'.join(str(p) for p in e['loc']) or '<root>'}: {e['msg']}" for e in errors[:4]
    )
    if ignored:
        detail += f" (unknown fields ignored: {', '.join(map(repr, ignored))})"
    field = ".".join(str(p) for p in errors[0]["loc"]) if errors else ""
    return InvalidMessage("invalid", f"{model}: {detail}", field=field or None, ignored=ignored)


class _Out(BaseModel):
    model_config = ConfigDict(
        frozen=True, allow_inf_nan=False, extra="forbid", use_attribute_docstrings=True
    )

    def to_json(self) -> bytes:
        """Compact UTF-8 JSON."""
        return self.model_dump_json().encode()

    @classmethod
    def read(cls, payload: bytes) -> Self:
        """(added) Validate a payload another process published (the dashboard reads
        Estimates, Truth, status): strict and finite as an input, unknown fields ignored at
        every level, as the contract says, so a newer publisher's additions do not break a
        reader. What this process publishes is still checked with ``extra="forbid"``.

        Raises:
            InvalidMessage: ``not_json`` or ``invalid`` with pydantic's reasons.
        """
        try:
            return cls.model_validate_json(payload, strict=True, extra="ignore")
        except ValidationError as exc:
            raise _invalid(cls.__name__, exc) from None


AttitudeSource = Literal["onboard", "external"]
"""Where an attitude comes from: ``onboard``, the drone's own estimator, or ``external``,
motion capture's rigid body (Telemetry's ``attitude_source``; ``[drone]`` and
``[calibration] attitude_source``)."""


class Telemetry(_In):
    """Drone → ground station, ``tether/{drone}/telemetry``."""

    seq: int = Field(ge=0)
    """Increases by one per message."""
    stamp_s: Finite
    """Drone clock, seconds."""
    accel_mps2: Vec3
    """IMU specific force in the body frame, m/s² (about [0, 0, 9.81] level at rest)."""
    quat_wxyz: Vec4
    """Attitude, body → world, scalar first."""
    thrust_n: Finite = Field(ge=0.0)
    """Collective rotor thrust along body +z, newtons."""
    gyro_rps: Vec3 | None = None
    """Body rates, rad/s."""
    position_m: Vec3 | None = None
    """External (motion-capture) position, world frame, metres."""
    armed: bool = True
    """Motors armed."""
    vbat_v: Finite | None = Field(default=None, gt=0.0)
    """(added) Battery voltage, volts, where the drone reports it (battery-aware thrust)."""
    position_source: Literal["mocap", "lighthouse", "loco", "flow"] | None = None
    """(added) What measured ``position_m``: ``mocap`` (motion capture; also when absent), or
    the drone's onboard estimator fusing a Lighthouse, Loco or Flow deck."""
    position_std_m: tuple[PositiveStd, PositiveStd, PositiveStd] | None = None
    """(added) Per-axis standard deviation of ``position_m``, world frame, metres (an onboard
    estimator's own); absent: motion capture's (``[localization] mocap_std_m``). A position
    whose σ exceeds ``[localization] position_max_std_m`` on any axis is no position to the
    service (a Flow deck's x/y: odometry, σ about 10 m)."""
    attitude_source: AttitudeSource | None = None
    """(added) Where ``quat_wxyz`` comes from: ``onboard``, the drone's own estimator
    (levelled on the same accelerometer ``accel_mps2`` reads), or ``external``, motion
    capture's rigid body (its axes set by the markers, not by the IMU or the thrust);
    absent: ``[drone] attitude_source``. The estimator trusts the attitude's level (its hover
    model) only when the calibration's thrust axis was fitted against the same source
    (docs/attitude_source.md)."""


class Reel(_In):
    """Reel → ground station, ``tether/{drone}/reel``."""

    stamp_s: Finite
    """Reel clock, seconds."""
    length_m: Finite = Field(gt=0.0)
    """Tether paid out from the base exit point to the drone, metres."""
    base_m: Vec3 | None = None
    """World position of the base exit point, metres."""
    exit_azimuth_rad: Finite | None = None
    """(added) World-frame azimuth of the tether's horizontal direction where it leaves the
    base, pointing from the base toward the drone, radians (atan2(y, x))."""
    exit_azimuth_std_rad: Finite | None = Field(default=None, gt=0.0)
    """(added) Standard deviation of ``exit_azimuth_rad``. Absent: ``[localization]
    exit_azimuth_std_rad`` over cos(``exit_elevation_rad``), the elevation of this or the
    last fresh message (near plumb the azimuth is noise: at plumb no azimuth); without one,
    as is."""
    exit_elevation_rad: Finite | None = Field(default=None, ge=-1.5708, le=1.5708)
    """(added) The tether's angle above horizontal where it leaves the base, radians."""
    exit_elevation_std_rad: Finite | None = Field(default=None, gt=0.0)
    """(added) Standard deviation of ``exit_elevation_rad``."""


class FollowCommand(_In):
    """Anyone → ground station, ``tether/{drone}/follow``."""

    enabled: bool
    """Follow mode on or off (required)."""
    threshold_n: Finite | None = Field(default=None, gt=0.0)
    """Pull above which the drone follows it, newtons: the tension beyond the tether's own
    (what the tether pulls with in quiet hover at the drone's position), not the tension's
    norm, so 0.10 N means a hand pulling with 0.10 N at any reach, near taut too; absent keeps
    the current setting. The service refuses values below ``[service]
    follow_threshold_min_n``."""
    land_below_m: Finite | None = None
    """Tug-to-land height, metres (world z); absent keeps the current setting."""
    land: bool | None = None
    """(added) Switch tug-to-land off (False) or back on (True) without changing the height."""


class TetherParams(_In):
    """(added) Operator → ground station, ``tether/{drone}/params``: tether ω and length.

    The length is taken only while no reel reports one.
    """

    weight_n_per_m: Finite | None = Field(default=None, gt=0.0)
    """Tether weight per length ω, N/m."""
    length_m: Finite | None = Field(default=None, gt=0.0)
    """Tether length paid out, metres (ignored while a reel reports one)."""


class FollowInfo(_Out):
    """The ``follow`` object of an Estimate (and of ``status``)."""

    enabled: bool
    """Follow mode switched on by an operator."""
    active: bool
    """The pull is above the threshold: the goal follows it."""
    threshold_n: float
    """Pull threshold in use (the tension beyond the tether's own), newtons."""
    land_below_m: float | None = None
    """(added) Tug-to-land height, or None when tug-to-land is off."""
    landing_armed: bool = False
    """(added) A tug has happened: below the land height the motors stop."""
    stopped: bool = False
    """(added) A Stop has been issued."""
    reason: str = ""
    """(added) Why follow last changed state (e.g. ``stale``)."""


class Estimate(_Out):
    """Ground station → anyone, ``tether/{drone}/estimate``, one per accepted Telemetry."""

    seq: int
    """The ``seq`` of the Telemetry it was computed from."""
    stamp_s: float
    """That Telemetry's ``stamp_s``, seconds."""
    tension_n: tuple[float, float, float]
    """Force the tether applies to the drone, world frame, newtons (filtered)."""
    tension_std_n: tuple[float, float, float]
    """Its standard deviation per axis, newtons."""
    horizontal_n: float
    """H = |tension_n[:2]|."""
    vertical_n: float
    """T_v = −tension_n[2], the downward pull on the drone."""
    position_m: tuple[float, float, float] | None
    """Tether-based position, world frame; null while undetermined."""
    follow: FollowInfo
    """Follow mode (see FollowInfo)."""
    position_std_m: tuple[float, float, float] | None = None
    """(added) Per-axis standard deviation of ``position_m``: the tension's uncertainty (the
    filter's, plus the calibration's misfit ``[calibration] tension_model_std_n`` in the air)
    carried through the catenary."""
    radial_m: float | None = None
    """(added) Horizontal distance base → drone from the tether."""
    radial_interval_m: tuple[float, float] | None = None
    """(added) Interval of the radial distance (wide when the tether rests slack on the floor)."""
    azimuth_determined: bool | None = None
    """(added) False when the azimuth's σ exceeds 1/3 rad (e.g. H within its noise, the
    tether near plumb, with no other source)."""
    azimuth_source: str | None = None
    """(added) The most certain source of the azimuth: ``tension``, ``reel``, ``mocap``, or
    ``none``; null without a position."""
    floor_contact: bool | None = None
    """(added) Part of the tether rests on the floor."""
    on_ground: bool = False
    """(added) The floor carries the drone (disarmed; thrust below ``[filter]
    ground_thrust_ratio`` of its weight while seen at rest; or spooling up before lift-off is
    seen; see groundstation.contact): no tension estimate, ``tension_n`` zero. A low thrust
    in the air (a dip, a hard descent) is not the ground: the filter coasts."""
    converged: bool = False
    """(added) The filter has seen enough samples for its std to be meaningful."""
    length_m: float | None = None
    """(added) Tether length used."""
    base_m: tuple[float, float, float] | None = None
    """(added) Base exit point used."""
    calibration: str = "none"
    """(added) Which sensor calibration the observation applied (``[calibration] source``,
    ``config`` for unlabelled values), or ``none``."""
    calibration_extrapolated: bool | None = None
    """(added) True when this Telemetry's ``vbat_v`` lies outside the battery range the
    thrust map was calibrated over (``[calibration] thrust_vbat_range_v``): the thrust, and
    with it the tension and position, rest on an extrapolation; null when no range is
    recorded, the Telemetry carries no ``vbat_v``, or the drone is on the ground (no thrust
    in use; an unloaded battery reads higher)."""


class EstimateSmoothed(_Out):
    """(added) ``replay --offline`` → its output file, ``tether/{drone}/estimate_smoothed``:
    the forward-backward (RTS) smoothed tension and position of one Estimate, for
    post-flight analysis (docs/smoother.md). Written at that Estimate's log time, for each
    Estimate the tension filter stepped for (none while on the ground)."""

    seq: int
    """The ``seq`` of the Estimate (and Telemetry) it smooths."""
    stamp_s: float
    """That Telemetry's ``stamp_s``, seconds."""
    tension_n: tuple[float, float, float]
    """Force the tether applies to the drone, world frame, newtons, from every sample of the
    regime (before and after this one)."""
    tension_std_n: tuple[float, float, float]
    """Its standard deviation per axis, newtons (the smoother's, plus the calibration's
    misfit ``[calibration] tension_model_std_n``, as the Estimate's)."""
    position_m: tuple[float, float, float] | None
    """Catenary position of the smoothed tension (azimuth from the tension), world, metres;
    None when it has no solution."""
    position_std_m: tuple[float, float, float] | None = None
    """Its standard deviation per world axis, metres."""


class Setpoint(_Out):
    """Ground station → drone, ``tether/{drone}/cmd/setpoint``."""

    stamp_s: float
    """The stamp of the Telemetry it answers, seconds."""
    position_m: tuple[float, float, float]
    """The position the drone should hold, world frame, metres."""


class Stop(_Out):
    """Ground station → drone, ``tether/{drone}/cmd/stop``: stop the motors now."""

    stamp_s: float
    """Seconds (the Telemetry's stamp, or the sender's clock for an operator's Stop)."""
    reason: str
    """Why (``tug-to-land``, ``operator``, ...)."""
    kind: Literal["emergency", "land"] = "emergency"
    """(added) ``emergency`` (also when absent, or any other value read back): motors off now,
    locked until a power cycle on a Crazyflie (the operator's emergency stop); ``land``: the
    ordinary end of a landing (tug-to-land): down to the floor at a safe rate, motors off
    there, no lock."""


class Truth(_Out):
    """Simulator → anyone, ``tether/{drone}/truth`` (added beside the contract)."""

    stamp_s: float
    """Simulation time, seconds."""
    position_m: tuple[float, float, float]
    """True position, world frame, metres."""
    velocity_mps: tuple[float, float, float]
    """True velocity, world frame, m/s."""
    tension_n: tuple[float, float, float]
    """True force of the tether (plus any pull) on the drone, world frame, newtons."""
    length_m: float
    """Tether paid out, metres."""
    base_m: tuple[float, float, float]
    """Base exit point, world frame, metres."""
    floor_contact: bool
    """Part of the tether rests on the floor."""
    taut: bool
    """The tether is taut (straight)."""
    armed: bool
    """Motors armed."""
    on_ground: bool
    """The drone sits on the floor."""
    phase: str = ""
    """Scenario phase label."""
    profile: str | None = None
    """(added) Simulator profile, ``realistic`` (absent: ``ideal``)."""
    errors: dict[str, Any] | None = None
    """(added) The flight's drawn sensor errors and their equivalent ``[calibration]`` values
    (``realistic`` profile; on the first Truth and once per second;
    :mod:`groundstation.sim.sensors` defines every sign)."""

    def to_json(self) -> bytes:
        """Compact UTF-8 JSON; the added optional fields only when set (ideal: as before)."""
        return self.model_dump_json(exclude_none=True).encode()


EVENT_KINDS = ("rejected", "warning", "follow", "params", "stop", "rearm")
"""Kinds of :class:`Event`."""


class Event(_Out):
    """(added) Ground station → anyone, ``tether/{drone}/events``: what the service did with an
    operator's input, and why; the operator action log.

    One per action: a command refused (``rejected``, with the reason and the offending
    field) or applied with a caveat (``warning``, e.g. unknown fields ignored), follow
    switched on/off or re-tuned (``follow``), tether parameters changed (``params``), a Stop
    seen or issued (``stop``), a re-arm requested (``rearm``, on the Crazyflie bridge's
    ``tether/{drone}/cmd/rearm``). Not per sample: rejected telemetry or reel messages give one
    event per drone and kind, then are only counted (``status``).
    """

    stamp_s: float
    """When, UNIX time (the service's wall clock), seconds."""
    kind: Literal["rejected", "warning", "follow", "params", "stop", "rearm"]
    """What happened (see above)."""
    input: str
    """The key the action came in on, after ``tether/{drone}/``: ``follow``, ``params``,
    ``cmd/stop``, ``cmd/rearm``, ``telemetry``, ``reel``; ``service`` for the service's own
    decisions."""
    who: str = "unknown"
    """Who: the zenoh session id (hex) of the sender where the sample carries it (groundstation
    tools attach it), the service's own id for its own actions, else ``unknown``."""
    reason: str = ""
    """Why, in words (the rejection reason, the Stop's reason, ...)."""
    field: str | None = None
    """The offending field of a rejected input (dotted path), or None."""
    changes: dict[str, float | bool | str | None] = Field(default_factory=dict)
    """What changed, with the new values (``{"enabled": true, "threshold_n": 0.15}``)."""


class StopIn(_In):
    """A Stop read back from the bus (simulator side)."""

    stamp_s: Finite
    reason: str
    kind: str = "emergency"
    """(added) Read leniently: anything but ``land`` is an emergency stop (a Stop is never
    dropped for its kind)."""

    @property
    def landing(self) -> bool:
        """(added) The landing stop (no lock), not the emergency stop."""
        return self.kind == "land"


class SetpointIn(_In):
    """A Setpoint read back from the bus (simulator side)."""

    stamp_s: Finite
    position_m: Vec3


class Status(_Out):
    """(added) Ground station → anyone, the queryable ``tether/{drone}/status`` (zenoh ``get``):
    health of one drone. Every field but ``drone`` may be absent (older or newer services)."""

    drone: str
    """The drone id."""
    stale: bool | None = None
    """No telemetry for longer than ``[service] stale_after_s`` (follow mode is then off)."""
    telemetry_hz: float | None = None
    """Accepted telemetry per second (2 s window)."""
    estimate_hz: float | None = None
    """Estimates published per second (2 s window)."""
    last_seen_age_s: float | None = None
    """Seconds since the last telemetry; None: never."""
    received: int | None = None
    """Telemetry messages received (valid JSON of the right shape)."""
    accepted: int | None = None
    """Telemetry messages accepted (in order, a sound observation)."""
    estimates: int | None = None
    """Estimates published."""
    setpoints: int | None = None
    """Setpoints published."""
    stops: int | None = None
    """Stops published by the service (tug-to-land)."""
    seq_gaps: int | None = None
    """Telemetry messages missing from the ``seq`` sequence."""
    drops: dict[str, int] | None = None
    """Rejected inputs per kind (``invalid``, ``not_json``, ``seq_backwards``,
    ``follow_refused``, ...)."""
    invalid: int | None = None
    """Sum of ``drops`` except ``queue_overflow``."""
    queue_overflow: int | None = None
    """Inputs dropped because the processing queue was full."""
    filter: dict[str, Any] | None = None
    """Filter state (``initialized``, ``change_detections``; the measured observation noise
    ``noise_std_n`` and ``noise_autocorrelation`` per world axis, ``time_constant_s``)."""
    follow: FollowInfo | None = None
    """Follow mode, as in the Estimate."""
    contact: dict[str, Any] | None = None
    """Ground/air state: ``on_ground`` and the ``reason`` that decided it (``start``,
    ``disarmed``, ``low_thrust``, ``resting``, ``mocap_height``, ``climbing``, ``push_free``,
    ``air``, ``flying_at_start``, ``falling``)."""
    length_m: float | None = None
    """Tether length in use, metres."""
    length_source: str | None = None
    """``config``, ``reel`` or ``operator``."""
    base_m: tuple[float, float, float] | None = None
    """Base exit point in use, world frame, metres."""
    weight_n_per_m: float | None = None
    """Tether weight per length ω in use, N/m."""
    calibration: str | None = None
    """(added) Which ``[calibration]`` the observation applies (its ``source``, ``config`` for
    unlabelled values) or ``none``, as in the Estimate."""
    calibration_extrapolated: bool | None = None
    """(added) As in the Estimate, for the last Telemetry."""
    calibration_vbat_range_v: tuple[float, float] | None = None
    """(added) ``[calibration] thrust_vbat_range_v`` in force, V, or null."""
    vbat_v: float | None = None
    """(added) The last Telemetry's ``vbat_v``, V, or null."""
    service: str | None = None
    """The answering service instance (liveliness token ``groundstation/service/{instance}``)."""
    peers: int | None = None
    """Zenoh peers and routers the service's session is connected to (0: nobody outside its
    process can reach it; None on an in-memory bus)."""
    alone_ok: bool | None = None
    """(added) The service expects no peer: ``groundstation demo`` runs simulator, service
    and dashboard on one session in one process, so ``peers: 0`` is normal there, not a
    fault (the dashboard then raises no alarm)."""
    events_suppressed: int | None = None
    """Events for this drone not published because of the per-drone cap (a flood)."""
    rest_calibration: dict[str, Any] | None = None
    """Rest calibration (``[calibration] rest``): None when off; else ``{"in_force": false}``,
    or the accelerometer's x/y offset found while the drone sat still and disarmed, applied
    until the next disarm: ``in_force``, ``offset_mps2`` [x, y], ``std_mps2``, ``duration_s``,
    ``stamp_s``. With ``[calibration] rest_required`` also ``required: true`` and
    ``missing_at_arming``: the drone armed without a rest offset in force (until the next
    disarm), so its x/y accelerometer bias is not the calibrated one."""
    attitude: dict[str, Any] | None = None
    """(added) The attitude of the last Telemetry: ``source`` (``onboard``/``external``),
    ``calibrated`` (the source the thrust axis was fitted against; null: a calibration that
    does not say) and the observation ``model`` they chose: ``hover`` (the attitude's level
    trusted) or ``accelerometer`` (docs/attitude_source.md); null before any Telemetry."""


class MocapPoseIn(_In):
    """(added) Motion capture → Crazyflie bridge, on ``[crazyflie] mocap_key``."""

    position_m: Vec3
    """World frame (the contract's), metres."""
    quat_wxyz: Vec4 | None = None
    """Body → world, scalar first (needed with ``attitude_source = "mocap"``)."""


class TakeoffIn(_In):
    """(added) Operator → Crazyflie bridge, ``tether/{drone}/cmd/takeoff``: climb straight up."""

    height_m: Finite = Field(gt=0.0, le=3.0)
    """Target height, world z, metres."""
    speed_mps: Finite = Field(default=0.25, gt=0.0, le=1.0)
    """Climb speed, m/s."""


class LandIn(_In):
    """(added) Operator → Crazyflie bridge, ``tether/{drone}/cmd/land``: down, motors off."""

    speed_mps: Finite = Field(default=0.25, gt=0.0, le=1.0)
    """Descent speed, m/s."""


# ---------------------------------------------------------------- fast Estimate encoding


_ANY_JSON: TypeAdapter[Any] = TypeAdapter(Any, config=ConfigDict(ser_json_inf_nan="constants"))
"""pydantic's serializer for plain values: the bytes ``model_dump_json`` writes for them (NaN
and infinities as the words ``NaN``/``Infinity``, for :func:`encode_estimate` to catch,
rather than a silent ``null``)."""


def _non_finite(value: object) -> bool:
    if isinstance(value, float):
        return not math.isfinite(value)
    if isinstance(value, (tuple, list)):
        return any(_non_finite(v) for v in value)
    if isinstance(value, dict):
        return any(_non_finite(v) for v in value.values())
    return False


_REQUIRED = object()
_ESTIMATE_FIELDS: dict[str, Any] = {
    name: _REQUIRED if info.is_required() else info.default
    for name, info in Estimate.model_fields.items()
}
"""Estimate's fields in its order, with their defaults (``_REQUIRED`` where none)."""


def encode_estimate(**given: Any) -> bytes:
    """An :class:`Estimate` as compact JSON without building the model (the per-message path).

    Takes the model's fields as keywords (``follow`` as the FollowInfo's ``model_dump()``: it
    changes only when follow changes state, so the caller keeps it). The same bytes as
    ``Estimate(...).to_json()``: the fields in the model's order (one the call leaves out
    takes the model's default), written by pydantic's own serializer (a ``TypeAdapter(Any)``,
    so floats are spelt as the model spells them), without the model's construction and
    validation, which cost as much again. ``tests/test_messages.py`` checks the bytes on
    randomized estimates.

    Raises:
        TypeError: a field the model does not have, or a required one missing.
        ValueError: a float is NaN or infinite (the model refuses them; never emitted).
    """
    unknown = given.keys() - _ESTIMATE_FIELDS.keys()
    if unknown:
        raise TypeError(f"encode_estimate: Estimate has no field(s) {sorted(unknown)}")
    fields = {}
    for name, default in _ESTIMATE_FIELDS.items():
        value = given.get(name, default)
        if value is _REQUIRED:
            raise TypeError(f"encode_estimate: required field {name!r} missing")
        fields[name] = value
    out = _ANY_JSON.dump_json(fields)
    # pydantic writes NaN and Infinity as bare words; look closer only if one appears
    # (a follow reason may contain the word).
    if (b"NaN" in out or b"Infinity" in out) and _non_finite(fields):
        bad = [k for k, v in fields.items() if _non_finite(v)]
        raise ValueError(f"non-finite value in Estimate field(s) {', '.join(bad)}")
    return out


ESTIMATE_FIELD_ORDER: tuple[str, ...] = tuple(_ESTIMATE_FIELDS)
"""Estimate's fields in the model's order (the order :func:`encode_estimate_ordered` takes)."""


def encode_estimate_ordered(fields: dict[str, Any]) -> bytes:
    """:func:`encode_estimate` of a dict that holds every field in the model's order.

    The per-message path builds its fields in :data:`ESTIMATE_FIELD_ORDER` (``follow`` as
    the FollowInfo's ``model_dump()``), so they go to pydantic's serializer as they are,
    without :func:`encode_estimate`'s pass over the keywords (which cost as much as the
    serialisation itself). A dict in another order or with other keys takes that pass.
    The same bytes as ``Estimate(**fields).to_json()``.

    Raises:
        TypeError, ValueError: as :func:`encode_estimate`.
    """
    if tuple(fields) != ESTIMATE_FIELD_ORDER:
        return encode_estimate(**fields)
    out = _ANY_JSON.dump_json(fields)
    if (b"NaN" in out or b"Infinity" in out) and _non_finite(fields):
        bad = [k for k, v in fields.items() if _non_finite(v)]
        raise ValueError(f"non-finite value in Estimate field(s) {', '.join(bad)}")
    return out
