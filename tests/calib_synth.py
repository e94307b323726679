"""A synthetic flight generator for the calibration tests: hover at spots on a catenary tether
with known sensor errors (thrust scale, thrust axis, accelerometer bias), coloured vibration
noise, a rest window on a known floor before take-off.

Static hover: ``R·u·F + T + m·g = 0``, so the attitude R turns the true thrust axis u onto
``m·g·e3 − T`` and F is its norm; the specific force is ``Rᵀ·(0, 0, g)``. The reported thrust
is ``F / scale``, the accelerometer reads ``f + bias + noise``. Not the simulator: it shares
the catenary with the fit on purpose (a test of the fit's algebra, not of the tether model).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from groundstation.calibration import CalibrationData
from groundstation.catenary import tether_force
from groundstation.config import Settings
from groundstation.pipeline import Pipeline

G = 9.81


@dataclass(frozen=True)
class Truth:
    thrust_scale: float = 1.0
    about_x_rad: float = 0.0
    about_y_rad: float = 0.0
    bias_mps2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    vbat_slope_per_v: float = 0.0


def _quat_wxyz(R: np.ndarray) -> np.ndarray:
    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return np.array([w, x, y, z])


def _ar1(rng: np.random.Generator, n: int, sigma: float, rho: float) -> np.ndarray:
    e = rng.normal(0.0, sigma * math.sqrt(1 - rho * rho), (n, 3))
    out = np.zeros((n, 3))
    out[0] = rng.normal(0.0, sigma, 3)
    for i in range(1, n):
        out[i] = rho * out[i - 1] + e[i]
    return out


def flight(
    spots: list[tuple[float, float, float]],
    truth: Truth,
    *,
    seed: int = 0,
    mass_kg: float = 0.030,
    weight_n_per_m: float = 0.05,
    length_m: float = 1.6,
    base_m: tuple[float, float, float] = (0.0, 0.0, 0.754),
    rate_hz: float = 100.0,
    hover_s: float = 6.0,
    move_s: float = 1.5,
    rest_s: float = 2.0,
    floor_tilt_rad: tuple[float, float] = (0.0, 0.0),
    accel_noise_mps2: float = 0.2,
    rho: float = 0.6,
    vbat_v: tuple[float, float] | None = None,
    segment: int = 0,
    t0_s: float = 0.0,
) -> CalibrationData:
    """Rest on the floor (disarmed), then hover at each spot with moves in between."""
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate_hz
    base = np.array(base_m)
    rows: dict[str, list] = {k: [] for k in ("t", "a", "q", "thr", "arm", "p", "g", "v")}
    bias = np.array(truth.bias_mps2)
    Q = Rotation.from_euler("xy", [truth.about_x_rad, truth.about_y_rad]).as_matrix()
    n_rest = int(rest_s * rate_hz)
    R_floor = Rotation.from_euler("xy", floor_tilt_rad).as_matrix()
    t = t0_s
    for _ in range(n_rest):
        rows["t"].append(t)
        rows["a"].append(R_floor.T @ np.array([0, 0, G]) + bias + rng.normal(0, 0.01, 3))
        rows["q"].append(_quat_wxyz(R_floor))
        rows["thr"].append(0.0)
        rows["arm"].append(False)
        rows["p"].append([math.nan] * 3)
        rows["g"].append(rng.normal(0, 0.002, 3))
        rows["v"].append(math.nan)
        t += dt
    total = len(spots) * (hover_s + move_s)
    t_fly0 = t
    prev = None
    for spot in spots:
        p_spot = np.array(spot)
        n_move = int(move_s * rate_hz)
        n_hov = int(hover_s * rate_hz)
        start = prev if prev is not None else np.array([spot[0], spot[1], 0.3])
        for i in range(n_move + n_hov):
            if i < n_move:
                s = 0.5 - 0.5 * math.cos(math.pi * i / n_move)
                p = start + s * (p_spot - start)
                acc = (
                    (p_spot - start)
                    * 0.5
                    * (math.pi / move_s) ** 2
                    * math.cos(math.pi * i / n_move)
                )
                moving = True
            else:
                p = p_spot + rng.normal(0, 0.0005, 3)
                acc = np.zeros(3)
                moving = False
            T = tether_force(base, p, length_m, weight_n_per_m).force_world_n
            need = mass_kg * (acc + np.array([0, 0, G])) - T
            F = float(np.linalg.norm(need))
            nz = need / F
            # R with R·u_true = nz: R0 takes e3 to nz (no yaw), then Q' takes u_true to e3.
            axis = np.cross([0, 0, 1.0], nz)
            ang = math.asin(min(1.0, float(np.linalg.norm(axis))))
            R0 = (
                Rotation.from_rotvec(axis / np.linalg.norm(axis) * ang).as_matrix()
                if ang > 1e-12
                else np.eye(3)
            )
            R = R0 @ Q.T
            f = R.T @ (acc + np.array([0, 0, G]))
            frac = (t - t_fly0) / total
            v = None if vbat_v is None else vbat_v[0] + frac * (vbat_v[1] - vbat_v[0])
            scale = truth.thrust_scale + (0.0 if v is None else truth.vbat_slope_per_v * (v - 3.9))
            rows["t"].append(t)
            rows["a"].append(f + bias)
            rows["q"].append(_quat_wxyz(R))
            rows["thr"].append(F / scale)
            rows["arm"].append(True)
            rows["p"].append(p)
            rows["g"].append(np.zeros(3) if not moving else np.array([0.0, 0.0, 0.0]))
            rows["v"].append(math.nan if v is None else v)
            t += dt
        prev = p_spot
    a = np.array(rows["a"])
    armed = np.array(rows["arm"])
    a[armed] += _ar1(rng, int(armed.sum()), accel_noise_mps2, rho)
    n = len(rows["t"])
    return CalibrationData.from_arrays(
        rows["t"],
        a,
        np.array(rows["q"]),
        np.array(rows["thr"]),
        armed=armed,
        position_world_m=np.array(rows["p"], dtype=float),
        gyro_rps=np.array(rows["g"]),
        vbat_v=np.array(rows["v"]),
        length_m=np.full(n, length_m),
        base_world_m=np.tile(base, (n, 1)),
        segment=np.full(n, segment),
    )


def concat(*parts: CalibrationData) -> CalibrationData:
    return CalibrationData(
        **{
            name: np.concatenate([getattr(p, name) for p in parts])
            for name in CalibrationData.__dataclass_fields__
        }
    )


def recorded_messages(
    data: CalibrationData,
    *,
    drone: str = "cf1",
    mocap: bool = True,
    reel_length_m: float | None = 1.6,
    reel_base_m: tuple[float, float, float] | None = (0.0, 0.0, 0.754),
) -> list:
    """The RecordedMessages ``groundstation record`` would write: Telemetry (and a Reel)."""
    import json

    from groundstation.recording.reader import RecordedMessage

    msgs = []
    t_ns = 1_700_000_000_000_000_000
    if reel_length_m is not None:
        reel = {"stamp_s": 0.0, "length_m": reel_length_m}
        if reel_base_m is not None:
            reel["base_m"] = list(reel_base_m)
        msgs.append(RecordedMessage(f"tether/{drone}/reel", json.dumps(reel).encode(), t_ns, t_ns))
    for i in range(len(data)):
        tel = {
            "seq": i,
            "stamp_s": float(data.stamp_s[i]),
            "accel_mps2": data.accel_body_mps2[i].tolist(),
            "quat_wxyz": data.quat_wxyz[i].tolist(),
            "thrust_n": float(data.thrust_n[i]),
            "armed": bool(data.armed[i]),
        }
        if np.all(np.isfinite(data.gyro_rps[i])):
            tel["gyro_rps"] = data.gyro_rps[i].tolist()
        if mocap and np.all(np.isfinite(data.position_world_m[i])):
            tel["position_m"] = data.position_world_m[i].tolist()
        if math.isfinite(data.vbat_v[i]):
            tel["vbat_v"] = float(data.vbat_v[i])
        t = t_ns + int((float(data.stamp_s[i]) + 1.0) * 1e9)
        msgs.append(RecordedMessage(f"tether/{drone}/telemetry", json.dumps(tel).encode(), t, t))
    return msgs


def write_mcap(
    path: str,
    data: CalibrationData,
    *,
    drone: str = "cf1",
    mocap: bool = True,
    reel_length_m: float | None = 1.6,
    reel_base_m: tuple[float, float, float] | None = (0.0, 0.0, 0.754),
) -> None:
    """A recording as ``groundstation record`` writes it: Telemetry (and a Reel) as JSON."""
    from pathlib import Path

    from groundstation.recording.reader import copy_messages

    msgs = recorded_messages(
        data, drone=drone, mocap=mocap, reel_length_m=reel_length_m, reel_base_m=reel_base_m
    )
    copy_messages(msgs, Path(path))


def served_position_errors(
    settings: Settings, data: CalibrationData, drone: str = "cf1"
) -> tuple[list[float], Pipeline]:
    """``serve``'s pipeline on ``data`` *without* motion capture (the Reel gives length and
    base): the distance of each airborne Estimate's position from the true one, m, and the
    pipeline (for its status)."""
    import json

    from groundstation.bus import Sample

    pipe = Pipeline(settings)
    reel = {"stamp_s": 0.0, "length_m": float(data.length_m[0])}
    reel["base_m"] = data.base_world_m[0].tolist()
    pipe.handle(Sample(f"tether/{drone}/reel", json.dumps(reel).encode()), 0.0)
    errors = []
    for i in range(len(data)):
        tel = {
            "seq": i,
            "stamp_s": float(data.stamp_s[i]),
            "accel_mps2": data.accel_body_mps2[i].tolist(),
            "quat_wxyz": data.quat_wxyz[i].tolist(),
            "thrust_n": float(data.thrust_n[i]),
            "armed": bool(data.armed[i]),
            "gyro_rps": data.gyro_rps[i].tolist(),
        }
        sample = Sample(f"tether/{drone}/telemetry", json.dumps(tel).encode())
        for out in pipe.handle(sample, float(data.stamp_s[i])):
            if not out.key.endswith("/estimate"):
                continue
            est = json.loads(out.payload)
            p = data.position_world_m[i]
            if est["position_m"] is not None and data.armed[i] and np.all(np.isfinite(p)):
                errors.append(float(np.linalg.norm(np.subtract(est["position_m"], p))))
    return errors, pipe
