"""Contract payloads: strict, finite, exact lengths, ranges, unknown fields ignored."""

import json
import math
from typing import Any

import numpy as np
import pytest

from groundstation.messages import (
    ESTIMATE_FIELD_ORDER,
    Estimate,
    FollowCommand,
    FollowInfo,
    InvalidMessage,
    Reel,
    Telemetry,
    encode_estimate,
    encode_estimate_ordered,
    parse_key,
)

GOOD = {
    "seq": 3,
    "stamp_s": 1.25,
    "accel_mps2": [0.0, 0.1, 9.81],
    "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
    "thrust_n": 0.3,
}


def _bytes(d: object) -> bytes:
    return json.dumps(d).encode()


def test_telemetry_minimal_and_optional() -> None:
    t = Telemetry.parse(_bytes(GOOD))
    assert t.armed is True and t.position_m is None and t.gyro_rps is None
    full = GOOD | {"position_m": [1, 2, 3], "gyro_rps": [0, 0, 0], "armed": False, "extra": 1}
    t = Telemetry.parse(_bytes(full))
    assert t.position_m == (1.0, 2.0, 3.0) and t.armed is False
    assert Telemetry.parse(_bytes(GOOD | {"position_m": None})).position_m is None


@pytest.mark.parametrize(
    "patch",
    [
        {"seq": -1},
        {"seq": 1.5},
        {"seq": "3"},
        {"seq": True},
        {"stamp_s": "1.0"},
        {"accel_mps2": [0.0, 9.81]},
        {"accel_mps2": [0.0, 0.0, 9.81, 0.0]},
        {"quat_wxyz": [1.0, 0.0, 0.0]},
        {"thrust_n": -0.01},
        {"armed": "yes"},
        {"position_m": [1.0, 2.0]},
    ],
)
def test_telemetry_rejects(patch: dict[str, object]) -> None:
    with pytest.raises(InvalidMessage) as info:
        Telemetry.parse(_bytes(GOOD | patch))
    assert info.value.kind == "invalid"


@pytest.mark.parametrize("literal", ["NaN", "Infinity", "-Infinity"])
def test_non_finite_rejected(literal: str) -> None:
    payload = _bytes(GOOD).replace(b'"thrust_n": 0.3', f'"thrust_n": {literal}'.encode())
    with pytest.raises(InvalidMessage):
        Telemetry.parse(payload)


def test_missing_field_and_not_json() -> None:
    with pytest.raises(InvalidMessage) as info:
        Telemetry.parse(_bytes({k: v for k, v in GOOD.items() if k != "thrust_n"}))
    assert info.value.kind == "invalid"
    with pytest.raises(InvalidMessage) as info:
        Telemetry.parse(b"{not json")
    assert info.value.kind == "not_json"
    with pytest.raises(InvalidMessage):
        Telemetry.parse(b"[1, 2, 3]")


def test_reel_and_follow_ranges() -> None:
    assert Reel.parse(b'{"stamp_s": 0, "length_m": 1.2}').length_m == 1.2
    with pytest.raises(InvalidMessage):
        Reel.parse(b'{"stamp_s": 0, "length_m": 0}')
    assert FollowCommand.parse(b'{"enabled": true}').threshold_n is None
    with pytest.raises(InvalidMessage):
        FollowCommand.parse(b'{"enabled": true, "threshold_n": 0}')
    with pytest.raises(InvalidMessage):
        FollowCommand.parse(b'{"enabled": 1}')


def test_keys() -> None:
    assert parse_key("tether/cf_1-A/telemetry") == ("cf_1-A", "telemetry")
    assert parse_key("tether/x/cmd/stop") == ("x", "cmd/stop")
    for key, kind in [
        ("tether/" + "a" * 65 + "/telemetry", "bad_drone_id"),
        ("tether/a.b/telemetry", "bad_drone_id"),
        ("tether/a/unknown", "bad_key"),
        ("other/a/telemetry", "bad_key"),
    ]:
        with pytest.raises(InvalidMessage) as info:
            parse_key(key)
        assert info.value.kind == kind


def test_estimate_serialises_contract_fields() -> None:
    est = Estimate(
        seq=1,
        stamp_s=0.5,
        tension_n=(0.01, -0.02, -0.05),
        tension_std_n=(0.001, 0.001, 0.001),
        horizontal_n=0.0223,
        vertical_n=0.05,
        position_m=None,
        follow=FollowInfo(enabled=False, active=False, threshold_n=0.15),
    )
    d = json.loads(est.to_json())
    for key in (
        "seq",
        "stamp_s",
        "tension_n",
        "tension_std_n",
        "horizontal_n",
        "vertical_n",
        "position_m",
        "follow",
    ):
        assert key in d
    assert d["position_m"] is None
    assert set(d["follow"]) >= {"enabled", "active", "threshold_n"}
    with pytest.raises(ValueError):
        Estimate(**(est.model_dump() | {"horizontal_n": float("nan")}))


# ---------------------------------------------------------------- the fast Estimate encoder


