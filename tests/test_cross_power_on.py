"""A calibration that transfers from one power-on to the next.

Three power-ons of one airframe (thrust scale 0.93, thrust axis (0.02, −0.03) rad), each
with its own accelerometer bias, as a Crazyflie re-levels and re-biases at every boot.
Two are recorded with motion capture and calibrated; the third is served without motion
capture. The airframe model fits the constants and leaves each bias to its power-on (the
service learns it there, groundstation.slow_accel); the earlier accelerometer-based model
(``--model full``) writes a bias that belongs to other power-ons and carries it over.
The flights come from tests/calib_synth.py (true attitude, accelerometer = f + bias + AR(1)
noise): a test of the algebra and of what is carried, not of the simulator.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from groundstation.cli import main
from groundstation.config import Settings, load_settings
from groundstation.sim.scenarios import PAPER_HOVER_SPOTS_M
from tests.calib_synth import Truth, flight, served_position_errors, write_mcap

AIRFRAME = {"thrust_scale": 0.93, "about_x_rad": 0.02, "about_y_rad": -0.03}
BIASES = ((0.15, -0.10, 0.20), (-0.20, 0.10, -0.15), (0.10, 0.25, -0.25))
SPOTS = list(PAPER_HOVER_SPOTS_M[:4])


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, str]:
    d = tmp_path_factory.mktemp("powerons")
    files = []
    for k, bias in enumerate(BIASES[:2]):
        path = d / f"poweron{k}.mcap"
        write_mcap(str(path), flight(SPOTS, Truth(**AIRFRAME, bias_mps2=bias), seed=k + 1))
        files.append(str(path))
    cfg = d / "in.toml"
    cfg.write_text("[drone]\nmass_kg = 0.030\n[tether]\nweight_n_per_m = 0.05\n")
    airframe, full = d / "airframe.toml", d / "full.toml"
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["calibrate", *files, "--config", str(cfg), "--out", str(airframe)]) == 0
    printed = buf.getvalue()
    argv = ["calibrate", "--model", "full", *files, "--config", str(cfg), "--out", str(full)]
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(argv) == 0
    return airframe, full, printed


def _median_cm(errors: list[float]) -> float:
    return 100.0 * float(np.median(errors))


def _truth_with_own_bias() -> Settings:
    """The oracle: the airframe's constants and the held-out power-on's own bias."""
    cal = {
        "thrust_scale": AIRFRAME["thrust_scale"],
        "thrust_axis_rad": [AIRFRAME["about_x_rad"], AIRFRAME["about_y_rad"]],
        "accel_bias_mps2": list(BIASES[2]),
        "accel_slow": False,
    }
    cfg = {"drone": {"mass_kg": 0.03}, "tether": {"weight_n_per_m": 0.05}, "calibration": cal}
    return load_settings(None, cfg, use_env=False)


def test_the_constants_are_written_and_each_power_ons_bias_only_printed(
    calibrated: tuple[Path, Path, str],
) -> None:
    airframe, _, printed = calibrated
    cal = load_settings(airframe, use_env=False).for_drone("cf1").calibration
    assert abs(cal.thrust_scale - 0.93) < 0.005
    assert abs(cal.thrust_axis_rad[0] - 0.02) < 0.004
    assert abs(cal.thrust_axis_rad[1] + 0.03) < 0.004
    assert cal.accel_bias_mps2 == (0.0, 0.0, 0.0)  # nothing per power-on is carried
    assert cal.accel_slow is True
    assert "NOT written" in printed and "airframe constants (written)" in printed
    # each power-on's accelerometer offset is found (and printed) as its own
    lines = [ln for ln in printed.splitlines() if "accelerometer offset [" in ln]
    assert len(lines) == 2
    for line, bias in zip(lines, BIASES[:2], strict=True):
        found = [float(x) for x in line.split("[")[1].split("]")[0].split(",")]
        assert np.allclose(found, bias, atol=0.03), (line, bias)


@pytest.mark.parametrize("rest_s", [2.0, 0.0], ids=["rest-before-take-off", "no-rest"])
def test_a_new_power_on_is_served_as_well_as_with_its_own_bias_known(
    calibrated: tuple[Path, Path, str], rest_s: float
) -> None:
    airframe, full, _ = calibrated
    held_out = flight(SPOTS, Truth(**AIRFRAME, bias_mps2=BIASES[2]), seed=9, rest_s=rest_s)
    ours, _ = served_position_errors(load_settings(airframe, use_env=False), held_out)
    oracle, _ = served_position_errors(_truth_with_own_bias(), held_out)
    carried, _ = served_position_errors(load_settings(full, use_env=False), held_out)
    assert _median_cm(ours) <= 1.3 * _median_cm(oracle) + 1.0, (ours, oracle)
    # what carrying other power-ons' bias costs (the issue's 36 cm, in miniature)
    assert _median_cm(carried) > 3.0 * _median_cm(ours), (carried, ours)
