"""Pipeline.process_batch (the service's batched drain) against Pipeline.handle, message by
message: the same outputs, byte for byte, in the same order.

The input is a realistic mix of nine drones at 250 Hz, interleaved at random as they
arrive: hovering, a plumb tether, a tether resting on the floor with a landing (thrust below
the weight, then disarmed), a tug with follow switched on and motion capture (setpoints),
a drone that starts late, one that falls silent for 1.2 s and comes back (the filter
restarts), one whose reel reports an exit azimuth (its localizations go one by one inside
the batch), one sending a bad quaternion, one whose battery leaves the calibrated range and
comes back every few samples; with invalid payloads, repeated seqs, reel,
params and follow commands mixed in. It is cut into batches of random sizes.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

import groundstation.pipeline as pipeline_mod
from groundstation.bus import Sample
from groundstation.config import Settings, load_settings
from groundstation.pipeline import Parsed, Pipeline
from groundstation.service import Service
from tests.hover_synth import hover_body

MASS_KG = 0.030
DT_S = 0.004
HOVER_N = np.array([-0.020, 0.005, -0.060])
STEPS = 320


def settings() -> Settings:
    return load_settings(
        None,
        {
            "drone": {"mass_kg": MASS_KG, "accel_noise_mps2": 0.3, "thrust_noise_n": 0.003},
            "tether": {"weight_n_per_m": 0.05, "length_m": 1.6},
            "base": {"position_m": [0.0, 0.0, 0.754], "floor_z_m": 0.0},
            "calibration": {"thrust_vbat_range_v": [3.8, 4.0]},
        },
        use_env=False,
    )


def _telemetry(
    drone: str,
    seq: int,
    tension_n: np.ndarray,
    rng: np.random.Generator,
    **kwargs: Any,
) -> bytes:
    body = hover_body(seq, tension_n, rng, mass_kg=MASS_KG, dt_s=DT_S, **kwargs)
    return json.dumps(body).encode()


Scenario = Callable[[int, np.random.Generator], list[tuple[str, bytes]]]


def _scenarios() -> dict[str, Scenario]:
    """Per drone: step k -> the (kind, payload) it sends at that step (none while silent)."""

    def tel(drone: str, tension: np.ndarray, **kw: Any) -> Scenario:
        return lambda k, rng: [("telemetry", _telemetry(drone, k, tension, rng, **kw))]

    def floor(k: int, rng: np.random.Generator) -> list[tuple[str, bytes]]:
        t = np.array([-0.010, 0.0, -0.010])  # a = s2 = 0.2 m: part of the tether on the floor
        if 100 <= k < 110:  # landed for a moment: thrust below half the weight, then disarmed
            return [("telemetry", _telemetry("floor", k, t, rng, thrust_scale=0.3, armed=k < 105))]
        return [("telemetry", _telemetry("floor", k, t, rng))]

    def follow(k: int, rng: np.random.Generator) -> list[tuple[str, bytes]]:
        out = []
        if k == 20:
            out.append(("follow", b'{"enabled":true,"threshold_n":0.02}'))
        t = HOVER_N + (np.array([-0.030, 0.0, 0.0]) if k >= 125 else 0.0)
        out.append(("telemetry", _telemetry("follow", k, t, rng, position_m=[0.8, 0.0, 1.0])))
        if k == 200:
            out.append(("follow", b'{"enabled":false}'))
        return out

    def late(k: int, rng: np.random.Generator) -> list[tuple[str, bytes]]:
        return [] if k < 80 else [("telemetry", _telemetry("late", k - 80, HOVER_N, rng))]

    def pause(k: int, rng: np.random.Generator) -> list[tuple[str, bytes]]:
        if 60 <= k < 60 + 300:  # 1.2 s of silence: the filter restarts when it is back
            return []
        return [("telemetry", _telemetry("pause", k, HOVER_N, rng))]

    def reel(k: int, rng: np.random.Generator) -> list[tuple[str, bytes]]:
        out = []
        if k in (50, 150):
            out.append(("reel", b'{"stamp_s":0.2,"length_m":1.6,"exit_azimuth_rad":2.9}'))
        if k == 90:
            out.append(("params", b'{"weight_n_per_m":0.055}'))
        out.append(("telemetry", _telemetry("reel", k, HOVER_N, rng)))
        return out

    def bad(k: int, rng: np.random.Generator) -> list[tuple[str, bytes]]:
        out = [("telemetry", _telemetry("bad", k, HOVER_N, rng))]
        if k == 70:
            out.append(("telemetry", _telemetry("bad", k + 1, HOVER_N, rng, quat=[0, 0, 0, 0])))
        if k in (90, 91):
            out.append(("telemetry", b'{"seq":"x"}'))
        if k == 120:
            out.append(out[0])  # a repeated seq
        return out

    def battery(k: int, rng: np.random.Generator) -> list[tuple[str, bytes]]:
        # In and out of the calibrated battery range every few samples: the Estimate's
        # calibration_extrapolated is each sample's own, whatever else the batch holds.
        vbat = 3.9 if (k // 3) % 2 else 3.7
        return [("telemetry", _telemetry("battery", k, HOVER_N, rng, vbat_v=vbat))]

    return {
        "battery": battery,
        "hover": tel("hover", HOVER_N),
        "plumb": tel("plumb", np.array([0.0, 0.0, -0.080])),
        "floor": floor,
        "follow": follow,
        "late": late,
        "pause": pause,
        "reel": reel,
        "bad": bad,
    }


def mixed_input(seed: int) -> list[tuple[Sample, float]]:
    """Every drone's samples, interleaved at random within each 4 ms step, with the receive
    time of each (s)."""
    rng = np.random.default_rng(seed)
    scenarios = _scenarios()
    rngs = {d: np.random.default_rng(seed * 100 + i) for i, d in enumerate(scenarios)}
    out: list[tuple[Sample, float]] = []
    for k in range(STEPS + 300):
        drones = list(scenarios)
        rng.shuffle(drones)
        step: list[Sample] = []
        for drone in drones:
            if k >= STEPS and drone != "pause":
                continue
            step += [
                Sample(f"tether/{drone}/{kind}", payload)
                for kind, payload in scenarios[drone](k, rngs[drone])
            ]
        out += [(s, k * DT_S + i * 1e-5) for i, s in enumerate(step)]
    return out


def _plain(samples: list[tuple[Sample, float]]) -> tuple[list[Sample], Pipeline]:
    pipe = Pipeline(settings())
    return [o for s, now_s in samples for o in pipe.handle(s, now_s)], pipe


def _drops(pipe: Pipeline) -> Counter[str]:
    return sum((r.drops for r in pipe.drones.values()), Counter(pipe.global_drops))


def _cut(parsed: list[Parsed], rng: np.random.Generator) -> list[list[Parsed]]:
    batches, i = [], 0
    while i < len(parsed):
        n = int(rng.choice([1, 2, 5, 12, 32, 64, 200]))
        batches.append(parsed[i : i + n])
        i += n
    return batches


@pytest.mark.parametrize("seed", [0, 1])
def test_process_batch_publishes_what_handle_publishes(seed: int) -> None:
    samples = mixed_input(seed)
    want, plain = _plain(samples)

    pipe = Pipeline(settings())
    parsed = [p for s, now_s in samples if (p := pipe.validate(s, now_s)) is not None]
    got = [
        o for batch in _cut(parsed, np.random.default_rng(seed)) for o in pipe.process_batch(batch)
    ]

    kinds = Counter(s.key.split("/", 2)[2] for s in want)
    assert kinds["estimate"] > 2000 and kinds["cmd/setpoint"] > 10, kinds
    assert got == want  # every byte, in the same order
    assert _drops(pipe) == _drops(plain)
    assert _drops(plain) == {"invalid": 2, "bad_quaternion": 1, "seq_repeated": 1}
    for drone, runtime in plain.drones.items():
        other = pipe.drones[drone]
        assert (other.estimates, other.setpoints, other.stops, other.seq_gaps) == (
            runtime.estimates,
            runtime.setpoints,
            runtime.stops,
            runtime.seq_gaps,
        )
        assert other.follow_state == runtime.follow_state
        assert other.contact == runtime.contact
        assert other.last_estimate == runtime.last_estimate
    # the regimes were reached: plumb, floor contact, on the ground, a filter restart
    est = [json.loads(s.payload) | {"drone": s.key.split("/")[1]} for s in want]
    est = [e for e in est if "tension_n" in e]
    assert any(e["drone"] == "plumb" and e["azimuth_determined"] is False for e in est)
    assert any(e["drone"] == "floor" and e["floor_contact"] for e in est)
    assert any(e["drone"] == "floor" and e["on_ground"] for e in est)
    assert any(e["drone"] == "reel" and e["azimuth_source"] == "reel" for e in est)
    flags = {e["calibration_extrapolated"] for e in est if e["drone"] == "battery"}
    assert {True, False} <= flags
    assert plain.drones["pause"].received == STEPS  # silent for 300 of its STEPS + 300


def test_service_step_batch_publishes_what_handle_publishes() -> None:
    """The service's worker (grouped by drone, its error handler, one publish run per batch):
    each drone's outputs as message by message."""
    samples = mixed_input(2)
    want, _ = _plain(samples)

    class Bus:
        def __init__(self) -> None:
            self.published: list[Sample] = []

        def publish(self, key: str, payload: bytes) -> None:
            self.published.append(Sample(key, payload))

    bus = Bus()
    service = Service(settings(), bus)  # type: ignore[arg-type]
    parsed = [p for s, now_s in samples if (p := service.pipeline.validate(s, now_s)) is not None]
    for batch in _cut(parsed, np.random.default_rng(5)):
        service._step_batch(batch)
    got = [s for s in bus.published if not s.key.endswith("/events")]

    def by_drone(out: list[Sample]) -> dict[str, list[Sample]]:
        d: dict[str, list[Sample]] = {}
        for s in out:
            d.setdefault(s.key.split("/")[1], []).append(s)
        return d

    assert by_drone(got) == by_drone(want)
    assert service.published == len(want)


