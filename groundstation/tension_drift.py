"""The tension filter's drift adaptation: a larger process noise while the tension ramps.

A constant-tension filter (``eq:sysk1``: A = I) with time constant tau lags a tension that
ramps (the drone moving) by rate * tau, and that lag shows as a bias of its whitened
innovations. :class:`DriftAdaptation` measures the bias and scales the process noise Q of
``eq:Kalman_vars`` up until the lag falls back to the threshold; a departure from the paper,
whose Q is fixed. Pure: Python floats only.
"""

from __future__ import annotations

import math

__all__ = ["RESCALE_TOLERANCE", "DriftAdaptation", "relaxed_scale"]

RESCALE_TOLERANCE = 0.01
"""The tension filter's one cost tolerance: a revised value is applied only once it has
moved by more than this fraction. P is rescaled to a revised noise R (P proportional to R
to within 1 %); the change test's threshold is derived again at a revised mean spacing; and
a process-noise scale within this of 1 is taken as 1 (Q within 1 % of the hover one: the
decayed adaptation ends instead of fading for ever; it was 0.1 %, ``SCALE_SNAP``, and 1 %
moved the sensitivity harness's figures by less than 1e-4 of themselves)."""


def relaxed_scale(scale: float, dt_s: float, memory_s: float) -> float:
    """A process-noise scale relaxed toward 1 over ``dt_s``: ``1 + (scale − 1)·exp(−dt/memory)``
    (no memory, ``memory_s`` 0: 1 at once). The drift adaptation's raised noise decays so, and
    so does the after-change hypothesis' (``tension_kalman.MovingTension``)."""
    if memory_s > 0.0:
        return 1.0 + (scale - 1.0) * math.exp(-dt_s / memory_s)
    return 1.0


class DriftAdaptation:
    """Innovation-bias average and the process-noise scale it drives.

    An exponential average b of the whitened innovations w over ``time_constant_s``
    (``drift_time_constant_s``, 0.5 s) measures the lag; its normalised square
    ``D = |b|^2 / (Var(b) youth)`` is chi-square with 3 dof at constant tension (``youth``
    the change test's factor for a young noise estimate). Above ``threshold`` (9) the
    process noise is scaled by ``(D / threshold)^exponent``, the time constant down to
    ``min_time_constant_s`` at most; the scale then decays with ``memory_s`` (1 s), so a
    restart (which clears b) does not forget that the tension was moving.

    Args:
        time_constant_s: Time constant of the innovation-bias average, s, > 0.
        threshold: Level of D above which the process noise is raised, > 0.
        exponent: Exponent of the scale, >= 0.
        min_time_constant_s: Shortest time constant the adaptation may reach, s, > 0.
        memory_s: Decay of the scale once the drift is gone, s, >= 0.
    """

    __slots__ = (
        "_beta_cache",
        "bias",
        "bias_var",
        "exponent",
        "memory_s",
        "min_time_constant_s",
        "scale",
        "threshold",
        "time_constant_s",
    )

    def __init__(
        self,
        time_constant_s: float,
        threshold: float,
        exponent: float,
        min_time_constant_s: float,
        memory_s: float,
    ) -> None:
        self.time_constant_s = time_constant_s
        self.threshold = threshold
        self.exponent = exponent
        self.min_time_constant_s = min_time_constant_s
        self.memory_s = memory_s
        self._beta_cache = (math.nan, math.nan)
        self.bias = (0.0, 0.0, 0.0)  # b, EWMA of whitened innovations
        self.bias_var = 0.0  # Var(b) per axis at no drift
        self.scale = 1.0

    def clear(self) -> None:
        """Forgets the innovation bias (a restart of the filter); the scale decays on."""
        self.bias = (0.0, 0.0, 0.0)
        self.bias_var = 0.0

    def new_regime(self) -> None:
        """Forgets the bias and the scale (a reset or a gap)."""
        self.clear()
        self.scale = 1.0

    def push(self, w: tuple[float, float, float] | list[float], dt: float) -> None:
        """Takes one whitened innovation per axis (dimensionless), ``dt`` s after the last."""
        if self._beta_cache[0] != dt:
            beta = -math.expm1(-dt / self.time_constant_s) if dt > 0 else 0.0
            self._beta_cache = (dt, beta)
        beta = self._beta_cache[1]
        b0, b1, b2 = self.bias
        w0, w1, w2 = w
        # b = (1 - beta) b + beta w
        self.bias = (b0 + beta * (w0 - b0), b1 + beta * (w1 - b1), b2 + beta * (w2 - b2))
        # Var(b) = (1 - beta)^2 Var(b) + beta^2 per axis, for white unit w.
        self.bias_var = (1.0 - beta) ** 2 * self.bias_var + beta * beta

    def process_noise_scale(
        self, dt: float, tau: float, youth: float, evidence: bool = True
    ) -> float:
        """The factor on the hover process noise for this step, >= 1.

        Args:
            dt: Time since the previous step, s.
            tau: The hover time constant, s.
            youth: The change test's youth factor (>= 1), dividing D.
            evidence: Whether the innovation bias is evidence of a moving tension this
                step. False while the drone manoeuvres (the caller's hover test says so):
                then the bias is the observation model's error as much as the tension's
                move, so the hover's process noise applies (1 is returned) while the scale
                raised before decays, unused.

        Returns:
            ``max((D / threshold)^exponent, decayed previous scale)``, at most
            ``(tau / min_time_constant_s)^2`` (Q scales as 1 / tau^2); 1 without
            ``evidence``.
        """
        inst = 1.0
        if evidence and self.bias_var > 0.0:
            b0, b1, b2 = self.bias
            d = ((b0 * b0 + b1 * b1) + b2 * b2) / (self.bias_var * youth)  # D = |b|^2 / Var(b)
            ratio = d / self.threshold
            if ratio > 1.0:
                inst = ratio**self.exponent
        relaxed = relaxed_scale(self.scale, dt, self.memory_s)
        scale = max(inst, relaxed)
        if scale < 1.0 + RESCALE_TOLERANCE:
            scale = 1.0
        self.scale = scale
        if not evidence:
            return 1.0
        # Down to min_time_constant_s, never below it (nor above 1).
        cap = max(1.0, (tau / self.min_time_constant_s) ** 2)
        return min(scale, cap)
