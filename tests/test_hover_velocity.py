"""The hover's velocity state (tension_kalman.HoverVelocity) and its use by the filter.

While the drone hovers the filter's state per world axis is (T, v): ``m·dv/dt = T − h``
with h the thrust balance, the accelerometer model observing T, and ``v = 0`` observed with
variance ``σ_v²·T_c/dt``. Checked here: the closed form equals filterpy's 2-state
``KalmanFilter`` step for step; in a synthetic hover the thrust balance makes the estimate
more precise than the accelerometer model alone, with a σ that holds it; and a tug that the
thrust balance does not see yet is found in the accelerometer model's innovations.
"""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from groundstation import config as config_mod
from groundstation.config import FilterSection
from groundstation.tension import TensionFilter, TensionFilterParams
from groundstation.tension_kalman import DiagonalKalman, HoverVelocity

MASS_KG = 0.030


def test_closed_form_equals_filterpy() -> None:
    rng = np.random.default_rng(7)
    r = [0.04**2, 0.03**2, 0.05**2]
    var_v, t_c, q_v = 0.05**2, 0.5, 1e-2
    x0, p0 = [-0.02, 0.01, -0.06], [1e-4, 2e-4, 3e-4]
    kf = DiagonalKalman()
    kf.set(x0, p0)
    hv = HoverVelocity()
    hv.start(var_v)
    refs = []
    for i in range(3):
        ref = KalmanFilter(dim_x=2, dim_z=1)
        ref.x = np.array([[x0[i]], [0.0]])
        ref.P = np.diag([p0[i], var_v])
        refs.append(ref)
    true_n = np.array([-0.02, 0.01, -0.06])
    for _ in range(400):
        dt = float(rng.uniform(0.006, 0.027))
        q = tuple(float(v) for v in rng.uniform(1e-9, 1e-7, 3))
        h = tuple(float(v) for v in true_n + rng.normal(0.0, 0.003, 3))
        z = tuple(float(v) for v in true_n + rng.normal(0.0, 0.04, 3))
        rest_var = var_v * t_c / dt
        x_prev = kf.x
        kf.predict(q)
        a_pred = kf.P
        w = kf.update(z, r)
        hv.step(kf, x_prev, a_pred, q, h, r, w, dt, MASS_KG, q_v, rest_var)
        d = dt / MASS_KG
        for i, ref in enumerate(refs):
            ref.F = np.array([[1.0, 0.0], [d, 1.0]])
            ref.B = np.array([[0.0], [-d]])
            ref.predict(u=np.array([[h[i]]]), Q=np.diag([q[i], q_v * dt]))
            ref.update(np.array([[z[i]]]), R=r[i], H=np.array([[1.0, 0.0]]))
            ref.update(np.array([[0.0]]), R=rest_var, H=np.array([[0.0, 1.0]]))
    for i, ref in enumerate(refs):
        assert math.isclose(kf.x[i], ref.x[0, 0], rel_tol=1e-9, abs_tol=1e-12)
        assert math.isclose(hv.v[i], ref.x[1, 0], rel_tol=1e-9, abs_tol=1e-12)
        assert math.isclose(kf.P[i], ref.P[0, 0], rel_tol=1e-7)
        assert math.isclose(hv.b[i], ref.P[0, 1], rel_tol=1e-7, abs_tol=1e-15)
        assert math.isclose(hv.c[i], ref.P[1, 1], rel_tol=1e-7)


def _hover(
    seconds: float, true_n: np.ndarray, *, thrust_balance: bool, seed: int = 3
) -> tuple[np.ndarray, np.ndarray]:
    """A hover at 100 Hz: the accelerometer model reads T + 35 mN of white vibration per
    axis, the thrust balance reads T within 2 mN. Returns the estimates and their σ."""
    rng = np.random.default_rng(seed)
    filt = TensionFilter(TensionFilterParams(mass_kg=MASS_KG))
    out, std = [], []
    for _ in range(int(seconds / 0.01)):
        z = true_n + rng.normal(0.0, 0.035, 3)
        h = true_n + rng.normal(0.0, 0.002, 3)
        hover = tuple(float(v) for v in h) if thrust_balance else None
        e = filt.update(z, 0.01, hover_model_world_n=hover)
        out.append(e.tension_world_n)
        std.append(e.std_n)
    return np.array(out), np.array(std)


def test_the_thrust_balance_makes_the_hover_precise() -> None:
    true_n = np.array([-0.020, 0.005, -0.060])
    with_h, std = _hover(10.0, true_n, thrust_balance=True)
    without, _ = _hover(10.0, true_n, thrust_balance=False)
    late = slice(500, None)  # from 5 s
    err_with = np.sqrt(np.mean((with_h[late] - true_n) ** 2))
    err_without = np.sqrt(np.mean((without[late] - true_n) ** 2))
    assert err_with < 0.5 * err_without, (err_with, err_without)
    assert err_with < 0.001
    # σ is not narrower than the error (here the model is the world's).
    inside = np.abs(with_h[late] - true_n) <= 2.0 * std[late]
    assert inside.mean() >= 0.9, inside.mean()


def test_a_tug_under_the_hover_is_found() -> None:
    """A 30 mN step at 5 s, which the thrust balance does not see yet (the controller has
    not answered): the accelerometer model's innovations find it within 1.5 times the
    information limit, the time at which the step's samples hold the fast test's threshold
    as non-centrality (n·step²/r = 50, r the vibration's variance: 0.68 s here)."""
    rng = np.random.default_rng(11)
    filt = TensionFilter(TensionFilterParams(mass_kg=MASS_KG))
    true_n = np.array([-0.020, 0.005, -0.060])
    step = np.array([0.030, 0.0, 0.0])
    found = None
    for k in range(800):
        t = k * 0.01
        tension = true_n + (step if t >= 5.0 else 0.0)
        z = tension + rng.normal(0.0, 0.035, 3)
        h = true_n + rng.normal(0.0, 0.002, 3)
        e = filt.update(z, 0.01, hover_model_world_n=tuple(float(v) for v in h))
        if e.change_detected:
            assert t >= 5.0, f"a detection before the tug, at {t:.2f} s"
            found = t
            break
    limit_s = filt.change_threshold * 0.035**2 / 0.030**2 * 0.01
    assert found is not None and found - 5.0 < 1.5 * limit_s, (found, limit_s)


def test_a_crossover_without_meaning_is_accepted_with_one_warning(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """``[filter] accel_hover_crossover_s``: only 0 (hover off) or on means something now;
    another value is kept, with one warning that names what replaced it."""
    config_mod._warned.clear()
    with caplog.at_level(logging.WARNING, logger="groundstation.config"):
        for _ in range(3):
            sec = FilterSection(accel_hover_crossover_s=0.5)
    assert sec.accel_hover_crossover_s == 0.5
    said = [r.getMessage() for r in caplog.records]
    assert len(said) == 1 and "velocity" in said[0] and "replaced" in said[0]
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="groundstation.config"):
        FilterSection()
        FilterSection(accel_hover_crossover_s=0.0)
    assert caplog.records == []
