"""The noise estimate's prior and its winsorisation (no ratio of its own)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2

from groundstation.tension import TensionFilterParams
from groundstation.tension_change import (
    ESTIMATE_SIGMAS,
    exceedance_square,
    kappa_prior_blocks,
    noise_warmup_samples,
)
from groundstation.tension_noise import NoiseEstimate

RATE_PER_H = TensionFilterParams().false_alarms_per_h
TAU_S = TensionFilterParams().noise_time_constant_s
PRIOR_SAMPLES = TensionFilterParams().noise_prior_samples
WARM = noise_warmup_samples()
KEEP = math.exp(-0.01 / TAU_S)  # the level's decay over a 100 Hz spacing


@pytest.mark.parametrize("dt_s", [0.004, 0.01, 0.04, NoiseEstimate.BLOCK_S])
def test_exceedance_square_is_the_chi_square_quantile_of_one_degree(dt_s: float) -> None:
    """z² with P(χ²₁ > z²) = rate·dt / 3600 s: a Gaussian's square over its mean exceeds it
    by chance at the one false-alarm rate (32.2 per sample at 100 Hz, 26.0 per block)."""
    p = RATE_PER_H * dt_s / 3600.0
    assert exceedance_square(RATE_PER_H, dt_s) == pytest.approx(chi2.isf(p, 1), rel=1e-6)
    assert exceedance_square(0.0, dt_s) == math.inf
    assert exceedance_square(RATE_PER_H, 0.01) == pytest.approx(32.2, abs=0.05)
    assert exceedance_square(RATE_PER_H, NoiseEstimate.BLOCK_S) == pytest.approx(26.0, abs=0.05)


def test_the_prior_weighs_its_samples_in_the_running_mean() -> None:
    """Before any difference the level is the prior's; then the running mean of the prior,
    weighed as ``prior_samples`` differences, and the data."""
    noise = NoiseEstimate((4.0, 4.0, 4.0), 2.0, RATE_PER_H)
    noise.push((0.0, 0.0, 0.0), 0.01, KEEP, TAU_S, WARM)
    assert noise.d1 == [8.0, 8.0, 8.0]  # 2 s_d = 2 × the prior variance
    noise.push((0.1, -0.2, 0.3), 0.01, KEEP, TAU_S, WARM)
    assert noise.d1 == pytest.approx([(16.0 + e) / 3.0 for e in (0.01, 0.04, 0.09)])
    noise.push((0.1, -0.2, 0.0), 0.01, KEEP, TAU_S, WARM)
    assert noise.d1 == pytest.approx([(16.0 + e) / 4.0 for e in (0.01, 0.04, 0.18)])


@pytest.mark.parametrize("dt_s", [0.004, 0.01])
def test_winsorisation_is_where_gaussian_noise_ends(dt_s: float) -> None:
    """Once the blocks have measured the spacing, a squared difference is capped at
    ``exceedance_square`` at that spacing: 60 s of Gaussian noise is never capped (its level
    within 10 % of the truth), a tug's single jump of 50 σ moves the level by the cap's share
    alone, and κ's block ratio is capped at the per-block value."""
    rng = np.random.default_rng(11)
    sigma = 0.02
    noise = NoiseEstimate((1.0, 1.0, 1.0), PRIOR_SAMPLES, RATE_PER_H)
    assert noise.sample_cap == math.inf  # no block yet
    assert noise.block_cap == pytest.approx(exceedance_square(RATE_PER_H, NoiseEstimate.BLOCK_S))
    capped = 0
    for y in rng.normal(0.0, sigma, (int(60.0 / dt_s), 3)).tolist():
        if noise.samples > WARM:
            d = [y[i] - noise.prev1[i] for i in range(3)] if noise.prev1 else [0.0] * 3
            capped += sum(d[i] * d[i] > noise.sample_cap * noise.d1[i] for i in range(3))
        noise.push(y, dt_s, math.exp(-dt_s / TAU_S), TAU_S, WARM)
    assert noise.sample_cap == pytest.approx(exceedance_square(RATE_PER_H, dt_s), rel=1e-3)
    assert capped == 0
    # s_d = σ², within 2 standard errors of a 5 s exponential mean (~1,000 samples at 100 Hz)
    assert 0.5 * np.array(noise.d1) == pytest.approx([sigma**2] * 3, rel=0.1)
    before = list(noise.d1)
    last = noise.prev1
    assert last is not None
    noise.push((last[0] + 50 * sigma, last[1], last[2]), dt_s, math.exp(-dt_s / TAU_S), TAU_S, WARM)
    alpha = -math.expm1(-dt_s / TAU_S)
    assert noise.d1[0] == pytest.approx(before[0] * (1.0 + alpha * (noise.sample_cap - 1.0)))
    assert noise.d1[0] < before[0] * 1.1  # uncapped, (50 σ)² would have raised it ~2.5x


