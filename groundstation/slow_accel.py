"""The accelerometer's slow content, replaced by what transfers (docs/estimator_design.md).

Pure physics: Python floats per message (the bias filter's block step: numpy); time enters
as ``dt_s``.

Why. The tension observation (``eq:NE_tether``) ``T = m·R·f − R·u·F`` uses the IMU's specific
force ``f``. An accelerometer reads ``f + b`` with ``b`` a bias (and scale/misalignment) that
changes at every power-on: 0.1–0.35 m/s² on Crazyflies, i.e. 3–10 mN of tension on a 30 g
drone, which a tether of ω = 0.05 N/m turns into 6–20 cm of ``s2`` (NOTES "Sensitivity"). A
calibration cannot carry it from one power-on to the next; the drone's kinematics can:
a tethered (or any) drone's velocity is bounded (or what motion capture says it is). So the
observation is complementary::

    T = m·R·(f − β) − R·u·F + R·D·Rᵀ·v           # eq:NE_tether with the slow part corrected
    β = b of the (p, v, b) Kalman filter          # groundstation.bias_kalman

``β`` is the accelerometer's slow error in the body frame (a body-fixed bias stays put when
the drone yaws), a state of a Kalman filter beside the velocity it integrates to: ``v = 0``
observed with the flight's velocity scatter σ_V and correlation time T_V without motion
capture, the motion-capture position with it, both fitted by ``calibrate``. The data weigh
it: a bias learnt in seconds where the velocity stays small or motion capture sees it, in
minutes where the drone manoeuvres within a loose bound. At rest on the floor (disarmed,
still) ``v = 0`` is exact and ``β`` is the rest window's mean: this power-on's bias,
measured at this power-on, carried nowhere else; each take-off adds the prior σ_δ of how
far the bias in the air strays from it (fitted by ``calibrate`` too).

What it cannot remove: where the drone's attitude estimator levels itself on the same
accelerometer (the Crazyflie's do), an x/y bias tilts the reported attitude by ``b/g``; the
observation is then off by about ``m·b`` horizontally in the full model and in the hover
model alike (the two errors are the same to first order), and neither a rest phase nor the
kinematics can tell it from the floor's tilt. docs/estimator_design.md has the argument.

Rotor drag (PX4's EKF2 fuses the same term): a multirotor in translation feels
``F_drag = −R·D·Rᵀ·v`` with ``D = diag(D_xy, D_xy, 0)`` in the body frame (momentum drag of
the rotors), which the observation would report as tension unless added back. ``v`` is the
filter's (fused) velocity while motion capture is in use, else the accelerometer's
high-passed velocity (a leaky integral of ``R·(f − β) − g·e3`` with time constant ``τ_v``):
it recovers manoeuvres of a few seconds and forgets drift. See
:func:`drag_velocity_world_mps`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Literal, NamedTuple

from groundstation import bias_kalman as bk
from groundstation.attitude import GRAVITY_MPS2, STILL_WINDOW_S
from groundstation.bias_kalman import MOCAP_HOLD_S, BiasKalman, BiasKalmanParams
from groundstation.frozen import evolve
from groundstation.tension import TensionFilterParams

__all__ = [
    "MOCAP_HOLD_S",
    "HoverProcess",
    "SlowAccelParams",
    "SlowAccelState",
    "correct_accel_body_mps2",
    "drag_velocity_world_mps",
    "end_hover",
    "hover_process",
    "slow_accel_step",
]

Vec3 = tuple[float, float, float]
_ZERO3: Vec3 = (0.0, 0.0, 0.0)
HOVER_MEAN_S = STILL_WINDOW_S
"""The hover test's mean acceleration window, s: the one window of stillness
(:data:`groundstation.attitude.STILL_WINDOW_S`, the rest's too)."""
Phase = Literal["rest", "air", "hold"]
"""``rest``: on the floor, disarmed and still (v = 0 and b measured exactly); ``air``:
flying (the filter observes); ``hold``: anything else (spool-up, landing, armed on the
floor): b kept, v = 0."""


class HoverProcess(NamedTuple):
    """The hover's own velocity as the hover test allows for it, per world axis.

    The tension filter observes ``v = 0`` while the drone hovers, weighed by the velocity's
    scatter σ_v and correlation time T_c (``TensionFilterParams.hover_velocity_std_mps`` /
    ``hover_velocity_time_s``, fitted by ``calibrate``): a velocity process of variance σ_v²
    and correlation time T_c. The hover test asks whether the drone's motion is consistent
    with that process (and the measurement's noise), so these are the motion it must
    tolerate (:func:`hover_process`).

    Attributes:
        speed_var_m2ps2: σ_v², the speed's (an upper bound for the accelerometer's leaky
            speed, which high-passes it: σ_v²·τ/(τ + T_c)), (m/s)².
        accel_mean_var_m2ps4: the variance of the 1 s exponential mean of that velocity's
            derivative, ``σ_v² / (T·(T_c + T))`` with T = :data:`HOVER_MEAN_S`, (m/s²)²:
            the mean is ``(v − v̄)/T`` with v̄ the exponential mean of v, and for a velocity
            of correlation time T_c ``Var(v − v̄) = σ_v²·T/(T_c + T)``.
    """

    speed_var_m2ps2: float
    accel_mean_var_m2ps4: float


def hover_process(velocity_std_mps: float, velocity_time_s: float) -> HoverProcess:
    """:class:`HoverProcess` from σ_v (m/s) and T_c (s)."""
    var = velocity_std_mps * velocity_std_mps
    return HoverProcess(var, var / (HOVER_MEAN_S * (velocity_time_s + HOVER_MEAN_S)))


_DEFAULT_HOVER = hover_process(
    TensionFilterParams.hover_velocity_std_mps, TensionFilterParams.hover_velocity_time_s
)
"""The hover's velocity where nothing was fitted: the tension filter's default σ_v and T_c."""


@dataclass(frozen=True, slots=True)
class SlowAccelParams:
    """Settings (config ``[filter]`` for the hover test, ``[calibration]`` for the flight's
    model that ``calibrate`` fits).

    Attributes:
        flight: the (p, v, b) filter's model of the flight (:class:`~groundstation.
            bias_kalman.BiasKalmanParams`: the velocity's scatter and correlation time, the
            bias's offset in the air from the rest's, the motion capture's noise).
        velocity_time_constant_s: τ_v of the accelerometer's leaky velocity (the rotor
            drag's velocity without motion capture), s.
        hover: the hover test, and the hover's velocity it allows for
            (:class:`HoverProcess`; the default from the tension filter's default σ_v and
            T_c, ``TensionFilterParams.hover_velocity_std_mps`` / ``hover_velocity_time_s``);
            None: no hover test, never quasi-static (the tension
            filter then observes the accelerometer model alone; config ``[filter]
            accel_hover_crossover_s = 0``). The test's thresholds have no value of their
            own (:func:`slow_accel_step`).
    """

    flight: BiasKalmanParams = field(default_factory=BiasKalmanParams)
    velocity_time_constant_s: float = 8.0
    hover: HoverProcess | None = field(default_factory=lambda: _DEFAULT_HOVER)

    def __post_init__(self) -> None:
        value = self.velocity_time_constant_s
        if not (value > 0.0):  # inf allowed, NaN refused
            raise ValueError(f"SlowAccelParams.velocity_time_constant_s must be > 0, got {value!r}")
        if self.hover is not None and not all(v >= 0.0 and math.isfinite(v) for v in self.hover):
            raise ValueError(f"SlowAccelParams.hover must be finite and >= 0, got {self.hover!r}")


_NEW_KF = BiasKalman()


@dataclass(frozen=True)  # no slots: stepped with frozen.evolve
class SlowAccelState:
    """One drone's slow-accelerometer state (immutable; :func:`slow_accel_step` returns the
    next).

    Attributes:
        kf: the bias filter between its blocks (:mod:`groundstation.bias_kalman`).
        kf_velocity_world_mps: its nominal v, integrated per sample, m/s (zero on the
            ground).
        kf_position_world_m: its nominal p while motion capture is in use, m; None else.
        block_s: time integrated since its block began, s.
        since_mocap_s: time since the last motion-capture frame, s.
        learnt_at_rest: b was set at rest at this power-on.
        seen_ground: a rest or a hold was seen (a take-off starts at v = 0; a drone first
            seen flying has an unknown velocity).
        in_air: the drone flies (a drag velocity; none on the ground).
        drag_velocity_world_mps: the drag's velocity, world frame, m/s: the filter's while
            motion capture is in use, else the corrected acceleration's leaky integral
            (``velocity_time_constant_s``).
        accel_1s_body_mps2: the 1 s mean of ``f − β − Rᵀ·g·e3``, body frame, m/s².
        quasi_static: the drone hovers (both below their thresholds).
        regime_velocity_world_mps: the velocity the hover test uses: the filter's while
            motion capture is in use, else the corrected acceleration's leaky integral with
            the flight velocity's correlation time T_V as its leak
            (``BiasKalmanParams.velocity_time_s``), world frame, m/s.
        hover_hold_s: time left before a hover may begin again after a change of the
            tension ended one (:func:`end_hover`), s.
    """

    kf: BiasKalman = _NEW_KF
    kf_velocity_world_mps: Vec3 = _ZERO3
    kf_position_world_m: Vec3 | None = None
    block_s: float = 0.0
    since_mocap_s: float = math.inf
    learnt_at_rest: bool = False
    seen_ground: bool = False
    in_air: bool = False
    drag_velocity_world_mps: Vec3 = _ZERO3
    accel_1s_body_mps2: Vec3 = _ZERO3
    quasi_static: bool = False
    regime_velocity_world_mps: Vec3 = _ZERO3
    hover_hold_s: float = 0.0

    @property
    def bias_body_mps2(self) -> Vec3:
        """β, the accelerometer's slow error, body frame, m/s² (the filter's b)."""
        return self.kf.bias_body_mps2


_ON_THE_GROUND: Mapping[str, object] = MappingProxyType(
    {
        "seen_ground": True,
        "kf_velocity_world_mps": _ZERO3,
        "kf_position_world_m": None,
        "block_s": 0.0,
        "since_mocap_s": math.inf,
        "in_air": False,
        "accel_1s_body_mps2": _ZERO3,
        "quasi_static": False,
        "regime_velocity_world_mps": _ZERO3,
        "hover_hold_s": 0.0,
    }
)
"""What a sample on the floor (at rest or held) sets: the floor holds the drone, so every
velocity is zero and no hover, block or motion-capture position carries over to the air."""


def end_hover(state: SlowAccelState) -> SlowAccelState:
    """The tension changed under a hover (a tug found on the accelerometer model): the hover
    ends at once (the tension filter drops the drone's velocity state), and no hover begins
    before the 1 s mean holds only samples after the change (``HOVER_MEAN_S``):
    until then it cannot vouch that the controller has answered the new tension."""
    return evolve(state, quasi_static=False, hover_hold_s=HOVER_MEAN_S)


def correct_accel_body_mps2(state: SlowAccelState, accel_body_mps2: Vec3) -> Vec3:
    """``f − β``: the reading with its slow error removed, body frame, m/s²."""
    bx, by, bz = state.kf.bias_body_mps2
    return (
        accel_body_mps2[0] - bx,
        accel_body_mps2[1] - by,
        accel_body_mps2[2] - bz,
    )


def drag_velocity_world_mps(state: SlowAccelState) -> Vec3 | None:
    """The velocity the rotor-drag term uses (None on the ground: no drag there)."""
    return state.drag_velocity_world_mps if state.in_air else None


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
    accel_density_m2ps3: float | None = None,
    hover_chi2: float,
    gravity_mps2: float = GRAVITY_MPS2,
) -> SlowAccelState:
    """Learn β and the velocity from one sample, and run the hover test (module doc).

    Args:
        state: the drone's state before the sample.
        params: settings.
        dt_s: time since the previous sample, s (0 at a restart: nothing integrates).
        stamp_s: the sample's time, s (unused: the filter integrates ``dt_s``).
        accel_body_mps2: the specific force as read (after any configured bias), m/s².
        R_world_body: the attitude as rows of the rotation matrix.
        phase: rest / air / hold (see :data:`Phase`).
        mocap_world_m: the motion-capture position of this sample (a fresh frame), m, or
            None.
        rest_mean_body_mps2: at rest, the still window's mean of ``f − Rᵀ·g·e3`` once it
            has lasted long enough (``calibration.RestCalibrator.rest_mean_body_mps2``, the
            one test of stillness), body frame, m/s²; None: β is kept.
        accel_density_m2ps3: the accelerometer's noise as a density, (m/s²)²·s: its
            long-run variance per sample times the mean spacing (the service: the tension
            filter's measure over m², which sees the same vibration; one measure of it,
            colour included). The hover test allows for it, and it weighs the bias
            filter's block step. None (not yet measured): the hover test allows for the
            hover's own motion alone, and the block step waits for it.
        hover_chi2: the hover test's threshold on each of its two 3-D statistics (the 1 s
            mean acceleration and the speed, squared over their per-axis variance): the
            estimator's one false-alarm rate at the sample spacing
            (``TensionFilter.sample_chi2``, :func:`~groundstation.tension_change.
            exceedance_chi2`: 39.5 at 100 Hz); infinite: no test, no hover.
        gravity_mps2: g, m/s².

    Returns:
        The next state.
    """
    del stamp_s
    if phase == "hold":
        return evolve(state, kf=bk.hold(state.kf), **_ON_THE_GROUND)
    if phase == "rest":
        # Still on the floor: v = 0 exactly, and the rest detector's window mean of
        # f − Rᵀ·g·e3 is this power-on's bias (a new rest, a new window: the drone may have
        # been moved between flights; a brief disarm is no measurement).
        learnt = state.learnt_at_rest or rest_mean_body_mps2 is not None
        return evolve(
            state,
            kf=bk.at_rest(state.kf, rest_mean_body_mps2),
            learnt_at_rest=learnt,
            **_ON_THE_GROUND,
        )
    kf = state.kf
    if not kf.flight_prior:
        kf = bk.take_off(kf, params.flight, from_ground=state.seen_ground)
    dt = dt_s
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R_world_body
    bx, by, bz = kf.bias_body_mps2
    fx, fy, fz = accel_body_mps2[0] - bx, accel_body_mps2[1] - by, accel_body_mps2[2] - bz
    # The corrected world acceleration R·(f − β) − g·e3: the bias filter's nominal state is
    # integrated with it (groundstation.bias_kalman: exactly, per sample), and the leaky
    # velocities below.
    awx = r00 * fx + r01 * fy + r02 * fz
    awy = r10 * fx + r11 * fy + r12 * fz
    awz = r20 * fx + r21 * fy + r22 * fz - gravity_mps2
    vx, vy, vz = state.kf_velocity_world_mps
    p = state.kf_position_world_m
    since = state.since_mocap_s + dt
    if p is not None:
        if mocap_world_m is None and since > MOCAP_HOLD_S:
            p = None  # motion capture lost: the velocity's bound observes from here
        else:
            h = 0.5 * dt * dt
            p = (p[0] + vx * dt + awx * h, p[1] + vy * dt + awy * h, p[2] + vz * dt + awz * h)
    v = (vx + awx * dt, vy + awy * dt, vz + awz * dt)
    block = state.block_s + dt
    kind: bk.Kind | None = None
    if mocap_world_m is not None:
        since = 0.0
        if p is None:
            kind = "start"  # motion capture (back) in use: p starts at the frame
        elif block >= bk.BLOCK_S:
            kind = "position"
    elif p is None and block >= bk.BLOCK_S:
        kind = "bound"
    density = accel_density_m2ps3
    if kind is not None and density is not None:
        kf, v, p = bk.block_update(
            kf,
            params.flight,
            kind,
            block_s=block,
            R_world_body=R_world_body,
            velocity_world_mps=v,
            position_world_m=p,
            mocap_world_m=mocap_world_m,
            accel_density_m2ps3=density,
        )
        block = 0.0
        bx, by, bz = kf.bias_body_mps2
    # The hover test. e = f − β − Rᵀ·g·e3 is the drone's acceleration plus vibration, body
    # frame. While the drone hovers (its 1 s mean acceleration and its velocity small) the
    # tension filter also takes the thrust balance through the drone's velocity
    # (tension_kalman.HoverVelocity); out of it the accelerometer model alone carries the
    # manoeuvre, whose sustained acceleration the thrust balance would miss.
    ex = accel_body_mps2[0] - bx - r20 * gravity_mps2
    ey = accel_body_mps2[1] - by - r21 * gravity_mps2
    ez = accel_body_mps2[2] - bz - r22 * gravity_mps2
    k1 = min(dt_s / HOVER_MEAN_S, 1.0)
    a1x, a1y, a1z = state.accel_1s_body_mps2
    leak2 = 1.0
    if p is not None:
        # Motion capture's velocity, through the filter: the drag's and the hover test's.
        velocity = rv = v
    else:
        # The corrected world acceleration's leaky integrals: high passes that keep a
        # manoeuvre of a few seconds (the drag's, τ_v) or what the flight's own velocity
        # keeps (the hover test's, whose leak is that velocity's correlation time T_V,
        # fitted by calibrate with σ_V: a velocity held longer than the flights hold one is
        # the integral's drift, a bias error ε held at ε·T_V, not a manoeuvre). The
        # filter's own velocity is held near zero by its bound, a model of the flight's
        # low frequencies (which is what β needs), not a measure of a manoeuvre: as the
        # drag's velocity it read NanoBench worse with the onboard attitude, in a
        # development variant not kept (docs/estimator_design.md, *The bias as a state*);
        # so did the drag's leak at T_V (NanoBench's median 4.39 -> 9.47 mN).
        ux, uy, uz = state.drag_velocity_world_mps if state.in_air else _ZERO3
        leak = math.exp(-dt_s / params.velocity_time_constant_s)
        velocity = (ux * leak + awx * dt_s, uy * leak + awy * dt_s, uz * leak + awz * dt_s)
        ox, oy, oz = state.regime_velocity_world_mps
        leak2 = math.exp(-dt_s / params.flight.velocity_time_s)
        rv = (ox * leak2 + awx * dt_s, oy * leak2 + awy * dt_s, oz * leak2 + awz * dt_s)
    a1 = (a1x + k1 * (ex - a1x), a1y + k1 * (ey - a1y), a1z + k1 * (ez - a1z))
    # The thresholds: the drone hovers while its 1 s mean acceleration and its speed are
    # what the hover's own velocity (the process the tension filter's v = 0 models, σ_v and
    # T_c fitted by calibrate) and the measurement's noise give, judged by chi-square at the
    # estimator's one false-alarm rate: a hover ends by chance at most that often; no value
    # of the test's own. Per axis, independent parts in sum:
    # - the 1 s mean, an exponential mean of gain k1 = dt/T over a noise of long-run
    #   variance r = D/dt per sample (D the density, colour included): r·k1/(2 − k1) =
    #   D/((2 − k1)·T), T = HOVER_MEAN_S; and the hover velocity's derivative's mean;
    # - the speed: the hover velocity's σ_v²; and when it is the accelerometer's leaky
    #   integral (v ← leak·v + e·dt), not motion capture's, that integral's noise, r·dt²/(1 −
    #   leak²) = D·dt/(1 − leak²), and the bias's step since the rest (σ_δ, fitted), which
    #   the leak holds at σ_δ·τ.
    hover = params.hover
    quasi = False
    hold = state.hover_hold_s
    if hold > 0.0:
        hold = hold - dt_s if hold > dt_s else 0.0
    if hover is not None and hold == 0.0 and hover_chi2 < math.inf:
        var1 = hover.accel_mean_var_m2ps4
        var_v = hover.speed_var_m2ps2
        if density is not None:
            var1 += density / ((2.0 - k1) * HOVER_MEAN_S)
            if leak2 < 1.0:
                held = params.flight.flight_bias_std_mps2 * params.flight.velocity_time_s
                var_v += density * dt_s / (1.0 - leak2 * leak2) + held * held
        vx, vy, vz = rv
        quasi = (
            a1[0] * a1[0] + a1[1] * a1[1] + a1[2] * a1[2] < hover_chi2 * var1
            and vx * vx + vy * vy + vz * vz < hover_chi2 * var_v
        )
    return evolve(
        state,
        kf=kf,
        kf_velocity_world_mps=v,
        kf_position_world_m=p,
        block_s=block,
        since_mocap_s=since,
        in_air=True,
        drag_velocity_world_mps=velocity,
        accel_1s_body_mps2=a1,
        quasi_static=quasi,
        regime_velocity_world_mps=(rv[0], rv[1], rv[2]),
        hover_hold_s=hold,
    )
