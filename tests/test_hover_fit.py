"""groundstation.hover_fit: σ_v and T_c of the hover, fitted from motion capture, and what the
service does with them (``[calibration] hover_velocity_*``)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from groundstation.bias_kalman import BiasKalmanParams
from groundstation.bus import Sample
from groundstation.calibration import CalibrationData
from groundstation.cli import main
from groundstation.config import load_settings
from groundstation.estimator.drone import flight_params, hover_velocity_params, slow_accel_params
from groundstation.hover_fit import (
    HOVER_FIT_MIN_S,
    FlightPhases,
    fit_flight,
    fit_hover_velocity,
    flight_phases,
    hover_flags,
)
from groundstation.pipeline import Pipeline
from groundstation.tension import TensionFilterParams
from tests.calib_synth import write_mcap

G = 9.81
TELEMETRY = (
    b'{"stamp_s": 0.0, "seq": 0, "accel_mps2": [0, 0, 9.81], "quat_wxyz": [1, 0, 0, 0],'
    b' "thrust_n": 0.3, "armed": true}'
)
DT_S = 0.01
MASS_KG = 0.03


def _hover(
    seconds: float,
    std_mps: float,
    corr_s: float,
    *,
    seed: int = 0,
    accel_noise_mps2: float = 0.3,
    armed: bool = True,
) -> CalibrationData:
    """A level hover at 1 m whose velocity is an AR(1) per axis (σ ``std_mps``, correlation
    time ``corr_s``: two-sided integral 2·corr_s), the accelerometer reading its derivative
    plus white vibration, the thrust the weight."""
    rng = np.random.default_rng(seed)
    n = round(seconds / DT_S)
    a = math.exp(-DT_S / corr_s)
    v = np.zeros((n, 3))
    v[0] = rng.normal(0.0, std_mps, 3)
    for k in range(1, n):
        v[k] = a * v[k - 1] + math.sqrt(1 - a * a) * std_mps * rng.normal(size=3)
    p = np.array([0.5, 0.0, 1.0]) + np.cumsum(v, axis=0) * DT_S
    acc = np.gradient(v, DT_S, axis=0) + np.array([0.0, 0.0, G])
    acc += rng.normal(0.0, accel_noise_mps2, (n, 3))
    return CalibrationData.from_arrays(
        np.arange(n) * DT_S,
        acc,
        np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)),
        np.full(n, MASS_KG * G),
        armed=np.full(n, armed),
        position_world_m=p,
    )


def _expected_time_s(corr_s: float) -> float:
    """The AR(1)'s two-sided integral of its autocorrelation, dt·(1 + a)/(1 − a)."""
    a = math.exp(-DT_S / corr_s)
    return DT_S * (1 + a) / (1 - a)


@pytest.mark.parametrize(("std_mps", "corr_s"), [(0.02, 0.25), (0.005, 1.0)])
def test_the_fit_finds_the_velocity_scatter_and_its_correlation_time(
    std_mps: float, corr_s: float
) -> None:
    data = _hover(240.0, std_mps, corr_s, seed=3)
    fit, hover_s = fit_hover_velocity(data, np.ones(len(data), bool))
    assert fit is not None and hover_s == pytest.approx(240.0, abs=0.1)
    # The motion-capture velocity is smoothed (a 0.25 s Savitzky–Golay): σ_v reads a little
    # low, T_c a little long; their product, the filter's observation density, holds.
    assert fit.std_mps == pytest.approx(std_mps, rel=0.2)
    density = fit.std_mps**2 * fit.time_s
    assert density == pytest.approx(std_mps**2 * _expected_time_s(corr_s), rel=0.3)


