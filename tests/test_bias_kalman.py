"""The accelerometer's bias as a Kalman state beside the velocity (groundstation.bias_kalman).

The block update is the exact Kalman filter of the linear model: tested equal to filterpy's
``KalmanFilter`` on the same transition, noise and observation. The rest: what the model
promises (a bias learnt from the velocity's bound or from motion capture, in every body axis
of a drone that yaws; the rest's bias exact; the flight's offset prior at take-off).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from scipy.spatial.transform import Rotation

from groundstation import bias_kalman as bk
from groundstation import slow_accel as slow_mod
from groundstation.attitude import GRAVITY_MPS2
from groundstation.tension import TensionFilterParams
from groundstation.tension_change import exceedance_chi2

G = GRAVITY_MPS2
DT = 0.004
HOVER_CHI2 = exceedance_chi2(TensionFilterParams().false_alarms_per_h, DT)  # the one knob's


def _rows(rot: Rotation) -> bk.Rows:
    m = rot.as_matrix()
    return (
        (float(m[0, 0]), float(m[0, 1]), float(m[0, 2])),
        (float(m[1, 0]), float(m[1, 1]), float(m[1, 2])),
        (float(m[2, 0]), float(m[2, 1]), float(m[2, 2])),
    )


def _reading(rot: Rotation, accel_world: np.ndarray, bias_body: np.ndarray) -> bk.Vec3:
    f = rot.inv().apply(accel_world + np.array([0.0, 0.0, G])) + bias_body
    return (float(f[0]), float(f[1]), float(f[2]))


@pytest.mark.parametrize("with_mocap", [False, True])
def test_block_update_equals_filterpy(with_mocap: bool) -> None:
    """The block's step on a constant attitude and reading (the nominal p and v integrated
    as the caller does, exactly) against filterpy's KalmanFilter on the model written out."""
    params = bk.BiasKalmanParams(velocity_std_mps=0.2, velocity_time_s=0.8, mocap_std_m=0.003)
    rot = Rotation.from_euler("xyz", [0.05, -0.03, 0.9])
    R = rot.as_matrix()
    density = 0.02
    state = bk.take_off(bk.at_rest(bk.BiasKalman(), (0.01, -0.02, 0.03)), params, from_ground=True)
    p0 = np.array([1.0, 0.5, 1.2])
    v0 = np.array([0.1, -0.05, 0.02])
    b0 = np.array(state.bias_body_mps2)
    assert state.cov is not None
    cov0 = state.cov.copy()
    if with_mocap:
        cov0[:3, :3] = np.eye(3) * 1e-4
        state = bk.BiasKalman(bias_body_mps2=state.bias_body_mps2, cov=cov0, flight_prior=True)
    f = np.array([0.2, -0.1, G + 0.05])
    T = 0.1
    a0 = R @ (f - b0) - np.array([0.0, 0.0, G])
    v_nom = v0 + a0 * T
    p_nom = p0 + v0 * T + 0.5 * a0 * T * T
    mocap = (1.01, 0.49, 1.21)
    kf, v, p = bk.block_update(
        state, params, "position" if with_mocap else "bound", block_s=T,
        R_world_body=_rows(rot), velocity_world_mps=tuple(v_nom),
        position_world_m=tuple(p_nom) if with_mocap else None,
        mocap_world_m=mocap if with_mocap else None, accel_density_m2ps3=density,
    )  # fmt: skip
    phi = np.eye(9)
    phi[3:6, 6:] = -R * T
    q = np.zeros((9, 9))
    q[3:6, 3:6] = np.eye(3) * density * T
    q[6:, 6:] = np.eye(3) * bk.BIAS_WALK_MPS2_PER_SQRT_S**2 * T
    if with_mocap:
        phi[:3, 3:6] = np.eye(3) * T
        phi[:3, 6:] = -R * T * T / 2.0
        q[:3, :3] = np.eye(3) * density * T**3 / 3.0
        q[:3, 3:6] = q[3:6, :3] = np.eye(3) * density * T * T / 2.0
    x0 = np.concatenate([p0 if with_mocap else np.zeros(3), v0, b0])
    nominal = np.concatenate([p_nom if with_mocap else np.zeros(3), v_nom, b0])
    ref = KalmanFilter(dim_x=9, dim_z=3)
    ref.x = x0.copy()
    ref.P = cov0.copy()
    ref.F = phi
    ref.Q = q
    ref.B = np.eye(9)
    ref.predict(u=nominal - phi @ x0)
    h = np.zeros((3, 9))
    if with_mocap:
        h[:, :3] = np.eye(3)
        ref.update(np.array(mocap), R=np.eye(3) * params.mocap_std_m**2, H=h)
    else:
        h[:, 3:6] = np.eye(3)
        r = params.velocity_std_mps**2 * params.velocity_time_s / T
        ref.update(np.zeros(3), R=np.eye(3) * r, H=h)
    lo = 0 if with_mocap else 3
    ours = np.concatenate([np.array(p) if p is not None else np.zeros(3), v, kf.bias_body_mps2])
    np.testing.assert_allclose(ours[lo:], ref.x[lo:], rtol=1e-9, atol=1e-12)
    assert kf.cov is not None
    np.testing.assert_allclose(kf.cov[lo:, lo:], ref.P[lo:, lo:], rtol=1e-9, atol=1e-15)
    assert (p is not None) == with_mocap


