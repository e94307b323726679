"""``groundstation calibrate``: recordings in, a configuration that serve accepts out."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from groundstation.bus import Sample
from groundstation.cli import main
from groundstation.config import load_settings
from groundstation.pipeline import Pipeline
from groundstation.sim.scenarios import PAPER_HOVER_SPOTS_M
from tests.calib_synth import Truth, flight, write_mcap

TRUTH = Truth(thrust_scale=0.93, about_x_rad=0.02, about_y_rad=-0.03, bias_mps2=(0.15, -0.1, 0.2))


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    d = tmp_path_factory.mktemp("rec")
    a, b = d / "a.mcap", d / "b.mcap"
    write_mcap(str(a), flight(list(PAPER_HOVER_SPOTS_M[:2]), TRUTH, seed=1))
    write_mcap(str(b), flight(list(PAPER_HOVER_SPOTS_M[2:4]), TRUTH, seed=2))
    cfg = d / "in.toml"
    cfg.write_text("# lab config\n[drone]\nmass_kg = 0.030\n[tether]\nweight_n_per_m = 0.05\n")
    return a, b, cfg


def test_smoke_subprocess_and_round_trip(
    recordings: tuple[Path, Path, Path], tmp_path: Path
) -> None:
    a, b, cfg = recordings
    out = tmp_path / "cal.toml"
    cmd = [sys.executable, "-m", "groundstation", "calibrate", str(a), str(b)]
    cmd += ["--config", str(cfg), "--out", str(out)]
    proc = subprocess.run(
        cmd,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert "thrust_scale" in proc.stdout and "±" in proc.stdout
    assert "residual RMS" in proc.stdout and "predicted position error" in proc.stdout
    assert "fixed bias_x_mps2" in proc.stdout  # rest = true: x/y from the rest, said so
    text = out.read_text()
    assert text.startswith("# lab config\n")  # the input, kept
    assert "# groundstation calibrate" in text
    settings = load_settings(out, use_env=False)
    cal = settings.for_drone("cf1").calibration
    assert cal.source.startswith("groundstation calibrate ") and "a.mcap" in cal.source
    assert abs(cal.thrust_scale - 0.93) < 0.005
    assert abs(cal.thrust_axis_rad[0] - 0.02) < 0.004
    assert abs(cal.thrust_axis_rad[1] + 0.03) < 0.004
    assert abs(cal.accel_bias_mps2[2] - 0.2) < 0.02
    assert settings.drone.mass_kg == 0.030
    # serve's own construction accepts it: a pipeline resolves the drone and runs a sample
    pipe = Pipeline(settings)
    from groundstation.bus import Sample

    payload = (
        b'{"seq":0,"stamp_s":0.0,"accel_mps2":[0,0,9.81],"quat_wxyz":[1,0,0,0],"thrust_n":0.3}'
    )
    pipe.handle(Sample("tether/cf1/telemetry", payload), 0.0)
    assert pipe.drones["cf1"].params.calibration == cal


def test_existing_calibration_table_is_replaced(
    recordings: tuple[Path, Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    a, b, _ = recordings
    cfg = tmp_path / "old.toml"
    cfg.write_text('[drones.cf1.calibration]\nthrust_scale = 1.5\nsource = "by hand"\n')
    out = tmp_path / "new.toml"
    assert main(["calibrate", str(a), str(b), "--config", str(cfg), "--out", str(out)]) == 0
    cal = load_settings(out, use_env=False).for_drone("cf1").calibration
    assert abs(cal.thrust_scale - 0.93) < 0.005 and cal.source != "by hand"


@pytest.mark.parametrize(
    ("kind", "expect"),
    [
        ("no_mocap", "no motion capture"),
        ("too_short", "too short"),
        ("wrong_drone", "no telemetry from drone 'cf9'"),
    ],
)
def test_bad_input_one_line_exit_2_nothing_written(
    kind: str,
    expect: str,
    recordings: tuple[Path, Path, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    a, _, _ = recordings
    bad = tmp_path / f"{kind}.mcap"
    args = ["calibrate", str(a), str(bad)]
    if kind == "no_mocap":
        write_mcap(str(bad), flight(list(PAPER_HOVER_SPOTS_M[:1]), TRUTH), mocap=False)
    elif kind == "too_short":
        write_mcap(str(bad), flight(list(PAPER_HOVER_SPOTS_M[:1]), TRUTH, hover_s=2.0))
    else:
        bad = a
        args = ["calibrate", str(a), "--drone", "cf9"]
    out = tmp_path / "out.toml"
    assert main([*args, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert str(bad) in err and expect in err, err
    assert not out.exists()
    assert not list(tmp_path.glob(".calibrate-*"))


def test_the_calibrated_battery_range_is_written_and_flagged_at_run_time(
    recordings: tuple[Path, Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """calibrate writes thrust_vbat_range_v (the hovers' vbat_v, rounded outward); serve's
    pipeline flags Telemetry outside it; recordings without vbat_v write none and drop a
    stale per-drone range from the input."""
    a, b, _ = recordings
    sag = dataclasses.replace(TRUTH, vbat_slope_per_v=0.3)
    rec = tmp_path / "sag.mcap"
    data = flight(list(PAPER_HOVER_SPOTS_M[:4]), sag, seed=3, vbat_v=(4.05, 3.85))
    write_mcap(str(rec), data)
    out = tmp_path / "cal.toml"
    assert main(["calibrate", str(rec), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "thrust_vbat_range_v      [" in printed
    cal = load_settings(out, use_env=False).for_drone("cf1").calibration
    assert cal.thrust_vbat_range_v is not None
    lo, hi = cal.thrust_vbat_range_v
    # the hovers' range: within the flight's 3.85-4.05 V, most of it (moves are excluded)
    assert 3.85 <= lo < 3.9 and 4.0 < hi <= 4.05
    hover = data.vbat_v[np.isfinite(data.vbat_v)]
    assert lo <= hover.min() + 0.05 and hi >= hover.max() - 0.05
    assert round(lo, 3) == lo and round(hi, 3) == hi
    assert abs(cal.thrust_vbat_slope_per_v - 0.3) < 0.05  # the spread determines the slope

    pipe = Pipeline(load_settings(out, use_env=False))
    flags = []
    for k, v in enumerate([4.0] * 250 + [lo - 0.05]):
        body = (
            f'{{"seq":{k},"stamp_s":{k * 0.004},"accel_mps2":[0,0,9.81],'
            f'"quat_wxyz":[1,0,0,0],"thrust_n":0.3,"vbat_v":{v},"position_m":[1,0,1]}}'
        )
        (o,) = pipe.handle(Sample("tether/cf1/telemetry", body.encode()), k * 0.004)
        flags.append(json.loads(o.payload)["calibration_extrapolated"])
    assert flags[249] is False and flags[-1] is True

    # no vbat_v in the recordings: no range, and an earlier one for this drone is dropped
    cfg = tmp_path / "old.toml"
    cfg.write_text("[drones.cf1.calibration]\nthrust_vbat_range_v = [3.9, 4.0]\n")
    out2 = tmp_path / "cal2.toml"
    assert main(["calibrate", str(a), str(b), "--config", str(cfg), "--out", str(out2)]) == 0
    assert "thrust_vbat_range_v      none" in capsys.readouterr().out
    cal2 = load_settings(out2, use_env=False).for_drone("cf1").calibration
    assert cal2.thrust_vbat_range_v is None
