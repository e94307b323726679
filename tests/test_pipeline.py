"""The pipeline seam against the simulator's truth, and its handling of bad input."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from groundstation.bus import Sample
from groundstation.config import Settings, load_settings
from groundstation.evaluation import closed_loop, settings_for
from groundstation.pipeline import Pipeline, exit_azimuth_default_std_rad

EXACT = {"calibration": {"source": "ideal simulator: exact sensors"}}
"""The ideal profile's sensors are exact: declared as the calibration in force, so that
follow runs without motion capture (uncalibrated it is refused there)."""

GOOD = {
    "seq": 0,
    "stamp_s": 0.0,
    "accel_mps2": [0.0, 0.0, 9.81 + 1.0],
    "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
    "thrust_n": 0.33,
}


def _telemetry(seq: int, **patch: object) -> Sample:
    body = GOOD | {"seq": seq, "stamp_s": seq * 0.004} | patch
    return Sample("tether/cf1/telemetry", json.dumps(body).encode())


def test_hover_without_mocap_matches_truth() -> None:
    run, pipe, _ = closed_loop(settings_for(mocap=False, seed=1), "hover", 12.0)
    assert len(run.estimates) == run.telemetry, "one estimate per accepted telemetry"
    assert [e["seq"] for e in run.estimates] == list(range(run.telemetry))
    late = [e for e in run.estimates if e["stamp_s"] > 7.0]
    pos_err = [
        np.linalg.norm(np.subtract(e["position_m"], run.truth_at(e["stamp_s"])["position_m"]))
        for e in late
    ]
    ten_err = [np.subtract(e["tension_n"], run.truth_at(e["stamp_s"])["tension_n"]) for e in late]
    assert float(np.median(pos_err)) < 0.05
    assert float(np.percentile(pos_err, 95)) < 0.10
    assert np.all(np.sqrt(np.mean(np.square(ten_err), axis=0)) < 1.5e-3)
    assert not run.setpoints and not run.stops
    status = pipe.status("cf1", 12.0)
    assert status is not None and status["accepted"] == run.telemetry and status["drops"] == {}


@pytest.mark.parametrize(
    ("sample", "kind"),
    [
        (Sample("tether/cf1/telemetry", b"not json"), "not_json"),
        (Sample("tether/cf1/telemetry", b'{"seq": 1}'), "invalid"),
        (Sample("tether/cf1/telemetry", b"[]"), "invalid"),
        (_telemetry(5, thrust_n=-1.0), "invalid"),
        (_telemetry(5, quat_wxyz=[0.0, 0.0, 0.0, 0.0]), "bad_quaternion"),
        (_telemetry(5, accel_mps2=[0.0, 0.0]), "invalid"),
        (Sample("tether/cf1/telemetry", b'{"seq": 5, "stamp_s": NaN}'), "invalid"),
        (Sample("tether/cf1/telemetry", b"x" * 2_000_000), "too_large"),
        (Sample("tether/" + "d" * 65 + "/telemetry", json.dumps(GOOD).encode()), "bad_drone_id"),
        (Sample("tether/cf1/reel", b'{"stamp_s": 0, "length_m": -1}'), "invalid"),
        (Sample("tether/cf1/follow", b'{"enabled": "yes"}'), "invalid"),
    ],
)
def test_bad_input_is_dropped_and_counted(sample: Sample, kind: str) -> None:
    pipe = Pipeline(settings_for())
    assert len(pipe.handle(_telemetry(0), 0.0)) == 1
    before = pipe.status("cf1", 0.0)
    assert before is not None
    assert pipe.handle(sample, 0.01) == []
    after = pipe.status("cf1", 0.01)
    assert after is not None
    drops = after["drops"] if kind != "bad_drone_id" else dict(pipe.global_drops)
    assert drops.get(kind) == 1
    assert after["accepted"] == before["accepted"]
    # still serving: the next good message gets its estimate
    out = pipe.handle(_telemetry(6), 0.02)
    assert [json.loads(o.payload)["seq"] for o in out] == [6]


def test_seq_backwards_and_repeated_are_dropped() -> None:
    pipe = Pipeline(settings_for())
    assert pipe.handle(_telemetry(10), 0.0)
    assert pipe.handle(_telemetry(9), 0.004) == []
    assert pipe.handle(_telemetry(10), 0.008) == []
    assert pipe.handle(_telemetry(11), 0.012)
    status = pipe.status("cf1", 0.012)
    assert status is not None
    assert status["drops"] == {"seq_backwards": 1, "seq_repeated": 1}


def test_drone_restart_after_silence_is_accepted() -> None:
    pipe = Pipeline(settings_for())
    assert pipe.handle(_telemetry(500), 0.0)
    pipe.tick(2.0)
    status = pipe.status("cf1", 2.0)
    assert status is not None and status["stale"] is True
    assert pipe.handle(_telemetry(0), 2.0), "a rebooted drone starts again at seq 0"


def test_silence_without_ticks_restarts_at_the_stale_time() -> None:
    """The gate's restart after silence is ``[service] stale_after_s``, the service's
    stale time: a pipeline driven without ticks (a script, a test) resumes where the
    service's tick would have marked the drone stale, not later."""
    settings = settings_for()
    stale_s = settings.service.stale_after_s
    pipe = Pipeline(settings)
    assert pipe.handle(_telemetry(500), 0.0)
    assert pipe.handle(_telemetry(0), stale_s) == [], "within the stale time: seq backwards"
    assert pipe.handle(_telemetry(0), stale_s + 0.01), "past it: a new stream"
    longer = settings.model_copy(
        update={"service": settings.service.model_copy(update={"stale_after_s": 2 * stale_s})}
    )
    pipe = Pipeline(longer)
    assert pipe.handle(_telemetry(500), 0.0)
    assert pipe.handle(_telemetry(0), stale_s + 0.01) == [], "the configured time, not 0.5 s"
    assert pipe.handle(_telemetry(0), 2 * stale_s + 0.01)