def test_kappas_prior_weighs_the_blocks_kappa_needs_to_stand_alone() -> None:
    """κ's prior weight is where its own estimate is bounded away from zero at the change
    test's allowance: 1 - 3·sqrt((35/27)/B) = 0 at B = 9·35/27 = 11.7 blocks; after that many
    blocks the prior weighs half."""
    b = kappa_prior_blocks()
    assert b == pytest.approx(9.0 * 35.0 / 27.0)
    assert 1.0 - ESTIMATE_SIGMAS * math.sqrt((35.0 / 27.0) / b) == pytest.approx(0.0, abs=1e-12)
    # White noise (κ = 1) from the prior 1.5: after B whole blocks κ is the running mean of
    # the prior weighed b and the B block ratios, (1.5·b + B)/(b + B), on average over seeds.
    rng = np.random.default_rng(12)
    blocks = round(b)
    n = (blocks + 2) * 25 + 1  # 100 Hz: the first ratio needs three 0.25 s blocks
    kappas = []
    for _ in range(60):
        noise = NoiseEstimate((1e-4, 1e-4, 1e-4), PRIOR_SAMPLES, RATE_PER_H)
        for y in rng.normal(0.0, 0.01, (n, 3)).tolist():
            noise.push(y, 0.01, KEEP, TAU_S, WARM)
        assert noise.blocks == blocks
        kappas.append(noise.kappa)
    want = (NoiseEstimate.KAPPA_PRIOR * b + blocks) / (b + blocks)
    assert float(np.mean(kappas)) == pytest.approx(want, abs=0.05)


def test_kappas_prior_weight_is_the_derived_one_to_the_digit() -> None:
    """The same samples from two priors: κ's difference is the prior's share after B
    blocks, b/(b + B), times the priors' difference, whatever the samples (the block ratios
    are the same in both runs). 11.7 blocks and the 10 set by hand before give shares 0.04
    apart here (near the most they can differ, at B ≈ 11), far beyond rounding; the averaged
    test above cannot tell them apart."""

    class OtherPrior(NoiseEstimate):
        KAPPA_PRIOR = NoiseEstimate.KAPPA_PRIOR + 2.0

    b = kappa_prior_blocks()
    blocks = 12
    n = (blocks + 2) * 25 + 1  # 100 Hz: the first ratio needs three 0.25 s blocks
    samples = np.random.default_rng(3).normal(0.0, 0.01, (n, 3)).tolist()
    runs = []
    for cls in (NoiseEstimate, OtherPrior):
        noise = cls((1e-4, 1e-4, 1e-4), PRIOR_SAMPLES, RATE_PER_H)
        for y in samples:
            noise.push(y, 0.01, KEEP, TAU_S, WARM)
        assert noise.blocks == blocks
        runs.append(noise.kappa)
    share = (runs[1] - runs[0]) / 2.0
    assert share == pytest.approx(b / (b + blocks), rel=1e-9)
    assert abs(share - 10.0 / (10.0 + blocks)) > 0.03
