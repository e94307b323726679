"""groundstation.slow_accel: the accelerometer's slow error learnt at rest and in the air."""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from groundstation import config as config_mod
from groundstation.attitude import rows_from_quat_wxyz
from groundstation.bias_kalman import BiasKalmanParams
from groundstation.calibration import RestCalibrator
from groundstation.config import FilterSection, load_settings
from groundstation.estimator.drone import slow_accel_params
from groundstation.slow_accel import (
    SlowAccelParams,
    SlowAccelState,
    correct_accel_body_mps2,
    drag_velocity_world_mps,
    hover_process,
    slow_accel_step,
)
from groundstation.tension import (
    ObservationCalibration,
    TensionFilterParams,
    observe_tension,
    rotation_world_body,
)
from groundstation.tension_change import exceedance_chi2

FALSE_ALARMS_PER_H = TensionFilterParams().false_alarms_per_h  # the one knob, as served

G = 9.81
LEVEL = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
BIAS = (0.12, -0.2, 0.3)


def _yaw(yaw_rad: float) -> tuple[tuple[float, float, float], ...]:
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return ((c, -s, 0.0), (s, c, 0.0), (0.0, 0.0, 1.0))


def _run(
    state: SlowAccelState,
    params: SlowAccelParams,
    n: int,
    phase: str,
    accel_fn,  # type: ignore[no-untyped-def]
    R_fn=lambda i: LEVEL,  # type: ignore[no-untyped-def]
    mocap_fn=lambda i: None,  # type: ignore[no-untyped-def]
    dt: float = 0.01,
    t0: float = 0.0,
    accel_noise_mps2: float = 0.0,
) -> SlowAccelState:
    """n samples in one phase; a rest runs through the rest detector as the drone does
    (its window mean is β once the window has lasted ``attitude.STILL_WINDOW_S``). The
    accelerometer's noise density is its white noise's, ``accel_noise_mps2² · dt`` (the
    service's tension filter measures it)."""
    rest = RestCalibrator()
    for i in range(n):
        rest_mean = None
        if phase == "rest":
            x, y, z, w = Rotation.from_matrix(np.array(R_fn(i))).as_quat()
            rest.update(t0 + i * dt, accel_fn(i), (w, x, y, z), False, (0.0, 0.0, 0.0))
            assert rest.still
            rest_mean = rest.rest_mean_body_mps2
        state = slow_accel_step(
            state,
            params,
            dt_s=dt,
            stamp_s=t0 + i * dt,
            accel_body_mps2=accel_fn(i),
            R_world_body=R_fn(i),
            phase=phase,  # type: ignore[arg-type]
            mocap_world_m=mocap_fn(i),
            rest_mean_body_mps2=rest_mean,
            accel_density_m2ps3=accel_noise_mps2**2 * dt,
            hover_chi2=exceedance_chi2(FALSE_ALARMS_PER_H, dt),
        )
    return state


def test_bad_settings_are_refused() -> None:
    with pytest.raises(ValueError, match="velocity_time_constant_s"):
        SlowAccelParams(velocity_time_constant_s=0.0)
    with pytest.raises(ValueError, match="velocity_time_constant_s"):
        SlowAccelParams(velocity_time_constant_s=math.nan)


def test_rest_learns_the_bias_of_this_power_on() -> None:
    rng = np.random.default_rng(1)
    params = SlowAccelParams()
    st = _run(
        SlowAccelState(),
        params,
        200,
        "rest",
        lambda i: tuple(np.add((0.0, 0.0, G), BIAS) + rng.normal(0, 0.02, 3)),
    )
    assert st.learnt_at_rest
    assert np.allclose(st.bias_body_mps2, BIAS, atol=0.01)
    corrected = correct_accel_body_mps2(st, (BIAS[0], BIAS[1], G + BIAS[2]))
    assert np.allclose(corrected, (0.0, 0.0, G), atol=0.01)
    assert drag_velocity_world_mps(st) is None  # no drag on the floor


def test_a_hold_changes_nothing() -> None:
    params = SlowAccelParams()
    st = _run(SlowAccelState(), params, 150, "rest", lambda i: (BIAS[0], BIAS[1], G + BIAS[2]))
    held = _run(st, params, 300, "hold", lambda i: (3.0, -2.0, 20.0))
    assert held.bias_body_mps2 == st.bias_body_mps2


