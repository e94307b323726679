"""The thrust and battery model (groundstation.thrust_model) and its fit (airframe)."""

from __future__ import annotations

import logging
import math
from typing import get_args

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from groundstation import config as config_mod
from groundstation.airframe import fit_airframe
from groundstation.calibration import GRAVITY_MPS2, CalibrationData
from groundstation.config import CalibrationSection
from groundstation.estimator.drone import calibration_from_config
from groundstation.tension import ObservationCalibration, observe_tension
from groundstation.thrust_model import (
    NOMINAL_PWM_MAP,
    THRUST_MODELS,
    mean_motor_voltage_v,
    mean_motor_voltage_v_array,
    motor_voltage_thrust_n,
    motor_voltage_thrust_n_array,
)

A, B, C = NOMINAL_PWM_MAP


def nominal_n(pwm: float) -> float:
    """The bridge's thrust for four motors at ``pwm``: the map summed."""
    return 4.0 * (A * pwm * pwm + B * pwm + C) if pwm > 0 else 0.0


def test_the_contract_and_the_physics_agree_on_the_map_and_the_models() -> None:
    assert config_mod.NOMINAL_PWM_MAP == NOMINAL_PWM_MAP
    assert get_args(config_mod.ThrustModel) == THRUST_MODELS
    assert CalibrationSection().thrust_pwm_map == NOMINAL_PWM_MAP


@pytest.mark.parametrize("pwm", [200.0, 20_000.0, 39_131.0, 58_000.0, 65_535.0])
@pytest.mark.parametrize("vbat_v", [2.9, 3.5, 4.2])
def test_the_map_is_inverted_to_the_motor_voltage(pwm: float, vbat_v: float) -> None:
    v = mean_motor_voltage_v(nominal_n(pwm), vbat_v, NOMINAL_PWM_MAP)
    assert v == pytest.approx(vbat_v * pwm / 65535.0, rel=1e-9)


def test_motors_off_give_no_thrust() -> None:
    assert mean_motor_voltage_v(0.0, 3.7, NOMINAL_PWM_MAP) == 0.0
    assert motor_voltage_thrust_n(0.0, 3.7, NOMINAL_PWM_MAP, 0.07, 2.9, 1.5) == 0.0
    cal = ObservationCalibration(thrust_model="motor_voltage", thrust_motor_ref_n=0.07)
    assert cal.thrust_n(0.0, 3.7) == 0.0


@settings(max_examples=200, deadline=None)
@given(
    pwm=st.floats(0.0, 65535.0),
    vbat_v=st.floats(2.5, 4.3),
    ref_n=st.floats(0.02, 0.2),
    ref_v=st.floats(1.5, 4.0),
    exponent=st.floats(0.5, 3.0),
    scale=st.floats(0.5, 2.0),
)
def test_one_equation_three_forms(
    pwm: float, vbat_v: float, ref_n: float, ref_v: float, exponent: float, scale: float
) -> None:
    """The per-message form (folded constants), the scalar function and the fit's arrays."""
    thrust = nominal_n(pwm)
    want = motor_voltage_thrust_n(thrust, vbat_v, NOMINAL_PWM_MAP, ref_n, ref_v, exponent)
    arr = motor_voltage_thrust_n_array(
        np.array([thrust]), np.array([vbat_v]), NOMINAL_PWM_MAP, ref_n, ref_v, exponent
    )
    assert float(arr[0]) == pytest.approx(want, rel=1e-9, abs=1e-12)
    v_arr = mean_motor_voltage_v_array(np.array([thrust]), np.array([vbat_v]), NOMINAL_PWM_MAP)
    assert float(v_arr[0]) == pytest.approx(
        mean_motor_voltage_v(thrust, vbat_v, NOMINAL_PWM_MAP), rel=1e-9, abs=1e-12
    )
    cal = ObservationCalibration(
        thrust_scale=scale,
        thrust_model="motor_voltage",
        thrust_motor_ref_n=ref_n,
        thrust_motor_ref_v=ref_v,
        thrust_motor_exponent=exponent,
    )
    assert cal.thrust_n(thrust, vbat_v) == pytest.approx(scale * want, rel=1e-9, abs=1e-12)


