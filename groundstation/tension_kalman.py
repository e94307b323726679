"""The tension filter's Kalman core: three scalar Kalman filters in closed form.

The model of the paper's tension filter (``eq:sysk1``, ``eq:sysk2``, ``eq:Kalman_vars``) has
state x = (Tx, Ty, Tz), A = C = I and B = D = 0. With the diagonal Q and R that
:class:`groundstation.tension.TensionFilter` sets at every step, P stays diagonal, and the
3-state filter is three independent scalar ones: :class:`DiagonalKalman`. Deciding Q, R and
when to restart is the tension filter's business; this module holds only the equations.
Pure: Python floats only.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from groundstation.tension_drift import relaxed_scale

__all__ = ["MOVING_MIN_LOG_ODDS", "DiagonalKalman", "HoverVelocity", "MovingTension"]

MOVING_MIN_LOG_ODDS = -20.7
"""Below this log likelihood ratio (a weight under 1e-9) the moving hypothesis has lost: it
is dropped, which moves the estimate by under 1e-9 of the two hypotheses' difference (a
numerical guard: it ends the hypothesis' work, not a decision)."""


class DiagonalKalman:
    """Three scalar Kalman filters, one per world axis: the tension filter's state and gain.

    The model of ``eq:sysk1``, ``eq:sysk2``, ``eq:Kalman_vars`` has A = C = I, and the
    tension filter's Q and R are diagonal at every step; P starts diagonal (P0 = R, a
    diagonal prior, or R / n at a restart) and is only ever rescaled by a diagonal D. So
    P stays diagonal and the 3-state filter is three independent scalar ones, written out
    here in closed form, equation beside each line. Stepped with the same Q and R, filterpy's
    ``KalmanFilter`` (dim_x = dim_z = 3, F = H = I) gives the same x and P to rounding:
    tests/test_tension.py steps both, with resets and coasts, and compares them to 1e-12.
    Per message this is a few float operations where filterpy's predict + update cost
    ~20 µs of numpy calls on 3x3 matrices (docs/pipeline_benchmark.md).

    Attributes:
        x: The state, the tension per world axis, N, 3 floats.
        P: The diagonal of the covariance, per world axis, N^2, 3 floats.
    """

    __slots__ = ("P", "x")

    def __init__(self) -> None:
        self.x = [0.0, 0.0, 0.0]
        self.P = [0.0, 0.0, 0.0]

    def set(self, x_n: Sequence[float], P_n2: Sequence[float]) -> None:
        """Sets the state and the diagonal of its covariance (an initialisation)."""
        self.x = [float(x_n[0]), float(x_n[1]), float(x_n[2])]
        self.P = [float(P_n2[0]), float(P_n2[1]), float(P_n2[2])]

    def predict(self, q_n2: list[float] | tuple[float, ...]) -> None:
        """The time update with process noise ``Q = diag(q_n2)``, N^2.

        x- = A x = x (A = I), so only the covariance moves.
        """
        p0, p1, p2 = self.P
        q0, q1, q2 = q_n2
        self.P = [p0 + q0, p1 + q1, p2 + q2]  # P- = A P A' + Q = P + Q

    def update(
        self, z_n: list[float] | tuple[float, ...], r_n2: list[float] | tuple[float, ...]
    ) -> tuple[float, float, float]:
        """The measurement update with ``z = x + v``, ``v ~ N(0, diag(r_n2))``.

        Written out per axis (three scalar filters; the same lines, i = 0, 1, 2).

        Args:
            z_n: The observation per world axis, N, 3 floats.
            r_n2: The observation noise variance per world axis, N^2, 3 floats.

        Returns:
            The whitened innovation ``nu / sqrt(S)`` per axis (``L^-1 nu`` with S = L L',
            L diagonal here), dimensionless: N(0, 1) per axis while the model holds.
        """
        x0, x1, x2 = self.x
        p0, p1, p2 = self.P
        z0, z1, z2 = z_n
        r0, r1, r2 = r_n2
        nu0, nu1, nu2 = z0 - x0, z1 - x1, z2 - x2  # nu = z - C x-
        s0, s1, s2 = p0 + r0, p1 + r1, p2 + r2  # S = C P- C' + R
        k0, k1, k2 = p0 / s0, p1 / s1, p2 / s2  # K = P- C' S^-1
        self.x = [x0 + k0 * nu0, x1 + k1 * nu1, x2 + k2 * nu2]  # x = x- + K nu
        # P = (I - KC) P- (I - KC)' + K R K' (Joseph form, as filterpy: >= 0 always)
        self.P = [
            (1.0 - k0) * p0 * (1.0 - k0) + k0 * r0 * k0,
            (1.0 - k1) * p1 * (1.0 - k1) + k1 * r1 * k1,
            (1.0 - k2) * p2 * (1.0 - k2) + k2 * r2 * k2,
        ]
        sqrt = math.sqrt
        return (nu0 / sqrt(s0), nu1 / sqrt(s1), nu2 / sqrt(s2))  # w = L^-1 nu

    def rescale(self, d: list[float]) -> None:
        """``P = D P D`` with ``D = diag(sqrt(d))``: P follows a revised R (``R = d R_prev``)."""
        P = self.P
        for i in range(3):
            sd = math.sqrt(d[i])
            P[i] = P[i] * (sd * sd)  # P = D P D