def test_ground_contact_gives_no_tension() -> None:
    pipe = Pipeline(settings_for())
    for seq, patch in enumerate([{"armed": False}, {"thrust_n": 0.1}]):
        (out,) = pipe.handle(_telemetry(seq, **patch), seq * 0.004)
        est = json.loads(out.payload)
        assert est["on_ground"] is True
        assert est["tension_n"] == [0.0, 0.0, 0.0] and est["position_m"] is None


def test_stale_drone_disengages_follow_and_publishes_nothing() -> None:
    pipe = Pipeline(load_settings(None, EXACT, use_env=False))
    pipe.handle(_telemetry(0), 0.0)
    pipe.handle(Sample("tether/cf1/follow", b'{"enabled": true}'), 0.01)
    (out,) = pipe.handle(_telemetry(1), 0.02)
    assert json.loads(out.payload)["follow"]["enabled"] is True
    assert pipe.tick(0.3) == []
    assert pipe.drones["cf1"].follow_state.enabled is True
    assert pipe.tick(0.6) == []
    assert pipe.drones["cf1"].stale is True
    assert pipe.drones["cf1"].follow_state.enabled is False


def test_motion_capture_is_held_between_frames_and_follow_stops_trusting_without_it() -> None:
    """Motion capture reaches telemetry at its own rate (70-116 Hz, gaps to 150 ms): a frame
    stays the external position for MOCAP_HOLD_S of telemetry time, so follow does not fall
    back to the tether-based position between frames. Uncalibrated, with no frame for longer
    than that, follow holds off (no setpoint, the reason says why) instead of flying to the
    tether-based position; a frame again and it trusts the position again."""
    from groundstation.pipeline import MOCAP_HOLD_S, UNTRUSTED_POSITION_REASON

    pipe = Pipeline(settings_for())
    at = [1.0, 0.0, 1.0]
    pipe.handle(_telemetry(0, position_m=at), 0.0)
    pipe.handle(Sample("tether/cf1/follow", b'{"enabled": true}'), 0.001)
    reasons = []
    for seq in range(1, 200):  # a frame on the first sample only, then none for 0.8 s
        (out,) = pipe.handle(_telemetry(seq), seq * 0.004)
        reasons.append((seq * 0.004, json.loads(out.payload)["follow"]["reason"]))
    held = [r for t, r in reasons if t <= MOCAP_HOLD_S]
    after = [r for t, r in reasons if t > MOCAP_HOLD_S]
    assert held and UNTRUSTED_POSITION_REASON not in held
    assert after and all(r == UNTRUSTED_POSITION_REASON for r in after)
    assert pipe.drones["cf1"].follow_state.enabled, "held off, not switched off"
    (out,) = pipe.handle(_telemetry(200, position_m=at), 0.8)
    assert json.loads(out.payload)["follow"]["reason"] != UNTRUSTED_POSITION_REASON


def test_reel_params_and_follow_command_apply() -> None:
    pipe = Pipeline(load_settings(None, EXACT, use_env=False))
    pipe.handle(_telemetry(0), 0.0)
    pipe.handle(Sample("tether/cf1/params", b'{"weight_n_per_m": 0.07, "length_m": 2.0}'), 0.0)
    status = pipe.status("cf1", 0.0)
    assert status is not None
    assert status["weight_n_per_m"] == 0.07 and status["length_m"] == 2.0
    assert status["length_source"] == "operator"
    pipe.handle(Sample("tether/cf1/reel", b'{"stamp_s": 1, "length_m": 1.4, "base_m": [1,2,0]}'), 0)
    pipe.handle(Sample("tether/cf1/params", b'{"length_m": 3.0}'), 0.0)
    status = pipe.status("cf1", 0.0)
    assert status is not None
    assert status["length_m"] == 1.4 and status["length_source"] == "reel"
    assert status["base_m"] == [1.0, 2.0, 0.0]
    cmd = b'{"enabled": true, "threshold_n": 0.2, "land_below_m": 0.3}'
    pipe.handle(Sample("tether/cf1/follow", cmd), 0.0)
    (out,) = pipe.handle(_telemetry(1), 0.004)
    follow = json.loads(out.payload)["follow"]
    assert follow["enabled"] is True and follow["threshold_n"] == 0.2
    assert follow["land_below_m"] == 0.3
    pipe.handle(Sample("tether/cf1/follow", b'{"enabled": true, "land": false}'), 0.0)
    (out,) = pipe.handle(_telemetry(2), 0.008)
    assert json.loads(out.payload)["follow"]["land_below_m"] is None
    pipe.handle(Sample("tether/cf1/follow", b'{"enabled": false, "land": true}'), 0.0)
    (out,) = pipe.handle(_telemetry(3), 0.012)
    follow = json.loads(out.payload)["follow"]
    assert follow["land_below_m"] == 0.3 and follow["enabled"] is False


def test_follow_only_when_enabled_and_tug_landing_stops_once() -> None:
    run, _, sim = closed_loop(settings_for(seed=3), "tug_landing", 16.0)
    assert all(sp["stamp_s"] >= 3.0 for sp in run.setpoints)
    assert run.setpoints, "the pull engages follow mode"
    assert len(run.stops) == 1
    z_at_stop = run.truth_at(run.stops[0]["stamp_s"])["position_m"][2]
    assert z_at_stop < 0.25 + 0.02
    assert not sim.drones["cf1"].armed
    reach = 1.6
    for sp in run.setpoints:
        assert np.linalg.norm(np.subtract(sp["position_m"], [0.0, 0.0, 0.754])) <= reach


NOISE_MPS2 = 2.0
"""The realistic tests' accelerometer noise: the worst of the real flights'."""


