"""The accelerometer's bias as a Kalman state beside the velocity it integrates.

Pure physics: Python floats per message, numpy at each block's covariance step; time enters
as ``dt_s``.

Why (docs/estimator_design.md, *The bias as a state*). The tension observation
(``eq:NE_tether``) reads the accelerometer's error ``b`` as ``m·R·b`` of tension. A rest
on the floor measures ``b`` at this power-on; in the air it moves (the airframe warms, the
propellers shake the sensor, and an external attitude's rigid body is not the IMU's frame
to the degree): on the NanoBench flights by 0.02–0.2 m/s² from the rest before, 0.6–6 mN
at 30 g. What observes it in the air is the velocity the corrected accelerometer integrates
to: a drone on a tether, or one flying a lab's trajectories, does not run away, so its
velocity stays within a scatter σ_V that decorrelates over T_V; with motion capture its
position is observed outright. So, as PX4's EKF2 does with its IMU biases::

    x = (p, v, b)      p, v world (p only while motion capture is in use), b body
    p' = v,   v' = R·(f − b) − g·e3 + w_a,   b' = w_b          # the accelerometer drives
    v = 0 observed with variance σ_V²·T_V/T over a block of T  # no motion capture
    p = p_mocap observed with variance σ_p²                    # motion capture

The accelerometer enters as the control input: the nominal p and v are integrated with it
per message, exactly, by the caller (``slow_accel``, which integrates the same corrected
acceleration for its other velocities); the covariance and the update run once per block
of :data:`BLOCK_S` (:func:`block_update`), with the block's Jacobians ``∂v/∂b = −R·T`` and
``∂p/∂b = −R·T²/2`` at the block's last attitude (the attitude moves by at most ω·T within a
block, 0.1 rad at 1 rad/s: it shifts the gain by that fraction, not the nominal state). For
a constant attitude this is the exact Kalman filter of the model observed once per block
(tests/test_bias_kalman.py: equal to filterpy's). ``w_a`` is the accelerometer's noise as a
density, measured on line (the tension filter's long-run variance over m², times the mean
spacing); ``w_b`` the bias's own walk (:data:`BIAS_WALK_MPS2_PER_SQRT_S`, physical).

At rest (disarmed and still: the rest detector's window) ``v = 0`` and ``b`` is the
window's mean, exactly; the first air sample after a rest adds the flight offset's prior
σ_δ² to ``b``'s variance (how far the bias in the air strays from the rest's, fitted by
``calibrate`` from its recordings). Without a rest at this power-on ``b`` starts at 0 with
:data:`BIAS_PRIOR_STD_MPS2`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from groundstation.tension import GAP_S
from groundstation.tension_noise import NoiseEstimate

__all__ = [
    "BIAS_PRIOR_STD_MPS2",
    "BIAS_WALK_MPS2_PER_SQRT_S",
    "BLOCK_S",
    "MOCAP_HOLD_S",
    "BiasKalman",
    "BiasKalmanParams",
    "Kind",
    "at_rest",
    "block_update",
    "hold",
    "take_off",
]

Vec3 = tuple[float, float, float]
Rows = tuple[Vec3, Vec3, Vec3]
_ZERO3: Vec3 = (0.0, 0.0, 0.0)

BLOCK_S = NoiseEstimate.BLOCK_S
"""The covariance is propagated and the state observed once per this much flight, s: the
noise estimate's block (0.25 s), the estimator's one block length for its slow per-block
work (it was 0.1 s of its own). A block is long beside the IMU's period (4–10 ms), so the
per-message cost is the nominal integration and two sums, and short beside the bias's time
to be learnt (seconds); against T_V (0.64–1.4 s fitted on NanoBench) the observation
``v = 0`` is weighed per block by ``σ_V²·T_V/T``, the same information per second at any T.
Numerical, not a model value: the block's update is the exact one of the model observed
once per block. 0.1 → 0.25 s moved no figure of ``python -m benchmarks.sensitivity
--variant bias_kalman.BLOCK_S=2.5`` by more than 1 % (at a977029); the realistic page's
follow flights with motion capture moved by at most 0.3 % (docs/realistic_benchmark.md, 337e450 →
35dd67e)."""

MOCAP_HOLD_S = GAP_S
"""Motion capture stays in use for this long (telemetry stamp) after the frame that brought
it, s: the estimator's external position (``estimator.drone``) and this filter's position
alike. It is the one definition of a broken stream, ``tension.GAP_S`` (0.25 s; it was a
hand-set 0.3 s of its own): a motion-capture stream silent for longer is lost as a
telemetry stream is. Real motion capture reaches a drone's telemetry at 70-116 Hz against
the IMU's 100 Hz, in bursts, with gaps up to 150 ms (the realistic profile draws the same):
without the hold, follow would switch to the tether-based position on every telemetry
message without a fresh frame."""

BIAS_PRIOR_STD_MPS2 = 0.2
"""σ of the bias when no rest was seen at this power-on (started in flight), m/s²:
physical, the zero-g offset of the Crazyflie's IMU (BMI088: ±20 mg typical)."""

