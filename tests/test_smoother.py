"""Tests of groundstation.smoother: known answers on synthetic traces, the causal filter's
trace, and ``replay --offline``'s smoothed series end to end."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from groundstation.config import Settings
from groundstation.messages import EstimateSmoothed
from groundstation.recording.reader import iter_messages
from groundstation.recording.replay import run_replay_offline
from groundstation.smoother import segments, smooth_tension
from groundstation.tension import FilterStep, TensionFilter, TensionFilterParams

ZERO = (0.0, 0.0, 0.0)


def _t3(v: np.ndarray) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


def _update(z: np.ndarray, r: float, q: float = 0.0, restart: int = 0) -> FilterStep:
    # x_n / p_n2 are the causal filter's; the smoother reads only z, q, r and the structure.
    return FilterStep("update", ZERO, ZERO, _t3(z), (q, q, q), (r, r, r), restart)


def test_constant_regimes_smooth_to_their_means() -> None:
    """Q = 0: every step of a regime smooths to the mean of all its samples, P = R / n.

    Three regimes: an init (x = z, P = R) and 59 updates, with a coast inside; a change
    detected 20 updates after it began 40 samples in (restart = 21: the cut is 20 back);
    a reset with a prior, whose regime smooths to the precision-weighted mean.
    """
    rng = np.random.default_rng(5)
    r = 4e-4
    a, b, c = np.array([0.01, -0.02, -0.05]), np.array([0.05, 0.0, -0.05]), np.zeros(3)
    za = a + rng.normal(0.0, 0.02, (40, 3))
    zb = b + rng.normal(0.0, 0.02, (60, 3))
    zc = c + rng.normal(0.0, 0.02, (30, 3))
    trace = [FilterStep("init", ZERO, ZERO, _t3(za[0]), ZERO, (r, r, r))]
    trace += [_update(z, r) for z in za[1:20]]
    trace.append(FilterStep("coast", ZERO, ZERO))
    trace += [_update(z, r) for z in za[20:]]
    trace += [_update(z, r) for z in zb[:20]]
    trace.append(_update(zb[20], r, restart=21))  # detected here; began 20 updates ago
    trace += [_update(z, r) for z in zb[21:]]
    x0, p0 = (0.0, 0.0, -0.01), (1e-4, 1e-4, 1e-4)
    trace.append(FilterStep("reset", x0, p0))
    trace += [_update(z, r) for z in zc]

    segs = segments(trace)
    assert [(s.start, s.stop, s.begin) for s in segs] == [
        (0, 41, "diffuse"),
        (41, 101, "diffuse"),
        (102, 132, "prior"),
    ]
    sm = smooth_tension(trace)
    np.testing.assert_allclose(sm.tension_world_n[:41], np.tile(za.mean(0), (41, 1)), atol=1e-12)
    np.testing.assert_allclose(sm.variance_n2[:41], r / 40, rtol=1e-9)
    np.testing.assert_allclose(sm.tension_world_n[41:101], np.tile(zb.mean(0), (60, 1)), atol=1e-12)
    np.testing.assert_allclose(sm.variance_n2[41:101], r / 60, rtol=1e-9)
    assert np.all(np.isnan(sm.tension_world_n[101]))  # the reset
    post = (np.array(x0) / p0[0] + zc.sum(0) / r) / (1 / p0[0] + 30 / r)
    np.testing.assert_allclose(sm.tension_world_n[102:], np.tile(post, (30, 1)), atol=1e-12)
    np.testing.assert_allclose(sm.variance_n2[102:], 1 / (1 / p0[0] + 30 / r), rtol=1e-9)


def test_random_walk_equals_the_scalar_rts_and_beats_the_filter() -> None:
    """Q > 0: filterpy's smoother equals a scalar RTS written out here, and on a random walk
    in noise its error is well below the causal filter's."""
    rng = np.random.default_rng(11)
    n, q, r = 3000, 1e-6, 4e-4
    truth = np.cumsum(rng.normal(0.0, math.sqrt(q), (n, 3)), axis=0)
    zs = truth + rng.normal(0.0, math.sqrt(r), (n, 3))
    trace = [FilterStep("init", ZERO, ZERO, _t3(zs[0]), ZERO, (r, r, r))]
    trace += [_update(z, r, q) for z in zs[1:]]
    sm = smooth_tension(trace)
    # scalar forward pass and RTS, per axis
    x, p = zs[0].copy(), np.full(3, r)
    xf, pf = [x.copy()], [p.copy()]
    for z in zs[1:]:
        p = p + q  # P- = P + Q
        k = p / (p + r)  # K = P-/(P- + R)
        x, p = x + k * (z - x), (1 - k) * p
        xf.append(x.copy())
        pf.append(p.copy())
    xs, ps = [xf[-1]], [pf[-1]]
    for j in range(n - 2, -1, -1):
        g = pf[j] / (pf[j] + q)  # G = P (P + Q)^-1
        xs.append(xf[j] + g * (xs[-1] - xf[j]))
        ps.append(pf[j] + g * g * (ps[-1] - (pf[j] + q)))
    np.testing.assert_allclose(sm.tension_world_n, np.array(xs[::-1]), atol=1e-12)
    np.testing.assert_allclose(sm.variance_n2, np.array(ps[::-1]), rtol=1e-8)
    rms_f = np.sqrt(np.mean((np.array(xf) - truth)[100:] ** 2))
    rms_s = np.sqrt(np.mean((sm.tension_world_n - truth)[100:] ** 2))
    assert rms_s < 0.8 * rms_f, (rms_s, rms_f)