def test_the_same_motor_voltage_reads_the_same_thrust_at_any_battery() -> None:
    """What the firmware's battery compensation does: a drained battery gets a larger duty
    for the same motor voltage, and so the same thrust. The straight line reads the larger
    duty through the map as more thrust, however it is fitted."""
    mv = ObservationCalibration(
        thrust_model="motor_voltage", thrust_motor_ref_n=0.075, thrust_motor_exponent=1.4
    )
    v_motor = 2.9
    full, drained = 4.1, 3.1
    at_full = mv.thrust_n(nominal_n(65535.0 * v_motor / full), full)
    at_drained = mv.thrust_n(nominal_n(65535.0 * v_motor / drained), drained)
    assert at_drained == pytest.approx(at_full, rel=1e-9)
    assert 4 * 0.075 * 0.95 < at_full < 4 * 0.075 * 1.05  # v_motor ≈ thrust_motor_ref_v
    assert nominal_n(65535.0 * v_motor / drained) > 1.2 * nominal_n(65535.0 * v_motor / full)


def test_without_vbat_the_reference_battery_is_assumed() -> None:
    cal = ObservationCalibration(
        thrust_model="motor_voltage", thrust_vbat_ref_v=3.6, thrust_motor_ref_n=0.07
    )
    thrust = nominal_n(50_000.0)
    assert cal.thrust_n(thrust, None) == cal.thrust_n(thrust, 3.6)


def test_the_default_calibration_changes_nothing() -> None:
    cal, label = calibration_from_config(CalibrationSection())
    assert cal is None and label == "none"
    # motor_voltage before calibrate wrote its constants: what calibrate is to fit, no more
    asked, label = calibration_from_config(CalibrationSection(thrust_model="motor_voltage"))
    assert asked is None and label == "none"
    uncalibrated = ObservationCalibration(thrust_model="motor_voltage")
    assert uncalibrated.is_identity and uncalibrated.thrust_n(0.4, 3.2) == 0.4
    mv, _ = calibration_from_config(
        CalibrationSection(thrust_model="motor_voltage", thrust_motor_ref_n=0.07)
    )
    assert mv is not None and not mv.is_identity


def test_the_observation_uses_the_model() -> None:
    cal = ObservationCalibration(thrust_model="motor_voltage", thrust_motor_ref_n=0.07)
    thrust = nominal_n(55_000.0)
    obs = observe_tension([0.0, 0.0, 9.81], [1, 0, 0, 0], thrust, 0.03, calibration=cal, vbat_v=3.4)
    assert obs.thrust_n == cal.thrust_n(thrust, 3.4)
    assert obs.tension_world_n is not None
    assert obs.tension_world_n[2] == pytest.approx(0.03 * 9.81 - obs.thrust_n, abs=1e-12)


def test_a_slope_without_meaning_is_accepted_with_one_warning(
    caplog: pytest.LogCaptureFixture,
) -> None:
    config_mod._warned.clear()
    with caplog.at_level(logging.WARNING, logger="groundstation.config"):
        for _ in range(3):
            sec = CalibrationSection(
                thrust_model="motor_voltage", thrust_motor_ref_n=0.07, thrust_vbat_slope_per_v=0.3
            )
    assert sec.thrust_vbat_slope_per_v == 0.3
    said = [r.getMessage() for r in caplog.records]
    assert len(said) == 1 and "thrust_motor_exponent" in said[0] and "replaced" in said[0]
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="groundstation.config"):
        CalibrationSection(thrust_vbat_slope_per_v=0.3)  # meaningful for vbat_linear
        CalibrationSection(thrust_model="motor_voltage", thrust_motor_ref_n=0.07)
        # motor_voltage not yet calibrated: the line's terms still apply, and mean something
        CalibrationSection(thrust_model="motor_voltage", thrust_vbat_slope_per_v=0.3)
    assert caplog.records == []


def test_a_map_that_cannot_be_inverted_is_refused() -> None:
    with pytest.raises(ValueError, match="a > 0"):
        CalibrationSection(thrust_pwm_map=(0.0, 1e-6, 0.0))


