"""The per-message localization's common case against two references.

``try_localize`` answers the common case (a freely hanging tether, the azimuth from the
tension alone and certain) in ``_localize_tension_free``, which leaves out what it knows the
result of. What these tests prove:

* **Same floats as the general path.** With the common case switched off (monkeypatched to
  decline), ``try_localize`` takes its general path, which computes every term (the reach at
  k sigma_H, the blend weights, the other sources' share, the floor-aware catenary). Both
  give the very same floats and flags on cases of every regime: hovering, near taut, slack,
  pulled up (T_v < 0), near the floor and on it, near plumb, singular and anisotropic
  covariances, with and without a floor.
* **The physics, computed another way.** An independent reference written here with numpy
  (``np.linalg.cholesky``, :func:`catenary.locate` on arrays, each sigma point's azimuth by
  ``np.arctan2`` and its offset by ``cos``/``sin``, as in the paper's unscented transform)
  agrees to 1e-9 relative on every free-hanging case: the shortcuts (a sigma point's
  direction as ``-T_xy / H``, the terms whose weight is zero) change nothing but rounding.
* **The batch.** :func:`localize_batch` (numpy over arrays, another implementation) gives the
  same floats on the same cases (``test_localization.py`` checks its own mix of cases too).
* **It is the path taken.** The converged hover of the service benchmark goes through the
  common case on every message (else the speed it buys would not be had).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

import groundstation.localization as loc
from groundstation import catenary
from groundstation.localization import (
    PLUMB_K,
    LocalizationFailure,
    PositionEstimate,
    localize_batch,
    try_localize,
)

BASE_M = np.array([0.0, 0.0, 0.754])
FIELDS = tuple(PositionEstimate.__dataclass_fields__)


def _cases(seed: int, n: int, with_model: bool = False) -> Iterator[dict[str, Any]]:
    """n cases cycling through the regimes, as keyword arguments of try_localize; with
    ``with_model`` each also has a calibration misfit (``model_var_n2``, up to (10 mN)²,
    zero on some axes)."""
    rng = np.random.default_rng(seed)
    for i in range(n):
        regime = i % 8
        length = float(rng.uniform(0.5, 3.0))
        omega = float(rng.choice([0.05, 0.055, 0.2]))
        ang = rng.uniform(-math.pi, math.pi)
        h, tv = {
            0: (0.02 * rng.uniform(0.5, 2.0), 0.06 * rng.uniform(0.5, 2.0)),  # hovering
            1: (omega * length * 10 ** rng.uniform(1.0, 4.0), rng.uniform(-1.0, 2.0)),  # taut
            2: (0.002 * rng.uniform(0.5, 2.0), omega * length * rng.uniform(0.6, 0.99)),  # slack
            3: (0.03 * rng.uniform(0.5, 2.0), -0.05 * rng.uniform(0.1, 2.0)),  # pulled up
            4: (0.01 * rng.uniform(0.2, 1.0), omega * length * rng.uniform(0.2, 0.6)),  # floor
            5: (3e-4 * rng.uniform(0.2, 2.0), 0.05),  # near plumb
            6: (0.05 * rng.uniform(0.5, 2.0), 0.1 * rng.uniform(-1.0, 1.0)),  # anything
            7: (0.02, 0.06),  # singular covariances, below
        }[regime]
        tension = np.array([h * math.cos(ang), h * math.sin(ang), -tv])
        a = rng.normal(0.0, 10 ** rng.uniform(-5.0, -2.0), (3, 3))
        cov = a @ a.T + np.diag(rng.uniform(0.0, 1e-8, 3))
        if regime == 7:
            cov = [np.zeros((3, 3)), np.diag([1e-6, 0.0, 1e-6]), np.eye(3) * 1e-7][i // 8 % 3]
        base = np.array([rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(0.3, 1.2)])
        floor = float(rng.choice([-math.inf, 0.0, base[2] - rng.uniform(0.0, 0.4)]))
        kw = {
            "tension_world_n": tension,
            "tension_cov_n2": cov,
            "weight_n_per_m": omega,
            "length_m": length,
            "base_world_m": base,
            "floor_z_m": floor,
        }
        if with_model:
            m = rng.uniform(0.0, 1e-4, 3) * (rng.random(3) < 0.8)
            kw["model_var_n2"] = (float(m[0]), float(m[1]), float(m[2]))
        yield kw


def _same(got: object, want: object) -> bool:
    """The same type, flags and floats (arrays: equal, read-only, same shape)."""
    if type(got) is not type(want):
        return False
    if isinstance(got, LocalizationFailure):
        return got == want
    for name in FIELDS:
        a, b = getattr(got, name), getattr(want, name)
        if isinstance(a, np.ndarray):
            if not (a.shape == b.shape and np.array_equal(a, b) and not a.flags.writeable):
                return False
        elif a != b or type(a) is not type(b):
            return False
    return True


def _general(kw: dict[str, Any], monkeypatch: pytest.MonkeyPatch) -> object:
    with monkeypatch.context() as m:
        m.setattr(loc, "_localize_tension_free", lambda *args: None)
        return try_localize(**kw)


@pytest.mark.parametrize(("seed", "with_model"), [(0, False), (1, False), (2, False), (7, True)])
def test_common_case_gives_the_general_paths_floats(
    seed: int, with_model: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    taken = []
    real = loc._localize_tension_free

    def counted(*args: Any) -> object:
        out = real(*args)
        taken.append(out is not None)
        return out

    regimes: dict[str, int] = {}
    for kw in _cases(seed, 480, with_model):
        monkeypatch.setattr(loc, "_localize_tension_free", counted)
        got = try_localize(**kw)
        monkeypatch.undo()
        want = _general(kw, monkeypatch)
        assert _same(got, want), (kw, got, want)
        key = want.case if isinstance(want, PositionEstimate) else "failure"
        regimes[key] = regimes.get(key, 0) + 1
    # every regime was there, and the common case answered most free cases itself
    assert {"free", "floor", "plumb"} <= set(regimes), regimes
    assert sum(taken) > 0.5 * regimes["free"], (sum(taken), regimes)


def _reference(kw: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, float, float, float]:
    """Position, covariance, r, beta, std_beta of a free, tension-azimuth case whose
    azimuth is certain (std <= 1 / (2 k): no blending toward the base), with numpy:
    the unscented transform (7 sigma points, kappa = 0) of the closed form
    (catenary.locate), each point carried along its own azimuth atan2(-T_y, -T_x); the
    points drawn from the covariance plus the model's variance, the azimuth's σ from the
    covariance alone."""
    t = np.asarray(kw["tension_world_n"], dtype=float)
    c = np.asarray(kw["tension_cov_n2"], dtype=float)
    c = 0.5 * (c + c.T)
    model = np.diag(kw.get("model_var_n2") or (0.0, 0.0, 0.0))
    s = np.linalg.cholesky(c + model) * math.sqrt(3.0)
    pts = np.array([t, *(t + s[:, i] for i in range(3)), *(t - s[:, i] for i in range(3))])
    h = np.hypot(pts[:, 0], pts[:, 1])
    r, z = catenary.locate(h, -pts[:, 2], kw["weight_n_per_m"], kw["length_m"], 0.0)
    r, z = np.asarray(r), np.asarray(z) + kw["base_world_m"][2]
    beta = np.arctan2(-pts[:, 1], -pts[:, 0])
    u = np.array([math.cos(beta[0]), math.sin(beta[0])])
    r0 = max(float(r[0]), 0.0)
    d = np.column_stack(
        [r[1:] * np.cos(beta[1:]) - r0 * u[0], r[1:] * np.sin(beta[1:]) - r0 * u[1], z[1:] - z[0]]
    )
    cov = d.T @ d / 6.0
    position = np.array([*(kw["base_world_m"][:2] + r0 * u), z[0]])
    side = np.array([-u[1], u[0]])  # across the pull
    std_beta = math.sqrt(side @ c[:2, :2] @ side) / h[0]
    return position, cov, r0, float(beta[0]), std_beta


@pytest.mark.parametrize(("seed", "with_model"), [(3, False), (4, False), (8, True)])
def test_common_case_against_an_independent_reference(seed: int, with_model: bool) -> None:
    checked = 0
    for kw in _cases(seed, 480, with_model):
        kw["floor_z_m"] = -math.inf  # the free curve everywhere (the floor: the test above)
        got = try_localize(**kw)
        if not (isinstance(got, PositionEstimate) and got.case == "free"):
            continue
        if not got.azimuth_std_rad <= 0.5 / PLUMB_K:  # blended toward the base: not here
            continue
        try:
            position, cov, r0, beta, std_beta = _reference(kw)
        except np.linalg.LinAlgError:  # singular: the general path's eigen square root
            continue
        scale = max(float(np.abs(cov).max()), 1e-30)
        assert np.allclose(got.position_world_m, position, rtol=1e-9, atol=1e-12), kw
        assert np.allclose(got.cov_world_m2, cov, rtol=1e-9, atol=1e-9 * scale), kw
        assert got.radial_m == pytest.approx(r0, rel=1e-9, abs=1e-12)
        assert got.azimuth_rad == pytest.approx(beta, abs=1e-12)
        assert got.azimuth_std_rad == pytest.approx(std_beta, rel=1e-9)
        checked += 1
    assert checked > 150


@pytest.mark.parametrize(("seed", "with_model"), [(5, False), (6, False), (9, True)])
def test_batch_gives_the_same_floats_on_every_regime(seed: int, with_model: bool) -> None:
    cases = list(_cases(seed, 480, with_model))
    fields = ("tension_world_n", "tension_cov_n2", "weight_n_per_m", "length_m")
    cols = {f: np.array([kw[f] for kw in cases]) for f in fields}
    got = localize_batch(
        cols["tension_world_n"],
        cols["tension_cov_n2"],
        cols["weight_n_per_m"],
        cols["length_m"],
        np.array([kw["base_world_m"] for kw in cases]),
        np.array([kw["floor_z_m"] for kw in cases]),
        model_var_n2=np.array([kw["model_var_n2"] for kw in cases]) if with_model else None,
    )
    for g, kw in zip(got, cases, strict=True):
        want = try_localize(**kw)
        if isinstance(want, LocalizationFailure):
            assert g is None
        else:
            assert _same(g, want), (kw, g, want)


def test_the_service_hover_takes_the_common_case(monkeypatch: pytest.MonkeyPatch) -> None:
    """The filter's converged hover (the service benchmark's telemetry, as bench_pipeline
    localizes it) goes through _localize_tension_free on every message."""
    from benchmarks.bench_service import _telemetry_payloads
    from groundstation.bus import Sample
    from groundstation.evaluation import settings_for
    from groundstation.pipeline import Pipeline

    taken = []
    real = loc._localize_tension_free

    def counted(*args: Any) -> object:
        out = real(*args)
        taken.append(out is not None)
        return out

    pipe = Pipeline(settings_for())
    payloads = _telemetry_payloads(1, 3.0, 0)
    for step in payloads[:500]:  # the filter converges
        pipe.handle(Sample("tether/d0/telemetry", step[0]), 0.0)
    monkeypatch.setattr(loc, "_localize_tension_free", counted)
    for step in payloads[500:]:
        pipe.handle(Sample("tether/d0/telemetry", step[0]), 0.0)
    assert taken and all(taken), (len(taken), sum(taken))


def test_plumb_k_is_respected_by_the_common_case(monkeypatch: pytest.MonkeyPatch) -> None:
    """A certain azimuth under one plumb_k is a blended one under a larger: the common case
    declines it, and both paths agree at every plumb_k."""
    kw = next(_cases(0, 1))
    for k in (0.5, PLUMB_K, 30.0, 300.0, 3000.0):
        got = try_localize(**kw, plumb_k=k)
        assert _same(got, _general({**kw, "plumb_k": k}, monkeypatch)), k


def test_numpy_scalars_and_lists_give_the_same_floats() -> None:
    """np.float64 scalars and list inputs give what float64 arrays and floats give: the
    same floats, of Python's float type (as numpy's .tolist() gave them before)."""
    for kw in _cases(7, 40):
        want = try_localize(**kw)
        as_numpy = {
            **kw,
            "weight_n_per_m": np.float64(kw["weight_n_per_m"]),
            "length_m": np.float64(kw["length_m"]),
            "floor_z_m": np.float64(kw["floor_z_m"]),
        }
        as_lists = {
            **kw,
            "tension_world_n": list(kw["tension_world_n"]),
            "tension_cov_n2": np.asarray(kw["tension_cov_n2"]).tolist(),
            "base_world_m": tuple(kw["base_world_m"]),
        }
        for other in (as_numpy, as_lists):
            assert _same(try_localize(**other), want), (other, want)


@pytest.mark.parametrize("seed", [0, 1])
def test_catenary_float_versions_against_the_array_versions(seed: int) -> None:
    """catenary.locate_free_floats and locate_with_floor_floats (the per-message path) give
    catenary.locate_free and locate_with_floor's results (numpy's, whose hypot is the C
    library's: an ulp apart at times) on every regime, floor contact and clamping included."""
    rng = np.random.default_rng(seed)
    n = 4000
    length = rng.uniform(0.3, 3.0, n)
    omega = rng.choice([0.05, 0.2], n)
    h = np.where(rng.random(n) < 0.1, 0.0, 10 ** rng.uniform(-6.0, 2.0, n))
    tv = omega * length * rng.uniform(-0.5, 1.5, n)
    base_z = rng.uniform(0.0, 1.5, n)
    floor = base_z - rng.uniform(0.0, 2.0, n)
    r_a, z_a = catenary.locate_free(h / omega, tv / omega, length, base_z)
    want = catenary.locate_with_floor(h, tv, omega, length, base_z, floor)
    contacts = 0
    for i in range(n):
        w_i, l_i, b_i, f_i = float(omega[i]), float(length[i]), float(base_z[i]), float(floor[i])
        (r,), (z,) = catenary.locate_free_floats([h[i] / w_i], [tv[i] / w_i], l_i, b_i)
        assert r == pytest.approx(r_a[i], rel=1e-13, abs=1e-15)
        assert z == pytest.approx(z_a[i], rel=1e-13, abs=1e-15)
        got = catenary.locate_with_floor_floats([float(h[i])], [float(tv[i])], w_i, l_i, b_i, f_i)
        (rm,), (zm,), (lo,), (hi,), (contact,), (run,) = got
        assert contact == bool(want.floor_contact[i])
        for g, w in ((rm, want.r_m), (zm, want.z_m), (lo, want.r_min_m), (hi, want.r_max_m)):
            assert g == pytest.approx(float(w[i]), rel=1e-12, abs=1e-14), i
        assert run == pytest.approx(float(want.floor_run_m[i]), rel=1e-12, abs=1e-14)
        contacts += contact
    assert 0.1 * n < contacts < 0.9 * n