def test_in_the_air_a_bounded_velocity_leaves_the_bias_alone() -> None:
    """Manoeuvres with bounded velocity: 0.5 m/s² sine at 0.2 Hz (0.4 m/s peak) on top of
    the bias, within the bound the filter is told (σ_V 0.45 m/s, T_V 0.7 s: NanoBench's
    trajectories, as ``calibrate`` fits them); after the rest, β stays within the σ_δ prior
    of the bias (0.05 m/s²) and the filter's own σ of it."""
    flight = BiasKalmanParams(velocity_std_mps=0.45, velocity_time_s=0.7)
    params = SlowAccelParams(flight=flight)
    st = _run(SlowAccelState(), params, 200, "rest", lambda i: (BIAS[0], BIAS[1], G + BIAS[2]))

    def manoeuvre(i: int) -> tuple[float, float, float]:
        a = 0.5 * math.sin(2 * math.pi * 0.2 * i * 0.01)
        return (BIAS[0] + a, BIAS[1], G + BIAS[2])

    st = _run(st, params, 6000, "air", manoeuvre)
    assert st.kf.cov is not None
    sd = np.sqrt(np.diag(st.kf.cov)[6:])
    err = np.subtract(st.bias_body_mps2, BIAS)
    assert np.all(np.abs(err) < np.maximum(3.0 * sd, 0.01)), (err, sd)
    assert np.all(np.abs(err) < flight.flight_bias_std_mps2), err


def test_started_in_the_air_the_filter_finds_the_bias() -> None:
    params = SlowAccelParams()
    rng = np.random.default_rng(2)
    st = _run(
        SlowAccelState(),
        params,
        1000,
        "air",
        lambda i: tuple(np.add((0.0, 0.0, G), BIAS) + rng.normal(0, 0.3, 3)),
        accel_noise_mps2=0.3,
    )
    assert not st.learnt_at_rest
    assert np.allclose(st.bias_body_mps2, BIAS, atol=0.03)


def test_a_body_fixed_bias_stays_put_while_the_drone_yaws() -> None:
    """A noiseless still drone yawing at 0.5 rad/s: the body-frame bias is found in every
    axis (the yaw turns it in the world, where the velocity sees it)."""
    params = SlowAccelParams()

    def R(i: int) -> tuple[tuple[float, float, float], ...]:
        return _yaw(0.5 * i * 0.01)  # 0.5 rad/s

    st = _run(SlowAccelState(), params, 6000, "air", lambda i: (BIAS[0], BIAS[1], G + BIAS[2]), R)
    assert np.allclose(st.bias_body_mps2, BIAS, atol=2e-3)


def test_motion_capture_keeps_a_sustained_turn_out_of_the_bias() -> None:
    """A 1 m circle at 1 rad/s: 1 m/s² centripetal, sustained, a velocity of 1 m/s far
    outside a hover's bound (σ_V 0.05 m/s). Without motion capture the filter takes part of
    it for bias; with motion capture's positions, the bias is found."""
    params = SlowAccelParams(flight=BiasKalmanParams(velocity_std_mps=0.05))
    w, dt = 1.0, 0.01

    def accel(i: int) -> tuple[float, float, float]:
        t = i * dt
        a = (-math.cos(w * t), -math.sin(w * t))  # centripetal, world = body (level)
        return (a[0] + BIAS[0], a[1] + BIAS[1], G + BIAS[2])

    def mocap(i: int) -> tuple[float, float, float]:
        t = i * dt
        return (math.cos(w * t), math.sin(w * t), 1.0)

    seen = _run(SlowAccelState(), params, 3000, "air", accel, mocap_fn=mocap)
    blind = _run(SlowAccelState(), params, 3000, "air", accel)
    err_seen = np.linalg.norm(np.subtract(seen.bias_body_mps2, BIAS))
    err_blind = np.linalg.norm(np.subtract(blind.bias_body_mps2, BIAS))
    assert err_seen < 0.01, seen.bias_body_mps2
    assert err_blind > 3.0 * err_seen, blind.bias_body_mps2  # 0.066 against 0.004 m/s²
    assert seen.kf_position_world_m is not None  # motion capture in use
    v = drag_velocity_world_mps(seen)
    assert v is not None
    t_end = 2999 * dt  # the fused velocity follows the turn
    assert np.allclose(v[:2], (-math.sin(w * t_end), math.cos(w * t_end)), atol=0.05), v


