"""The accelerometer's slow content, replaced by what transfers (docs/estimator_design.md).

Pure physics: Python floats only; time enters as ``dt_s``.

Why. The tension observation (``eq:NE_tether``) ``T = m·R·f − R·u·F`` uses the IMU's specific
force ``f``. An accelerometer reads ``f + b`` with ``b`` a bias (and scale/misalignment) that
changes at every power-on: 0.1–0.35 m/s² on Crazyflies, i.e. 3–10 mN of tension on a 30 g
drone, which a tether of ω = 0.05 N/m turns into 6–20 cm of ``s2`` (NOTES "Sensitivity"). A
calibration cannot carry it from one power-on to the next; the drone's kinematics can:
a tethered (or any) drone's velocity is bounded, so over a long window its mean acceleration
is zero (or what motion capture says it is). So the observation is complementary::

    T = m·R·(f − β) − R·u·F + R·D·Rᵀ·v           # eq:NE_tether with the slow part corrected
    β ← β + (dt/τ)·((f − Rᵀ·(g·e3 + a_ref)) − β)   # body frame, first-order low-pass

``β`` is the accelerometer's slow error in the body frame (a body-fixed bias stays put when
the drone yaws); ``a_ref`` is the acceleration that the drone's kinematics vouch for: zero
without motion capture, the motion-capture acceleration (low-passed) with it. Above the
crossover ``1/(2π·τ)`` the accelerometer carries everything (tugs, manoeuvres); below it the
slow content rests on thrust, attitude and the thrust axis (the hover model
``m·g·e3 − R·u·F``) plus ``a_ref``. At rest on the floor (disarmed, still) ``a_ref = 0`` is
exact and ``β`` is learnt quickly: that is this power-on's bias, measured at this power-on,
carried nowhere else.

What it cannot remove: where the drone's attitude estimator levels itself on the same
accelerometer (the Crazyflie's do), an x/y bias tilts the reported attitude by ``b/g``; the
observation is then off by about ``m·b`` horizontally in the full model and in the hover
model alike (the two errors are the same to first order), and neither a rest phase nor the
kinematics can tell it from the floor's tilt. docs/estimator_design.md has the argument.

Rotor drag (PX4's EKF2 fuses the same term): a multirotor in translation feels
``F_drag = −R·D·Rᵀ·v`` with ``D = diag(D_xy, D_xy, 0)`` in the body frame (momentum drag of
the rotors), which the observation would report as tension unless added back. ``v`` is the
motion-capture velocity when there is one, else the accelerometer's high-passed velocity
(a leaky integral of ``R·(f − β) − g·e3`` with time constant ``τ_v``): it recovers
manoeuvres of a few seconds and forgets drift. See :func:`drag_velocity_world_mps`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from groundstation.attitude import GRAVITY_MPS2
from groundstation.frozen import evolve

__all__ = [
    "MOCAP_HOLD_S",
    "SlowAccelParams",
    "SlowAccelState",
    "correct_accel_body_mps2",
    "drag_velocity_world_mps",
    "end_hover",
    "slow_accel_step",
]

Vec3 = tuple[float, float, float]
_ZERO3: Vec3 = (0.0, 0.0, 0.0)
HOVER_MEAN_S = 1.0
"""The hover test's mean acceleration window, s."""
HOVER_SPEED_LEAK_S = 2.0
"""Without motion capture the hover test's speed is the corrected acceleration's leaky
integral with this time constant, s (twice ``HOVER_MEAN_S``: it forgets the integral's
drift, keeps a manoeuvre of a second or two)."""
VIBRATION_MEAN_S = 2.0
"""Memory of the vibration variance around the 1 s mean that scales the hover test's
thresholds (``SlowAccelParams.quasi_static_sigmas``), s."""
MOCAP_HOLD_S = 0.3
"""Motion capture stays in use for this long (telemetry stamp) after the frame that brought
it, s: the estimator's external position (``estimator.drone``) and the slow stage's
differences of positions alike (one value). Real motion capture reaches a drone's telemetry
at 70-116 Hz against the IMU's 100 Hz, in bursts, with gaps up to 150 ms (the realistic
profile draws the same): without the hold, follow would switch to the tether-based position
on every telemetry message without a fresh frame."""
Phase = Literal["rest", "air", "hold"]
"""``rest``: on the floor, disarmed and still (a_ref = 0 exactly); ``air``: flying (the
filter observes); ``hold``: anything else (spool-up, landing, armed on the floor): β kept."""