def _fly(
    seconds: float,
    bias_body: np.ndarray,
    *,
    noise_mps2: float = 0.8,
    mocap: bool = False,
    yaw_rate_rps: float = 0.0,
    circle_mps: float = 0.0,
    seed: int = 1,
    params: bk.BiasKalmanParams | None = None,
) -> slow_mod.SlowAccelState:
    """A drone at hover (or on a horizontal circle), its accelerometer biased in the body
    frame, the attitude exact; the slow stage (which integrates the bias filter's nominal
    state) from a rest that measured a zero bias."""
    rng = np.random.default_rng(seed)
    params = params or bk.BiasKalmanParams(flight_bias_std_mps2=0.3)
    slow = slow_mod.SlowAccelParams(flight=params)
    state = slow_mod.slow_accel_step(
        slow_mod.SlowAccelState(), slow, dt_s=0.0, stamp_s=0.0, accel_body_mps2=(0.0, 0.0, G),
        R_world_body=_rows(Rotation.identity()), phase="rest", mocap_world_m=None,
        rest_mean_body_mps2=(0.0, 0.0, 0.0), hover_chi2=HOVER_CHI2,
    )  # fmt: skip
    omega = 0.0 if circle_mps == 0.0 else 1.0
    radius = circle_mps / omega if omega else 0.0
    for k in range(int(seconds / DT)):
        t = k * DT
        rot = Rotation.from_euler("xyz", [0.01 * math.sin(t), -0.01, yaw_rate_rps * t])
        accel = np.zeros(3)
        pos = np.array([0.0, 0.0, 1.0])
        if circle_mps:
            accel = -radius * omega**2 * np.array([math.cos(omega * t), math.sin(omega * t), 0])
            pos = np.array([radius * math.cos(omega * t), radius * math.sin(omega * t), 1.0])
        f = np.array(_reading(rot, accel, bias_body)) + rng.normal(0.0, noise_mps2, 3)
        frame = None
        if mocap and k % 3 == 0:
            pm = pos + rng.normal(0.0, 0.001, 3)
            frame = (float(pm[0]), float(pm[1]), float(pm[2]))
        reading = (float(f[0]), float(f[1]), float(f[2]))
        state = slow_mod.slow_accel_step(
            state, slow, dt_s=DT, stamp_s=t, accel_body_mps2=reading,
            R_world_body=_rows(rot), phase="air", mocap_world_m=frame,
            accel_density_m2ps3=noise_mps2**2 * DT, hover_chi2=HOVER_CHI2,
        )  # fmt: skip
    return state


def test_a_bias_is_learnt_from_the_velocity_bound_in_every_body_axis_of_a_yawing_drone() -> None:
    bias = np.array([0.15, -0.1, 0.08])
    state = _fly(40.0, bias, yaw_rate_rps=0.3).kf
    assert state.cov is not None
    sd = np.sqrt(np.diag(state.cov)[6:])
    err = np.array(state.bias_body_mps2) - bias
    assert np.all(np.abs(err) < 4.0 * sd), (err, sd)
    assert np.all(np.abs(err) < 0.03), err  # learnt: 0.3 m/s² of prior shrunk tenfold


def test_motion_capture_learns_the_bias_tighter_than_the_bound() -> None:
    # A quiet IMU (0.1 m/s²): the velocity's bound, not the accelerometer's noise, limits
    # what the bound teaches; under 0.8 m/s² the noise limits both alike (σ 0.016 / 0.019).
    bias = np.array([-0.12, 0.2, -0.05])
    bound = _fly(10.0, bias, noise_mps2=0.1).kf
    mocap = _fly(10.0, bias, noise_mps2=0.1, mocap=True).kf
    assert bound.cov is not None and mocap.cov is not None
    sd = np.sqrt(np.diag(mocap.cov)[6:])
    err = np.array(mocap.bias_body_mps2) - bias
    assert np.all(np.abs(err) < 4.0 * sd), (err, sd)
    assert np.all(np.diag(mocap.cov)[6:] < 0.5 * np.diag(bound.cov)[6:])