def test_a_calibration_misfit_widens_the_position_not_its_estimate() -> None:
    """``model_var_n2`` (the calibration's misfit) is drawn into the sigma points: the
    position's covariance grows; the point, the azimuth and its determination (the noise's
    question) do not move. Negative or non-finite: a failure that says so."""
    t = np.array([0.03, -0.01, -0.06])
    cov = np.diag([1e-7, 1e-7, 2e-7])
    kw = dict(weight_n_per_m=0.055, length_m=1.6, base_world_m=BASE_M)
    plain = try_localize(t, cov, **kw)
    wide = try_localize(t, cov, **kw, model_var_n2=(25e-6, 25e-6, 16e-6))
    assert isinstance(plain, PositionEstimate) and isinstance(wide, PositionEstimate)
    assert np.array_equal(plain.position_world_m, wide.position_world_m)
    assert plain.azimuth_rad == wide.azimuth_rad and wide.azimuth_determined
    assert plain.azimuth_std_rad == wide.azimuth_std_rad
    assert np.all(wide.std_world_m > 3.0 * plain.std_world_m)
    # The same as the covariance carrying it, where that leaves the azimuth determined.
    both = try_localize(t, cov + np.diag([25e-6, 25e-6, 16e-6]), **kw)
    assert isinstance(both, PositionEstimate)
    assert np.allclose(both.cov_world_m2, wide.cov_world_m2, rtol=1e-9)
    assert _same(try_localize(t, cov, **kw, model_var_n2=(0.0, 0.0, 0.0)), plain)
    for bad in ((-1e-6, 0.0, 0.0), (math.nan, 0.0, 0.0), (0.0, math.inf, 0.0)):
        out = try_localize(t, cov, **kw, model_var_n2=bad)
        assert isinstance(out, LocalizationFailure) and "model_var_n2" in out.reason