@dataclass(frozen=True, slots=True)
class SlowAccelParams:
    """Settings (config ``[filter]``: ``accel_slow_time_constant_s`` …).

    Attributes:
        time_constant_s: τ, the crossover in the air, s (> 0; ``inf``: the accelerometer's
            mean is trusted, β only from rest). Longer: less of a sustained manoeuvre leaks
            into β (error ≤ m·Δv/τ), slower to learn a bias never seen at rest.
        velocity_time_constant_s: τ_v of the accelerometer's leaky velocity (drag without
            motion capture), s.
        mocap_time_constant_s: low-pass of the motion-capture velocity (finite
            differences of positions) that the drag term uses, s.
        hover: run the hover test (False: never quasi-static, the tension filter then
            observes the accelerometer model alone; config ``[filter]
            accel_hover_crossover_s = 0``).
        quasi_static_accel_mps2: quasi-static while the accelerometer's 1 s mean
            acceleration (bias removed) stays below this, m/s² ...
        quasi_static_speed_mps: ... and the drag's velocity below this, m/s.
        quasi_static_sigmas: the hover test's thresholds follow the vibration too: the 1 s
            mean's is ``max(quasi_static_accel_mps2, quasi_static_sigmas·σ₁)``, σ₁ its
            standard deviation from the vibration measured around it; the speed's (the
            accelerometer's leaky integral, not motion capture's) likewise with that
            integral's σ (0, the default: the fixed thresholds alone; config ``[filter]
            accel_hover_noise_sigmas``). At 2 m/s² of vibration (100 Hz) σ₁
            ≈ 0.15 m/s² and the speed's σ ≈ 0.2 m/s per axis: fixed 0.2 and 0.3 are met a
            fraction of the time and the hover test switches on and off.
        quasi_static_exit_ratio: hysteresis: in the hover, it ends only when the 1 s mean
            or the speed exceeds this many times its threshold for starting one (1, the
            default: none; ``[filter] accel_hover_exit_ratio``). Without it a noise-aware
            test flickers on its own noise near the threshold (5–6 switches/s at 1–2 m/s²).
    """

    time_constant_s: float = 60.0
    velocity_time_constant_s: float = 8.0
    mocap_time_constant_s: float = 0.15
    hover: bool = True
    quasi_static_accel_mps2: float = 0.2
    quasi_static_speed_mps: float = 0.3
    quasi_static_sigmas: float = 0.0
    quasi_static_exit_ratio: float = 1.0

    def __post_init__(self) -> None:
        sigmas = self.quasi_static_sigmas
        if not (sigmas >= 0.0 and math.isfinite(sigmas)):
            raise ValueError(
                f"SlowAccelParams.quasi_static_sigmas must be finite and >= 0, got {sigmas!r}"
            )
        if not (
            self.quasi_static_exit_ratio >= 1.0 and math.isfinite(self.quasi_static_exit_ratio)
        ):
            raise ValueError(
                "SlowAccelParams.quasi_static_exit_ratio must be finite and >= 1, got "
                f"{self.quasi_static_exit_ratio!r}"
            )
        for name in (
            "quasi_static_accel_mps2",
            "quasi_static_speed_mps",
            "time_constant_s",
            "velocity_time_constant_s",
            "mocap_time_constant_s",
        ):
            value = getattr(self, name)
            if not (value > 0.0):  # inf allowed, NaN refused
                raise ValueError(f"SlowAccelParams.{name} must be > 0, got {value!r}")


