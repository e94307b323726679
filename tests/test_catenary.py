"""Tests of groundstation.catenary against a 50-digit mpmath reference and physical truth."""

from __future__ import annotations

import math
import subprocess
import sys

import mpmath as mp
import numpy as np
import numpy.typing as npt
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from groundstation import catenary
from groundstation.catenary import (
    Catenary,
    CatenaryError,
    FloorLocation,
    TetherForce,
    TetherTooShortError,
    locate,
    locate_with_floor,
    solve,
    tether_force,
    tether_points,
)

OMEGA_N_PER_M = 0.05
REF_DPS = 50


# ---------------------------------------------------------------------------------------------
# Reference: 50 significant digits, from the exact float inputs.


def mp_reference(x1: float, y1: float, x2: float, y2: float, length: float) -> dict[str, mp.mpf]:
    """a, x0 and the anchor data of the catenary, by findroot on sinh(ξ)/ξ = q at 50 digits.

    The 1D reduction of eq:sys2_eq1–5 is checked against the system itself in
    ``test_reference_satisfies_the_paper_system``.
    """
    with mp.workdps(REF_DPS):
        X1, Y1, X2, Y2, L = (mp.mpf(v) for v in (x1, y1, x2, y2, length))
        h = abs(X2 - X1)
        v = Y2 - Y1
        if h == 0:
            return {"a": mp.mpf(0), "x0": X1, "c": (Y1 + Y2 - L) / 2, "X1": X1, "Y1": Y1}
        q = mp.sqrt(L * L - v * v) / h
        lnq = mp.log(q)
        guess = mp.sqrt(6 * lnq) if q < 3 else mp.log(2 * q) + mp.log(mp.log(2 * q))
        xi = mp.findroot(lambda t: mp.log(mp.sinh(t) / t) - lnq, guess, tol=mp.mpf(10) ** -45)
        assert abs(mp.log(mp.sinh(xi) / xi) - lnq) <= mp.mpf(10) ** -40 * max(1, lnq)
        a = h / (2 * xi)
        x0 = (X1 + X2) / 2 - mp.sign(X2 - X1) * a * mp.atanh(v / L)
        return {"a": a, "x0": x0, "c": Y1 - a * mp.cosh((X1 - x0) / a), "X1": X1, "Y1": Y1}


def mp_curve(ref: dict[str, mp.mpf], x: float) -> mp.mpf:
    with mp.workdps(REF_DPS):
        a, x0, X1, Y1 = ref["a"], ref["x0"], ref["X1"], ref["Y1"]
        X = mp.mpf(x)
        return Y1 + 2 * a * mp.sinh((X + X1 - 2 * x0) / (2 * a)) * mp.sinh((X - X1) / (2 * a))


def arr(value: object) -> npt.NDArray[np.float64]:
    return np.asarray(value, dtype=np.float64)


def assert_matches_reference(
    cat: Catenary, case: tuple[float, ...], index: int | None = None
) -> None:
    x1, _, x2, _, length = case
    ref = mp_reference(*case)
    a = float(arr(cat.a) if index is None else arr(cat.a)[index])
    x0 = float(arr(cat.x0) if index is None else arr(cat.x0)[index])
    scale = max(1.0, length)
    assert math.isfinite(a) and math.isfinite(x0), (case, a, x0)
    assert abs(mp.mpf(a) / ref["a"] - 1) <= 1e-9, (case, a, ref["a"])
    assert abs(mp.mpf(x0) - ref["x0"]) <= 1e-9 * scale, (case, x0, ref["x0"])
    single = cat if index is None else _pick(cat, index)
    for frac in (0.0, 0.1, 0.37, 0.5, 0.81, 1.0):
        x = x1 + frac * (x2 - x1)
        y = single.y(x)
        assert abs(mp.mpf(y) - mp_curve(ref, x)) <= 1e-9 * scale, (case, frac, y)


def _pick(cat: Catenary, index: int) -> Catenary:
    fields = (cat.a, cat.x0, cat.c, cat.x1, cat.y1, cat.u1)
    a, x0, c, x1, y1, u1 = (float(arr(f)[index]) for f in fields)
    return Catenary(a, x0, c, x1, y1, u1)


def _case(x1: float, y1: float, h: float, v: float, ratio: float) -> tuple[float, ...]:
    """A case with span h (signed), rise v and length ≈ ratio·chord."""
    x2 = x1 + h
    y2 = y1 + v
    return (x1, y1, x2, y2, math.hypot(x2 - x1, y2 - y1) * ratio)


# ---------------------------------------------------------------------------------------------
# The reference itself


@pytest.mark.parametrize(
    "case",
    [
        (0.0, 0.754, 1.0, 1.0, 1.6),
        (1.0, 1.0, 0.0, 0.754, 1.6),  # leftward
        (-2.0, 3.0, -5.0, -1.0, 7.0),  # leftward, drone below
        (0.3, 0.1, 1.7, 0.1, 2.0),  # equal heights
        _case(0.1, 0.2, 3.0, 1.0, 1.0 + 1e-9),  # nearly taut
    ],
)
def test_reference_satisfies_the_paper_system(case: tuple[float, ...]) -> None:
    """The reference (a, x0, c) satisfies eq:sys2_eq1–5: this pins the sign of eq:cat6."""
    ref = mp_reference(*case)
    with mp.workdps(REF_DPS):
        a, x0, c = ref["a"], ref["x0"], ref["c"]
        X1, Y1, X2, Y2, L = (mp.mpf(v) for v in case)
        tol = mp.mpf(10) ** -35
        assert abs(a * mp.cosh((X1 - x0) / a) + c - Y1) < tol  # eq:sys2_eq1
        assert abs(a * mp.cosh((X2 - x0) / a) + c - Y2) < tol  # eq:sys2_eq2
        # eq:sys2_eq3–5 with signed arc lengths (the |·| of eq:cat_s1 when x0 is outside).
        arc = abs(a * (mp.sinh((X2 - x0) / a) - mp.sinh((X1 - x0) / a)))
        assert abs(arc - L) < tol