def _realistic(seed: int, *, mocap: bool, calibration: dict[str, object] | None) -> Settings:
    """The realistic profile at 2 m/s^2, every error class at its real size, as the realistic
    benchmark flies it; ``calibration`` None leaves ``[calibration]`` at its defaults."""
    from benchmarks.bench_realistic import _settings

    return _settings(NOISE_MPS2, seed, {}, calibration, mocap)  # type: ignore[arg-type]


def _true_calibration(seed: int) -> dict[str, object]:
    """The flight's drawn sensor errors as ``[calibration]`` (the simulator's equivalent)."""
    from benchmarks.bench_realistic import _true_calibration as truth

    return truth(NOISE_MPS2, seed, {})


def test_uncalibrated_without_mocap_follow_is_refused_and_nothing_moves() -> None:
    """Uncalibrated, the tether-based height of the realistic drone at 0.9 m reads most of a
    metre low: followed anyway, tug-to-land stopped the motors with the drone at up to 0.9 m
    (docs/realistic_benchmark.md, rows *none, declared*). So without motion capture and
    without a calibration the service refuses follow: the
    operator's command is rejected (counted), no setpoint, no Stop, the drone flies on."""
    settings = _realistic(11, mocap=False, calibration=None)
    run, pipe, sim = closed_loop(settings, "tug_landing", 16.0)
    assert not run.setpoints and not run.stops
    assert sim.drones["cf1"].armed
    assert not any(e["follow"]["enabled"] for e in run.estimates)
    status = pipe.status("cf1", 16.0)
    assert status is not None and status["drops"].get("follow_refused") == 1


def test_calibrated_without_mocap_tug_landing_stops_once_near_the_floor() -> None:
    """The same flight with the calibration = the drawn truth: the pull engages following,
    exactly one Stop after the pull began, with the drone low (true z below 0.4 m)."""
    settings = _realistic(11, mocap=False, calibration=_true_calibration(11))
    run, _, sim = closed_loop(settings, "tug_landing", 16.0)
    assert run.setpoints and all(sp["stamp_s"] >= 3.0 for sp in run.setpoints)
    assert len(run.stops) == 1 and run.stops[0]["stamp_s"] >= 6.0
    assert run.truth_at(run.stops[0]["stamp_s"])["position_m"][2] < 0.4
    assert not sim.drones["cf1"].armed


def test_uncalibrated_with_mocap_hover_follow_on_and_nobody_pulling() -> None:
    """Follow on (the default 0.10 N threshold, tug-to-land at 0.5 m) on a biased, vibrating
    drone with motion capture that nobody pulls: the biases read as a steady tension, which
    is the tether's own, so following never engages: no setpoint, no Stop, landing not armed."""
    settings = _realistic(12, mocap=True, calibration=None)
    enable = Sample("tether/cf1/follow", b'{"enabled": true, "land_below_m": 0.5}')
    run, _, _ = closed_loop(
        settings, "hover", 20.0, inject={round(3.0 * settings.sim.rate_hz): [enable]}
    )
    late = [e for e in run.estimates if e["stamp_s"] > 3.5]
    assert late and all(e["follow"]["enabled"] for e in late), "follow was switched on"
    assert not any(e["follow"]["active"] or e["follow"]["landing_armed"] for e in run.estimates)
    assert not run.setpoints and not run.stops


@pytest.mark.parametrize("calibrated", [False, True], ids=["uncalibrated", "calibrated"])
def test_realistic_spool_up_with_follow_on_publishes_no_floor_push_and_no_stop(
    calibrated: bool,
) -> None:
    """On the realistic profile (2 m/s^2 vibration, drawn biases, motor lag,
    thrust map 10 % off): armed on the floor, the thrust ramps to the weight over 2 s, then
    the drone climbs; follow with tug-to-land at 0.3 m is on from the start (motion capture
    present). On the floor no tension above 20 mN is published and landing is never armed;
    no setpoint, no Stop at all."""
    cal = _true_calibration(13) if calibrated else None
    settings = _realistic(13, mocap=True, calibration=cal)
    follow = Sample("tether/cf1/follow", b'{"enabled": true, "land_below_m": 0.3}')
    # at 0.5 s: motion capture has reached the telemetry by then (uncalibrated, follow is
    # refused until it has)
    at = round(0.5 * settings.sim.rate_hz)
    run, _, sim = closed_loop(settings, "takeoff_ramp", 10.0, inject={at: [follow]})
    assert not run.stops and not run.setpoints and sim.drones["cf1"].armed
    floor = [e for e in run.estimates if run.truth_at(e["stamp_s"])["on_ground"]]
    assert [e for e in floor if e["stamp_s"] >= 2.0], "the ramp is on the floor"
    assert max(float(np.linalg.norm(e["tension_n"])) for e in floor) <= 0.020
    assert not any(e["follow"]["landing_armed"] or e["follow"]["active"] for e in run.estimates)
    assert all(e["follow"]["enabled"] for e in run.estimates if e["stamp_s"] > 0.6)