def test_trace_of_the_tension_filter_matches_its_estimates() -> None:
    """The trace records each step's state (equal to the estimate), Q, R and restarts; a
    tug's regime is cut within a few samples of the tug."""
    rng = np.random.default_rng(3)
    filt = TensionFilter()
    trace = filt.start_trace()
    n, tug = 2000, 1000
    truth = np.tile([-0.02, 0.005, -0.06], (n, 1))
    truth[tug:] += [0.04, 0.0, 0.0]
    ests = []
    for k in range(n):
        ests.append(filt.update(truth[k] + rng.normal(0.0, 0.012, 3), 0.004))
        if k == 500:
            filt.coast(0.004)
    assert [s.kind for s in trace[:2]] == ["init", "update"]
    assert sum(s.kind == "coast" for s in trace) == 1
    updates = [s for s in trace if s.kind in ("init", "update")]
    assert len(updates) == n
    for s, e in zip(updates, ests, strict=True):
        assert s.x_n == tuple(e.tension_world_n.tolist())
    cuts = [s.start for s in segments(trace)[1:]]
    assert cuts and abs(cuts[0] - (tug + 1)) <= 5, cuts  # +1: the coast
    sm = smooth_tension(trace)
    est = np.array([e.tension_world_n for e in ests])
    idx = [i for i, s in enumerate(trace) if s.kind in ("init", "update")]
    err_s = np.abs(sm.tension_world_n[idx] - truth)[tug : tug + 250, 0]
    err_c = np.abs(est - truth)[tug : tug + 250, 0]
    assert err_s.mean() < 0.5 * err_c.mean(), (err_s.mean(), err_c.mean())


def _telemetry(seq: int, accel_noise_mps2: np.ndarray) -> bytes:
    return json.dumps(
        {
            "seq": seq,
            "stamp_s": seq * 0.004,
            "accel_mps2": (np.array([0.0, 0.0, 9.81]) + accel_noise_mps2).tolist(),
            "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
            "thrust_n": 0.2943 + 0.05,
        }
    ).encode()