# ---------------------------------------------------------------------------------------------
# solve: accuracy in every regime


def _grid_cases() -> list[tuple[float, ...]]:
    rng = np.random.default_rng(20240611)
    cases: list[tuple[float, ...]] = []
    for excess in (1e-9, 3e-9, 1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2):  # nearly taut
        for h, v in ((1.0, 0.0), (1.0, 0.7), (15.0, 4.0), (0.05, 1.0), (-3.0, -2.0)):
            x1, y1 = (float(u) for u in rng.uniform(-3, 3, 2))
            cases.append(_case(x1, y1, h, v, 1 + excess))
    for ratio in (1.5, 3.0, 10.0, 100.0, 1e3, 1e4):  # slack
        for h, v in ((1.0, 0.3), (0.2, -1.0), (-2.0, 0.5), (1e-3, 0.0)):
            cases.append(_case(float(rng.uniform(-3, 3)), float(rng.uniform(-3, 3)), h, v, ratio))
    for h in (1e-100, 1e-50, 1e-20, 1e-12, 1e-9, 1e-6, 1e-3):  # near plumb
        for ratio in (1.0 + 1e-6, 1.01, 2.0):
            cases.append(_case(0.0, 0.754, h, 0.4, ratio))
            cases.append(_case(0.0, 0.754, -h, -0.4, ratio))
    cases += [
        (0.0, 0.754, 1.2, 1.0, 1.6),  # the paper's setup
        (0.0, 0.754, 0.5, 0.5, 1.6),
        (0.0, 0.754, 1.0, 1.2, 1.6),
        (0.3, 1.0, 0.3 + 1e-12, 1.0, 0.5),  # tiny span, equal heights
        (1e3, -1e3, 1e3 + 5.0, -1e3 + 5.0, 7.1),  # large offsets
    ]
    return cases


GRID = _grid_cases()


def test_solve_grid_matches_mpmath_scalar() -> None:
    for case in GRID:
        assert_matches_reference(solve(*case), case)


def test_solve_grid_matches_mpmath_vectorised() -> None:
    cols = [np.array(col) for col in zip(*GRID, strict=True)]
    cat = solve(*cols)
    assert isinstance(cat.a, np.ndarray) and cat.a.shape == (len(GRID),)
    for i, case in enumerate(GRID):
        assert_matches_reference(cat, case, i)


def test_scalar_and_vectorised_paths_agree() -> None:
    # Both are within ~1e-12 of the reference; they iterate differently (see the module).
    cols = [np.array(col) for col in zip(*GRID, strict=True)]
    cat = solve(*cols)
    for i, case in enumerate(GRID):
        one = solve(*case)
        assert one.a == pytest.approx(arr(cat.a)[i], rel=1e-11)
        assert one.x0 == pytest.approx(arr(cat.x0)[i], rel=1e-11, abs=1e-11 * max(1.0, case[4]))


def floats(lo: float, hi: float) -> st.SearchStrategy[float]:
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


@st.composite
def catenary_cases(draw: st.DrawFn) -> tuple[float, ...]:
    """The whole domain: offsets, spans of both signs, rises, L/chord from 1 + 1e-9 to 1e4."""
    x1 = draw(floats(-20.0, 20.0))
    y1 = draw(floats(-20.0, 20.0))
    h = draw(floats(1e-6, 20.0)) * draw(st.sampled_from((-1.0, 1.0)))
    v = draw(st.one_of(st.just(0.0), floats(-20.0, 20.0)))
    excess_log10 = draw(floats(-9.0, 4.0))
    case = _case(x1, y1, h, v, 1.0 + 10.0**excess_log10)
    x2, y2 = case[2], case[3]
    assume(x2 != x1)
    length = case[4]
    # Keep to the stated domain: a up to 1e5 (a grows like h/sqrt(excess)).
    assume(abs(x2 - x1) / math.sqrt(6.0 * max(10.0**excess_log10, 1e-300)) < 2e5)
    assume(length >= math.hypot(x2 - x1, y2 - y1))
    return case


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(catenary_cases())
def test_solve_matches_mpmath_everywhere(case: tuple[float, ...]) -> None:
    assert_matches_reference(solve(*case), case)


# Arrays of up to catenary._SMALL_ARRAY elements take the scalar path: tile to test the pass.
VECTOR_MIN = 32