def _synthetic_flight(
    ref_n: float, ref_v: float, exponent: float, seconds: float = 60.0, dt_s: float = 0.01
) -> CalibrationData:
    """A level drone bobbing up and down (true tension zero) while its battery drains from
    3.9 to 3.3 V; its thrust reported through the nominal map from the duty the motor
    voltage of the true model needs."""
    t = np.arange(0.0, seconds, dt_s)
    # slow enough for the motion-capture derivatives (0.25 s windows) to be exact
    w = 2 * math.pi * 0.15
    z = 1.0 + 0.5 * np.sin(w * t) + 0.2 * np.sin(2.5 * w * t)
    zdd = -0.5 * w * w * np.sin(w * t) - 0.2 * (2.5 * w) ** 2 * np.sin(2.5 * w * t)
    m = 0.030
    thrust_true = m * (GRAVITY_MPS2 + zdd)
    vbat = 3.9 - 0.6 * t / seconds - 0.05 * (zdd / np.abs(zdd).max())  # sag under load
    v_motor = ref_v * (thrust_true / (4 * ref_n)) ** (1.0 / exponent)
    pwm = 65535.0 * v_motor / vbat
    thrust_n = 4.0 * (A * pwm**2 + B * pwm + C)
    n = t.size
    pos = np.stack([np.zeros(n), np.zeros(n), z], axis=1)
    accel = np.stack([np.zeros(n), np.zeros(n), GRAVITY_MPS2 + zdd], axis=1)
    return CalibrationData.from_arrays(
        t,
        accel,
        np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)),
        thrust_n,
        position_world_m=pos,
        gyro_rps=np.zeros((n, 3)),
        vbat_v=vbat,
    )


def test_calibrate_recovers_the_motor_model_and_it_extrapolates() -> None:
    """Fitted on the part above 3.6 V, the motor-voltage model reads the part below it
    right; the straight line, fitted on the same part, reads it mN off."""
    ref_n, ref_v, exponent = 0.0745, 2.9, 1.4
    data = _synthetic_flight(ref_n, ref_v, exponent)
    high = data.vbat_v >= 3.6
    fit = fit_airframe(data, 0.030, weight_n_per_m=None, samples=high, thrust_model="motor_voltage")
    assert fit.thrust_model == "motor_voltage" and fit.motor_ref_v is not None
    n_fit = fit.values["thrust_motor_exponent"]
    assert n_fit == pytest.approx(exponent, abs=0.02)
    f_at_ref = ref_n * (fit.motor_ref_v / ref_v) ** exponent  # the truth at the fit's v_ref
    assert fit.values["thrust_motor_ref_n"] == pytest.approx(f_at_ref, rel=2e-3)
    lin = fit_airframe(data, 0.030, weight_n_per_m=None, samples=high)
    low = data.vbat_v < 3.4
    truth = 0.030 * (GRAVITY_MPS2 + (data.accel_body_mps2[low, 2] - GRAVITY_MPS2))
    mv = ObservationCalibration(
        thrust_model="motor_voltage",
        thrust_motor_ref_n=fit.values["thrust_motor_ref_n"],
        thrust_motor_ref_v=fit.motor_ref_v,
        thrust_motor_exponent=n_fit,
    )
    line = ObservationCalibration(
        thrust_scale=lin.values["thrust_scale"],
        thrust_vbat_slope_per_v=lin.values["vbat_slope_per_v"],
        thrust_vbat_ref_v=lin.vbat_ref_v,
    )
    pairs = zip(data.thrust_n[low].tolist(), data.vbat_v[low].tolist(), strict=True)
    err_mv, err_line = [], []
    for (thrust, vbat), true_n in zip(pairs, truth.tolist(), strict=True):
        err_mv.append(mv.thrust_n(thrust, vbat) - true_n)
        err_line.append(line.thrust_n(thrust, vbat) - true_n)
    assert abs(float(np.mean(err_mv))) < 0.5e-3  # N
    assert abs(float(np.mean(err_line))) > 2e-3  # N: the line misses the curve below


def test_an_exponent_outside_what_a_motor_does_is_held_at_its_bound_and_said() -> None:
    data = _synthetic_flight(0.0745, 2.9, 0.7, seconds=30.0)
    fit = fit_airframe(data, 0.030, weight_n_per_m=None, thrust_model="motor_voltage")
    assert fit.values["thrust_motor_exponent"] == pytest.approx(1.0, abs=1e-3)
    assert fit.exponent_at_bound
    free = fit_airframe(
        data, 0.030, weight_n_per_m=None, thrust_model="motor_voltage", exponent_bounds=(0.2, 5)
    )
    assert free.values["thrust_motor_exponent"] == pytest.approx(0.7, abs=0.02)
    assert not free.exponent_at_bound
