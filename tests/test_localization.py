"""Tests of groundstation.localization against catenary truth."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.typing import ArrayLike

from groundstation.catenary import solve, tether_force
from groundstation.localization import (
    PLUMB_K,
    AngleObservation,
    LocalizationFailure,
    PositionEstimate,
    localize,
    localize_batch,
    try_localize,
    try_localize_batch,
)

OMEGA_N_PER_M = 0.05
LENGTH_M = 1.6
BASE_M = np.array([0.0, 0.0, 0.754])
FLOOR_M = 0.0
# The paper's hovering flights (sec. Position estimation), m.
PAPER_SPOTS = [
    (1.2, 0.0, 1.0),
    (1.0, -0.3, 1.0),
    (1.0, 0.0, 1.2),
    (1.0, -0.3, 0.5),
    (0.5, -0.6, 1.0),
    (0.9, 0.6, 1.0),
]
FILTER_COV_N2 = np.eye(3) * (0.5e-3) ** 2  # a converged tension filter, about 0.5 mN/axis


def truth_tension(
    drone_m: np.ndarray | tuple[float, float, float],
    base_m: np.ndarray = BASE_M,
    length_m: float = LENGTH_M,
    floor_z_m: float = FLOOR_M,
) -> tuple[np.ndarray, bool]:
    tf = tether_force(np.asarray(base_m), np.asarray(drone_m), length_m, OMEGA_N_PER_M, floor_z_m)
    return np.asarray(tf.force_world_n, dtype=float), bool(tf.floor_contact)


def estimate(*args: object, **kwargs: object) -> PositionEstimate:
    out = try_localize(*args, **kwargs)  # type: ignore[arg-type]
    assert isinstance(out, PositionEstimate), out
    return out


def test_import_does_not_pull_io_libraries() -> None:
    code = (
        "import sys, groundstation.localization\n"
        "bad = [m for m in ('zenoh', 'viser') if m in sys.modules]\n"
        "assert not bad, bad\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.parametrize("spot", PAPER_SPOTS)
@pytest.mark.parametrize("cov", [np.zeros((3, 3)), FILTER_COV_N2], ids=["exact", "noisy-cov"])
def test_paper_hover_spots_recovered(spot: tuple[float, float, float], cov: np.ndarray) -> None:
    drone = np.array(spot)
    T, contact = truth_tension(drone)
    est = estimate(T, cov, OMEGA_N_PER_M, LENGTH_M, BASE_M, FLOOR_M)
    assert est.azimuth_determined and est.azimuth_rad is not None
    assert est.azimuth_rad == pytest.approx(math.atan2(drone[1], drone[0]), abs=1e-9)
    assert est.floor_contact == contact
    r_true = math.hypot(drone[0] - BASE_M[0], drone[1] - BASE_M[1])
    lo, hi = est.radial_interval_m
    assert lo - 1e-9 <= r_true <= hi + 1e-9
    if not contact:
        np.testing.assert_allclose(est.position_world_m, drone, rtol=0, atol=1e-6)
        assert est.radial_m == pytest.approx(r_true, abs=1e-6)
        assert est.case == "free"
    else:
        assert est.position_world_m[2] == pytest.approx(drone[2], abs=1e-6)
    assert np.all(np.isfinite(est.std_world_m)) and np.all(est.std_world_m >= 0.0)
    if not cov.any():
        np.testing.assert_allclose(est.std_world_m, 0.0, atol=1e-12)
    # Same spot without a floor: the free-hanging formula.
    if not contact:
        free = estimate(T, cov, OMEGA_N_PER_M, LENGTH_M, BASE_M)
        np.testing.assert_allclose(free.position_world_m, drone, rtol=0, atol=1e-6)


@pytest.mark.parametrize("spot", [PAPER_SPOTS[0], PAPER_SPOTS[3], PAPER_SPOTS[4]])
def test_std_is_calibrated_monte_carlo(spot: tuple[float, float, float]) -> None:
    """Tension noise of the reported covariance gives positions within 1 sigma ~68 %."""
    rng = np.random.default_rng(7)
    drone = np.array(spot)
    T, _ = truth_tension(drone)
    cov = np.diag([0.8e-3, 0.5e-3, 0.6e-3]) ** 2
    ref = estimate(T, cov, OMEGA_N_PER_M, LENGTH_M, BASE_M, FLOOR_M)
    samples = rng.multivariate_normal(T, cov, size=600)
    pos = []
    for s in samples:
        e = localize(s, cov, OMEGA_N_PER_M, LENGTH_M, BASE_M, FLOOR_M)
        assert e is not None and e.azimuth_determined
        pos.append(e.position_world_m)
    err = np.array(pos) - drone
    within = np.mean(np.abs(err) <= ref.std_world_m, axis=0)
    assert np.all((within > 0.55) & (within < 0.80)), within
    # The spread itself matches the reported std within 20 %.
    np.testing.assert_allclose(err.std(axis=0), ref.std_world_m, rtol=0.2)


@pytest.mark.parametrize("height_m", [0.3, 1.3])
def test_plumb_tether_leaves_azimuth_undetermined(height_m: float) -> None:
    base = np.array([0.0, 0.0, 0.0])
    drone = np.array([0.0, 0.0, height_m])
    T, _ = truth_tension(drone, base_m=base)
    assert T[2] == pytest.approx(-OMEGA_N_PER_M * height_m, rel=1e-6)  # T_v = omega z
    est = estimate(T, FILTER_COV_N2, OMEGA_N_PER_M, LENGTH_M, base, FLOOR_M)
    assert not est.azimuth_determined and est.azimuth_rad is None
    assert est.case == "plumb" and est.azimuth_source == "none"
    # Straight above the base (radial_m is the catenary's r: the straight run on the floor
    # the floor model assumes, inside the interval below).
    np.testing.assert_allclose(est.position_world_m, drone, atol=1e-6)
    lo, hi = est.radial_interval_m
    assert lo == 0.0
    # The horizontal std at least covers the radius reachable at H = k sigma_H
    # (which includes the tether lying on the floor: L - z of it).
    assert hi >= LENGTH_M - height_m - 1e-6
    assert est.std_world_m[0] >= hi and est.std_world_m[1] >= hi
    assert est.std_world_m[2] < 0.05


def test_plumb_threshold_uses_k_sigma_and_the_position_is_continuous() -> None:
    sigma_h = 1e-3
    cov = np.diag([sigma_h**2, sigma_h**2, 1e-6])
    below = estimate([PLUMB_K * sigma_h * 0.9, 0.0, -0.05], cov, OMEGA_N_PER_M, LENGTH_M, BASE_M)
    above = estimate([PLUMB_K * sigma_h * 1.001, 0.0, -0.05], cov, OMEGA_N_PER_M, LENGTH_M, BASE_M)
    assert not below.azimuth_determined
    assert above.azimuth_determined
    assert above.azimuth_rad == pytest.approx(math.pi)  # pull +x: drone on the -x side
    # No jump at the threshold (the old rule put the drone at the base's xy just below it
    # and ~0.2 m away just above): a sweep of H moves the position by at most what r
    # itself moves, and it goes from the base's xy (H = 0) to r u (H >> sigma_H).
    hs = np.linspace(0.0, 10.0 * PLUMB_K * sigma_h, 400)
    xs, rs = [], []
    for h in hs:
        e = estimate([h, 0.0, -0.05], cov, OMEGA_N_PER_M, LENGTH_M, BASE_M)
        assert e.position_world_m[1] == pytest.approx(0.0, abs=1e-12)
        xs.append(float(e.position_world_m[0]))
        rs.append(e.radial_m)
    steps = np.abs(np.diff(xs))
    assert steps.max() <= np.abs(np.diff(rs)).max() + 1e-9, steps.max()
    assert xs[0] == pytest.approx(BASE_M[0], abs=1e-12)
    assert xs[-1] == pytest.approx(BASE_M[0] - rs[-1], abs=1e-9)
    # Undetermined, the horizontal std still covers the radius reachable at H = k sigma_H.
    at_zero = estimate([0.0, 0.0, -0.05], cov, OMEGA_N_PER_M, LENGTH_M, BASE_M)
    reach = estimate(
        [PLUMB_K * sigma_h, 0.0, -0.05], np.zeros((3, 3)), OMEGA_N_PER_M, LENGTH_M, BASE_M
    )
    assert at_zero.std_world_m[0] >= reach.radial_m - 1e-9
    assert at_zero.radial_interval_m == (0.0, pytest.approx(reach.radial_m, rel=1e-9))


def test_floor_contact_interval_contains_truth() -> None:
    base = np.array([0.0, 0.0, 0.2])
    for drone in ([0.5, 0.0, 0.3], [0.3, 0.4, 0.25], [-0.6, 0.2, 0.5]):
        d = np.array(drone)
        T, contact = truth_tension(d, base_m=base)
        assert contact
        est = estimate(T, FILTER_COV_N2, OMEGA_N_PER_M, LENGTH_M, base, FLOOR_M)
        assert est.floor_contact and est.floor_run_m > 0.0
        r_true = math.hypot(d[0] - base[0], d[1] - base[1])
        lo, hi = est.radial_interval_m
        assert lo - 1e-6 <= r_true <= hi + 1e-6, (lo, r_true, hi)
        assert est.position_world_m[2] == pytest.approx(d[2], abs=1e-6)
        # The horizontal 1-sigma extent covers the interval around the best value.
        u = (d[:2] - base[:2]) / r_true
        radial_std = math.sqrt(float(u @ est.cov_world_m2[:2, :2] @ u))
        assert radial_std >= max(est.radial_m - lo, hi - est.radial_m) - 1e-9


def test_no_estimate_and_bad_inputs() -> None:
    assert localize(None, FILTER_COV_N2, OMEGA_N_PER_M, LENGTH_M, BASE_M) is None
    cases: list[tuple[list[float], np.ndarray, float, float, ArrayLike, str]] = [
        ([math.nan, 0.0, -0.05], FILTER_COV_N2, OMEGA_N_PER_M, LENGTH_M, BASE_M, "tension"),
        ([0.01, 0.0, -0.05], np.full((3, 3), math.inf), OMEGA_N_PER_M, LENGTH_M, BASE_M, "cov"),
        ([0.01, 0.0, -0.05], FILTER_COV_N2, 0.0, LENGTH_M, BASE_M, "weight"),
        ([0.01, 0.0, -0.05], FILTER_COV_N2, OMEGA_N_PER_M, -1.0, BASE_M, "length"),
        ([0.01, 0.0, -0.05], FILTER_COV_N2, OMEGA_N_PER_M, LENGTH_M, [0, math.nan, 0], "base"),
    ]
    for T, cov, w, L, b, word in cases:
        out = try_localize(T, cov, w, L, b)
        assert isinstance(out, LocalizationFailure) and word in out.reason
        assert localize(T, cov, w, L, b) is None
    below = try_localize([0.01, 0.0, -0.05], FILTER_COV_N2, 0.05, 1.6, [0, 0, -1.0], 0.0)
    assert isinstance(below, LocalizationFailure) and "floor" in below.reason


finite_n = st.floats(-2.0, 2.0, allow_nan=False)


@given(
    T=st.tuples(finite_n, finite_n, finite_n),
    sig=st.tuples(*[st.floats(0.0, 0.1)] * 3),
    length=st.floats(0.01, 10.0),
    omega=st.floats(1e-4, 1.0),
    base_z=st.floats(-1.0, 2.0),
    floor=st.one_of(st.just(-math.inf), st.floats(-2.0, 2.0)),
)
@settings(max_examples=300, deadline=None)
def test_property_never_nan(
    T: tuple[float, float, float],
    sig: tuple[float, float, float],
    length: float,
    omega: float,
    base_z: float,
    floor: float,
) -> None:
    out = try_localize(np.array(T), np.diag(sig) ** 2, omega, length, [0.3, -0.2, base_z], floor)
    # Every input here is valid except a base below the floor: that, and only that, fails
    # (a test that accepted any failure could not fail).
    if base_z < floor:
        assert isinstance(out, LocalizationFailure) and "below the floor" in out.reason
        return
    assert isinstance(out, PositionEstimate), out
    assert np.all(np.isfinite(out.position_world_m))
    assert np.all(np.isfinite(out.std_world_m)) and np.all(out.std_world_m >= 0.0)
    assert np.all(np.isfinite(out.cov_world_m2))
    assert math.isfinite(out.radial_m) and out.radial_m >= 0.0
    lo, hi = out.radial_interval_m
    assert math.isfinite(lo) and math.isfinite(hi) and lo <= hi + 1e-9
    assert out.azimuth_determined == (out.azimuth_rad is not None)


# ---------------------------------------------------------------- every azimuth source


def exit_elevation(drone: np.ndarray, base: np.ndarray = BASE_M) -> float:
    """The tether's slope where it leaves the base, from the catenary through both ends
    (catenary.solve, not the localization's own formula)."""
    r = math.hypot(drone[0] - base[0], drone[1] - base[1])
    cat = solve(0.0, base[2], r, drone[2], LENGTH_M)
    return math.atan(math.sinh((0.0 - cat.x0) / cat.a))


@pytest.mark.parametrize("spot", PAPER_SPOTS)
def test_exact_exit_elevation_is_consistent_with_the_tension(
    spot: tuple[float, float, float],
) -> None:
    drone = np.array(spot)
    T, contact = truth_tension(drone)
    if contact:
        pytest.skip("the elevation is fused only while the tether hangs free")
    theta = AngleObservation(exit_elevation(drone), 0.01)
    est = estimate(T, FILTER_COV_N2, OMEGA_N_PER_M, LENGTH_M, BASE_M, FLOOR_M, exit_elevation=theta)
    assert est.elevation_used
    np.testing.assert_allclose(est.position_world_m, drone, atol=1e-6)
    # The elevation adds information: the radial/vertical std can only shrink.
    alone = estimate(T, FILTER_COV_N2, OMEGA_N_PER_M, LENGTH_M, BASE_M, FLOOR_M)
    assert est.std_world_m[2] <= alone.std_world_m[2] + 1e-12


def test_exit_elevation_corrects_a_biased_tension() -> None:
    """A 3 mN thrust error (1 % of the weight) moves the tension-only position by 10 cm; an
    exit elevation accurate to 0.01 rad pulls the estimate back toward the truth (the
    tension's covariance says what it knows: 3 mN vertically)."""
    drone = np.array(PAPER_SPOTS[0])
    T, _ = truth_tension(drone)
    biased = T + np.array([0.0, 0.0, 0.003])
    cov = np.diag([1e-3, 1e-3, 3e-3]) ** 2
    alone = estimate(biased, cov, OMEGA_N_PER_M, LENGTH_M, BASE_M, FLOOR_M)
    theta = AngleObservation(exit_elevation(drone), 0.01)
    fused = estimate(biased, cov, OMEGA_N_PER_M, LENGTH_M, BASE_M, FLOOR_M, exit_elevation=theta)
    err_alone = float(np.linalg.norm(alone.position_world_m - drone))
    err_fused = float(np.linalg.norm(fused.position_world_m - drone))
    assert err_alone > 0.03
    assert err_fused < 0.5 * err_alone, (err_alone, err_fused)


def test_azimuth_sources_modes_and_fusion() -> None:
    drone = np.array([0.5, -0.6, 1.0])
    beta_true = math.atan2(drone[1], drone[0])
    T, _ = truth_tension(drone)
    cov = np.eye(3) * (1e-3) ** 2
    # The tension's own direction, rotated by a sideways error of 2 mN (H = 8.9 mN: 13 deg).
    u = np.array([-T[1], T[0], 0.0]) / math.hypot(T[0], T[1])
    bent = T + 0.002 * u
    args = (bent, cov, OMEGA_N_PER_M, LENGTH_M, BASE_M, FLOOR_M)
    reel = AngleObservation(beta_true, 0.01)
    tension_only = estimate(*args, azimuth="tension", exit_azimuth=reel)
    assert tension_only.azimuth_source == "tension"
    assert abs(tension_only.azimuth_rad - beta_true) > math.radians(10)  # type: ignore[operator]
    reel_only = estimate(*args, azimuth="reel", exit_azimuth=reel)
    assert reel_only.azimuth_source == "reel"
    assert reel_only.azimuth_rad == pytest.approx(beta_true, abs=1e-12)
    auto = estimate(*args, exit_azimuth=reel)
    assert auto.azimuth_source == "reel"  # the most certain one
    # Inverse-variance weights: between the two, close to the reel's.
    assert auto.azimuth_std_rad < min(reel.std_rad, tension_only.azimuth_std_rad)
    assert abs(auto.azimuth_rad - beta_true) < 0.1 * abs(  # type: ignore[operator]
        tension_only.azimuth_rad - beta_true  # type: ignore[operator]
    )
    assert np.linalg.norm(auto.position_world_m[:2] - drone[:2]) < 0.02
    # mocap: the paper's method, beta from position_m.
    mocap = estimate(*args, azimuth="mocap", mocap_world_m=drone + 0.001)
    assert mocap.azimuth_source == "mocap"
    assert mocap.azimuth_rad == pytest.approx(beta_true, abs=0.005)
    # A source asked for but absent: the azimuth is undetermined, the position above the base.
    none = estimate(*args, azimuth="reel")
    assert none.azimuth_source == "none" and not none.azimuth_determined
    np.testing.assert_allclose(none.position_world_m[:2], BASE_M[:2], atol=1e-12)
    bad = try_localize(*args, azimuth="compass")  # type: ignore[arg-type]
    assert isinstance(bad, LocalizationFailure) and "azimuth" in bad.reason


def test_reel_azimuth_keeps_a_plumb_tether_determined_and_continuous() -> None:
    """Near plumb the tension's direction is noise; the reel's exit azimuth still knows it."""
    reel = AngleObservation(math.radians(40.0), 0.02)
    xs = []
    for h in np.linspace(0.0, 0.01, 200):
        e = estimate([-h, 0.0, -0.05], FILTER_COV_N2, OMEGA_N_PER_M, LENGTH_M, BASE_M,
                     azimuth="reel", exit_azimuth=reel)  # fmt: skip
        assert e.azimuth_determined
        assert e.azimuth_rad == pytest.approx(reel.value_rad)
        xs.append(e.position_world_m[:2])
    steps = np.linalg.norm(np.diff(np.array(xs), axis=0), axis=1)
    assert steps.max() < 0.02


# ---------------------------------------------------------------- the batch


def _batch_cases(seed: int, n: int) -> dict[str, object]:
    """n cases of every kind: free, near plumb, plumb, exactly plumb, on the floor, near taut,
    singular and anisotropic covariances, reel azimuths and elevations, non-finite input."""
    rng = np.random.default_rng(seed)
    T = np.empty((n, 3))
    C = np.empty((n, 3, 3))
    for i in range(n):
        kind = i % 6
        h = {0: 0.03, 1: 0.002, 2: 1e-4, 3: 0.0, 4: 0.01, 5: 0.3}[kind] * rng.uniform(0.2, 1.5)
        ang = rng.uniform(-math.pi, math.pi)
        tv = {4: rng.uniform(-0.01, 0.01), 5: rng.uniform(0.05, 0.2)}.get(
            kind, rng.uniform(-0.02, 0.12)
        )
        T[i] = [h * math.cos(ang), h * math.sin(ang), -tv]
        A = rng.normal(0.0, 1e-3 * rng.uniform(0.1, 3.0), (3, 3))
        C[i] = A @ A.T + np.diag(rng.uniform(1e-8, 1e-6, 3))
        if i % 17 == 0:
            C[i] = np.zeros((3, 3))  # singular: the eigen square root
        if i % 29 == 0:
            T[i, int(rng.integers(3))] = math.nan  # a failure, named
    lengths = rng.uniform(0.5, 2.5, n)
    weights = rng.choice([0.05, 0.055], n)
    base = np.column_stack(
        [rng.uniform(-0.2, 0.2, n), rng.uniform(-0.2, 0.2, n), np.full(n, 0.754)]
    )
    floor = np.where(rng.random(n) < 0.6, 0.0, -math.inf)
    exit_azimuth = [AngleObservation(0.3, 0.05) if i % 13 == 0 else None for i in range(n)]
    exit_elevation = [AngleObservation(0.5, 0.05) if i % 19 == 0 else None for i in range(n)]
    return dict(
        tension_world_n=T,
        tension_cov_n2=C,
        weight_n_per_m=weights,
        length_m=lengths,
        base_world_m=base,
        floor_z_m=floor,
        exit_azimuth=exit_azimuth,
        exit_elevation=exit_elevation,
    )


def _same(got: PositionEstimate | LocalizationFailure, want: object) -> bool:
    if type(got) is not type(want):
        return False
    if isinstance(got, LocalizationFailure):
        return got == want
    for name in PositionEstimate.__dataclass_fields__:
        a, b = getattr(got, name), getattr(want, name)
        if isinstance(a, np.ndarray):
            if not (a.shape == b.shape and np.array_equal(a, b) and not a.flags.writeable):
                return False
        elif a != b or type(a) is not type(b):
            return False
    return True


@pytest.mark.parametrize("azimuth", ["auto", "tension", "reel"])
@pytest.mark.parametrize("seed", [0, 1])
def test_batch_gives_the_very_floats_of_one_by_one(
    azimuth: str, seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """try_localize_batch is try_localize per case, to the bit, whichever path a case takes
    (the arrays for the free and plumb cases with the tension's azimuth, try_localize for
    the rest): every kind of case, mixed in one batch."""
    import groundstation.localization as loc

    n = 600
    kw = _batch_cases(seed, n)
    one_by_one = []

    def counted(*args: object, **kwargs: object) -> object:
        one_by_one.append(1)
        return try_localize(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(loc, "try_localize", counted)
    got = try_localize_batch(**kw, azimuth=azimuth)  # type: ignore[arg-type]
    monkeypatch.undo()
    # the arrays took most cases (all of them with the reel's azimuth went one by one)
    assert len(one_by_one) == n if azimuth == "reel" else len(one_by_one) < n // 2
    cases: dict[str, int] = {}
    for i, g in enumerate(got):
        want = try_localize(
            kw["tension_world_n"][i],  # type: ignore[index]
            kw["tension_cov_n2"][i],  # type: ignore[index]
            float(kw["weight_n_per_m"][i]),  # type: ignore[index]
            float(kw["length_m"][i]),  # type: ignore[index]
            kw["base_world_m"][i],  # type: ignore[index]
            float(kw["floor_z_m"][i]),  # type: ignore[index]
            azimuth=azimuth,  # type: ignore[arg-type]
            exit_azimuth=kw["exit_azimuth"][i],  # type: ignore[index]
            exit_elevation=kw["exit_elevation"][i],  # type: ignore[index]
        )
        assert _same(g, want), (i, g, want)
        key = want.case if isinstance(want, PositionEstimate) else "failure"
        if isinstance(want, PositionEstimate) and want.elevation_used:
            key += "+elevation"
        cases[key] = cases.get(key, 0) + 1
    # every kind of case was in the batch
    assert {"free", "plumb", "floor", "failure"} <= set(cases), cases
    if azimuth != "reel":
        assert any(k.endswith("+elevation") for k in cases), cases
    nones = localize_batch(**kw, azimuth=azimuth)  # type: ignore[arg-type]
    assert [o is None for o in nones] == [isinstance(o, LocalizationFailure) for o in got]


def test_batch_of_none_and_bad_shapes() -> None:
    assert try_localize_batch(np.zeros((0, 3)), np.zeros((0, 3, 3)), 0.05, 1.6, BASE_M) == []
    with pytest.raises(ValueError, match="tension_world_n must be"):
        try_localize_batch(np.zeros((2, 3)), np.zeros((3, 3, 3)), 0.05, 1.6, BASE_M)
    # scalars broadcast; an invalid scalar is try_localize's failure, per case
    T = np.array([[-0.02, 0.005, -0.06]] * 2)
    C = np.array([FILTER_COV_N2] * 2)
    out = try_localize_batch(T, C, [0.05, -1.0], 1.6, BASE_M, FLOOR_M)
    assert isinstance(out[0], PositionEstimate) and isinstance(out[1], LocalizationFailure)
    assert _same(out[0], try_localize(T[0], C[0], 0.05, 1.6, BASE_M, FLOOR_M))