def tile(*values: object) -> list[npt.NDArray[np.float64]]:
    """Each value repeated to VECTOR_MIN elements (element i keeps index i % len)."""
    arrays = [np.atleast_1d(arr(v)) for v in values]
    return [np.resize(a, VECTOR_MIN) for a in arrays]


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(st.lists(catenary_cases(), min_size=1, max_size=8))
def test_vectorised_solve_matches_mpmath_everywhere(cases: list[tuple[float, ...]]) -> None:
    reps = -(-VECTOR_MIN // len(cases))
    cols = [np.array(col) for col in zip(*(cases * reps), strict=True)]
    cat = solve(*cols)
    for i, case in enumerate(cases):
        assert_matches_reference(cat, case, i)


def test_scalar_start_table_is_within_its_stated_error() -> None:
    """The scalar path's polynomial start for ξ(ln q) (catenary._XI_START) is within 6e-7."""
    with mp.workdps(30):
        for y in np.geomspace(1e-3, catenary._XI_START_Y_MAX, 300):
            ref = mp.findroot(
                lambda t, y=y: mp.log(mp.sinh(t) / t) - mp.mpf(float(y)),
                math.sqrt(6 * y) if y < 1 else y + math.log(2 * y) + 1,
            )
            assert abs(catenary._xi_start_scalar(float(y)) / ref - 1) < 6e-7, y


def test_curve_passes_through_both_points_with_length() -> None:
    for case in GRID:
        x1, y1, x2, y2, length = case
        cat = solve(*case)
        assert cat.y(x1) == y1
        assert cat.y(x2) == pytest.approx(y2, abs=1e-9 * max(1.0, length))
        if cat.a > 0.0 and cat.a < math.inf:
            # Arc length from the slopes at both ends: a·|sinh(u2) − sinh(u1)|.
            u1 = float(arr(cat.u1))
            u2 = u1 + (x2 - x1) / float(cat.a)
            arc = abs(float(cat.a) * (math.sinh(u2) - math.sinh(u1)))
            assert arc == pytest.approx(length, rel=1e-9)


# ---------------------------------------------------------------------------------------------
# solve: regimes, degenerate cases and the documented results


def test_floats_in_python_floats_out() -> None:
    cat = solve(0.0, 0.754, 1.0, 1.0, 1.6)
    for value in (cat.a, cat.x0, cat.c, cat.x1, cat.y1, cat.u1, cat.y(0.5)):
        assert type(value) is float
    ints = solve(0, 0, 1, 0, 2)
    assert type(ints.a) is float
    numpy_scalars = solve(np.float64(0.0), 0.0, np.float64(1.0), 0.0, 2.0)
    assert type(numpy_scalars.a) is float


@pytest.mark.parametrize("shape", [(3, 4), (6, 5)])  # element by element; one pass
def test_arrays_broadcast(shape: tuple[int, int]) -> None:
    x2 = np.linspace(-1.0, 1.2, shape[0])[:, None]  # (rows, 1)
    length = np.linspace(1.6, 50.0, shape[1])  # (cols,)
    cat = solve(0.0, 0.754, x2, 1.0, length)
    for field in (cat.a, cat.x0, cat.c, cat.x1, cat.y1, cat.u1):
        assert isinstance(field, np.ndarray) and field.shape == shape
        assert field.dtype == np.float64
    for i in range(shape[0]):
        for j in range(shape[1]):
            one = solve(0.0, 0.754, float(x2[i, 0]), 1.0, float(length[j]))
            assert arr(cat.a)[i, j] == pytest.approx(one.a, rel=1e-11)
    y = cat.y(np.zeros(shape))
    assert isinstance(y, np.ndarray)
    np.testing.assert_allclose(y, 0.754, atol=1e-12)
    zero_d = solve(np.asarray(0.0), 0.0, 1.0, 0.0, 2.0)
    assert isinstance(zero_d.a, np.ndarray) and zero_d.a.shape == ()


def test_arrays_longer_than_a_chunk() -> None:
    rng = np.random.default_rng(7)
    n = 40_000
    x1 = rng.uniform(-1, 1, n)
    x2 = x1 + rng.uniform(0.1, 3, n) * rng.choice([-1.0, 1.0], n)
    y1 = rng.uniform(-1, 1, n)
    y2 = y1 + rng.uniform(-2, 2, n)
    length = np.hypot(x2 - x1, y2 - y1) * (1.0 + 10.0 ** rng.uniform(-9, 3, n))
    cat = solve(x1, y1, x2, y2, length)
    assert np.all(np.isfinite(cat.a)) and np.all(cat.a > 0)
    for i in rng.choice(n, 20, replace=False):
        one = solve(float(x1[i]), float(y1[i]), float(x2[i]), float(y2[i]), float(length[i]))
        assert arr(cat.a)[i] == pytest.approx(one.a, rel=1e-11)
    assert np.all(np.abs(cat.y(x2) - y2) <= 1e-9 * np.maximum(1.0, length))


def test_leftward_span_mirrors_rightward() -> None:
    right = solve(0.0, 0.754, 1.0, 1.0, 1.6)
    left = solve(0.0, 0.754, -1.0, 1.0, 1.6)
    assert left.a == pytest.approx(right.a, rel=1e-15)
    assert left.x0 == pytest.approx(-right.x0, rel=1e-15)
    assert left.y(-0.3) == pytest.approx(right.y(0.3), abs=1e-15)


def test_swapping_the_ends_gives_the_same_curve() -> None:
    for case in GRID[::3]:
        x1, y1, x2, y2, length = case
        fwd, back = solve(*case), solve(x2, y2, x1, y1, length)
        assert back.a == pytest.approx(fwd.a, rel=1e-12)
        assert back.x0 == pytest.approx(fwd.x0, rel=1e-12, abs=1e-9 * max(1.0, length))
        xm = 0.5 * (x1 + x2)
        assert back.y(xm) == pytest.approx(fwd.y(xm), abs=1e-9 * max(1.0, length))


def test_equal_heights_vertex_at_midpoint() -> None:
    for ratio in (1.0 + 1e-9, 1.001, 2.0, 1e3):
        cat = solve(0.3, 2.0, 1.7, 2.0, 1.4 * ratio)
        assert cat.x0 == pytest.approx(1.0, abs=1e-15)


def test_plumb_line_is_documented_degenerate() -> None:
    cat = solve(0.5, 0.0, 0.5, 1.0, 1.6)
    assert (cat.a, cat.x0, cat.c, cat.u1) == (0.0, 0.5, -0.30000000000000004, 0.0)
    assert cat.c == pytest.approx((0.0 + 1.0 - 1.6) / 2)
    assert cat.y(0.5) == cat.c
    assert cat.y(0.6) == math.inf
    taut_vertical = solve(0.5, 0.0, 0.5, 1.0, 1.0)
    assert taut_vertical.a == 0.0 and taut_vertical.c == 0.0
    for pair in ([0.5, 0.0], [0.5, 1.0]), tile([0.5, 0.0], [0.5, 1.0]):
        arrays = solve(np.array(pair[0]), 0.0, np.array(pair[1]), 1.0, 1.6)
        assert arr(arrays.a)[0] == 0.0 and arr(arrays.c)[0] == pytest.approx(-0.3)
        assert np.all(np.isfinite(arrays.a)) and np.all(np.isfinite(arrays.c))
        y = arrays.y(np.full(len(pair[0]), 0.5))
        assert isinstance(y, np.ndarray) and y[0] == pytest.approx(-0.3)
        assert np.isfinite(y[1])
    vertical = solve(*tile(0.5, 0.0, [0.5, 1.0], 1.0, [1.0, 1.5]))
    assert arr(vertical.a)[0] == 0.0 and arr(vertical.c)[0] == 0.0


def test_near_plumb_tends_to_plumb() -> None:
    plumb = solve(0.0, 0.754, 0.0, 1.0, 1.6)
    for h in (1e-3, 1e-6, 1e-9, 1e-12, 1e-100, 1e-300):
        cat = solve(0.0, 0.754, h, 1.0, 1.6)
        assert 0.0 < cat.a < 10 * h
        assert cat.a + cat.c == pytest.approx(plumb.c, abs=2 * h + 1e-12)
        assert np.isfinite(arr(cat.x0)) and np.isfinite(arr(cat.u1))
        many = solve(*tile(0.0, 0.754, [h, 0.7], 1.0, 1.6))
        assert arr(many.a)[0] == pytest.approx(cat.a, rel=1e-11)
        assert arr(many.c)[0] == pytest.approx(cat.c, abs=1e-12)
    tiniest = solve(*tile(0.0, 0.754, [5e-324, 0.7], 1.0, 1.6))
    assert arr(tiniest.a)[0] == 0.0 and arr(tiniest.c)[0] == pytest.approx(plumb.c)
    assert solve(0.0, 0.754, 5e-324, 1.0, 1.6).c == pytest.approx(plumb.c)


def test_exactly_taut_is_the_straight_line() -> None:
    cat = solve(0.0, 0.0, 3.0, 4.0, 5.0)
    assert cat.a == math.inf and cat.c == -math.inf and cat.x0 == -math.inf
    assert cat.y(1.5) == pytest.approx(2.0)
    level = solve(0.0, 1.0, 2.0, 1.0, 2.0)
    assert level.a == math.inf and level.x0 == 1.0
    assert level.y(0.7) == 1.0
    for cols in (
        [np.array(v) for v in ([3.0, 2.0], [4.0, 0.0], [5.0, 2.0])],
        tile([3.0, 2.0], [4.0, 0.0], [5.0, 2.0]),
    ):
        arrays = solve(0.0, 0.0, *cols)
        np.testing.assert_array_equal(arr(arrays.a)[:2], [math.inf, math.inf])
        np.testing.assert_array_equal(arr(arrays.x0)[:2], [-math.inf, 1.0])
        np.testing.assert_allclose(arr(arrays.y(np.resize([1.5, 1.0], cols[0].size)))[:2], [2, 0])


def test_nearly_taut_a_reaches_1e5_and_sag_is_tiny() -> None:
    cat = solve(0.0, 0.0, 20.0, 0.0, 20.0 * (1 + 1e-9))
    assert cat.a > 1e5
    sag = -cat.y(10.0)
    assert sag == pytest.approx(20.0 * math.sqrt(3e-9 / 8), rel=1e-3)


def test_hand_built_catenary_evaluates_from_its_vertex() -> None:
    cat = Catenary(a=2.0, x0=1.0, c=-1.0)
    assert cat.y(1.0) == 1.0
    assert cat.y(3.0) == pytest.approx(2.0 * math.cosh(1.0) - 1.0, rel=1e-15)
    y = cat.y(np.array([1.0, 3.0]))
    np.testing.assert_allclose(y, [1.0, 2.0 * math.cosh(1.0) - 1.0], rtol=1e-15)
    assert cat.y(1e6) == math.inf
    assert Catenary(2.0, 1.0, -1.0) == Catenary(2.0, 1.0, -1.0)


def test_catenary_is_frozen() -> None:
    cat = solve(0.0, 0.0, 1.0, 0.0, 2.0)
    with pytest.raises(AttributeError):
        cat.a = 3.0  # type: ignore[misc]
    assert cat == solve(0.0, 0.0, 1.0, 0.0, 2.0)


@settings(max_examples=200, deadline=None)
@given(
    floats(0.05, 5.0),
    floats(-3.0, 3.0),
    floats(1e-6, 10.0),
    floats(1.0 + 1e-6, 3.0),
)
def test_more_slack_sags_deeper(h: float, v: float, excess: float, grow: float) -> None:
    chord = math.hypot(h, v)
    tight = solve(0.0, 0.0, h, v, chord * (1 + excess))
    slack = solve(0.0, 0.0, h, v, chord * (1 + excess) * grow)
    assert slack.a < tight.a
    # The height at mid-span drops as the length grows.
    assert slack.y(0.5 * h) < tight.y(0.5 * h)


# ---------------------------------------------------------------------------------------------
# solve: errors


def test_too_short_raises_naming_length_and_chord() -> None:
    with pytest.raises(TetherTooShortError) as info:
        solve(0.0, 0.0, 3.0, 4.0, 4.9)
    assert info.value.length_m == 4.9 and info.value.chord_m == 5.0
    assert "4.9" in str(info.value) and "5.0" in str(info.value)
    assert isinstance(info.value, CatenaryError) and isinstance(info.value, ValueError)
    with pytest.raises(TetherTooShortError):
        solve(0.0, 0.0, 3.0, 4.0, 5.0 * (1 - 1e-15))
    with pytest.raises(TetherTooShortError):
        solve(0.0, 0.0, 0.0, 1.0, 0.5)  # plumb, too short


def test_too_short_in_small_arrays_names_the_index() -> None:
    with pytest.raises(TetherTooShortError, match="flat index 1") as info:
        solve(0.0, 0.0, np.array([1.0, 3.0]), 0.0, np.array([2.0, 1.0]))
    assert info.value.length_m == 1.0 and info.value.chord_m == 3.0


def test_too_short_in_arrays_names_the_index() -> None:
    length = np.full(50_000, 2.0)
    length[33_333] = 0.5
    with pytest.raises(TetherTooShortError) as info:
        solve(0.0, 0.0, 1.0, 0.0, length)
    assert "33333" in str(info.value) and info.value.length_m == 0.5 and info.value.chord_m == 1.0


@pytest.mark.parametrize(
    "case",
    [
        (math.nan, 0.0, 1.0, 0.0, 2.0),
        (0.0, math.inf, 1.0, 0.0, 2.0),
        (0.0, 0.0, 1.0, 0.0, math.inf),
        (0.0, 0.0, 1.0, 0.0, -2.0),
        (0.0, 0.0, 0.0, 0.0, -1.0),
    ],
)
def test_bad_inputs_raise_catenary_error(case: tuple[float, ...]) -> None:
    with pytest.raises(CatenaryError) as info:
        solve(*case)
    assert not isinstance(info.value, TetherTooShortError)
    with pytest.raises(CatenaryError):
        solve(*(np.array([0.0, v]) for v in case))
    with pytest.raises(CatenaryError, match="flat index 1"):
        solve(*tile(*([0.0, v] for v in case)))


def test_zero_length_between_coincident_points() -> None:
    cat = solve(1.0, 2.0, 1.0, 2.0, 0.0)
    assert (cat.a, cat.x0, cat.c) == (0.0, 1.0, 2.0)


# ---------------------------------------------------------------------------------------------
# locate


def test_locate_paper_initial_instant() -> None:
    """eq:in_instants: H = 0, T_v = 0 gives z = 0.754 − 1.6 = −0.846 (no floor)."""
    r, z = locate(0.0, 0.0, OMEGA_N_PER_M, 1.6, 0.754)
    assert (r, z) == (0.0, pytest.approx(-0.846, abs=1e-15))
    assert type(r) is float and type(z) is float


def test_locate_h_zero_limits() -> None:
    """eq:posfull_limr, eq:posfull_limz: r → 0, z → z_i + |s2| − |L − s2|."""
    for tv in (-0.02, 0.0, 0.03, 0.08, 0.1):
        s2 = tv / OMEGA_N_PER_M
        r, z = locate(0.0, tv, OMEGA_N_PER_M, 1.6, 0.754)
        assert r == 0.0
        assert z == pytest.approx(0.754 + abs(s2) - abs(1.6 - s2), abs=1e-15)
        r_small, z_small = locate(1e-300, tv, OMEGA_N_PER_M, 1.6, 0.754)
        assert r_small == pytest.approx(0.0, abs=1e-290)
        assert z_small == pytest.approx(z, abs=1e-15)
        # Continuity as H → 0.
        r_eps, z_eps = locate(1e-12, tv, OMEGA_N_PER_M, 1.6, 0.754)
        assert r_eps < 1e-8 and z_eps == pytest.approx(z, abs=1e-9)


def test_locate_arrays_and_broadcast() -> None:
    h = np.array([0.0, 0.01, 0.1])[:, None]
    tv = np.array([-0.01, 0.0, 0.05, 0.2])
    r, z = locate(h, tv, OMEGA_N_PER_M, 1.6, 0.754)
    assert isinstance(r, np.ndarray) and r.shape == (3, 4) and isinstance(z, np.ndarray)
    assert np.all(np.isfinite(r)) and np.all(np.isfinite(z))
    for i in range(3):
        for j in range(4):
            rr, zz = locate(float(h[i, 0]), float(tv[j]), OMEGA_N_PER_M, 1.6, 0.754)
            assert r[i, j] == rr and z[i, j] == zz


@pytest.mark.parametrize(
    ("args", "name"),
    [
        ((-0.1, 0.0, 0.05, 1.6), "horizontal_n"),
        ((math.nan, 0.0, 0.05, 1.6), "horizontal_n"),
        ((0.1, math.inf, 0.05, 1.6), "vertical_n"),
        ((0.1, 0.0, 0.0, 1.6), "weight_n_per_m"),
        ((0.1, 0.0, -0.05, 1.6), "weight_n_per_m"),
        ((0.1, 0.0, 0.05, 0.0), "length_m"),
        ((0.1, 0.0, 0.05, -1.0), "length_m"),
    ],
)
def test_locate_rejects_bad_inputs(args: tuple[float, ...], name: str) -> None:
    with pytest.raises(CatenaryError, match=name):
        locate(*args)
    with pytest.raises(CatenaryError, match="index"):
        locate(*(np.array([1.0, v]) if k == 0 else v for k, v in enumerate(args)))


def _solve_to_tension(x2: float, y2: float, length: float, base_z: float) -> tuple[float, float]:
    """H and T_v at the drone end of solve(0, base_z, x2, y2, L) (eq:cat_T0, eq:cat_Tv)."""
    cat = solve(0.0, base_z, x2, y2, length)
    a = float(cat.a)
    sigma = a * math.sinh(float(arr(cat.u1)) + x2 / a)  # a·sinh((x2 − x0)/a)
    return OMEGA_N_PER_M * a, OMEGA_N_PER_M * sigma


@settings(max_examples=300, deadline=None)
@given(
    floats(0.01, 5.0),
    floats(-3.0, 3.0),
    floats(-6.0, 1.0),
    floats(-2.0, 2.0),
)
def test_solve_locate_round_trip(r: float, dz: float, excess_log10: float, base_z: float) -> None:
    length = math.hypot(r, dz) * (1 + 10**excess_log10)
    h_n, tv_n = _solve_to_tension(r, base_z + dz, length, base_z)
    r_est, z_est = locate(h_n, tv_n, OMEGA_N_PER_M, length, base_z)
    # Conditioning: near taut, L − r is what carries the information.
    tol = 1e-9 * max(1.0, length) * (1 + 1e-6 / 10**excess_log10)
    assert r_est == pytest.approx(r, abs=tol)
    assert z_est == pytest.approx(base_z + dz, abs=tol)


def test_locate_plumb_round_trip() -> None:
    # Drone straight above the base: T_v = ω·(L + v)/2.
    for v in (-0.5, 0.0, 0.3, 1.5):
        r, z = locate(0.0, OMEGA_N_PER_M * (1.6 + v) / 2, OMEGA_N_PER_M, 1.6, 0.754)
        assert r == 0.0 and z == pytest.approx(0.754 + v, abs=1e-15)


# ---------------------------------------------------------------------------------------------
# Forward model


def test_tether_force_matches_solve_and_notes_direction() -> None:
    base = np.array([0.2, -0.1, 0.754])
    drone = np.array([1.0, 0.5, 1.2])
    tf = tether_force(base, drone, 1.6, OMEGA_N_PER_M)
    assert isinstance(tf, TetherForce)
    r = math.hypot(0.8, 0.6)
    h_n, tv_n = _solve_to_tension(r, 1.2, 1.6, 0.754)
    assert tf.horizontal_n == pytest.approx(h_n, rel=1e-13)
    assert tf.vertical_n == pytest.approx(tv_n, rel=1e-13)
    u = np.array([0.8, 0.6]) / r
    np.testing.assert_allclose(tf.force_world_n[:2], -h_n * u, rtol=1e-13)
    assert tf.force_world_n[2] == -tf.vertical_n
    assert tf.vertical_n > 0  # drone above the lowest point: pulled down
    assert not tf.floor_contact and tf.floor_run_m == 0.0
    assert not tf.force_world_n.flags.writeable


def test_tether_force_pulls_up_when_drone_hangs_below_the_vertex() -> None:
    tf = tether_force([0.0, 0.0, 1.0], [0.5, 0.0, 0.2], 1.0, OMEGA_N_PER_M)
    assert tf.vertical_n < 0 and tf.force_world_n[2] > 0
    assert tf.force_world_n[0] < 0  # toward the base


def test_tether_force_plumb_is_vertical() -> None:
    tf = tether_force([0.0, 0.0, 0.754], [0.0, 0.0, 1.3], 1.6, OMEGA_N_PER_M)
    assert tf.horizontal_n == 0.0
    np.testing.assert_array_equal(tf.force_world_n[:2], [0.0, 0.0])
    assert tf.vertical_n == pytest.approx(OMEGA_N_PER_M * (1.6 + 1.3 - 0.754) / 2)


def test_tether_force_vertical_takeoff_with_floor() -> None:
    """NOTES: base raised, drone straight above a point of the floor: T_v = ω·z."""
    for z in (0.0, 0.3, 0.45):  # the pile holds while L − z − z_i >= r = 0.36
        tf = tether_force([0.0, 0.0, 0.754], [0.3, 0.2, z], 1.6, OMEGA_N_PER_M, 0.0)
        assert tf.floor_contact and tf.horizontal_n == 0.0
        assert tf.vertical_n == pytest.approx(OMEGA_N_PER_M * z)
        assert tf.floor_run_m == pytest.approx(1.6 - 0.754 - z)


def test_tether_force_too_long_chord_raises() -> None:
    with pytest.raises(TetherTooShortError):
        tether_force([0, 0, 0], [1.0, 1.0, 1.0], 1.6, OMEGA_N_PER_M)
    with pytest.raises(TetherTooShortError):
        tether_force([0, 0, 0], [0.0, 0.0, 1.7], 1.6, OMEGA_N_PER_M)


def test_tether_force_exactly_taut_is_infinite_along_the_chord() -> None:
    tf = tether_force([0.0, 0.0, 0.0], [3.0, 0.0, 4.0], 5.0, OMEGA_N_PER_M)
    assert tf.horizontal_n == math.inf
    assert tf.force_world_n[0] == -math.inf and tf.force_world_n[1] == 0.0
    assert tf.force_world_n[2] == -math.inf
    assert not np.any(np.isnan(tf.force_world_n))


@pytest.mark.parametrize(
    ("base", "drone", "length", "floor"),
    [
        ([0, 0, 0], [1, 0, 1], 0.0, -math.inf),
        ([0, 0, 0], [1, 0, 1], math.nan, -math.inf),
        ([0, 0, 0], [1, 0, math.nan], 2.0, -math.inf),
        ([0, 0, 0], [1, 0], 2.0, -math.inf),
        ([0, 0, 0.5], [1, 0, -0.1], 2.0, 0.0),
        ([0, 0, -0.5], [1, 0, 0.1], 2.0, 0.0),
    ],
)
def test_tether_force_rejects_bad_inputs(
    base: list[float], drone: list[float], length: float, floor: float
) -> None:
    with pytest.raises(CatenaryError):
        tether_force(base, drone, length, OMEGA_N_PER_M, floor)


def _energy_over_omega(base: np.ndarray, drone: np.ndarray, length: float, floor: float) -> float:
    """Gravitational energy / ω of the static tether: ∫ z ds, from tether_points (Simpson)."""
    n = 8001
    z = tether_points(base, drone, length, floor, n=n)[:, 2]
    w = np.ones(n)
    w[1:-1:2] = 4.0
    w[2:-1:2] = 2.0
    return float(w @ z) * (length / (n - 1)) / 3.0


@pytest.mark.parametrize(
    ("drone", "length", "floor", "contact"),
    [
        ([1.0, 0.3, 1.1], 1.6, -math.inf, False),
        ([0.4, -0.6, 0.3], 1.6, -math.inf, False),  # drone below the base
        ([0.9, 0.6, 1.0], 1.6, 0.0, False),
        ([1.2, 0.0, 0.15], 1.6, 0.0, True),  # touchdown, straight run
        ([1.3, 0.5, 0.02], 1.6, 0.0, True),
        ([0.2, 0.3, 0.6], 2.5, 0.0, True),  # pile: no horizontal force
    ],
)
def test_force_is_minus_gradient_of_the_tether_energy(
    drone: list[float], length: float, floor: float, contact: bool
) -> None:
    """A static inextensible tether pulls its end along −∇E, E = ω·∫ z ds (virtual work)."""
    base = np.array([0.1, 0.2, 0.754])
    p = np.array(drone)
    tf = tether_force(base, p, length, OMEGA_N_PER_M, floor)
    assert tf.floor_contact == contact
    step = 1e-5
    grad = np.zeros(3)
    for k in range(3):
        e = np.zeros(3)
        e[k] = step
        grad[k] = (
            _energy_over_omega(base, p + e, length, floor)
            - _energy_over_omega(base, p - e, length, floor)
        ) / (2 * step)
    np.testing.assert_allclose(tf.force_world_n, -OMEGA_N_PER_M * grad, atol=2e-6)


def test_touchdown_solver_on_hard_cases() -> None:
    # Drone resting on a floor at 0.2 m: the pile starts at r* = L − h_b; taut at r_max.
    r_pile = 1.6 - (0.754 - 0.2)
    r_max = math.sqrt(1.6**2 - (0.754 - 0.2) ** 2)
    for r in (r_pile + 1e-12, r_pile + 1e-6, 0.5 * (r_pile + r_max), r_max - 1e-9):
        tf = tether_force([0.0, 0.0, 0.754], [r, 0.0, 0.2], 1.6, OMEGA_N_PER_M, 0.2)
        assert math.isfinite(tf.horizontal_n)
        loc = locate_with_floor(tf.horizontal_n, tf.vertical_n, OMEGA_N_PER_M, 1.6, 0.754, 0.2)
        assert loc.r_m == pytest.approx(r, abs=1e-6)


# ---------------------------------------------------------------------------------------------
# Floor contact: inverse and round trips


def test_locate_with_floor_without_contact_matches_locate() -> None:
    loc = locate_with_floor(0.02, 0.03, OMEGA_N_PER_M, 1.6, 0.754, 0.0)
    r, z = locate(0.02, 0.03, OMEGA_N_PER_M, 1.6, 0.754)
    assert isinstance(loc, FloorLocation)
    assert (loc.r_m, loc.z_m, loc.r_min_m, loc.r_max_m) == (r, z, r, r)
    assert loc.floor_contact is False and loc.floor_run_m == 0.0


def test_locate_with_floor_paper_initial_instant() -> None:
    """eq:in_instants with the floor: the drone rests on the floor, so does part of the tether."""
    loc = locate_with_floor(0.0, 0.0, OMEGA_N_PER_M, 1.6, 0.754, 0.0)
    assert loc.floor_contact is True
    assert loc.z_m == 0.0
    assert loc.floor_run_m == pytest.approx(1.6 - 0.754)
    assert (loc.r_min_m, loc.r_max_m, loc.r_m) == (0.0, loc.floor_run_m, loc.floor_run_m)


def test_locate_with_floor_arrays() -> None:
    h = np.array([0.0, 0.005, 0.02, 0.2])
    tv = np.array([0.0, 0.01, 0.03, 0.05])
    loc = locate_with_floor(h, tv, OMEGA_N_PER_M, 1.6, 0.754, 0.0)
    assert isinstance(loc.r_m, np.ndarray) and loc.r_m.shape == (4,)
    assert isinstance(loc.floor_contact, np.ndarray) and loc.floor_contact.dtype == np.bool_
    for i in range(4):
        one = locate_with_floor(float(h[i]), float(tv[i]), OMEGA_N_PER_M, 1.6, 0.754, 0.0)
        assert arr(loc.r_m)[i] == one.r_m and arr(loc.z_m)[i] == one.z_m
        assert loc.floor_contact[i] == one.floor_contact
    assert np.all(np.asarray(loc.r_min_m) <= np.asarray(loc.r_m))


def test_locate_with_floor_rejects_base_below_floor() -> None:
    with pytest.raises(CatenaryError, match="base_z_m"):
        locate_with_floor(0.1, 0.1, OMEGA_N_PER_M, 1.6, -0.1, 0.0)


@settings(max_examples=300, deadline=None)
@given(
    floats(0.0, 2.0),  # base height above the floor
    floats(0.0, 1.0),  # drone radial fraction of the reach
    floats(0.0, 2.5),  # drone height above the floor
    floats(0.2, 4.0),  # length
    floats(0.0, 6.283),  # azimuth
)
def test_tether_force_locate_with_floor_round_trip(
    hb: float, frac: float, hd: float, length: float, azimuth: float
) -> None:
    floor = 0.1
    base = np.array([0.3, -0.2, floor + hb])
    reach_sq = length * length - (hd - hb) ** 2
    assume(reach_sq > 1e-6)
    r = frac * math.sqrt(reach_sq) * (1 - 1e-9)
    drone = base + np.array([r * math.cos(azimuth), r * math.sin(azimuth), hd - hb])
    drone[2] = floor + hd
    tf = tether_force(base, drone, length, OMEGA_N_PER_M, floor)
    assert np.all(np.isfinite(tf.force_world_n))
    loc = locate_with_floor(tf.horizontal_n, tf.vertical_n, OMEGA_N_PER_M, length, base[2], floor)
    r_true = math.hypot(*(drone[:2] - base[:2]))
    tol = 1e-7 * max(1.0, length)
    assert loc.z_m == pytest.approx(drone[2], abs=tol)
    assert loc.r_min_m - tol <= r_true <= loc.r_max_m + tol
    if not tf.floor_contact:
        r_free, z_free = locate(tf.horizontal_n, tf.vertical_n, OMEGA_N_PER_M, length, base[2])
        assert loc.r_m == r_free and loc.z_m == max(z_free, floor)
        assert r_free == pytest.approx(r_true, abs=tol)
    elif tf.horizontal_n > 0.0:
        assert loc.floor_contact
        assert loc.r_m == pytest.approx(r_true, abs=tol)
        assert loc.floor_run_m == pytest.approx(tf.floor_run_m, abs=tol)
    else:
        assert loc.floor_contact and loc.r_min_m == 0.0


# ---------------------------------------------------------------------------------------------
# Points for drawing


def _polyline_length(points: np.ndarray) -> float:
    return float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))


