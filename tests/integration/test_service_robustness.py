"""The service against bad input, signals, health queries and a second instance, over TCP."""

from __future__ import annotations

import json
import math
import signal
import time
import urllib.request
from typing import Any

import pytest
import zenoh

from tests.integration.harness import Probe, Procs, free_port

pytestmark = [pytest.mark.integration, pytest.mark.slow]

GOOD = {
    "seq": 0,
    "stamp_s": 0.0,
    "accel_mps2": [0.0, 0.0, 11.0],
    "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
    "thrust_n": 0.33,
}


def _router_and_service(procs: Procs, make_probe: Any, *serve_args: str) -> tuple[Probe, str]:
    port = free_port()
    procs.router(port)
    probe: Probe = make_probe(port)
    ep = f"tcp/127.0.0.1:{port}"
    procs.groundstation("serve", "serve", "--connect", ep, "--headless", *serve_args)
    return probe, ep


def _wait_alive(probe: Probe, timeout_s: float = 20.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        replies = probe.bus.session.liveliness().get("groundstation/service/*", timeout=1.0)
        if any(r.ok is not None for r in replies):
            return
    raise AssertionError("no service liveliness token")


def _status(probe: Probe, drone: str) -> dict[str, Any]:
    replies = probe.bus.query(f"tether/{drone}/status", timeout_s=3.0)
    assert len(replies) == 1, replies
    return dict(json.loads(replies[0].payload))


def _bad_payloads() -> list[tuple[str, bytes]]:
    big = json.dumps(GOOD | {"pad": "x" * 2_000_000}).encode()
    return [
        ("tether/cf1/telemetry", b"this is not json"),
        ("tether/cf1/telemetry", b'{"seq": 1}'),
        ("tether/cf1/telemetry", json.dumps(GOOD | {"accel_mps2": [0.0, 9.81]}).encode()),
        ("tether/cf1/telemetry", json.dumps(GOOD | {"thrust_n": -0.1}).encode()),
        ("tether/cf1/telemetry", json.dumps(GOOD | {"quat_wxyz": [0, 0, 0, 0]}).encode()),
        ("tether/cf1/telemetry", json.dumps(GOOD | {"thrust_n": math.nan}).encode()),
        ("tether/cf1/telemetry", json.dumps(GOOD | {"accel_mps2": [math.inf, 0, 9.8]}).encode()),
        ("tether/cf1/telemetry", json.dumps(GOOD | {"seq": 0, "stamp_s": 0.0}).encode()),
        ("tether/cf1/reel", b'{"stamp_s": 0, "length_m": -1.0}'),
        ("tether/cf1/follow", b'{"enabled": "please"}'),
        ("tether/bad.id/telemetry", json.dumps(GOOD).encode()),
        ("tether/" + "x" * 70 + "/telemetry", json.dumps(GOOD).encode()),
        # Last in a round: its fragments fill the transport's queues for a moment.
        ("tether/cf1/telemetry", big),
    ]


def test_bad_input_mixed_into_a_flight(procs: Procs, make_probe: Any) -> None:
    probe, ep = _router_and_service(procs, make_probe)
    for key in ("tether/*/estimate", "tether/*/truth", "tether/*/cmd/**"):
        probe.collect(key)
    _wait_alive(probe)
    procs.groundstation(
        "sim", "sim", "--connect", ep, "--scenario", "hover", "--drones", "cf1", "--no-mocap"
    )
    probe.wait_for(lambda: len(probe.got("tether/*/estimate")) > 500, 30, "estimates")
    for _ in range(5):  # several rounds of every kind, mixed into the live stream
        for key, payload in _bad_payloads():
            # Blocking congestion control: the default (drop) may lose a sample queued
            # behind the 2 MB one, and the counts below are of what the service received.
            probe.bus.session.put(key, payload, congestion_control=zenoh.CongestionControl.BLOCK)
        time.sleep(0.1)
    n0 = len(probe.got("tether/*/truth"))
    probe.wait_for(lambda: len(probe.got("tether/*/truth")) > n0 + 1000, 30, "4 s more flight")
    status = _status(probe, "cf1")
    drops = status["drops"]
    for kind in ("not_json", "invalid", "bad_quaternion", "too_large", "seq_backwards"):
        assert drops.get(kind, 0) >= 5, (kind, drops)
    assert status["stale"] is False
    estimates = probe.json("tether/*/estimate")
    for e in estimates:
        assert e["tension_n"] and all(math.isfinite(v) for v in e["tension_n"])
        assert all(math.isfinite(v) for v in e["tension_std_n"])
        assert e["position_m"] is None or all(math.isfinite(v) for v in e["position_m"])
    truth = probe.json("tether/*/truth")
    # Estimates may trail the truth stream on a busy machine: leave the last second out.
    last_s = max(t["stamp_s"] for t in truth)
    window = {round(t["stamp_s"], 6) for t in truth if 2.0 < t["stamp_s"] < last_s - 1.0}
    estimated = {round(e["stamp_s"], 6) for e in estimates} & window
    assert len(estimated) >= 0.98 * len(window), f"{len(estimated)}/{len(window)} estimated"
    assert not probe.got("tether/*/cmd/**"), "no commands without follow mode"


def test_silence_makes_the_drone_stale_and_publishes_nothing(procs: Procs, make_probe: Any) -> None:
    probe, _ = _router_and_service(procs, make_probe)
    probe.collect("tether/*/estimate")
    probe.collect("tether/*/cmd/**")
    probe.collect("tether/*/events")
    _wait_alive(probe)
    for seq in range(50):
        # with motion capture: without it (and uncalibrated) follow would be refused outright
        tel = GOOD | {"seq": seq, "stamp_s": seq * 0.004, "position_m": [1.0, 0.0, 1.0]}
        probe.publish_json("tether/q1/telemetry", tel)
        time.sleep(0.004)
    probe.publish_json("tether/q1/follow", {"enabled": True})
    probe.wait_for(lambda: len(probe.got("tether/*/estimate")) >= 50, 10, "50 estimates")
    probe.wait_for(
        lambda: any(e["kind"] == "follow" for e in probe.json("tether/*/events")),
        10,
        "the premise: follow switched on",
    )
    n = len(probe.got("tether/*/estimate"))
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline and not _status(probe, "q1")["stale"]:
        time.sleep(0.1)
    status = _status(probe, "q1")
    assert status["stale"] is True
    assert status["follow"]["enabled"] is False, "stale data disengages follow mode"
    assert len(probe.got("tether/*/estimate")) == n, "nothing published during a silence"
    assert not probe.got("tether/*/cmd/**")


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
@pytest.mark.parametrize("headless", [True, False])
def test_signals_end_the_service_with_exit_0_within_2_s(
    procs: Procs, make_probe: Any, sig: int, headless: bool
) -> None:
    args = ["--headless"] if headless else ["--web-port", str(free_port())]
    port = free_port()
    procs.router(port)
    probe: Probe = make_probe(port)
    serve = procs.groundstation("serve", "serve", "--connect", f"tcp/127.0.0.1:{port}", *args)
    _wait_alive(probe)
    probe.publish_json("tether/s1/telemetry", GOOD)  # a declared subscriber has fired
    if not headless:
        # The dashboard runs in its own process (a bus client): it answers, then goes
        # down with the service.
        url = f"http://127.0.0.1:{args[1]}"
        deadline = time.monotonic() + 30
        while f"dashboard: {url}" not in serve.output():
            assert time.monotonic() < deadline, serve.output()
            time.sleep(0.1)
        with urllib.request.urlopen(url, timeout=10) as resp:
            assert resp.status == 200
    t0 = time.monotonic()
    serve.popen.send_signal(sig)
    code = serve.popen.wait(10)
    elapsed = time.monotonic() - t0
    assert code == 0, serve.output()[-2000:]
    assert elapsed < 2.0, f"took {elapsed:.2f} s"
    if not headless:
        with pytest.raises(OSError):  # the dashboard process is gone too
            urllib.request.urlopen(f"http://127.0.0.1:{args[1]}", timeout=2)


def test_two_instances_split_the_drones(procs: Procs, make_probe: Any) -> None:
    port = free_port()
    procs.router(port)
    probe: Probe = make_probe(port)
    ep = f"tcp/127.0.0.1:{port}"
    probe.collect("tether/*/estimate")
    procs.groundstation("serve_a", "serve", "--connect", ep, "--headless", "--drones", "lab-a-*")
    procs.groundstation("serve_b", "serve", "--connect", ep, "--headless", "--drones", "lab-b-*")
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        tokens = probe.bus.session.liveliness().get("groundstation/service/*", timeout=1.0)
        if sum(1 for r in tokens if r.ok is not None) == 2:
            break
    drones = ("lab-a-1", "lab-a-2", "lab-b-1")
    for seq in range(200):
        for d in drones:
            probe.publish_json(f"tether/{d}/telemetry", GOOD | {"seq": seq, "stamp_s": seq * 0.004})
        time.sleep(0.002)
    probe.wait_for(lambda: len(probe.got("tether/*/estimate")) >= 600, 20, "600 estimates")
    time.sleep(0.5)  # a duplicate, if any, would arrive now
    seen: dict[tuple[str, int], int] = {}
    for s in probe.got("tether/*/estimate"):
        key = (s.key.split("/")[1], json.loads(s.payload)["seq"])
        seen[key] = seen.get(key, 0) + 1
    assert len(seen) == 600 and set(seen.values()) == {1}, "every drone estimated exactly once"
    owners = {d: _status(probe, d)["service"] for d in drones}
    assert owners["lab-a-1"] == owners["lab-a-2"] != owners["lab-b-1"]
    # A third instance whose slice overlaps theirs refuses to start (two services would
    # both command those drones), says whose drones they are, and exits 2.
    for i, slice_ in enumerate(("lab-*", "*")):
        late = procs.groundstation(
            f"late{i}", "serve", "--connect", ep, "--headless", "--drones", slice_
        )
        assert late.popen.wait(30) == 2, late.output()[-2000:]
        out = late.output()
        assert "overlap another service" in out and f"instance {owners['lab-a-1']} owns" in out
        assert "Traceback" not in out


def test_serve_records_the_bus_in_process(procs: Procs, make_probe: Any, tmp_path: Any) -> None:
    from groundstation.recording import is_complete, iter_messages

    out = tmp_path / "session.mcap"
    probe, _ = _router_and_service(procs, make_probe, "--record", str(out))
    probe.collect("tether/*/estimate")
    _wait_alive(probe)
    for seq in range(100):
        probe.publish_json("tether/r1/telemetry", GOOD | {"seq": seq, "stamp_s": seq * 0.004})
        time.sleep(0.002)
    probe.wait_for(lambda: len(probe.got("tether/*/estimate")) >= 100, 10, "100 estimates")
    serve = next(p for p in procs.procs if p.name == "serve")
    assert serve.stop(signal.SIGTERM) == 0
    assert is_complete(out)
    by_key: dict[str, list[int]] = {}
    for msg in iter_messages(out):
        by_key.setdefault(msg.key, []).append(json.loads(msg.payload)["seq"])
    assert by_key["tether/r1/telemetry"] == list(range(100))
    assert by_key["tether/r1/estimate"] == list(range(100))