def test_the_drag_velocity_without_motion_capture_follows_a_manoeuvre() -> None:
    """1 m/s² for 1 s: the leaky integral reads about 1 m/s (τ_v = 8 s leaks ~6 %)."""
    params = SlowAccelParams()
    st = _run(SlowAccelState(), params, 150, "rest", lambda i: (0.0, 0.0, G))
    st = _run(st, params, 100, "air", lambda i: (1.0, 0.0, G))
    v = drag_velocity_world_mps(st)
    assert v is not None and st.kf_position_world_m is None
    assert 0.9 < v[0] < 1.0 and abs(v[1]) < 1e-9


def test_rows_match_the_rotation_matrix() -> None:
    q = np.array([0.9, 0.1, -0.2, 0.3])
    assert np.allclose(rows_from_quat_wxyz(tuple(q)), rotation_world_body(q / np.linalg.norm(q)))


@pytest.mark.parametrize("yaw", [0.0, 1.0])
def test_rotor_drag_is_added_back_in_the_body_plane(yaw: float) -> None:
    """F_drag = −R·D·Rᵀ·v: a drone at 1 m/s reads −D·v of 'tension' unless added back."""
    D, m = 0.012, 0.03
    q = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
    cal = ObservationCalibration(rotor_drag_n_s_per_m=D)
    v = (1.0, 0.5, 0.3)
    # untethered at constant velocity: m·f = F·e3 + Rᵀ·F_drag
    R = rotation_world_body(q)
    vb = R.T @ np.array(v)
    f = (np.array([0.0, 0.0, m * G]) - D * np.array([vb[0], vb[1], 0.0])) / m
    thrust = m * G
    no = observe_tension(f, q, thrust, m)
    yes = observe_tension(f, q, thrust, m, calibration=cal, velocity_world_mps=v)
    assert no.tension_world_n is not None and yes.tension_world_n is not None
    assert np.allclose(no.tension_world_n[:2], -D * np.array(v[:2]), atol=1e-9)
    assert np.allclose(yes.tension_world_n, 0.0, atol=1e-9)
    # no velocity: no drag term (bit for bit the calibration without drag)
    plain = observe_tension(f, q, thrust, m, calibration=cal)
    assert np.array_equal(plain.tension_world_n, no.tension_world_n)  # type: ignore[arg-type]


def test_the_hover_test_finds_a_hover_and_ends_it_at_a_manoeuvre() -> None:
    """Quasi-static under vibration with a slow error the bias has not learnt; a sustained
    manoeuvre ends it; with the hover switched off (``hover=None``) never quasi-static.
    The reading is corrected by β alone (``f − β``), in or out of the hover."""
    params = SlowAccelParams()
    rng = np.random.default_rng(4)
    st = _run(SlowAccelState(), params, 200, "rest", lambda i: (0.0, 0.0, G))
    drift = (0.05, -0.04, 0.03)  # a slow error the bias has not learnt yet

    def hover(i: int) -> tuple[float, float, float]:
        n = rng.normal(0.0, 0.2, 3)
        return (drift[0] + n[0], drift[1] + n[1], G + drift[2] + n[2])

    st = _run(st, params, 500, "air", hover, accel_noise_mps2=0.2)
    assert st.quasi_static
    reading = (drift[0], drift[1], G + drift[2])
    corrected = correct_accel_body_mps2(st, reading)
    assert np.allclose(np.subtract(reading, corrected), st.bias_body_mps2, atol=1e-15)
    st = _run(st, params, 300, "air", lambda i: (1.0, 0.0, G), t0=5.0)
    assert not st.quasi_static
    off = _run(
        SlowAccelState(), SlowAccelParams(hover=None), 500, "air", hover, accel_noise_mps2=0.2
    )
    assert not off.quasi_static


def _hover_then_push(
    params: SlowAccelParams,
    push_mps2: float,
    vibration_mps2: float = 0.3,
    seed: int = 0,
    *,
    dt_s: float = 0.004,
    samples: int = 2000,
    push_from: int = 1250,
    rho: float = 0.0,
    density_m2ps3: float | None = None,
) -> list[bool]:
    """Hover with vibration (no motion capture) for ``push_from`` samples (5 s by default),
    then a sustained push along x: the quasi-static flag at each sample. The vibration is
    AR(1) with lag-1 correlation ``rho`` (0: white) and ``vibration_mps2`` per sample; the
    stage is told ``density_m2ps3`` as its noise density (None: the white noise's,
    ``vibration_mps2² · dt_s``)."""
    rng = np.random.default_rng(seed)
    if density_m2ps3 is None:
        density_m2ps3 = vibration_mps2**2 * dt_s
    innovation_mps2 = vibration_mps2 * math.sqrt(1.0 - rho * rho)
    state = SlowAccelState()
    e = np.zeros(3)
    flags = []
    for i in range(samples):
        push = push_mps2 if i >= push_from else 0.0
        e = rho * e + rng.normal(0.0, innovation_mps2, 3)
        ax, ay, az = e
        state = slow_accel_step(
            state,
            params,
            dt_s=dt_s,
            stamp_s=i * dt_s,
            accel_body_mps2=(ax + push, ay, G + az),
            R_world_body=LEVEL,
            phase="air",
            mocap_world_m=None,
            accel_density_m2ps3=density_m2ps3,
            hover_chi2=exceedance_chi2(FALSE_ALARMS_PER_H, dt_s),
        )
        flags.append(state.quasi_static)
    return flags