@dataclass(frozen=True)  # no slots: stepped with frozen.evolve
class SlowAccelState:
    """One drone's slow-accelerometer state (immutable; :func:`slow_accel_step` returns the
    next).

    Attributes:
        bias_body_mps2: β, the accelerometer's slow error, body frame, m/s².
        air_samples: samples in the air since β was last set at rest (the running mean's
            count when no rest was seen).
        learnt_at_rest: β was set at rest at this power-on.
        velocity_world_mps: the drag's velocity, world frame, m/s (zero on the ground).
        velocity_source: where it comes from now.
        mocap_stamp_s / mocap_world_m: the last motion-capture sample (None: none yet).
        mocap_velocity_world_mps: the low-passed first difference (the drag's velocity).
        mocap_raw_velocity_world_mps / mocap_accel_world_mps2: the raw first and second
            differences (a_ref).
        mocap_samples: consecutive motion-capture samples (the differences need 3).
        accel_1s_body_mps2: the 1 s mean of ``f − β − Rᵀ·g·e3``, body frame, m/s².
        vibration_var_mps4: the variance per axis of ``f − β − Rᵀ·g·e3`` around its 1 s
            mean (the vibration), (m/s²)², a 2 s mean.
        quasi_static: the drone hovers (both below their thresholds).
        regime_velocity_world_mps: the velocity the hover test uses: motion capture's, or a
            leaky integral with a 2 s leak (a bias not yet learnt drifts it 2 s × less than
            the drag's 8 s one), world frame, m/s.
        hover_hold_s: time left before a hover may begin again after a change of the
            tension ended one (:func:`end_hover`), s.
    """

    bias_body_mps2: Vec3 = _ZERO3
    air_samples: int = 0
    learnt_at_rest: bool = False
    velocity_world_mps: Vec3 = _ZERO3
    velocity_source: Literal["none", "accel", "mocap"] = "none"
    mocap_stamp_s: float | None = None
    mocap_world_m: Vec3 | None = None
    mocap_velocity_world_mps: Vec3 = _ZERO3
    mocap_raw_velocity_world_mps: Vec3 = _ZERO3
    mocap_accel_world_mps2: Vec3 = _ZERO3
    mocap_samples: int = 0
    accel_1s_body_mps2: Vec3 = _ZERO3
    vibration_var_mps4: float = 0.0
    quasi_static: bool = False
    regime_velocity_world_mps: Vec3 = _ZERO3
    hover_hold_s: float = 0.0


def end_hover(state: SlowAccelState) -> SlowAccelState:
    """The tension changed under a hover (a tug found on the accelerometer model): the hover
    ends at once (the tension filter drops the drone's velocity state), and no hover begins
    before the 1 s mean holds only samples after the change (``HOVER_MEAN_S``):
    until then it cannot vouch that the controller has answered the new tension."""
    return evolve(state, quasi_static=False, hover_hold_s=HOVER_MEAN_S)


def correct_accel_body_mps2(state: SlowAccelState, accel_body_mps2: Vec3) -> Vec3:
    """``f − β``: the reading with its slow error removed, body frame, m/s²."""
    bx, by, bz = state.bias_body_mps2
    return (
        accel_body_mps2[0] - bx,
        accel_body_mps2[1] - by,
        accel_body_mps2[2] - bz,
    )


def drag_velocity_world_mps(state: SlowAccelState) -> Vec3 | None:
    """The velocity the rotor-drag term uses (None on the ground: no drag there)."""
    return None if state.velocity_source == "none" else state.velocity_world_mps


def _mocap_step(
    state: SlowAccelState, params: SlowAccelParams, stamp_s: float, mocap_world_m: Vec3 | None
) -> SlowAccelState:
    """Low-passed first and second differences of the motion-capture position."""
    if mocap_world_m is None:
        if state.mocap_stamp_s is not None and stamp_s - state.mocap_stamp_s > MOCAP_HOLD_S:
            return evolve(state, mocap_stamp_s=None, mocap_world_m=None, mocap_samples=0)
        return state
    prev, prev_t = state.mocap_world_m, state.mocap_stamp_s
    if prev is None or prev_t is None:
        return evolve(state, mocap_stamp_s=stamp_s, mocap_world_m=mocap_world_m, mocap_samples=1)
    dt = stamp_s - prev_t
    if not (0.0 < dt <= MOCAP_HOLD_S):
        return evolve(state, mocap_stamp_s=stamp_s, mocap_world_m=mocap_world_m, mocap_samples=1)
    k = min(dt / params.mocap_time_constant_s, 1.0)  # first-order low-pass gain
    v_old = state.mocap_velocity_world_mps
    raw_v = tuple((mocap_world_m[i] - prev[i]) / dt for i in range(3))
    v_new: tuple[float, ...]
    a_new: tuple[float, ...]
    if state.mocap_samples < 2:
        v_new, a_new = raw_v, _ZERO3
    else:
        # The drag's velocity is low-passed (it multiplies D directly); the acceleration is
        # the raw second difference: β low-passes it over τ, where a second difference's
        # noise telescopes (its mean over a window is Δv/window), and a low-pass here would
        # lag a turn's rotating acceleration into β.
        v_raw_old = state.mocap_raw_velocity_world_mps
        v_new = tuple(v_old[i] + k * (raw_v[i] - v_old[i]) for i in range(3))
        a_new = tuple((raw_v[i] - v_raw_old[i]) / dt for i in range(3))
    return evolve(
        state,
        mocap_stamp_s=stamp_s,
        mocap_world_m=mocap_world_m,
        mocap_velocity_world_mps=(v_new[0], v_new[1], v_new[2]),
        mocap_raw_velocity_world_mps=(raw_v[0], raw_v[1], raw_v[2]),
        mocap_accel_world_mps2=(a_new[0], a_new[1], a_new[2]),
        mocap_samples=state.mocap_samples + 1,
    )