def test_a_circle_leaks_a_little_into_the_bias() -> None:
    """A sustained manoeuvre leaks into the bias: the price of learning it in seconds. On a
    0.5 m circle at 0.5 m/s (0.5 m/s² of centripetal acceleration turning with the circle,
    the bound of NanoBench's fitted trajectories: σ_V 0.45 m/s, T_V 0.7 s) the estimate
    stays within a tenth of that acceleration of the true bias (measured: 0.035 m/s²); a
    mean of the acceleration over the last second would be off by up to all of it."""
    params = bk.BiasKalmanParams(velocity_std_mps=0.45, velocity_time_s=0.7)
    bias = np.array([0.05, 0.0, -0.03])
    state = _fly(30.0, bias, circle_mps=0.5, params=params).kf
    err = np.array(state.bias_body_mps2) - bias
    assert np.all(np.abs(err) < 0.1 * 0.5), err


def test_a_rest_measures_the_bias_and_a_take_off_adds_the_flight_prior() -> None:
    params = bk.BiasKalmanParams(flight_bias_std_mps2=0.05)
    rest = bk.at_rest(bk.BiasKalman(), (0.1, -0.2, 0.3))
    assert rest.bias_body_mps2 == (0.1, -0.2, 0.3)
    assert rest.bias_var_mps4 == 0.0 and rest.grounded
    assert bk.at_rest(rest, (0.1, -0.2, 0.3)) is rest  # nothing new: no new state
    assert bk.hold(rest) is rest
    flying = bk.take_off(rest, params, from_ground=True)
    assert flying.cov is not None
    np.testing.assert_allclose(np.diag(flying.cov)[6:], 0.05**2)
    np.testing.assert_allclose(np.diag(flying.cov)[:6], 0.0)
    # Landed: v = 0, b kept with its variance; the next rest without a window keeps it.
    landed = bk.hold(_fly(1.0, np.zeros(3)).kf)
    assert landed.grounded and landed.cov is None and landed.flight_prior
    again = bk.at_rest(landed, None)
    assert not again.flight_prior and again.bias_body_mps2 == landed.bias_body_mps2


def test_started_in_flight_the_prior_is_the_imus_zero_g_offset() -> None:
    params = bk.BiasKalmanParams(flight_bias_std_mps2=0.05, velocity_std_mps=0.3)
    state = bk.take_off(bk.BiasKalman(), params, from_ground=False)
    assert state.cov is not None
    np.testing.assert_allclose(np.diag(state.cov)[6:], bk.BIAS_PRIOR_STD_MPS2**2 + 0.05**2)
    np.testing.assert_allclose(np.diag(state.cov)[3:6], 0.3**2)  # v unknown: the scatter


def test_motion_capture_lost_hands_over_to_the_bound_and_back() -> None:
    slow = slow_mod.SlowAccelParams()
    rows = _rows(Rotation.identity())
    level = (0.0, 0.0, G)

    def step(state: slow_mod.SlowAccelState, frame: bk.Vec3 | None) -> slow_mod.SlowAccelState:
        return slow_mod.slow_accel_step(
            state, slow, dt_s=DT, stamp_s=0.0, accel_body_mps2=level, R_world_body=rows,
            phase="air", mocap_world_m=frame, accel_density_m2ps3=1e-3, hover_chi2=HOVER_CHI2,
        )  # fmt: skip

    state = step(slow_mod.SlowAccelState(), (0.0, 0.0, 1.0))
    assert state.kf_position_world_m == (0.0, 0.0, 1.0)
    for _ in range(int(1.5 * bk.MOCAP_HOLD_S / DT)):
        state = step(state, None)
    assert state.kf_position_world_m is None  # held too long: the bound observes
    assert state.kf.cov is not None and np.all(state.kf.cov[:3, :] == 0.0)
    state = step(state, (0.1, 0.0, 1.0))
    assert state.kf_position_world_m == (0.1, 0.0, 1.0)


def test_params_refuse_nonsense() -> None:
    with pytest.raises(ValueError, match="velocity_std_mps"):
        bk.BiasKalmanParams(velocity_std_mps=0.0)
    with pytest.raises(ValueError, match="flight_bias_std_mps2"):
        bk.BiasKalmanParams(flight_bias_std_mps2=math.nan)
