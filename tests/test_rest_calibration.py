"""Rest calibration in the pipeline: measured on the floor, applied in flight, cleared at
disarm, reported in status."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from groundstation.bus import Sample
from groundstation.calibration import RestCalibrator
from groundstation.config import ConfigError, load_settings
from groundstation.pipeline import Pipeline

G = 9.81
OFFSET = np.array([0.25, -0.15, 0.0])  # the accelerometer's offset after this power-on


def _quat(R: np.ndarray) -> list[float]:
    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return [float(w), float(x), float(y), float(z)]


def _sample(seq: int, t: float, accel: np.ndarray, R: np.ndarray, armed: bool, thrust: float):
    body = {
        "seq": seq,
        "stamp_s": t,
        "accel_mps2": [float(v) for v in accel],
        "quat_wxyz": _quat(R),
        "thrust_n": thrust,
        "gyro_rps": [0.0, 0.0, 0.0],
        "armed": armed,
    }
    return Sample("tether/cf1/telemetry", json.dumps(body).encode())


def _fly(rest: bool, accel_slow: bool = True) -> tuple[Pipeline, list[dict], list[dict]]:
    """Rest 2 s on a tilted floor (the attitude shows the tilt), hover 2 s with a free
    tether-less hover (true tension 0), land, disarm."""
    cal = {"rest": rest, "accel_slow": accel_slow}
    settings = load_settings(None, {"calibration": cal}, use_env=False)
    pipe = Pipeline(settings)
    rng = np.random.default_rng(0)
    floor = Rotation.from_euler("xy", [0.04, -0.06]).as_matrix()
    seq, t = 0, 0.0
    status = []
    for _ in range(200):  # at rest, 100 Hz
        a = floor.T @ [0, 0, G] + OFFSET + rng.normal(0, 0.02, 3)
        pipe.handle(_sample(seq, t, a, floor, False, 0.0), t)
        seq, t = seq + 1, t + 0.01
    status.append(pipe.status("cf1", t) or {})
    estimates = []
    level = np.eye(3)
    for _ in range(200):  # hover, no tether: f = (0, 0, g), thrust = m g
        a = np.array([0, 0, G]) + OFFSET + rng.normal(0, 0.02, 3)
        for out in pipe.handle(_sample(seq, t, a, level, True, 0.030 * G), t):
            if out.key.endswith("/estimate"):
                estimates.append(json.loads(out.payload))
        seq, t = seq + 1, t + 0.01
    status.append(pipe.status("cf1", t) or {})
    pipe.handle(_sample(seq, t, level.T @ [0, 0, G] + OFFSET, level, False, 0.0), t)
    status.append(pipe.status("cf1", t) or {})
    return pipe, status, estimates


def test_rest_offset_measured_applied_and_cleared() -> None:
    _, status, estimates = _fly(rest=True)
    at_rest, in_flight, after = (s["rest_calibration"] for s in status)
    assert at_rest["in_force"] and in_flight["in_force"]
    off, std = np.array(at_rest["offset_mps2"]), np.array(at_rest["std_mps2"])
    assert np.all(std > 0) and np.all(np.abs(off - OFFSET[:2]) <= 3 * std)
    assert in_flight["offset_mps2"] == at_rest["offset_mps2"]  # held through the flight
    assert after == {"in_force": False}  # cleared at the disarm (no rest_required: no more)
    # Applied: the true tension is 0, the horizontal tension stays within noise of it,
    # while the offset alone would read m·|offset| = 8.7 mN.
    late = estimates[-50:]
    h = np.median([e["horizontal_n"] for e in late])
    assert h < 0.002


def test_without_rest_the_offset_shows_as_tension() -> None:
    """The accelerometer's mean trusted as read (``accel_slow = false``, what a
    ``--model full`` calibration writes) and no rest calibration: the offset is tension."""
    _, status, estimates = _fly(rest=False, accel_slow=False)
    assert all(s["rest_calibration"] is None for s in status)
    h = np.median([e["horizontal_n"] for e in estimates[-50:]])
    assert abs(h - 0.030 * np.linalg.norm(OFFSET[:2])) < 0.002


def test_the_slow_stage_learns_the_offset_at_rest_without_the_rest_calibration() -> None:
    """The default (``accel_slow``): the same power-on's offset, learnt on the floor by the
    slow stage (groundstation.slow_accel), is not read as tension either."""
    _, status, estimates = _fly(rest=False)
    assert all(s["rest_calibration"] is None for s in status)
    h = np.median([e["horizontal_n"] for e in estimates[-50:]])
    assert h < 0.002  # the offset alone would read m·|offset| = 8.7 mN


def _rest_window(seq0: int, t0: float, n: int, rng: np.random.Generator) -> list[tuple]:
    """(seq, stamp, accel) of ``n`` samples at rest on a level floor, 100 Hz."""
    return [
        (seq0 + k, t0 + 0.01 * k, np.array([0, 0, G]) + OFFSET + rng.normal(0, 0.02, 3))
        for k in range(n)
    ]


def test_dropped_repeats_and_out_of_order_messages_stay_out_of_the_rest_window() -> None:
    """Every rest sample delivered twice, and now and then an older one again with a later
    stamp but a stale seq and a different reading: the pipeline drops them (seq_repeated,
    seq_backwards), and the rest window sees only what it accepted (a repeat's stamp alone
    would restart the window: no offset at all)."""
    pipe = Pipeline(load_settings(None, use_env=False))
    rng = np.random.default_rng(1)
    level = np.eye(3)
    window = _rest_window(0, 0.0, 150, rng)
    reference = RestCalibrator()  # fed only the accepted samples
    for seq, t, a in window:
        pipe.handle(_sample(seq, t, a, level, False, 0.0), t)
        pipe.handle(_sample(seq, t, a, level, False, 0.0), t)  # repeated
        if seq >= 5 and seq % 10 == 0:  # an old seq with a later stamp and another reading
            stale = a + np.array([0.12, -0.12, 0.0])
            pipe.handle(_sample(seq - 3, t + 0.005, stale, level, False, 0.0), t + 0.005)
        reference.update(t, a, _quat(level), False, (0.0, 0.0, 0.0))
    status = pipe.status("cf1", 2.0) or {}
    assert status["drops"].get("seq_repeated") == 150 and status["drops"].get("seq_backwards")
    rest = status["rest_calibration"]
    assert rest["in_force"], rest
    ref = reference.offset
    assert ref is not None
    np.testing.assert_allclose(rest["offset_mps2"], ref.offset_body_mps2[:2], atol=1e-12)
    assert rest["duration_s"] == pytest.approx(ref.duration_s)


def test_arming_without_the_required_rest_offset_is_warned_once_and_in_status() -> None:
    """``rest_required`` (calibrate left x/y to the rest): arming with no rest offset in force
    is said in status until the disarm, and warned once; arming after a rest is fine."""
    settings = load_settings(None, {"calibration": {"rest_required": True}}, use_env=False)
    events: list = []
    pipe = Pipeline(settings, on_event=lambda d, e: events.append((d, e)))
    rng = np.random.default_rng(2)
    level = np.eye(3)
    seq, t = 0, 0.0

    def send(n: int, armed: bool, still: bool = False) -> None:
        nonlocal seq, t
        for _ in range(n):
            a = np.array([0, 0, G]) + OFFSET + rng.normal(0, 0.02 if still else 0.5, 3)
            pipe.handle(_sample(seq, t, a, level, armed, 0.030 * G if armed else 0.0), t)
            seq, t = seq + 1, t + 0.01

    def rest_status() -> dict:
        return (pipe.status("cf1", t) or {})["rest_calibration"]

    send(20, armed=False)  # handled, never still: no offset
    assert rest_status() == {"in_force": False, "required": True, "missing_at_arming": False}
    send(50, armed=True)
    assert rest_status()["missing_at_arming"] is True
    warnings = [e for _, e in events if e.kind == "warning"]
    assert len(warnings) == 1 and "rest" in warnings[0].reason and warnings[0].field == "armed"
    send(150, armed=False, still=True)  # disarmed: cleared; 1.5 s still: offset in force
    assert rest_status()["missing_at_arming"] is False and rest_status()["in_force"]
    send(50, armed=True)
    assert rest_status()["missing_at_arming"] is False
    send(5, armed=False)
    send(50, armed=True)  # armed again without a rest: said again, not warned again
    assert rest_status()["missing_at_arming"] is True
    assert len([e for _, e in events if e.kind == "warning"]) == 1


def test_rest_required_without_rest_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match="rest_required"):
        load_settings(None, {"calibration": {"rest": False, "rest_required": True}}, use_env=False)
