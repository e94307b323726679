"""The one root configuration: defaults, then a TOML file, then the environment, then the CLI.

The TOML layout is the public contract (``docs/contract.md``, "Configuration file"):
``[zenoh]``, ``[drone]``, ``[tether]``, ``[base]`` and per-drone overrides under
``[drones.<id>]`` with the same sub-tables. Tables added beside the contract: ``[follow]``,
``[filter]``, ``[calibration]``, ``[web]``, ``[service]``, ``[sim]``, ``[crazyflie]``,
``[localization]`` (``docs/contract.md``).

Environment overrides use the prefix ``GROUNDSTATION_`` and ``__`` between levels, e.g.
``GROUNDSTATION_TETHER__WEIGHT_N_PER_M=0.04`` or ``GROUNDSTATION_ZENOH__CONNECT='["tcp/..."]'``.

Nothing here is read at import time: :func:`load_settings` builds the object once and the
caller passes it on.
"""

from __future__ import annotations

import contextvars
import json
import logging
import math
import os
import re
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal, NamedTuple, Self, get_args

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)
from pydantic_settings import (
    BaseSettings,
    PydanticBaseSettingsSource,
    SettingsConfigDict,
)

from groundstation.messages import DRONE_ID_RE, AttitudeSource

NOMINAL_PWM_MAP: tuple[float, float, float] = (2.130295e-11, 1.032633e-6, 5.484560e-4)
"""The widely used Crazyflie 2.x PWM→thrust map, per motor ``a·pwm² + b·pwm + c`` N (the
same as groundstation.thrust_model's, tested equal: the contract imports no physics)."""
ThrustModel = Literal["vbat_linear", "motor_voltage"]
"""``[calibration] thrust_model`` (groundstation.thrust_model's, tested equal)."""

_log = logging.getLogger(__name__)
_warned: set[str] = set()
"""Warnings already logged by this process (a key that lost its meaning: told once)."""


def _warn_once(text: str) -> None:
    """Log ``text`` as a warning the first time this process sees it."""
    if text not in _warned:
        _warned.add(text)
        _log.warning("%s", text)