BIAS_WALK_MPS2_PER_SQRT_S = 1.2e-3
"""The bias's random walk in the air, (m/s²)/√s: physical, derived from the IMU's offset
temperature drift (BMI088: ±0.2 mg/K) over an airframe that warms by ~15 K in ten
minutes of flight: (0.2e-3·9.81·15)² / 600 s ≈ (1.2e-3)² (m/s²)²/s."""


@dataclass(frozen=True, slots=True)
class BiasKalmanParams:
    """The flight's model (config ``[calibration]``, fitted by ``calibrate``).

    Attributes:
        velocity_std_mps: σ_V, the scatter of the drone's velocity about zero in the air,
            per world axis, m/s.
        velocity_time_s: T_V, its correlation time, s (``v = 0`` is observed with variance
            ``σ_V²·T_V/T`` per block of T: one independent look per T_V).
        flight_bias_std_mps2: σ_δ, how far the bias in the air strays from the rest's
            before it, per body axis, m/s².
        mocap_std_m: σ_p, the motion-capture position's noise per axis, m.
    """

    velocity_std_mps: float = 0.13
    velocity_time_s: float = 1.4
    flight_bias_std_mps2: float = 0.05
    mocap_std_m: float = 0.002

    def __post_init__(self) -> None:
        for name in (
            "velocity_std_mps",
            "velocity_time_s",
            "flight_bias_std_mps2",
            "mocap_std_m",
        ):
            value = getattr(self, name)
            if not (value > 0.0 and math.isfinite(value)):
                raise ValueError(f"BiasKalmanParams.{name} must be finite and > 0, got {value!r}")


@dataclass(frozen=True, slots=True)
class BiasKalman:
    """One drone's bias filter between blocks (immutable; the functions below return the
    next). The nominal p and v are the caller's (module doc).

    Attributes:
        bias_body_mps2: b, m/s².
        cov: the 9×9 covariance of (p, v, b) in the air (p's rows zero while p is unused);
            None on the ground.
        bias_var_mps4: b's variance per axis on the ground (cov None), (m/s²)².
        flight_prior: the flight offset's prior was added since the last rest.
    """

    bias_body_mps2: Vec3 = _ZERO3
    cov: NDArray[np.float64] | None = None
    bias_var_mps4: float = BIAS_PRIOR_STD_MPS2 * BIAS_PRIOR_STD_MPS2
    flight_prior: bool = False

    @property
    def grounded(self) -> bool:
        """On the ground: v = 0, no p, b's variance alone (no covariance)."""
        return self.cov is None


def _grounded(state: BiasKalman, flight_prior: bool) -> BiasKalman:
    """v = 0 and no position (the floor holds the drone); b kept with its variance (the
    mean of the three axes': the covariance's cross terms are dropped on the ground)."""
    cov = state.cov
    var = state.bias_var_mps4 if cov is None else float(cov[6, 6] + cov[7, 7] + cov[8, 8]) / 3.0
    return BiasKalman(
        bias_body_mps2=state.bias_body_mps2, bias_var_mps4=var, flight_prior=flight_prior
    )


def at_rest(state: BiasKalman, rest_mean_body_mps2: Vec3 | None) -> BiasKalman:
    """On the floor, disarmed and still: v = 0, and b the rest window's mean once it has
    lasted (None: b kept), taken as exact (its window's standard error, ~1 mm/s² over a
    second of a still IMU, is far below σ_δ). The next take-off adds the flight's offset
    prior again."""
    if rest_mean_body_mps2 is None:
        if state.grounded and not state.flight_prior:
            return state
        return _grounded(state, flight_prior=False)
    if (
        state.grounded
        and not state.flight_prior
        and state.bias_var_mps4 == 0.0
        and state.bias_body_mps2 == rest_mean_body_mps2
    ):
        return state
    return BiasKalman(bias_body_mps2=rest_mean_body_mps2, bias_var_mps4=0.0)


def hold(state: BiasKalman) -> BiasKalman:
    """Spool-up, landing, armed on the floor: b kept, v = 0 (the floor holds the drone)."""
    return state if state.grounded else _grounded(state, flight_prior=state.flight_prior)


