"""The per-message path gives the same numbers as before its performance work.

A fixed, seeded telemetry sequence (hover, a 30 mN step with follow engaged, a slow
drift, a plumb tether, a tether resting on the floor with a landing in between) runs
through :meth:`Pipeline.handle`. Every output sample (Estimate, Setpoint, Stop), the
tension filter's full state after each step (x, P, change statistic, drift scale) and
the full :func:`localize` result are compared with golden values recorded from the
code before the optimisation: numbers to 1e-9 relative / 1e-12 absolute, everything
else (flags, keys, modes, which fields are None) exactly.

Regenerate the golden file only for an intended change of behaviour::

    .venv/bin/python -m tests.test_perf_equivalence --regenerate

The committed file comes from the code before the optimisation (tension.py,
localization.py and pipeline.py of 24a4690), with the intended follow change of 6995ece
(admittance without motion capture) wired in; regenerating from the current code would
bake its rounding (within 1e-10 of that) into the reference.

It writes ``tests/data/pipeline_golden.json``: per case, the exact (non-numeric)
fields run-length encoded, and the numeric fields as a float64 matrix (rows = input
messages, NaN where a field is absent; the last 16 mantissa bits dropped),
zlib-compressed and base64-encoded.
"""

from __future__ import annotations

import argparse
import base64
import json
import math
import zlib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from groundstation.bus import Sample
from groundstation.config import Settings, load_settings
from groundstation.localization import localize
from groundstation.pipeline import Pipeline

GOLDEN = Path(__file__).parent / "data" / "pipeline_golden.json"
REGENERATE = (
    "A performance change must not change these numbers; if the change of behaviour is "
    "intended (e.g. of follow or of the estimator), regenerate the golden file with "
    "`.venv/bin/python -m tests.test_perf_equivalence --regenerate` and say so in the commit"
)
RTOL = 1e-9
ATOL = 1e-12

MASS_KG = 0.030
GRAVITY_MPS2 = 9.81
DT_S = 0.004
DRONE = "cf1"
HOVER_N = np.array([-0.020, 0.005, -0.060])
E3 = np.array([0.0, 0.0, 1.0])
# Every setting the per-message path reads, pinned: a later change of a default must not
# pass for a change of behaviour (or fail this test).
PINNED: dict[str, Any] = {
    "drone": {"mass_kg": MASS_KG, "accel_noise_mps2": 0.3, "thrust_noise_n": 0.003},
    "tether": {"weight_n_per_m": 0.05, "length_m": 1.6},
    "base": {"position_m": [0.0, 0.0, 0.754], "floor_z_m": 0.0},
    "follow": {
        "threshold_n": 0.15,
        "hysteresis_ratio": 0.2,
        "land_below_m": None,
        "max_speed_mps": 0.5,
        "reach_margin_m": 0.05,
        "stale_after_s": 0.5,
    },
}


def pinned_settings() -> Settings:
    return load_settings(None, PINNED, use_env=False)


# ---------------------------------------------------------------- the sequence


def _quat_aligning_e3(direction: np.ndarray) -> np.ndarray:
    """Scalar-first quaternion whose body +z points along ``direction`` (world)."""
    d = direction / np.linalg.norm(direction)
    axis = np.cross(E3, d)
    s = float(np.linalg.norm(axis))
    if s < 1e-12:
        return np.array([1.0, 0.0, 0.0, 0.0])
    angle = math.atan2(s, float(d[2]))
    return np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * axis / s])


