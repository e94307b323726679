"""The one root configuration: defaults, then a TOML file, then the environment, then the CLI.

The TOML layout is the public contract (``../shared/INTERFACE.md``, "Configuration file"):
``[zenoh]``, ``[drone]``, ``[tether]``, ``[base]`` and per-drone overrides under
``[drones.<id>]`` with the same sub-tables. Tables added beside the contract: ``[follow]``,
``[filter]``, ``[web]``, ``[service]``, ``[sim]`` (documented in README.md).

Environment overrides use the prefix ``GROUNDSTATION_`` and ``__`` between levels, e.g.
``GROUNDSTATION_TETHER__WEIGHT_N_PER_M=0.04`` or ``GROUNDSTATION_ZENOH__CONNECT='["tcp/..."]'``.

Nothing here is read at import time: :func:`load_settings` builds the object once and the
caller passes it on.
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    field_validator,
)
from pydantic_settings import (
    BaseSettings,
    PydanticBaseSettingsSource,
    SettingsConfigDict,
)

from groundstation.messages import DRONE_ID_RE

__all__ = [
    "BaseSection",
    "CalibrationSection",
    "ConfigError",
    "DroneOverride",
    "DroneParams",
    "DroneSection",
    "FilterSection",
    "FollowSection",
    "RealisticSection",
    "ServiceSection",
    "Settings",
    "SimSection",
    "TetherSection",
    "WebSection",
    "ZenohSection",
    "load_settings",
]


Vec3 = tuple[float, float, float]


class ConfigError(ValueError):
    """A configuration value is invalid; the message names the key and the value."""


class _Section(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)


class ZenohSection(_Section):
    """``[zenoh]``: how the service joins the bus."""

    mode: Literal["peer", "client", "router"] = "peer"
    connect: tuple[str, ...] = ()
    """Endpoints to connect to, e.g. ``tcp/127.0.0.1:7447``."""
    listen: tuple[str, ...] = ()
    """Endpoints to listen on."""
    multicast_scouting: bool = False
    """Off unless asked for: a lab network should not find peers by accident."""
    config_file: str | None = None
    """Optional zenoh JSON5 config (TLS, access control) loaded before the keys above."""
    raw: dict[str, Any] = Field(default_factory=dict)
    """Extra zenoh config entries, ``{"path/in/config": value}``, inserted as JSON5."""


class DroneSection(_Section):
    """``[drone]``: the vehicle."""

    mass_kg: float = Field(0.030, gt=0.0, le=100.0)
    accel_noise_mps2: float = Field(0.3, gt=0.0)
    """Accelerometer noise standard deviation per axis: the tension filter's prior until it has
    measured the noise on line (level and colour, over its first seconds in the air)."""
    thrust_noise_n: float = Field(0.003, gt=0.0)
    """Collective-thrust noise standard deviation (the filter's prior, as above)."""


class TetherSection(_Section):
    """``[tether]``: the tether's weight per length (ω) and its default length."""

    weight_n_per_m: float = Field(0.05, gt=0.0)
    length_m: float = Field(1.6, gt=0.0)
    """Used until a Reel message arrives."""


class BaseSection(_Section):
    """``[base]``: where the tether leaves the base, and the floor a slack tether rests on."""

    position_m: Vec3 = (0.0, 0.0, 0.754)
    floor_z_m: float = 0.0


class FollowSection(_Section):
    """``[follow]``: tension following and tug-to-land defaults (off until enabled)."""

    threshold_n: float = Field(0.10, gt=0.0)
    """|T| above which the drone follows the pull, N. Above the whole default tether's
    weight (ω·L = 0.08 N) so a hanging tether alone never engages it."""
    hysteresis_ratio: float = Field(0.2, ge=0.0, lt=1.0)
    land_below_m: float | None = None
    max_speed_mps: float = Field(0.5, gt=0.0)
    reach_margin_m: float = Field(0.05, ge=0.0)
    stale_after_s: float = Field(0.5, gt=0.0)
    admittance_mps_per_n: float = Field(2.0, gt=0.0)
    """Without motion capture the goal moves along the pull at this speed per newton."""


class FilterSection(_Section):
    """``[filter]``: tension-filter knobs beside the noise figures of ``[drone]``."""

    ground_thrust_ratio: float = Field(0.5, gt=0.0, lt=1.0)
    """Below this fraction of the weight the drone is taken to be on the ground."""


class CalibrationSection(_Section):
    """``[calibration]`` (added; per drone ``[drones.<id>.calibration]``): sensor corrections.

    Applied in the tension observation (eq:NE_tether): ``accel = accel_mps2 − accel_bias``,
    thrust ``F = thrust_n · (thrust_scale + thrust_vbat_slope_per_v · (vbat_v −
    thrust_vbat_ref_v))`` (the voltage term only when Telemetry carries ``vbat_v``), along the
    body axis ``R_x(about_x) · R_y(about_y) · e3`` instead of body +z. Written by
    ``groundstation calibrate``; the defaults change nothing.
    """

    thrust_scale: float = Field(1.0, gt=0.2, lt=5.0)
    """Multiplies ``thrust_n`` (the nominal PWM→thrust map's error)."""
    thrust_axis_rad: tuple[float, float] = (0.0, 0.0)
    """Thrust axis as a small rotation of body +z, ``[about_x, about_y]``, radians, in the body
    frame of the attitude Telemetry reports."""
    accel_bias_mps2: Vec3 = (0.0, 0.0, 0.0)
    """Subtracted from ``accel_mps2``, body frame, m/s²."""
    thrust_vbat_slope_per_v: float = 0.0
    """Change of the thrust scale per volt of ``vbat_v`` above ``thrust_vbat_ref_v``, 1/V."""
    thrust_vbat_ref_v: float = Field(3.9, gt=0.0)
    """Battery voltage at which ``thrust_scale`` holds, V."""
    rest: bool = True
    """Estimate the accelerometer's x/y offset while the drone sits disarmed and still on the
    floor, and apply it until the next disarm (real Crazyflies re-level at every power-on)."""
    source: str = "none"
    """Where these numbers come from (file and time, written by ``groundstation calibrate``),
    reported in Estimate and ``status``; ``none`` when nothing was calibrated."""

    @field_validator("thrust_axis_rad")
    @classmethod
    def _small_axis(cls, value: tuple[float, float]) -> tuple[float, float]:
        if any(not math.isfinite(v) or abs(v) > 0.35 for v in value):
            raise ValueError(f"{value!r}: each angle must be finite and within ±0.35 rad (20°)")
        return value


class WebSection(_Section):
    """``[web]``: the dashboard."""

    host: str = "127.0.0.1"
    port: int = Field(8080, ge=0, le=65535)
    scene_rate_hz: float = Field(20.0, gt=0.0, le=30.0)
    scene_budget_hz: float = Field(80.0, gt=0.0)
    """Drone redraws per second in all: with many drones each is drawn less often, so the
    dashboard's cost stays bounded and estimation keeps its capacity."""


class ServiceSection(_Section):
    """``[service]``: the estimation service."""

    drones: str = "*"
    """Drones this instance owns: one key-expression chunk such as ``lab-a-*`` (``tether/``
    in front is accepted); ``*`` inside a chunk is zenoh's ``$*``."""
    queue_size: int = Field(8192, ge=16)
    max_payload_bytes: int = Field(65536, ge=256)
    stale_after_s: float = Field(0.5, gt=0.0)
    status_period_s: float = Field(1.0, gt=0.0)
    log_level: Literal["DEBUG", "INFO", "WARNING", "ERROR"] = "INFO"
    log_json: bool = False
    record: str | None = None
    """Record every bus sample to this MCAP file while serving."""

    @field_validator("drones")
    @classmethod
    def _drones_chunk(cls, value: str) -> str:
        chunk = value.removeprefix("tether/").removesuffix("/**").removesuffix("/*")
        chunk = chunk.replace("$*", "*")
        if not chunk or "/" in chunk or not re.fullmatch(r"[A-Za-z0-9_*-]{1,64}", chunk):
            raise ValueError(
                f"{value!r} is not one drone-id pattern like 'lab-a-*' ([A-Za-z0-9_-] and *)"
            )
        return chunk

    @property
    def drones_keyexpr_chunk(self) -> str:
        """``drones`` as a zenoh chunk: ``*`` alone, or ``$*`` inside a chunk."""
        if self.drones in ("*", "**"):
            return "*"
        return re.sub(r"\*+", "$*", self.drones)


class RealisticSection(_Section):
    """``[sim.realistic]``: the ``realistic`` profile (docs/simulator.md has every source).

    Defaults are the real tethered Crazyflie 2.1 flights of issue 9 (30.7 g, 1.6 m tether,
    motion capture); each error class has a switch and a size; per-flight constants are drawn
    from ``[sim] seed`` and the drone's index. Sign conventions of every error and the
    equivalent ``[calibration]`` values: :mod:`groundstation.sim.sensors`.
    """

    physics_rate_hz: float = Field(1000.0, ge=200.0, le=20000.0)
    """Rate of the rigid-body and tether integration, Hz."""
    warmup_s: float = Field(2.0, ge=0.0, le=60.0)
    """Closed-loop settling before t = 0 for airborne starts (after the tether settles), s."""
    # airframe (Crazyflie 2.1: Förster 2015, "System identification of the Crazyflie 2.0")
    inertia_kg_m2: Vec3 = (1.66e-5, 1.66e-5, 2.93e-5)
    """Principal moments of inertia, kg·m²."""
    arm_m: float = Field(0.046, gt=0.0)
    """Centre-to-motor distance, m."""
    max_thrust_ratio: float = Field(2.0, gt=1.0)
    """Maximum collective thrust over the drone's weight."""
    motor_lag: bool = True
    motor_tau_s: float = Field(0.030, ge=0.0, le=0.5)
    """Motor time constant, s (issue 9: ~30 ms)."""
    rotor_drag: bool = True
    rotor_drag_n_s_per_m: float = Field(0.0073, ge=0.0)
    """Horizontal rotor drag at hover thrust, N per m/s of body velocity (Förster 2015)."""
    yaw_motion: bool = True
    """Initial yaw uniform in ±π per flight, then a slow yaw swing."""
    yaw_amplitude_rad: float = Field(0.3, ge=0.0, le=3.2)
    yaw_period_s: float = Field(20.0, gt=0.0)
    # tether (lumped mass; ω and L come from [tether])
    tether_segments: int = Field(10, ge=2, le=200)
    tether_stretch_stiffness_n: float = Field(100.0, gt=0.0)
    """EA, N (the real tether is stiffer, ~1e4 N; 100 N stretches 0.1 % at 0.1 N and keeps
    the integration cheap; stiffer costs sub-steps, not stability)."""
    tether_axial_damping_ratio: float = Field(0.1, ge=0.0, le=1.0)
    tether_air_damping_n_s_per_m2: float = Field(1e-3, ge=0.0)
    """Effective linear drag per metre of tether (air + internal friction), N·s/m²."""
    floor_friction: float = Field(0.4, ge=0.0)
    """Coulomb friction coefficient of the tether on the floor."""
    # accelerometer and gyro
    vibration: bool = True
    accel_noise_mps2: float = Field(1.0, ge=0.0)
    """Vibration noise std per axis at hover, m/s² (issue 9: 0.7–2.0; newer firmware
    0.06–0.39)."""
    accel_noise_lag1: float = Field(0.2, ge=0.0, lt=1.0)
    """Lag-1 autocorrelation of the noise per IMU sample (issue 9: up to 0.3)."""
    accel_noise_ar: float = Field(0.6, ge=0.0, lt=1.0)
    """AR(1) coefficient of the coloured part (must be >= accel_noise_lag1)."""
    accel_noise_floor_mps2: float = Field(0.02, ge=0.0)
    """Sensor noise with the motors off, m/s²."""
    gyro_noise_rps: float = Field(0.01, ge=0.0)
    misalignment: bool = True
    misalignment_max_rad: float = Field(0.052, ge=0.0, le=0.35)
    """Per-boot accelerometer tilt against the attitude frame, magnitude up to this, rad
    (issue 9: ~3°)."""
    accel_scale: bool = True
    accel_scale_max: float = Field(0.025, ge=0.0, le=0.5)
    """Per-boot accelerometer scale error, uniform in ±this (issue 9: up to 2.5 %)."""
    accel_bias: bool = True
    accel_bias_std_mps2: float = Field(0.05, ge=0.0)
    """Per-boot accelerometer bias std per axis, m/s² (beyond misalignment and scale)."""
    thrust_axis: bool = True
    thrust_axis_rad: tuple[float, float] = (-0.037, -0.016)
    """Thrust axis ``[about_x, about_y]`` of body +z, rad, airframe constant (issue 9)."""
    thrust_map: bool = True
    thrust_report_error: float = Field(-0.0909, ge=-0.5, le=2.0)
    """Reported/true thrust − 1 at ``thrust_vbat_ref_v`` (issue 9: true = 1.10 × reported,
    i.e. −0.091; range −0.10..+0.90)."""
    thrust_report_error_std: float = Field(0.01, ge=0.0)
    """Per-flight spread of ``thrust_report_error``."""
    thrust_vbat_exponent: float = Field(2.0, ge=0.0, le=5.0)
    """γ: reported/true grows as (V_ref/V)^γ as the battery sags."""
    thrust_vbat_ref_v: float = Field(4.05, gt=0.0)
    """Battery voltage at which ``thrust_report_error`` holds, V (issue 9: 4.03–4.06 V)."""
    battery: bool = True
    """A sagging battery; off: constant ``thrust_vbat_ref_v`` and no ``vbat_v``."""
    publish_vbat: bool = True
    """Publish ``vbat_v`` in Telemetry."""
    battery_full_v: float = Field(4.20, gt=0.0)
    battery_empty_v: float = Field(3.50, gt=0.0)
    battery_capacity_mah: float = Field(250.0, gt=0.0)
    battery_internal_ohm: float = Field(0.12, ge=0.0)
    battery_hover_current_a: float = Field(1.2, ge=0.0)
    battery_soc_start: float = Field(1.0, ge=0.0, le=1.0)
    # timing
    imu_timing: bool = True
    imu_rate_hz: float = Field(100.0, gt=0.0, le=1000.0)
    """Mean IMU Telemetry rate, Hz (issue 9: 100 Hz)."""
    imu_jitter_std_s: float = Field(0.0015, ge=0.0)
    imu_late_prob: float = Field(0.05, ge=0.0, le=1.0)
    imu_spacing_min_s: float = Field(0.006, gt=0.0)
    imu_spacing_max_s: float = Field(0.027, gt=0.0)
    """IMU spacing bounds, s (issue 9: 6–27 ms)."""
    mocap_timing: bool = True
    """Off: a motion-capture frame at every IMU sample, no latency, no bursts."""
    mocap_rate_min_hz: float = Field(70.0, gt=0.0)
    mocap_rate_max_hz: float = Field(116.0, gt=0.0)
    """Per-flight frame rate, uniform in [min, max], Hz (issue 9: 70–116 Hz)."""
    mocap_latency_s: float = Field(0.010, ge=0.0)
    mocap_burst_prob: float = Field(0.175, ge=0.0, lt=1.0)
    """Fraction of frames held back and delivered with the next (issue 9: 15–20 % < 1 ms)."""
    mocap_outage_rate_per_s: float = Field(0.2, ge=0.0)
    mocap_outage_max_s: float = Field(0.150, gt=0.0)
    """Longest gap, s (issue 9: up to 150 ms)."""
    mocap_noise_m: float = Field(0.0003, ge=0.0)
    mocap_attach: Literal["latest", "new"] = "latest"
    """``latest``: every Telemetry carries the latest arrived frame; ``new``: only the first
    Telemetry after a new frame."""

    @field_validator("accel_noise_ar")
    @classmethod
    def _ar_covers_lag1(cls, value: float, info: ValidationInfo) -> float:
        lag1 = info.data.get("accel_noise_lag1", 0.0)
        if value < lag1:
            raise ValueError(f"{value!r} must be >= accel_noise_lag1 {lag1!r}")
        return value


class SimSection(_Section):
    """``[sim]``: the simulator."""

    profile: Literal["ideal", "realistic"] = "ideal"
    """``ideal``: the estimator's own assumptions (quasi-static catenary, white noise, exact
    sensors); ``realistic``: rigid body, lumped-mass tether and real sensor errors
    (``[sim.realistic]``). docs/simulator.md."""
    realistic: RealisticSection = RealisticSection()

    scenario: str = "hover"
    rate_hz: float = Field(250.0, gt=0.0, le=2000.0)
    drones: tuple[str, ...] = ("cf1",)
    accel_noise_mps2: float = Field(0.3, ge=0.0)
    thrust_noise_n: float = Field(0.003, ge=0.0)
    thrust_bias_ratio: float = Field(0.0, ge=-0.5, le=0.5)
    mocap: bool = True
    """Publish the motion-capture ``position_m`` in Telemetry."""
    seed: int = 0
    speed: float = Field(1.0, gt=0.0)
    """Real-time factor (1 = wall clock)."""
    duration_s: float | None = None


class DroneOverride(_Section):
    """``[drones.<id>]``: any of the per-drone tables, partially."""

    drone: dict[str, Any] = Field(default_factory=dict)
    tether: dict[str, Any] = Field(default_factory=dict)
    base: dict[str, Any] = Field(default_factory=dict)
    follow: dict[str, Any] = Field(default_factory=dict)
    calibration: dict[str, Any] = Field(default_factory=dict)


class DroneParams(_Section):
    """The resolved parameters of one drone (root tables merged with its override)."""

    drone: DroneSection
    tether: TetherSection
    base: BaseSection
    follow: FollowSection
    filter: FilterSection
    calibration: CalibrationSection = CalibrationSection()


class Settings(BaseSettings):
    """The root configuration object."""

    model_config = SettingsConfigDict(
        env_prefix="GROUNDSTATION_",
        env_nested_delimiter="__",
        extra="forbid",
        frozen=True,
    )

    zenoh: ZenohSection = ZenohSection()
    drone: DroneSection = DroneSection()
    tether: TetherSection = TetherSection()
    base: BaseSection = BaseSection()
    follow: FollowSection = FollowSection()
    filter: FilterSection = FilterSection()
    calibration: CalibrationSection = CalibrationSection()
    web: WebSection = WebSection()
    service: ServiceSection = ServiceSection()
    sim: SimSection = SimSection()
    drones: dict[str, DroneOverride] = Field(default_factory=dict)

    @field_validator("drones")
    @classmethod
    def _drone_ids(cls, value: dict[str, DroneOverride]) -> dict[str, DroneOverride]:
        for drone_id in value:
            if not DRONE_ID_RE.fullmatch(drone_id):
                raise ValueError(f"drone id {drone_id!r} does not match [A-Za-z0-9_-]{{1,64}}")
        return value

    @classmethod
    def settings_customise_sources(
        cls,
        settings_cls: type[BaseSettings],
        init_settings: PydanticBaseSettingsSource,
        env_settings: PydanticBaseSettingsSource,
        dotenv_settings: PydanticBaseSettingsSource,
        file_secret_settings: PydanticBaseSettingsSource,
    ) -> tuple[PydanticBaseSettingsSource, ...]:
        # Only ``Settings()`` reads the environment; load_settings lays it between the
        # file and the CLI. ``model_validate`` reads no source at all.
        return (init_settings, env_settings)

    def for_drone(self, drone_id: str) -> DroneParams:
        """Resolve the parameters of ``drone_id`` (its ``[drones.<id>]`` over the root tables).

        Raises:
            ConfigError: the override makes a value invalid (names key and value).
        """
        override = self.drones.get(drone_id)
        sections: dict[str, BaseModel] = {
            "drone": self.drone,
            "tether": self.tether,
            "base": self.base,
            "follow": self.follow,
            "calibration": self.calibration,
        }
        merged: dict[str, Any] = {"filter": self.filter}
        for name, section in sections.items():
            patch = getattr(override, name) if override is not None else {}
            if not patch:
                merged[name] = section
                continue
            try:
                merged[name] = type(section).model_validate(section.model_dump() | patch)
            except ValidationError as exc:
                raise ConfigError(
                    _describe(exc, prefix=f"drones.{drone_id}.{name}", data=patch)
                ) from None
        return DroneParams(**merged)


def _lookup(data: Any, loc: tuple[int | str, ...]) -> Any:
    for part in loc:
        if isinstance(data, Mapping) and part in data:  # noqa: SIM114 (mypy narrows apart)
            data = data[part]
        elif isinstance(data, list | tuple) and isinstance(part, int) and part < len(data):
            data = data[part]
        else:
            return "<missing>"
    return data


def _describe(exc: ValidationError, *, prefix: str = "", data: Any = None) -> str:
    lines = []
    for err in exc.errors():
        loc = tuple(err["loc"])
        key = ".".join(str(p) for p in loc)
        if prefix:
            key = f"{prefix}.{key}" if key else prefix
        value = err.get("input", _lookup(data, loc))
        if isinstance(value, float) and not math.isfinite(value):
            value = repr(value)
        lines.append(f"{key} = {value!r}: {err['msg']}")
    return "invalid configuration: " + "; ".join(lines)


def _deep_merge(base: dict[str, Any], patch: Mapping[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in patch.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = _deep_merge(dict(out[key]), value)
        else:
            out[key] = value
    return out


def load_settings(
    config_path: str | Path | None = None,
    cli_overrides: Mapping[str, Any] | None = None,
    *,
    base: Mapping[str, Any] | None = None,
    use_env: bool = True,
) -> Settings:
    """Build the root :class:`Settings`: defaults < ``base`` < file < environment < CLI.

    Args:
        config_path: a TOML file in the contract's layout, or None.
        cli_overrides: nested dict of values given on the command line.
        base: nested dict applied before the file (e.g. an embedded demo default).
        use_env: read ``GROUNDSTATION_*`` variables.

    Raises:
        ConfigError: unreadable file, TOML syntax error, or an invalid value (the message
            names the key and the value).
    """
    layered: dict[str, Any] = dict(base or {})
    if config_path is not None:
        path = Path(config_path)
        try:
            with path.open("rb") as fh:
                file_data = tomllib.load(fh)
        except OSError as exc:
            raise ConfigError(f"cannot read config file {str(path)!r}: {exc.strerror}") from None
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"config file {str(path)!r} is not valid TOML: {exc}") from None
        layered = _deep_merge(layered, file_data)

    try:
        if use_env:
            # Environment beats the file: validate env alone, then lay it over the file.
            env_only = Settings()
            env_set = env_only.model_dump(exclude_unset=True)
            layered = _deep_merge(layered, env_set)
        layered = _deep_merge(layered, dict(cli_overrides or {}))
        settings = Settings.model_validate(layered)
    except ValidationError as exc:
        raise ConfigError(_describe(exc, data=layered)) from None
    # Resolve every override once at start-up so a bad per-drone value fails now.
    for drone_id in settings.drones:
        settings.for_drone(drone_id)
    return settings
