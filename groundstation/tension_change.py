"""The tension filter's change test: when has the tension stepped (a tug)?

The paper's filter (``eq:sysk1``, ``eq:sysk2``, ``eq:Kalman_vars``) assumes a constant
tension; this test finds where that assumption broke, so that
:class:`groundstation.tension.TensionFilter` restarts from the samples since the change
(x = their mean, P = R / n: what the Kalman filter itself gives from an uninformative prior
with Q = 0 over them). A departure from the paper, whose filter has no change test; the
reasoning and the numbers in the ``TensionFilter`` docstring.

:class:`ChangeTest` is a GLR on the filter's whitened innovations over windows of up to
``change_max_window_s``, ``max_n |sum of the last n w|^2 / n`` (chi-square, 3 dof, per
window under no change), its threshold from :func:`scan_threshold` for the filter's
false-alarm rate. It divides its statistic by a *youth factor* (:func:`youth_factor`)
while the noise estimate is young, and by at least :func:`level_scatter_factor` once it is
warm. Pure: numpy and Python floats.
"""

from __future__ import annotations

import math
from statistics import NormalDist

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "ChangeTest",
    "LazyChangeStatistic",
    "exceedance_chi2",
    "exceedance_sigmas",
    "level_samples",
    "level_scatter_factor",
    "scan_threshold",
    "youth_factor",
]

FloatArray = NDArray[np.float64]
_STANDARD_NORMAL = NormalDist()


def scan_threshold(
    false_alarms_per_h: float, n_lo: float, n_hi: float, dt_s: float, dof: int = 3
) -> float:
    """Threshold of a sliding chi-square scan over windows [n_lo, n_hi] for a false-alarm rate.

    For white Gaussian noise of known variance, ``max_n |S_n|^2 / n`` over the windows
    ending at each sample crosses h at a rate of about (the Brownian scan approximation)::

        nu(h) = h^(d/2) e^(-h/2) / (2^(d/2) Gamma(d/2)) * (h/2) * (1/n_lo - 1/n_hi)

    per sample, d = ``dof``; this solves ``nu(h) = false_alarms_per_h * dt_s / 3600`` by
    Newton's method on its logarithm (decreasing in h beyond d + 2). The rate per hour
    does not depend on the sample rate: windows in samples grow with it, looks per
    second too.

    Args:
        false_alarms_per_h: Target rate, 1/h, > 0.
        n_lo: Shortest window, samples, > 0.
        n_hi: Longest window, samples, > n_lo.
        dt_s: Sample spacing, s, > 0.
        dof: Degrees of freedom of each window's statistic.

    Returns:
        The threshold h, dimensionless (at least d + 2).
    """
    span = 1.0 / n_lo - 1.0 / n_hi
    if not (false_alarms_per_h > 0.0 and dt_s > 0.0 and span > 0.0):
        raise ValueError(
            f"scan_threshold needs a rate, dt_s > 0 and 0 < n_lo < n_hi, got "
            f"{false_alarms_per_h!r}, {dt_s!r}, {n_lo!r}, {n_hi!r}"
        )
    half = 0.5 * dof
    # log nu(h) = (d/2 + 1) log h - h/2 - log(2^(d/2 + 1) Gamma(d/2)) + log(span)
    target = math.log(false_alarms_per_h * dt_s / 3600.0)
    const = math.log(span) - (half + 1.0) * math.log(2.0) - math.lgamma(half)
    h = max(2.0 * (const - target), dof + 4.0)
    for _ in range(30):
        f = (half + 1.0) * math.log(h) - 0.5 * h + const - target
        step = f / ((half + 1.0) / h - 0.5)
        h = max(h - step, dof + 2.0)
        if abs(step) < 1e-9 * h:
            break
    return h