@pytest.mark.parametrize(
    ("base", "drone", "length", "floor"),
    [
        ([0.0, 0.0, 0.754], [1.0, 0.5, 1.0], 1.6, -math.inf),  # free
        ([0.0, 0.0, 0.754], [-1.0, -0.5, 0.2], 1.6, -math.inf),  # free, drone low
        ([0.0, 0.0, 0.754], [0.0, 0.0, 1.2], 1.6, -math.inf),  # plumb
        ([0.0, 0.0, 0.754], [0.0, 0.0, 0.1], 1.6, 0.0),  # plumb onto the floor (pile)
        ([0.0, 0.0, 0.754], [1.3, 0.2, 0.1], 1.6, 0.0),  # touchdown
        ([0.0, 0.0, 0.754], [0.3, 0.2, 0.2], 2.6, 0.0),  # pile with a detour
        ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], 2.0, 0.0),  # both on the floor
        ([0.0, 0.0, 0.754], [1.0, 0.0, 1.0], math.hypot(1.0, 0.246) * (1 + 1e-9), -math.inf),
        ([0.0, 0.0, 0.754], [1e-9, 0.0, 1.0], 1.6, -math.inf),  # near plumb
    ],
)
def test_tether_points_every_regime(
    base: list[float], drone: list[float], length: float, floor: float
) -> None:
    pts = tether_points(base, drone, length, floor, n=4001)
    assert pts.shape == (4001, 3) and np.all(np.isfinite(pts))
    np.testing.assert_array_equal(pts[0], base)
    np.testing.assert_array_equal(pts[-1], drone)
    assert np.all(pts[:, 2] >= floor - 1e-12)
    # The polyline cuts the corners of plumb lines and piles by about one spacing.
    assert _polyline_length(pts) == pytest.approx(length, abs=2.5 * length / 4000)
    coarse = tether_points(base, drone, length, floor)
    assert coarse.shape == (64, 3) and np.all(np.isfinite(coarse))