def test_too_little_hover_fits_nothing_and_says_how_much_there_was() -> None:
    data = _hover(2.5, 0.02, 0.25)
    fit, hover_s = fit_hover_velocity(data, np.ones(len(data), bool))
    assert fit is None and 0.0 < hover_s < HOVER_FIT_MIN_S
    # Stretches shorter than the hover test's window do not count.
    data = _hover(20.0, 0.02, 0.25)
    every_other_half_second = (np.arange(len(data)) // 50) % 2 == 0
    fit, hover_s = fit_hover_velocity(data, every_other_half_second)
    assert fit is None and hover_s == 0.0


def test_the_hover_flags_are_the_services_hover_test() -> None:
    """A quiet level hover is one; disarmed it is not; a manoeuvre is not, and the hover
    comes back after it."""
    settings = load_settings(None, {}, use_env=False)
    params = slow_accel_params(settings.for_drone("cf1"))
    kw = {"mass_kg": MASS_KG, "floor_z_m": 0.0, "ground_thrust_ratio": 0.5}
    flags = hover_flags(_hover(10.0, 0.01, 0.25), params, **kw)  # type: ignore[arg-type]
    assert flags[200:].mean() > 0.95
    disarmed = _hover(10.0, 0.01, 0.25, armed=False)
    flags = hover_flags(disarmed, params, **kw)  # type: ignore[arg-type]
    assert not flags.any()
    push = _hover(12.0, 0.01, 0.25)
    # 2 s on the floor, disarmed and still: β learnt at rest, as the service does
    push.armed[:200] = False
    push.thrust_n[:200] = 0.0
    push.accel_body_mps2[:200] = (0.0, 0.0, G)
    push.accel_body_mps2[400:550, 0] += 1.0  # 1 m/s² for 1.5 s, then back to rest
    push.accel_body_mps2[550:700, 0] -= 1.0
    flags = hover_flags(push, params, **kw)  # type: ignore[arg-type]
    assert not flags[:200].any() and flags[200:400].all()  # the floor, then the hover
    assert not flags[450:575].any() and flags[1100:].all()  # the push, then hover again


def test_the_service_uses_the_fitted_values_and_the_defaults_without_them() -> None:
    none = load_settings(None, {}, use_env=False).for_drone("cf1")
    default = TensionFilterParams()
    assert hover_velocity_params(none.calibration) == (
        default.hover_velocity_std_mps,
        default.hover_velocity_time_s,
    )
    fitted_settings = load_settings(
        None,
        {"calibration": {"hover_velocity_std_mps": 0.004, "hover_velocity_time_s": 0.8}},
        use_env=False,
    )
    fitted = fitted_settings.for_drone("cf1")
    assert hover_velocity_params(fitted.calibration) == (0.004, 0.8)
    pipe = Pipeline(fitted_settings)
    pipe.handle(Sample("tether/cf1/telemetry", TELEMETRY), 0.0)
    got = pipe.drones["cf1"].filter.params
    assert (got.hover_velocity_std_mps, got.hover_velocity_time_s) == (0.004, 0.8)
    with pytest.raises(Exception, match="hover_velocity_std_mps"):
        load_settings(None, {"calibration": {"hover_velocity_std_mps": -1.0}}, use_env=False)


def test_calibrate_writes_what_it_fitted_and_says_when_it_cannot(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``groundstation calibrate`` on a recording with 30 s of hover under motion capture
    writes ``[calibration] hover_velocity_*`` (σ_v near the recording's); on one whose
    drone never hovers it writes neither and says so."""
    rec = tmp_path / "hover.mcap"
    write_mcap(str(rec), _hover(30.0, 0.01, 0.25, seed=5, accel_noise_mps2=0.1))
    out = tmp_path / "cal.toml"
    assert (
        main(["calibrate", "--untethered", "--tether-detached", str(rec), "--out", str(out)]) == 0
    )
    assert "hover_velocity_std_mps" in capsys.readouterr().out
    cal = load_settings(out, use_env=False).for_drone("cf1").calibration
    assert cal.hover_velocity_std_mps == pytest.approx(0.01, rel=0.3)
    assert cal.hover_velocity_time_s is not None and 0.2 < cal.hover_velocity_time_s < 1.5

    short = tmp_path / "circle.mcap"
    circle = _hover(20.0, 0.0, 0.25, accel_noise_mps2=0.1)
    t = circle.stamp_s
    w, r = 1.2, 0.5  # 0.6 m/s around a circle: never a hover
    circle.position_world_m[:, 0] = r * np.cos(w * t)
    circle.position_world_m[:, 1] = r * np.sin(w * t)
    circle.accel_body_mps2[:, 0] = -r * w * w * np.cos(w * t)
    circle.accel_body_mps2[:, 1] = -r * w * w * np.sin(w * t)
    write_mcap(str(short), circle)
    out2 = tmp_path / "cal2.toml"
    assert (
        main(["calibrate", "--untethered", "--tether-detached", str(short), "--out", str(out2)])
        == 0
    )
    assert "hover velocity           not fitted" in capsys.readouterr().out
    cal = load_settings(out2, use_env=False).for_drone("cf1").calibration
    assert cal.hover_velocity_std_mps is None and cal.hover_velocity_time_s is None


def test_the_flight_fit_finds_the_velocity_about_zero_and_the_bias_offset_from_the_rest() -> None:
    """σ_V and T_V of an airborne AR(1) velocity (about zero); σ_δ from a flight whose
    accelerometer reads 0.08 m/s² more in x than at the rest before it."""
    settings = load_settings(None, {}, use_env=False)
    params = slow_accel_params(settings.for_drone("cf1"))
    data = _hover(120.0, 0.1, 0.5, seed=4, accel_noise_mps2=0.2)
    data.position_world_m[:, 2] = 1.0  # level flight (a vertical walk would reach the floor)
    data.accel_body_mps2[:, 2] = G
    data.armed[:200] = False  # 2 s on the floor, disarmed and still
    data.thrust_n[:200] = 0.0
    data.accel_body_mps2[:200] = (0.0, 0.0, G)
    data.accel_body_mps2[200:, 0] += 0.08  # the bias in the air: +0.08 m/s² in x
    phases = flight_phases(data, params, mass_kg=MASS_KG, floor_z_m=0.0, ground_thrust_ratio=0.5)
    assert not phases.airborne[:200].any() and phases.airborne[300:].all()
    np.testing.assert_allclose(phases.rest_mean_body_mps2[300], (0.0, 0.0, 0.0), atol=1e-9)
    fit, airborne_s = fit_flight(data, phases)
    assert fit is not None and airborne_s == pytest.approx(118.0, abs=0.2)
    # Two axes of 0.1 m/s and a still one: σ_V² the mean of the three.
    assert fit.velocity_std_mps == pytest.approx(0.1 * math.sqrt(2.0 / 3.0), rel=0.25)
    assert fit.velocity_time_s == pytest.approx(_expected_time_s(0.5), rel=0.5)
    # One flight after a rest: δ = (0.08, 0, 0) ± its mean's noise, RMS over the axes.
    assert fit.flights == 1
    assert fit.bias_std_mps2 == pytest.approx(0.08 / math.sqrt(3), rel=0.15)
    # No rest before the flight: no σ_δ; too little flight: nothing.
    no_rest = np.full_like(phases.rest_mean_body_mps2, np.nan)
    fit2, _ = fit_flight(data, FlightPhases(phases.hovering, phases.airborne, no_rest))
    assert fit2 is not None and fit2.bias_std_mps2 is None
    short = _hover(2.5, 0.1, 0.5)
    short_phases = flight_phases(
        short, params, mass_kg=MASS_KG, floor_z_m=0.0, ground_thrust_ratio=0.5
    )
    fit3, _ = fit_flight(short, short_phases)
    assert fit3 is None


def test_the_service_takes_the_fitted_flight_model() -> None:
    none = load_settings(None, {}, use_env=False)
    assert flight_params(none.for_drone("cf1").calibration) == BiasKalmanParams()
    fitted = load_settings(
        None,
        {
            "calibration": {
                "flight_velocity_std_mps": 0.4,
                "flight_velocity_time_s": 0.6,
                "flight_bias_std_mps2": 0.03,
            },
            "localization": {"mocap_std_m": 0.001},
        },
        use_env=False,
    )
    pipe = Pipeline(fitted)
    pipe.handle(Sample("tether/cf1/telemetry", TELEMETRY), 0.0)
    slow = pipe.drones["cf1"].slow_params
    assert slow is not None
    assert slow.flight == BiasKalmanParams(
        velocity_std_mps=0.4, velocity_time_s=0.6, flight_bias_std_mps2=0.03, mocap_std_m=0.001
    )
    with pytest.raises(Exception, match="flight_bias_std_mps2"):
        load_settings(None, {"calibration": {"flight_bias_std_mps2": 0.0}}, use_env=False)


def test_calibrate_writes_the_flight_model(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec = tmp_path / "flight.mcap"
    data = _hover(40.0, 0.1, 0.5, seed=6, accel_noise_mps2=0.1)
    data.position_world_m[:, 2] = 1.0
    data.accel_body_mps2[:, 2] = G
    data.armed[:200] = False
    data.thrust_n[:200] = 0.0
    data.accel_body_mps2[:200] = (0.0, 0.0, G)
    write_mcap(str(rec), data)
    out = tmp_path / "cal.toml"
    assert (
        main(["calibrate", "--untethered", "--tether-detached", str(rec), "--out", str(out)]) == 0
    )
    said = capsys.readouterr().out
    assert "flight_velocity_std_mps" in said and "flight_bias_std_mps2" in said
    cal = load_settings(out, use_env=False).for_drone("cf1").calibration
    assert cal.flight_velocity_std_mps == pytest.approx(0.1 * math.sqrt(2.0 / 3.0), rel=0.3)
    assert cal.flight_velocity_time_s is not None and cal.flight_bias_std_mps2 is not None
