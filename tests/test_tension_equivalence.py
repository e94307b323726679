"""The tension filter's fast bookkeeping against slow references that recompute from scratch.

The per-message filter keeps running sums and a certificate instead of re-summing windows
(groundstation/tension_change.py) and defers the fields nobody reads on the hot path
(``TensionEstimate.change_statistic``, ``noise_std_n``, ``noise_autocorrelation``). Each
test here recomputes what those shortcuts stand for, the straightforward way, over long
streams (buffer moves, regime restarts, drifts that cross the threshold), and compares.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from groundstation.tension import TensionEstimate, TensionFilter, TensionFilterParams
from groundstation.tension_change import ChangeTest, youth_factor
from groundstation.tension_noise import per_sample


def _slow_change_statistic(
    history: list[np.ndarray], n_min: int, n_valid: int, youth: float
) -> tuple[float, int]:
    """``max_n |sum of the last n w|^2 / (n youth)`` over n = n_min .. n_valid, every
    window summed afresh from the innovations (a cumulative sum from the newest back, made
    anew at every call; the smallest n on a tie)."""
    sums = np.cumsum(np.array(history[::-1]), axis=0)[n_min - 1 : n_valid]  # n_min .. n_valid
    n = np.arange(n_min, n_valid + 1)
    stats = np.sum(sums * sums, axis=1) / (n * youth)
    best = int(np.argmax(stats))
    return float(stats[best]), int(n[best])


@pytest.mark.parametrize("seed", [1, 2])
def test_change_test_equals_windows_summed_afresh(seed: int) -> None:
    """Over 8 000 innovations (the buffer moves ~20 times; regimes restart; drifts push
    the statistic over the threshold): wherever the certificate says no window can cross,
    none does, and the statistic, read at once or long after, and its window equal the
    windows summed afresh, to 1e-9, whatever the longest window in use (``cap_n``) was
    set to meanwhile."""
    rng = np.random.default_rng(seed)
    size, n_min, threshold = 128, 4, 50.0
    test = ChangeTest(n_min, 1.0, size, threshold)
    history: list[np.ndarray] = []
    bias = np.zeros(3)
    certified = evaluated = crossings = 0
    deferred = []
    for k in range(8_000):
        if rng.random() < 0.002:  # a restart: a new regime
            test.clear()
            history = []
        if rng.random() < 0.01:  # a drift starts or stops: statistics over the threshold
            bias = rng.normal(0.0, 0.6, 3) if not bias.any() else np.zeros(3)
        w = rng.normal(size=3) + bias
        z = tuple(rng.normal(size=3).tolist())
        history.append(w)
        history = history[-size:]
        dt_mean = float(rng.choice([0.004, 0.01, math.nan]))
        youth = youth_factor(int(rng.integers(1, 2000)))
        if rng.random() < 0.05:  # the filter sets the longest window from the noise
            test.set_cap(int(rng.integers(1, size + 1)))
        n_valid = max(test.window_cap(dt_mean, len(history)), n_min) if len(history) >= n_min else 0
        if test.push(z, tuple(w.tolist())):
            certified += 1
            lazy = test.lazy_statistic(dt_mean, youth)
            if n_valid >= n_min:
                want, _ = _slow_change_statistic(history, n_min, n_valid, youth)
                # Sound: no window within the cap above the threshold, whatever the youth
                # factor (a longer window only grows until the next evaluation).
                want_1, _ = _slow_change_statistic(history, n_min, n_valid, 1.0)
                assert want_1 <= threshold
                if k % 7 == 0:
                    deferred.append((lazy, want))  # read long after
                else:
                    assert lazy() == pytest.approx(want, rel=1e-9, abs=1e-12)
        else:
            evaluated += 1
            stat, window = test.evaluate(dt_mean, youth)
            if n_valid >= n_min:
                want, want_n = _slow_change_statistic(history, n_min, n_valid, youth)
                assert stat == pytest.approx(want, rel=1e-9, abs=1e-12)
                assert window == want_n
                crossings += stat > threshold
    for lazy, want in deferred:
        assert lazy() == pytest.approx(want, rel=1e-9, abs=1e-12)
    assert certified > evaluated  # the certificate spares most evaluations (half are drifts)
    assert crossings >= 10 and len(deferred) > 300


def test_a_history_that_grows_keeps_what_it_held() -> None:
    """The history's capacity follows the spacing (``ChangeTest.reserve``, called by the
    filter at each new spacing): a test that starts with room for 8 samples and grows to 32
    and then 128 midway gives, at every step, the statistic, window and restart mean of one
    built with 128 from the start, on the same innovations, over the windows it held."""
    rng = np.random.default_rng(5)
    grown, whole = ChangeTest(4, 1.0, 8, 50.0), ChangeTest(4, 1.0, 128, 50.0)
    bias = np.zeros(3)
    for k in range(2_000):
        if k in (10, 700):
            grown.reserve(20 if k == 10 else 100)
        if k == 1_500:
            grown.clear()
            whole.clear()
        if rng.random() < 0.01:
            bias = rng.normal(0.0, 0.6, 3) if not bias.any() else np.zeros(3)
        w = tuple((rng.normal(size=3) + bias).tolist())
        z = tuple(rng.normal(size=3).tolist())
        # The windows the grown one holds (what it never held it cannot give back).
        cap = max(min(grown.ring.count + 1, grown.ring.size), 4)
        for test in (grown, whole):
            test.set_cap(cap)
            test.push(z, w)
        got, want = grown.evaluate(math.nan, 1.0), whole.evaluate(math.nan, 1.0)
        assert got[1] == want[1] and got[0] == pytest.approx(want[0], rel=1e-12, abs=1e-12)
        n = min(grown.ring.count, cap)
        if n:
            np.testing.assert_allclose(grown.mean_of_window(n), whole.mean_of_window(n))
    assert grown.ring.size == 128 and grown.ring.count == whole.ring.count


def test_restart_mean_is_the_mean_of_the_window() -> None:
    """The restart's x: the mean of the last n observations, summed afresh."""
    rng = np.random.default_rng(3)
    test = ChangeTest(4, 1.0, 64, 50.0)
    zs = []
    for _ in range(300):
        z = tuple(rng.normal(size=3).tolist())
        zs.append(z)
        test.push(z, (0.0, 0.0, 0.0))
        n = int(rng.integers(1, min(len(zs), 64) + 1))
        np.testing.assert_allclose(
            test.mean_of_window(n), np.mean(np.array(zs[-n:]), axis=0), rtol=1e-12, atol=1e-15
        )