def _replay(
    tmp_path: Path, name: str, noise_mps2: float, settings: Settings | None = None
) -> tuple[dict, dict]:
    from tests.test_recording import write_recording

    rng = np.random.default_rng(17)
    t0 = 1_700_000_000 * 10**9
    msgs = [
        ("tether/cf1/telemetry", _telemetry(i, rng.normal(0.0, noise_mps2, 3)), t0 + i * 4_000_000)
        for i in range(400)
    ]
    src, out = tmp_path / f"{name}.mcap", tmp_path / f"{name}-out.mcap"
    write_recording(src, msgs)
    assert run_replay_offline(settings or Settings(), src, out) == 0
    est, smo = {}, {}
    for m in iter_messages(out):
        if m.key == "tether/cf1/estimate":
            est[json.loads(m.payload)["seq"]] = (json.loads(m.payload), m.log_time_ns)
        elif m.key == "tether/cf1/estimate_smoothed":
            s = EstimateSmoothed.read(m.payload)
            smo[s.seq] = (s, m.log_time_ns)
    return est, smo


def test_replay_offline_writes_the_smoothed_series(tmp_path: Path) -> None:
    """End to end on a small recording (400 samples, 1 m/s^2 of accelerometer noise): one
    estimate_smoothed per estimate the filter stepped for, same seq and log time, valid, a
    position, and closer to the truth (the noiseless recording's estimate) than the causal
    estimate over the first samples, where the causal filter has seen few."""
    truth = np.array(_replay(tmp_path, "clean", 0.0)[0][399][0]["tension_n"])
    est, smo = _replay(tmp_path, "noisy", 1.0)
    assert len(est) == 400
    airborne = {k for k, (e, _) in est.items() if not e["on_ground"]}
    # one per estimate the filter stepped for (the trace began at the first message)
    assert set(smo) == airborne and len(smo) > 350
    for seq, (s, t_ns) in smo.items():
        assert t_ns == est[seq][1] and s.stamp_s == est[seq][0]["stamp_s"]
        assert s.position_m is not None
    early = range(min(smo) + 5, min(smo) + 100)
    err_c = np.mean([np.linalg.norm(np.subtract(est[k][0]["tension_n"], truth)) for k in early])
    err_s = np.mean([np.linalg.norm(np.subtract(smo[k][0].tension_n, truth)) for k in early])
    assert err_s < 0.5 * err_c, (err_s, err_c)
    k = min(smo) + 5
    assert np.all(np.array(smo[k][0].tension_std_n) < np.array(est[k][0]["tension_std_n"]))


@pytest.mark.parametrize("smooth", [False])
def test_replay_offline_without_smoothing_writes_none(tmp_path: Path, smooth: bool) -> None:
    from groundstation.pipeline import Pipeline
    from groundstation.recording.replay import replay_offline
    from tests.test_recording import telemetry, write_recording

    t0 = 1_700_000_000 * 10**9
    msgs = [("tether/cf1/telemetry", telemetry(i), t0 + i * 4_000_000) for i in range(50)]
    src, out = tmp_path / "in.mcap", tmp_path / "out.mcap"
    write_recording(src, msgs)
    replay_offline(src, out, Pipeline(Settings()), smooth=smooth)
    assert not [m for m in iter_messages(out) if m.key.endswith("estimate_smoothed")]


def test_the_smoothed_sigma_carries_the_calibrations_misfit_as_the_live_one(
    tmp_path: Path,
) -> None:
    """With ``[calibration] tension_model_std_n`` the smoothed series' tension σ is
    ``sqrt(smoothed variance + misfit²)`` and its position σ grows with it, as the live
    Estimate's do; the smoothed tension and position themselves do not move."""
    from groundstation.config import load_settings

    model = [0.004, 0.003, 0.005]
    cal = {"thrust_scale": 1.0, "source": "test", "tension_model_std_n": model}
    _, plain = _replay(tmp_path, "plain", 1.0)
    _, wide = _replay(
        tmp_path, "wide", 1.0, load_settings(None, {"calibration": cal}, use_env=False)
    )
    k = max(wide)
    p, w = plain[k][0], wide[k][0]
    np.testing.assert_allclose(w.tension_n, p.tension_n, atol=1e-12)
    np.testing.assert_allclose(
        w.tension_std_n, np.sqrt(np.square(p.tension_std_n) + np.square(model)), rtol=1e-9
    )
    assert w.position_m is not None and p.position_m is not None
    np.testing.assert_allclose(w.position_m, p.position_m, atol=1e-12)
    # A plumb tether here (the pull is vertical): its height's σ is the one to grow.
    assert w.position_std_m[2] > 2.0 * p.position_std_m[2]


