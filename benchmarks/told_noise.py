"""The estimator issue's baseline for a tug: "an estimator told the noise".

A GLR test for a change of mean in any direction, told the true noise (the long-run variance
of the observations about the truth before the change, per axis: what a sum of samples
suffers, colour included) and the true level before it, at the service's false-alarm rate
(0.005 per hour, windows up to 1 s, :func:`groundstation.tension_change.scan_threshold`); from
its detection a random-walk Kalman filter with a chosen time constant (Q = r·dt²/τ² per
sample, as the service's), started from the detecting window's mean with P = r/n. The
benchmarks run it over a grid of time constants and report the best, chosen in hindsight: a
bound the service, told neither the noise nor the level nor the best time constant, is not
expected to beat. Used by ``bench_reel_tug`` and ``bench_realistic``'s tug.
"""

from __future__ import annotations

import numpy as np

from groundstation.tension_change import scan_threshold

FALSE_ALARMS_PER_H = 0.005
"""The service's rate (``TensionFilterParams.false_alarms_per_h``)."""
MAX_WINDOW_S = 1.0
"""The detector's longest window, s (the service's change test's when this baseline was
set; kept, so that its figures compare across pages)."""
TAUS_S = (0.05, 0.1, 0.2, 0.3, 0.5, 1.0, 2.0)
"""Time constants of the random-walk filter the benchmarks try, s."""
BLOCK = 25
"""Samples per block of the long-run variance (0.1 s at 250 Hz, 0.25 s at 100 Hz)."""


def long_run_variance_n2(err_n: np.ndarray, block: int = BLOCK) -> np.ndarray:
    """Long-run variance per axis of an error sequence (N^2): ``block x Var(block means)``."""
    n = (len(err_n) // block) * block
    means = err_n[:n].reshape(-1, block, 3).mean(axis=1)
    out: np.ndarray = block * means.var(axis=0, ddof=1)
    return out


def _forward_filled(obs_n: np.ndarray) -> np.ndarray:
    """Rows with a NaN (no observation) take the previous row's values (the first finite row
    before any)."""
    ok = np.all(np.isfinite(obs_n), axis=1)
    if ok.all():
        return obs_n
    idx = np.where(ok, np.arange(len(obs_n)), 0)
    np.maximum.accumulate(idx, out=idx)
    first = int(np.argmax(ok))
    idx[: first + 1] = first
    return obs_n[idx]


def glr_random_walk(
    t_s: np.ndarray,
    obs_n: np.ndarray,
    true_n: np.ndarray,
    change_s: float,
    tau_s: float,
    level_s: float = 2.0,
    noise_s: float = 8.0,
) -> tuple[np.ndarray, float | None]:
    """Estimates per sample and the detection time (from ``change_s``; None: none).

    Told: the truth's mean over ``level_s`` before ``change_s`` (the level), and the long-run
    variance of ``obs_n − true_n`` over ``noise_s`` before it (the noise; 8 s of 0.1-0.25 s
    blocks: within ~±15 %). Before its detection the estimate is
    that level. The scan starts 1 s before the change (a false alarm there counts).
    """
    before = (t_s >= change_s - level_s) & (t_s < change_s)
    level = true_n[before].mean(axis=0)
    quiet = (t_s >= change_s - noise_s) & (t_s < change_s)
    r = long_run_variance_n2(obs_n[quiet] - true_n[quiet])
    dt = float(np.median(np.diff(t_s)))
    n_max = max(int(MAX_WINDOW_S / dt), 2)
    h = scan_threshold(FALSE_ALARMS_PER_H, 1.0, float(n_max), dt)
    est = np.tile(level, (len(t_s), 1))
    obs_n = _forward_filled(obs_n)
    w = (obs_n - level) / np.sqrt(r)  # whitened about the known level
    cum = np.vstack([np.zeros(3), np.cumsum(w, axis=0)])
    k_det, n_det = None, 0
    for k in range(int(np.searchsorted(t_s, change_s - 1.0)), len(t_s)):
        n = np.arange(1, min(n_max, k + 1) + 1)
        stat = ((cum[k + 1] - cum[k + 1 - n]) ** 2).sum(axis=1) / n
        j = int(np.argmax(stat))
        if stat[j] > h:
            k_det, n_det = k, int(n[j])
            break
    if k_det is None:
        return est, None
    x = obs_n[k_det + 1 - n_det : k_det + 1].mean(axis=0)
    p = r / n_det
    q = r * dt * dt / (tau_s * tau_s)  # q = r dt / tau^2 per second, times dt
    est[k_det] = x
    for k in range(k_det + 1, len(t_s)):
        p = p + q
        gain = p / (p + r)
        x = x + gain * (obs_n[k] - x)
        p = (1.0 - gain) * p
        est[k] = x
    return est, float(t_s[k_det] - change_s)
