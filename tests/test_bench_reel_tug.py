"""The reel-tug benchmark's own parts: its criterion and its told-the-noise baseline."""

from __future__ import annotations

import numpy as np

from benchmarks.bench_reel_tug import TUG_S, t90, told_the_noise


def _flight(seed: int, moving: bool) -> dict[str, np.ndarray]:
    dt = 0.004
    t = np.arange(int((TUG_S + 3.0) / dt)) * dt
    true = np.tile([-0.014, 0.0, -0.046], (len(t), 1))
    after = t >= TUG_S
    true[after] += [-0.030, 0.0, 0.0]
    if moving:
        true[after, 0] += 0.015 * (1.0 - np.exp(-(t[after] - TUG_S) / 0.2))
    rng = np.random.default_rng(seed)
    obs = true + rng.normal(0.0, 0.009, true.shape)
    return {"t_s": t, "true_n": true, "obs_n": obs, "est_n": true.copy()}


def test_told_the_noise_detects_a_step_at_once_and_follows_it() -> None:
    for seed in range(3):
        f = _flight(seed, moving=False)
        est, detection_s = told_the_noise(f, 0.5)
        assert detection_s is not None and 0.0 <= detection_s <= 0.05
        err = np.linalg.norm(est - f["true_n"], axis=1)
        assert t90(f["t_s"], err, 0.030) is not None
        before = f["t_s"] < TUG_S - 1.0
        assert np.allclose(est[before], f["true_n"][before])  # the level it was told


def test_a_short_time_constant_follows_a_moving_truth_better() -> None:
    errs = {}
    for tau in (0.1, 2.0):
        rms = []
        for seed in range(3):
            f = _flight(seed, moving=True)
            est, _ = told_the_noise(f, tau)
            w = (f["t_s"] >= TUG_S + 0.1) & (f["t_s"] < TUG_S + 1.0)
            rms.append(np.sqrt(np.mean(np.sum((est[w] - f["true_n"][w]) ** 2, axis=1))))
        errs[tau] = float(np.median(rms))
    assert errs[0.1] < 0.7 * errs[2.0], errs


def test_the_reel_tug_meets_the_issue_target_on_three_seeds() -> None:
    """The estimator issue's reel tug on the ideal profile (docs/reel_tug.md has 8 seeds:
    every one within 0.58 s, median 0.43 s; 0.81 s before the after-change hypothesis, when
    these three read 0.86, 0.56 and 1.07 s): the median of three seeds within the issue's
    0.6 s, the pre-tug error within its 1.5 mN."""
    from benchmarks.bench_reel_tug import PRE_TUG_TARGET_N, T90_TARGET_S, fly, judge

    runs = [judge(fly("ideal", seed)) for seed in (700, 701, 702)]
    t90s = sorted(9.0 if r["t90_s"] is None else r["t90_s"] for r in runs)
    assert t90s[1] <= T90_TARGET_S, runs
    assert all(r["pre_tug_error_mn"] <= 1e3 * PRE_TUG_TARGET_N for r in runs), runs


def test_two_commits_are_compared_sample_by_sample() -> None:
    """``reel_tug_diff.compare``: an estimate 0.2 mN off along x everywhere differs by
    0.2 mN at every stamp both published, and its mean error over the span is 0.2 mN more;
    stamps only one side published are left out; t90 judged on each as the page does."""
    from benchmarks.reel_tug_diff import compare

    f = _flight(0, moving=False)
    t, true = f["t_s"], f["true_n"]
    lag = np.where((t >= TUG_S) & (t < TUG_S + 0.3), 1.0, 0.0)[:, None]
    est = true + lag * [0.030, 0.0, 0.0]  # 0.3 s behind the jump, then exact
    shifted = est + np.array([0.0002, 0.0, 0.0])
    before = {"t_s700": t, "est_n700": est, "true_n700": true}
    after = {"t_s700": t[::2], "est_n700": shifted[::2], "true_n700": true[::2]}
    r = compare(before, after, 700)
    assert abs(r["median_difference_mn"] - 0.2) < 1e-9
    assert abs(r["max_difference_mn"] - 0.2) < 1e-9
    assert r["mean_error_after_mn"] is not None and r["mean_error_before_mn"] is not None
    assert r["mean_error_after_mn"] > r["mean_error_before_mn"]
    assert r["t90_before_s"] is not None and abs(r["t90_before_s"] - 0.3) < 0.01
    assert r["t90_after_s"] is not None and abs(r["t90_after_s"] - 0.3) < 0.01