def _hover_flight(
    seed: int, n: int, dt_s: float, filt: TensionFilter
) -> tuple[np.ndarray, np.ndarray, list]:
    """A hover at constant tension, fed to ``filt`` with its thrust balance: the velocity an
    AR(1) of σ 0.02 m/s and correlation 0.5 s, ``h = T − m·dv/dt`` plus 3 mN of thrust noise,
    the accelerometer model ``z = T`` plus 0.3 m/s² of vibration (× m). Returns the truth, the
    causal estimates and the trace (one init, then updates)."""
    rng = np.random.default_rng(seed)
    m = filt.params.mass_kg
    truth = np.array([0.012, -0.004, 0.031])
    rho = math.exp(-dt_s / 0.5)
    v = np.zeros(3)
    trace = filt.start_trace()
    ests = []
    for _ in range(n):
        v_new = rho * v + math.sqrt(1 - rho * rho) * 0.02 * rng.normal(size=3)
        h = truth - m * (v_new - v) / dt_s + rng.normal(0.0, 0.003, 3)
        v = v_new
        z = truth + m * rng.normal(0.0, 0.3, 3)
        ests.append(filt.update(z, dt_s, hover_model_world_n=h).tension_world_n)
    return truth, np.array(ests), trace


def test_the_smoother_follows_the_hovers_velocity_as_the_filter_does() -> None:
    """While the drone hovers the causal filter's state is (T, v) with the thrust balance as
    an input and ``v = 0`` observed (HoverVelocity); the smoother runs the same model
    (filterpy, 6 states, the input through ``B·u``). Its last step, where smoothed equals
    filtered, is the causal filter's state (R fixed: no rescale, which the trace does not
    record); over the hover it is closer to the truth than the causal filter and than a
    smoother that drops the hover's part of the trace (the tension alone, as before)."""
    params = TensionFilterParams(estimate_noise=False, accel_noise_mps2=0.3)
    filt = TensionFilter(params)
    truth, ests, trace = _hover_flight(21, 3000, 0.01, filt)
    hovering = [s.hover is not None for s in trace]
    assert trace[0].kind == "init" and not hovering[0] and all(hovering[1:])
    assert trace[1].hover is not None and trace[1].hover.started
    assert not any(s.hover.started for s in trace[2:] if s.hover is not None)
    assert not any(s.restart for s in trace)  # no change detected: one regime
    sm = smooth_tension(trace)
    np.testing.assert_allclose(sm.tension_world_n[-1], ests[-1], rtol=0, atol=1e-9)
    np.testing.assert_allclose(sm.variance_n2[-1], trace[-1].p_n2, rtol=1e-6)
    causal_p = np.array([s.p_n2 for s in trace])
    assert np.all(sm.variance_n2 <= causal_p * (1 + 1e-9))
    alone = smooth_tension([dataclasses.replace(s, hover=None) for s in trace])
    err = {
        "causal": np.sqrt(np.mean((ests[500:] - truth) ** 2)),
        "smoothed": np.sqrt(np.mean((sm.tension_world_n[500:] - truth) ** 2)),
        "tension alone": np.sqrt(np.mean((alone.tension_world_n[500:] - truth) ** 2)),
    }
    assert err["smoothed"] < 0.8 * err["causal"], err
    assert err["smoothed"] < 0.8 * err["tension alone"], err


