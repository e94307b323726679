"""Contract payloads: strict, finite, exact lengths, ranges, unknown fields ignored."""

import json

import pytest

from groundstation.messages import (
    Estimate,
    FollowCommand,
    FollowInfo,
    InvalidMessage,
    Reel,
    Telemetry,
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
