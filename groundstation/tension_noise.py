"""The tension filter's observation noise, measured on line (per world axis).

What an average of n observations suffers is the *long-run* variance r (the spectral density
at zero frequency times the rate): ``Var(mean of n) -> r / n``, with
``r = s2 (1 + 2 sum_k rho_k)`` for per-sample variance s2 and autocorrelations rho_k. The
paper's filter is told R (``eq:Kalman_vars``); :class:`groundstation.tension.TensionFilter`
uses ``R = diag(r)`` with r measured here, colour included (:class:`NoiseEstimate`).
Pure: Python floats only.
"""

from __future__ import annotations

import math

from groundstation.tension_change import exceedance_square, kappa_prior_blocks
from groundstation.tension_drift import RESCALE_TOLERANCE

__all__ = ["MIN_NOISE_VAR_N2", "NoiseEstimate", "NoiseStatus", "per_sample"]

MIN_NOISE_VAR_N2 = 1e-10
"""Floor of every noise variance, N^2 (10 uN per sample): keeps S = P- + R positive definite
on a stream that repeats one value."""
KAPPA_MIN = 0.5
"""Floor of kappa = r / s_d (half of white noise's 1): an anti-correlated stretch cannot
read the long-run variance as nothing."""
BLOCK_MIN_SAMPLES = 2
"""A noise block ends after ``NoiseEstimate.BLOCK_S`` and at least this many samples: a
guard, not a tunable. The within-block variance (``status``) divides by ``n − 1``; κ's
block ratio needs no more, since each second difference is divided by its own expected
size ``r·(1/n₀ + 4/n₁ + 1/n₂)``, exact for any block counts (it was 3, a judgement that a
two-sample block "says little": it says as much, weighed as it is). It binds only below
8 Hz (two samples per 0.25 s)."""


