"""Catenary model of the tether: shape, solve, locate, floor contact, points for drawing.

Pure physics: numpy and the standard library only; no I/O, clock or logging.

Frames and symbols
------------------
In the vertical plane through base and drone, ``x`` is horizontal and ``y`` points up (the
paper's sec. t_shape); in 3D the plane is spanned by world ``z`` and the horizontal unit vector
``û`` from base to drone, and ``x`` becomes the radial distance ``r`` (sec. pos_est). Lengths
are metres, forces newtons, ``omega`` (``weight_n_per_m``) is the tether's weight per length.

The curve is ``y = a·cosh((x − x0)/a) + c`` (eq:cat_expression): ``a`` > 0 [m] is the
catenary parameter (H = ω·a, eq:cat_T0), ``x0`` [m] the abscissa of the lowest point and ``c``
[m] the offset (eq:Cparam). The signed arc length from the lowest point is
``σ(x) = a·sinh((x − x0)/a)`` and the vertical tension there is ω·σ (eq:cat_Tv, eq:cat_s2).

Regimes and their documented results
------------------------------------
* Slack (L ≫ chord), nearly taut (L/chord − 1 down to 1e-9 and below, ``a`` up to 1e5·L and
  beyond), equal heights, leftward spans (x2 < x1): ordinary solutions.
* Drone straight above the base (h = |x2 − x1| = 0): the degenerate plumb line, ``a = 0``,
  ``x0 = x1`` and ``c`` the height of the lowest point, ``(y1 + y2 − L)/2`` (the a → 0 limit).
* Exactly taut (L equal to the chord): the straight line, ``a = inf``, ``c = −inf``, ``x0`` the
  midpoint for a level chord and ``∓inf`` otherwise; :meth:`Catenary.y` draws the line.
* L shorter than the chord: :class:`TetherTooShortError`.

Numerics
--------
``solve`` reduces eq:cat7 to one equation ``sinh(ξ)/ξ = q`` with ``ξ = h/(2a)`` and
``q = sqrt(L² − v²)/h`` (see NOTES.md). Its hard regime is q → 1 (nearly taut): there the
answer depends on the slack ``D = L² − v² − h²``, a difference of nearly equal squares, and
on the differences ``x2 − x1``, ``y2 − y1`` of the inputs. Where D is below 2^-12·L², it is
evaluated with error-free transformations (Knuth's two-sum, Dekker's split), so ``a`` keeps
full relative precision even when it is 1e5 times the span, and ``x0 = x̄ − a·atanh(v/L)``
(which can be 1e5 m away) stays right to ~1e-12·L. Then ``w = q² − 1 = D/h²`` gives ξ by the
exact reverted power series ξ²(w) for w <= 2e-3; above, ξ is iterated on the well-conditioned
``ψ(ξ) = ln(sinh ξ/ξ) − ln q``: vectorised, from a two-formula start (4 %) by one Halley and
one Newton step; scalar, from a tabulated polynomial start (6e-7) by one Newton step. Both
reach ~1e-13, measured against a 50-digit mpmath reference (tests, benchmark). The
curve is evaluated from an anchor point on it (NOTES):
``y(x) − y1 = 2a·sinh((x + x1 − 2x0)/(2a))·sinh((x − x1)/(2a))``, which never forms the huge,
cancelling ``c``.

The vectorised path works in chunks of scratch rows reused with ``out=`` (no allocation in
the loop), each element taking only its own regime's branch; the scalar path uses ``math``,
and arrays of up to 24 elements go through it element by element.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Final, TypeAlias

import numpy as np
import numpy.typing as npt

__all__ = [
    "Catenary",
    "CatenaryError",
    "FloorLocation",
    "TetherForce",
    "TetherTooShortError",
    "locate",
    "locate_free",
    "locate_free_floats",
    "locate_with_floor",
    "locate_with_floor_floats",
    "solve",
    "tether_force",
    "tether_force_xyz",
    "tether_points",
]

FloatArray: TypeAlias = npt.NDArray[np.float64]
FloatOrArray: TypeAlias = float | FloatArray
BoolOrArray: TypeAlias = bool | npt.NDArray[np.bool_]

# Veltkamp/Dekker split constant 2**27 + 1: x = hi + lo with hi, lo of 26 bits each, so that
# products of parts are exact in float64.
_SPLIT: Final = 134217729.0
# With w = q² − 1 = D/h² (D = L² − v² − h², no square root needed), ξ² = t(w) is the exact
# reversion of sinh(ξ)/ξ = sqrt(1 + w): t = Σ _T_OF_W[k]·w^(k+1) (from the series
# sinh(ξ)/ξ − 1 = Σ ξ^2k/(2k+1)!, in exact rational arithmetic). Radius of convergence 0.95
# (the branch point where tanh ξ = ξ); with 6 terms the truncation error at w = _SERIES_MAX_W
# is below 1e-17 relative. Above it ln(sinh ξ/ξ) is formed directly and loses at most three
# digits to cancellation, which the iteration's 1e-13 accounts for.
_T_OF_W: Final = (3.0, -6 / 5, 123 / 175, -12 / 25, 120093 / 336875, -6113694 / 21896875)
_T0, _T1, _T2, _T3, _T4, _T5 = _T_OF_W
_SERIES_MAX_W: Final = 2e-3
# Above this ln q (h/L below 1e-299) sinh(ξ) would overflow; there e^(−2ξ) < 1e-600 and the
# equation is exactly ξ − ln(2ξ) = ln q, solved by its own Newton iteration.
_MAX_LN_Q: Final = 690.0
# Above this fraction of L² the plain L² − v² − h² is accurate enough (relative error below
# 4e-12, so a to 2e-12 and x0 to 4e-11·L): the error-free evaluation is skipped there.
_NAIVE_D_MIN: Final = 2.0**-12
# Start for the scalar iteration, ln q = y in [1e-3, 40]: ξ/z as a degree-8 polynomial in
# s = (z − mid)·inv_half on four segments of z = sqrt(y), each row (z_max, mid, inv_half,
# c0 … c8). Chebyshev interpolation of the 40-digit root (mpmath) at 9 nodes per segment,
# converted to powers of s; relative error below 6e-7 (checked in tests/test_catenary.py), so
# one Newton step leaves 2e-13.
# fmt: off
_XI_START: Final = (
    (0.11842897541618509, 0.07493876287440118, 22.99367930288302,
     2.450865092299136, 0.0015960717095184858, 0.00046281155109291684,
     -1.8802786169363686e-07, -2.7593027193591934e-08, -1.0813007277113539e-10,
     -1.006803798488215e-11, 1.0283124296592053e-13, 8.699293528894794e-15),
    (0.44597992816160803, 0.2822044517888966, 6.10592026442502,
     2.4689484605833503, 0.02252789184589749, 0.0064691375325726065,
     -4.0464883562110884e-05, -6.6349429199101345e-06, -2.3485627286921354e-07,
     -8.00873504502517e-09, 3.401663706093759e-09, 1.6416583196788878e-10),
    (1.6794715619556961, 1.062725745058652, 1.6214135104007266,
     2.714977982924537, 0.29424663331754347, 0.06885650799748458,
     -0.009391229065466532, -0.0006619641516980653, 0.0004900028979490963,
     3.3572303444332205e-05, -3.900938662214861e-05, -1.5338055431611782e-06),
    (6.324555320336759, 4.002013441146228, 0.43056274203698197,
     4.919857521476569, 2.0384259248573424, 0.1067892696821451,
     -0.04436026901701293, 0.019524921092658555, -0.008595824357706025,
     0.004280211411542815, -0.0026109328131060233, 0.0009196998378642006),
)
# fmt: on
_XI_START_Y_MAX: Final = 40.0
_LN2: Final = math.log(2.0)
_sqrt, _log, _log1p, _exp, _cosh = math.sqrt, math.log, math.log1p, math.exp, math.cosh
_TINY: Final = np.finfo(np.float64).tiny
_EPS: Final = np.finfo(np.float64).eps
# Elements per pass of the vectorised solver: its 29 scratch rows (7 MiB) stay in the L3
# cache; smaller passes pay more Python overhead per element (measured 8k-64k: 32k best).
_CHUNK: Final = 32768
# Up to this many elements the scalar path, element by element, is faster than one pass.
_SMALL_ARRAY: Final = 24
# Series of asinh(S) − S and of asinh(S) − 2S/(1 + sqrt(1 + S²)) in S² (after S³), used for
# a hanging part much shorter than a (S = s/a < 0.1) where the closed forms cancel.
_ASINH_MINUS_S: Final = (-1 / 6, 3 / 40, -5 / 112, 35 / 1152, -63 / 2816, 231 / 13312)
_D_ASINH_MINUS_S: Final = (1 / 12, -1 / 20, 15 / 448, -7 / 288, 105 / 5632, -99 / 6656)
# A tether within this fraction of being taut is drawn as a straight line.
_DRAW_TAUT: Final = 1e-12


class CatenaryError(ValueError):
    """Input outside the domain of the catenary model; the message names the values."""


class TetherTooShortError(CatenaryError):
    """The tether is shorter than the straight distance between its ends.

    Attributes:
        length_m: The tether length [m] (the first offending one for arrays).
        chord_m: The straight distance between the end points [m].
    """

    def __init__(self, length_m: float, chord_m: float, detail: str = "") -> None:
        self.length_m = length_m
        self.chord_m = chord_m
        super().__init__(
            f"tether length {length_m!r} m is shorter than the chord {chord_m!r} m between "
            f"its end points{detail}: no catenary reaches that far"
        )


# ---------------------------------------------------------------------------------------------
# The curve


@dataclass(frozen=True, slots=True)
class Catenary:
    """The curve ``y = a·cosh((x − x0)/a) + c`` (eq:cat_expression), floats or arrays.

    ``solve`` also records a point of the curve, the anchor ``(x1, y1)`` with the curve's
    parameter there, ``u1 = (x1 − x0)/a`` (``sinh(u1)`` is the slope dy/dx at ``x1``), so that
    :meth:`y` stays exact when ``a`` and ``x0`` are huge (nearly taut) and works in the
    straight-line limit ``a = inf``. Built by hand from ``a, x0, c`` only, the anchor is the
    lowest point (``x0``, ``a + c``) with ``u1 = 0``.

    Attributes:
        a: Catenary parameter [m], ``H/ω`` (eq:cat_T0); 0 for the plumb line, inf when taut.
        x0: Abscissa of the lowest point [m] (eq:cat6).
        c: Offset [m] (eq:Cparam); huge and imprecise in absolute terms when ``a`` is.
        x1: Abscissa of the anchor point [m], or None for the lowest point.
        y1: Height of the anchor point [m], or None for the lowest point.
        u1: ``(x1 − x0)/a`` [-], or None for the lowest point (0).
    """

    a: FloatOrArray
    x0: FloatOrArray
    c: FloatOrArray
    x1: FloatOrArray | None = None
    y1: FloatOrArray | None = None
    u1: FloatOrArray | None = None

    def y(self, x: npt.ArrayLike) -> FloatOrArray:
        """Height of the curve at ``x``, without cancellation.

        ``y(x) = y1 + 2a·sinh(u1 + (x − x1)/(2a))·sinh((x − x1)/(2a))`` (NOTES: the difference
        of eq:sys2_eq1 at x and x1 written as a product). For ``a = inf`` it is the straight
        line ``y1 + (x − x1)·sinh(u1)``; for the plumb line ``a = 0`` it is the a → 0 limit:
        the lowest point ``c`` at ``x == x0`` (the vertical segment above it is not a
        function of x) and ``+inf`` elsewhere.

        Args:
            x: Abscissa [m], float or array broadcastable with the parameters.

        Returns:
            Height [m]: a float for float parameters and ``x``, else an array.
        """
        a, x0, c = self.a, self.x0, self.c
        x1 = x0 if self.x1 is None else self.x1
        y1 = a + c if self.y1 is None else self.y1
        u1 = 0.0 if self.u1 is None else self.u1
        if _all_scalars(a, x0, c, x1, y1, u1, x):
            fx = float(x)  # type: ignore[arg-type]
            return _y_scalar(float(a), float(x0), float(c), float(x1), float(y1), float(u1), fx)
        xa = np.asarray(x, dtype=np.float64)
        aa = np.asarray(a, dtype=np.float64)
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            w = (xa - x1) / (2.0 * aa)
            out = y1 + 2.0 * aa * np.sinh(u1 + w) * np.sinh(w)
            if not np.all((aa > 0.0) & (aa < np.inf)):
                line = y1 + (xa - x1) * np.sinh(u1)
                out = np.where(aa == np.inf, line, out)
                out = np.where(aa == 0.0, np.where(xa == x0, c, np.inf), out)
        return np.asarray(out, dtype=np.float64)


def _y_scalar(a: float, x0: float, c: float, x1: float, y1: float, u1: float, x: float) -> float:
    if a == 0.0:
        return c if x == x0 else math.inf
    if a == math.inf:
        return y1 + (x - x1) * math.sinh(u1)
    w = (x - x1) / (2.0 * a)
    try:
        return y1 + 2.0 * a * math.sinh(u1 + w) * math.sinh(w)
    except OverflowError:
        # Both factors have the sign of w far out: the curve goes up on both sides.
        return math.inf


def _all_scalars(*values: object) -> bool:
    return all(isinstance(v, (float, int, np.floating, np.integer)) for v in values)


# The dataclass-generated __init__ of a frozen class sets each field through
# object.__setattr__, about 0.1 µs per field: a third of a scalar solve. solve() fills the
# slots through their descriptors instead; the result is an ordinary, equal instance.
_SET_A = Catenary.__dict__["a"].__set__
_SET_X0 = Catenary.__dict__["x0"].__set__
_SET_C = Catenary.__dict__["c"].__set__
_SET_X1 = Catenary.__dict__["x1"].__set__
_SET_Y1 = Catenary.__dict__["y1"].__set__
_SET_U1 = Catenary.__dict__["u1"].__set__
_new_object = object.__new__


def _make_catenary(a: Any, x0: Any, c: Any, x1: Any, y1: Any, u1: Any) -> Catenary:
    obj: Catenary = _new_object(Catenary)
    _SET_A(obj, a)
    _SET_X0(obj, x0)
    _SET_C(obj, c)
    _SET_X1(obj, x1)
    _SET_Y1(obj, y1)
    _SET_U1(obj, u1)
    return obj


# ---------------------------------------------------------------------------------------------
# solve: the catenary through two points with a given length


def solve(
    x1: npt.ArrayLike,
    y1: npt.ArrayLike,
    x2: npt.ArrayLike,
    y2: npt.ArrayLike,
    length: npt.ArrayLike,
) -> Catenary:
    """The catenary through (x1, y1) and (x2, y2) with arc length ``length`` (sec. t_shape).

    The paper's system eq:sys2_eq1–eq:sys2_eq5 reduces (eq:cat4–eq:cat7, NOTES) to
    ``sqrt(L² − v²) = 2a·sinh(h/(2a))`` with h = |x2 − x1|, v = y2 − y1, i.e.
    ``sinh(ξ)/ξ = q = sqrt(L² − v²)/h`` with ξ = h/(2a), monotone in ξ > 0; then
    ``x0 = x̄ − a·atanh(v/L)·sign(x2 − x1)`` (eq:cat6, with the sign that makes leftward spans
    work) and ``c = y1 − a·cosh((x1 − x0)/a)`` (eq:sys2_eq1).

    Departures from the paper's recipe: no Taylor start (eq:tayl4) and no Newton on eq:cat7
    (which cancels catastrophically when nearly taut and divides by Δx); instead the
    cancellation-free ``q² − 1`` is inverted by its power series or by Halley/Newton steps in
    log form (module docstring). Leftward spans, equal heights (where eq:cat7 is void) and the
    plumb line are handled. All regimes are documented in the module docstring.

    Args:
        x1: Abscissa of the first point [m] (the base).
        y1: Height of the first point [m].
        x2: Abscissa of the second point [m] (the drone).
        y2: Height of the second point [m].
        length: Arc length between the points [m], at least the chord.

    Returns:
        The curve, anchored at (x1, y1). Python floats when all inputs are scalars, else
        arrays of the broadcast shape.

    Raises:
        TetherTooShortError: ``length`` is shorter than the chord (names both).
        CatenaryError: An input is not finite or ``length`` is negative.
    """
    if (
        type(x1) is float
        and type(y1) is float
        and type(x2) is float
        and type(y2) is float
        and type(length) is float
    ):
        a, x0, c, u1, _ = _solve_scalar(x1, y1, x2, y2, length)
        return _make_catenary(a, x0, c, x1, y1, u1)
    if _all_scalars(x1, y1, x2, y2, length):
        fx1, fy1 = float(x1), float(y1)  # type: ignore[arg-type]
        a, x0, c, u1, _ = _solve_scalar(fx1, fy1, float(x2), float(y2), float(length))  # type: ignore[arg-type]
        return _make_catenary(a, x0, c, fx1, fy1, u1)
    return _solve_arrays(x1, y1, x2, y2, length)


def _solve_scalar(
    x1: float, y1: float, x2: float, y2: float, length: float
) -> tuple[float, float, float, float, float]:
    """Scalar solve with the math module. Returns (a, x0, c, u1, xi)."""
    big_l = length
    dx = x2 - x1
    dy = y2 - y1
    v = abs(dy)
    # D = L² − v² − h² >= 0, the slack (0 when taut). Where it is small against L², rounding
    # in this plain form would dominate: the error-free evaluation of _exact_slack, inlined.
    d_big = (big_l - v) * (big_l + v) - dx * dx
    if d_big >= _NAIVE_D_MIN * big_l * big_l:
        l_minus_v = big_l - v
    else:
        bb = dx - x2
        dx_err = (x2 - (dx - bb)) - (x1 + bb)  # dx + dx_err == x2 − x1 exactly (two-sum)
        bb = dy - y2
        dy_err = (y2 - (dy - bb)) - (y1 + bb)
        p = _SPLIT * big_l
        l_hi = p - (p - big_l)
        l_lo = big_l - l_hi
        p = _SPLIT * dx
        x_hi = p - (p - dx)
        x_lo = dx - x_hi
        p = _SPLIT * dy
        y_hi = p - (p - dy)
        y_lo = dy - y_hi
        x_hi2 = x_hi * x_hi
        y_hi2 = y_hi * y_hi
        s_hi = x_hi2 + y_hi2
        bb = s_hi - x_hi2
        s_err = (x_hi2 - (s_hi - bb)) + (y_hi2 - bb)
        d_big = (
            ((l_hi * l_hi - s_hi) - s_err)
            + 2.0 * (l_hi * l_lo - x_hi * x_lo - y_hi * y_lo)
            + (l_lo * l_lo - x_lo * x_lo - y_lo * y_lo)
            - 2.0 * (dx * dx_err + dy * dy_err)
        )
        l_minus_v = (big_l - v) - (dy_err if dy > 0.0 else -dy_err)
    if not (0.0 <= d_big < math.inf) or big_l < 0.0:
        raise _domain_error(x1, y1, x2, y2, big_l)
    h = abs(dx)
    if h == 0.0:
        # Plumb line: both ends on one vertical, the lowest point (L − |v|)/2 below the lower.
        return 0.0, x1, 0.5 * (y1 + y2 - big_l), 0.0, math.inf
    # atanh(|v|/L) = ½·ln((L + |v|)/(L − |v|)), with L − |v| from the exact v (eq:cat6).
    t_abs = 0.5 * _log1p(2.0 * v / (l_minus_v if l_minus_v > _TINY else _TINY))
    t = math.copysign(t_abs, dy) if dx > 0.0 else -math.copysign(t_abs, dy)
    x_mid = 0.5 * (x1 + x2)
    if d_big == 0.0:
        # Exactly taut: the straight line, a = inf (vertex infinitely far on the low side).
        x0 = x_mid if t == 0.0 else -math.copysign(math.inf, t)
        return math.inf, x0, -math.inf, t, 0.0
    hh = h * h
    w = d_big / hh if hh > 0.0 else math.inf  # q² − 1 = (L² − v²)/h² − 1
    if w <= _SERIES_MAX_W:
        xi = _sqrt(w * (_T0 + w * (_T1 + w * (_T2 + w * (_T3 + w * (_T4 + w * _T5))))))
    else:
        # ln q = ½·ln(1 + w); for h below ~1e-154·L, w overflows: ln q = ½·ln D − ln h.
        y = 0.5 * _log1p(w) if w < math.inf else 0.5 * _log(d_big) - _log(h)
        if y > _XI_START_Y_MAX:
            xi = _xi_asymptotic_scalar(y)
        else:
            xi = _xi_start_scalar(y)
            # One Newton step on ψ(ξ) = ln(sinh ξ/ξ) − ln q, ψ' = coth ξ − 1/ξ.
            e = _exp(xi)
            ei = 1.0 / e
            sh2 = e - ei  # 2·sinh ξ
            xi -= (_log(sh2 / xi) - (y + _LN2)) / ((e + ei) / sh2 - 1.0 / xi)
    a = h / (2.0 * xi)
    if a == 0.0:  # h/L below ~1e-300: underflow, the plumb line to every digit
        return 0.0, x1, 0.5 * (y1 + y2 - big_l), 0.0, math.inf
    x0 = x_mid - a * t  # eq:cat6, t carries sign(x2 − x1)
    u1 = t - xi if dx > 0.0 else t + xi  # (x1 − x0)/a = sign(x2 − x1)·(atanh(v/L) − ξ)
    c = y1 - (a * _cosh(u1) if -700.0 < u1 < 700.0 else _a_cosh(a, u1))  # eq:sys2_eq1
    return a, x0, c, u1, xi


def _xi_start_scalar(y: float) -> float:
    """ξ to 6e-7 from y = ln q in [1e-3, 40] (the table _XI_START)."""
    z = _sqrt(y)
    for seg in _XI_START:  # the last segment also takes a rounding overshoot
        if z <= seg[0]:
            break
    _, mid, inv_half, c0, c1, c2, c3, c4, c5, c6, c7, c8 = seg
    s = (z - mid) * inv_half
    return z * (
        c0 + s * (c1 + s * (c2 + s * (c3 + s * (c4 + s * (c5 + s * (c6 + s * (c7 + s * c8)))))))
    )


def _xi_asymptotic_scalar(y: float) -> float:
    """Root of ξ − ln(2ξ) = y, which is sinh ξ/ξ = e^y to 1e-38 once y > 40; inf for inf."""
    if y == math.inf:
        return math.inf
    xi = y + math.log(2.0 * y)
    for _ in range(3):
        xi -= (xi - math.log(2.0 * xi) - y) / (1.0 - 1.0 / xi)
    return xi


def _xi_asymptotic(y: FloatArray) -> FloatArray:
    """Vectorised _xi_asymptotic_scalar."""
    xi = y + np.log(2.0 * y)
    for _ in range(3):
        xi -= (xi - np.log(2.0 * xi) - y) / (1.0 - 1.0 / xi)
    return np.where(y == np.inf, np.inf, xi)


def _a_cosh(a: float, u: float) -> float:
    """a·cosh(u) without overflow of cosh when a is tiny (near plumb)."""
    if abs(u) < 700.0:
        return a * math.cosh(u)
    lg = abs(u) + math.log(a) - _LN2
    return math.exp(lg) if lg < 709.0 else math.inf


def _a_sinh(a: float, u: float) -> float:
    """a·sinh(u) without overflow of sinh when a is tiny (near plumb)."""
    if abs(u) < 700.0:
        return a * math.sinh(u)
    lg = abs(u) + math.log(a) - _LN2
    return math.copysign(math.exp(lg) if lg < 709.0 else math.inf, u)


def _domain_error(x1: float, y1: float, x2: float, y2: float, length: float) -> CatenaryError:
    values = f"(x1={x1!r}, y1={y1!r}, x2={x2!r}, y2={y2!r}, length={length!r})"
    if not all(math.isfinite(v) for v in (x1, y1, x2, y2, length)):
        return CatenaryError(f"catenary inputs must be finite, got {values}")
    if length < 0.0:
        return CatenaryError(f"tether length must be >= 0, got {length!r} m {values}")
    chord = math.hypot(x2 - x1, y2 - y1)
    if chord == math.inf:
        return CatenaryError(f"catenary inputs too large for float64: {values}")
    return TetherTooShortError(length, chord, f" {values}")


def _solve_arrays(
    x1: npt.ArrayLike,
    y1: npt.ArrayLike,
    x2: npt.ArrayLike,
    y2: npt.ArrayLike,
    length: npt.ArrayLike,
) -> Catenary:
    arrays = np.broadcast_arrays(
        *(np.asarray(v, dtype=np.float64) for v in (x1, y1, x2, y2, length))
    )
    shape = arrays[0].shape
    flat = [np.ravel(v) for v in arrays]
    n = flat[0].size
    out = np.empty((6, n))  # rows: a, x0, c, u1 and the anchor x1, y1 (copies of the inputs)
    if n <= _SMALL_ARRAY:
        # A pass costs ~150 numpy calls whatever its length: few elements go one by one.
        for i, row in enumerate(zip(*(v.tolist() for v in flat), strict=True)):
            try:
                a_i, x0_i, c_i, u1_i, _ = _solve_scalar(*row)
            except TetherTooShortError as err:
                raise TetherTooShortError(err.length_m, err.chord_m, f" at flat index {i}") from err
            except CatenaryError as err:
                raise CatenaryError(f"{err} at flat index {i}") from err
            out[:, i] = (a_i, x0_i, c_i, u1_i, row[0], row[1])
        a, x0, c, u1, x1_out, y1_out = (row.reshape(shape) for row in out)
        return _make_catenary(a, x0, c, x1_out, y1_out, u1)
    # Scratch rows reused by every chunk, so that the loop allocates (almost) nothing: a
    # freshly allocated temporary of 100 KiB or more costs page faults whenever the
    # allocator has handed its memory back to the OS (4x slower iterations in isolation).
    width = max(1, min(n, _CHUNK))
    work = np.empty((_WORK_ROWS, width))
    flags = np.empty(width, dtype=np.bool_)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for start in range(0, n, _CHUNK):
            sl = slice(start, start + _CHUNK)
            chunk = [v[sl] for v in flat]
            _solve_chunk(*chunk, out=out[:, sl], work=work, flags=flags, offset=start)
    a, x0, c, u1, x1_out, y1_out = (row.reshape(shape) for row in out)
    return _make_catenary(a, x0, c, x1_out, y1_out, u1)


# Scratch rows: 9 named ones in _solve_chunk, then 20 for the helpers (gathered subsets,
# _exact_slack's 12, _xi_iterated's 6).
_ROW_FIRST_FREE: Final = 9
_WORK_ROWS: Final = _ROW_FIRST_FREE + 20


def _solve_chunk(
    x1: FloatArray,
    y1: FloatArray,
    x2: FloatArray,
    y2: FloatArray,
    big_l: FloatArray,
    *,
    out: FloatArray,
    work: FloatArray,
    flags: npt.NDArray[np.bool_],
    offset: int,
) -> None:
    """Vectorised solve of one chunk into ``out`` rows (a, x0, c, u1, x1, y1).

    The formulas of :func:`_solve_scalar`, written with ``out=`` into the scratch rows of
    ``work``. Each regime takes only its own path (index subsets: cheaper than computing
    every path for every element and selecting). Runs under np.errstate(ignore).
    """
    m = x1.size
    a, x0, c, u1, x1_out, y1_out = out
    rows = work[:, :m]
    dx, dy, l_minus_v, l_plus_v, d_big, h, w, y, xi = rows[:_ROW_FIRST_FREE]
    tmp = rows[_ROW_FIRST_FREE:]
    t0, t1 = tmp[0], tmp[1]
    ok = flags[:m]

    np.subtract(x2, x1, out=dx)
    np.subtract(y2, y1, out=dy)
    np.abs(dy, out=t0)  # |v|
    np.subtract(big_l, t0, out=l_minus_v)
    np.add(big_l, t0, out=l_plus_v)
    np.multiply(l_minus_v, l_plus_v, out=d_big)
    d_big -= np.multiply(dx, dx, out=t0)  # D = L² − v² − h², plain
    # Where D is small against L² (nearly taut) rounding in the plain form would dominate:
    # redo those elements without it.
    np.multiply(big_l, big_l, out=t0)
    t0 *= _NAIVE_D_MIN
    np.greater_equal(d_big, t0, out=ok)
    n_plain = int(np.count_nonzero(ok))
    if n_plain == 0:
        _exact_slack(x1, y1, x2, y2, big_l, d_big, l_minus_v, tmp)
    elif n_plain < m:
        tight = np.flatnonzero(~ok)
        k = tight.size
        sub = tmp[:, :k]
        for i, v in enumerate((x1, y1, x2, y2, big_l)):
            np.take(v, tight, out=sub[i])
        _exact_slack(sub[0], sub[1], sub[2], sub[3], sub[4], sub[5], sub[6], sub[7:])
        d_big[tight] = sub[5]
        l_minus_v[tight] = sub[6]
    d_min = d_big.min()
    if not (d_min >= 0.0 and d_big.max() < np.inf and big_l.min() >= 0.0):
        raise _first_domain_error(x1, y1, x2, y2, big_l, d_big, offset)

    np.abs(dx, out=h)
    np.multiply(h, h, out=w)
    np.divide(d_big, w, out=w)  # q² − 1
    np.log1p(w, out=y)
    y *= 0.5  # ln q
    if y.max() == np.inf:  # h below ~1e-154·L: w overflows, ln q = ½·ln D − ln h
        y[...] = np.where(y == np.inf, 0.5 * np.log(d_big) - np.log(h), y)
    np.less_equal(w, _SERIES_MAX_W, out=ok)
    n_small = int(np.count_nonzero(ok))
    if n_small == m:
        _xi_series(w, xi)
    elif n_small == 0:
        _xi_iterated(y, xi, tmp)
    else:
        i_small = np.flatnonzero(ok)
        i_large = np.flatnonzero(~ok)
        ks, kl = i_small.size, i_large.size
        _xi_series(np.take(w, i_small, out=tmp[0, :ks]), tmp[1, :ks])
        xi[i_small] = tmp[1, :ks]
        _xi_iterated(np.take(y, i_large, out=tmp[0, :kl]), tmp[1, :kl], tmp[2:, :kl])
        xi[i_large] = tmp[1, :kl]

    np.multiply(xi, 2.0, out=t0)
    np.divide(h, t0, out=a)
    # atanh(|v|/L) = ½·ln(1 + 2|v|/(L − |v|)) (eq:cat6), with the sign of v·(x2 − x1).
    np.abs(dy, out=t0)
    t0 *= 2.0
    np.maximum(l_minus_v, _TINY, out=t1)
    np.divide(t0, t1, out=t1)
    np.log1p(t1, out=t1)
    t1 *= 0.5
    np.copysign(t1, np.multiply(dy, dx, out=t0), out=t1)
    np.subtract(t1, np.copysign(xi, dx, out=t0), out=u1)  # (x1 − x0)/a = t − sign(dx)·ξ
    np.add(x1, x2, out=x0)
    x0 *= 0.5
    x0 -= np.multiply(a, t1, out=t0)  # eq:cat6
    np.cosh(u1, out=c)
    c *= a
    np.subtract(y1, c, out=c)  # eq:sys2_eq1
    x1_out[...] = x1
    y1_out[...] = y1

    if d_min == 0.0 or a.min() == 0.0 or not np.isfinite(c).all():
        a[...], x0[...], c[...], u1[...] = _patch_degenerate(
            x1, y1, y2, big_l, dx, d_big, t1, a, x0, c, u1
        )


def _split(x: FloatArray, hi: FloatArray, lo: FloatArray, p: FloatArray) -> None:
    """Dekker's split x = hi + lo, 26 bits each, so products of parts are exact."""
    np.multiply(x, _SPLIT, out=p)
    np.subtract(p, x, out=lo)
    np.subtract(p, lo, out=hi)
    np.subtract(x, hi, out=lo)