@pytest.mark.parametrize("calibrated", [False, True], ids=["uncalibrated", "calibrated"])
@pytest.mark.parametrize("seed", [2, 13, 21])
def test_realistic_take_off_without_mocap_publishes_no_floor_push_and_no_stop(
    seed: int, calibrated: bool
) -> None:
    """On the realistic profile *without* motion capture (2 m/s^2 vibration,
    drawn biases, motor lag, the thrust map ~15 % low uncalibrated): spool-up over 2 s,
    ~3 s on the floor at hover thrust, then the climb; follow with tug-to-land at 0.3 m on
    from the start. While the simulator's truth says the drone is on the floor no tension
    above 20 mN is published (before: 27-63 mN, the climb rule firing on vibration and the
    filter restarting with the prior's noise); no setpoint, no Stop, landing never armed;
    the take-off is seen by the time the drone is 5 cm up."""
    settings = _realistic(
        seed, mocap=False, calibration=_true_calibration(seed) if calibrated else None
    )
    follow = Sample("tether/cf1/follow", b'{"enabled": true, "land_below_m": 0.3}')
    run, _, sim = closed_loop(settings, "takeoff_ramp", 6.0, inject={0: [follow]})
    assert not run.stops and not run.setpoints and sim.drones["cf1"].armed
    floor = [e for e in run.estimates if run.truth_at(e["stamp_s"])["on_ground"]]
    assert [e for e in floor if e["stamp_s"] >= 4.0], "the premise: on the floor at hover thrust"
    assert max(float(np.linalg.norm(e["tension_n"])) for e in floor) <= 0.020
    assert not any(e["follow"]["landing_armed"] or e["follow"]["active"] for e in run.estimates)
    up_5cm_s = min(
        e["stamp_s"] for e in run.estimates if run.truth_at(e["stamp_s"])["position_m"][2] > 0.05
    )
    seen_s = min(e["stamp_s"] for e in run.estimates if e["stamp_s"] > 1.0 and not e["on_ground"])
    assert seen_s <= up_5cm_s, (seen_s, up_5cm_s)


def _near_taut_scenario(
    monkeypatch: pytest.MonkeyPatch, name: str, length_m: float, fraction: float, pull_n: float
) -> None:
    """Hover at ``fraction`` of the tether's reach, 0.3 m above the base; follow and
    tug-to-land (0.5 m) switched on at 1 s; a ``pull_n`` pull toward the base at 6-8 s."""
    from groundstation.sim.scenarios import SCENARIOS, Pull, Scenario, Waypoint

    base = (0.0, 0.0, 0.754)
    chord = fraction * length_m
    spot = (float(np.sqrt(chord**2 - 0.3**2)), 0.0, base[2] + 0.3)
    monkeypatch.setitem(
        SCENARIOS,
        name,
        Scenario(
            name,
            f"hover near taut; follow on at 1 s; a {pull_n:g} N pull toward the base at 6 s",
            start_m=spot,
            waypoints=(Waypoint(0.0, spot),),
            length_m=length_m,
            pulls=(Pull(6.0, 8.0, (-pull_n, 0.0, 0.0)),),
            operator=((1.0, {"enabled": True, "land_below_m": 0.5}),),
        ),
    )


@pytest.mark.parametrize("fraction", [0.97, 0.90])
def test_realistic_near_taut_with_follow_on_and_nobody_pulling(
    monkeypatch: pytest.MonkeyPatch, fraction: float
) -> None:
    """On the realistic profile (lumped-mass tether of its own, 2 m/s^2
    vibration, drawn biases uncorrected, motion capture): hovering at 97 % and 90 % of the
    1.6 m tether's reach (there the tether alone pulls 0.105 N and 0.066 N, against the
    0.10 N threshold) with follow and tug-to-land on and nobody pulling: following never
    engages, no setpoint, no Stop, landing not armed; a 0.15 N pull at 6 s engages."""
    _near_taut_scenario(monkeypatch, "near_taut_realistic", 1.6, fraction, 0.15)
    run, _, _ = closed_loop(
        _realistic(14, mocap=True, calibration=None), "near_taut_realistic", 8.0
    )
    quiet = [e for e in run.estimates if 1.1 < e["stamp_s"] < 6.0]
    assert quiet and all(e["follow"]["enabled"] for e in quiet)
    own = [np.linalg.norm(run.truth_at(e["stamp_s"])["tension_n"]) for e in quiet]
    assert float(np.median(own)) > (0.10 if fraction > 0.95 else 0.05), "the premise"
    assert not any(e["follow"]["active"] or e["follow"]["landing_armed"] for e in quiet)
    assert all(sp["stamp_s"] >= 6.0 for sp in run.setpoints), "no setpoint before the pull"
    assert not run.stops
    pulled = [e for e in run.estimates if 6.0 <= e["stamp_s"] < 8.0]
    assert any(e["follow"]["active"] for e in pulled), "a real pull engages"


def test_no_nan_ever_published() -> None:
    run, _, _ = closed_loop(settings_for(seed=4), "reel_in", 16.0)
    for e in run.estimates:
        values = [*e["tension_n"], *e["tension_std_n"], e["horizontal_n"], e["vertical_n"]]
        values += e["position_m"] or []
        assert np.all(np.isfinite(values))


def test_calibration_is_applied_and_reported_per_drone() -> None:
    """[calibration] and [drones.<id>.calibration] reach the observation and the reports."""
    from groundstation.config import load_settings

    settings = load_settings(
        None,
        {
            "calibration": {"thrust_scale": 1.1, "source": "cal.toml 2026-12-01"},
            "drones": {"cf2": {"calibration": {"thrust_scale": 1.0, "source": "none"}}},
        },
        use_env=False,
    )
    pipe = Pipeline(settings)
    # position_m: motion capture at 1 m, so the contact rules see the drone in the air at once
    level = GOOD | {
        "accel_mps2": [0.0, 0.0, 9.81],
        "thrust_n": 0.30,
        "vbat_v": 3.7,
        "position_m": [1.0, 0.0, 1.0],
    }
    outs = {}
    for drone in ("cf1", "cf2"):
        # 1 s of level hover: the contact state starts on the ground and finds the drone in
        # the air once the floor visibly carries nothing (groundstation.contact).
        for k in range(250):
            body = json.dumps(level | {"seq": k, "stamp_s": k * 0.004}).encode()
            (out,) = pipe.handle(Sample(f"tether/{drone}/telemetry", body), k * 0.004)
        outs[drone] = json.loads(out.payload)
    # m f - F: cf1 thrust 0.30 * 1.1 = 0.33 N against m g = 0.2943 N: 35.7 mN downward pull
    # (the filtered estimate, from the lift-off prior of 0: within 2 mN after 1 s).
    assert outs["cf1"]["tension_n"][2] == pytest.approx(0.030 * 9.81 - 0.33, abs=2e-3)
    assert outs["cf2"]["tension_n"][2] == pytest.approx(0.030 * 9.81 - 0.30, abs=2e-3)
    assert outs["cf1"]["calibration"] == "cal.toml 2026-12-01"
    assert outs["cf2"]["calibration"] == "none"
    status1, status2 = pipe.status("cf1", 0.0), pipe.status("cf2", 0.0)
    assert status1 is not None and status1["calibration"] == "cal.toml 2026-12-01"
    assert status2 is not None and status2["calibration"] == "none"
    # values without a source are never reported as "none"
    unlabelled = load_settings(
        None, {"calibration": {"accel_bias_mps2": [0.1, 0, 0]}}, use_env=False
    )
    pipe = Pipeline(unlabelled)
    (out,) = pipe.handle(_telemetry(0), 0.0)
    assert json.loads(out.payload)["calibration"] == "config"


