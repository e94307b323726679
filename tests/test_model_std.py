"""The calibration's own error in the published σ (``[calibration] tension_model_std_n``).

The filter's σ is what averaging the vibration leaves; the error a calibration leaves (its
fit's residual: the thrust/attitude model against the motion-capture force) does not
average away. ``calibrate`` writes it, and the Estimate's ``tension_std_n`` carries it in
quadrature, in the air only (on the ground no tension is estimated).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
from pathlib import Path

import numpy as np
import pytest

from groundstation.airframe import AirframeFit
from groundstation.bus import Sample
from groundstation.cli import main
from groundstation.config import ConfigError, load_settings
from groundstation.pipeline import Pipeline
from tests.calib_synth import Truth, flight, write_mcap
from tests.hover_synth import hover_body

MASS_KG = 0.030
TENSION_N = np.array([-0.015, 0.005, -0.040])


def _estimates(cfg: dict, *, armed: bool = True) -> list[dict]:
    pipe = Pipeline(load_settings(None, cfg, use_env=False))
    rng = np.random.default_rng(1)
    out = []
    for k in range(1500):
        body = hover_body(k, TENSION_N, rng, mass_kg=MASS_KG, dt_s=0.004, armed=armed)
        for s in pipe.handle(Sample("tether/cf1/telemetry", json.dumps(body).encode()), k * 0.004):
            if s.key.endswith("/estimate"):
                out.append(json.loads(s.payload))
    return out


def _stds(cfg: dict, *, armed: bool = True) -> np.ndarray:
    return np.array([e["tension_std_n"] for e in _estimates(cfg, armed=armed)])


def test_the_position_sigma_carries_it_too_and_the_position_stays() -> None:
    """The position's σ is computed from the filter's covariance plus the model's variance
    (localization's ``model_var_n2``); the position itself does not move."""
    model = [0.004, 0.003, 0.005]
    plain = _estimates({"drone": {"mass_kg": MASS_KG}})[-1]
    cal = {"thrust_scale": 1.0, "source": "test", "tension_model_std_n": model}
    wide = _estimates({"drone": {"mass_kg": MASS_KG}, "calibration": cal})[-1]
    assert plain["position_m"] is not None and wide["position_m"] is not None
    np.testing.assert_allclose(wide["position_m"], plain["position_m"], atol=1e-12)
    assert np.all(np.array(wide["position_std_m"]) > 2.0 * np.array(plain["position_std_m"]))


def test_the_published_sigma_carries_the_calibrations_error_in_the_air_only() -> None:
    model = [0.004, 0.003, 0.005]
    plain = _stds({"drone": {"mass_kg": MASS_KG}})
    cal = {"thrust_scale": 1.0, "source": "test", "tension_model_std_n": model}
    with_model = _stds({"drone": {"mass_kg": MASS_KG}, "calibration": cal})
    np.testing.assert_allclose(with_model[-1], np.sqrt(plain[-1] ** 2 + np.square(model)))
    assert np.all(with_model[-1] > model)
    on_floor = _stds({"drone": {"mass_kg": MASS_KG}, "calibration": cal}, armed=False)
    assert np.all(on_floor == 0.0), "no tension estimated on the ground, no σ added"


def test_the_key_refuses_nonsense() -> None:
    for bad in ([-0.001, 0.0, 0.0], [math.nan, 0.0, 0.0], [2.0, 0.0, 0.0]):
        with pytest.raises(ConfigError, match="tension_model_std_n"):
            load_settings(None, {"calibration": {"tension_model_std_n": bad}}, use_env=False)


def test_model_std_is_the_residual_with_the_fits_degrees_of_freedom_taken_back() -> None:
    fit = AirframeFit(
        values={},
        std={},
        fixed={"rotor_drag_n_s_per_m": "fixed"},
        flights=(),
        rms_before_n=np.zeros(3),
        rms_after_n=np.array([0.004, 0.004, 0.002]),
        samples=1000,
        n_eff=24.0,
        vbat_ref_v=3.7,
        vbat_range_v=None,
        tethered=True,
    )
    free = len(fit.parameters) - 1
    np.testing.assert_allclose(fit.model_std_n, fit.rms_after_n * math.sqrt(24.0 / (24.0 - free)))


def test_calibrate_writes_it(tmp_path: Path) -> None:
    files = []
    for k in range(2):
        path = tmp_path / f"f{k}.mcap"
        data = flight([(0.5, 0.0, 1.0), (0.3, 0.4, 1.1)], Truth(thrust_scale=0.95), seed=k)
        write_mcap(str(path), data)
        files.append(str(path))
    cfg = tmp_path / "in.toml"
    cfg.write_text("[drone]\nmass_kg = 0.030\n[tether]\nweight_n_per_m = 0.05\n")
    out = tmp_path / "cal.toml"
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(["calibrate", *files, "--config", str(cfg), "--out", str(out)]) == 0
    written = load_settings(out, use_env=False).for_drone("cf1").calibration
    std = np.array(written.tension_model_std_n)
    said = f"[{std[0] * 1e3:.1f}, {std[1] * 1e3:.1f}, {std[2] * 1e3:.1f}] mN"
    assert f"tension_model_std_n      {said}" in printed.getvalue()
    # the generator's noise (0.2 m/s² AR(1) on 30 g: ~6 mN per sample) smoothed by the fit's
    # samples is all that is left: positive, a few mN, not more
    assert np.all(std > 0.0) and np.all(std < 0.02), std
