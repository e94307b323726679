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
from groundstation.recording.reader import copy_messages
from groundstation.sim.scenarios import PAPER_HOVER_SPOTS_M
from tests.calib_synth import (
    Truth,
    flight,
    recorded_messages,
    served_position_errors,
    write_mcap,
)

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
    cmd = [sys.executable, "-m", "groundstation", "calibrate", "--model", "full", str(a), str(b)]
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
    assert (
        main(
            [
                "calibrate",
                "--model",
                "full",
                str(a),
                str(b),
                "--config",
                str(cfg),
                "--out",
                str(out),
            ]
        )
        == 0
    )
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
    args = ["calibrate", "--model", "full", str(a), str(bad)]
    if kind == "no_mocap":
        write_mcap(str(bad), flight(list(PAPER_HOVER_SPOTS_M[:1]), TRUTH), mocap=False)
    elif kind == "too_short":
        write_mcap(str(bad), flight(list(PAPER_HOVER_SPOTS_M[:1]), TRUTH, hover_s=2.0))
    else:
        bad = a
        args = ["calibrate", "--model", "full", str(a), "--drone", "cf9"]
    out = tmp_path / "out.toml"
    assert main([*args, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert str(bad) in err and expect in err, err
    assert not out.exists()
    assert not list(tmp_path.glob(".*.partial"))


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
    assert main(["calibrate", "--model", "full", str(rec), "--out", str(out)]) == 0
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
    assert (
        main(
            [
                "calibrate",
                "--model",
                "full",
                str(a),
                str(b),
                "--config",
                str(cfg),
                "--out",
                str(out2),
            ]
        )
        == 0
    )
    assert "thrust_vbat_range_v      none" in capsys.readouterr().out
    cal2 = load_settings(out2, use_env=False).for_drone("cf1").calibration
    assert cal2.thrust_vbat_range_v is None


# ----------------------------------------------------------- rest and the thrust axis (gap 1)

AXIS_TRUTH = Truth(thrust_scale=0.93, about_y_rad=0.035, bias_mps2=(0.05, 0.0, 0.0))


def _median_cm(errors: list[float]) -> float:
    """Median error over the last two thirds of a flight's airborne estimates, cm."""
    return 100 * float(np.median(errors[len(errors) // 3 :]))


def test_without_a_rest_window_rest_is_turned_off_and_the_axis_kept(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A calibration recording without a rest window: the x/y bias is fitted and carries the
    thrust axis (fixed at 0). Written with rest = true, a flight that starts resting on the
    floor would replace that bias by the rest offset and lose the axis (the audit: 63 cm
    against 2.3 cm with the true calibration). So rest = false is written and said, and
    served on such a flight the written config errs as little as the truth."""
    spots = list(PAPER_HOVER_SPOTS_M[:4])
    rec = tmp_path / "norest.mcap"
    write_mcap(str(rec), flight(spots, AXIS_TRUTH, seed=1, rest_s=0.0, accel_noise_mps2=0.1))
    out = tmp_path / "cal.toml"
    assert main(["calibrate", "--model", "full", str(rec), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "rest = false (configured true)" in printed
    text = out.read_text()
    comments = [line for line in text.splitlines() if line.startswith("#")]
    assert any("rest = false" in c for c in comments)
    assert any("on the floor, disarmed and still for at least 1 s" in c for c in comments)
    written = load_settings(out, use_env=False)
    cal = written.for_drone("cf1").calibration
    assert cal.rest is False and cal.rest_required is False
    assert cal.thrust_axis_rad == (0.0, 0.0)  # left to the x/y bias, which carries it

    test = flight(spots, AXIS_TRUTH, seed=7, rest_s=2.0, accel_noise_mps2=0.1)  # from the floor
    fitted, _ = served_position_errors(written, test)
    # The true calibration served as the written one is (--model full writes accel_slow =
    # false: its fitted bias stands for the accelerometer's mean, so no hover either).
    truth_cfg = load_settings(
        None,
        {
            "calibration": {
                "thrust_scale": 0.93,
                "thrust_axis_rad": [0.0, 0.035],
                "accel_bias_mps2": [0.05, 0.0, 0.0],
                "accel_slow": cal.accel_slow,
            }
        },
        use_env=False,
    )
    true, pipe = served_position_errors(truth_cfg, test)
    assert pipe.status("cf1", 99.0)["rest_calibration"]["in_force"]  # type: ignore[index]
    with_rest = written.model_copy(
        update={"drones": {}, "calibration": cal.model_copy(update={"rest": True})}
    )
    lost, _ = served_position_errors(with_rest, test)
    print(  # docs/calibration.md quotes these (pytest -s)
        f"median position error: written config {_median_cm(fitted):.1f} cm, true calibration "
        f"{_median_cm(true):.1f} cm, written but rest = true {_median_cm(lost):.1f} cm"
    )
    assert _median_cm(fitted) <= 1.3 * _median_cm(true) + 0.5, (fitted, true)
    assert _median_cm(lost) > 20.0  # what rest = true would have cost


def test_with_a_rest_window_the_axis_is_fitted_and_rest_required(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    spots = list(PAPER_HOVER_SPOTS_M[:4])
    rec = tmp_path / "rest.mcap"
    write_mcap(str(rec), flight(spots, AXIS_TRUTH, seed=1, rest_s=2.0, accel_noise_mps2=0.1))
    out = tmp_path / "cal.toml"
    assert main(["calibrate", "--model", "full", str(rec), "--out", str(out)]) == 0
    assert "rest_required = true" in capsys.readouterr().out
    written = load_settings(out, use_env=False)
    cal = written.for_drone("cf1").calibration
    assert cal.rest and cal.rest_required
    assert abs(cal.thrust_axis_rad[1] - 0.035) < 0.003
    test = flight(spots, AXIS_TRUTH, seed=7, rest_s=2.0, accel_noise_mps2=0.1)
    fitted, pipe = served_position_errors(written, test)
    assert _median_cm(fitted) < 5.0
    status = pipe.status("cf1", 99.0)["rest_calibration"]  # type: ignore[index]
    assert status["required"] and status["missing_at_arming"] is False


def test_rest_stays_on_when_the_axis_is_fitted_without_full_rest_coverage(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Two recordings, one starting at rest: too few hovers carry a rest offset to leave x/y
    to it, but the still samples separate bias and axis, so the fitted x/y bias is the
    accelerometer's own and the rest calibration may replace it at the next power-on."""
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    write_mcap(str(a), flight(list(PAPER_HOVER_SPOTS_M[:2]), AXIS_TRUTH, seed=1, rest_s=2.0))
    write_mcap(str(b), flight(list(PAPER_HOVER_SPOTS_M[2:4]), AXIS_TRUTH, seed=2, rest_s=0.0))
    out = tmp_path / "cal.toml"
    assert main(["calibrate", "--model", "full", str(a), str(b), "--out", str(out)]) == 0
    assert "rest = false" not in capsys.readouterr().out
    cal = load_settings(out, use_env=False).for_drone("cf1").calibration
    assert cal.rest and not cal.rest_required
    assert abs(cal.thrust_axis_rad[1] - 0.035) < 0.005
    assert abs(cal.accel_bias_mps2[0] - 0.05) < 0.05


# ------------------------------------------------------------------ which drones (gap 3)


def test_without_drone_every_recorded_drone_is_calibrated_and_said(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    spots = list(PAPER_HOVER_SPOTS_M[:2])
    msgs = recorded_messages(flight(spots, TRUTH, seed=1), drone="cf1")
    msgs += recorded_messages(flight(spots, TRUTH, seed=2), drone="cf2")
    rec = tmp_path / "two.mcap"
    copy_messages(sorted(msgs, key=lambda m: m.log_time_ns), rec)
    out = tmp_path / "cal.toml"
    assert main(["calibrate", "--model", "full", str(rec), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "calibrating every drone in the recordings: cf1, cf2" in printed
    settings = load_settings(out, use_env=False)
    for d in ("cf1", "cf2"):
        assert abs(settings.for_drone(d).calibration.thrust_scale - 0.93) < 0.01


def test_a_drone_the_configuration_does_not_describe_needs_drone(
    recordings: tuple[Path, Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    a, _, _ = recordings  # drone cf1
    cfg = tmp_path / "lab.toml"
    cfg.write_text("[drones.cf7.base]\nposition_m = [0.0, 0.0, 0.7]\n")
    out = tmp_path / "cal.toml"
    assert (
        main(["calibrate", "--model", "full", str(a), "--config", str(cfg), "--out", str(out)]) == 2
    )
    err = capsys.readouterr().err
    assert str(a) in err and "cf1" in err and "cf7" in err and "--drone" in err
    assert not out.exists()
    # named explicitly, it is fitted with the shared tables, and that is said
    argv = [
        "calibrate",
        "--model",
        "full",
        str(a),
        "--config",
        str(cfg),
        "--drone",
        "cf1",
        "--out",
        str(out),
    ]
    assert main(argv) == 0
    assert "cf1: no [drones.cf1] in the configuration" in capsys.readouterr().out
    settings = load_settings(out, use_env=False)
    assert settings.for_drone("cf7").base.position_m == (0.0, 0.0, 0.7)  # kept
    assert abs(settings.for_drone("cf1").calibration.thrust_scale - 0.93) < 0.01


# ----------------------------------------------------------------------- --fit-tether (gap 4)


def test_fit_tether_recovers_omega_and_writes_a_loadable_config(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The paper's six spots, ω 20 % above the configured 0.05 N/m, the Reel without a base:
    ω is recovered within two standard errors; the base offset is not determined by these
    spots, fixed and said so; the written file loads with the fitted ω."""
    rec = tmp_path / "ft.mcap"
    data = flight(list(PAPER_HOVER_SPOTS_M), Truth(thrust_scale=0.95), seed=5, weight_n_per_m=0.06)
    write_mcap(str(rec), data, reel_base_m=None)
    out = tmp_path / "ft.toml"
    assert main(["calibrate", "--model", "full", str(rec), "--fit-tether", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    line = next(x for x in printed.splitlines() if "tether weight_n_per_m" in x)
    omega, se = (float(v) for v in line.split()[-3::2])
    assert se > 0 and abs(omega - 0.06) <= 2 * se, line
    for axis in ("x", "y", "z"):
        assert f"fixed base_d{axis}_m = 0: not determined by these spots" in printed
    params = load_settings(out, use_env=False).for_drone("cf1")
    assert params.tether.weight_n_per_m == pytest.approx(omega, abs=1e-4)
    assert params.base.position_m == pytest.approx((0.0, 0.0, 0.754))


def test_a_corrupt_chunk_costs_its_messages_not_the_calibration(tmp_path: Path) -> None:
    """8 flipped bytes in a middle chunk of a calibration flight: the chunk is
    skipped with a warning, the fit runs on the rest (before: a zstandard traceback, rc 1)."""
    from mcap.reader import make_reader

    from groundstation.recording.format import ChannelTable, open_writer

    rec = tmp_path / "flight.mcap"
    out_file, writer = open_writer(rec, 16 * 1024)
    channels = ChannelTable(writer)
    msgs = recorded_messages(flight(list(PAPER_HOVER_SPOTS_M[:2]), TRUTH, seed=1))
    for m in msgs:
        writer.add_message(channels.channel_id(m.key), m.log_time_ns, m.payload, m.publish_time_ns)
    writer.finish()
    out_file.commit()
    with rec.open("rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None and len(summary.chunk_indexes) > 4
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    mid = chunks[2 * len(chunks) // 3]  # in a hover, after the rest window
    data = bytearray(rec.read_bytes())
    at = mid.chunk_start_offset + mid.chunk_length // 2
    data[at : at + 8] = bytes(b ^ 0xFF for b in data[at : at + 8])
    clean = tmp_path / "clean.toml"
    assert main(["calibrate", "--model", "full", str(rec), "--out", str(clean)]) == 0
    rec.write_bytes(bytes(data))
    out = tmp_path / "cal.toml"
    assert main(["calibrate", "--model", "full", str(rec), "--out", str(out)]) == 0
    cal = load_settings(out, use_env=False).for_drone("cf1").calibration
    want = load_settings(clean, use_env=False).for_drone("cf1").calibration
    assert abs(cal.thrust_scale - want.thrust_scale) < 0.005, (cal, want)


def test_a_configured_motor_model_is_fitted_or_refused_and_never_half_written(
    recordings: tuple[Path, Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``[calibration] thrust_model = "motor_voltage"`` asks calibrate for the motor model:
    the full model cannot fit it and writes the line it fits as such; the airframe model
    needs the battery voltage and refuses recordings without it."""
    a, b, _ = recordings
    cfg = tmp_path / "motor.toml"
    cfg.write_text(
        "[drone]\nmass_kg = 0.030\n[tether]\nweight_n_per_m = 0.05\n"
        '[calibration]\nthrust_model = "motor_voltage"\n'
    )
    out = tmp_path / "full.toml"
    args = ["calibrate", "--model", "full", str(a), str(b), "--config", str(cfg)]
    assert main([*args, "--out", str(out)]) == 0
    cal = load_settings(out, use_env=False).for_drone("cf1").calibration
    assert cal.thrust_model == "vbat_linear" and abs(cal.thrust_scale - 0.93) < 0.005
    assert 'thrust_model = "vbat_linear" written' in capsys.readouterr().out
    refused = tmp_path / "airframe.toml"
    argv = ["calibrate", str(a), str(b), "--config", str(cfg), "--out", str(refused)]
    assert main(argv) == 2
    assert "needs vbat_v" in capsys.readouterr().err and not refused.exists()


def test_a_fit_outside_its_keys_range_is_said_and_not_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Exact motion capture (an ideal simulator's) gives the hover's velocity no scatter at
    all: σ_v = 0 cannot be written ([calibration] needs > 0), so calibrate says so and writes
    the rest, where it once failed with "the written configuration is invalid"."""
    data = flight([PAPER_HOVER_SPOTS_M[0]], TRUTH, seed=1, hover_s=12.0)
    # Positions on a 1 cm grid: every hover sample is its spot exactly, its velocity 0.
    exact = dataclasses.replace(data, position_world_m=np.round(data.position_world_m, 2))
    rec = tmp_path / "exact.mcap"
    write_mcap(str(rec), exact)
    out = tmp_path / "cal.toml"
    assert main(["calibrate", str(rec), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "hover velocity           not fitted: hover_velocity_std_mps = 0 is outside" in printed
    cal = load_settings(out, use_env=False).for_drone("cf1").calibration
    assert cal.hover_velocity_std_mps is None and cal.hover_velocity_time_s is None
    assert abs(cal.thrust_scale - 0.93) < 0.01  # the rest of the fit is written