__all__ = [
    "BaseSection",
    "CalibrationSection",
    "ConfigError",
    "CrazyflieSection",
    "DroneOverride",
    "DroneParams",
    "DroneSection",
    "FilterSection",
    "FollowSection",
    "FoxgloveSection",
    "LocalizationSection",
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


_STRICT = {"strict_scalars": True}
"""Validation context of values from a file or the command line (see :class:`_Section`)."""


def _scalar_kinds(annotation: Any) -> set[type]:
    """The scalar types (float, int, bool) an annotation accepts, through Optional/tuple."""
    if annotation in (float, int, bool):
        return {annotation}
    kinds: set[type] = set()
    for arg in get_args(annotation):
        if arg is not Ellipsis:
            kinds |= _scalar_kinds(arg)
    return kinds


def _loose_scalar(kinds: set[type], value: Any) -> str | None:
    """Why ``value`` is not a real number/bool where ``kinds`` are expected (None if it is)."""
    if value is None:
        return None
    if isinstance(value, list | tuple):
        for item in value:
            why = _loose_scalar(kinds, item)
            if why is not None:
                return why
        return None
    if isinstance(value, str) and kinds:
        kind = "true or false" if kinds == {bool} else "a number"
        return f"{kind} is required, not the string {value!r} (write it without quotes)"
    if bool in kinds and kinds <= {bool} and not isinstance(value, bool):
        return f"true or false is required, not {value!r}"
    if isinstance(value, bool) and kinds and bool not in kinds:
        return f"a number is required, not the boolean {value!r}"
    return None


class _Section(BaseModel):
    """A config table: frozen, no unknown keys, finite floats.

    Values from a TOML file or the command line are validated with the context
    ``{"strict_scalars": True}``: a number or a bool written as a string (``length_m =
    "1.6"``, ``mocap = "false"``) is an error, as is a bool where a number belongs. Values
    from the environment are strings by nature and are converted first (lax), then laid over
    the file as numbers.
    """

    model_config = ConfigDict(
        frozen=True, extra="forbid", allow_inf_nan=False, use_attribute_docstrings=True
    )

    @field_validator("*", mode="before")
    @classmethod
    def _strict_scalars(cls, value: Any, info: ValidationInfo) -> Any:
        if not (info.context or {}).get("strict_scalars") or info.field_name is None:
            return value
        kinds = _scalar_kinds(cls.model_fields[info.field_name].annotation)
        why = _loose_scalar(kinds, value)
        if why is not None:
            raise ValueError(why)
        return value


_ENDPOINT_RE = re.compile(r"[A-Za-z0-9_+-]+/[^\s/?#][^\s]*")
"""zenoh's endpoint form ``<protocol>/<address>[?<metadata>][#<config>]``, loosely."""


class ZenohSection(_Section):
    """``[zenoh]``: how the service joins the bus."""

    mode: Literal["peer", "client", "router"] = "peer"
    """Zenoh mode: a peer, a client of a router, or a router."""
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

    @field_validator("connect", "listen")
    @classmethod
    def _endpoints(cls, value: tuple[str, ...]) -> tuple[str, ...]:
        for endpoint in value:
            if not _ENDPOINT_RE.fullmatch(endpoint):
                raise ValueError(
                    f"{endpoint!r} is not a zenoh endpoint <protocol>/<address> "
                    "(e.g. tcp/127.0.0.1:7447)"
                )
        return value


class DroneSection(_Section):
    """``[drone]``: the vehicle."""

    mass_kg: float = Field(0.030, gt=0.0)
    """Drone mass, kg (m of eq:NE_tether); 0.005–2 kg unless ``unusual_rig``."""
    accel_noise_mps2: float = Field(0.3, gt=0.0)
    """Accelerometer noise standard deviation per axis: the tension filter's prior until it has
    measured the noise on line (level and colour, over its first seconds in the air)."""
    thrust_noise_n: float = Field(0.003, gt=0.0)
    """Collective-thrust noise standard deviation (the filter's prior, as above)."""
    unusual_rig: bool = False
    """Accept a mass, tether length or tether weight outside a micro drone's plausible
    ranges (:data:`PLAUSIBLE`): without it such a value is taken for a unit mistake."""
    attitude_source: AttitudeSource = "onboard"
    """(added) Where Telemetry's attitude comes from when a message does not say
    (``attitude_source`` of Telemetry): ``onboard``, the drone's own estimator, or
    ``external``, motion capture's rigid body. The hover model, which trusts the attitude's
    level, is used only when the calibration's thrust axis was fitted against the same
    source (``[calibration] attitude_source``; uncalibrated: ``onboard``); otherwise the
    accelerometer model, in which a tilt of the attitude cancels (docs/attitude_source.md)."""


class TetherSection(_Section):
    """``[tether]``: the tether's weight per length (ω) and its default length."""

    weight_n_per_m: float = Field(0.05, gt=0.0)
    """ω, the tether's weight per unit length, N/m (weigh it: docs/troubleshooting.md)."""
    length_m: float = Field(1.6, gt=0.0)
    """Used until a Reel message arrives."""


class BaseSection(_Section):
    """``[base]``: where the tether leaves the base, and the floor a slack tether rests on."""

    position_m: Vec3 = (0.0, 0.0, 0.754)
    """World position of the base exit point, metres (until a Reel message gives it)."""
    floor_z_m: float = 0.0
    """Height of the floor a slack tether rests on, metres."""


class FollowSection(_Section):
    """``[follow]``: tension following and tug-to-land defaults (off until enabled)."""

    threshold_n: float = Field(0.10, gt=0.0)
    """Pull above which the drone follows it, N: the tension beyond the tether's own in quiet
    hover at the drone's position (catenary there, plus a slowly tracked offset), so a
    hanging tether alone never engages it, near taut neither."""
    hysteresis_ratio: float = Field(0.2, ge=0.0, lt=1.0)
    """Following releases below threshold_n · (1 − hysteresis_ratio)."""
    land_below_m: float | None = None
    """Tug-to-land height (world z), metres; none: tug-to-land off."""
    max_speed_mps: float = Field(0.5, gt=0.0)
    """Largest setpoint speed, m/s."""
    reach_margin_m: float = Field(0.05, ge=0.0)
    """Setpoints stay this much inside the tether's reach from the base, metres."""
    stale_after_s: float = Field(0.5, gt=0.0)
    """Input older than this disengages following, s."""
    admittance_mps_per_n: float = Field(2.0, gt=0.0)
    """Without motion capture the goal moves along the pull at this speed per newton."""


class FilterSection(_Section):
    """``[filter]``: tension-filter knobs beside the noise figures of ``[drone]``."""

    ground_thrust_ratio: float = Field(0.5, gt=0.0, lt=1.0)
    """Below this fraction of the weight the drone is on the ground when seen at rest (the
    vertical acceleration near zero for 0.2 s; in the air it is a dip and the filter coasts);
    at or above it, on the ground until lift-off is seen (groundstation.contact:
    motion-capture height, the IMU's climb, or the floor no longer carrying it)."""
    accel_slow_time_constant_s: float = Field(60.0, gt=0.0)
    """(added) No longer used: a value other than 60 is accepted with one warning. It was
    the time constant of a low-pass that learnt the accelerometer's bias in the air, s; the
    bias is a state of a Kalman filter beside the velocity now (groundstation.bias_kalman),
    weighed by the flight's model that ``calibrate`` fits (``[calibration]
    flight_velocity_std_mps``, ``flight_velocity_time_s``, ``flight_bias_std_mps2``)."""
    accel_hover_crossover_s: float = Field(0.3, ge=0.0)
    """(added) 0 turns the hover off: the tension filter then observes the accelerometer
    model alone. Otherwise, while the drone hovers (its 1 s mean acceleration and its speed
    what the hover's own velocity and the vibration give, at the estimator's one
    false-alarm rate), the filter also takes the thrust balance ``m·g·e3 − R·u·F`` through the
    drone's velocity (groundstation.tension_kalman.HoverVelocity). Any other value than 0 or
    0.3 is accepted with a warning: it was the crossover below which the hover model
    replaced the accelerometer, s, which the velocity state replaced."""
    accel_hover_exit_window_s: float = Field(0.0, ge=0.0)
    """(added) No longer used: a value other than 0 is accepted with one warning. It was a
    second, shorter mean for the hover test (the hover also ended when the acceleration's
    mean over this window exceeded 4 of its own σ), s; the tension filter's own change
    tests end a hover at a tug now (the filter observes the accelerometer model throughout),
    and a 0.3 s window measured no faster on the tug and worse on hovers (t90 0.35 s against
    0.34 s; hover at 1 m/s² 0.6 / 2.0 cm against 0.3 / 0.6 cm: ``python -m
    benchmarks.hover_exit`` at commit 7168cba, whose page docs/hover_exit.md was removed
    with the window)."""
    accel_hover_noise_sigmas: float = Field(4.0, ge=0.0)
    """(added) No longer used: a value other than 4 is accepted with one warning. It was the
    hover test's thresholds in standard deviations of what they test, beside fixed floors
    of 0.2 m/s² and 0.3 m/s; the test now allows for the hover's own velocity (``[calibration]
    hover_velocity_std_mps`` / ``hover_velocity_time_s``, fitted by ``calibrate``) and the
    measured vibration, judged at the estimator's one false-alarm rate (``false_alarms_per_h``,
    groundstation.slow_accel)."""
    accel_hover_exit_ratio: float = Field(1.5, ge=1.0)
    """(added) No longer used: a value other than 1.5 is accepted with one warning. It was the
    hover test's hysteresis (a hover ended only above this many times the thresholds for
    entering one); at the one false-alarm rate the noise ends a hover by chance at most
    that often, with no hysteresis."""
    drag_velocity_time_constant_s: float = Field(8.0, gt=0.0)
    """(added) Without motion capture the rotor-drag term's velocity is the accelerometer's
    leaky integral with this time constant, s (groundstation.slow_accel)."""

    @model_validator(mode="after")
    def _slow_time_constant_without_meaning(self) -> FilterSection:
        if self.accel_slow_time_constant_s != 60.0:
            _warn_once(
                f"[filter] accel_slow_time_constant_s = {self.accel_slow_time_constant_s:g} "
                "is not used: the accelerometer's bias is a state of a Kalman filter beside "
                "the velocity (groundstation.bias_kalman), weighed by [calibration] "
                "flight_velocity_std_mps, flight_velocity_time_s and flight_bias_std_mps2 "
                "(fitted by groundstation calibrate), which replaced the low-pass"
            )
        return self

    @model_validator(mode="after")
    def _hover_thresholds_without_meaning(self) -> FilterSection:
        for key, default in (("accel_hover_noise_sigmas", 4.0), ("accel_hover_exit_ratio", 1.5)):
            value = getattr(self, key)
            if value != default:
                _warn_once(
                    f"[filter] {key} = {value:g} is not used: the hover test allows for the "
                    "hover's own velocity ([calibration] hover_velocity_std_mps and "
                    "hover_velocity_time_s, fitted by groundstation calibrate) and the "
                    "measured vibration at the estimator's one false-alarm rate, which "
                    "replaced its thresholds and their hysteresis"
                )
        return self

    @model_validator(mode="after")
    def _exit_window_without_meaning(self) -> FilterSection:
        if self.accel_hover_exit_window_s != 0.0:
            _warn_once(
                f"[filter] accel_hover_exit_window_s = {self.accel_hover_exit_window_s:g} is "
                "not used: the tension filter's change tests end a hover at a tug (the filter "
                "observes the accelerometer model throughout), which replaced the hover "
                "test's short window"
            )
        return self

    @model_validator(mode="after")
    def _crossover_without_meaning(self) -> FilterSection:
        value = self.accel_hover_crossover_s
        if value not in (0.0, 0.3):
            _warn_once(
                f"[filter] accel_hover_crossover_s = {value:g} is used only as on (> 0) or "
                "off (0): the hover's thrust balance enters the tension filter through the "
                "drone's velocity (a state of the filter), which replaced the crossover"
            )
        return self


class LocalizationSection(_Section):
    """``[localization]`` (added): where the azimuth and the catenary's shape come from."""

    azimuth: Literal["auto", "tension", "reel", "mocap"] = "auto"
    """``auto`` fuses the tension's direction and the reel's exit azimuth by their
    uncertainty; ``tension``, ``reel`` or ``mocap`` uses that one alone (``mocap`` with
    ``elevation = false`` is the paper's method: β from Telemetry ``position_m``, r and z from
    the tension; ``mocap`` alone still fuses a reel's exit elevation into r and z, which the
    paper did not). A source asked for but absent or stale leaves the azimuth undetermined."""
    elevation: bool = True
    """Fuse the reel's ``exit_elevation_rad`` with the tension (the base slope constrains
    the catenary); false for the paper's method (with ``azimuth = "mocap"``)."""
    reel_stale_after_s: float = Field(0.5, gt=0.0)
    """Exit angles older than this (receive time) are not used, s."""
    exit_azimuth_std_rad: float = Field(0.03, gt=0.0)
    """σ of the tether's direction across it at the exit, for an ``exit_azimuth_rad`` the Reel
    message gives no σ for, rad: the azimuth's σ is this over cos(exit elevation) (near
    plumb the azimuth is noise; at plumb there is none), with the elevation of the same or
    the last fresh Reel; without an elevation this as is."""
    exit_elevation_std_rad: float = Field(0.03, gt=0.0)
    """σ of ``exit_elevation_rad`` when the Reel message gives none, rad."""
    mocap_std_m: float = Field(0.002, gt=0.0)
    """σ of the motion-capture position per axis, m (a Telemetry ``position_m`` without a
    ``position_std_m`` of its own): the azimuth's with ``azimuth = "mocap"``, the bias
    filter's position observation, and the floor-contact height band (lift-off once the
    height stands out of it by the one false-alarm rate: 1.1 cm at 2 mm). Set it to the
    system's real noise: too small reads a jittering marker as a lift-off."""
    position_max_std_m: float = Field(0.05, gt=0.0)
    """A Telemetry ``position_m`` whose ``position_std_m`` exceeds this on any axis (an onboard
    estimator not yet converged, a Flow deck's x/y odometry) is used as no position: not for
    follow, tug-to-land, floor contact or the azimuth, m."""


class CalibrationSection(_Section):
    """``[calibration]`` (added; per drone ``[drones.<id>.calibration]``): sensor corrections.

    Applied in the tension observation (eq:NE_tether): ``accel = accel_mps2 − accel_bias``,
    thrust by ``thrust_model`` (groundstation.thrust_model, docs/battery_model.md):
    ``vbat_linear`` ``F = thrust_n · (thrust_scale + thrust_vbat_slope_per_v · (vbat_v −
    thrust_vbat_ref_v))`` (the voltage term only when Telemetry carries ``vbat_v``);
    ``motor_voltage`` ``F = thrust_scale · 4 · thrust_motor_ref_n · (v /
    thrust_motor_ref_v)^thrust_motor_exponent`` with ``v = vbat_v · pwm / 65535`` the motor
    voltage and ``pwm`` the mean motor command ``thrust_pwm_map`` gives ``thrust_n / 4``
    (``thrust_vbat_ref_v`` stands in for a missing ``vbat_v``); along the body axis
    ``R_x(about_x) · R_y(about_y) · e3`` instead of body +z. Written by ``groundstation
    calibrate``; the defaults change nothing.
    """

    thrust_scale: float = Field(1.0, gt=0.2, lt=5.0)
    """Multiplies ``thrust_n`` (the nominal PWM→thrust map's error; ``motor_voltage``: a
    factor on the model's thrust, 1 as ``calibrate`` writes it)."""
    thrust_axis_rad: tuple[float, float] = (0.0, 0.0)
    """Thrust axis as a small rotation of body +z, ``[about_x, about_y]``, radians, in the body
    frame of the attitude Telemetry reports."""
    accel_bias_mps2: Vec3 = (0.0, 0.0, 0.0)
    """Subtracted from ``accel_mps2``, body frame, m/s²."""
    thrust_vbat_slope_per_v: float = 0.0
    """Change of the thrust scale per volt of ``vbat_v`` above ``thrust_vbat_ref_v``, 1/V
    (fitted; ``vbat_linear`` only: ``motor_voltage`` has its exponent instead)."""
    thrust_vbat_ref_v: float = Field(3.9, gt=0.0)
    """Battery voltage at which ``thrust_scale`` holds, V (``motor_voltage``: the battery
    voltage assumed for a Telemetry without ``vbat_v``, the calibration's median)."""
    thrust_model: ThrustModel = "vbat_linear"
    """(added) How thrust follows the battery (docs/battery_model.md): ``vbat_linear``, a
    straight line in ``vbat_v`` (holds over the calibrated range only); ``motor_voltage``,
    a power of the motor voltage (duty × battery), which extrapolates below the range. The
    latter needs ``thrust_n`` from the PWM map ``thrust_pwm_map`` (the bridge's ``thrust_model
    = "pwm_map"``). ``groundstation calibrate`` fits the one configured here."""
    thrust_pwm_map: tuple[float, float, float] = NOMINAL_PWM_MAP
    """(added) ``[a, b, c]`` of the per-motor map ``a·pwm² + b·pwm + c`` N that made
    Telemetry's ``thrust_n`` (the bridge's ``[crazyflie] thrust_map``; physical), inverted by
    ``motor_voltage``; ``a > 0``, ``b >= 0``."""
    thrust_motor_ref_n: float | None = Field(None, gt=0.0, lt=10.0)
    """(added) ``motor_voltage``: one motor's thrust at motor voltage ``thrust_motor_ref_v``,
    N (fitted by ``groundstation calibrate``); none: not calibrated, ``motor_voltage`` only
    says what ``calibrate`` is to fit and the thrust is ``thrust_n · thrust_scale``."""
    thrust_motor_ref_v: float = Field(3.0, gt=0.0, lt=60.0)
    """(added) ``motor_voltage``: the reference motor voltage, V (the calibration's median
    motor voltage, so that ``thrust_motor_ref_n`` and the exponent are nearly independent;
    the default is unused while ``thrust_motor_ref_n`` is none)."""
    thrust_motor_exponent: float = Field(2.0, gt=0.2, lt=5.0)
    """(added) ``motor_voltage``: thrust ∝ (motor voltage)^this, dimensionless (fitted; 2,
    thrust ∝ ω² with ω ∝ v, where the data do not determine it)."""
    accel_slow: bool = True
    """(added) Replace the accelerometer's slow content by what transfers across power-ons
    (groundstation.slow_accel, docs/estimator_design.md): its bias is learnt at rest and, in
    the air, from the velocity it integrates to (bounded, or motion capture's:
    groundstation.bias_kalman). False: the accelerometer's mean is trusted as read (what
    ``groundstation calibrate --model full`` writes: its fitted bias stands for it)."""
    tension_model_std_n: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """(added) The tension error the calibration leaves, per world axis, N (written by
    ``groundstation calibrate``: its fit's residual, groundstation.airframe
    ``AirframeFit.model_std_n``). The model's error, not the vibration's: the filter cannot
    average it away, so the Estimate's ``tension_std_n`` carries it,
    ``sqrt(filter variance + this²)``; zero: the filter's σ alone."""
    hover_velocity_std_mps: float | None = Field(None, gt=0.0, lt=1.0)
    """(added) σ_v, how far a hovering drone's velocity strays (its scatter about the
    hover's mean, per world axis), m/s: while the drone hovers the tension filter takes the
    thrust balance through the velocity, ``v = 0`` observed with variance ``σ_v²·T_c/dt``
    (groundstation.tension_kalman.HoverVelocity). Written by ``groundstation calibrate``
    from the motion-capture velocity in the hovers of its recordings
    (groundstation.hover_fit); none: 0.02 (NanoBench's quasi-static stretches,
    docs/constants.md)."""
    hover_velocity_time_s: float | None = Field(None, gt=0.0, lt=60.0)
    """(added) T_c, the correlation time of that velocity, s (fitted with
    ``hover_velocity_std_mps``); none: 0.5."""
    hover_wander_n2_per_s: float | None = Field(None, gt=0.0, lt=1e-3)
    """(added) q_w, the random walk's spectral density of the tension the thrust balance
    reads at hover (the tension's own wander and the balance's slow error), N²/s: the
    hover's time constant is ``sqrt(r·dt/q_w)`` (groundstation.tension). Written by
    ``groundstation calibrate`` from the hovers of its recordings under motion capture,
    by maximum likelihood (groundstation.hover_fit.fit_hover_balance), where the data tell
    it from no wander; none: 4.5e-8 (the realistic simulator, docs/constants.md)."""
    hover_balance_density_n2s: float | None = Field(None, gt=0.0, lt=1e-3)
    """(added) D, the thrust balance's white noise at hover as a force density, N²·s: the
    process noise of the hover's velocity state, ``D/m²`` per second (fitted with
    ``hover_wander_n2_per_s``); none: ``[drone] thrust_noise_n``² times the measured
    sample spacing."""
    flight_velocity_std_mps: float | None = Field(None, gt=0.0, lt=10.0)
    """(added) σ_V, how far the flying drone's velocity strays from zero (per world axis),
    m/s: the accelerometer's bias is learnt in the air from the velocity it integrates to,
    ``v = 0`` observed with variance ``σ_V²·T_V/T`` per block of T (groundstation.
    bias_kalman). Written by ``groundstation calibrate`` from the motion-capture velocity
    of its recordings' airborne samples (groundstation.hover_fit); none: 0.13 (NanoBench's
    slowest flight, docs/constants.md)."""
    flight_velocity_time_s: float | None = Field(None, gt=0.0, lt=60.0)
    """(added) T_V, the correlation time of that velocity, s (fitted with
    ``flight_velocity_std_mps``); none: 1.4."""
    flight_bias_std_mps2: float | None = Field(None, gt=0.0, lt=5.0)
    """(added) σ_δ, how far the accelerometer's bias in the air strays from the rest's
    before it (per body axis), m/s²: the prior the bias filter adds at each take-off.
    Written by ``groundstation calibrate`` from its recordings' rests and flights under
    motion capture (groundstation.hover_fit); none: 0.05 (NanoBench, docs/constants.md)."""
    rotor_drag_n_s_per_m: float = Field(0.0, ge=0.0, le=1.0)
    """(added) ``D_xy``: the rotors' drag per m/s of body-horizontal speed, N·s/m; the
    observation adds ``R·D·Rᵀ·v`` back (v from motion capture, else the accelerometer's
    leaky velocity). Written by ``groundstation calibrate``; 0: no drag term."""
    thrust_vbat_range_v: tuple[float, float] | None = None
    """(added) Battery voltage range ``[lo, hi]`` the thrust map was calibrated over, V
    (written by ``groundstation calibrate``: its hover samples' ``vbat_v``). Outside it the
    thrust map is extrapolated, and Estimate and ``status`` say so
    (``calibration_extrapolated``); none: not recorded, nothing is flagged."""
    rest: bool = True
    """Estimate the accelerometer's x/y offset while the drone sits disarmed and still on the
    floor, and apply it until the next disarm (real Crazyflies re-level at every power-on)."""
    rest_required: bool = False
    """(added) Written true by ``groundstation calibrate`` when it left the x/y accelerometer
    bias to the rest calibration (kept as configured) and fitted the thrust axis on top of
    the rest offsets: a drone that arms with no rest offset in force then flies with an x/y
    bias nobody calibrated; the service warns once and ``status`` says so
    (``rest_calibration.missing_at_arming``). Needs ``rest = true``."""
    attitude_source: AttitudeSource | None = None
    """(added) The attitude the thrust axis was fitted against (written by ``groundstation
    calibrate`` from the recordings): ``onboard`` or ``external``. A drone served with
    another source gets the accelerometer model instead of the hover model (``[drone]
    attitude_source``); none (a calibration written before this key): whatever is served."""
    source: str = "none"
    """Where these numbers come from (file and time, written by ``groundstation calibrate``),
    reported in Estimate and ``status``; ``none`` when nothing was calibrated."""

    @field_validator("thrust_axis_rad")
    @classmethod
    def _small_axis(cls, value: tuple[float, float]) -> tuple[float, float]:
        if any(not math.isfinite(v) or abs(v) > 0.35 for v in value):
            hint = ""
            if all(math.isfinite(v) and abs(math.radians(v)) <= 0.35 for v in value):
                rad = ", ".join(f"{math.radians(v):.4g}" for v in value)
                hint = f"; degrees? {list(value)!r} degrees is thrust_axis_rad = [{rad}]"
            raise ValueError(
                f"{value!r}: each angle must be finite and within ±0.35 rad (20°){hint}"
            )
        return value

    @field_validator("tension_model_std_n")
    @classmethod
    def _model_std(cls, value: tuple[float, float, float]) -> tuple[float, float, float]:
        if not all(math.isfinite(v) and 0.0 <= v < 1.0 for v in value):
            raise ValueError(f"{list(value)!r}: each must be finite, >= 0 and < 1 N")
        return value

    @field_validator("thrust_vbat_range_v")
    @classmethod
    def _vbat_range(cls, value: tuple[float, float] | None) -> tuple[float, float] | None:
        if value is None:
            return None
        lo, hi = value
        if not (0.0 < lo <= hi < 60.0):
            raise ValueError(f"{list(value)!r}: must be [lo, hi] volts with 0 < lo <= hi < 60")
        return value

    @field_validator("thrust_pwm_map")
    @classmethod
    def _invertible_map(cls, value: tuple[float, float, float]) -> tuple[float, float, float]:
        a, b, c = value
        top = a * 65535.0**2 + b * 65535.0 + c
        if not (all(math.isfinite(v) for v in value) and a > 0.0 and b >= 0.0 and 0 < top < 10):
            raise ValueError(
                f"{list(value)!r}: a > 0, b >= 0 and a thrust at pwm 65535 within (0, 10) N"
            )
        return value

    @model_validator(mode="after")
    def _keys_without_meaning(self) -> CalibrationSection:
        motor = self.thrust_model == "motor_voltage" and self.thrust_motor_ref_n is not None
        if motor and self.thrust_vbat_slope_per_v != 0.0:
            _warn_once(
                f"[calibration] thrust_vbat_slope_per_v = {self.thrust_vbat_slope_per_v:g} is "
                'not used with thrust_model = "motor_voltage": thrust_motor_exponent (the '
                "power of the motor voltage) replaced it"
            )
        return self

    @model_validator(mode="after")
    def _rest_required_needs_rest(self) -> CalibrationSection:
        if self.rest_required and not self.rest:
            raise ValueError(
                "rest_required = true with rest = false: the calibration relies on the rest "
                "offset, which rest = false turns off (calibrate again with rest = false)"
            )
        return self


class WebSection(_Section):
    """``[web]``: the dashboard."""

    host: str = "127.0.0.1"
    """Dashboard bind address (``0.0.0.0``: every interface)."""
    port: int = Field(8080, ge=0, le=65535)
    """Dashboard TCP port."""
    scene_rate_hz: float = Field(20.0, gt=0.0, le=30.0)
    """Scene and chart updates per second."""
    scene_budget_hz: float = Field(80.0, gt=0.0)
    """Drone redraws per second in all: with many drones each is drawn less often, so the
    dashboard's cost stays bounded and estimation keeps its capacity."""
    panel: Literal["tab", "shared"] = "tab"
    """(added) ``tab``: each browser tab has its own panel and selected drone; ``shared``:
    one panel for every tab (a wall display mirroring the operator's)."""
    forget_after_s: float = Field(60.0, ge=0.0)
    """(added) A drone silent this long (seconds) is dropped from the scene and the selector;
    it is drawn faded from ``[service] stale_after_s`` on. 0: never forget."""


class FoxgloveSection(_Section):
    """``[foxglove]``: Foxglove's WebSocket server (live 3D scene and the contract's messages);
    off unless a port is given."""

    host: str = "127.0.0.1"
    """Bind address of the Foxglove WebSocket server (``0.0.0.0``: every interface)."""
    port: int | None = Field(None, ge=0, le=65535)
    """Its TCP port (Foxglove's default is 8765; 0: any free port); none: no server."""
    scene_rate_hz: float = Field(15.0, ge=1.0, le=30.0)
    """Scene and frame-transform updates per second (each drone's latest state)."""
    arrow_m_per_n: float = Field(4.0, gt=0.0)
    """Drawn length of the tension arrow per newton of tension, m/N."""


class ServiceSection(_Section):
    """``[service]``: the estimation service."""

    drones: str = "*"
    """Drones this instance owns: one key-expression chunk such as ``lab-a-*`` (``tether/``
    in front is accepted); ``*`` inside a chunk is zenoh's ``$*``."""
    queue_size: int = Field(8192, ge=16)
    """Inputs waiting for the worker at most; beyond, dropped as ``queue_overflow``."""
    max_payload_bytes: int = Field(65536, ge=256)
    """Larger payloads are dropped as ``too_large``."""
    stale_after_s: float = Field(0.5, gt=0.0)
    """A drone silent this long is stale: no estimates, follow off, s; its next message
    restarts its stream and its tension filter (the tension may have changed meanwhile)."""
    status_period_s: float = Field(1.0, gt=0.0)
    """Health bookkeeping period, s."""
    log_level: Literal["DEBUG", "INFO", "WARNING", "ERROR"] = "INFO"
    """Log level."""
    log_json: bool = False
    """Log one JSON object per line on stderr."""
    record: str | None = None
    """Record every bus sample to this MCAP file while serving."""
    follow_threshold_min_n: float = Field(0.02, gt=0.0)
    """(added) The smallest follow threshold the service accepts, N: a FollowCommand with a
    lower ``threshold_n`` is refused (and said so on ``tether/{drone}/events``), as is a
    ``[follow] threshold_n`` below it."""

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

    Defaults are measured on real tethered Crazyflie 2.1 flights (30.7 g, 1.6 m tether,
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
    """Switch: first-order motor lag (``motor_tau_s``)."""
    motor_tau_s: float = Field(0.030, ge=0.0, le=0.5)
    """Motor time constant, s (real flights: ~30 ms)."""
    rotor_drag: bool = True
    """Switch: rotor drag (``rotor_drag_n_s_per_m``)."""
    rotor_drag_n_s_per_m: float = Field(0.0073, ge=0.0)
    """Horizontal rotor drag at hover thrust, N per m/s of body velocity (Förster 2015)."""
    yaw_motion: bool = True
    """Initial yaw uniform in ±π per flight, then a slow yaw swing."""
    yaw_amplitude_rad: float = Field(0.3, ge=0.0, le=3.2)
    """Amplitude of the yaw swing, rad."""
    yaw_period_s: float = Field(20.0, gt=0.0)
    """Period of the yaw swing, s."""
    # tether (lumped mass; ω and L come from [tether])
    tether_segments: int = Field(10, ge=2, le=200)
    """Segments of the lumped-mass tether (10 keeps shape within 0.5 % of L)."""
    tether_stretch_stiffness_n: float = Field(100.0, gt=0.0)
    """EA, N (the real tether is stiffer, ~1e4 N; 100 N stretches 0.1 % at 0.1 N and keeps
    the integration cheap; stiffer costs sub-steps, not stability)."""
    tether_axial_damping_ratio: float = Field(0.25, ge=0.0, le=1.0)
    """Damping ratio of each segment's stretch."""
    tether_air_damping_n_s_per_m2: float = Field(1e-3, ge=0.0)
    """Effective linear drag per metre of tether (air + internal friction), N·s/m²."""
    floor_friction: float = Field(0.4, ge=0.0)
    """Coulomb friction coefficient of the tether on the floor."""
    # accelerometer and gyro
    vibration: bool = True
    """Switch: vibration noise (off: only ``accel_noise_floor_mps2``)."""
    accel_noise_mps2: float = Field(1.0, ge=0.0)
    """Vibration noise std per axis at hover, m/s² (real flights: 0.7–2.0; newer firmware
    0.06–0.39)."""
    accel_noise_lag1: float = Field(0.2, ge=0.0, lt=1.0)
    """Lag-1 autocorrelation of the noise per IMU sample (real flights: up to 0.3)."""
    draw_levels: bool = False
    """Draw ``accel_noise_mps2``, ``accel_noise_lag1`` and ``battery_soc_start`` per flight,
    uniform in their ``*_range`` keys, from ``[sim] seed`` and the drone's index (a stream of
    their own: the other drawn errors stay as they are); off: the fixed values above (every
    benchmark's, so its numbers do not move)."""
    accel_noise_range_mps2: tuple[float, float] = (0.7, 2.0)
    """Range of the drawn vibration noise, m/s² (0.7–2.0 on real flights)."""
    accel_noise_lag1_range: tuple[float, float] = (0.0, 0.3)
    """Range of the drawn lag-1 autocorrelation (real flights: up to 0.3)."""
    battery_soc_range: tuple[float, float] = (0.6, 1.0)
    """Range of the drawn state of charge at t = 0 (0.6: ~3.74 V at hover, where the
    thrust map reads ~1.17 times its value at 4.05 V)."""
    accel_noise_ar: float = Field(0.6, ge=0.0, lt=1.0)
    """AR(1) coefficient of the coloured part (must be >= accel_noise_lag1)."""
    accel_noise_floor_mps2: float = Field(0.02, ge=0.0)
    """Sensor noise with the motors off, m/s²."""
    gyro_noise_rps: float = Field(0.01, ge=0.0)
    """Gyro white noise per axis, rad/s."""
    misalignment: bool = True
    """Switch: per-boot accelerometer misalignment."""
    misalignment_max_rad: float = Field(0.052, ge=0.0, le=0.35)
    """Per-boot accelerometer tilt against the attitude frame, magnitude up to this, rad
    (real flights: ~3°)."""
    accel_scale: bool = True
    """Switch: per-boot accelerometer scale error."""
    accel_scale_max: float = Field(0.025, ge=0.0, le=0.5)
    """Per-boot accelerometer scale error, uniform in ±this (real flights: up to 2.5 %)."""
    accel_bias: bool = True
    """Switch: per-boot accelerometer bias."""
    accel_bias_std_mps2: float = Field(0.05, ge=0.0)
    """Per-boot accelerometer bias std per axis, m/s² (beyond misalignment and scale)."""
    attitude_levelled: bool = False
    """Switch (added): the reported attitude is levelled on the same misaligned, biased
    accelerometer, as a Crazyflie's estimators level it, so its error is the accelerometer's
    (a per-boot tilt of about |b_xy|/g plus the misalignment). Off by default: the published
    realistic figures were made without it; benchmarks/bench_powerons.py turns it on."""
    thrust_axis: bool = True
    """Switch: thrust axis off body +z."""
    thrust_axis_rad: tuple[float, float] = (-0.037, -0.016)
    """Thrust axis ``[about_x, about_y]`` of body +z, rad, airframe constant (as measured)."""
    thrust_map: bool = True
    """Switch: reported thrust through an erroneous nominal map."""
    thrust_report_error: float = Field(-0.0909, ge=-0.5, le=2.0)
    """Reported/true thrust − 1 at ``thrust_vbat_ref_v`` (real flights: true = 1.10 × reported,
    i.e. −0.091; range −0.10..+0.90)."""
    thrust_report_error_std: float = Field(0.01, ge=0.0)
    """Per-flight spread of ``thrust_report_error``."""
    thrust_vbat_exponent: float = Field(2.0, ge=0.0, le=5.0)
    """γ: reported/true grows as (V_ref/V)^γ as the battery sags."""
    thrust_vbat_ref_v: float = Field(4.05, gt=0.0)
    """Battery voltage at which ``thrust_report_error`` holds, V (real flights: 4.03–4.06 V)."""
    battery: bool = True
    """A sagging battery; off: constant ``thrust_vbat_ref_v`` and no ``vbat_v``."""
    publish_vbat: bool = True
    """Publish ``vbat_v`` in Telemetry."""
    battery_full_v: float = Field(4.20, gt=0.0)
    """Open-circuit voltage when full, V."""
    battery_empty_v: float = Field(3.50, gt=0.0)
    """Open-circuit voltage when empty, V (linear in the charge between)."""
    battery_capacity_mah: float = Field(250.0, gt=0.0)
    """Battery capacity, mAh."""
    battery_internal_ohm: float = Field(0.12, ge=0.0)
    """Internal resistance, Ω (the sag under load)."""
    battery_hover_current_a: float = Field(1.2, ge=0.0)
    """Current at hover thrust, A (∝ (thrust/weight)^1.5)."""
    battery_soc_start: float = Field(1.0, ge=0.0, le=1.0)
    """State of charge at t = 0."""
    # timing
    imu_timing: bool = True
    """Switch: IMU jitter (off: exactly every 1/``imu_rate_hz``)."""
    imu_rate_hz: float = Field(100.0, gt=0.0, le=1000.0)
    """Mean IMU Telemetry rate, Hz (real flights: 100 Hz)."""
    imu_jitter_std_s: float = Field(0.0015, ge=0.0)
    """IMU spacing jitter std, s."""
    imu_late_prob: float = Field(0.05, ge=0.0, le=1.0)
    """Share of late IMU messages (spacing up to ``imu_spacing_max_s``)."""
    imu_spacing_min_s: float = Field(0.006, gt=0.0)
    """Shortest IMU spacing, s."""
    imu_spacing_max_s: float = Field(0.027, gt=0.0)
    """IMU spacing bounds, s (real flights: 6–27 ms)."""
    mocap_timing: bool = True
    """Off: a motion-capture frame at every IMU sample, no latency, no bursts."""
    mocap_rate_min_hz: float = Field(70.0, gt=0.0)
    """Lowest per-flight motion-capture rate, Hz."""
    mocap_rate_max_hz: float = Field(116.0, gt=0.0)
    """Per-flight frame rate, uniform in [min, max], Hz (real flights: 70–116 Hz)."""
    mocap_latency_s: float = Field(0.010, ge=0.0)
    """Capture → arrival latency of motion capture, s."""
    mocap_burst_prob: float = Field(0.175, ge=0.0, lt=1.0)
    """Fraction of frames held back and delivered with the next (real flights: 15–20 % < 1 ms)."""
    mocap_outage_rate_per_s: float = Field(0.2, ge=0.0)
    """Motion-capture outages per second (Poisson)."""
    mocap_outage_max_s: float = Field(0.150, gt=0.0)
    """Longest gap, s (real flights: up to 150 ms)."""
    mocap_noise_m: float = Field(0.0003, ge=0.0)
    """Motion-capture position noise std per axis, m."""
    mocap_attach: Literal["latest", "new"] = "latest"
    """``latest``: every Telemetry carries the latest arrived frame; ``new``: only the first
    Telemetry after a new frame."""

    @model_validator(mode="after")
    def _consistent(self) -> Self:
        # Cross-field rules (field validators do not see defaults); each message names keys.
        if self.accel_noise_ar < self.accel_noise_lag1:
            raise ValueError(
                f"accel_noise_ar {self.accel_noise_ar!r} must be >= accel_noise_lag1 "
                f"{self.accel_noise_lag1!r}"
            )
        ranges = {
            "accel_noise_range_mps2": (self.accel_noise_range_mps2, 0.0, math.inf),
            "accel_noise_lag1_range": (self.accel_noise_lag1_range, 0.0, self.accel_noise_ar),
            "battery_soc_range": (self.battery_soc_range, 0.0, 1.0),
        }
        for key, ((lo, hi), least, most) in ranges.items():
            if not least <= lo <= hi <= most:
                raise ValueError(f"{key} ({lo!r}, {hi!r}) must be ordered within [{least}, {most}]")
        nominal = 1.0 / self.imu_rate_hz
        if not self.imu_spacing_min_s <= nominal <= self.imu_spacing_max_s:
            raise ValueError(
                f"imu_spacing_min_s {self.imu_spacing_min_s!r} <= 1/imu_rate_hz {nominal:.4f} "
                f"<= imu_spacing_max_s {self.imu_spacing_max_s!r} must hold"
            )
        if self.mocap_rate_max_hz < self.mocap_rate_min_hz:
            raise ValueError(
                f"mocap_rate_max_hz {self.mocap_rate_max_hz!r} must be >= mocap_rate_min_hz "
                f"{self.mocap_rate_min_hz!r}"
            )
        if self.battery_empty_v >= self.battery_full_v:
            raise ValueError(
                f"battery_empty_v {self.battery_empty_v!r} must be below battery_full_v "
                f"{self.battery_full_v!r}"
            )
        return self


class SimSection(_Section):
    """``[sim]``: the simulator."""

    profile: Literal["ideal", "realistic"] = "ideal"
    """``ideal``: the estimator's own assumptions (quasi-static catenary, white noise, exact
    sensors); ``realistic``: rigid body, lumped-mass tether and real sensor errors
    (``[sim.realistic]``). docs/simulator.md."""
    realistic: RealisticSection = RealisticSection()
    """``[sim.realistic]``: the realistic profile's parameters."""

    scenario: str = "hover"
    """Scenario (``groundstation sim --list``)."""
    rate_hz: float = Field(250.0, gt=0.0, le=2000.0)
    """Telemetry rate, Hz."""
    drones: tuple[str, ...] = ("cf1",)
    """Drone ids to simulate."""
    accel_noise_mps2: float = Field(0.3, ge=0.0)
    """Simulated accelerometer noise per axis, m/s²."""
    thrust_noise_n: float = Field(0.003, ge=0.0)
    """Simulated thrust noise, N."""
    thrust_bias_ratio: float = Field(0.0, ge=-0.5, le=0.5)
    """Relative error of the reported thrust (0.02: reports 2 % too much)."""
    mocap: bool = True
    """Publish the motion-capture ``position_m`` in Telemetry."""
    untethered: bool = False
    """Fly without a tether (``sim --untethered``): no tether force on the drone and no Reel;
    Truth's tension is only the scenario's pulls (none in ``calibration``), its ``length_m``
    0. The flight ``calibrate --untethered`` fits (docs/calibration.md)."""
    exit_angles: bool = False
    """(added) A base sensor: publish the tether's ``exit_azimuth_rad`` / ``exit_elevation_rad``
    (and their σ) in Reel, from the simulated tether's first segment, with the noise below
    (groundstation/sim/base_sensor.py)."""
    exit_azimuth_noise_rad: float = Field(0.02, ge=0.0)
    """Azimuth noise σ of the base sensor for a horizontal exit, rad (grows as 1/cos(elevation))."""
    exit_elevation_noise_rad: float = Field(0.02, ge=0.0)
    """Elevation noise σ of the base sensor, rad."""
    seed: int = 0
    """Random seed of the simulated sensor noise."""
    speed: float = Field(1.0, gt=0.0)
    """Real-time factor (1 = wall clock)."""
    duration_s: float | None = None
    """Stop after this many simulated seconds; none: the scenario's own end, or never."""


class CrazyflieSection(_Section):
    """``[crazyflie]`` (added): the bridge ``groundstation crazyflie`` (docs/real-lab.md).

    The bridge publishes the nominal thrust of ``thrust_map``; the service applies
    ``[calibration]`` on top, so a thrust scale is never applied twice.
    """

    thrust_map: tuple[float, float, float] = NOMINAL_PWM_MAP
    """``[a, b, c]``: thrust of one motor, ``a·pwm² + b·pwm + c`` newtons, pwm in 0..65535
    (a motor at pwm 0 gives 0 N). The default is the widely used Crazyflie 2.x fit."""
    motor_variables: Literal["motor", "pwm"] = "motor"
    """``motor``: ``motor.m1..m4``; ``pwm``: ``pwm.m1_pwm..m4_pwm`` (firmware of about
    2021–2022 only). Compensate the battery once (docs/real-lab.md, "compensating once"):
    current firmware logs ``motor.*`` after its battery compensation (the duty: fit
    ``[calibration] thrust_vbat_slope_per_v``) and has no ``pwm`` group; firmware of about
    2021–2022 logs ``motor.*`` before it (the request: keep the slope 0) and ``pwm.*`` after it
    (the duty: fit the slope)."""
    attitude_source: Literal["estimator", "mocap"] = "estimator"
    """``estimator``: ``stateEstimate.qw..qz``; ``mocap``: ``quat_wxyz`` of ``mocap_key``."""
    mocap_key: str | None = None
    """Zenoh key of the motion-capture pose of this drone, JSON ``{"position_m": [x, y, z],
    "quat_wxyz": [w, x, y, z] (optional)}``; ``{drone}`` is replaced by the drone id."""
    mocap_stale_s: float = Field(0.1, gt=0.0)
    """A pose older than this (host clock) is not used: ``position_m`` is left out."""
    send_extpos: bool = False
    """Also forward motion-capture poses to the drone's estimator (``extpos``, at most
    ``extpos_rate_hz``): the bridge then selects the Kalman estimator, resets it at connection
    and refuses take-off until it has settled, as Bitcraze's mocap example does."""
    armed_source: Literal["auto", "supervisor", "none"] = "auto"
    """``supervisor``: bit 1 of ``supervisor.info``; ``auto``: that when the firmware logs it,
    else no ``armed`` field; ``none``: never report ``armed``."""
    rate_hz: float = Field(100.0, ge=0.5, le=100.0)
    """Telemetry rate; the log period is the nearest multiple of 10 ms. Setpoints go out every
    20 ms whatever the rate (the firmware's commander watchdog acts after 0.5 s)."""
    slow_period_ms: int = Field(100, ge=10, le=2540)
    """Period of the slowly changing variables (battery, armed), ms, a multiple of 10."""
    watchdog_s: float = Field(0.5, gt=0.0)
    """No fresh setpoint for this long: hold the last one (logged once); a setpoint computed
    from telemetry older than this is dropped."""
    yaw_deg: float | None = None
    """Yaw of the position setpoints, degrees; None holds the yaw the drone has when the first
    setpoint arrives."""
    connect_timeout_s: float = Field(10.0, gt=0.0)
    toc_cache_dir: str | None = None
    """Directory where cflib caches the firmware's TOCs (faster reconnections); None: none."""
    data_timeout_s: float = Field(1.0, gt=0.0)
    """No log data for this long on an open link: taken as lost (a driver may not notice); at
    least three periods of the most frequent log block."""
    reconnect_max_s: float = Field(5.0, gt=0.0)
    """Longest wait between reconnection attempts (the back-off doubles from 0.25 s)."""
    status_period_s: float = Field(1.0, gt=0.0)
    """Period of ``tether/{drone}/bridge`` status messages."""
    silence_s: float = Field(0.1, gt=0.0)
    """Ground-station silence (no Setpoint, Estimate or command for this drone, timed on
    arrival) beyond which a flying drone holds its setpoint: ``holding`` (at least three log
    periods: the service answers each Telemetry)."""
    hold_s: float = Field(0.3, gt=0.0, le=5.0)
    """How long the drone holds in silence before the bridge lands it itself (docs/real-lab.md,
    "what the bridge does when something goes wrong")."""
    land_speed_mps: float = Field(0.25, gt=0.0, le=1.0)
    """Descent speed of the bridge's own landings (silence, a landing Stop), m/s."""
    max_setpoint_speed_mps: float = Field(1.0, gt=0.0)
    """A Setpoint that jumps from the one in force faster than this is refused (the firmware's
    position controller flies at most 1 m/s per axis)."""
    thrust_model: Literal[
        "pwm_map", "cubic_21plus", "cubic_legacy", "cubic_upgrade_kit", "cubic_brushless"
    ] = "pwm_map"
    """``pwm_map``: ``thrust_map`` on the motor values; ``cubic_*``: the firmware's own model
    (2025.09 and later) for that propeller type, a cubic in the motor's voltage ``pm.vbat`` ×
    ``motor.m*``/65535 (``VMOTOR2THRUST0..3``; needs ``pm.vbat``; docs/real-lab.md)."""

    onboard_position: Literal["none", "lighthouse", "loco", "flow"] = "none"
    """The positioning the drone's own Kalman estimator fuses (a Lighthouse, Loco or Flow
    deck). Not ``none``: the bridge logs ``stateEstimate.x/y/z`` with ``kalman.varX/Y/Z`` in a
    block of its own and publishes them as ``position_m`` (``position_source``, σ in
    ``position_std_m``) when no fresh motion-capture pose is at hand, and take-off waits for
    the estimator to settle after a reset (docs/real-lab.md, "onboard positioning")."""
    extpos_rate_hz: float = Field(100.0, gt=0.0, le=500.0)
    """With ``send_extpos``: poses go to the drone at most this often, the latest one winning
    (a faster motion capture would fill the radio that several drones share)."""
    ext_quat_std_rad: float = Field(8.0e-3, gt=0.0)
    """With ``send_extpos`` and poses that carry an attitude: ``locSrv.extQuatStdDev``, set at
    each connection (Bitcraze's mocap example: 8.0e-3; the firmware's default 4.5e-3)."""
    ext_pos_std_m: float | None = Field(None, gt=0.0)
    """With ``send_extpos``: ``locSrv.extPosStdDev`` set at each connection (None: the
    firmware's, 0.01 m)."""
    estimator_initial_m: tuple[float, float, float] | None = None
    """Written to ``kalman.initialX/Y/Z`` before each estimator reset: where the drone sits,
    world frame, m (a Flow deck's odometry then starts in the world frame). None: untouched."""
    estimator_settle_s: float = Field(4.5, gt=0.0)
    """After a reset the estimator has settled when each of ``kalman.varPX/PY/PZ`` has stayed
    within ``estimator_settle_spread`` over this long (cflib's ``reset_estimator``: ten samples
    0.5 s apart), s."""
    estimator_settle_spread: float = Field(0.001, gt=0.0)
    """Largest spread (max − min) of each variance over ``estimator_settle_s`` (cflib's
    threshold), the variances' unit (m²/s²)."""

    @field_validator("slow_period_ms")
    @classmethod
    def _ten_ms_steps(cls, value: int) -> int:
        if value % 10:
            raise ValueError(f"{value!r}: Crazyflie log periods are multiples of 10 ms")
        return value

    @field_validator("thrust_map")
    @classmethod
    def _thrust_map(cls, value: tuple[float, float, float]) -> tuple[float, float, float]:
        a, b, c = value
        top = a * 65535.0**2 + b * 65535.0 + c
        if not all(math.isfinite(v) for v in value) or not 0.0 < top < 10.0:
            raise ValueError(f"{list(value)!r}: thrust at pwm 65535 must be within (0, 10) N")
        return value

    @property
    def log_period_ms(self) -> int:
        """The telemetry log period: ``1000 / rate_hz`` rounded to 10 ms steps, at least 10."""
        return max(10, 10 * round(100.0 / self.rate_hz))


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


_ENV_SOURCE_ON: contextvars.ContextVar[bool] = contextvars.ContextVar(
    "groundstation_env_source_on", default=True
)
"""Whether constructing :class:`Settings` reads ``GROUNDSTATION_*`` (off while
:func:`load_settings` validates its layers)."""


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
    localization: LocalizationSection = LocalizationSection()
    web: WebSection = WebSection()
    foxglove: FoxgloveSection = FoxgloveSection()
    service: ServiceSection = ServiceSection()
    sim: SimSection = SimSection()
    crazyflie: CrazyflieSection = CrazyflieSection()
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
        # file and the CLI, then validates the layers with the environment source off
        # (pydantic-settings reads it in ``model_validate`` too: ``use_env=False`` would
        # otherwise still see GROUNDSTATION_* variables).
        if not _ENV_SOURCE_ON.get():
            return (init_settings,)
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
                merged[name] = type(section).model_validate(
                    section.model_dump() | patch, context=_STRICT
                )
            except ValidationError as exc:
                raise ConfigError(
                    _describe(exc, prefix=f"drones.{drone_id}.{name}", data=patch)
                ) from None
        return DroneParams(**merged)


class _Range(NamedTuple):
    """A plausible range of a micro drone's quantity and the unit mistakes that leave it."""

    low: float
    high: float
    unit: str
    typical: float
    mistakes: tuple[tuple[str, str, float], ...]
    """``(unit, name, factor)``: the value written in that unit, times factor, is SI."""


PLAUSIBLE: dict[str, _Range] = {
    "drone.mass_kg": _Range(0.005, 2.0, "kg", 0.03, (("g", "grams", 1e-3),)),
    "tether.length_m": _Range(
        0.1, 30.0, "m", 1.6, (("cm", "centimetres", 1e-2), ("mm", "millimetres", 1e-3))
    ),
    "tether.weight_n_per_m": _Range(1e-4, 1.0, "N/m", 0.05, (("g/m", "grams per metre", 9.81e-3),)),
}
"""Plausible ranges of a micro drone (5 g to 2 kg) and its tether (10 cm to 30 m, 0.01 to
100 g/m): outside them the configuration is refused as a likely unit mistake, unless
``[drone] unusual_rig = true``."""


def _implausible(key: str, value: float) -> str | None:
    """Why ``value`` of ``key`` (``table.field``) is no micro drone's, or None if it could be."""
    r = PLAUSIBLE[key]
    if r.low <= value <= r.high:
        return None
    field_name = key.split(".")[1]
    # The likeliest mistake: the one that lands in range nearest the typical value.
    fits = [(abs(math.log(value * f / r.typical)), u, n, value * f) for u, n, f in r.mistakes]
    fits = [x for x in fits if r.low <= x[3] <= r.high]
    hint = ""
    if fits:
        _, short, name, si = min(fits)
        hint = f"; {name}? {value:g} {short} is {field_name} = {si:.3g}"
    return (
        f"{value:g} {r.unit} is outside a micro drone's {r.low:g}-{r.high:g} {r.unit}{hint} "
        "(for an unusual rig set [drone] unusual_rig = true)"
    )


STANDARD_GRAVITY_MPS2 = 9.80665
"""Standard gravity (physical, CGPM 1901), for the plausibility checks only: the
configuration imports no physics module (the simulator imports the configuration)."""

BASE_COORDINATE_MAX_M = PLAUSIBLE["tether.length_m"].high
"""Largest plausible |coordinate| of the base exit point, m: the longest plausible tether
(a base further from the world origin than any tether reaches is a unit mistake, e.g. a
height of 75.4 given in centimetres)."""

FOLLOW_THRESHOLD_MAX_WEIGHTS = 1.0
"""Largest plausible follow threshold as a multiple of the drone's weight m·g (physical: a
micro quadrotor's thrust-to-weight ratio is about 2 (Crazyflie 2.1: ~60 g of thrust for
~30 g), so its margin over hover is about one weight; a pull above that drags the drone
whatever it does, and following would never engage before it)."""


def _check_plausible(params: DroneParams | Settings, prefix: str) -> None:
    """Refuse a value no micro drone rig has, unless ``unusual_rig``: the ranges of
    :data:`PLAUSIBLE`, a base exit point further out than any tether
    (:data:`BASE_COORDINATE_MAX_M`), a floor above the base, a follow threshold above
    :data:`FOLLOW_THRESHOLD_MAX_WEIGHTS` times the drone's weight.

    Raises:
        ConfigError: one line with the key, the value and the likely unit mistake.
    """
    if params.drone.unusual_rig:
        return
    for key in PLAUSIBLE:
        table, name = key.split(".")
        value = getattr(getattr(params, table), name)
        why = _implausible(key, value)
        if why is not None:
            raise ConfigError(f"invalid configuration: {prefix}{key} = {value:g}: {why}")
    unusual = "(for an unusual rig set [drone] unusual_rig = true)"
    base = params.base.position_m
    far = BASE_COORDINATE_MAX_M
    if any(abs(v) > far for v in base):
        hint = ""
        for short, name, f in (("cm", "centimetres", 1e-2), ("mm", "millimetres", 1e-3)):
            if all(abs(v * f) <= far for v in base):
                si = ", ".join(f"{v * f:.4g}" for v in base)
                hint = f"; {name}? {list(base)!r} {short} is position_m = [{si}]"
                break
        raise ConfigError(
            f"invalid configuration: {prefix}base.position_m = {list(base)!r}: further than "
            f"{far:g} m from the origin, beyond any micro drone's tether{hint} {unusual}"
        )
    if params.base.floor_z_m > base[2]:
        raise ConfigError(
            f"invalid configuration: {prefix}base.floor_z_m = {params.base.floor_z_m:g}: above "
            f"the base exit point (base.position_m z = {base[2]:g} m); the tether leaves the "
            f"base above the floor it rests on (both heights in metres, in the world frame) "
            f"{unusual}"
        )
    weight_n = params.drone.mass_kg * STANDARD_GRAVITY_MPS2
    limit_n = FOLLOW_THRESHOLD_MAX_WEIGHTS * weight_n
    threshold_n = params.follow.threshold_n
    if threshold_n > limit_n:
        hint = ""
        if threshold_n * 1e-3 <= limit_n:
            hint = f"; millinewtons? {threshold_n:g} mN is threshold_n = {threshold_n * 1e-3:.3g}"
        raise ConfigError(
            f"invalid configuration: {prefix}follow.threshold_n = {threshold_n:g}: above the "
            f"drone's weight ({weight_n:.3g} N for drone.mass_kg = {params.drone.mass_kg:g}), "
            f"a pull no micro drone resists{hint} {unusual}"
        )


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
        lines.append(f"{key} = {value!r}: {err['msg'].removeprefix('Value error, ')}")
    return "invalid configuration: " + "; ".join(lines)


def _check_tables_strictly(layered: Mapping[str, Any]) -> None:
    """Validate each table with the strict-scalars context (``BaseSettings`` drops contexts).

    Raises:
        ConfigError: names the key and the value.
    """
    for name, field in Settings.model_fields.items():
        section_type, value = field.annotation, layered.get(name)
        if not (isinstance(value, Mapping) and isinstance(section_type, type)):
            continue
        if issubclass(section_type, _Section):
            try:
                section_type.model_validate(value, context=_STRICT)
            except ValidationError as exc:
                raise ConfigError(_describe(exc, prefix=name, data=value)) from None


def _decode_env(raw: Any) -> Any:
    if not isinstance(raw, str):
        return raw
    try:
        return json.loads(raw)
    except ValueError:
        return raw


def _deep_merge(base: dict[str, Any], patch: Mapping[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in patch.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = _deep_merge(dict(out[key]), value)
        else:
            out[key] = value
    return out


ENV_PREFIX = "GROUNDSTATION_"
ENV_NOT_SETTINGS = frozenset({"GROUNDSTATION_PUBLIC_CONTRACT"})
"""``GROUNDSTATION_*`` variables that are not configuration (the contract test's path to the
shared original): left alone by :func:`check_env_names`."""


def check_env_names(environ: Mapping[str, str]) -> None:
    """Refuse a ``GROUNDSTATION_*`` variable that names no setting, as a misspelt key in a
    file is refused (pydantic-settings would drop an unknown section silently).

    ``GROUNDSTATION_SECTION__KEY`` must name a table of :class:`Settings` and one of its
    keys; ``GROUNDSTATION_DRONES__<ID>__<TABLE>__<KEY>`` one of :class:`DroneOverride`'s
    tables and a key of that table. Case-insensitive, as the settings source is.

    Raises:
        ConfigError: names the variable and the nearest known names.
    """
    import difflib

    for var in sorted(environ):
        if not var.upper().startswith(ENV_PREFIX) or var.upper() in ENV_NOT_SETTINGS:
            continue
        parts = var[len(ENV_PREFIX) :].lower().split("__")
        sections = list(Settings.model_fields)
        where, known = "section", sections
        problem: str | None = None
        if parts[0] not in sections:
            problem = parts[0]
        elif parts[0] == "drones":
            tables = list(DroneOverride.model_fields)
            if len(parts) < 4:
                problem, where, known = "", "GROUNDSTATION_DRONES__<ID>__<TABLE>__<KEY>", []
            elif parts[2] not in tables:
                problem, where, known = parts[2], "per-drone table", tables
            else:
                section_type = Settings.model_fields[parts[2]].annotation
                keys = list(getattr(section_type, "model_fields", {}))
                if keys and parts[3] not in keys:
                    problem, where, known = parts[3], f"key of [{parts[2]}]", keys
        else:
            section_type = Settings.model_fields[parts[0]].annotation
            keys = list(getattr(section_type, "model_fields", {}))
            if len(parts) < 2:
                problem, where, known = "", "GROUNDSTATION_SECTION__KEY", []
            elif keys and parts[1] not in keys:
                problem, where, known = parts[1], f"key of [{parts[0]}]", keys
        if problem is None:
            continue
        if not known:
            raise ConfigError(f"environment variable {var}: not of the form {where}")
        near = difflib.get_close_matches(problem, known, n=1)
        hint = f"; did you mean {near[0]!r}?" if near else f" (known: {', '.join(known)})"
        raise ConfigError(f"environment variable {var}: unknown {where} {problem!r}{hint}")


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
            check_env_names(os.environ)
            # Environment beats the file: validate env alone, then lay it over the file.
            env_only = Settings()
            env_set = env_only.model_dump(exclude_unset=True)
            # Per-drone overrides stay untyped dicts until resolved: decode their strings
            # here (a number or a list in JSON), as the typed tables were decoded above.
            for override in env_set.get("drones", {}).values():
                for table in override.values():
                    if isinstance(table, dict):
                        for key, raw in table.items():
                            table[key] = _decode_env(raw)
            layered = _deep_merge(layered, env_set)
        layered = _deep_merge(layered, dict(cli_overrides or {}))
        _check_tables_strictly(layered)
        token = _ENV_SOURCE_ON.set(False)  # the environment is in ``layered`` already
        try:
            settings = Settings.model_validate(layered)
        finally:
            _ENV_SOURCE_ON.reset(token)
    except ValidationError as exc:
        raise ConfigError(_describe(exc, data=layered)) from None
    # Resolve every override once at start-up so a bad per-drone value fails now.
    _check_plausible(settings, "")
    for drone_id in settings.drones:
        _check_plausible(settings.for_drone(drone_id), f"drones.{drone_id}.")
    floor_n = settings.service.follow_threshold_min_n
    for key, follow in [("follow", settings.follow)] + [
        (f"drones.{d}.follow", settings.for_drone(d).follow) for d in settings.drones
    ]:
        if follow.threshold_n < floor_n:
            raise ConfigError(
                f"invalid configuration: {key}.threshold_n = {follow.threshold_n!r}: below "
                f"service.follow_threshold_min_n = {floor_n!r} (a threshold that low follows "
                "the tether's own pull)"
            )
    return settings