def slow_accel_step(
    state: SlowAccelState,
    params: SlowAccelParams,
    *,
    dt_s: float,
    stamp_s: float,
    accel_body_mps2: Vec3,
    R_world_body: tuple[Vec3, Vec3, Vec3],
    phase: Phase,
    mocap_world_m: Vec3 | None,
    rest_mean_body_mps2: Vec3 | None = None,
    gravity_mps2: float = GRAVITY_MPS2,
) -> SlowAccelState:
    """Learn β and the drag velocity from one sample (module doc for the equations).

    Args:
        state: the drone's state before the sample.
        params: settings.
        dt_s: time since the previous sample, s (0 at a restart: nothing integrates).
        stamp_s: the sample's time, s.
        accel_body_mps2: the specific force as read (after any configured bias), m/s².
        R_world_body: the attitude as rows of the rotation matrix.
        phase: rest / air / hold (see :data:`Phase`).
        mocap_world_m: the motion-capture position of this sample, m, or None.
        rest_mean_body_mps2: at rest, the still window's mean of ``f − Rᵀ·g·e3`` once it
            has lasted long enough (``calibration.RestCalibrator.rest_mean_body_mps2``, the
            one test of stillness), body frame, m/s²; None: β is kept.
        gravity_mps2: g, m/s².

    Returns:
        The next state.
    """
    st = _mocap_step(state, params, stamp_s, mocap_world_m)
    mocap_ok = st.mocap_samples >= 3 and mocap_world_m is not None
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R_world_body
    if phase == "hold":
        return evolve(
            st,
            velocity_world_mps=_ZERO3,
            velocity_source="none",
            accel_1s_body_mps2=_ZERO3,
            quasi_static=False,
            regime_velocity_world_mps=_ZERO3,
            hover_hold_s=0.0,
        )
    if phase == "rest":
        # Still on the floor: a_ref = 0 exactly, and the rest detector's window mean of
        # f − Rᵀ·g·e3 is this power-on's bias (a new rest, a new window: the drone may have
        # been moved between flights; a brief disarm is no measurement).
        bias = st.bias_body_mps2
        learnt_at_rest = st.learnt_at_rest
        if rest_mean_body_mps2 is not None:
            bias, learnt_at_rest = rest_mean_body_mps2, True
        return evolve(
            st,
            bias_body_mps2=bias,
            air_samples=0,
            learnt_at_rest=learnt_at_rest,
            velocity_world_mps=_ZERO3,
            velocity_source="none",
            accel_1s_body_mps2=_ZERO3,
            quasi_static=False,
            regime_velocity_world_mps=_ZERO3,
            hover_hold_s=0.0,
        )
    n = st.air_samples + 1
    if mocap_ok:
        ax, ay, az = st.mocap_accel_world_mps2
        ref = (ax, ay, gravity_mps2 + az)
    else:
        ref = (0.0, 0.0, gravity_mps2)
    if st.learnt_at_rest:
        gain = min(dt_s / params.time_constant_s, 1.0)
    else:
        # Never seen at rest (started in flight): the running mean until τ's worth.
        gain = max(1.0 / n, min(dt_s / params.time_constant_s, 1.0))
    # e = f − Rᵀ·(g·e3 + a_ref), body frame: what the accelerometer reads beyond the
    # kinematics it should read.
    rx, ry, rz = ref
    ex = accel_body_mps2[0] - (r00 * rx + r10 * ry + r20 * rz)
    ey = accel_body_mps2[1] - (r01 * rx + r11 * ry + r21 * rz)
    ez = accel_body_mps2[2] - (r02 * rx + r12 * ry + r22 * rz)
    bx, by, bz = st.bias_body_mps2
    bias = (bx + gain * (ex - bx), by + gain * (ey - by), bz + gain * (ez - bz))
    source: Literal["accel", "mocap"]
    if mocap_ok:
        velocity, source = st.mocap_velocity_world_mps, "mocap"
    else:
        # Leaky integral of the corrected world acceleration: v' = a − v/τ_v.
        fx, fy, fz = (
            accel_body_mps2[0] - bias[0],
            accel_body_mps2[1] - bias[1],
            accel_body_mps2[2] - bias[2],
        )
        awx = r00 * fx + r01 * fy + r02 * fz
        awy = r10 * fx + r11 * fy + r12 * fz
        awz = r20 * fx + r21 * fy + r22 * fz - gravity_mps2
        vx, vy, vz = st.velocity_world_mps if st.velocity_source != "none" else _ZERO3
        leak = math.exp(-dt_s / params.velocity_time_constant_s)
        velocity = (vx * leak + awx * dt_s, vy * leak + awy * dt_s, vz * leak + awz * dt_s)
        source = "accel"
    # The hover test. e = f − β − Rᵀ·g·e3 is the drone's acceleration plus vibration, body
    # frame. While the drone hovers (its 1 s mean acceleration and its velocity small) the
    # tension filter also takes the thrust balance through the drone's velocity
    # (tension_kalman.HoverVelocity); out of it the accelerometer model alone carries the
    # manoeuvre, whose sustained acceleration the thrust balance would miss.
    gx, gy, gz = r20 * gravity_mps2, r21 * gravity_mps2, r22 * gravity_mps2  # Rᵀ·g·e3
    ex = accel_body_mps2[0] - bias[0] - gx
    ey = accel_body_mps2[1] - bias[1] - gy
    ez = accel_body_mps2[2] - bias[2] - gz
    k1 = min(dt_s / HOVER_MEAN_S, 1.0)
    a1x, a1y, a1z = st.accel_1s_body_mps2
    a1 = (a1x + k1 * (ex - a1x), a1y + k1 * (ey - a1y), a1z + k1 * (ez - a1z))
    leak2 = 1.0
    if source == "mocap":
        rv = velocity
    else:
        # awx.. is this sample's corrected world acceleration (computed above).
        ox, oy, oz = st.regime_velocity_world_mps
        leak2 = math.exp(-dt_s / HOVER_SPEED_LEAK_S)
        rv = (ox * leak2 + awx * dt_s, oy * leak2 + awy * dt_s, oz * leak2 + awz * dt_s)
    vx, vy, vz = rv
    # The vibration around the 1 s mean (per axis): the mean's standard deviation is the
    # vibration's times sqrt(k / (2 − k)) for an exponential mean of gain k over white noise.
    dx, dy, dz = ex - a1[0], ey - a1[1], ez - a1[2]
    kv = min(dt_s / VIBRATION_MEAN_S, 1.0)
    var = st.vibration_var_mps4
    var += kv * ((dx * dx + dy * dy + dz * dz) / 3.0 - var)
    limit1 = params.quasi_static_accel_mps2**2
    limit_v = params.quasi_static_speed_mps**2
    sigmas2 = params.quasi_static_sigmas**2
    if sigmas2 > 0.0:
        # The 1 s mean's threshold: never below the fixed one, and at least
        # quasi_static_sigmas of its own standard deviation (σ₁² = var·k1/(2 − k1) per axis).
        limit1 = max(limit1, sigmas2 * var * k1 / (2.0 - k1))
        # The speed's likewise when it is the accelerometer's leaky integral (v ← leak·v +
        # e·dt: σ_v² = var·dt²/(1 − leak²) per axis), not motion capture's.
        if source == "accel" and leak2 < 1.0:
            limit_v = max(limit_v, sigmas2 * var * dt_s * dt_s / (1.0 - leak2 * leak2))
    if st.quasi_static:
        # In the hover, times the exit ratio (hysteresis: the noise around the threshold
        # does not switch it).
        ratio2 = params.quasi_static_exit_ratio**2
        limit1 *= ratio2
        limit_v *= ratio2
    hold = st.hover_hold_s
    if hold > 0.0:
        hold = hold - dt_s if hold > dt_s else 0.0
    quasi = (
        params.hover
        and hold == 0.0
        and a1[0] * a1[0] + a1[1] * a1[1] + a1[2] * a1[2] < limit1
        and vx * vx + vy * vy + vz * vz < limit_v
    )
    return evolve(
        st,
        bias_body_mps2=bias,
        air_samples=n,
        velocity_world_mps=velocity,
        velocity_source=source,
        accel_1s_body_mps2=a1,
        vibration_var_mps4=var,
        quasi_static=quasi,
        regime_velocity_world_mps=(rv[0], rv[1], rv[2]),
        hover_hold_s=hold,
    )