@pytest.mark.parametrize("mocap", [True, False], ids=["mocap", "no-mocap"])
@pytest.mark.parametrize(("length_m", "fraction"), [(1.6, 0.97), (3.0, 0.90)])
def test_near_taut_hover_with_follow_enabled_never_engages_until_pulled(
    monkeypatch: pytest.MonkeyPatch, length_m: float, fraction: float, mocap: bool
) -> None:
    """Through the pipeline and the simulator: near taut the tether alone pulls
    with more than the 0.10 N threshold; with follow and tug-to-land enabled and nobody
    pulling nothing engages, no setpoint, landing not armed; a 0.12 N pull at 6 s engages."""
    _near_taut_scenario(monkeypatch, "near_taut_test", length_m, fraction, 0.12)
    settings = load_settings(
        None,
        {"sim": {"mocap": mocap, "seed": 5}, "tether": {"length_m": length_m}, **EXACT},
        use_env=False,
    )
    run, _, _ = closed_loop(settings, "near_taut_test", 8.0)
    quiet = [e for e in run.estimates if 1.1 < e["stamp_s"] < 6.0]
    assert quiet and all(e["follow"]["enabled"] for e in quiet)
    assert min(np.linalg.norm(e["tension_n"]) for e in quiet) > 0.10, "the premise"
    assert not any(e["follow"]["active"] or e["follow"]["landing_armed"] for e in quiet)
    assert all(sp["stamp_s"] >= 6.0 for sp in run.setpoints), "no setpoint before the pull"
    assert not run.stops
    pulled = [e for e in run.estimates if 6.0 <= e["stamp_s"] < 6.5]
    assert any(e["follow"]["active"] for e in pulled), "a real pull engages"


@pytest.mark.parametrize("mocap", [True, False], ids=["mocap", "no-mocap"])
def test_takeoff_ramp_publishes_no_floor_push_and_sends_no_stop(mocap: bool) -> None:
    """On the simulator: armed on the floor, the thrust ramps 0 → weight over
    2 s; follow is on with tug-to-land at 0.3 m from the start. While the drone is on the
    floor no tension above 20 mN is published and landing is never armed; no Stop at all;
    the lift-off is seen (on_ground false) by the time the drone is 4 cm up."""
    follow = Sample("tether/cf1/follow", b'{"enabled": true, "land_below_m": 0.3}')
    settings = load_settings(None, {"sim": {"mocap": mocap, "seed": 11}, **EXACT}, use_env=False)
    run, _, sim = closed_loop(settings, "takeoff_ramp", 8.0, inject={0: [follow]})
    assert not run.stops and sim.drones["cf1"].armed
    floor = [e for e in run.estimates if run.truth_at(e["stamp_s"])["on_ground"]]
    ramp = [e for e in floor if e["stamp_s"] >= 2.0]
    assert ramp, "the ramp is on the floor"
    assert max(float(np.linalg.norm(e["tension_n"])) for e in floor) <= 0.020
    assert not any(e["follow"]["landing_armed"] or e["follow"]["active"] for e in floor)
    up_4cm_s = min(
        e["stamp_s"] for e in run.estimates if run.truth_at(e["stamp_s"])["position_m"][2] > 0.04
    )
    seen_s = min(e["stamp_s"] for e in run.estimates if e["stamp_s"] > 2.0 and not e["on_ground"])
    assert seen_s <= up_4cm_s, (seen_s, up_4cm_s)
    assert all(e["follow"]["enabled"] for e in run.estimates[1:]), "follow stayed on throughout"


@pytest.mark.parametrize("bias_mps2", [0.0, 0.3])
@pytest.mark.parametrize("mocap", [True, False], ids=["mocap", "no-mocap"])
def test_half_weight_on_the_floor_is_not_tension(mocap: bool, bias_mps2: float) -> None:
    """0.51 of the weight on the floor for 5 s (the floor pushes 144 mN), follow enabled with
    tug-to-land, 0.3 m/s² accelerometer noise and a vertical bias: every Estimate says
    on_ground with zero tension; no setpoint, no Stop."""
    rng = np.random.default_rng(3)
    pipe = Pipeline(settings_for())
    weight_n = 0.030 * 9.81
    pipe.handle(Sample("tether/cf1/follow", b'{"enabled": true, "land_below_m": 0.3}'), 0.0)
    outputs: list[Sample] = []
    for seq in range(1250):
        accel = [*rng.normal(0.0, 0.3, 2), 9.81 + bias_mps2 + rng.normal(0.0, 0.3)]
        patch: dict[str, object] = {"accel_mps2": accel, "thrust_n": 0.51 * weight_n}
        if mocap:
            patch["position_m"] = [0.5, 0.0, float(rng.normal(0.0, 1e-3))]
        outputs += pipe.handle(_telemetry(seq, **patch), seq * 0.004)
    estimates = [json.loads(o.payload) for o in outputs if o.key.endswith("/estimate")]
    assert len(estimates) == len(outputs) == 1250, "no setpoint, no Stop"
    assert all(e["on_ground"] and e["tension_n"] == [0.0, 0.0, 0.0] for e in estimates)
    assert not any(e["follow"]["landing_armed"] for e in estimates)