def test_tether_points_taut_or_overstretched_is_straight() -> None:
    for length in (math.sqrt(2.0) * (1 - 1e-13), 1.0):
        pts = tether_points([0, 0, 0], [1.0, 0.0, 1.0], length, n=5)
        np.testing.assert_allclose(pts, [[k / 4, 0, k / 4] for k in range(5)], atol=1e-15)


def test_tether_points_free_lies_on_the_solved_curve() -> None:
    pts = tether_points([0.0, 0.0, 0.754], [0.6, 0.8, 1.0], 1.6, n=33)
    cat = solve(0.0, 0.754, 1.0, 1.0, 1.6)
    r = np.hypot(pts[:, 0], pts[:, 1])
    np.testing.assert_allclose(pts[:, 2], cat.y(r), atol=1e-12)


def test_tether_points_rejects_bad_inputs() -> None:
    with pytest.raises(CatenaryError):
        tether_points([0, 0, 0], [1, 0, 0], 2.0, n=1)
    with pytest.raises(CatenaryError):
        tether_points([0, 0, 0], [1, 0, -1], 2.0, floor_z_m=0.0)


# ---------------------------------------------------------------------------------------------
# Purity


def test_import_pulls_no_io_dependencies() -> None:
    code = (
        "import sys, groundstation.catenary\n"
        "bad = [m for m in ('zenoh', 'viser', 'pydantic') if m in sys.modules]\n"
        "assert not bad, bad\n"
        "print('ok')\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=False
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"


def test_public_names() -> None:
    for name in catenary.__all__:
        assert hasattr(catenary, name)


def test_benchmark_alternatives_behave_as_documented() -> None:
    """The paper's recipe and fsolve in benchmarks/ agree on an easy case; the recipe as
    written fails on a leftward span."""
    from benchmarks.bench_catenary import fsolve_solve, newton_baseline, paper_recipe_solve

    case = (0.0, 0.754, 1.0, 1.0, 1.6)
    ours = solve(*case)
    for other in (paper_recipe_solve(*case), fsolve_solve(*case)):
        assert other.a == pytest.approx(ours.a, rel=1e-9)
        assert other.x0 == pytest.approx(ours.x0, abs=1e-9)
        assert other.y(0.5) == pytest.approx(ours.y(0.5), abs=1e-9)
    with pytest.raises(ValueError):
        paper_recipe_solve(1.0, 1.0, 0.0, 0.754, 1.6)
    a, x0, _ = newton_baseline(*(np.array([v]) for v in case))
    assert a[0] == pytest.approx(ours.a, rel=1e-9) and x0[0] == pytest.approx(ours.x0, abs=1e-9)