def _rotation(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _telemetry(
    seq: int,
    tension_n: np.ndarray,
    rng: np.random.Generator,
    *,
    armed: bool = True,
    thrust_scale: float = 1.0,
    position_m: list[float] | None = None,
) -> Sample:
    """A drone holding still against ``tension_n`` (world, N), with the simulator's noise."""
    thrust_vec = -(tension_n + MASS_KG * np.array([0.0, 0.0, -GRAVITY_MPS2]))
    quat = _quat_aligning_e3(thrust_vec)
    accel = _rotation(quat).T @ np.array([0.0, 0.0, GRAVITY_MPS2]) + rng.normal(0.0, 0.3, 3)
    thrust = thrust_scale * float(np.linalg.norm(thrust_vec)) + float(rng.normal(0.0, 0.003))
    body: dict[str, Any] = {
        "seq": seq,
        "stamp_s": seq * DT_S,
        "accel_mps2": accel.tolist(),
        "quat_wxyz": quat.tolist(),
        "thrust_n": max(thrust, 0.0),
        "armed": armed,
    }
    if position_m is not None:
        body["position_m"] = position_m
    return Sample(f"tether/{DRONE}/telemetry", json.dumps(body).encode())


def _follow(**body: Any) -> Sample:
    return Sample(f"tether/{DRONE}/follow", json.dumps(body).encode())


def _hover(rng: np.random.Generator) -> Iterator[Sample]:
    for k in range(250):
        if 200 <= k < 203:  # three lost samples: a seq gap and a longer dt
            continue
        yield _telemetry(k, HOVER_N, rng)


def _step(rng: np.random.Generator) -> Iterator[Sample]:
    # Follow engaged below the post-step tension (0.078 N) so setpoints flow after the tug.
    yield _follow(enabled=True, threshold_n=0.07)
    for k in range(250):
        tension = HOVER_N + (np.array([-0.030, 0.0, 0.0]) if k >= 125 else 0.0)
        yield _telemetry(k, tension, rng)


def _drift(rng: np.random.Generator) -> Iterator[Sample]:
    direction = np.array([1.0, -0.5, 0.3]) / math.sqrt(1.34)
    for k in range(400):
        yield _telemetry(k, HOVER_N + 0.020 * (k * DT_S) * direction, rng)  # 20 mN/s


def _plumb(rng: np.random.Generator) -> Iterator[Sample]:
    for k in range(150):
        yield _telemetry(k, np.array([0.0, 0.0, -0.080]), rng)


def _floor(rng: np.random.Generator) -> Iterator[Sample]:
    # a = s2 = 0.2 m with L = 1.6 m: the free curve would sag 1.2 m below a 0.754 m base.
    tension = np.array([-0.010, 0.0, -0.010])
    for k in range(200):
        if 100 <= k < 110:  # landed for a moment: thrust below half the weight, then disarmed
            yield _telemetry(k, tension, rng, thrust_scale=0.3, armed=k < 105)
            continue
        pos = [0.5, 0.0, 0.3] if k >= 190 else None  # motion capture for the last samples
        yield _telemetry(k, tension, rng, position_m=pos)


CASES: dict[str, tuple[int, Callable[[np.random.Generator], Iterator[Sample]]]] = {
    "hover": (11, _hover),
    "step": (12, _step),
    "drift": (13, _drift),
    "plumb": (14, _plumb),
    "floor": (15, _floor),
}


# ---------------------------------------------------------------- running and flattening


def _flatten(prefix: str, value: Any, out: dict[str, Any]) -> None:
    if isinstance(value, dict):
        for k, v in value.items():
            _flatten(f"{prefix}.{k}", v, out)
    elif isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            _flatten(f"{prefix}.{i}", v, out)
    elif isinstance(value, np.ndarray):
        _flatten(prefix, value.tolist(), out)
    elif isinstance(value, (bool, np.bool_)):
        out[prefix] = bool(value)
    elif isinstance(value, (int, float, np.integer, np.floating)):
        out[prefix] = float(value)
    else:
        out[prefix] = value  # str or None: compared exactly


def run_case(name: str) -> list[dict[str, Any]]:
    """One row per input sample: its outputs, the filter state and the full localization."""
    seed, make = CASES[name]
    settings = pinned_settings()
    pipe = Pipeline(settings)
    rows = []
    for sample in make(np.random.default_rng(seed)):
        row: dict[str, Any] = {}
        outs = pipe.handle(sample, 0.0)
        row["outputs"] = " ".join(o.key.rsplit("/", 1)[1] for o in outs)
        for o in outs:
            _flatten(o.key.rsplit("/", 1)[1], json.loads(o.payload), row)
        runtime = pipe.drones[DRONE]
        est = runtime.filter.estimate
        if est is not None:
            _flatten("filter", {k: getattr(est, k) for k in est.__dataclass_fields__}, row)
            kf = runtime.filter.kalman_filter  # the estimate must be filterpy's own state
            assert np.array_equal(kf.x[:, 0], est.tension_world_n)
            assert np.array_equal(kf.P, est.cov_n2)
            if est.converged and runtime.filter.initialized:
                pos = localize(
                    est.tension_world_n,
                    est.cov_n2,
                    runtime.weight_n_per_m,
                    runtime.length_m,
                    runtime.base_world_m,
                    settings.for_drone(DRONE).base.floor_z_m,
                )
                if pos is not None:
                    _flatten("loc", {k: getattr(pos, k) for k in pos.__dataclass_fields__}, row)
        rows.append(row)
    return rows


def _is_number(v: Any) -> bool:
    return isinstance(v, float)


def encode(rows: list[dict[str, Any]]) -> dict[str, Any]:
    numeric = sorted({k for r in rows for k, v in r.items() if _is_number(v)})
    col = {k: i for i, k in enumerate(numeric)}
    mat = np.full((len(rows), len(numeric)), np.nan)
    exact: list[list[Any]] = []  # run-length: [count, {path: value}]
    for i, r in enumerate(rows):
        rest = {}
        for k, v in r.items():
            if _is_number(v):
                mat[i, col[k]] = v
            else:
                rest[k] = v
        if exact and exact[-1][1] == rest:
            exact[-1][0] += 1
        else:
            exact.append([1, rest])
    # The low 16 mantissa bits are dropped (relative change < 2**-36 = 1.5e-11, far inside
    # RTOL): they are noise to zlib, and the file shrinks by a third.
    bits = mat.astype("<f8").view("<u8") & np.uint64(~0xFFFF & 0xFFFF_FFFF_FFFF_FFFF)
    blob = base64.b64encode(zlib.compress(bits.tobytes(), 9)).decode()
    return {"rows": len(rows), "numeric": numeric, "values": blob, "exact": exact}


def decode(case: dict[str, Any]) -> tuple[list[str], np.ndarray, list[dict[str, Any]]]:
    raw = zlib.decompress(base64.b64decode(case["values"]))
    mat = np.frombuffer(raw, dtype="<f8").reshape(case["rows"], len(case["numeric"]))
    exact = [rest for count, rest in case["exact"] for _ in range(count)]
    return case["numeric"], mat, exact


# ---------------------------------------------------------------- the test


@pytest.fixture(scope="module")
def golden() -> dict[str, Any]:
    return dict(json.loads(GOLDEN.read_text()))


@pytest.mark.parametrize("name", list(CASES))
def test_pipeline_matches_golden(name: str, golden: dict[str, Any]) -> None:
    want_cols, want, want_exact = decode(golden[name])
    got_case = encode(run_case(name))
    got_cols, got, got_exact = decode(got_case)
    assert got_cols == want_cols, f"the set of numeric fields changed. {REGENERATE}"
    assert got.shape == want.shape
    for i, (g, w) in enumerate(zip(got_exact, want_exact, strict=True)):
        assert g == w, f"{name} row {i}: exact fields differ. {REGENERATE}"
    close = np.isclose(got, want, rtol=RTOL, atol=ATOL, equal_nan=True)
    if not close.all():
        i, j = np.argwhere(~close)[0]
        pytest.fail(
            f"{name}: {int((~close).sum())} values differ; first row {i} {got_cols[j]}: "
            f"got {got[i, j]!r}, golden {want[i, j]!r}. {REGENERATE}"
        )


def test_golden_sequence_covers_every_branch(golden: dict[str, Any]) -> None:
    """The cases exercise what they are named after (guards a stale golden file)."""
    seen: dict[str, set[Any]] = {}
    for name in CASES:
        _, _, exact = decode(golden[name])
        for rest in exact:
            for key in ("loc.case", "filter.change_detected", "outputs", "estimate.on_ground"):
                seen.setdefault(key, set()).add(rest.get(key))
    assert {"free", "floor", "plumb"} <= seen["loc.case"]
    assert True in seen["filter.change_detected"]
    assert "estimate setpoint" in seen["outputs"]
    assert True in seen["estimate.on_ground"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--regenerate", action="store_true", help=f"write {GOLDEN}")
    args = parser.parse_args()
    data = {name: encode(run_case(name)) for name in CASES}
    if args.regenerate:
        GOLDEN.parent.mkdir(parents=True, exist_ok=True)
        GOLDEN.write_text(json.dumps(data, separators=(",", ":")) + "\n")
        print(f"wrote {GOLDEN} ({GOLDEN.stat().st_size} bytes)")
    else:
        for name, case in data.items():
            print(name, case["rows"], "rows", len(case["numeric"]), "numeric fields")


if __name__ == "__main__":
    main()


def test_running_window_sums_equal_the_cumulative_sum() -> None:
    """The filter's running window sums equal a fresh cumulative sum over the history,
    across regime restarts and the moves of the live windows inside the buffer."""
    from groundstation.tension import _Ring

    rng = np.random.default_rng(7)
    ring = _Ring(16)
    history: list[np.ndarray] = []
    moves = 0
    for _ in range(2000):
        if rng.random() < 0.01:  # a re-initialisation starts a new regime
            ring.count = 0
            history = []
        w = rng.normal(size=3)
        start_before = ring.start
        ring.push(np.zeros(3), (0.0, 0.0, 1.0), w.tolist())
        moves += ring.start > start_before
        history.append(w)
        n = ring.count
        want = np.cumsum(np.array(history[::-1][:n]), axis=0).T
        np.testing.assert_allclose(ring.window_sums(n), want, rtol=1e-12, atol=1e-12)
    assert moves >= 10
