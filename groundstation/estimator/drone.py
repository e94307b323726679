"""One drone's estimator: its state, and the stages a telemetry message goes through.

::

    Telemetry ─▶ observation ─▶ gate ─▶ rest · contact · battery ─▶ slow accel
              ─▶ filter ─▶ localize ─▶ follow ─▶ Estimate, Setpoint, Stop

Each stage is a module of :mod:`groundstation.estimator` (control) around a physics module
(the equations), joined by immutable records read by name (``typing.NamedTuple``: a frozen
dataclass's ``__init__`` sets each field through ``object.__setattr__``, six times the cost,
and a message crosses some 35 fields of them):

============================  ==================================  ===========================
stage                         control                             physics
============================  ==================================  ===========================
observation                   :mod:`.observation`                 ``tension.observe_tension``
stream gate (order, gaps)     :mod:`.gate`                        —
rest calibration              :meth:`DroneEstimator._feed_rest`   ``calibration.RestCalibrator``
contact (ground / air)        :mod:`.contact_control`             ``contact.contact_step``
battery, position σ checks    :mod:`.checks`                      —
slow accelerometer error      :func:`.observation.learn_slow`     ``slow_accel``
tension filter                :mod:`.filter_control`              ``tension.TensionFilter``
localization                  :mod:`.localize_control`            ``localization.localize``
follow, tug-to-land           :mod:`.follow_control`              ``follow.follow_step``
Estimate                      :mod:`.output`                      —
============================  ==================================  ===========================

:meth:`DroneEstimator.step` runs a message through all of them: :meth:`front` up to the
localization's inputs (a :class:`Front`), the localization, :meth:`back` from the
localization on. The estimator reports what the operator must hear
(drops, one-off warnings, the Stops it issues) through the callbacks it is given; it never
touches the bus.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np

from groundstation import contact as contact_mod
from groundstation import follow as follow_mod
from groundstation import slow_accel as slow_mod
from groundstation.bias_kalman import BiasKalmanParams
from groundstation.bus import Sample
from groundstation.calibration import RestCalibrator
from groundstation.config import CalibrationSection, DroneParams, Settings
from groundstation.estimator import checks, output
from groundstation.estimator.contact_control import contact_decide
from groundstation.estimator.filter_control import FilterControl
from groundstation.estimator.follow_control import follow_decide, follow_stamped
from groundstation.estimator.gate import GateState, gate_step, mark_stale
from groundstation.estimator.localize_control import LocalizeIn, fresh_angle, localize_one
from groundstation.estimator.observation import learn_slow, observe
from groundstation.localization import AngleObservation, PositionEstimate
from groundstation.messages import Estimate, FollowInfo, Setpoint, Stop, Telemetry
from groundstation.tension import (
    DegenerateQuaternionError,
    ObservationCalibration,
    TensionError,
    TensionFilter,
    TensionFilterParams,
)

__all__ = [
    "MOCAP_HOLD_S",
    "DroneEstimator",
    "Front",
    "calibration_from_config",
]

MOCAP_HOLD_S = slow_mod.MOCAP_HOLD_S
"""A motion-capture position stays the drone's external position for this long (telemetry
stamp) after the frame that brought it, s (:data:`groundstation.bias_kalman.MOCAP_HOLD_S`,
which is ``tension.GAP_S``: one definition of a broken stream)."""

Vec3 = tuple[float, float, float]
OnDrop = Callable[[str, str, str], None]
"""``on_drop(drone, kind, detail)``: a message or output refused."""
OnWarning = Callable[[str, float, str, str], None]
"""``on_warning(drone, now_s, text, field)``: something the operator must hear, once."""
OnStop = Callable[[str, float, str], None]
"""``on_stop(drone, now_s, reason)``: the estimator issued a Stop (tug-to-land)."""


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
        thrust_model=section.thrust_model,
        thrust_pwm_map=section.thrust_pwm_map,
        thrust_motor_ref_n=section.thrust_motor_ref_n,
        thrust_motor_ref_v=section.thrust_motor_ref_v,
        thrust_motor_exponent=section.thrust_motor_exponent,
    )
    if cal.is_identity:
        return None, section.source
    return cal, section.source if section.source != "none" else "config"


def slow_accel_params(
    params: DroneParams, mocap_std_m: float | None = None
) -> slow_mod.SlowAccelParams:
    """The slow stage's settings from ``[filter]`` and ``[calibration]`` (the service's, and
    ``calibrate``'s when it runs the same hover test over a recording); ``mocap_std_m``:
    ``[localization] mocap_std_m`` (None: the bias filter's default, the same 2 mm)."""
    hover = None
    if params.filter.accel_hover_crossover_s > 0.0:
        hover = slow_mod.hover_process(*hover_velocity_params(params.calibration))
    return slow_mod.SlowAccelParams(
        flight=flight_params(params.calibration, mocap_std_m),
        velocity_time_constant_s=params.filter.drag_velocity_time_constant_s,
        hover=hover,
    )


_FILTER_DEFAULTS = TensionFilterParams()
_FLIGHT_DEFAULTS = BiasKalmanParams()


def flight_params(
    section: CalibrationSection, mocap_std_m: float | None = None
) -> BiasKalmanParams:
    """The bias filter's model of the flight where ``calibrate`` fitted it (``[calibration]
    flight_velocity_std_mps`` / ``flight_velocity_time_s`` / ``flight_bias_std_mps2``); the
    defaults otherwise (groundstation.bias_kalman)."""
    d = _FLIGHT_DEFAULTS
    std, time, bias = (
        section.flight_velocity_std_mps,
        section.flight_velocity_time_s,
        section.flight_bias_std_mps2,
    )
    return BiasKalmanParams(
        velocity_std_mps=d.velocity_std_mps if std is None else std,
        velocity_time_s=d.velocity_time_s if time is None else time,
        flight_bias_std_mps2=d.flight_bias_std_mps2 if bias is None else bias,
        mocap_std_m=d.mocap_std_m if mocap_std_m is None else mocap_std_m,
    )


def hover_velocity_params(section: CalibrationSection) -> tuple[float, float]:
    """``TensionFilterParams``' σ_v (m/s) and T_c (s) where ``calibrate`` fitted them
    (``[calibration] hover_velocity_std_mps`` / ``hover_velocity_time_s``); the filter's
    defaults otherwise."""
    std = section.hover_velocity_std_mps
    time = section.hover_velocity_time_s
    return (
        _FILTER_DEFAULTS.hover_velocity_std_mps if std is None else std,
        _FILTER_DEFAULTS.hover_velocity_time_s if time is None else time,
    )


def hover_balance_params(section: CalibrationSection) -> tuple[float, float | None]:
    """``TensionFilterParams``' q_w (N²/s) and D (N²·s) where ``calibrate`` fitted them
    (``[calibration] hover_wander_n2_per_s`` / ``hover_balance_density_n2s``); the
    filter's defaults otherwise."""
    wander = section.hover_wander_n2_per_s
    return (
        _FILTER_DEFAULTS.hover_wander_n2_per_s if wander is None else wander,
        section.hover_balance_density_n2s,
    )


def calibrated_attitude_source(section: CalibrationSection, label: str) -> str | None:
    """The attitude a calibration's thrust axis holds in (:class:`DroneEstimator`).

    ``[calibration] attitude_source`` where ``calibrate`` wrote it; nothing calibrated
    (``label`` ``none``): ``onboard``, the body axis of the drone's own estimator, levelled
    on the same accelerometer; a calibration that does not say: None, any.
    """
    if section.attitude_source is not None:
        return section.attitude_source
    return "onboard" if label == "none" else None


class Rate:
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


class Front(NamedTuple):
    """A telemetry message stepped up to its localization (:meth:`DroneEstimator.front`).

    Attributes:
        msg: the message (without a position too uncertain to use).
        now_s: its receive time, s.
        tension_world_n, std_n, converged: the filter stage's output.
        finite: the filter's output is finite (else no Estimate).
        on_ground: the contact stage's decision (or disarmed).
        localize_in: what to localize it from (None: nothing to localize).
        mocap_world_m: the motion-capture position held for this message (None: none).
    """

    msg: Telemetry
    now_s: float
    tension_world_n: Sequence[float]
    std_n: Sequence[float]
    converged: bool
    finite: bool
    on_ground: bool
    localize_in: LocalizeIn | None
    mocap_world_m: Vec3 | None


def _ignore(*_: Any) -> None:
    return None


class DroneEstimator:
    """One drone's state and its per-message step (module doc).

    Owned by the processing thread. What operators change (reel length and base, tether
    weight, follow settings) the :class:`~groundstation.pipeline.Pipeline` writes to the
    attributes below between messages.

    Args:
        drone: the drone's id.
        settings: the root configuration (its per-drone values are taken here).
        on_drop, on_warning, on_stop: what the estimator reports (see the type aliases).
    """

    def __init__(
        self,
        drone: str,
        settings: Settings,
        *,
        on_drop: OnDrop = _ignore,
        on_warning: OnWarning = _ignore,
        on_stop: OnStop = _ignore,
    ) -> None:
        params: DroneParams = settings.for_drone(drone)
        self.drone = drone
        self.params = params
        self.localization = settings.localization
        self._on_drop, self._on_warning, self._on_stop = on_drop, on_warning, on_stop
        self.estimate_key = f"tether/{drone}/estimate"
        self.setpoint_key = f"tether/{drone}/cmd/setpoint"
        self.stop_key = f"tether/{drone}/cmd/stop"

        # -- the tether and the base (the reel and operators may change them)
        self.length_m = params.tether.length_m
        self.length_source = "config"
        self.base_world_m = np.array(params.base.position_m, dtype=float)
        self.weight_n_per_m = params.tether.weight_n_per_m
        self.exit_azimuth: AngleObservation | None = None
        """The reel's last exit azimuth (with its σ); when received below."""
        self.exit_azimuth_received_s = -math.inf
        self.exit_elevation: AngleObservation | None = None
        self.exit_elevation_received_s = -math.inf

        # -- the stages' states
        self.gate = GateState()
        self.max_gap_s = settings.service.stale_after_s
        """Receive-time silence that resumes the stream (the gate's), s: the service's
        stale time, so a pipeline without ticks restarts where the service would."""
        self.calibration, self.calibration_source = calibration_from_config(params.calibration)
        self.vbat_range_v = params.calibration.thrust_vbat_range_v
        self.rest_detector = RestCalibrator(bias_body_mps2=params.calibration.accel_bias_mps2)
        """The one test of "still on the floor": the rest offset's (``[calibration] rest``)
        and the slow stage's β at rest."""
        self.rest = self.rest_detector if params.calibration.rest else None
        """The rest calibration (None: ``[calibration] rest`` off)."""
        self.contact_params = contact_mod.ContactParams(
            ground_thrust_ratio=params.filter.ground_thrust_ratio
        )
        self.contact = contact_mod.ContactState()
        self.mocap_std_m = settings.localization.mocap_std_m
        """σ_p, m: the motion-capture position's noise per axis (``[localization]
        mocap_std_m``): the contact stage's height band where a message gives no
        ``position_std_m`` of its own."""
        self.bias_step_std_mps2 = flight_params(params.calibration).flight_bias_std_mps2
        """σ_δ, m/s²: how far the accelerometer's bias strays from the rest's once the
        propellers spin (``[calibration] flight_bias_std_mps2``, fitted by ``calibrate``;
        the default where nothing was): the contact stage's climb test allows for it."""
        self.slow_params = (
            slow_accel_params(params, settings.localization.mocap_std_m)
            if params.calibration.accel_slow
            else None
        )
        """``[calibration] accel_slow``: the accelerometer's slow content replaced (None: off)."""
        self.slow = slow_mod.SlowAccelState()
        mx, my, mz = params.calibration.tension_model_std_n
        self.model_var_n2 = (mx * mx, my * my, mz * mz) if mx or my or mz else None
        """``[calibration] tension_model_std_n`` squared, N² (None: zero): the calibration's
        error, added to the filter's variance in the published σ and to the covariance the
        position's σ is computed from (in the air)."""
        self.changes_at_hover_end = 0
        """The filter's change detections when the last hover ended: a hover that begins
        after one more (a manoeuvre that changed the tension) restarts the filter's
        averaging (:meth:`TensionFilter.new_hover`)."""
        self.attitude_calibrated = calibrated_attitude_source(
            params.calibration, self.calibration_source
        )
        """The attitude the thrust axis was fitted against (None: any, a calibration that
        does not say)."""
        self.attitude_served: str | None = None
        """The last Telemetry's attitude source (its own, else ``[drone]``'s)."""
        self.slow_active = False
        """The hover model in use: :attr:`slow_params` set and the attitude served the one
        calibrated (:meth:`_attitude_changed`)."""
        self.rest_active = False
        """A rest offset may be applied: the accelerometer model, and not as the fallback of
        an attitude from another source (its rest offset would carry the frames' tilt)."""
        hover_std_mps, hover_time_s = hover_velocity_params(params.calibration)
        wander_n2_per_s, balance_n2s = hover_balance_params(params.calibration)
        self.filter_control = FilterControl(
            TensionFilterParams(
                mass_kg=params.drone.mass_kg,
                accel_noise_mps2=params.drone.accel_noise_mps2,
                thrust_noise_n=params.drone.thrust_noise_n,
                hover_velocity_std_mps=hover_std_mps,
                hover_velocity_time_s=hover_time_s,
                hover_wander_n2_per_s=wander_n2_per_s,
                hover_balance_density_n2s=balance_n2s,
            ),
            self.contact_params.push_free_weight_ratio,
        )
        # [follow] and FollowParams share their field names (a new key fails loudly).
        self.follow_params = follow_mod.FollowParams(**params.follow.model_dump())
        self.follow_state = follow_mod.FollowState()
        self.land_below_m_memory: float | None = None
        """Last tug-to-land height, restored when tug-to-land is switched back on."""

        # -- what the drone's messages told, for the status and the checks
        self.mocap_m: Vec3 | None = None
        """The last motion-capture ``position_m`` received, m, world frame."""
        self.mocap_stamp_s = -math.inf
        """The telemetry ``stamp_s`` that brought :attr:`mocap_m`, s."""
        self.last_vbat_v: float | None = None
        self.calibration_extrapolated: bool | None = None
        """The last Telemetry's ``vbat_v`` outside :attr:`vbat_range_v` (None: unknown)."""
        self.rest_missing = False
        """``[calibration] rest_required`` and armed without a rest offset in force."""
        self._told: set[str] = set()
        """The one-off warnings already sent."""

        # -- counters and rates
        self.received = 0
        self.accepted = 0
        self.estimates = 0
        self.setpoints = 0
        self.stops = 0
        self.seq_gaps = 0
        self.drops: Counter[str] = Counter()
        self.telemetry_rate = Rate()
        self.estimate_rate = Rate()

        # -- the last Estimate, and caches of what rarely changes
        self.last_estimate_fields: dict[str, Any] | None = None
        self.follow_json_cache: tuple[FollowInfo, dict[str, Any]] | None = None
        self.follow_info_cache: tuple[follow_mod.FollowParams, tuple[Any, ...], FollowInfo] | None
        self.follow_info_cache = None
        self.base_cache: tuple[np.ndarray, Vec3] | None = None

    # ---------------------------------------------------------------- views

    @property
    def filter(self) -> TensionFilter:
        return self.filter_control.filter

    @property
    def change_detections(self) -> int:
        return self.filter_control.change_detections

    @property
    def stale(self) -> bool:
        return self.gate.stale

    @property
    def last_seq(self) -> int | None:
        return self.gate.last_seq

    @property
    def last_stamp_s(self) -> float | None:
        return self.gate.last_stamp_s

    @property
    def last_seen_s(self) -> float | None:
        return self.gate.last_seen_s

    @property
    def last_estimate(self) -> Estimate | None:
        """The last published Estimate as a model (built on demand, not per message)."""
        if self.last_estimate_fields is None or self.follow_json_cache is None:
            return None
        return Estimate(**{**self.last_estimate_fields, "follow": self.follow_json_cache[0]})

    def fresh_mocap(self, stamp_s: float) -> Vec3 | None:
        """The motion-capture position if a frame came within :data:`MOCAP_HOLD_S`."""
        if self.mocap_m is not None and 0.0 <= stamp_s - self.mocap_stamp_s <= MOCAP_HOLD_S:
            return self.mocap_m
        return None

    def trusted_position(self) -> bool | None:
        """The last message had a position follow may fly to: motion capture held for it,
        or a calibration in force (None: no message yet)."""
        stamp_s = self.gate.last_stamp_s
        if stamp_s is None:
            return None
        return self.fresh_mocap(stamp_s) is not None or self.calibration_source != "none"

    # ---------------------------------------------------------------- the step

    def step(self, msg: Telemetry, now_s: float) -> list[Sample]:
        """One telemetry message through every stage; the samples to publish."""
        front = self.front(msg, now_s)
        if front is None:
            return []
        x = front.localize_in
        return self.back(front, localize_one(self.localization, x) if x is not None else None)

    def front(self, msg: Telemetry, now_s: float) -> Front | None:
        """A message up to its localization: observation, gate, rest, contact, battery,
        slow accelerometer, filter. None for a refused message (reported)."""
        self.received += 1
        if checks.position_too_uncertain(msg, self.localization.position_max_std_m):
            self._warn_position(msg, now_s)
            msg = msg.model_copy(update={"position_m": None})
        served = msg.attitude_source or self.params.drone.attitude_source
        if served != self.attitude_served:
            self._attitude_changed(served, now_s)
        slow = self.slow if self.slow_active else None
        rest_offset = None
        if self.rest_active and self.rest is not None and self.rest.offset is not None:
            ox, oy, _ = self.rest.offset.offset_body_mps2.tolist()
            rest_offset = (ox, oy)
        # Malformed content first (whatever its seq), then the stream's order.
        try:
            observed = observe(
                msg,
                mass_kg=self.params.drone.mass_kg,
                calibration=self.calibration,
                rest_offset_xy_mps2=rest_offset,
                slow=slow,
                ground_thrust_ratio=self.contact_params.ground_thrust_ratio,
            )
        except DegenerateQuaternionError as exc:
            self._drop("bad_quaternion", str(exc))
            return None
        except TensionError as exc:
            self._drop("bad_observation", str(exc))
            return None
        gate, verdict = gate_step(
            self.gate,
            seq=msg.seq,
            stamp_s=msg.stamp_s,
            now_s=now_s,
            max_gap_s=self.max_gap_s,
            drone=self.drone,
        )
        if verdict.drop_kind is not None:
            self._drop(verdict.drop_kind, verdict.detail)
            return None
        self.gate = gate
        self.seq_gaps += verdict.seq_gap
        if verdict.resumed:
            self.filter_control.restart()
        dt_s = verdict.dt_s
        if msg.position_m is not None:
            self.mocap_m = msg.position_m
            self.mocap_stamp_s = msg.stamp_s
        self.accepted += 1
        self.telemetry_rate.add(now_s)
        self._feed_rest(msg, now_s)

        # Ground or air, with hysteresis: between ground_thrust_ratio and the weight the
        # floor may still carry the drone (its push is no tension) until lift-off is seen.
        obs = observed.observation
        mass_kg = self.params.drone.mass_kg
        # The floor's vibration for the climb test: the tension filter's measure of it
        # (read on the ground and armed only, where the test runs).
        on_floor_armed = self.contact.on_ground and msg.armed
        noise_n2 = self.filter.vertical_noise_var_n2() if on_floor_armed else None
        # The per-sample tests' threshold (the climb's, the motion-capture height's): both
        # judge an armed drone only (disarmed is the ground at once).
        judged = noise_n2 is not None or (msg.armed and msg.position_m is not None)
        sample_sigmas = self.filter.sigmas_at(dt_s) if judged else math.inf
        contact, on_ground = contact_decide(
            self.contact,
            self.contact_params,
            msg,
            thrust_n=obs.thrust_n,  # calibrated
            mass_kg=mass_kg,
            dt_s=dt_s,
            floor_z_m=self.params.base.floor_z_m,
            rotation_rows_world_body=observed.rotation_rows_world_body,
            vertical_noise_var_mps4=None if noise_n2 is None else noise_n2 / (mass_kg * mass_kg),
            sample_sigmas=sample_sigmas,
            bias_step_std_mps2=self.bias_step_std_mps2,
            # The height's own σ where the message gives one (an onboard estimator's), else
            # motion capture's (the contract's default for an absent position_std_m).
            height_std_m=self.mocap_std_m if msg.position_std_m is None else msg.position_std_m[2],
        )
        self.contact = contact
        self._check_battery(msg.vbat_v, on_ground, now_s)
        was_hovering = False
        if self.slow_active:
            assert self.slow_params is not None
            was_hovering = self.slow.quasi_static
            still = not msg.armed and self.rest_detector.still  # armed: no property calls
            # The vibration the hover test's thresholds and the velocity filter's block step
            # need: the tension filter's measure of it, over the mass squared (one measure).
            # And the hover test's threshold: the one false-alarm rate at the spacing.
            density, hover_chi2 = None, math.inf
            if self.slow.in_air:
                filt = self.filter_control.filter
                density_n2s = filt.noise_density_n2s
                hover_chi2 = filt.sample_chi2
                if density_n2s is not None:
                    density = density_n2s / (mass_kg * mass_kg)
            self.slow = learn_slow(
                self.slow,
                self.slow_params,
                msg,
                observed,
                dt_s=dt_s,
                on_ground=on_ground,
                calibration=self.calibration,
                still=still,
                rest_mean_body_mps2=self.rest_detector.rest_mean_body_mps2 if still else None,
                accel_density_m2ps3=density,
                hover_chi2=hover_chi2,
            )
            if self.slow.quasi_static != was_hovering:
                detections = self.filter_control.change_detections
                if was_hovering:
                    self.changes_at_hover_end = detections
                elif detections != self.changes_at_hover_end:
                    self.filter.new_hover(slow_mod.HOVER_MEAN_S)
        filtered = self.filter_control.step(
            on_ground=on_ground,
            contact_reason=contact.reason,
            observation=obs,
            dt_s=dt_s,
            accel_model_world_n=observed.accel_model_world_n if self.slow_active else None,
            hover_model_world_n=observed.hover_model_world_n,
            hovering=was_hovering,
        )
        if filtered.hover_change:
            # A tug under the hover: the hover ends (its velocity no longer stays small).
            # The next hover averages afresh (new_hover above): the detection counted
            # makes change_detections differ from changes_at_hover_end.
            self.slow = slow_mod.end_hover(self.slow)
        if not filtered.finite:
            self._drop("non_finite_estimate", "filter produced NaN/inf")
        est = filtered.estimate
        localize_in = None
        model_var = self.model_var_n2 if not on_ground else None
        if est is not None and filtered.converged:
            localize_in = LocalizeIn(
                est.tension_world_n,
                est.cov_n2,
                self.weight_n_per_m,
                self.length_m,
                self.base_world_m,
                self.params.base.floor_z_m,
                self._fresh(self.exit_azimuth, self.exit_azimuth_received_s, now_s),
                self._fresh(self.exit_elevation, self.exit_elevation_received_s, now_s)
                if self.localization.elevation
                else None,
                msg.position_m,
                model_var,
            )
        std_n = filtered.std_n
        if model_var is not None:
            s0, s1, s2 = std_n
            v0, v1, v2 = model_var
            std_n = (math.sqrt(s0 * s0 + v0), math.sqrt(s1 * s1 + v1), math.sqrt(s2 * s2 + v2))
        return Front(
            msg,
            now_s,
            filtered.tension_world_n,
            std_n,
            filtered.converged,
            filtered.finite,
            on_ground,
            localize_in,
            self.fresh_mocap(msg.stamp_s),
        )

    def back(self, front: Front, position: PositionEstimate | None) -> list[Sample]:
        """A message from its localization on: follow, the Estimate, Setpoint and Stop."""
        msg = front.msg
        fs = self.follow_state
        if not (fs.enabled or fs.active) and math.isfinite(msg.stamp_s):
            # Follow off and idle (follow_decide's first rule, without its call's cost).
            self.follow_state, decision = follow_stamped(fs, msg.stamp_s), None
        else:
            self.follow_state, decision = self._follow(front, position)
        out: list[Sample] = []
        estimate = self._estimate(front, position) if front.finite else None
        if estimate is not None:
            self.estimates += 1
            self.estimate_rate.add(front.now_s)
            out.append(Sample(self.estimate_key, estimate))
        if decision is None:
            return out
        setpoint = decision.setpoint_world_m
        if setpoint is not None and all(map(math.isfinite, output.vec3(setpoint))):
            sp = Setpoint(stamp_s=msg.stamp_s, position_m=output.vec3(setpoint))
            self.setpoints += 1
            out.append(Sample(self.setpoint_key, sp.to_json()))
        if decision.stop_reason is not None:
            self.stops += 1
            stop = Stop(stamp_s=msg.stamp_s, reason=decision.stop_reason, kind="land")
            out.append(Sample(self.stop_key, stop.to_json()))
            self._on_stop(self.drone, front.now_s, decision.stop_reason)
        return out

    def _follow(
        self, front: Front, position: PositionEstimate | None
    ) -> tuple[follow_mod.FollowState, follow_mod.FollowDecision | None]:
        return follow_decide(
            self.follow_state,
            self.follow_params,
            stamp_s=front.msg.stamp_s,
            tension_world_n=front.tension_world_n,
            converged=front.converged,
            position=position,
            mocap_world_m=front.mocap_world_m,
            trusted_without_mocap=self.calibration_source != "none",
            base_world_m=self.base_world_m,
            length_m=self.length_m,
            floor_z_m=self.params.base.floor_z_m,
            weight_n_per_m=self.weight_n_per_m,
            on_ground=front.on_ground,
        )

    def mark_stale(self) -> bool:
        """The drone fell silent: its next message resumes the stream, and follow is off.

        Returns:
            Whether follow was on (the operator must hear it was switched off).
        """
        self.gate = mark_stale(self.gate)
        was_on = self.follow_state.enabled
        self.follow_state = follow_mod.mark_stale(self.follow_state)
        return was_on

    # ---------------------------------------------------------------- stage helpers

    def _fresh(
        self, angle: AngleObservation | None, received_s: float, now_s: float
    ) -> AngleObservation | None:
        return fresh_angle(angle, received_s, now_s, self.localization.reel_stale_after_s)

    def _drop(self, kind: str, detail: str) -> None:
        self._on_drop(self.drone, kind, detail)

    def _warn_once(self, key: str, now_s: float, text: str, field: str) -> None:
        if key not in self._told:
            self._told.add(key)
            self._on_warning(self.drone, now_s, text, field)

    def _attitude_changed(self, served: str, now_s: float) -> None:
        """Choose the model for the attitude served (docs/attitude_source.md).

        The hover model's slow part ``m·g·e3 − R·u·F`` trusts the attitude's level: against
        a thrust axis ``u`` fitted in another attitude's frame it reads the frames' tilt δ as
        tension (``m·g·δ``, 5 mN per degree at 30 g). The accelerometer model ``m·R·f −
        R·u·F`` cancels it (δ enters both terms) and carries the accelerometer's bias
        instead, so it is the model when the attitude served is not the one calibrated.
        """
        self.attitude_served = served
        calibrated = self.attitude_calibrated
        mismatch = calibrated is not None and served != calibrated
        self.slow_active = self.slow_params is not None and not mismatch
        self.rest_active = not self.slow_active and not mismatch
        if mismatch and self.slow_params is not None:
            self._warn_once(
                f"attitude_source_{served}",
                now_s,
                f"{self.drone}'s attitude is {served}, but its thrust axis was "
                + (
                    f"fitted against the {calibrated} one ([calibration] attitude_source)"
                    if self.calibration_source != "none"
                    else "not calibrated (the drone's own body axis, which fits the onboard "
                    "attitude)"
                )
                + ": the accelerometer model is in use instead of the hover model (a tilt "
                "between the two frames would read as tension); calibrate with the attitude "
                "the drone flies with (told once)",
                "attitude_source",
            )

    def _warn_position(self, msg: Telemetry, now_s: float) -> None:
        std = msg.position_std_m
        assert std is not None
        self._warn_once(
            "position_untrusted",
            now_s,
            f"{self.drone}'s position_m ({msg.position_source or 'mocap'}) has σ "
            f"{[round(v, 3) for v in std]} m, above [localization] position_max_std_m "
            f"{self.localization.position_max_std_m:g} m: not used (follow flies on the "
            "tether's position)",
            "position_std_m",
        )

    def _feed_rest(self, msg: Telemetry, now_s: float) -> None:
        """Feed an accepted sample to the rest calibration (only after the gate: a repeated
        or out-of-order message must not enter the still window); with ``[calibration]
        rest_required``, warn once when the drone arms without a rest offset in force."""
        rest = self.rest_detector
        was_armed = rest.armed
        rest.update(msg.stamp_s, msg.accel_mps2, msg.quat_wxyz, msg.armed, msg.gyro_rps)
        if self.rest is None or not self.params.calibration.rest_required:
            return
        missing = checks.rest_missing_at_arming(
            was_armed=bool(was_armed),
            armed=msg.armed,
            offset_in_force=rest.offset is not None,
            missing_before=self.rest_missing,
        )
        if missing and not self.rest_missing:
            self._warn_once(
                "rest_missing",
                now_s,
                f"{self.drone}: armed without a rest offset in force, but its calibration "
                "relies on one ([calibration] rest_required: the thrust axis was fitted with "
                "the x/y accelerometer bias left to the rest calibration): the x/y bias is "
                "the configured one, not this power-on's. Let the drone sit disarmed and "
                "still on the floor for 1 s before arming (status rest_calibration; told "
                "once)",
                "armed",
            )
        self.rest_missing = missing

    def _check_battery(self, vbat_v: float | None, on_ground: bool, now_s: float) -> None:
        """Flag a battery outside the calibrated range on every message; tell it once."""
        self.last_vbat_v = vbat_v
        outside = checks.battery_outside(self.vbat_range_v, vbat_v, on_ground)
        self.calibration_extrapolated = outside
        if outside:
            assert self.vbat_range_v is not None and vbat_v is not None
            lo, hi = self.vbat_range_v
            self._warn_once(
                "battery",
                now_s,
                f"{self.drone}: battery {vbat_v:.3f} V outside the range the thrust map was "
                f"calibrated over ({lo:.3f}–{hi:.3f} V, [calibration] "
                "thrust_vbat_range_v): thrust, tension and position are extrapolated "
                "(calibration_extrapolated in Estimate and status; told once)",
                "vbat_v",
            )

    def _estimate(self, front: Front, position: PositionEstimate | None) -> bytes | None:
        """The Estimate's JSON, or None (a non-finite field: dropped and counted)."""
        follow = self.follow_info()
        cached = self.follow_json_cache
        if cached is None or cached[0] is not follow:
            cached = self.follow_json_cache = (follow, follow.model_dump())
        base = self.base_cache
        if base is None or base[0] is not self.base_world_m:
            base = self.base_cache = (self.base_world_m, output.vec3(self.base_world_m))
        fields = output.estimate_fields(
            seq=front.msg.seq,
            stamp_s=front.msg.stamp_s,
            tension_world_n=front.tension_world_n,
            std_n=front.std_n,
            position=position,
            follow_json=cached[1],
            on_ground=front.on_ground,
            converged=front.converged,
            length_m=self.length_m,
            base_m=base[1],
            calibration=self.calibration_source,
            calibration_extrapolated=self.calibration_extrapolated,
        )
        try:
            payload = output.encode(fields)
        except ValueError as exc:  # a non-finite field the checks above did not cover
            self._drop("non_finite_estimate", str(exc))
            return None
        self.last_estimate_fields = fields
        return payload

    def follow_info(self) -> FollowInfo:
        """The Estimate's ``follow`` object (also the status's)."""
        fs = self.follow_state
        fp = self.follow_params
        # FollowInfo changes only when follow changes state: reuse it (it is frozen). The
        # params are compared by identity, so their floats are the very same objects.
        flags = (fs.enabled, fs.active, fs.landing_armed, fs.stopped, fs.reason)
        cached = self.follow_info_cache
        if cached is not None and cached[0] is fp and cached[1] == flags:
            return cached[2]
        follow = FollowInfo(
            enabled=fs.enabled,
            active=fs.active,
            threshold_n=fp.threshold_n,
            land_below_m=fp.land_below_m,
            landing_armed=fs.landing_armed,
            stopped=fs.stopped,
            reason=fs.reason,
        )
        self.follow_info_cache = (fp, flags, follow)
        return follow

    # ---------------------------------------------------------------- health

    def status(self, now_s: float, drops: dict[str, int]) -> dict[str, Any]:
        """Health of the drone as a JSON-ready dict (``tether/{drone}/status``)."""
        last_seen_s = self.gate.last_seen_s
        return {
            "drone": self.drone,
            "stale": self.gate.stale,
            "telemetry_hz": self.telemetry_rate.hz(now_s),
            "estimate_hz": self.estimate_rate.hz(now_s),
            "last_seen_age_s": None if last_seen_s is None else max(0.0, now_s - last_seen_s),
            "received": self.received,
            "accepted": self.accepted,
            "estimates": self.estimates,
            "setpoints": self.setpoints,
            "stops": self.stops,
            "seq_gaps": self.seq_gaps,
            "drops": drops,
            "invalid": sum(v for k, v in drops.items() if k != "queue_overflow"),
            "queue_overflow": drops.get("queue_overflow", 0),
            "filter": {
                "initialized": self.filter.initialized,
                "change_detections": self.change_detections,
                **_noise_status(self.filter),
            },
            "follow": self.follow_info().model_dump(),
            "contact": {"on_ground": self.contact.on_ground, "reason": self.contact.reason},
            "length_m": self.length_m,
            "length_source": self.length_source,
            "base_m": list(map(float, self.base_world_m)),
            "weight_n_per_m": self.weight_n_per_m,
            "calibration": self.calibration_source,
            "calibration_extrapolated": self.calibration_extrapolated,
            "calibration_vbat_range_v": (
                None if self.vbat_range_v is None else list(self.vbat_range_v)
            ),
            "vbat_v": self.last_vbat_v,
            "rest_calibration": self._rest_status(),
            "attitude": self._attitude_status(),
        }

    def _attitude_status(self) -> dict[str, Any] | None:
        """The attitude served and calibrated, and the model they chose (None: no message)."""
        if self.attitude_served is None:
            return None
        return {
            "source": self.attitude_served,
            "calibrated": self.attitude_calibrated,
            "model": "hover" if self.slow_active else "accelerometer",
        }

    def _rest_status(self) -> dict[str, Any] | None:
        """The rest calibration: off (None), or the offset in force (or none yet); with
        ``[calibration] rest_required``, whether the drone armed without one."""
        rest = self.rest
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
        if self.params.calibration.rest_required:
            out["required"] = True
            out["missing_at_arming"] = self.rest_missing
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