@pytest.mark.parametrize("landed", ["disarmed", "low_thrust"])
def test_landing_armed_in_the_air_is_disarmed_once_on_the_ground(landed: str) -> None:
    """Through the pipeline: a 0.2 N downward pull at 1 m (motion capture) engages following
    and arms tug-to-land (land_below_m 0.5 m: no Stop up there); the drone is then on the
    ground (disarmed, or armed below the thrust ratio): landing is disarmed, and stays so
    with the next spool-up; no Stop at any time."""
    pipe = Pipeline(settings_for())
    weight_n = 0.030 * 9.81
    hover = {"accel_mps2": [0.0, 0.0, 9.81], "position_m": [1.0, 0.0, 1.0]}
    pulled = hover | {"thrust_n": weight_n + 0.2}  # the observation: 0.2 N downward
    outputs = pipe.handle(_telemetry(0, **pulled), 0.0)
    pipe.handle(Sample("tether/cf1/follow", b'{"enabled": true, "land_below_m": 0.5}'), 0.0)
    for seq in range(1, 200):
        outputs += pipe.handle(_telemetry(seq, **pulled), seq * 0.004)
    estimates = [json.loads(o.payload) for o in outputs if o.key.endswith("/estimate")]
    assert estimates[-1]["follow"]["landing_armed"], "the premise: the pull armed landing"
    on_floor = {"accel_mps2": [0.0, 0.0, 9.81], "position_m": [1.0, 0.0, 0.0]}
    on_floor |= {"armed": False, "thrust_n": 0.0} if landed == "disarmed" else {}
    on_floor |= {"thrust_n": 0.3 * weight_n} if landed == "low_thrust" else {}
    spool_up = {"accel_mps2": [0.0, 0.0, 9.81], "position_m": [1.0, 0.0, 0.0]}
    after = []
    for seq in range(200, 450):
        patch = on_floor if seq < 300 else spool_up | {"thrust_n": 0.9 * weight_n}
        after += pipe.handle(_telemetry(seq, **patch), seq * 0.004)
    later = [json.loads(o.payload) for o in after if o.key.endswith("/estimate")]
    assert len(later) == len(after) == 250, "no setpoint, no Stop"
    assert not any(e["follow"]["landing_armed"] for e in later)
    assert all(e["on_ground"] for e in later)
    assert not any(o.key.endswith("/cmd/stop") for o in outputs)


def test_ground_thrust_ratio_is_honoured() -> None:
    """At rest on the floor (the accelerometer reads g) for 0.3 s: below the configured
    ratio the rest is seen (low_thrust, after rest_hold_s); above it the floor's load holds
    the drone on the ground (resting)."""
    weight_n = 0.030 * 9.81
    rest = {"accel_mps2": [0.0, 0.0, 9.81], "quat_wxyz": [1.0, 0.0, 0.0, 0.0]}
    for ratio, thrust_ratio, reason in [(0.6, 0.55, "low_thrust"), (0.4, 0.45, "resting")]:
        settings = load_settings(None, {"filter": {"ground_thrust_ratio": ratio}}, use_env=False)
        pipe = Pipeline(settings)
        for seq in range(75):
            (out,) = pipe.handle(_telemetry(seq, thrust_n=thrust_ratio * weight_n, **rest), 0.0)
            assert json.loads(out.payload)["on_ground"] is True
        status = pipe.status("cf1", 0.0)
        assert status is not None and status["contact"]["reason"] == reason


def test_reel_exit_angles_are_used_while_fresh_and_named_in_the_estimate() -> None:
    """A plumb-ish hover (H ~ 2 mN: the tension's direction is noise): with the reel's exit
    azimuth the Estimate says azimuth_source "reel" and the position lies along it; once the
    reel falls silent for longer than [localization] reel_stale_after_s, the azimuth is
    the tension's again."""
    pipe = Pipeline(settings_for())
    reel = json.dumps(
        {"stamp_s": 0.0, "length_m": 1.6, "exit_azimuth_rad": 0.7, "exit_azimuth_std_rad": 0.02}
    ).encode()
    # The drone 0.3 m above the base, just off plumb: T_v = 0.3 * 0.05 N, H = 2 mN along -x.
    accel = [0.0, 0.0, 9.81 + (0.33 - 0.03 * 9.81 - 0.015) / 0.030]
    # The accelerometer's noise (0.3 m/s^2): the filter measures it, and a noise-free
    # stream would tell it that the 2 mN direction is exact.
    noise = np.random.default_rng(12).normal(0.0, 0.3, (500, 3))
    sources = []
    for seq in range(500):
        now = seq * 0.004
        if seq % 25 == 0 and now < 1.0:  # 10 Hz for 1 s, then silent
            pipe.handle(Sample("tether/cf1/reel", reel), now)
        a = noise[seq]
        patch = {"accel_mps2": [0.002 / 0.030 + a[0], a[1], accel[2] + a[2]]}
        (out,) = pipe.handle(_telemetry(seq, **patch), now)
        est = json.loads(out.payload)
        sources.append((now, est["azimuth_source"], est["position_m"]))
    fresh = [s for t, s, p in sources if 0.5 < t < 1.0 and p is not None]
    stale = [s for t, s, p in sources if t > 1.6 and p is not None]
    assert fresh and set(fresh) == {"reel"}
    assert stale and set(stale) == {"tension"}
    _, _, p = next(x for x in sources if x[0] > 0.9)
    assert p is not None
    assert np.arctan2(p[1], p[0]) == pytest.approx(0.7, abs=0.02)  # fused, the reel dominant