def _two_diff(
    a: FloatArray, b: FloatArray, d: FloatArray, err: FloatArray, tmp: FloatArray
) -> None:
    """Knuth's two-sum for a − b: d + err == a − b exactly."""
    np.subtract(a, b, out=d)
    np.subtract(d, a, out=tmp)  # bb
    np.subtract(d, tmp, out=err)
    np.subtract(a, err, out=err)  # a − (d − bb)
    tmp += b  # b + bb
    err -= tmp


def _exact_slack(
    x1: FloatArray,
    y1: FloatArray,
    x2: FloatArray,
    y2: FloatArray,
    big_l: FloatArray,
    d_out: FloatArray,
    lmv_out: FloatArray,
    scratch: FloatArray,
) -> None:
    """D = L² − (x2 − x1)² − (y2 − y1)² and L − |y2 − y1| to ~2^-100·L², error-free.

    Knuth's two-sum gives each difference with its exact rounding error, Dekker's split
    makes every product of parts exact, and l_hi² − (x_hi² + y_hi²) is exact when nearly
    taut (Sterbenz); what is left is below 2^-80·L². :func:`_solve_scalar` inlines the same.
    ``scratch`` needs 12 rows.
    """
    dx, dx_err, dy, dy_err, l_hi, l_lo, x_hi, x_lo, y_hi, y_lo, p, bb = scratch[:12]
    _two_diff(x2, x1, dx, dx_err, p)
    _two_diff(y2, y1, dy, dy_err, p)
    # L − |v| with the exact v = dy + dy_err.
    np.subtract(big_l, np.abs(dy, out=p), out=lmv_out)
    lmv_out -= np.multiply(np.sign(dy, out=p), dy_err, out=p)
    np.multiply(dx_err, dx, out=dx_err)
    dx_err += np.multiply(dy_err, dy, out=dy_err)  # dx·dx_err + dy·dy_err
    _split(big_l, l_hi, l_lo, p)
    _split(dx, x_hi, x_lo, p)
    _split(dy, y_hi, y_lo, p)
    x_hi2 = np.multiply(x_hi, x_hi, out=dx)
    y_hi2 = np.multiply(y_hi, y_hi, out=dy)
    s_hi = np.add(x_hi2, y_hi2, out=dy_err)
    np.subtract(s_hi, x_hi2, out=bb)
    np.subtract(s_hi, bb, out=p)
    np.subtract(x_hi2, p, out=p)
    np.subtract(y_hi2, bb, out=bb)
    p += bb  # two-sum error of s_hi
    # D = ((l_hi² − s_hi) − s_err) + 2(l_hi·l_lo − x_hi·x_lo − y_hi·y_lo)
    #     + (l_lo² − x_lo² − y_lo²) − 2(dx·dx_err + dy·dy_err)
    np.multiply(l_hi, l_hi, out=d_out)
    d_out -= s_hi
    d_out -= p
    np.multiply(l_hi, l_lo, out=p)
    p -= np.multiply(x_hi, x_lo, out=bb)
    p -= np.multiply(y_hi, y_lo, out=bb)
    p *= 2.0
    d_out += p
    np.multiply(l_lo, l_lo, out=p)
    p -= np.multiply(x_lo, x_lo, out=bb)
    p -= np.multiply(y_lo, y_lo, out=bb)
    d_out += p
    dx_err *= 2.0
    d_out -= dx_err