class HoverVelocity:
    """The drone's velocity beside the tension while it hovers: a second state per axis.

    Newton along each world axis is ``m·dv/dt = T − h`` with h the thrust balance
    ``m·g·e3 − R·u·F`` (the observation stage's hover model: what the tension is when the
    drone does not accelerate). A hovering drone's velocity stays small: ``v = 0`` with
    variance ``σ_v²·T_c/dt`` per sample is an observation (σ_v the hover's velocity
    scatter, T_c its correlation time: over T_c it counts as one look at v). With the
    tension T a random walk, the filter on (T, v) weighs the accelerometer model
    (``z = T + noise``, :meth:`DiagonalKalman.update`) against the thrust balance by what
    each can be off: the accelerometer model by its vibration, the thrust balance's mean
    over t by ``m·Δv/t`` (``eq:NE_tether`` with the velocity as a state), Δv bounded by σ_v.
    A settling drone whose velocity changes by more than σ_v biases the estimate as a mean
    of h would (m·Δv/t), and its σ does not show it. The tension part is
    :class:`DiagonalKalman`'s x and P; this
    class holds per axis v, ``b = cov(T, v)`` and ``c = var(v)``, and the equations,
    written out. Active from :meth:`start` (the hover begins: v = 0, var σ_v², no
    correlation) until the filter clears ``active``. Tested against filterpy's
    ``KalmanFilter`` on the 2-state model (tests/test_hover_velocity.py).
    """

    __slots__ = ("active", "b", "c", "v")

    def __init__(self) -> None:
        self.active = False
        self.v = [0.0, 0.0, 0.0]
        self.b = [0.0, 0.0, 0.0]
        self.c = [0.0, 0.0, 0.0]

    def start(self, velocity_var_m2ps2: float) -> None:
        """The hover begins: v = 0 with variance ``velocity_var_m2ps2``, uncorrelated."""
        self.active = True
        self.v = [0.0, 0.0, 0.0]
        self.b = [0.0, 0.0, 0.0]
        self.c = [velocity_var_m2ps2] * 3

    def step(
        self,
        kf: DiagonalKalman,
        x_prev: Sequence[float],
        a_pred: Sequence[float],
        q_n2: Sequence[float],
        hover_model_n: Sequence[float],
        r_n2: Sequence[float],
        w: Sequence[float],
        dt_s: float,
        mass_kg: float,
        accel_noise_m2ps3: float,
        rest_var_m2ps2: float,
    ) -> None:
        """The velocity's part of one step, after ``kf.predict(q_n2)`` and ``kf.update``
        (whose T part is the same in the 2-state filter: T does not depend on v in F, and
        the accelerometer model observes T alone). ``x_prev``: T before the step, N;
        ``a_pred``: var(T) after the prediction, N^2; ``w``: the update's whitened
        innovation (:func:`_hover_axis` has the equations)."""
        d = dt_s / mass_kg
        qv = accel_noise_m2ps3 * dt_s
        x, P, v, b, c = kf.x, kf.P, self.v, self.b, self.c
        x0, p0, v0, b0, c0 = _hover_axis(
            x[0], P[0], x_prev[0], a_pred[0], q_n2[0], hover_model_n[0], r_n2[0], w[0],
            v[0], b[0], c[0], d, qv, rest_var_m2ps2,
        )  # fmt: skip
        x1, p1, v1, b1, c1 = _hover_axis(
            x[1], P[1], x_prev[1], a_pred[1], q_n2[1], hover_model_n[1], r_n2[1], w[1],
            v[1], b[1], c[1], d, qv, rest_var_m2ps2,
        )  # fmt: skip
        x2, p2, v2, b2, c2 = _hover_axis(
            x[2], P[2], x_prev[2], a_pred[2], q_n2[2], hover_model_n[2], r_n2[2], w[2],
            v[2], b[2], c[2], d, qv, rest_var_m2ps2,
        )  # fmt: skip
        kf.x = [x0, x1, x2]
        kf.P = [p0, p1, p2]
        self.v = [v0, v1, v2]
        self.b = [b0, b1, b2]
        self.c = [c0, c1, c2]

    def rescale(self, d: list[float]) -> None:
        """P's tension part scaled by d (:meth:`DiagonalKalman.rescale`): cov(T, v) by √d."""
        b = self.b
        for i in range(3):
            b[i] *= math.sqrt(d[i])


