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

__all__ = ["DiagonalKalman"]


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