def _flight(n: int, seed: int, rate_hz: float, noise_n: float) -> list[tuple[np.ndarray, float]]:
    """Observations (N) and spacings (s): hover, tugs, a ramp, jitter and a gap."""
    rng = np.random.default_rng(seed)
    level = np.array([-0.02, 0.005, -0.06])
    ar = np.zeros(3)
    out = []
    for k in range(n):
        if k % 3000 == 1500:
            level = level + rng.normal(0.0, 0.03, 3)  # a tug
        if 6000 <= k < 7000:
            level = level + 0.01 / rate_hz  # 10 mN/s ramp
        dt = (1.0 + 0.2 * (rng.random() - 0.5)) / rate_hz
        if k == 4000:
            dt = 0.6  # a gap
        ar = 0.3 * ar + rng.normal(0.0, noise_n, 3)
        out.append((level + ar, dt))
    return out


@pytest.mark.parametrize(("rate_hz", "noise_n"), [(250.0, 0.009), (100.0, 0.06)])
def test_deferred_fields_equal_their_formulas(rate_hz: float, noise_n: float) -> None:
    """Over 10 000 steps of a flight, every estimate equals ``TensionEstimate(...)`` built
    field by field; its noise fields equal :func:`per_sample` of the noise model in force
    at that step; and reading a field late (after buffer moves and restarts) gives what
    reading it at once gave on a twin filter."""
    now, late = TensionFilter(), TensionFilter()
    kept = []
    changes = 0
    for k, (y, dt) in enumerate(_flight(10_000, 5, rate_hz, noise_n)):
        a = now.update(y, dt)
        b = late.update(y, dt)
        s2, rho, _ = now.noise_model()
        want_std = tuple(math.sqrt(v) for v in per_sample(now._noise.d1, now._noise.s2)[0])
        assert a.noise_std_n == want_std == tuple(math.sqrt(v) for v in s2)
        assert a.noise_autocorrelation == rho
        values = {f.name: getattr(a, f.name) for f in dataclasses.fields(TensionEstimate)}
        built = TensionEstimate(**values)
        for name, value in values.items():
            np.testing.assert_array_equal(getattr(built, name), value)
        assert not a.tension_world_n.flags.writeable and not a.cov_n2.flags.writeable
        assert a.cov_n2.shape == (3, 3) and a.std_n.shape == (3,)
        changes += a.change_detected
        if k % 11 == 0:
            kept.append((b, values))
    for b, values in kept:  # read now, thousands of steps after
        for name, value in values.items():
            np.testing.assert_array_equal(getattr(b, name), value)
    assert changes >= 2


def test_estimate_defaults_and_replace() -> None:
    """The deferred fields behave as plain dataclass fields: defaults, replace, repr."""
    e = TensionEstimate(np.zeros(3), np.zeros((3, 3)), np.zeros(3), False, False, 0)
    assert e.change_statistic == 0.0
    assert all(math.isnan(v) for v in e.noise_std_n) and e.noise_autocorrelation == (0.0,) * 3
    f = TensionFilter(TensionFilterParams())
    for y, dt in _flight(200, 9, 250.0, 0.009):
        est = f.update(y, dt)
    r = dataclasses.replace(est, samples=7)
    assert r.samples == 7 and r.change_statistic == est.change_statistic
    assert r.noise_std_n == est.noise_std_n and "change_statistic=" in repr(est)
    with pytest.raises(dataclasses.FrozenInstanceError):
        est.change_statistic = 1.0  # type: ignore[misc]


def test_observation_is_what_its_constructor_makes() -> None:
    """observe_tension's result, made without the dataclass's ``__init__``, equals the one
    its constructor makes from the same fields, and its array is read-only float64 (3,)."""
    from groundstation.tension import TensionObservation, observe_tension, rotation_world_body

    rng = np.random.default_rng(4)
    for _ in range(200):
        q = rng.normal(size=4)
        accel = rng.normal(0.0, 3.0, 3) + np.array([0.0, 0.0, 9.81])
        obs = observe_tension(accel, q, float(rng.uniform(0.2, 0.6)), 0.03)
        assert obs.tension_world_n is not None
        names = [f.name for f in dataclasses.fields(TensionObservation)]
        built = TensionObservation(**{n: getattr(obs, n) for n in names})
        assert vars(built).keys() == vars(obs).keys()
        t = obs.tension_world_n
        assert t.dtype == np.float64 and t.shape == (3,) and not t.flags.writeable
        # T = R (m f - e3 F), with the rotation matrix (eq:NE_tether)
        want = rotation_world_body(q) @ (0.03 * accel - np.array([0.0, 0.0, obs.thrust_n]))
        np.testing.assert_allclose(t, want, rtol=1e-12, atol=1e-15)