def _hover_axis(
    x: float,
    P: float,
    x_prev: float,
    a_pred: float,
    q: float,
    h: float,
    r: float,
    w: float,
    v: float,
    b: float,
    c: float,
    d: float,
    qv: float,
    rest_var: float,
) -> tuple[float, float, float, float, float]:
    """One axis of :meth:`HoverVelocity.step`: state (T, v), covariance [[a, b], [b, c]].

    Prediction with F = [[1, 0], [d, 1]] (d = dt/m) and Q = diag(q, qv):
    ``v- = v + d·(T − h)``, ``b- = b + d·a``, ``c- = c + 2·d·b + d²·a + qv``, ``a- = a + q``
    (a = a- − q: var(T) before the tension's Q). The accelerometer model's update
    (H = [1, 0], S = a- + r, innovation ``nu = w·sqrt(S)``) moves v by ``(b-/S)·nu``,
    ``c = c- − b-²/S``, ``b = (1 − a-/S)·b-`` (x and a are ``kf.update``'s). Then the
    hover's observation ``0 = v + noise`` (H = [0, 1], variance ``rest_var``):
    ``K = (b, c)/(c + rest_var)``, ``nu = −v``, P = P − K·(b, c). Returns x, a, v, b, c."""
    a = a_pred - q
    v += d * (x_prev - h)
    c += 2.0 * d * b + d * d * a + qv
    b += d * a
    s = a_pred + r
    kv = b / s
    v += kv * w * math.sqrt(s)
    c -= kv * b
    b -= a_pred / s * b
    s = c + rest_var
    kt = b / s
    kv = c / s
    x -= kt * v  # nu = 0 − v
    P -= kt * b
    b_new = b - kt * c
    c -= kv * c
    v -= kv * v
    return x, P, v, b_new, c