def exceedance_sigmas(false_alarms_per_h: float, dt_s: float) -> float:
    """The one-sided Gaussian quantile a sample exceeds by chance at ``false_alarms_per_h``
    per hour when one sample is judged every ``dt_s``, standard deviations: ``z`` with
    ``Q(z) = rate·dt / 3600 s`` (Q the normal tail).

    A test that compares each sample of a Gaussian statistic with ``z`` of its standard
    deviation fires at most that often: an exceedance that lasts several samples is one
    alarm, counted here as several, so the bound holds for any correlation between samples
    (a leaky integral's with a time constant of ~25 samples at 100 Hz: within ~1.3× of it,
    its lag-1 correlation 0.96). The false-alarm rate is the estimator's one knob
    (``TensionFilterParams.false_alarms_per_h``); this turns it into a per-sample threshold
    for the contact stage's climb test: 5.55 at 100 Hz, 5.72 at 250 Hz for 0.005 per hour.
    Infinite (never fires) for a rate of 0 or no spacing.
    """
    p = false_alarms_per_h * dt_s / 3600.0
    if not (p > 0.0 and math.isfinite(p)):
        return math.inf
    if p >= 0.5:
        return 0.0
    return -_STANDARD_NORMAL.inv_cdf(p)


def exceedance_square(false_alarms_per_h: float, dt_s: float) -> float:
    """The ratio a Gaussian's square exceeds over its mean by chance at ``false_alarms_per_h``
    per hour when one is judged every ``dt_s``, dimensionless: ``z²`` with ``P(chi2_1 > z²)
    = rate·dt / 3600 s``, i.e. the two-sided normal quantile squared. The noise estimate's
    winsorisation (:class:`~groundstation.tension_noise.NoiseEstimate`): a squared
    difference, or a block's squared second difference, beyond it is not the noise's (32.2
    per sample at 100 Hz, 26.0 per 0.25 s block, for 0.005 per hour). Infinite for a rate
    of 0 or no spacing.
    """
    z = exceedance_sigmas(0.5 * false_alarms_per_h, dt_s)
    return z * z


def exceedance_chi2(false_alarms_per_h: float, dt_s: float) -> float:
    """The threshold a chi-square statistic of 3 degrees of freedom exceeds by chance at
    ``false_alarms_per_h`` per hour when one sample is judged every ``dt_s``,
    dimensionless: ``h`` with ``P(chi2_3 > h) = rate·dt / 3600 s``.

    The 3-D counterpart of :func:`exceedance_sigmas` (the same bound on the alarm rate):
    the hover test's squared 1 s mean acceleration and squared speed, each over its
    per-axis variance. ``P(chi2_3 > h) = erfc(sqrt(h/2)) + sqrt(2h/pi)·exp(-h/2)``, solved
    by Newton's method on its logarithm: 39.5 at 100 Hz, 41.3 at 250 Hz for 0.005 per hour.
    Infinite for a rate of 0 or no spacing.
    """
    p = false_alarms_per_h * dt_s / 3600.0
    if not (p > 0.0 and math.isfinite(p)):
        return math.inf
    if p >= 1.0:
        return 0.0
    target = math.log(p)
    h = max(-2.0 * target, 1.0)
    for _ in range(50):
        root = math.sqrt(0.5 * h)
        tail = math.erfc(root) + math.sqrt(2.0 * h / math.pi) * math.exp(-0.5 * h)
        density = math.sqrt(h / (2.0 * math.pi)) * math.exp(-0.5 * h)
        step = (math.log(tail) - target) / (density / tail)  # d log S / dh = -density / S
        h = max(h + step, 0.5 * h)
        if abs(step) < 1e-10 * h:
            break
    return h


ESTIMATE_SIGMAS = 3.0
"""Standard errors of the noise estimate the change test allows for, young or warm: the
youth factor's ``1 + 3 sqrt(2 / k)`` of a k-sample mean square (relative standard deviation
sqrt(2 / k); :func:`youth_factor`) and the warm estimate's floor (its level and kappa;
:func:`level_scatter_factor`); the contact stage's floor vibration uses the same bound. One
value where there were two (3 young, 2 warm): at 3 for both the sensitivity harness's
NanoBench median read 4.4 mN instead of 4.9 (fewer manoeuvres taken for changes) and no
tug, hover or take-off figure moved beyond 2 %."""


def noise_warmup_samples() -> int:
    """The noise estimate's warm-up, samples (differences), derived: the smallest k at
    which a k-sample mean square is bounded away from zero at ``ESTIMATE_SIGMAS`` standard
    errors, ``1 - ESTIMATE_SIGMAS·sqrt(2 / k) > 0``, i.e. ``k > 2·ESTIMATE_SIGMAS²`` (19 at
    3). Before it the estimate may be any fraction of the truth at that confidence, so
    nothing weighed by it is evidence: the change test waits for it (its youth factor
    :func:`youth_factor` is the allowance from there), the squared differences are
    winsorised only from it, and the filter reports ``converged`` (and is localized) from
    it."""
    return math.floor(2.0 * ESTIMATE_SIGMAS * ESTIMATE_SIGMAS) + 1


