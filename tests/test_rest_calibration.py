"""Rest calibration in the pipeline: measured on the floor, applied in flight, cleared at
disarm, reported in status (issue 10 §3)."""

from __future__ import annotations

import json

import numpy as np
from scipy.spatial.transform import Rotation

from groundstation.bus import Sample
from groundstation.config import load_settings
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


def _fly(rest: bool) -> tuple[Pipeline, list[dict], list[dict]]:
    """Rest 2 s on a tilted floor (the attitude shows the tilt), hover 2 s with a free
    tether-less hover (true tension 0), land, disarm."""
    settings = load_settings(None, {"calibration": {"rest": rest}}, use_env=False)
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
    assert after == {"in_force": False}  # cleared at the disarm
    # Applied: the true tension is 0, the horizontal tension stays within noise of it,
    # while the offset alone would read m·|offset| = 8.7 mN.
    late = estimates[-50:]
    h = np.median([e["horizontal_n"] for e in late])
    assert h < 0.002


def test_without_rest_the_offset_shows_as_tension() -> None:
    _, status, estimates = _fly(rest=False)
    assert all(s["rest_calibration"] is None for s in status)
    h = np.median([e["horizontal_n"] for e in estimates[-50:]])
    assert abs(h - 0.030 * np.linalg.norm(OFFSET[:2])) < 0.002