class MovingTension:
    """After a detected change: a second hypothesis, the tension still moving, weighed
    against the filter's own (constant since the change) by the data.

    A change test finds a change ``n`` samples after it (``eq:sysk1`` with a jump) and the
    filter restarts from the mean of those samples, which is the best estimate while the
    tension stays where it jumped. A tug is often not a step: the tether is reeled for a
    tenth of a second, the drone's controller answers the pull, the tether swings, and the
    truth moves for another half second. Neither model is right in general, so both run:

    * the filter's own, ``Q`` the hover's (``constant``), and
    * this one, a random walk whose time constant starts at the detection window's span
      (``n·dt``: the data said the tension moved on that scale) and relaxes to the hover's
      as the drift adaptation's raised noise does (scale decaying with ``memory_s``, time
      constant never below ``min_time_constant_s``).

    Both are Kalman filters on the same observations from the same restart (a static
    multiple-model estimator: two models, no switching between them). Each scores its own
    one-step predictive likelihood ``N(ν; 0, S)`` per axis, and the published estimate is
    their posterior mixture: weight ``σ(L)`` on this one, L the accumulated log likelihood
    ratio, from even odds at the change (neither favoured; the filter carries the odds over
    to a change found while this hypothesis was winning); covariance the mixture's, spread
    included. On a step the constant model's innovations are the smaller and L falls; on a
    tension that keeps moving its innovations grow and L rises within a few samples. When
    this model's time constant has relaxed to the filter's own the two are one model, and
    the filter takes the mixture as its state (:meth:`mixture`).

    Attributes:
        kf: This hypothesis's filter.
        scale: Its process-noise scale over the hover's, decaying.
        log_odds: L, the log likelihood ratio of this hypothesis over the constant one.
    """

    __slots__ = ("kf", "log_odds", "memory_s", "min_time_constant_s", "scale", "tau_hover_s")

    def __init__(
        self,
        x_n: Sequence[float],
        p_n2: Sequence[float],
        window_s: float,
        tau_hover_s: float,
        memory_s: float,
        min_time_constant_s: float,
    ) -> None:
        self.kf = DiagonalKalman()
        self.kf.set(x_n, p_n2)
        self.tau_hover_s = tau_hover_s
        self.scale = (tau_hover_s / window_s) ** 2
        self.memory_s = memory_s
        self.min_time_constant_s = min_time_constant_s
        self.log_odds = 0.0

    def step(
        self,
        z_n: list[float] | tuple[float, ...],
        r_n2: list[float] | tuple[float, ...],
        dt_s: float,
        dt_mean_s: float,
        tau_s: float,
        constant_pred_p_n2: Sequence[float],
        constant_w: Sequence[float],
    ) -> bool:
        """One step beside the constant model's; False at the step its time constant has
        relaxed to the constant model's (the two are one model from then on: merge them) or
        its weight has fallen below 1e-9 (:data:`MOVING_MIN_LOG_ODDS`).

        Args:
            z_n: The observation, world, N.
            r_n2: The observation noise R per axis, N^2.
            dt_s: Time since the previous step, s (> 0).
            dt_mean_s: The mean sample spacing, s.
            tau_s: The constant model's time constant this step, s.
            constant_pred_p_n2: The constant model's P- this step, N^2.
            constant_w: Its whitened innovation ``ν / sqrt(S)`` this step.
        """
        scale = relaxed_scale(self.scale, dt_s, self.memory_s)  # no memory: relaxed at once
        self.scale = scale
        tau = self.tau_hover_s / math.sqrt(scale)
        tau = tau if tau > self.min_time_constant_s else self.min_time_constant_s
        same = tau >= tau_s
        if same:
            tau = tau_s  # relaxed to the constant model's: this is the last step
        c = dt_mean_s / (tau * tau) * dt_s  # q = r dt_mean / tau^2 per second
        kf = self.kf
        kf.predict([r_n2[0] * c, r_n2[1] * c, r_n2[2] * c])
        pred = kf.P
        w = kf.update(z_n, r_n2)
        log = math.log
        lo = self.log_odds
        for i in range(3):
            # log N(nu_a; 0, S_a) - log N(nu_c; 0, S_c), with nu / sqrt(S) = w
            s_c = constant_pred_p_n2[i] + r_n2[i]
            s_a = pred[i] + r_n2[i]
            lo += 0.5 * (constant_w[i] * constant_w[i] - w[i] * w[i] + log(s_c / s_a))
        self.log_odds = lo
        return not same and lo > MOVING_MIN_LOG_ODDS

    def weight(self) -> float:
        """The posterior probability of this hypothesis, ``σ(L)``."""
        lo = self.log_odds
        if lo >= 0.0:
            return 1.0 / (1.0 + math.exp(-lo))
        e = math.exp(lo)
        return e / (1.0 + e)

    def mixture(self, constant: DiagonalKalman) -> tuple[list[float], list[float]]:
        """The posterior mixture of the two: ``(x, diag P)``, P with the spread of the means."""
        wa = self.weight()
        wc = 1.0 - wa
        xa, pa = self.kf.x, self.kf.P
        xc, pc = constant.x, constant.P
        x = [wc * xc[i] + wa * xa[i] for i in range(3)]
        p = [
            wc * (pc[i] + (xc[i] - x[i]) ** 2) + wa * (pa[i] + (xa[i] - x[i]) ** 2)
            for i in range(3)
        ]
        return x, p