def kappa_prior_blocks() -> float:
    """The weight of κ's prior (``NoiseEstimate.KAPPA_PRIOR``), blocks, derived as
    :func:`noise_warmup_samples` is for the level: the blocks at which κ's own estimate is
    bounded away from zero at ``ESTIMATE_SIGMAS`` standard errors, ``1 −
    ESTIMATE_SIGMAS·sqrt(c / B) > 0`` with c = 35/27 κ's relative variance per block
    (:data:`_KAPPA_VAR_PER_BLOCK`): B = 9·35/27 = 11.7 blocks (2.9 s). The change test's
    allowance for κ is its warm scatter (:func:`level_scatter_factor`), so until κ's data
    can stand on their own the prior holds it."""
    return ESTIMATE_SIGMAS * ESTIMATE_SIGMAS * _KAPPA_VAR_PER_BLOCK


def level_samples(memory_samples: float) -> float:
    """The noise level's equilibrium sample count, ``k = 2·M − 1`` (at least 1): an
    exponential mean over ``memory_samples`` = M = tau / dt samples scatters as a k-sample
    mean does (its weights' sum of squares is 1 / (2M − 1)). Derived; 999 at 100 Hz with the
    5 s memory."""
    return max(2.0 * memory_samples - 1.0, 1.0)


def youth_factor(noise_samples: int, fade_samples: float = math.inf) -> float:
    """Variance factor of the change test while the noise estimate is young, >= 1.

    R is the long-run variance, so every window sum has at most the variance the test
    assumes (short windows of positively correlated noise have less): the statistic counts
    effective samples and errs toward silence. While the noise estimate is young (k
    differences) an upper bound on its error, ``1 + 3 sqrt(2 / k)`` (the scatter of a
    k-sample mean square), fading out linearly as k reaches the level's own equilibrium count
    (:func:`level_samples`: from there the estimate is no younger than its memory, and
    :func:`level_scatter_factor` is the change test's floor). Without it the first flight's
    first samples fired on 2 m/s^2 noise: the estimate is 30 % low after 20 samples.

    Args:
        noise_samples: Differences the noise estimate has taken, k.
        fade_samples: Where the factor reaches 1, samples: :func:`level_samples` at the
            measured spacing (infinite: no fade, before a spacing is known).
    """
    k = noise_samples
    if k < fade_samples:
        fade = 1.0 - k / fade_samples
        return 1.0 + ESTIMATE_SIGMAS * math.sqrt(2.0 / max(k, 1)) * fade
    return 1.0


_KAPPA_VAR_PER_BLOCK = 35.0 / 27.0
"""kappa's relative variance times its blocks, 35/27 = 1.296 (derived): per axis a block's
``d² = (m_j − 2 m_(j−1) + m_(j−2))²`` of independent Gaussian block means has relative
variance 2, and neighbouring blocks' d share means: correlation −4/6 at lag 1 and 1/6 at lag
2, so their squares correlate by the squares of those (4/9, 1/36). A mean of B of them has
relative variance ``2·(1 + 2·(4/9 + 1/36))/B = (35/9)/B`` per axis, and the three axes
pooled (independent) ``(35/27)/B``: relative standard error sqrt(1.296 / B)
(tests/test_tension.py draws it)."""
_KAPPA_BLOCKS = 239
"""kappa's equilibrium block count: its 30 s exponential average of 0.25 s blocks."""