def _xi_series(w: FloatArray, xi: FloatArray) -> None:
    """ξ into ``xi`` for w <= _SERIES_MAX_W from the reverted series t(w) = ξ²."""
    np.multiply(w, _T5, out=xi)
    for coef in (_T4, _T3, _T2, _T1):
        xi += coef
        xi *= w
    xi += _T0
    xi *= w
    np.sqrt(xi, out=xi)


def _xi_iterated(y: FloatArray, xi: FloatArray, scratch: FloatArray) -> None:
    """ξ into ``xi`` from y = ln q > ½·ln(1 + _SERIES_MAX_W) (6 scratch rows).

    Start: the larger of ξ² ≈ 6y + 1.2y² (series of ψ) and ξ ≈ ln(2qξ) iterated once from
    ln 2q, each within 4 % where it is the larger. Then one Halley and one Newton step on
    ψ(ξ) = ln(sinh ξ/ξ) − ln q (4e-2 → 5e-7 → 1e-13) with ψ' = coth ξ − 1/ξ and
    ψ'' = 1/ξ² − 1/sinh² ξ.
    """
    y_2q, b0, b1, b2, b3, b4 = scratch[:6]
    np.minimum(y, _MAX_LN_Q, out=y_2q)  # sinh stays finite; larger y below
    np.minimum(y_2q, 30.0, out=b0)
    np.multiply(b0, 1.2, out=b1)
    b1 += 6.0
    b1 *= b0
    np.sqrt(b1, out=b1)
    y_2q += _LN2  # ln 2q
    np.log(y_2q, out=b0)
    b0 += y_2q
    np.log(b0, out=b0)
    b0 += y_2q
    np.maximum(b1, b0, out=xi)
    # Halley
    e = np.exp(xi, out=b0)
    ei = np.divide(1.0, e, out=b1)
    sh2 = np.subtract(e, ei, out=b2)  # 2·sinh ξ
    ch2 = np.add(e, ei, out=b0)  # 2·cosh ξ
    rx = np.divide(1.0, xi, out=b3)
    f = np.multiply(sh2, rx, out=b4)
    np.log(f, out=f)
    f -= y_2q  # ψ
    p1 = np.divide(ch2, sh2, out=b0)
    p1 -= rx  # ψ'
    p2 = np.multiply(sh2, sh2, out=b1)
    np.divide(4.0, p2, out=p2)
    np.subtract(np.multiply(rx, rx, out=b2), p2, out=p2)  # ψ''
    p2 *= f
    den = np.multiply(p1, p1, out=b2)
    den *= 2.0
    den -= p2  # 2ψ'² − ψψ''
    f *= p1
    f *= 2.0
    f /= den
    xi -= f
    # Newton
    e = np.exp(xi, out=b0)
    ei = np.divide(1.0, e, out=b1)
    sh2 = np.subtract(e, ei, out=b2)
    ch2 = np.add(e, ei, out=b0)
    f = np.divide(sh2, xi, out=b4)
    np.log(f, out=f)
    f -= y_2q
    p1 = np.divide(ch2, sh2, out=b0)
    p1 -= np.divide(1.0, xi, out=b1)
    f /= p1
    xi -= f
    if y.max() > _MAX_LN_Q:
        huge = y > _MAX_LN_Q
        xi[huge] = _xi_asymptotic(y[huge])