def test_vibration_alone_does_not_end_a_hover_and_a_push_does() -> None:
    params = SlowAccelParams()
    for vibration in (0.3, 1.0):
        hover = _hover_then_push(params, 0.0, vibration)[750:]  # from 3 s: vibration only
        assert np.mean(hover) > 0.95, "vibration alone must not end the hover"
    # A 0.5 m/s² push (a 15 mN tug on a 30 g drone) at the ideal profile's 0.3 m/s²: the
    # 1 s mean's threshold is sqrt(39.5·(σ_v²/(T·(T_c + T)) + D/((2 − k)·T))) ≈ 0.13 m/s²
    # (σ_v 0.02 m/s, T_c 0.5 s, 250 Hz), which the mean reaches after ~0.3 s; the fixed
    # 0.2 m/s² of before took ~0.5 s.
    after = _hover_then_push(params, 0.5)[1250:]
    exit_s = 0.004 * next(i for i, q in enumerate(after) if not q)
    assert 0.1 < exit_s < 0.35


def test_the_retired_short_window_key_is_accepted_with_one_warning(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """``[filter] accel_hover_exit_window_s``: the change tests replaced the hover test's
    short window; a value other than 0 is kept, told once, and changes nothing."""
    config_mod._warned.clear()
    with caplog.at_level(logging.WARNING, logger="groundstation.config"):
        for _ in range(3):
            sec = FilterSection(accel_hover_exit_window_s=0.3)
    said = [r.getMessage() for r in caplog.records]
    assert len(said) == 1 and "accel_hover_exit_window_s = 0.3 is not used" in said[0]
    assert "replaced" in said[0]
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="groundstation.config"):
        FilterSection(accel_hover_exit_window_s=0.0)
    assert caplog.records == []
    settings = load_settings(None, {"filter": {"accel_hover_exit_window_s": 0.3}}, use_env=False)
    default = load_settings(None, {}, use_env=False)
    assert slow_accel_params(settings.for_drone("cf1")) == slow_accel_params(
        default.for_drone("cf1")
    )
    assert sec.accel_hover_exit_window_s == 0.3


def _hover_flags(
    params: SlowAccelParams, vibration_mps2: float, push_mps2: float = 0.0, seed: int = 1
) -> list[bool]:
    """10 s of hover at 100 Hz, then 5 s of a sustained push along x (``_hover_then_push``)."""
    return _hover_then_push(
        params, push_mps2, vibration_mps2, seed, dt_s=0.01, samples=1500, push_from=1000
    )


def test_the_hover_test_holds_through_strong_vibration_and_a_push_ends_it() -> None:
    """At 2 m/s² of vibration (100 Hz) the test allows for the measured noise: the hover
    holds; a 2 m/s² push ends it within 1 s and it stays out. At the ideal profile's noise
    the hover's own velocity sets the thresholds, and a hover with that velocity's scatter
    holds too."""
    params = SlowAccelParams()
    assert np.mean(_hover_flags(params, 2.0)[300:1000]) > 0.95
    pushed = _hover_flags(params, 2.0, push_mps2=2.0)[1000:]
    assert not any(pushed[100:])  # out within 1 s, and stays out
    assert np.mean(_hover_flags(params, 0.3)[300:1000]) > 0.95
    with pytest.raises(ValueError, match="hover"):
        SlowAccelParams(hover=hover_process(math.nan, 0.5))


