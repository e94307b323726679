"""groundstation.hover_fit.fit_hover_balance: the hover's tension wander q_w and the thrust
balance's noise D, fitted by maximum likelihood from motion capture, and what the service
and ``calibrate`` do with them (``[calibration] hover_wander_n2_per_s`` /
``hover_balance_density_n2s``)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from groundstation.bus import Sample
from groundstation.calibration import CalibrationData
from groundstation.cli import main
from groundstation.config import load_settings
from groundstation.estimator.drone import hover_balance_params
from groundstation.hover_fit import (
    BALANCE_BLOCK_S,
    balance_blocks,
    balance_world_n,
    fit_hover_balance,
    fit_hover_velocity,
)
from groundstation.pipeline import Pipeline
from groundstation.tension import (
    ObservationCalibration,
    TensionFilter,
    TensionFilterParams,
    observe_tension,
    rotation_rows,
)
from tests.calib_synth import write_mcap

G = 9.81
DT_S = 0.01
MASS_KG = 0.03


def _balanced_hover(
    seconds: float,
    wander_n2_per_s: float,
    density_n2s: float,
    *,
    seed: int,
    mocap_std_m: float = 0.0005,
) -> tuple[CalibrationData, np.ndarray, np.ndarray]:
    """A level hover whose tension (what the balance reads) is a random walk of density
    ``wander_n2_per_s`` per axis; the velocity an AR(1) (0.01 m/s, 0.3 s) moved by Newton,
    ``m·dv/dt = T − h``; the thrust balance h read with white noise of density
    ``density_n2s``; motion capture's positions with ``mocap_std_m`` of noise. Returns the
    recording, the balance and the true tension per sample."""
    rng = np.random.default_rng(seed)
    n = round(seconds / DT_S)
    a = math.exp(-DT_S / 0.3)
    v = np.zeros((n, 3))
    for k in range(1, n):
        v[k] = a * v[k - 1] + math.sqrt(1 - a * a) * 0.01 * rng.normal(size=3)
    tension = np.cumsum(rng.normal(0.0, math.sqrt(wander_n2_per_s * DT_S), (n, 3)), axis=0)
    h = tension.copy()
    h[:-1] -= MASS_KG * np.diff(v, axis=0) / DT_S  # h = T − m·dv/dt over each step
    h += rng.normal(0.0, math.sqrt(density_n2s / DT_S), (n, 3))
    p = np.array([0.5, 0.0, 1.0]) + np.vstack([np.zeros(3), np.cumsum(v[:-1], axis=0) * DT_S])
    p += rng.normal(0.0, mocap_std_m, (n, 3))
    data = CalibrationData.from_arrays(
        np.arange(n) * DT_S,
        np.tile([0.0, 0.0, G], (n, 1)),
        np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)),
        np.full(n, MASS_KG * G),
        position_world_m=p,
    )
    return data, h, tension


@pytest.mark.parametrize(("wander", "density"), [(1e-9, 9e-8), (1e-7, 9e-8), (4.5e-8, 1e-6)])
def test_the_likelihood_finds_the_wander_and_the_balance_noise(
    wander: float, density: float
) -> None:
    """Five minutes of hover: q_w within a factor of 2.5 (a random walk's density from
    block increments is a slow statistic) and D within 30 %, whatever their ratio."""
    data, h, _ = _balanced_hover(300.0, wander, density, seed=11)
    fit, hover_s = fit_hover_balance(data, np.ones(len(data), bool), h, mass_kg=MASS_KG)
    assert fit is not None and hover_s == pytest.approx(300.0, abs=0.5)
    assert fit.wander_resolved
    assert wander / 2.5 < fit.wander_n2_per_s < wander * 2.5
    assert fit.balance_density_n2s == pytest.approx(density, rel=0.3)


def test_no_wander_is_not_taken_for_one() -> None:
    """A tension that does not move: the likelihood does not tell q_w from zero, and
    ``calibrate`` would not write it."""
    data, h, _ = _balanced_hover(120.0, 0.0, 9e-8, seed=12)
    fit, _ = fit_hover_balance(data, np.ones(len(data), bool), h, mass_kg=MASS_KG)
    assert fit is not None and not fit.wander_resolved
    assert fit.balance_density_n2s == pytest.approx(9e-8, rel=0.3)


def test_one_axis_at_a_time() -> None:
    """``axes`` sums the likelihood over the axes named: a wander in y only is found on y
    alone and not on x alone; all three together find it diluted between them."""
    data, h, _ = _balanced_hover(300.0, 0.0, 9e-8, seed=14)
    walked, h_walk, _ = _balanced_hover(300.0, 3e-7, 9e-8, seed=14)
    h[:, 1] = h_walk[:, 1]  # the same hover, with y's balance from the wandering one
    assert np.allclose(walked.position_world_m, data.position_world_m)  # same motion
    fit_x, _ = fit_hover_balance(data, np.ones(len(data), bool), h, mass_kg=MASS_KG, axes=(0,))
    fit_y, _ = fit_hover_balance(data, np.ones(len(data), bool), h, mass_kg=MASS_KG, axes=(1,))
    fit_all, _ = fit_hover_balance(data, np.ones(len(data), bool), h, mass_kg=MASS_KG)
    assert fit_x is not None and fit_y is not None and fit_all is not None
    assert not fit_x.wander_resolved and fit_y.wander_resolved
    assert 3e-7 / 2.5 < fit_y.wander_n2_per_s < 3e-7 * 2.5
    assert fit_all.wander_n2_per_s < fit_y.wander_n2_per_s
    assert fit_x.blocks == fit_y.blocks == fit_all.blocks  # blocks of time, any axes


def test_too_little_hover_fits_nothing() -> None:
    data, h, _ = _balanced_hover(2.5, 1e-8, 9e-8, seed=13)
    fit, hover_s = fit_hover_balance(data, np.ones(len(data), bool), h, mass_kg=MASS_KG)
    assert fit is None and 0.0 < hover_s < 3.0


def test_the_blocks_are_newton_integrated_over_each_block() -> None:
    """With no noise, Y_k is the block's mean tension exactly: the balance's mean plus
    m·Δv/Δt."""
    data, _, _ = _balanced_hover(4.0, 1e-6, 1e-30, seed=14, mocap_std_m=0.0)
    rng = np.random.default_rng(0)
    v = rng.normal(0.0, 0.01, (len(data), 3))
    tension = rng.normal(0.0, 0.01, (len(data), 3))
    h = tension.copy()
    h[:-1] -= MASS_KG * np.diff(v, axis=0) / DT_S
    y = balance_blocks(data.stamp_s, h, v, MASS_KG)
    per_block = round(BALANCE_BLOCK_S / DT_S)
    assert y.shape == (len(data) // per_block - 1, 3)
    for k in range(y.shape[0]):
        block = tension[k * per_block : (k + 1) * per_block]
        np.testing.assert_allclose(y[k], block.mean(axis=0), atol=1e-12)


def test_the_balance_is_the_services_hover_model() -> None:
    """``balance_world_n`` is the observation stage's thrust balance: the accelerometer
    model less what the accelerometer reads, ``T_acc − m·(R·(f − b) − g·e3)``
    (groundstation.estimator.observation), for a calibrated, tilted, battery-sagging
    drone."""
    rng = np.random.default_rng(3)
    n = 50
    quat = np.column_stack([np.ones(n), rng.normal(0.0, 0.05, (n, 3))])
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    accel = np.array([0.0, 0.0, G]) + rng.normal(0.0, 0.5, (n, 3))
    thrust = MASS_KG * G * (1.0 + rng.normal(0.0, 0.05, n))
    vbat = np.linspace(4.0, 3.5, n)
    data = CalibrationData.from_arrays(np.arange(n) * DT_S, accel, quat, thrust, vbat_v=vbat)
    cal = ObservationCalibration(
        thrust_scale=1.07,
        thrust_axis_rad=(0.02, -0.03),
        accel_bias_mps2=(0.05, -0.02, 0.1),
        thrust_vbat_slope_per_v=0.1,
        thrust_vbat_ref_v=3.8,
    )
    got = balance_world_n(data, np.ones(n, bool), mass_kg=MASS_KG, calibration=cal)
    bias = np.asarray(cal.accel_bias_mps2)
    for i in range(n):
        obs = observe_tension(
            accel[i], quat[i], float(thrust[i]), MASS_KG, calibration=cal, vbat_v=float(vbat[i])
        )
        assert obs.tension_world_n is not None
        rows = np.array(rotation_rows(quat[i]))
        want = obs.tension_world_n - MASS_KG * (rows @ (accel[i] - bias) - [0.0, 0.0, G])
        np.testing.assert_allclose(got[i], want, atol=1e-12)


@pytest.mark.parametrize(("wander", "density"), [(1e-9, 9e-8), (1e-7, 9e-8), (1e-7, 1e-6)])
def test_fitted_from_one_hover_the_sigma_is_honest_on_another(
    wander: float, density: float
) -> None:
    """The σ follows the recordings: fitted (σ_v, T_c, q_w, D) from five minutes of one hover
    under motion capture, the filter run on another hover of the same drone (the
    accelerometer model with 1 m/s² of white vibration, the thrust balance as read) holds
    the true tension within 2σ per axis in 90–98 % of the samples after 20 s; the priors
    do not in these regimes (100 %, 89 %, 73 %), and their error is no smaller."""
    data, h, _ = _balanced_hover(300.0, wander, density, seed=5)
    hovering = np.ones(len(data), bool)
    fit, _ = fit_hover_balance(data, hovering, h, mass_kg=MASS_KG)
    velocity, _ = fit_hover_velocity(data, hovering)
    assert fit is not None and velocity is not None
    prior = TensionFilterParams()
    fitted = TensionFilterParams(
        hover_wander_n2_per_s=fit.wander_n2_per_s
        if fit.wander_resolved
        else prior.hover_wander_n2_per_s,
        hover_balance_density_n2s=fit.balance_density_n2s,
        hover_velocity_std_mps=velocity.std_mps,
        hover_velocity_time_s=velocity.time_s,
    )
    judged, h2, truth = _balanced_hover(120.0, wander, density, seed=6)
    rng = np.random.default_rng(7)
    vibration = rng.normal(0.0, MASS_KG * 1.0, (len(judged), 3))
    share, rms = {}, {}
    for name, params in (("prior", prior), ("fitted", fitted)):
        f = TensionFilter(params)
        inside, errors = [], []
        for i in range(len(judged)):
            est = f.update(truth[i] + vibration[i], DT_S, hover_model_world_n=h2[i])
            if i * DT_S >= 20.0:
                e = est.tension_world_n - truth[i]
                errors.append(e)
                inside.append(np.abs(e) <= 2.0 * est.std_n)
        share[name] = float(np.mean(inside))
        rms[name] = float(np.sqrt(np.mean(np.square(errors))))
    assert 0.90 <= share["fitted"] <= 0.98, share
    assert not 0.90 <= share["prior"] <= 0.98, share
    assert rms["fitted"] <= rms["prior"], rms


def test_the_fitted_density_is_the_velocitys_process_noise() -> None:
    """D = thrust_noise_n²·dt is what the filter took from ``thrust_noise_n`` before: at a
    regular spacing the two filters publish the same to rounding; a different D does
    not."""
    rng = np.random.default_rng(4)
    prior = TensionFilterParams()
    same = TensionFilterParams(hover_balance_density_n2s=prior.thrust_noise_n**2 * DT_S)
    other = TensionFilterParams(hover_balance_density_n2s=100.0 * prior.thrust_noise_n**2 * DT_S)
    filters = [TensionFilter(p) for p in (prior, same, other)]
    out: list[list[float]] = [[], [], []]
    for _ in range(600):
        z = rng.normal(0.0, 0.02, 3)
        h = rng.normal(0.0, 0.003, 3)
        for f, o in zip(filters, out, strict=True):
            est = f.update(z, DT_S, hover_model_world_n=h)
            o.append(float(est.tension_world_n[0]))
    np.testing.assert_allclose(out[1], out[0], rtol=1e-9, atol=1e-12)
    assert max(abs(a - b) for a, b in zip(out[2], out[0], strict=True)) > 1e-5


def test_the_service_takes_the_fitted_values_and_the_defaults_without_them() -> None:
    none = load_settings(None, {}, use_env=False).for_drone("cf1")
    default = TensionFilterParams()
    assert hover_balance_params(none.calibration) == (default.hover_wander_n2_per_s, None)
    fitted_settings = load_settings(
        None,
        {"calibration": {"hover_wander_n2_per_s": 2e-7, "hover_balance_density_n2s": 3e-7}},
        use_env=False,
    )
    pipe = Pipeline(fitted_settings)
    telemetry = (
        b'{"stamp_s": 0.0, "seq": 0, "accel_mps2": [0, 0, 9.81], "quat_wxyz": [1, 0, 0, 0],'
        b' "thrust_n": 0.3, "armed": true}'
    )
    pipe.handle(Sample("tether/cf1/telemetry", telemetry), 0.0)
    got = pipe.drones["cf1"].filter.params
    assert (got.hover_wander_n2_per_s, got.hover_balance_density_n2s) == (2e-7, 3e-7)
    for key in ("hover_wander_n2_per_s", "hover_balance_density_n2s"):
        with pytest.raises(Exception, match=key):
            load_settings(None, {"calibration": {key: 0.0}}, use_env=False)


def test_calibrate_writes_the_balance_it_fitted(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``groundstation calibrate`` on a level hover whose thrust carries a wandering
    vertical tension and white noise writes both keys; the wander where it was resolved."""
    rng = np.random.default_rng(21)
    n = round(60.0 / DT_S)
    wander = np.cumsum(rng.normal(0.0, math.sqrt(2e-7 * DT_S), n))
    noise = rng.normal(0.0, math.sqrt(1e-7 / DT_S), n)
    data = CalibrationData.from_arrays(
        np.arange(n) * DT_S,
        np.tile([0.0, 0.0, G], (n, 1)) + rng.normal(0.0, 0.1, (n, 3)),
        np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)),
        MASS_KG * G - wander + noise,  # h_z = m·g − F: the wander, plus the noise
        position_world_m=np.tile([0.5, 0.0, 1.0], (n, 1)) + rng.normal(0.0, 5e-4, (n, 3)),
    )
    rec = tmp_path / "hover.mcap"
    write_mcap(str(rec), data)
    out = tmp_path / "cal.toml"
    argv = ["calibrate", "--untethered", "--tether-detached", str(rec), "--out", str(out)]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "hover_wander_n2_per_s" in printed and "maximum likelihood" in printed
    cal = load_settings(out, use_env=False).for_drone("cf1").calibration
    # Pooled over the axes (one q_w, one D, as the filter has): x and y carry neither.
    assert cal.hover_wander_n2_per_s is not None and 1e-8 < cal.hover_wander_n2_per_s < 2e-7
    assert cal.hover_balance_density_n2s is not None
    assert 1e-8 < cal.hover_balance_density_n2s < 1e-7