def test_exit_azimuth_without_std_grows_toward_plumb() -> None:
    """A Reel exit azimuth without its σ gets ``[localization] exit_azimuth_std_rad`` over
    cos(elevation), no floor: the elevation of the same message, or the last one still
    fresh; without an elevation the configured σ as is; at or past plumb no azimuth (the
    localization then takes none from the reel). A σ sent is kept as sent."""
    pipe = Pipeline(settings_for())
    loc = pipe.settings.localization
    base = {"length_m": 1.6, "exit_azimuth_rad": 0.7}

    def reel(now_s: float, **fields: float) -> float:
        body = json.dumps({"stamp_s": now_s, **base, **fields}).encode()
        assert pipe.handle(Sample("tether/cf1/reel", body), now_s) == []
        exit_azimuth = pipe.drones["cf1"].exit_azimuth
        assert exit_azimuth is not None and exit_azimuth.value_rad == 0.7
        return exit_azimuth.std_rad

    std = loc.exit_azimuth_std_rad
    assert reel(0.0) == pytest.approx(std), "no elevation known: the configured σ"
    assert reel(0.1, exit_elevation_rad=0.0) == pytest.approx(std)
    assert reel(0.2, exit_elevation_rad=math.radians(60)) == pytest.approx(2 * std)
    assert reel(0.3, exit_elevation_rad=-math.radians(80)) == pytest.approx(
        std / math.cos(math.radians(80))
    )
    # 89.9°: 573 times the configured σ, no floor on the cosine
    assert reel(0.35, exit_elevation_rad=math.radians(89.9)) == pytest.approx(
        std / math.cos(math.radians(89.9))
    )
    # the message's largest elevation, past plumb by rounding: no azimuth at all, and the
    # estimate takes none from the reel
    assert reel(0.4, exit_elevation_rad=1.5708) == math.inf
    # the last elevation while fresh, then no longer
    assert reel(0.4 + loc.reel_stale_after_s / 2) == math.inf
    assert reel(0.5 + loc.reel_stale_after_s) == pytest.approx(std)
    # a σ sent is the reel's own
    assert reel(2.0, exit_elevation_rad=1.5, exit_azimuth_std_rad=0.01) == 0.01
    assert exit_azimuth_default_std_rad(0.03, None) == 0.03

    # The localization's view: a plumb pull (no tension azimuth), the reel's azimuth the
    # source at 57° of elevation, none at plumb.
    pipe = Pipeline(settings_for())
    sources = []
    for elevation_rad in (1.0, 1.5708):
        t0 = len(sources) * 0.4
        body = json.dumps({"stamp_s": t0, **base, "exit_elevation_rad": elevation_rad})
        pipe.handle(Sample("tether/cf1/reel", body.encode()), t0)
        for i in range(100):
            now_s = t0 + 0.004 * i
            out = pipe.handle(_telemetry(100 * len(sources) + i, stamp_s=now_s), now_s)
        sources.append(json.loads(out[0].payload)["azimuth_source"])
    assert sources == ["reel", "none"]


def test_mocap_azimuth_takes_beta_from_position_m_one_by_one_and_batched() -> None:
    """``[localization] azimuth = "mocap"``, ``elevation = false`` (the paper's method): β
    comes from Telemetry ``position_m``, r and z from the tension. The tension pulls toward
    -x (a drone at +x by the catenary) while motion capture puts the drone at +y: the
    published position lies along +y, ``azimuth_source`` "mocap", and its radius and height
    are the tension's. The same through Pipeline.process_batch (the service's drain): the
    same bytes as Pipeline.handle."""
    from tests.hover_synth import hover_body

    tension = np.array([-0.020, 0.0, -0.060])
    mocap = [0.0, 0.9, 1.0]

    def settings(azimuth: str) -> Settings:
        over = {"localization": {"azimuth": azimuth, "elevation": False}}
        return load_settings(None, over | {"tether": {"weight_n_per_m": 0.05}}, use_env=False)

    rng = np.random.default_rng(3)
    bodies = [
        json.dumps(
            hover_body(k, tension, rng, mass_kg=0.030, dt_s=0.004, position_m=mocap)
        ).encode()
        for k in range(600)
    ]
    samples = [(Sample("tether/cf1/telemetry", b), k * 0.004) for k, b in enumerate(bodies)]

    def one_by_one(azimuth: str) -> list[Sample]:
        pipe = Pipeline(settings(azimuth))
        return [o for s, now_s in samples for o in pipe.handle(s, now_s)]

    want = one_by_one("mocap")
    late = [json.loads(o.payload) for o in want[-100:]]
    assert all(e["azimuth_source"] == "mocap" and e["position_m"] is not None for e in late)
    x, y, z = np.median([e["position_m"] for e in late], axis=0)
    assert math.degrees(math.atan2(y, x)) == pytest.approx(90.0, abs=0.5)
    # r and z are the tension's: the same as with the tension's own azimuth (along +x)
    ref = np.median([json.loads(o.payload)["position_m"] for o in one_by_one("tension")[-100:]], 0)
    assert math.degrees(math.atan2(ref[1], ref[0])) == pytest.approx(0.0, abs=2.0)
    assert math.hypot(x, y) == pytest.approx(math.hypot(ref[0], ref[1]), abs=1e-3)
    assert z == pytest.approx(ref[2], abs=1e-3)

    pipe = Pipeline(settings("mocap"))
    parsed = [p for s, now_s in samples if (p := pipe.validate(s, now_s)) is not None]
    got = [o for i in range(0, len(parsed), 50) for o in pipe.process_batch(parsed[i : i + 50])]
    assert got == want