def test_the_hover_test_takes_the_fitted_hover_velocity_and_the_retired_keys_warn(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """The hover test allows for the hover's velocity the tension filter uses (σ_v, T_c:
    ``[calibration] hover_velocity_std_mps`` / ``hover_velocity_time_s`` where ``calibrate``
    fitted them, the filter's defaults otherwise); ``accel_hover_crossover_s = 0`` turns it
    off. ``[filter] accel_hover_noise_sigmas`` and ``accel_hover_exit_ratio``, which set
    its former thresholds, are accepted with one warning each and change nothing; an exit
    ratio below 1 is still refused."""
    from groundstation.config import ConfigError
    from groundstation.estimator.drone import DroneEstimator
    from groundstation.tension import TensionFilterParams

    d = TensionFilterParams()
    default = DroneEstimator("cf1", load_settings(None, {}, use_env=False)).slow_params
    assert default is not None
    assert default.hover == hover_process(d.hover_velocity_std_mps, d.hover_velocity_time_s)
    fitted = load_settings(
        None,
        {"calibration": {"hover_velocity_std_mps": 0.05, "hover_velocity_time_s": 1.5}},
        use_env=False,
    )
    slow = DroneEstimator("cf1", fitted).slow_params
    assert slow is not None and slow.hover == hover_process(0.05, 1.5)
    off = load_settings(None, {"filter": {"accel_hover_crossover_s": 0.0}}, use_env=False)
    slow = DroneEstimator("cf1", off).slow_params
    assert slow is not None and slow.hover is None
    config_mod._warned.clear()
    cfg = tmp_path / "gs.toml"
    cfg.write_text("[filter]\naccel_hover_noise_sigmas = 0.0\naccel_hover_exit_ratio = 1.0\n")
    with caplog.at_level(logging.WARNING, logger="groundstation.config"):
        for _ in range(2):
            retired = load_settings(cfg, {}, use_env=False)
    said = [r.getMessage() for r in caplog.records]
    assert len(said) == 2 and all("is not used" in m and "replaced" in m for m in said)
    assert slow_accel_params(retired.for_drone("cf1")) == default
    cfg.write_text("[filter]\naccel_hover_exit_ratio = 0.5\n")
    with pytest.raises(ConfigError, match="accel_hover_exit_ratio"):
        load_settings(cfg, {}, use_env=False)


def test_the_retired_bias_time_constant_is_accepted_with_one_warning(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """``[filter] accel_slow_time_constant_s``: the bias filter replaced the low-pass; a
    value other than 60 is kept, told once (naming what replaced it), and changes nothing."""
    config_mod._warned.clear()
    with caplog.at_level(logging.WARNING, logger="groundstation.config"):
        for _ in range(3):
            FilterSection(accel_slow_time_constant_s=10.0)
    said = [r.getMessage() for r in caplog.records]
    assert len(said) == 1 and "accel_slow_time_constant_s = 10 is not used" in said[0]
    assert "flight_velocity_std_mps" in said[0] and "replaced" in said[0]
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="groundstation.config"):
        FilterSection()
    assert caplog.records == []
    settings = load_settings(None, {"filter": {"accel_slow_time_constant_s": 10.0}}, use_env=False)
    assert slow_accel_params(settings.for_drone("cf1")) == slow_accel_params(
        load_settings(None, {}, use_env=False).for_drone("cf1")
    )


def test_the_hover_thresholds_scale_with_the_long_run_noise_not_the_per_sample() -> None:
    """The hover test's thresholds take the accelerometer's noise as a density (the tension
    filter's long-run measure, colour included): a 1 s mean of AR(1) vibration (ρ = 0.8,
    2 m/s² per sample, 100 Hz) scatters with r = s²·(1 + ρ)/(1 − ρ) = 9 s², not s². Told the
    long-run density the hover holds; told the per-sample variance (what a white measure
    such as the stage's former own reads) its thresholds are 3× too tight and it drops (to
    about 80 % of the samples at the one false-alarm rate's chi-square threshold, 39.5)."""
    params = SlowAccelParams()
    s, rho, dt = 2.0, 0.8, 0.01

    def held(density_m2ps3: float, seed: int) -> float:
        flags = _hover_then_push(
            params, 0.0, s, seed, dt_s=dt, samples=1500, push_from=1500, rho=rho,
            density_m2ps3=density_m2ps3,
        )  # fmt: skip
        return float(np.mean(flags[300:]))

    long_run = s * s * (1.0 + rho) / (1.0 - rho) * dt
    for seed in (3, 4, 5):
        assert held(long_run, seed) > 0.95
    assert np.mean([held(s * s * dt, seed) for seed in (3, 4, 5)]) < 0.9  # 0.80 measured