def _patch_degenerate(
    x1: FloatArray,
    y1: FloatArray,
    y2: FloatArray,
    big_l: FloatArray,
    dx: FloatArray,
    d_big: FloatArray,
    t: FloatArray,
    a: FloatArray,
    x0: FloatArray,
    c: FloatArray,
    u1: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Documented values for the exactly taut, plumb and absurdly-near-plumb elements."""
    x_mid = x1 + 0.5 * dx
    taut = (d_big == 0.0) & (dx != 0.0)
    x0 = np.where(taut, np.where(t == 0.0, x_mid, -np.copysign(np.inf, t)), x0)
    # a tiny, |u1| > 710: a·cosh(u1) through logs.
    far = ~np.isfinite(c) & (a > 0.0) & (a < np.inf)
    c = np.where(far, y1 - np.exp(np.abs(u1) + np.log(a) - _LN2), c)
    plumb = (dx == 0.0) | (a == 0.0)  # or h/L so small that a underflows
    a = np.where(plumb, 0.0, a)
    x0 = np.where(plumb, x1, x0)
    c = np.where(plumb, 0.5 * (y1 + y2 - big_l), c)
    u1 = np.where(plumb, 0.0, u1)
    return a, x0, c, u1


def _first_domain_error(
    x1: FloatArray,
    y1: FloatArray,
    x2: FloatArray,
    y2: FloatArray,
    big_l: FloatArray,
    d_big: FloatArray,
    offset: int,
) -> CatenaryError:
    bad = ~((d_big >= 0.0) & (d_big < np.inf) & (big_l >= 0.0))
    i = int(np.argmax(bad))
    err = _domain_error(float(x1[i]), float(y1[i]), float(x2[i]), float(y2[i]), float(big_l[i]))
    detail = f" at flat index {offset + i} ({int(bad.sum())} bad in its chunk of {bad.size})"
    if isinstance(err, TetherTooShortError):
        return TetherTooShortError(err.length_m, err.chord_m, detail)
    return CatenaryError(f"{err}{detail}")


# ---------------------------------------------------------------------------------------------
# locate: drone position from the tension at the drone end


def locate(
    horizontal_n: npt.ArrayLike,
    vertical_n: npt.ArrayLike,
    weight_n_per_m: npt.ArrayLike,
    length_m: npt.ArrayLike,
    base_z_m: npt.ArrayLike = 0.0,
) -> tuple[FloatOrArray, FloatOrArray]:
    """Drone end of a freely hanging tether from the tension on the drone (sec. pos_est).

    With ``a = H/ω`` (eq:a_param) and ``s2 = T_v/ω`` (eq:s2_param) the signed arc length from
    the lowest point to the drone (negative when the tether pulls the drone up: then the
    drone is the lowest point of the tether, which rises all the way to the base), the base is
    at ``s2 − L`` (eq:posfull_stot) and eqs. posfull_r_0 … posfull_C collapse to (NOTES):

        r = a·[asinh(s2/a) + asinh((L − s2)/a)]
        z = z_i + sqrt(a² + s2²) − sqrt(a² + (L − s2)²) = z_i + (2·s2 − L)·L / (sum of roots)

    The second form has no cancellation, and ``a·asinh(s/a)`` is evaluated so that a → 0 gives
    the exact limits r → 0, z → z_i + |s2| − |L − s2| (eq:posfull_limr, eq:posfull_limz):
    H = 0 is an ordinary input.

    Args:
        horizontal_n: Horizontal tension H on the drone [N], >= 0.
        vertical_n: Downward pull T_v of the tether on the drone [N], any sign.
        weight_n_per_m: Tether weight per length ω [N/m], > 0.
        length_m: Tether length L from the base exit to the drone [m], > 0.
        base_z_m: Height of the base exit z_i [m].

    Returns:
        ``(r_m, z_m)``: horizontal distance from the base [m] and drone height [m]. Floats for
        scalar inputs, else arrays of the broadcast shape.

    Raises:
        CatenaryError: Negative or non-finite H, non-positive ω or L, non-finite T_v or z_i.
    """
    scalar = _all_scalars(horizontal_n, vertical_n, weight_n_per_m, length_m, base_z_m)
    h_n, tv_n, omega, big_l, z_i = _checked_tension_inputs(
        horizontal_n, vertical_n, weight_n_per_m, length_m, base_z_m
    )
    a = h_n / omega
    s2 = tv_n / omega
    r, z = locate_free(a, s2, big_l, z_i)
    return _out(r, scalar), _out(z, scalar)


def locate_free(
    a: FloatArray, s2: FloatArray, big_l: FloatArray, z_i: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """:func:`locate` from the catenary parameters, without input checks (hot paths).

    Args:
        a: H/ω, m, ≥ 0 (eq:a_param). s2: T_v/ω, m (eq:s2_param). big_l: tether length, m.
        z_i: base height, m. Float64 arrays of one broadcast shape; the caller has
            validated them (finite, a ≥ 0, L > 0).

    Returns:
        (r_m, z_m), eq:posfull_radial and eq:posfull_z in the closed form of NOTES.md.
    """
    t = big_l - s2
    r = _a_asinh(a, s2) + _a_asinh(a, t)  # eq:posfull_r_0 + eq:posfull_radial
    with np.errstate(over="ignore"):
        z = z_i + (2.0 * s2 - big_l) * big_l / (np.hypot(a, s2) + np.hypot(a, t))  # eq:posfull_z
    return r, z


def _a_asinh(a: FloatArray, s: FloatArray) -> FloatArray:
    """a·asinh(s/a), horizontal reach of a hanging arc s; 0 in the limit a → 0."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        v = a * np.arcsinh(s / a)
    # a == 0 gives 0·inf or 0/0; a subnormal overflows s/a while the true value is < 1e-305.
    return np.where(np.isfinite(v), v, 0.0)


def locate_free_floats(
    a: list[float], s2: list[float], big_l: float, z_i: float
) -> tuple[list[float], list[float]]:
    """:func:`locate_free` of a few points on Python floats (the per-message path).

    The same operations element by element, so the same floats, except that ``hypot`` is
    ``math.hypot`` (CPython's, correctly rounded in practice) where numpy's is the C
    library's: the two differ by an ulp at times. ``math.asinh`` is numpy's ``arcsinh``
    (both the C library's). numpy's call overhead (~1 µs a call, a dozen calls) is what
    this saves on 8 points.

    Args:
        a: H/ω per point, m, ≥ 0 (eq:a_param). s2: T_v/ω per point, m (eq:s2_param).
        big_l: Tether length, m, > 0. z_i: Base height, m. All finite (the caller checked).

    Returns:
        (r_m, z_m) per point, eq:posfull_radial and eq:posfull_z in the closed form of NOTES.
    """
    asinh, hypot, isfinite = math.asinh, math.hypot, math.isfinite
    rs: list[float] = []
    zs: list[float] = []
    for ai, si in zip(a, s2, strict=True):
        t = big_l - si
        if ai > 0.0:
            # Both terms finite exactly when their sum is (inf - inf is NaN): then this is
            # _a_asinh's value; otherwise each term is checked as there.
            r = ai * asinh(si / ai) + ai * asinh(t / ai)  # eq:posfull_r_0 + eq:posfull_radial
            if not isfinite(r):
                r = _a_asinh_float(ai, si) + _a_asinh_float(ai, t)
        else:  # a = 0: 0·inf or 0/0 in numpy, 0 in the limit
            r = 0.0
        rs.append(r)
        zs.append(z_i + (2.0 * si - big_l) * big_l / (hypot(ai, si) + hypot(ai, t)))  # eq:posfull_z
    return rs, zs


def _a_asinh_float(a: float, s: float) -> float:
    """:func:`_a_asinh` of one point, a ≥ 0."""
    if not a > 0.0:
        return 0.0
    v = a * math.asinh(s / a)
    return v if math.isfinite(v) else 0.0


def locate_with_floor_floats(
    horizontal_n: list[float],
    vertical_n: list[float],
    weight_n_per_m: float,
    length_m: float,
    base_z_m: float,
    floor_z_m: float,
) -> tuple[list[float], list[float], list[float], list[float], list[bool], list[float]]:
    """:func:`locate_with_floor` of a few points on Python floats (the per-message path).

    The operations of :func:`locate_with_floor` element by element (``hypot`` is
    ``math.hypot``: see :func:`locate_free_floats`), without its input checks: H ≥ 0 and
    finite, T_v finite, ω and L finite and > 0, ``floor_z_m <= base_z_m`` (the caller checked).

    Returns:
        ``(r_m, z_m, r_min_m, r_max_m, floor_contact, floor_run_m)``, one list each.
    """
    omega, big_l, z_i, z_f = weight_n_per_m, length_m, base_z_m, floor_z_m
    hypot, isfinite, sqrt = math.hypot, math.isfinite, math.sqrt
    a_pts = [h / omega for h in horizontal_n]  # eq:a_param
    s2_pts = [v / omega for v in vertical_n]  # eq:s2_param
    r_free, z_free = locate_free_floats(a_pts, s2_pts, big_l, z_i)
    h_b = z_i - z_f
    r_m: list[float] = []
    z_m: list[float] = []
    r_lo: list[float] = []
    contact_m: list[bool] = []
    run_m: list[float] = []
    for a, s2, rf, zf in zip(a_pts, s2_pts, r_free, z_free, strict=True):
        t = big_l - s2
        den = hypot(a, t) + a
        sag = t * t / den if den > 0.0 else math.nan  # sqrt(a² + t²) − a: vertex below the base
        if not isfinite(sag):
            sag = 0.0
        contact = s2 >= 0.0 and t >= 0.0 and z_i - sag < z_f
        if not contact:
            r_m.append(rf)
            z_m.append(zf if not zf < z_f else z_f)  # the floor holds the drone up
            r_lo.append(rf)
            contact_m.append(False)
            run_m.append(0.0)
            continue
        s2c = s2 if not s2 < 0.0 else 0.0
        s_b = sqrt(h_b * (h_b + 2.0 * a))
        run = big_l - s2c - s_b
        run = run if not run < 0.0 else 0.0
        den = hypot(a, s2c) + a
        lift = s2c * s2c / den if den > 0.0 else math.nan  # sqrt(a² + s2²) − a
        if not isfinite(lift):
            lift = 0.0
        reach = _a_asinh_float(a, s2c) + _a_asinh_float(a, s_b)
        r_max = reach + run
        r_min = reach - run
        r_m.append(r_max)
        z_m.append(z_f + lift)
        r_lo.append(r_min if not r_min < 0.0 else 0.0)
        contact_m.append(True)
        run_m.append(run)
    return r_m, z_m, r_lo, list(r_m), contact_m, run_m


def _out(v: FloatArray, scalar: bool) -> FloatOrArray:
    return float(v) if scalar else v


def _checked_tension_inputs(
    horizontal_n: npt.ArrayLike,
    vertical_n: npt.ArrayLike,
    weight_n_per_m: npt.ArrayLike,
    length_m: npt.ArrayLike,
    base_z_m: npt.ArrayLike,
) -> list[FloatArray]:
    arrays = np.broadcast_arrays(
        *(
            np.asarray(v, dtype=np.float64)
            for v in (horizontal_n, vertical_n, weight_n_per_m, length_m, base_z_m)
        )
    )
    h_n, tv_n, omega, big_l, z_i = arrays
    _require(h_n, (h_n >= 0.0) & (h_n < np.inf), "horizontal_n", "finite and >= 0 N")
    _require(tv_n, np.isfinite(tv_n), "vertical_n", "finite")
    _require(omega, (omega > 0.0) & (omega < np.inf), "weight_n_per_m", "finite and > 0 N/m")
    _require(big_l, (big_l > 0.0) & (big_l < np.inf), "length_m", "finite and > 0 m")
    _require(z_i, np.isfinite(z_i), "base_z_m", "finite")
    return list(arrays)


def _require(values: FloatArray, ok: npt.NDArray[np.bool_], name: str, what: str) -> None:
    if ok.all():
        return
    bad = ~ok
    if values.ndim == 0:
        raise CatenaryError(f"{name} must be {what}, got {float(values)!r}")
    i = np.unravel_index(int(np.argmax(bad)), bad.shape)
    raise CatenaryError(
        f"{name} must be {what}; {int(bad.sum())} of {bad.size} values are not, "
        f"first {float(values[i])!r} at index {tuple(int(k) for k in i)}"
    )


# ---------------------------------------------------------------------------------------------
# Floor contact: inverse


@dataclass(frozen=True, slots=True)
class FloorLocation:
    """Drone position from the tension when part of the tether may rest on the floor.

    Attributes:
        r_m: Best horizontal distance from the base [m]: the floor run lying straight (see
            :func:`locate_with_floor`); equals the free solution without contact.
        z_m: Drone height [m], world z.
        r_min_m: Smallest r consistent with the tension [m] (the run folded back).
        r_max_m: Largest r consistent with the tension [m] (the run straight).
        floor_contact: Part of the tether rests on the floor.
        floor_run_m: Length of tether lying on the floor [m]; 0 without contact.
    """

    r_m: FloatOrArray
    z_m: FloatOrArray
    r_min_m: FloatOrArray
    r_max_m: FloatOrArray
    floor_contact: BoolOrArray
    floor_run_m: FloatOrArray


def locate_with_floor(
    horizontal_n: npt.ArrayLike,
    vertical_n: npt.ArrayLike,
    weight_n_per_m: npt.ArrayLike,
    length_m: npt.ArrayLike,
    base_z_m: npt.ArrayLike,
    floor_z_m: npt.ArrayLike,
) -> FloorLocation:
    """Drone position from the tension, with a floor the slack tether can rest on (NOTES).

    Contact is decided by the free-hanging solution of :func:`locate`: if its lowest point
    lies below the floor, the tether touches down. The drone side then hangs from a touchdown
    point with zero slope, ``z − z_f = sqrt(a² + s2²) − a`` with horizontal reach
    ``a·asinh(s2/a)``; the base side hangs to the floor with length ``s_b`` from
    ``z_i − z_f = sqrt(a² + s_b²) − a``, i.e. ``s_b = sqrt(h_b² + 2a·h_b)``, reach
    ``a·asinh(s_b/a)``; the rest, ``L − s2 − s_b``, lies on the floor.

    Under any tension H > 0 a frictionless floor keeps that run straight and in line, so
    ``r = reach_d + run + reach_b``; the interval ``[max(0, reach_d + reach_b − run),
    reach_d + reach_b + run]`` covers a run folded on itself. At H = 0 exactly the run can lie
    anywhere in ``[0, run]``; the best value reported there is still the straight run (the
    interval's top), which keeps ``r_m`` continuous as H → 0 and matches the forward model at
    the boundary where the pile starts. Consumers that need to know should use the interval.

    Contact needs the free solution's lowest point between the ends (0 <= s2 <= L). A free
    solution whose lowest point is the drone itself (s2 < 0, the tether pulls the drone up)
    below the floor is inconsistent with a floor that holds the drone: z is clamped to the
    floor and r kept.

    Args:
        horizontal_n: Horizontal tension H on the drone [N], >= 0.
        vertical_n: Downward pull T_v of the tether on the drone [N].
        weight_n_per_m: Tether weight per length ω [N/m], > 0.
        length_m: Tether length L [m], > 0.
        base_z_m: Height of the base exit z_i [m], >= floor_z_m.
        floor_z_m: Height of the floor z_f [m]; -inf for no floor (then as :func:`locate`).

    Returns:
        A :class:`FloorLocation`; floats for scalar inputs, else arrays of the broadcast shape.

    Raises:
        CatenaryError: As :func:`locate`, or a base below the floor.
    """
    scalar = _all_scalars(horizontal_n, vertical_n, weight_n_per_m, length_m, base_z_m, floor_z_m)
    h_n, tv_n, omega, big_l, z_i = _checked_tension_inputs(
        horizontal_n, vertical_n, weight_n_per_m, length_m, base_z_m
    )
    z_f = np.broadcast_to(np.asarray(floor_z_m, dtype=np.float64), h_n.shape)
    _require(z_f, z_f < np.inf, "floor_z_m", "below +inf (-inf: no floor)")
    _require(z_i, z_i >= z_f, "base_z_m", f"at or above floor_z_m ({floor_z_m!r})")
    a = h_n / omega
    s2 = tv_n / omega
    r_free, z_free = locate_free(a, s2, big_l, z_i)

    # The tether can only rest on the floor if its lowest point lies between the ends
    # (0 <= s2 <= L) and below the floor. Otherwise the lowest point is an end: the base (at
    # or above the floor), or the drone, which the floor holds up (its z is clamped below).
    t = big_l - s2
    with np.errstate(invalid="ignore", divide="ignore"):
        sag = t * t / (np.hypot(a, t) + a)  # sqrt(a² + t²) − a: vertex depth below the base
    sag = np.where(np.isfinite(sag), sag, 0.0)
    contact = (s2 >= 0.0) & (t >= 0.0) & (z_i - sag < z_f)
    z_free = np.maximum(z_free, z_f)

    s2c = np.maximum(s2, 0.0)
    h_b = z_i - z_f
    s_b = np.sqrt(h_b * (h_b + 2.0 * a))
    run = np.maximum(big_l - s2c - s_b, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        lift = s2c * s2c / (np.hypot(a, s2c) + a)  # sqrt(a² + s2²) − a
    lift = np.where(np.isfinite(lift), lift, 0.0)
    reach = _a_asinh(a, s2c) + _a_asinh(a, s_b)
    r_max = reach + run
    r_min = np.maximum(reach - run, 0.0)

    r_m = np.where(contact, r_max, r_free)
    z_m = np.where(contact, z_f + lift, z_free)
    lo = np.where(contact, r_min, r_free)
    run_m = np.where(contact, run, 0.0)
    if scalar:
        return FloorLocation(
            float(r_m), float(z_m), float(lo), float(r_m), bool(contact), float(run_m)
        )
    return FloorLocation(r_m, z_m, lo, r_m.copy(), contact, run_m)


# ---------------------------------------------------------------------------------------------
# Forward model: the force of the tether on the drone


@dataclass(frozen=True, slots=True)
class TetherForce:
    """Force of the tether on the drone (forward model).

    Attributes:
        force_world_n: (3,) force on the drone, world frame [N] (read-only array).
        horizontal_n: H >= 0 [N], the magnitude of the horizontal part (eq:cat_T0).
        vertical_n: Downward pull on the drone T_v = −force_world_n[2] [N] (eq:cat_Tv).
        floor_contact: Part of the tether rests on the floor.
        floor_run_m: Length lying on the floor [m]; 0 without contact.
    """

    force_world_n: FloatArray
    horizontal_n: float
    vertical_n: float
    floor_contact: bool
    floor_run_m: float


def tether_force(
    base_world_m: npt.ArrayLike,
    drone_world_m: npt.ArrayLike,
    length_m: float,
    weight_n_per_m: float,
    floor_z_m: float = -math.inf,
) -> TetherForce:
    """Static force of an inextensible tether of given length on the drone.

    The free catenary through base and drone comes from :func:`solve` in the vertical plane
    through both. Its tension at the drone end has horizontal part ``H = ω·a`` (eq:cat_T0)
    and vertical part ``ω·σ_d``, ``σ_d = a·sinh((r − x0)/a)`` the signed arc length from the
    lowest point (eq:cat_Tv); the force on the drone is ``−ω·(a·û, σ_d)`` with ``û`` the
    horizontal unit vector from base to drone (NOTES "Tension along the tether"): it pulls
    toward the base, and down when σ_d > 0. With the drone straight above the base it is
    purely vertical.

    Floor contact (NOTES): if the free solution's lowest point is below the floor, the
    tether touches down and each side hangs from a zero-slope touchdown point; with a straight
    run on the floor ``a`` solves ``r = a·acosh(1 + h_d/a) + (L − s_d − s_b) + a·acosh(1 +
    h_b/a)``, ``s = sqrt(h² + 2a·h)``: Newton's method in a on [0, an upper bound from the
    small- and large-a asymptotes], monotone once left of the root since the residual is
    concave and increasing in a (a step past zero shrinks a instead). If even a → 0 leaves
    slack (``L − h_d − h_b >= r``), the tether piles up: H = 0 and T_v = ω·h_d.

    Args:
        base_world_m: (3,) base exit point, world frame [m].
        drone_world_m: (3,) drone tether attachment, world frame [m].
        length_m: Tether length [m], > 0.
        weight_n_per_m: Weight per length ω [N/m], > 0.
        floor_z_m: Floor height [m]; -inf for no floor. Both ends must be at or above it.

    Returns:
        The :class:`TetherForce`. An exactly taut tether (chord == length) carries unbounded
        tension: H = inf and the force is infinite along the chord (0 in the components the
        chord lacks, never NaN).

    Raises:
        TetherTooShortError: ``|drone − base| > length`` (the simulator's taut stop).
        CatenaryError: Non-finite positions, non-positive length or weight, an end below the
            floor.
    """
    bx, by, bz = _xyz(base_world_m, "base_world_m")
    px, py, pz = _xyz(drone_world_m, "drone_world_m")
    fx, fy, fz, h_n, tv_n, geom = _force(
        bx, by, bz, px, py, pz, length_m, weight_n_per_m, floor_z_m
    )
    force = np.array([fx, fy, fz])
    force.flags.writeable = False
    return TetherForce(force, h_n, tv_n, geom.floor_contact, geom.floor_run_m)


def tether_force_xyz(
    base_world_m: tuple[float, float, float],
    drone_world_m: tuple[float, float, float],
    length_m: float,
    weight_n_per_m: float,
    floor_z_m: float = -math.inf,
) -> tuple[float, float, float]:
    """:func:`tether_force`'s ``force_world_n`` for points given as three Python floats
    each: the same floats and the same errors, without the arrays (a per-message caller's
    form, :mod:`groundstation.follow`)."""
    bx, by, bz = base_world_m
    px, py, pz = drone_world_m
    if not all(map(math.isfinite, (bx, by, bz, px, py, pz))):
        raise CatenaryError(f"positions must be finite, got {base_world_m!r}, {drone_world_m!r}")
    fx, fy, fz, _, _, _ = _force(bx, by, bz, px, py, pz, length_m, weight_n_per_m, floor_z_m)
    return fx, fy, fz


def _force(
    bx: float,
    by: float,
    bz: float,
    px: float,
    py: float,
    pz: float,
    length_m: float,
    weight_n_per_m: float,
    floor_z_m: float,
) -> tuple[float, float, float, float, float, _Hang]:
    """:func:`tether_force` on finite floats: ``(fx, fy, fz, H, T_v, shape)``."""
    big_l, omega, floor = float(length_m), float(weight_n_per_m), float(floor_z_m)
    if not (0.0 < big_l < math.inf):
        raise CatenaryError(f"length_m must be finite and > 0, got {length_m!r}")
    if not (0.0 < omega < math.inf):
        raise CatenaryError(f"weight_n_per_m must be finite and > 0, got {weight_n_per_m!r}")
    if math.isnan(floor) or floor == math.inf or bz < floor or pz < floor:
        raise CatenaryError(
            f"base z {bz!r} m and drone z {pz!r} m must be at or above the floor {floor_z_m!r} m"
        )
    ex, ey = px - bx, py - by
    r = math.hypot(ex, ey)
    geom = _hang(r, bz, pz, big_l, floor)
    if r > 0.0:
        ux, uy = ex / r, ey / r
    else:
        ux = uy = 0.0
    h_n = omega * geom.a
    tv_n = omega * geom.sigma_drone
    return _times(-h_n, ux), _times(-h_n, uy), -tv_n, h_n, tv_n, geom


def _times(magnitude: float, component: float) -> float:
    # inf·0 is NaN; an infinite tension has no component where the chord has none.
    return magnitude * component if component != 0.0 else 0.0


def _xyz(point: npt.ArrayLike, name: str) -> tuple[float, float, float]:
    try:
        arr = np.asarray(point, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise CatenaryError(f"{name} must be 3 numbers, got {point!r}") from exc
    if arr.shape != (3,):
        raise CatenaryError(f"{name} must have shape (3,), got {point!r}")
    x, y, z = arr.tolist()
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        raise CatenaryError(f"{name} must be finite, got {point!r}")
    return x, y, z


@dataclass(frozen=True, slots=True)
class _Hang:
    """Shape of the tether in the vertical plane, base at x = 0 (internal)."""

    kind: str  # "free", "plumb", "touchdown", "pile", "taut"
    a: float  # catenary parameter [m]
    sigma_drone: float  # arc length from the (hanging) lowest point to the drone [m]
    floor_contact: bool
    floor_run_m: float
    u1: float = 0.0  # free: (0 − x0)/a
    s_base: float = 0.0  # touchdown/pile: hanging length on the base side [m]
    low_z: float = 0.0  # plumb: height of the lowest point [m]


def _hang(r: float, bz: float, pz: float, big_l: float, floor: float) -> _Hang:
    """Static shape of the tether from base (0, bz) to drone (r, pz), r >= 0."""
    if r == 0.0:
        low = 0.5 * (bz + pz - big_l)
        if big_l < abs(pz - bz):
            raise TetherTooShortError(
                big_l, abs(pz - bz), f" (vertical, base z {bz!r} m, drone z {pz!r} m)"
            )
        if low >= floor:
            return _Hang("plumb", 0.0, pz - low, False, 0.0, low_z=low)
        h_d, h_b = pz - floor, bz - floor
        return _Hang("pile", 0.0, h_d, True, max(big_l - h_d - h_b, 0.0), s_base=h_b)
    a, _, _, u1, xi = _solve_scalar(0.0, bz, r, pz, big_l)
    if a == math.inf:
        # Exactly taut: tension unbounded along the chord.
        return _Hang(
            "taut",
            math.inf,
            math.copysign(math.inf, pz - bz) if pz != bz else 0.0,
            False,
            0.0,
            u1=u1,
        )
    u2 = u1 + 2.0 * xi  # (r − x0)/a
    low = bz - 2.0 * _a_sinh_sq_half(a, u1) if u1 < 0.0 < u2 else min(bz, pz)
    if low >= floor:
        return _Hang("free", a, _a_sinh(a, u2), False, 0.0, u1=u1)
    h_d, h_b = pz - floor, bz - floor
    if big_l - h_d - h_b >= r:
        return _Hang("pile", 0.0, h_d, True, big_l - h_d - h_b, s_base=h_b)
    a = _touchdown_a(r, big_l, h_d, h_b)
    s_d = math.sqrt(h_d * (h_d + 2.0 * a))
    s_b = math.sqrt(h_b * (h_b + 2.0 * a))
    return _Hang("touchdown", a, s_d, True, max(big_l - s_d - s_b, 0.0), s_base=s_b)


def _a_sinh_sq_half(a: float, u: float) -> float:
    """a·sinh²(u/2) = (a·cosh(u) − a)/2: half the depth of the vertex below the point at u."""
    if abs(u) < 1400.0:
        sh = math.sinh(0.5 * u)
        return a * sh * sh
    return math.inf


def _hang_terms(a: float, h: float) -> tuple[float, float, float]:
    """One side hanging height h from a zero-slope touchdown: (s, reach − s, d(reach − s)/da).

    reach − s = a·asinh(S) − a·S with S = s/a = sqrt(ε(2 + ε)), ε = h/a; its derivative in a
    is asinh(S) − 2S/(1 + sqrt(1 + S²)) > 0, decreasing in a.
    """
    if h == 0.0:
        return 0.0, 0.0, 0.0
    s = math.sqrt(h * (h + 2.0 * a))
    big_s = s / a
    if big_s < 0.1:
        s2 = big_s * big_s
        c, dc = _ASINH_MINUS_S, _D_ASINH_MINUS_S
        phi = c[5]
        dphi = dc[5]
        for k in (4, 3, 2, 1, 0):
            phi = phi * s2 + c[k]
            dphi = dphi * s2 + dc[k]
        return s, s * s2 * phi, big_s * s2 * dphi
    # For a near underflow asinh(s/a) = ln(2s) − ln(a) to 1e-300, without overflowing s/a.
    asinh_s = math.asinh(big_s) if big_s < 1e150 else math.log(2.0 * s) - math.log(a)
    return s, a * asinh_s - s, asinh_s - 2.0 * big_s / (1.0 + math.hypot(1.0, big_s))


def _touchdown_a(r: float, big_l: float, h_d: float, h_b: float) -> float:
    """a > 0 with L − r + Σ (reach_i − s_i)(a) = 0, given L − h_d − h_b < r < L."""
    slack = big_l - r
    if slack <= 0.0:
        return math.inf
    f0 = slack - h_d - h_b  # value at a → 0, < 0
    # Two upper bounds on the root: the large-a asymptote reach − s ≈ −(h/3)·sqrt(2h/a)
    # and the small-a one reach − s ≈ −h + a·(ln(2h/a) − 1); both under-estimate F.
    k = math.sqrt(2.0) / 3.0 * (h_d * math.sqrt(h_d) + h_b * math.sqrt(h_b))
    a = (k / slack) ** 2
    a_small = -f0
    for _ in range(2):
        logs = sum(math.log(2.0 * h / a_small) - 1.0 for h in (h_d, h_b) if h > 0.0)
        if logs <= 0.0:  # the small-a form does not apply: keep the other bound
            a_small = math.inf
            break
        a_small = -f0 / logs
    a = min(a, a_small)
    # F is concave increasing in a: Newton from the right lands left of the root (or below
    # zero, then shrink), and from the left it climbs monotonically.
    for _ in range(100):
        s_d, phi_d, dphi_d = _hang_terms(a, h_d)
        s_b, phi_b, dphi_b = _hang_terms(a, h_b)
        f = slack + phi_d + phi_b
        if abs(f) <= 8.0 * _EPS * (big_l + s_d + s_b):
            break
        step = -f / (dphi_d + dphi_b)
        if step <= -a:
            a *= 0.01
            continue
        a += step
        if abs(step) <= 4.0 * _EPS * a:
            break
    return a


# ---------------------------------------------------------------------------------------------
# Points for drawing


def tether_points(
    base_world_m: npt.ArrayLike,
    drone_world_m: npt.ArrayLike,
    length_m: float,
    floor_z_m: float = -math.inf,
    n: int = 64,
) -> FloatArray:
    """World points along the tether from base to drone, evenly spaced in arc length.

    Every regime is drawn: free catenary, plumb line, touchdown with a straight floor run, a
    slack pile (drawn as a flat triangular detour on the floor, sideways to the base–drone
    direction, so its length shows), and a nearly taut or over-stretched tether as the straight
    segment (chord >= length·(1 − 1e-12); no exception here, this is for display).

    Args:
        base_world_m: (3,) base exit point, world frame [m].
        drone_world_m: (3,) drone end, world frame [m].
        length_m: Tether length [m], > 0.
        floor_z_m: Floor height [m]; -inf for no floor.
        n: Number of points, >= 2.

    Returns:
        (n, 3) float array, first row the base, last row the drone, never NaN.

    Raises:
        CatenaryError: Non-finite positions, non-positive length, n < 2, an end below the
            floor.
    """
    bx, by, bz = _xyz(base_world_m, "base_world_m")
    px, py, pz = _xyz(drone_world_m, "drone_world_m")
    big_l, floor = float(length_m), float(floor_z_m)
    if not (0.0 < big_l < math.inf):
        raise CatenaryError(f"length_m must be finite and > 0, got {length_m!r}")
    if n < 2:
        raise CatenaryError(f"n must be >= 2, got {n!r}")
    if math.isnan(floor) or floor == math.inf or bz < floor or pz < floor:
        raise CatenaryError(
            f"base z {bz!r} m and drone z {pz!r} m must be at or above the floor {floor_z_m!r} m"
        )
    base = np.array([bx, by, bz])
    drone = np.array([px, py, pz])
    ex, ey = px - bx, py - by
    r = math.hypot(ex, ey)
    frac = np.linspace(0.0, 1.0, n)
    if math.hypot(r, pz - bz) >= big_l * (1.0 - _DRAW_TAUT):
        return base + frac[:, None] * (drone - base)
    ux, uy = (ex / r, ey / r) if r > 0.0 else (1.0, 0.0)
    geom = _hang(r, bz, pz, big_l, floor)
    s = frac * big_l
    if geom.kind == "free":
        x, z = _free_profile(geom.a, geom.u1, bz, s)
        pts = _plane_to_world(base, ux, uy, x, z)
    elif geom.kind == "plumb":
        pts = _plane_to_world(base, ux, uy, np.zeros(n), _plumb_profile(bz, geom.low_z, s))
    elif geom.kind == "touchdown":
        x, z = _touchdown_profile(geom.a, geom.s_base, geom.floor_run_m, bz, floor, s)
        pts = _plane_to_world(base, ux, uy, x, z)
    else:  # pile
        pts = _pile_points(base, ux, uy, r, geom.s_base, geom.floor_run_m, floor, s)
    pts[0] = base
    pts[-1] = drone
    return pts


def _plane_to_world(
    base: FloatArray, ux: float, uy: float, x: FloatArray, z: FloatArray
) -> FloatArray:
    return np.column_stack((base[0] + x * ux, base[1] + x * uy, z))


def _free_profile(a: float, u1: float, bz: float, s: FloatArray) -> tuple[FloatArray, FloatArray]:
    # σ = σ1 + s from the lowest point; x − x1 = a·(asinh(σ/a) − u1);
    # z − z1 = sqrt(a² + σ²) − sqrt(a² + σ1²) = s·(σ + σ1)/(sum of roots).
    sigma1 = _a_sinh(a, u1)
    sigma = sigma1 + s
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        x = a * (np.arcsinh(sigma / a) - u1)
        z = bz + s * (sigma + sigma1) / (np.hypot(a, sigma) + math.hypot(a, sigma1))
    return np.where(np.isfinite(x), x, 0.0), np.where(np.isfinite(z), z, bz)


def _plumb_profile(bz: float, low: float, s: FloatArray) -> FloatArray:
    return np.where(s <= bz - low, bz - s, low + (s - (bz - low)))


def _touchdown_profile(
    a: float, s_b: float, run: float, bz: float, floor: float, s: FloatArray
) -> tuple[FloatArray, FloatArray]:
    reach_b = float(_a_asinh(np.asarray(a), np.asarray(s_b)))
    sigma = np.where(s < s_b, s - s_b, np.maximum(s - s_b - run, 0.0))  # from the touchdowns
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        hang_x = a * np.arcsinh(sigma / a)
        lift = sigma * sigma / (np.hypot(a, sigma) + a)
    hang_x = np.where(np.isfinite(hang_x), hang_x, 0.0)
    lift = np.where(np.isfinite(lift), lift, np.abs(sigma))
    flat = np.clip(s - s_b, 0.0, run)
    return reach_b + flat + hang_x, floor + lift


def _pile_points(
    base: FloatArray,
    ux: float,
    uy: float,
    r: float,
    h_b: float,
    run: float,
    floor: float,
    s: FloatArray,
) -> FloatArray:
    # Plumb down h_b, a run of length `run` >= r on the floor from below the base to below the
    # drone (a triangle bulging sideways when longer than r), plumb up to the drone.
    half = 0.5 * run
    bulge = math.sqrt(max(half * half - 0.25 * r * r, 0.0))
    nx, ny = -uy, ux
    f = np.clip(s - h_b, 0.0, run)  # distance along the floor run
    first = f <= half
    leg = np.where(first, f, run - f) / half if half > 0.0 else np.zeros_like(f)
    along = np.where(first, 0.5 * r * leg, r - 0.5 * r * leg)
    side = bulge * leg
    z = np.where(s < h_b, base[2] - s, np.where(s > h_b + run, floor + (s - h_b - run), floor))
    return np.column_stack((base[0] + along * ux + side * nx, base[1] + along * uy + side * ny, z))