def level_scatter_factor(memory_samples: float) -> float:
    """The change test's floor of the youth factor, >= 1: the noise estimate's own scatter
    once it is warm, ``1 + 3 sqrt(2 / k + (35/27) / 239)`` (:data:`ESTIMATE_SIGMAS`).

    r = s_d kappa is measured, not known, and a window's statistic scales as 1 / r: a
    level a few per cent low reads every window a few per cent high, and over hours it is
    low often enough to matter. Thresholds set for a known variance (~0.005 false
    detections per hour each) fired 4 times in 90 hours of simulated hover at 1 and 2 m/s^2
    (``benchmarks/bench_change_test.py --minutes 60 --flights 30``; the filter then had a
    second, long-window test, and both fired). The level s_d is
    an exponential mean over ``memory_samples`` = tau / dt samples: a k = 2 tau / dt − 1
    sample mean square's relative variance 2 / k; kappa's at its equilibrium count of 239
    blocks is (35/27) / 239 (its 30 s exponential average of 0.25 s blocks, 3 axes pooled,
    neighbouring blocks' second differences correlated: :data:`_KAPPA_VAR_PER_BLOCK`); 3
    standard errors of their sum are allowed for (2 until the young and the warm allowance
    became one). 1.26 at ~95 Hz with the 5 s memory."""
    k = level_samples(memory_samples)
    return 1.0 + ESTIMATE_SIGMAS * math.sqrt(2.0 / k + _KAPPA_VAR_PER_BLOCK / _KAPPA_BLOCKS)


class _Ring:
    """Fixed-size history of a regime's observations and whitened innovations.

    The innovations are kept as their running sum ``C_t = w_1 + ... + w_t`` (rows of
    ``cum``, row ``pos`` the newest, row ``pos - n`` holding ``C_(t-n)``), so the sum of
    the last n is one difference, ``S_n = C_t - C_(t-n)``, for every n at once (one numpy
    subtraction when a statistic is needed, nothing per window per step). The buffer is
    append-only: rows once written never change, so a statistic can be computed later from
    it (:class:`LazyChangeStatistic`). When it is full, the live rows move to a new buffer,
    less the oldest live row (so ``C`` stays of the size of one buffer's innovations, and
    a difference loses no digits however long the flight). The observations are kept as
    Python tuples: they are read only at a detection.

    Args:
        size: Capacity, samples.
    """

    def __init__(self, size: int) -> None:
        self.size = size
        self.obs: list[tuple[float, float, float]] = [(0.0, 0.0, 0.0)] * size
        self.head = 0  # next observation slot to write
        self.count = 0  # valid entries (innovations) since the regime began
        self._rows = 4 * size
        self._new_buffer(np.zeros((3, self._rows)))
        self.pos = 0
        self.c = (0.0, 0.0, 0.0)  # C_t, the newest row, as floats
        # The last size + 1 rows again, as floats: C_(t-n) = recent[(t - n) % (size + 1)].
        self._recent: list[tuple[float, float, float]] = [(0.0, 0.0, 0.0)] * (size + 1)
        self._t = 0
        self.moves = 0  # times the live rows moved (and C was rebased)

    def _new_buffer(self, cum: FloatArray) -> None:
        # Laid out (3, rows): each axis a contiguous row, so every operation on a stretch of
        # windows is a 1-D one (numpy's fast path).
        self.cum = cum
        self._x, self._y, self._z = cum[0], cum[1], cum[2]  # views, for scalar writes

    @property
    def start(self) -> int:
        """Rows left before the live rows move to a new buffer (jumps up when they do)."""
        return self._rows - 1 - self.pos

    def _move(self) -> None:
        """The last ``size + 1`` rows to the front of a new buffer, less the oldest of them."""
        pos, keep = self.pos, self.size
        live = self.cum[:, pos - keep : pos + 1]
        base = live[:, :1].copy()
        cum = np.zeros((3, self._rows))
        np.subtract(live, base, out=cum[:, : keep + 1])  # C - C_base: differences unchanged
        self._new_buffer(cum)
        self.pos = keep
        c0, c1, c2 = self.c
        b0, b1, b2 = base[:, 0].tolist()
        self.c = (c0 - b0, c1 - b1, c2 - b2)  # the same rounding as the row
        self._recent = [(r0 - b0, r1 - b1, r2 - b2) for r0, r1, r2 in self._recent]
        self.moves += 1

    def push(
        self,
        obs_n: tuple[float, float, float] | list[float],
        innov: tuple[float, float, float] | list[float],
    ) -> None:
        """Takes one observation (N) and its whitened innovation (dimensionless)."""
        head = self.head
        self.obs[head] = obs_n  # type: ignore[assignment]  # only read, never changed
        self.head = head + 1 if head + 1 < self.size else 0
        if self.pos + 1 == self._rows:
            self._move()
        c0, c1, c2 = self.c
        w0, w1, w2 = innov
        c0, c1, c2 = self.c = (c0 + w0, c1 + w1, c2 + w2)  # C_t = C_(t-1) + w_t
        pos = self.pos = self.pos + 1
        self._x[pos] = c0
        self._y[pos] = c1
        self._z[pos] = c2
        t = self._t = self._t + 1
        self._recent[t % (self.size + 1)] = (c0, c1, c2)
        if self.count < self.size:
            self.count += 1

    def grown(self, size: int) -> _Ring:
        """A ring of capacity ``size`` (> :attr:`size`) holding this one's history: its
        live observations and rows ``C``, differences unchanged (so every window's sum is
        the same), ``count`` kept."""
        new = _Ring(size)
        n = self.count
        obs = [self.obs[i] for i in self.latest_first(n).tolist()[::-1]]  # oldest first
        new.obs[:n] = obs
        new.head = n % size
        live = self.cum[:, self.pos - n : self.pos + 1]
        new.cum[:, : n + 1] = live
        new.pos = n
        new.c = self.c
        new._t = n
        for k in range(n + 1):
            new._recent[k] = self.back(n - k)
        new.count = n
        new.moves = self.moves + 1  # C's rows moved: a certificate anchored on them is void
        return new

    def back(self, n: int) -> tuple[float, float, float]:
        """``C_(t-n)``, 0 <= n <= count."""
        return self._recent[(self._t - n) % (self.size + 1)]

    def latest_first(self, n: int) -> NDArray[np.intp]:
        """Indices into :attr:`obs` of the ``n`` most recent entries, newest first."""
        return (self.head - 1 - np.arange(n)) % self.size

    def mean_of_latest(self, n: int) -> list[float]:
        """The mean of the ``n`` most recent observations, N, per axis."""
        obs = self.obs
        rows = np.array([obs[i] for i in self.latest_first(n).tolist()])
        mean: list[float] = rows.mean(axis=0).tolist()
        return mean

    def window_sums(self, n: int) -> FloatArray:
        """Sums of the newest 1 .. ``n`` whitened innovations, shape (3, n)."""
        pos = self.pos
        out: FloatArray = self.cum[:, pos : pos + 1] - self.cum[:, pos - n : pos][:, ::-1]
        return out