def test_a_hover_that_begins_and_ends_inside_a_regime() -> None:
    """A hover between two stretches without one (the velocity started afresh, then
    forgotten): the smoother's last step is still the causal filter's state, and the
    stretches before and after the hover are smoothed as the tension alone would be where
    the hover cannot reach them."""
    params = TensionFilterParams(estimate_noise=False, accel_noise_mps2=0.3)
    filt = TensionFilter(params)
    trace = filt.start_trace()
    rng = np.random.default_rng(4)
    truth = np.array([0.0, 0.01, 0.02])
    ests = []
    for k in range(1500):
        z = truth + 0.009 * rng.normal(size=3)
        h = truth + rng.normal(0.0, 0.003, 3) if 500 <= k < 1000 else None
        ests.append(filt.update(z, 0.01, hover_model_world_n=h).tension_world_n)
    starts = [i for i, s in enumerate(trace) if s.hover is not None and s.hover.started]
    assert starts == [500]
    assert trace[999].hover is not None and trace[1000].hover is None
    sm = smooth_tension(trace)
    np.testing.assert_allclose(sm.tension_world_n[-1], ests[-1], rtol=0, atol=1e-9)
    np.testing.assert_allclose(sm.variance_n2[-1], trace[-1].p_n2, rtol=1e-6)
    # the hover's information lowers the smoothed variance inside it below the causal one
    causal_p = np.array([s.p_n2 for s in trace])
    assert np.all(sm.variance_n2[600:900] < causal_p[600:900])


def test_replay_offline_smooths_a_realistic_flight_no_worse_than_the_estimate(
    tmp_path: Path,
) -> None:
    """End to end on the realistic simulator (benchmarks.bench_powerons' flight: floor,
    spool-up, climb, four spots; attitude levelled on the accelerometer; calibration = the
    flight's own constants; no motion capture), through ``replay_offline``: in the dwells the
    smoothed position is no worse than the published one (the smoother once ignored the
    hover's thrust balance and read 14.7 cm where the estimate read 0.8), and in the 2 s
    after each move, where the causal filter lags, it is better."""
    from benchmarks import bench_powerons as bp
    from benchmarks.bench_smoother import _outputs
    from groundstation.config import load_settings
    from groundstation.pipeline import Pipeline
    from groundstation.recording.reader import copy_messages
    from groundstation.recording.replay import replay_offline

    rec = bp.record(11, 0.8, mocap=False, levelled=True)
    path = tmp_path / "flight.mcap"
    copy_messages(rec.messages, path)
    cal = {**rec.errors["airframe_equivalent"], "source": "truth"}
    out = tmp_path / "out.mcap"
    replay_offline(path, out, Pipeline(load_settings(None, {"calibration": cal}, use_env=False)))
    causal, smoothed = _outputs(out)
    moves = [(a - bp.SETTLE_S, a - bp.SETTLE_S + 2.0) for a, _ in rec.judged_from_s]
    err: dict[str, dict[str, list[float]]] = {
        w: {"causal": [], "smoothed": []} for w in ("dwell", "move")
    }
    for seq, e in causal.items():
        s, tr = smoothed.get(seq), rec.truth.get(round(e["stamp_s"], 6))
        if s is None or tr is None or e["on_ground"]:
            continue
        t = e["stamp_s"]
        kind = (
            "dwell"
            if any(a <= t < b for a, b in rec.judged_from_s)
            else "move"
            if any(a <= t < b for a, b in moves)
            else None
        )
        if kind is None or e["position_m"] is None or s["position_m"] is None:
            continue
        for key, est in (("causal", e), ("smoothed", s)):
            err[kind][key].append(
                float(np.linalg.norm(np.subtract(est["position_m"], tr["position_m"])))
            )
    med = {w: {k: float(np.median(v)) for k, v in d.items()} for w, d in err.items()}
    assert min(len(v) for d in err.values() for v in d.values()) > 100, err.keys()
    assert med["dwell"]["smoothed"] <= 1.25 * med["dwell"]["causal"] + 0.002, med
    assert med["move"]["smoothed"] < 0.8 * med["move"]["causal"], med