def test_service_started_mid_hover_finds_the_drone_in_the_air() -> None:
    """No rest was seen (the service starts while the drone hovers, no motion capture): the
    contact state starts on the ground, the floor's push is found absent within ~0.1 s and
    the filter starts from its first observation, not from the lift-off prior."""
    run, pipe, _ = closed_loop(settings_for(mocap=False, seed=2), "hover", 2.0)
    first = next(e for e in run.estimates if e["position_m"] is not None)
    assert first["stamp_s"] <= 0.25
    late = [e for e in run.estimates if e["stamp_s"] > 1.0]
    assert all(not e["on_ground"] for e in late)
    err = [np.linalg.norm(np.subtract(e["position_m"], run.truth_at(e["stamp_s"])["position_m"]))
           for e in late]  # fmt: skip
    assert float(np.median(err)) < 0.05
    status = pipe.status("cf1", 2.0)
    assert status is not None and status["contact"]["reason"] == "air"


def test_flight_outside_the_calibrated_battery_range_is_flagged_and_told_once() -> None:
    """calibration_extrapolated: null without a range, without vbat_v or on the ground; else
    whether vbat_v lies outside [calibration] thrust_vbat_range_v; one warning Event."""
    events: list[tuple[str, object]] = []

    def run(settings: object, vbats: list[float | None], armed: bool = True) -> list[dict]:
        pipe = Pipeline(settings, on_event=lambda d, e: events.append((d, e)))  # type: ignore[arg-type]
        level = GOOD | {"accel_mps2": [0.0, 0.0, 9.81], "thrust_n": 0.30, "armed": armed}
        level |= {"position_m": [1.0, 0.0, 1.0]}
        out = []
        for k, v in enumerate(vbats):
            body = level | {"seq": k, "stamp_s": k * 0.004}
            if v is not None:
                body["vbat_v"] = v
            (o,) = pipe.handle(Sample("tether/cf1/telemetry", json.dumps(body).encode()), k * 0.004)
            out.append(json.loads(o.payload))
        status = pipe.status("cf1", len(vbats) * 0.004)
        assert status is not None
        out.append(status)
        return out

    ranged = load_settings(
        None, {"calibration": {"thrust_vbat_range_v": [3.9, 4.0]}}, use_env=False
    )
    # 1 s in range (the contact rules find the drone in the air), then below, back, above
    vbats: list[float | None] = [3.95] * 250 + [3.85] * 10 + [3.95] * 10 + [4.05] * 10
    *est, status = run(ranged, vbats)
    air = [e for e in est if not e["on_ground"]]
    assert air, "the drone must be found in the air"
    assert all(e["calibration_extrapolated"] is None for e in est if e["on_ground"])
    flags = [e["calibration_extrapolated"] for e in est[250:]]
    assert flags == [True] * 10 + [False] * 10 + [True] * 10
    assert est[249]["calibration_extrapolated"] is False
    assert status["calibration_extrapolated"] is True
    assert status["calibration_vbat_range_v"] == [3.9, 4.0] and status["vbat_v"] == 4.05
    told = [e for d, e in events if e.kind == "warning" and e.field == "vbat_v"]  # type: ignore[attr-defined]
    assert len(told) == 1, "told once, not per sample"
    assert "3.850 V outside" in told[0].reason and "3.900–4.000 V" in told[0].reason  # type: ignore[attr-defined]

    # no vbat_v: unknown; no range: unknown; disarmed on the floor: unknown, never told
    events.clear()
    *est, status = run(ranged, [None] * 300)
    assert {e["calibration_extrapolated"] for e in est} == {None}
    *est, status = run(load_settings(None, use_env=False), [3.5] * 300)
    assert {e["calibration_extrapolated"] for e in est} == {None}
    assert status["calibration_vbat_range_v"] is None and status["vbat_v"] == 3.5
    *est, status = run(ranged, [4.2] * 300, armed=False)
    assert all(e["on_ground"] for e in est)
    assert {e["calibration_extrapolated"] for e in est} == {None}
    assert not events


@pytest.mark.parametrize("own_std", [True, False])
def test_the_floor_band_is_the_heights_own_sigma(own_std: bool) -> None:
    """Lift-off by the height stands out of that height's noise: an onboard position (a
    Lighthouse deck) resting on the floor with 1 cm of noise in z, armed at 0.9 of the weight,
    stays on the ground when its ``position_std_m`` says 1 cm; read with motion capture's
    σ (``[localization] mocap_std_m``, 2 mm, the contract's default without one) the same
    noise is taken for lift-offs. 10 s at 250 Hz."""
    rng = np.random.default_rng(21)
    pipe = Pipeline(settings_for())
    weight_n = 0.030 * 9.81
    std = {"position_std_m": [0.01, 0.01, 0.01]} if own_std else {}
    seq = 0
    for _ in range(500):  # 2 s disarmed at rest: the resting height is learnt
        pipe.handle(
            _telemetry(seq, accel_mps2=[0.0, 0.0, 9.81], thrust_n=0.0, armed=False,
                       position_m=[0.5, 0.0, 0.04], **std),
            seq * 0.004,
        )  # fmt: skip
        seq += 1
    airborne = 0
    for z in (0.04 + rng.normal(0.0, 0.01, 2500)).tolist():
        out = pipe.handle(
            _telemetry(seq, accel_mps2=[0.0, 0.0, 9.81], thrust_n=0.9 * weight_n,
                       position_m=[0.5, 0.0, z], **std),
            seq * 0.004,
        )  # fmt: skip
        seq += 1
        estimates = [json.loads(o.payload) for o in out if o.key.endswith("/estimate")]
        airborne += sum(not e["on_ground"] for e in estimates)
    if own_std:
        assert airborne == 0
    else:
        assert airborne > 100