def take_off(state: BiasKalman, params: BiasKalmanParams, *, from_ground: bool) -> BiasKalman:
    """The first air sample since a rest: b's variance grows by σ_δ² (the bias in the air
    strays from the rest's by that much). ``from_ground``: the drone left the floor (v = 0
    exactly there); otherwise it was found flying (a service started mid-flight): v's
    variance is the flight's scatter σ_V²."""
    if state.cov is None:
        cov = np.zeros((9, 9))
        var = state.bias_var_mps4
    else:
        cov = state.cov.copy()
        var = 0.0
    cov[6:, 6:] += np.eye(3) * (var + params.flight_bias_std_mps2**2)
    if not from_ground:
        cov[3:6, 3:6] += np.eye(3) * params.velocity_std_mps**2
    return BiasKalman(
        bias_body_mps2=state.bias_body_mps2,
        cov=cov,
        flight_prior=True,
    )


Kind = Literal["bound", "position", "start"]
"""A block's end: ``bound`` observes v = 0 (no motion capture), ``position`` the frame's p;
``start`` observes nothing and starts p at the frame (motion capture (back) in use)."""


def block_update(
    state: BiasKalman,
    params: BiasKalmanParams,
    kind: Kind,
    *,
    block_s: float,
    R_world_body: Rows,
    velocity_world_mps: Vec3,
    position_world_m: Vec3 | None,
    mocap_world_m: Vec3 | None,
    accel_density_m2ps3: float,
) -> tuple[BiasKalman, Vec3, Vec3 | None]:
    """A block's covariance step and its observation (module doc).

    Args:
        state: the filter at the block's start (after :func:`take_off`).
        params: the flight's model.
        kind: what the block's end observes (:data:`Kind`).
        block_s: the block's length T, s.
        R_world_body: the attitude at the block's end, as rows.
        velocity_world_mps: the nominal v at the block's end (integrated with b), m/s.
        position_world_m: the nominal p there (``position``), m; else unused.
        mocap_world_m: the frame (``position``, ``start``), m.
        accel_density_m2ps3: the accelerometer's noise as a density, (m/s²)²·s.

    Returns:
        ``(filter, v, p)`` after the observation (p None for ``bound``).
    """
    T = block_s
    eye = np.eye(3)
    q_a = accel_density_m2ps3 if accel_density_m2ps3 > 0.0 else 0.0
    q_b = BIAS_WALK_MPS2_PER_SQRT_S * BIAS_WALK_MPS2_PER_SQRT_S
    old = state.cov
    if old is None:  # no take_off (a caller's slip): b's variance from the ground
        old = np.zeros((9, 9))
        old[6:, 6:] = eye * state.bias_var_mps4
    rot = np.array(R_world_body)
    phi = np.eye(9)
    phi[3:6, 6:] = -T * rot
    q = np.zeros((9, 9))
    q[3:6, 3:6] = eye * (q_a * T)
    q[6:, 6:] = eye * (q_b * T)
    if kind == "position":
        phi[:3, 3:6] = T * eye
        phi[:3, 6:] = -0.5 * T * T * rot
        q[:3, :3] = eye * (q_a * T**3 / 3.0)
        q[:3, 3:6] = q[3:6, :3] = eye * (q_a * T * T / 2.0)
    cov = phi @ old @ phi.T + q
    p = position_world_m if kind == "position" else None
    x = np.array([*(p if p is not None else _ZERO3), *velocity_world_mps, *state.bias_body_mps2])
    if kind == "position":
        assert mocap_world_m is not None
        gain = np.linalg.solve(cov[:3, :3] + eye * params.mocap_std_m**2, cov[:3, :]).T
        x = x + gain @ (np.array(mocap_world_m) - x[:3])
        cov = cov - gain @ cov[:3, :]
        p = (float(x[0]), float(x[1]), float(x[2]))
    else:
        if kind == "bound":
            # v = 0, one independent look per T_V: variance σ_V²·T_V/T.
            r = params.velocity_std_mps**2 * params.velocity_time_s / T
            gain = np.linalg.solve(cov[3:6, 3:6] + eye * r, cov[3:6, :]).T
            x = x - gain @ x[3:6]
            cov = cov - gain @ cov[3:6, :]
        cov[:3, :] = 0.0
        cov[:, :3] = 0.0
        if kind == "start":
            assert mocap_world_m is not None
            cov[:3, :3] = eye * params.mocap_std_m**2
            p = mocap_world_m
    nxt = BiasKalman(
        bias_body_mps2=(float(x[6]), float(x[7]), float(x[8])),
        cov=0.5 * (cov + cov.T),
        flight_prior=state.flight_prior,
    )
    return nxt, (float(x[3]), float(x[4]), float(x[5])), p