def test_an_error_in_one_message_loses_only_its_outputs(monkeypatch: pytest.MonkeyPatch) -> None:
    samples = mixed_input(3)[:800]
    pipe = Pipeline(settings())
    parsed = [p for s, now_s in samples if (p := pipe.validate(s, now_s)) is not None]
    for p in parsed[:200]:
        pipe.process(p, p.received_s)
    # The back pass of two messages raises (DroneEstimator.back, patched on the class).
    from groundstation.estimator.drone import DroneEstimator

    real = DroneEstimator.back
    first, second = (
        next(i for i in range(k, k + 50) if parsed[i].kind == "telemetry") for k in (250, 450)
    )
    boom = {id(parsed[first].message), id(parsed[second].message)}

    def back(self: Any, front: Any, position: Any) -> list[Sample]:
        if id(front.msg) in boom:
            raise RuntimeError("boom")
        return real(self, front, position)

    monkeypatch.setattr(DroneEstimator, "back", back)
    failed: list[Parsed] = []
    out = pipe.process_batch(parsed[200:400], failed.append)
    assert failed == [parsed[first]]
    assert sum(1 for s in out if s.key.endswith("/estimate")) > 150
    with pytest.raises(RuntimeError, match="boom"):  # without a handler it propagates
        pipe.process_batch(parsed[400:600])


def test_follow_stamped_is_replace() -> None:
    from dataclasses import replace

    from groundstation.follow import FollowState

    state = FollowState(reason="disabled", setpoint_world_m=(1.0, 2.0, 3.0), last_stamp_s=0.5)
    new = pipeline_mod._follow_stamped(state, 0.75)
    assert new == replace(state, last_stamp_s=0.75) and new is not state
    assert state.last_stamp_s == 0.5  # the old one untouched
    with pytest.raises(AttributeError):
        new.last_stamp_s = 1.0  # type: ignore[misc]  # still frozen
