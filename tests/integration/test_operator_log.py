"""The operator action log over real zenoh: a service process behind a router tells a
client why its commands were refused, names the client by its zenoh id, logs one line per
action, and counts its peers in ``status``."""

from __future__ import annotations

import signal
import time
from typing import Any

import pytest

from tests.integration.harness import Probe, Procs, free_port
from tests.integration.test_service_robustness import GOOD, _status, _wait_alive

pytestmark = [pytest.mark.integration]


def test_refusals_and_stops_reach_the_sender_with_its_id(procs: Procs, make_probe: Any) -> None:
    port = free_port()
    procs.router(port)
    probe: Probe = make_probe(port)
    serve = procs.groundstation(
        "serve", "serve", "--connect", f"tcp/127.0.0.1:{port}", "--headless"
    )
    probe.collect("tether/*/events")
    _wait_alive(probe)
    me = probe.bus.zid

    # Follow for a drone that does not exist yet: refused, and the sender hears why.
    probe.publish_json("tether/cf9/follow", {"enabled": True})
    probe.wait_for(lambda: len(probe.json("tether/*/events")) >= 1, 10, "a rejection")
    (refused,) = probe.json("tether/*/events")
    assert refused["kind"] == "rejected" and refused["field"] == "enabled"
    assert refused["who"] == me, "who: the sender's zenoh session id"

    # cf9 starts flying: it is not in follow mode.
    for seq in range(100):
        probe.publish_json("tether/cf9/telemetry", GOOD | {"seq": seq, "stamp_s": seq * 0.004})
    probe.wait_for(lambda: _status(probe, "cf9")["accepted"] >= 100, 10, "100 accepted")
    status = _status(probe, "cf9")
    assert status["follow"]["enabled"] is False
    assert status["peers"] >= 1, "the router is counted"

    # A typo and an operator's Stop, each told and logged.
    probe.publish_json("tether/cf9/follow", {"enable": True})
    probe.publish_json("tether/cf9/cmd/stop", {"stamp_s": 1.0, "reason": "operator"})
    probe.wait_for(lambda: len(probe.json("tether/*/events")) >= 3, 10, "two more events")
    # Two keys, two subscriptions: their events may come in either order.
    later = probe.json("tether/*/events")[1:3]
    (typo,) = [e for e in later if e["kind"] == "rejected"]
    (stop,) = [e for e in later if e["kind"] != "rejected"]
    assert typo["kind"] == "rejected" and "'enable'" in typo["reason"]
    assert stop["kind"] == "stop" and stop["reason"] == "operator" and stop["who"] == me

    assert serve.stop(signal.SIGTERM) == 0
    log = serve.output()
    actions = [line for line in log.splitlines() if "groundstation.actions" in line]
    assert len(actions) == 3, actions
    assert sum(f"cf9 stop on cmd/stop from {me}: operator" in a for a in actions[1:]) == 1
    assert "connected to 1 zenoh peer(s)/router(s)" in log


@pytest.mark.parametrize(
    "command",
    [["serve", "--headless"], ["sim", "--scenario", "hover"], ["record", "--out", "alone.mcap"]],
    ids=["serve", "sim", "record"],
)
def test_a_process_alone_says_no_router_is_reachable(procs: Procs, command: list[str]) -> None:
    port = free_port()
    # Peer mode keeps trying in the background: it starts, and says what is missing.
    proc = procs.groundstation(
        command[0], *command, "--mode", "peer", "--connect", f"tcp/127.0.0.1:{port}"
    )
    deadline = time.monotonic() + 20.0
    while "no peer / no router reachable" not in proc.output():
        assert time.monotonic() < deadline, proc.output()
        assert proc.popen.poll() is None, proc.output()
        time.sleep(0.1)  # polling a log file
    assert f"groundstation {command[0]}: no peer / no router reachable" in proc.output()
    assert f"reachable at tcp/127.0.0.1:{port}" in proc.output()
    assert proc.stop(signal.SIGINT) == 0