class NoiseEstimate:
    """On-line observation noise per world axis: short-range and long-run variance.

    Vibration noise is not white (lag-1 autocorrelation up to 0.3 on real flights) and not
    a pure AR(1) either (the realistic simulator mixes white noise with an AR(0.6) part:
    lag-1 0.2 but r = 2.0 s2, where an AR(1) with that lag-1 has 1.5 s2), so r is measured
    directly, in two parts, both blind to a slowly moving tension:

    * ``s_d = E[(y_t - y_(t-1))^2] / 2 = s2 (1 - rho_1)`` over ``noise_time_constant_s``
      = 5 s: the noise level, which moves with throttle and battery;
    * ``kappa = r / s_d``, the noise's shape, from second differences of block means
      (blocks of 0.25 s, i.e. 25 samples at 100 Hz, long against the vibration's
      correlation time): for independent blocks of n_j samples
      ``E[(m_j - 2 m_(j-1) + m_(j-2))^2] = r (1/n_j + 4/n_(j-1) + 1/n_(j-2))``, which a
      tension ramp does not reach. Pooled over the axes and averaged over six times as long
      (30 s, 120 blocks: +-8 %), from a prior kappa = 1.5 between white noise (kappa = 1)
      and real vibration (AR(1) with rho = 0.3: 2.65; the realistic simulator's: 2.5),
      weighed as the blocks kappa's estimate needs to be bounded away from zero at the
      change test's allowance (:func:`~groundstation.tension_change.kappa_prior_blocks`:
      11.7 blocks, 2.9 s).

    Then ``r = s_d kappa``. Each mean is an exponential average (a running mean for the
    first samples, started from the prior), winsorised once warm where the
    noise ends: at the ratio to its mean that a Gaussian's square exceeds by chance at the
    estimator's one false-alarm rate (:func:`~groundstation.tension_change.exceedance_square`:
    32.2 per sample at 100 Hz, at the spacing the blocks measure; 26.0 per block), so a
    tug's one large difference moves it by a few per cent at most and Gaussian noise is not
    capped. For ``status`` the
    per-sample s2 comes from the variance within blocks and ``rho_1 = 1 - s_d / s2``.

    Per message this is a few dozen float operations, written out per axis (numpy's
    per-call overhead would cost more than the arithmetic).

    Args:
        prior_var_n2: Prior per-sample variance per world axis, N^2.
        prior_samples: Weight of the prior, samples.
        false_alarms_per_h: The estimator's one false-alarm rate, 1/h
            (``TensionFilterParams.false_alarms_per_h``): the winsorisation's level.
    """

    BLOCK_S = 0.25
    SLOW = 6.0
    KAPPA_PRIOR = 1.5

    def __init__(
        self,
        prior_var_n2: tuple[float, float, float],
        prior_samples: float,
        false_alarms_per_h: float,
    ) -> None:
        self.d1 = [2.0 * v for v in prior_var_n2]
        self.s2 = list(prior_var_n2)
        self.prior_samples = prior_samples
        self.false_alarms_per_h = false_alarms_per_h
        self.sample_cap = math.inf
        """The squared difference's winsorisation over its mean (:func:`exceedance_square`
        at the spacing the blocks measured; infinite before a block has)."""
        self._cap_spacing = math.nan  # the spacing sample_cap was derived at, s
        self.block_cap = exceedance_square(false_alarms_per_h, self.BLOCK_S)
        """The block ratio's winsorisation over κ (one judged per block)."""
        self.samples = 0  # differences taken
        self.prev1: tuple[float, float, float] | None = None  # y_(t-1)
        # long-run part: kappa, the mean over blocks and axes of r_block / s_d
        # The prior, weighed as the blocks κ needs to stand on its own (kappa_prior_blocks).
        self.kappa = self.KAPPA_PRIOR
        self._prior_blocks = kappa_prior_blocks()
        self.blocks = 0
        self.break_chain()

    def break_chain(self) -> None:
        """Forgets the previous sample and the block in progress (a gap, a reset)."""
        self.prev1 = None
        self.block_sum = [0.0, 0.0, 0.0]
        self.block_sq = [0.0, 0.0, 0.0]
        self.block_n = 0
        self.block_t = 0.0
        self.means: list[tuple[list[float], int]] = []  # the last two block means, counts

    def push(
        self,
        y: tuple[float, float, float] | list[float],
        dt: float,
        keep: float,
        time_constant_s: float,
        warm: int,
    ) -> tuple[float, float, float]:
        """Takes one observation.

        Args:
            y: The observation per world axis, N.
            dt: Time since the previous one, s.
            keep: ``exp(-dt / time_constant_s)``, the level's decay over ``dt`` (the
                caller's: the filter decays its mean spacing by the same factor).
            time_constant_s: Memory of the level ``s_d``, s.
            warm: Differences after which the squared differences are winsorised.

        Returns:
            :meth:`long_run` after it, N^2.
        """
        y0, y1, y2 = y
        p1 = self.prev1
        self.prev1 = (y0, y1, y2)
        if p1 is not None:
            self.samples += 1
            a_fast = 1.0 - keep
            run = 1.0 / (self.samples + self.prior_samples)
            alpha = a_fast if a_fast > run else run  # max(run, a_fast)
            # e_i = (y_t - y_(t-1))^2 per axis, winsorised where the noise ends once warm
            e0, e1, e2 = y0 - p1[0], y1 - p1[1], y2 - p1[2]
            e0, e1, e2 = e0 * e0, e1 * e1, e2 * e2
            a0, a1, a2 = self.d1
            if self.samples > warm:
                cap = self.sample_cap
                if e0 > cap * a0:
                    e0 = cap * a0
                if e1 > cap * a1:
                    e1 = cap * a1
                if e2 > cap * a2:
                    e2 = cap * a2
            # 2 s_d <- 2 s_d + alpha (e - 2 s_d)
            self.d1 = [a0 + alpha * (e0 - a0), a1 + alpha * (e1 - a1), a2 + alpha * (e2 - a2)]
            self.block_t += dt
        bs, bq = self.block_sum, self.block_sq
        bs[0] += y0
        bs[1] += y1
        bs[2] += y2
        bq[0] += y0 * y0
        bq[1] += y1 * y1
        bq[2] += y2 * y2
        self.block_n += 1
        if self.block_t >= self.BLOCK_S and self.block_n >= BLOCK_MIN_SAMPLES:
            self._end_block(time_constant_s)
        return self.long_run()

    def _end_block(self, time_constant_s: float) -> None:
        n = self.block_n
        # The spacing this block measured sets the per-sample cap (derived again once it
        # has moved by 1 %, the filter's cost tolerance); a first block of a chain has one
        # spacing fewer than samples.
        intervals = n if self.means else n - 1
        spacing = self.block_t / intervals if intervals > 0 else math.nan
        known = self._cap_spacing
        if spacing > 0.0 and not abs(spacing - known) <= RESCALE_TOLERANCE * known:
            self._cap_spacing = spacing
            self.sample_cap = exceedance_square(self.false_alarms_per_h, spacing)
        mean = [v / n for v in self.block_sum]
        # Within-block variance (for status only), over the same memory as s_d.
        alpha = max(1.0 / (self.blocks + 2.0), self.BLOCK_S / time_constant_s)
        s2 = list(self.s2)  # a new list: a NoiseStatus may hold the old one
        for i in range(3):
            within = max(self.block_sq[i] / n - mean[i] * mean[i], 0.0) * n / (n - 1)
            s2[i] += alpha * (within - s2[i])
        self.s2 = s2
        self.means.append((mean, n))
        if len(self.means) == 3:
            (m2, n2), (m1, n1), (m0, n0) = self.means
            # E[(m0 - 2 m1 + m2)^2] = r (1/n0 + 4/n1 + 1/n2) for independent blocks
            weight = 1.0 / n0 + 4.0 / n1 + 1.0 / n2
            self.blocks += 1
            beta = max(
                1.0 / (self.blocks + self._prior_blocks),
                self.BLOCK_S / (self.SLOW * time_constant_s),
            )
            ratio = 0.0
            for i in range(3):
                sd = 0.5 * self.d1[i]
                e = (m0[i] - 2.0 * m1[i] + m2[i]) ** 2 / weight / sd if sd > 0.0 else 1.0
                ratio += min(e, self.block_cap * self.kappa) / 3.0
            self.kappa += beta * (ratio - self.kappa)
            del self.means[0]
        self.block_sum = [0.0, 0.0, 0.0]
        self.block_sq = [0.0, 0.0, 0.0]
        self.block_n = 0
        self.block_t = 0.0

    def long_run(self) -> tuple[float, float, float]:
        """The long-run variance ``r = s_d kappa`` per axis (floored), N^2: the filter's R."""
        k = max(self.kappa, KAPPA_MIN)
        floor = MIN_NOISE_VAR_N2
        a0, a1, a2 = self.d1
        # s_d = E[(y_t - y_(t-1))^2] / 2; r = max(s_d k, floor), in max's order
        r0, r1, r2 = 0.5 * a0 * k, 0.5 * a1 * k, 0.5 * a2 * k
        return (
            r0 if r0 > floor else floor,
            r1 if r1 > floor else floor,
            r2 if r2 > floor else floor,
        )

    def model(
        self,
    ) -> tuple[tuple[float, float, float], tuple[float, float, float], tuple[float, float, float]]:
        """``(s2, rho_1, r)`` per axis: per-sample variance (N^2), lag-1 autocorrelation,
        long-run variance (N^2) (:func:`per_sample`, :meth:`long_run`)."""
        s2, rho = per_sample(self.d1, self.s2)
        return s2, rho, self.long_run()

    def status(self) -> NoiseStatus:
        """The noise std per sample (N) and the lag-1 autocorrelation per axis, computed
        when first read (the estimate's ``noise_std_n``, ``noise_autocorrelation``)."""
        return NoiseStatus(self.d1, self.s2)  # replaced, never changed in place: a snapshot