def _squared_sums(cum: FloatArray, pos: int, n_min: int, n_max: int) -> FloatArray:
    """``|S_n|^2 = |C_t - C_(t-n)|^2`` for n = n_min .. n_max, in that order.

    Element by element (no reduction whose rounding could depend on the length), so a value
    is the same whatever ``n_max``: the eager and the lazy statistic agree to the bit.
    """
    a, b = pos - n_max, pos - n_min + 1  # C_(t-n) for n = n_max .. n_min
    x, y, z = cum[0], cum[1], cum[2]
    d = x[a:b] - x[pos]  # -S_n per axis, n descending
    d *= d
    e = y[a:b] - y[pos]
    e *= e
    d += e
    e = z[a:b] - z[pos]
    e *= e
    d += e
    out: FloatArray = d[::-1]
    return out


class LazyChangeStatistic:
    """The change test's statistic of one step, computed when first read.

    ``max_n |S_n|^2 / (n youth)`` over n = n_min .. n_valid, from the ring's
    append-only buffer as it was at that step (:class:`_Ring`). The filter needs only to
    know that no window crossed the threshold, which :class:`ChangeTest` certifies without
    computing every window; the value itself is computed only if someone reads
    :attr:`groundstation.tension.TensionEstimate.change_statistic`.
    """

    __slots__ = ("_args",)

    def __init__(
        self,
        test: ChangeTest,
        cum: FloatArray,
        pos: int,
        count: int,
        dt_mean_s: float,
        youth: float,
        cap_n: int,
    ) -> None:
        self._args = (test, cum, pos, count, dt_mean_s, youth, cap_n)

    def __call__(self, name: str = "change_statistic") -> float:
        test, cum, pos, count, dt_mean_s, youth, cap_n = self._args
        n_min = test.min_window
        if count < n_min:
            return 0.0
        n_valid = max(test.window_cap(dt_mean_s, count, cap_n), n_min)
        ss = _squared_sums(cum, pos, n_min, n_valid)
        stat, _ = _best_window(ss, n_min, test.inv_n, youth)
        return stat


def _best_window(ss: FloatArray, n_min: int, inv_n: FloatArray, youth: float) -> tuple[float, int]:
    """``(max_n |S_n|^2 / (n youth), its n)`` from :func:`_squared_sums`."""
    stats = ss * inv_n[: len(ss)]  # |S_n|^2 / n
    best = int(stats.argmax())
    return float(stats[best]) / youth, n_min + best


