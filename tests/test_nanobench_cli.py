"""Real flights through the command line: ``calibrate --untethered`` on two power-ons of
two days, a third day's flight served without motion capture.

NanoBench excerpts (tests/data/nanobench/, 25 Hz; real Crazyflie 2.1, untethered, so the
true tension is zero). The nominal PWM map reads ~200 mN of tension that is not there;
calibrated, the served estimate must be near zero on a flight of another day and shape.
The full-rate figures on all six shared flights are benchmarks/nanobench_cli.py's
(docs/nanobench_cli.md).
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import pytest

from benchmarks import nanobench_cli as nb
from groundstation.cli import main
from groundstation.config import load_settings

DATA = Path(__file__).resolve().parent / "data" / "nanobench"
TRAIN = ("B3_figure8_fast_rep1", "B6_linear_ramp_rep3")
HELD_OUT = "B5_helix_medium_rep3"


@pytest.fixture(scope="module")
def work(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    d = tmp_path_factory.mktemp("nanobench")
    (d / "base.toml").write_text(nb.CONFIG)
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        cal, _ = nb.calibrate([nb.load(n, DATA) for n in TRAIN], d, "cli", [])
    return cal, buf.getvalue()


def test_calibrate_untethered_writes_the_airframe_and_no_bias(work: tuple[Path, str]) -> None:
    cal_path, _ = work
    cal = load_settings(cal_path, use_env=False).for_drone("cf1").calibration
    # The motor-voltage model (the benchmark's configuration): one motor's thrust at the
    # calibration's median motor voltage near a quarter of the 30 g weight (0.074 N), where
    # the nominal map over-reads by 1.6–1.9× (the data README); the exponent in its bounds.
    assert cal.thrust_model == "motor_voltage" and cal.thrust_motor_ref_n is not None
    assert 0.06 < cal.thrust_motor_ref_n < 0.09, cal.thrust_motor_ref_n
    assert 1.0 <= cal.thrust_motor_exponent <= 2.0
    assert cal.thrust_scale == 1.0 and cal.thrust_vbat_slope_per_v == 0.0
    assert cal.accel_bias_mps2 == (0.0, 0.0, 0.0)
    assert cal.rotor_drag_n_s_per_m > 0.002  # fast flights: the rotors' drag is seen
    assert cal.attitude_source == "onboard"  # the drone's own attitude was recorded
    assert cal.accel_slow is True
    assert "untethered (reference tension zero)" in cal_path.read_text()


def test_a_flight_of_another_day_served_without_motion_capture(
    work: tuple[Path, str], tmp_path: Path
) -> None:
    cal_path, _ = work
    flight = nb.load(HELD_OUT, DATA)
    ours = nb.judge(flight, cal_path, tmp_path)
    base = tmp_path / "nominal.toml"
    base.write_text(nb.CONFIG)
    nominal = nb.judge(flight, base, tmp_path)
    assert nominal.median_abs_t_mn > 100.0, nominal  # the nominal map's phantom tension
    assert ours.median_abs_t_mn < 16.0, ours  # the per-flight bound (full rate: 6.6)
    print(
        f"held-out median |T| {ours.median_abs_t_mn:.1f} mN "
        f"(nominal map {nominal.median_abs_t_mn:.0f})"
    )
    assert ours.answered >= 0.98 and ours.airborne_not_on_ground >= 0.9, ours


def test_calibrate_untethered_refuses_a_recording_without_motion_capture(
    tmp_path: Path,
) -> None:
    flight = nb.load(HELD_OUT, DATA)
    rec = tmp_path / "nomocap.mcap"
    from groundstation.recording.reader import copy_messages

    copy_messages(flight.without_mocap, rec)
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        rc = main(["calibrate", "--untethered", str(rec), "--out", str(tmp_path / "x.toml")])
    assert rc == 2
    assert "no motion capture" in err.getvalue()
    assert not (tmp_path / "x.toml").exists()


@pytest.mark.parametrize("missing", ["no_such_dir", "empty_dir"])
def test_the_benchmark_without_its_flights_says_where_they_go(
    tmp_path: Path, missing: str, capsys: pytest.CaptureFixture[str]
) -> None:
    data = tmp_path / missing
    if missing == "empty_dir":
        data.mkdir()
    with pytest.raises(SystemExit) as exit_info:
        nb.main(["--data", str(data)])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert f"--data {data}: " in err and "not in the repository: pass --data DIR" in err
    assert ("no such directory" in err) == (missing == "no_such_dir")
    assert "Traceback" not in err