def _random_estimate_fields(rng: np.random.Generator) -> dict[str, Any]:
    """Estimate fields with floats across magnitudes (1e-9 … 1e9, both signs, ±0.0) and
    every optional field present or absent."""

    def f() -> float:
        kind = rng.integers(5)
        if kind == 0:
            return float(rng.choice([0.0, -0.0, 1.0, 0.1, 1e-5, 1e-7, 2.5e-4, 1e16, 1e21]))
        return float(rng.normal() * 10.0 ** rng.integers(-9, 10))

    def v3() -> tuple[float, float, float]:
        return (f(), f(), f())

    def maybe(x: Any) -> Any:
        return x if rng.random() < 0.7 else None

    def maybe_bool() -> bool | None:
        return maybe(bool(rng.integers(2)))

    return {
        "seq": int(rng.integers(0, 2**40)),
        "stamp_s": f(),
        "tension_n": v3(),
        "tension_std_n": v3(),
        "horizontal_n": abs(f()),
        "vertical_n": f(),
        "position_m": maybe(v3()),
        "position_std_m": maybe(v3()),
        "radial_m": maybe(f()),
        "radial_interval_m": maybe((f(), f())),
        "azimuth_determined": maybe_bool(),
        "azimuth_source": maybe(str(rng.choice(["tension", "reel", "mocap", "fused"]))),
        "floor_contact": maybe_bool(),
        "on_ground": bool(rng.integers(2)),
        "converged": bool(rng.integers(2)),
        "length_m": maybe(abs(f())),
        "base_m": maybe(v3()),
        "calibration_extrapolated": maybe_bool(),
    }


def _random_follow(rng: np.random.Generator) -> FollowInfo:
    return FollowInfo(
        enabled=bool(rng.integers(2)),
        active=bool(rng.integers(2)),
        threshold_n=float(rng.uniform(0.01, 1.0)),
        land_below_m=None if rng.random() < 0.5 else float(rng.normal()),
        landing_armed=bool(rng.integers(2)),
        stopped=bool(rng.integers(2)),
        reason=str(rng.choice(["", "stale", "tug", 'a "quoted" \\ reason', "höhe", "NaN seen"])),
    )


def test_fast_encoder_agrees_with_the_model_on_random_estimates() -> None:
    """encode_estimate writes the bytes the model writes: its fields in its order, the very
    same values (compared after parsing too, so a failure says which)."""
    rng = np.random.default_rng(42)
    for _ in range(3000):
        fields = _random_estimate_fields(rng)
        if rng.random() < 0.2:  # a field left out takes the model's default
            optional = [k for k, f in Estimate.model_fields.items() if not f.is_required()]
            fields.pop(str(rng.choice(optional)), None)
        follow = _random_follow(rng)
        want = Estimate(follow=follow, **fields).to_json()
        got = encode_estimate(follow=follow.model_dump(), **fields)
        parsed = json.loads(got)
        assert list(parsed) == list(Estimate.model_fields)
        assert parsed == json.loads(want), (got, want)
        assert got == want


def test_fast_encoder_never_emits_nan() -> None:
    rng = np.random.default_rng(3)
    follow = _random_follow(rng).model_dump()
    for name in ("stamp_s", "tension_n", "horizontal_n", "position_m", "radial_interval_m"):
        for bad in (math.nan, math.inf, -math.inf):
            fields = _random_estimate_fields(rng)
            value = fields[name]
            if isinstance(value, tuple) or value is None:
                n = 2 if name == "radial_interval_m" else 3
                fields[name] = (bad,) + (0.0,) * (n - 1)
            else:
                fields[name] = bad
            with pytest.raises(ValueError, match="non-finite"):
                encode_estimate(follow=follow, **fields)


def test_fast_encoder_refuses_unknown_and_missing_fields() -> None:
    rng = np.random.default_rng(5)
    fields = _random_estimate_fields(rng)
    follow = _random_follow(rng).model_dump()
    with pytest.raises(TypeError, match="no field"):
        encode_estimate(follow=follow, not_a_field=1.0, **fields)
    del fields["seq"]
    with pytest.raises(TypeError, match="'seq' missing"):
        encode_estimate(follow=follow, **fields)


def test_ordered_encoder_writes_the_models_bytes() -> None:
    """encode_estimate_ordered: a dict of every field in the model's order goes to the
    serializer as it is; in another order (or with a field missing) it takes
    encode_estimate's pass; NaN is refused either way."""
    rng = np.random.default_rng(7)
    assert tuple(Estimate.model_fields) == ESTIMATE_FIELD_ORDER
    for _ in range(1000):
        fields = _random_estimate_fields(rng)
        follow = _random_follow(rng)
        want = Estimate(follow=follow, **fields).to_json()
        ordered = {k: fields.get(k, Estimate.model_fields[k].default) for k in ESTIMATE_FIELD_ORDER}
        ordered["follow"] = follow.model_dump()
        assert encode_estimate_ordered(ordered) == want
        shuffled = dict(reversed(list(ordered.items())))
        assert encode_estimate_ordered(shuffled) == want
    ordered["tension_n"] = (math.nan, 0.0, 0.0)
    with pytest.raises(ValueError, match="non-finite value in Estimate field"):
        encode_estimate_ordered(ordered)
    del ordered["seq"]
    with pytest.raises(TypeError, match="'seq' missing"):
        encode_estimate_ordered(ordered)