def per_sample(
    d1: list[float], s2: list[float]
) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """The per-sample variance (N^2) and the lag-1 autocorrelation ``rho_1 = 1 - s_d / s2``
    per axis, from ``2 s_d`` and the within-block variance."""
    floor = MIN_NOISE_VAR_N2
    a0, a1, a2 = d1
    sd0, sd1, sd2 = 0.5 * a0, 0.5 * a1, 0.5 * a2
    v0 = max(s2[0], sd0 * 0.5, floor)
    v1 = max(s2[1], sd1 * 0.5, floor)
    v2 = max(s2[2], sd2 * 0.5, floor)
    return (v0, v1, v2), (
        min(max(1.0 - sd0 / v0, -1.0), 1.0),
        min(max(1.0 - sd1 / v1, -1.0), 1.0),
        min(max(1.0 - sd2 / v2, -1.0), 1.0),
    )


class NoiseStatus:
    """The noise std (N) and the lag-1 autocorrelation per axis of one step, computed when
    first read (:func:`per_sample` on that step's state)."""

    __slots__ = ("_d1", "_s2")

    def __init__(self, d1: list[float], s2: list[float]) -> None:
        self._d1, self._s2 = d1, s2

    def __call__(self, name: str) -> tuple[float, float, float]:
        """``noise_std_n`` (N) or ``noise_autocorrelation``, by field name."""
        s2, rho = per_sample(self._d1, self._s2)
        if name == "noise_std_n":
            return math.sqrt(s2[0]), math.sqrt(s2[1]), math.sqrt(s2[2])
        return rho
