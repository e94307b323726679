"""Payloads of the public contract (``../shared/INTERFACE.md``) as frozen pydantic v2 models.

Inputs are validated strictly: finite floats only, exact vector lengths, ranges (thrust ≥ 0,
length > 0, threshold > 0), no type coercion from strings or bools; unknown fields are
ignored, as the contract says. Outputs serialise to compact UTF-8 JSON.

Fields added beside the contract are marked "(added)"; they are documented in README.md.
"""

from __future__ import annotations

import re
from typing import Annotated, Any, Self

from pydantic import BaseModel, ConfigDict, Field, ValidationError

__all__ = [
    "DRONE_ID_RE",
    "KEY_KINDS",
    "Estimate",
    "FollowCommand",
    "FollowInfo",
    "InvalidMessage",
    "Reel",
    "Setpoint",
    "Stop",
    "Telemetry",
    "TetherParams",
    "Truth",
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
)
_KEY_RE = re.compile(r"tether/([^/]+)/(" + "|".join(KEY_KINDS) + ")")

Finite = Annotated[float, Field(allow_inf_nan=False)]
Vec3 = tuple[Finite, Finite, Finite]
Vec4 = tuple[Finite, Finite, Finite, Finite]


class InvalidMessage(ValueError):
    """A payload or key that the contract does not allow; ``kind`` names the reason."""

    def __init__(self, kind: str, detail: str) -> None:
        super().__init__(f"{kind}: {detail}")
        self.kind = kind
        self.detail = detail


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

    model_config = ConfigDict(frozen=True, strict=True, extra="ignore", allow_inf_nan=False)

    @classmethod
    def parse(cls, payload: bytes) -> Self:
        """Validate a JSON payload.

        Raises:
            InvalidMessage: ``not_json`` or ``invalid`` with pydantic's reasons.
        """
        try:
            return cls.model_validate_json(payload)
        except ValidationError as exc:
            errors = exc.errors(include_url=False, include_input=False)
            if errors and errors[0]["type"] in {"json_invalid", "json_type"}:
                raise InvalidMessage("not_json", errors[0]["msg"]) from None
            detail = "; ".join(
                f"{'.'.join(str(p) for p in e['loc']) or '<root>'}: {e['msg']}" for e in errors[:4]
            )
            raise InvalidMessage("invalid", f"{cls.__name__}: {detail}") from None


class _Out(BaseModel):
    model_config = ConfigDict(frozen=True, allow_inf_nan=False, extra="forbid")

    def to_json(self) -> bytes:
        """Compact UTF-8 JSON."""
        return self.model_dump_json().encode()


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
    vbat_v: Finite | None = Field(default=None, gt=0.0)
    """(added) Battery voltage, volts, where the drone reports it (battery-aware thrust)."""


class Reel(_In):
    """Reel → ground station, ``tether/{drone}/reel``."""

    stamp_s: Finite
    length_m: Finite = Field(gt=0.0)
    """Tether paid out from the base exit point to the drone, metres."""
    base_m: Vec3 | None = None
    """World position of the base exit point, metres."""
    exit_azimuth_rad: Finite | None = None
    """(added) World-frame azimuth of the tether's horizontal direction where it leaves the
    base, pointing from the base toward the drone, radians (atan2(y, x))."""
    exit_azimuth_std_rad: Finite | None = Field(default=None, gt=0.0)
    """(added) Standard deviation of ``exit_azimuth_rad``."""
    exit_elevation_rad: Finite | None = Field(default=None, ge=-1.5708, le=1.5708)
    """(added) The tether's angle above horizontal where it leaves the base, radians."""
    exit_elevation_std_rad: Finite | None = Field(default=None, gt=0.0)
    """(added) Standard deviation of ``exit_elevation_rad``."""


class FollowCommand(_In):
    """Anyone → ground station, ``tether/{drone}/follow``."""

    enabled: bool
    threshold_n: Finite | None = Field(default=None, gt=0.0)
    land_below_m: Finite | None = None
    """Tug-to-land height, metres (world z); absent keeps the current setting."""
    land: bool | None = None
    """(added) Switch tug-to-land off (False) or back on (True) without changing the height."""


class TetherParams(_In):
    """(added) Operator → ground station, ``tether/{drone}/params``: tether ω and length.

    The length is taken only while no reel reports one.
    """

    weight_n_per_m: Finite | None = Field(default=None, gt=0.0)
    length_m: Finite | None = Field(default=None, gt=0.0)


class FollowInfo(_Out):
    enabled: bool
    active: bool
    threshold_n: float
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
    stamp_s: float
    tension_n: tuple[float, float, float]
    """Force the tether applies to the drone, world frame, newtons (filtered)."""
    tension_std_n: tuple[float, float, float]
    horizontal_n: float
    """H = |tension_n[:2]|."""
    vertical_n: float
    """T_v = −tension_n[2], the downward pull on the drone."""
    position_m: tuple[float, float, float] | None
    """Tether-based position, world frame; null while undetermined."""
    follow: FollowInfo
    position_std_m: tuple[float, float, float] | None = None
    """(added) Per-axis standard deviation of ``position_m``."""
    radial_m: float | None = None
    """(added) Horizontal distance base → drone from the tether."""
    radial_interval_m: tuple[float, float] | None = None
    """(added) Interval of the radial distance (wide when the tether rests slack on the floor)."""
    azimuth_determined: bool | None = None
    """(added) False when H is within its noise (tether near plumb: azimuth unknown)."""
    floor_contact: bool | None = None
    """(added) Part of the tether rests on the floor."""
    on_ground: bool = False
    """(added) Drone disarmed or thrust below half its weight: no tension estimate."""
    converged: bool = False
    """(added) The filter has seen enough samples for its std to be meaningful."""
    length_m: float | None = None
    """(added) Tether length used."""
    base_m: tuple[float, float, float] | None = None
    """(added) Base exit point used."""
    calibration: str = "none"
    """(added) Which sensor calibration the observation applied (``[calibration] source``,
    ``config`` for unlabelled values), or ``none``."""


class Setpoint(_Out):
    """Ground station → drone, ``tether/{drone}/cmd/setpoint``."""

    stamp_s: float
    position_m: tuple[float, float, float]


class Stop(_Out):
    """Ground station → drone, ``tether/{drone}/cmd/stop``: stop the motors now."""

    stamp_s: float
    reason: str


class Truth(_Out):
    """Simulator → anyone, ``tether/{drone}/truth`` (added beside the contract)."""

    stamp_s: float
    position_m: tuple[float, float, float]
    velocity_mps: tuple[float, float, float]
    tension_n: tuple[float, float, float]
    """True force of the tether on the drone, world frame."""
    length_m: float
    base_m: tuple[float, float, float]
    floor_contact: bool
    taut: bool
    armed: bool
    on_ground: bool
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


class StopIn(_In):
    """A Stop read back from the bus (simulator side)."""

    stamp_s: Finite
    reason: str


class SetpointIn(_In):
    """A Setpoint read back from the bus (simulator side)."""

    stamp_s: Finite
    position_m: Vec3