class ChangeTest:
    """The change test: a GLR on whitened innovations (tug detection).

    Each innovation nu is whitened by the Cholesky factor of S = P- + R
    (:meth:`groundstation.tension_kalman.DiagonalKalman.update`), so that at constant
    tension w ~ N(0, I). A step k samples ago shifts the mean of the last k whitened
    innovations. For every window n in [``min_window``, min(history, :attr:`cap_n`,
    ``max_window_s`` / dt_mean)] the statistic ``|S_n|^2 / n``, S_n the sum of the last n
    w, is chi-square with 3 dof under no change (when the noise is white; smaller for
    positively correlated noise on short windows, since R is the long-run variance). The
    largest, divided by the youth factor, is compared with ``threshold``; its window is the
    maximum-likelihood change point.

    *Cost: a certificate instead of every window at every step.* ``|S_n|^2 / (n youth) >
    threshold`` needs ``|C_t - C_(t-n)| > sqrt(threshold n)`` (youth >= 1): C_t outside a
    ball around each window's start C_(t-n), whose radius only grows as the window does.
    So once every window has been evaluated at a step t0 (:meth:`evaluate`), none can
    cross before C_t has moved from C_t0 by the smallest slack ``sigma = min_n (sqrt(threshold
    n) - |C_t0 - C_(t0-n)|)`` (triangle inequality); a window that starts later lowers sigma
    by its own slack when it enters, measured from C_t0 too. The certificate covers the
    windows within the cap in force (:attr:`cap_n`; a longer one only grows, and a larger cap
    drops the certificate, :meth:`set_cap`), so its cost follows the cap. While ``|C_t - C_t0| <=
    sigma`` (:meth:`push` says so, a few float operations) no window can detect, and the
    statistic is left to :class:`LazyChangeStatistic`; otherwise (and whenever the ring's
    buffer moves, which rebases C) every window is evaluated again, exactly as before: one
    step in ~20 at hover, 4-6 % of the steps of the realistic simulator's flights.

    Args:
        min_window: Shortest window, samples (a single outlier cannot trigger it).
        max_window_s: Longest window, s (:attr:`cap_n`, set by the filter from the
            noise, may lower it).
        size: Capacity of the history, samples.
        threshold: The detection threshold on the statistic, dimensionless.
    """

    def __init__(self, min_window: int, max_window_s: float, size: int, threshold: float) -> None:
        self.min_window = min_window
        self.max_window_s = max_window_s
        self.cap_n = size
        """The longest window in use, samples (within ``max_window_s``): set by the filter
        from the noise (:meth:`set_cap`; ``TensionFilter``: where the smallest step of
        interest reaches the threshold)."""
        self._cert_n = size  # the longest window the certificate covers
        self.ring = _Ring(size)
        self._n = np.arange(min_window, size + 1, dtype=np.float64)  # windows min_window..size
        self.inv_n = 1.0 / self._n
        self._anchor = (0.0, 0.0, 0.0)  # C_t0
        self._moves = 0  # ring.moves when the anchor was set
        self.set_threshold(threshold)

    def set_threshold(self, threshold: float) -> None:
        """A new detection threshold (the spacing moved): the certificate is dropped."""
        self.threshold = threshold
        # The radius of each window's ball, a hair smaller than sqrt(threshold n) so that
        # rounding cannot certify a window that the exact statistic puts just above it.
        self._radius = np.sqrt(threshold * self._n) * (1.0 - 1e-9) - 1e-12
        self._radius_min = float(self._radius[0])
        self._sigma = -1.0  # the slack; < 0: no certificate

    def reserve(self, n: int) -> None:
        """Room for windows of ``n`` samples at least: the history grows (to the next power
        of two, so that a spacing that keeps shrinking grows it a few times in all), keeping
        what it holds; the certificate is dropped. A capacity, not a tunable: the windows
        the test judges are set by ``max_window_s`` and :attr:`cap_n`."""
        if n <= self.ring.size:
            return
        size = 1 << (n - 1).bit_length()
        self.ring = self.ring.grown(size)
        self._n = np.arange(self.min_window, size + 1, dtype=np.float64)
        self.inv_n = 1.0 / self._n
        self.set_threshold(self.threshold)  # the radii of the new windows; no certificate
        self._cert_n = size

    def set_cap(self, n: int) -> None:
        """The longest window in use from now on, samples; a cap beyond the windows the
        certificate covers drops it (the next step evaluates every window)."""
        if n > self._cert_n:
            self._sigma = -1.0
        self.cap_n = n

    def clear(self) -> None:
        """Forgets the windows (a new regime): none can detect until they fill again."""
        self.ring.count = 0
        self._anchor = self.ring.c
        self._moves = self.ring.moves
        self._sigma = math.inf
        self._cert_n = self.ring.size  # every window enters at min_window, under push

    def push(
        self,
        z_n: tuple[float, float, float] | list[float],
        w: tuple[float, float, float] | list[float],
    ) -> bool:
        """Takes one observation (N) and its whitened innovation (dimensionless).

        Returns:
            True when no window can be above the threshold.
        """
        ring = self.ring
        ring.push(z_n, w)
        if ring.moves != self._moves:
            # C was rebased: the anchor is in the old coordinates, so evaluate afresh.
            self._moves = ring.moves
            self._sigma = -1.0
        sigma = self._sigma
        if sigma < 0.0:
            return False
        a0, a1, a2 = self._anchor
        n_min = self.min_window
        if ring.count >= n_min:
            # The window of n_min samples that enters now: its slack, from C_t0.
            b0, b1, b2 = ring._recent[(ring._t - n_min) % (ring.size + 1)]  # ring.back(n_min)
            d0, d1, d2 = a0 - b0, a1 - b1, a2 - b2
            slack = self._radius_min - math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            if slack < sigma:
                sigma = self._sigma = slack
                if sigma < 0.0:
                    return False
        c0, c1, c2 = ring.c
        d0, d1, d2 = c0 - a0, c1 - a1, c2 - a2
        return d0 * d0 + d1 * d1 + d2 * d2 <= sigma * sigma

    def window_cap(self, dt_mean_s: float, count: int, cap_n: int | None = None) -> int:
        """The longest window with ``count`` innovations at a mean sample spacing, samples:
        at most ``cap_n`` (default :attr:`cap_n`) and ``max_window_s``."""
        n = count
        cap = self.cap_n if cap_n is None else cap_n
        if cap < n:
            n = cap
        if dt_mean_s == dt_mean_s and dt_mean_s > 0.0:
            n_cap = max(self.min_window, int(self.max_window_s / dt_mean_s))
            if n_cap < n:
                n = n_cap
        return n

    def lazy_statistic(self, dt_mean_s: float, youth: float) -> LazyChangeStatistic:
        """This step's statistic (as :meth:`evaluate` gives it), computed when read."""
        ring = self.ring
        return LazyChangeStatistic(
            self, ring.cum, ring.pos, ring.count, dt_mean_s, youth, self.cap_n
        )

    def evaluate(self, dt_mean_s: float, youth: float) -> tuple[float, int]:
        """``(max_n |S_n|^2 / (n youth), its n)`` over every window, and a new certificate;
        ``(0.0, 0)`` while the history is shorter than the shortest window.

        Args:
            dt_mean_s: Mean sample spacing, s (NaN: unknown, the whole history is used).
            youth: The youth factor (:func:`youth_factor`), >= 1.
        """
        ring = self.ring
        n_min = self.min_window
        self._anchor = ring.c
        self._moves = ring.moves
        if ring.count < n_min:
            self._sigma = math.inf
            self._cert_n = ring.size
            return 0.0, 0
        n_valid = max(self.window_cap(dt_mean_s, ring.count), n_min)
        # Every window within the cap in force (:attr:`cap_n`): a longer one only grows
        # until the next evaluation, and a larger cap (set_cap) drops the certificate.
        n_cert = max(min(ring.count, self.cap_n), n_min)
        self._cert_n = ring.size if n_cert >= ring.count else n_cert
        ss = _squared_sums(ring.cum, ring.pos, n_min, n_cert)
        self._sigma = float((self._radius[: len(ss)] - np.sqrt(ss)).min())
        return _best_window(ss[: n_valid - n_min + 1], n_min, self.inv_n, youth)

    def mean_of_window(self, n: int) -> list[float]:
        """The mean of the last ``n`` observations, N (the restart's x)."""
        return self.ring.mean_of_latest(n)
