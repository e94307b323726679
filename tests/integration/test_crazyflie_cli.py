"""``groundstation crazyflie`` against the fake link, with a real service, over a real router.

Router, service and bridge are separate processes on TCP 127.0.0.1; the fake link
(``--uri fake://...``, test support shipped in the package, not a drone) records every command
it receives to a JSON-lines file that the test reads.
"""

from __future__ import annotations

import itertools
import json
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.integration.harness import Probe, Procs, free_port

pytestmark = [pytest.mark.integration, pytest.mark.slow]


def _commands(path: Path) -> list[dict[str, Any]]:
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def _names(path: Path) -> list[str]:
    return [c["cmd"] for c in _commands(path)]


def _service_status(probe: Probe, drone: str = "cf1") -> dict[str, Any] | None:
    """The service's ``tether/{drone}/status`` (a zenoh query), or None before it knows the
    drone."""
    replies = probe.bus.query(f"tether/{drone}/status", timeout_s=3.0)
    return dict(json.loads(replies[0].payload)) if replies else None


def _start(
    procs: Procs, make_probe: Any, uri: str, *bridge_args: str
) -> tuple[Probe, Any, Any, str]:
    port = free_port()
    procs.router(port)
    probe: Probe = make_probe(port)
    for key in ("tether/cf1/estimate", "tether/cf1/bridge", "tether/cf1/cmd/**"):
        probe.collect(key)
    ep = f"tcp/127.0.0.1:{port}"
    service = procs.groundstation("serve", "serve", "--connect", ep, "--headless")
    bridge = procs.groundstation(
        "bridge", "crazyflie", "--uri", uri, "--drone", "cf1", "--connect", ep, *bridge_args
    )
    return probe, service, bridge, ep


def test_fake_hover_gives_estimates_and_a_stop_reaches_the_link_once(
    procs: Procs, make_probe: Any, tmp_path: Path
) -> None:
    """The default configuration against the fake's current firmware (no pwm group), with
    out-of-order log packets (``ooo``: an old timestamp every 25th period)."""
    record = tmp_path / "commands.jsonl"
    probe, service, bridge, _ = _start(procs, make_probe, f"fake://hover?record={record}&ooo=1")
    probe.wait_for(
        lambda: sum(1 for e in probe.json("tether/cf1/estimate") if e["converged"]) > 300,
        timeout_s=40,
        what="3 s of converged estimates from the bridged fake drone",
    )
    estimates = probe.json("tether/cf1/estimate")
    seqs = [e["seq"] for e in estimates]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
    stamps = [e["stamp_s"] for e in estimates]
    assert all(b > a for a, b in itertools.pairwise(stamps)), "stamps only forward"
    # The bridge drops the old packets and counts them; the service never sees one.
    probe.wait_for(
        lambda: any(s["out_of_order"] >= 5 for s in probe.json("tether/cf1/bridge")),
        timeout_s=10,
        what="the bridge's status counting out-of-order packets",
    )
    status = _service_status(probe)
    assert status is not None and not status["stale"]
    for kind in ("stamp_backwards", "seq_backwards", "seq_repeated"):
        assert status["drops"].get(kind, 0) == 0, status["drops"]
    n_before = len(probe.json("tether/cf1/estimate"))
    probe.wait_for(
        lambda: len(probe.json("tether/cf1/estimate")) > n_before + 100,
        timeout_s=10,
        what="estimates still coming after the out-of-order packets",
    )
    late = [e for e in estimates if e["converged"]][-200:]
    # The fake hovers level with the tether pulling 0.05 N straight down: the service sees
    # exactly that through the bridge's unit conversion (g, deg/s, PWM -> SI).
    vertical = np.median([e["vertical_n"] for e in late])
    horizontal = np.median([e["horizontal_n"] for e in late])
    assert vertical == pytest.approx(0.05, abs=0.01), f"vertical tension {vertical:.4f} N"
    assert horizontal < 0.01
    assert not any(e["on_ground"] for e in late)
    assert "stop_motors" not in _names(record)

    # A Stop on cmd/stop, as the service publishes it.
    stamp = late[-1]["stamp_s"]
    probe.publish_json("tether/cf1/cmd/stop", {"stamp_s": stamp, "reason": "test"})
    probe.wait_for(lambda: "stop_motors" in _names(record), 10, "stop_motors on the link")
    # Latched: a setpoint after it is dropped (the bridge's status counts it).
    probe.publish_json(
        "tether/cf1/cmd/setpoint", {"stamp_s": stamp + 0.1, "position_m": [0.0, 0.0, 0.5]}
    )
    probe.wait_for(
        lambda: any(
            s["latched"] and s["dropped_setpoints"].get("latched", 0) >= 1
            for s in probe.json("tether/cf1/bridge")
        ),
        timeout_s=10,
        what="the bridge reports the latch and the dropped setpoint",
    )
    # The fake drone's motors are off: the service sees a drone on the floor.
    probe.wait_for(
        lambda: any(e["on_ground"] for e in probe.json("tether/cf1/estimate")[-50:]),
        timeout_s=10,
        what="estimates on the ground after the stop",
    )
    names = _names(record)
    assert names.count("stop_motors") == 1
    assert "send_position_setpoint" not in names
    assert bridge.stop(signal.SIGTERM) == 0
    assert _names(record)[-1] == "close"
    assert service.stop(signal.SIGTERM) == 0


def test_tug_to_land_from_the_service_lands_the_fake_drone_once_without_a_lock(
    procs: Procs, make_probe: Any, tmp_path: Path
) -> None:
    record = tmp_path / "commands.jsonl"
    cfg = tmp_path / "bridge.toml"
    # watchdog_s: on a loaded test machine the service's setpoints may trail the telemetry by
    # more than the 0.5 s default, and the bridge would drop them as stale.
    cfg.write_text(
        '[crazyflie]\nmocap_key = "mocap/{drone}"\nmocap_stale_s = 0.5\nwatchdog_s = 2.0\n'
    )
    probe, service, bridge, _ = _start(
        procs, make_probe, f"fake://tug?record={record}", "--config", str(cfg)
    )
    # Motion capture of a drone hovering 0.3 m from the base, 0.7 m up: above the land height.
    done = threading.Event()
    height_m = [0.7]

    def mocap() -> None:
        while not done.wait(0.02):  # a 50 Hz stream
            probe.publish_json("mocap/cf1", {"position_m": [0.3, 0.0, height_m[0]]})

    thread = threading.Thread(target=mocap, daemon=True)
    thread.start()
    try:
        probe.wait_for(
            lambda: (
                sum(
                    1
                    for e in probe.json("tether/cf1/estimate")
                    if e["converged"] and e["position_m"] is not None
                )
                > 200
            ),
            timeout_s=40,
            what="converged estimates",
        )
        late = probe.json("tether/cf1/estimate")[-100:]
        assert np.median([e["vertical_n"] for e in late]) == pytest.approx(0.2, abs=0.02)
        # Follow with tug-to-land: the pull engages it, and the service's setpoints reach
        # the drone while it is above the land height.
        probe.publish_json(
            "tether/cf1/follow", {"enabled": True, "threshold_n": 0.1, "land_below_m": 0.6}
        )
        try:
            probe.wait_for(
                lambda: _names(record).count("send_position_setpoint") >= 10,
                timeout_s=15,
                what="the service's setpoints on the link while following",
            )
        except AssertionError as exc:  # say why: dropped by the bridge, or never sent
            bridge_status = probe.json("tether/cf1/bridge")[-1:]
            raise AssertionError(f"{exc}; bridge status {bridge_status}") from None
        assert "stop_motors" not in _names(record)
        height_m[0] = 0.5  # pulled down below land_below_m: the service stops it
        # tug-to-land's Stop is a landing Stop: down at the landing rate, motors off on the
        # floor, no supervisor emergency stop (which would lock the drone until a power cycle)
        probe.wait_for(
            lambda: "send_stop_setpoint" in _names(record), 20, "the landing's motors off"
        )
        stops = [
            json.loads(s.payload)
            for s in probe.got("tether/cf1/cmd/**")
            if s.key == "tether/cf1/cmd/stop"
        ]
        assert any("tug-to-land" in s["reason"] and s["kind"] == "land" for s in stops)
        probe.wait_for(
            lambda: any(e["on_ground"] for e in probe.json("tether/cf1/estimate")[-50:]),
            timeout_s=10,
            what="the drone on the ground after the stop",
        )
    finally:
        done.set()
        thread.join(2)
    commands = _commands(record)
    names = [c["cmd"] for c in commands]
    assert "stop_motors" not in names, "no emergency stop: nothing locked"
    assert names.count("send_stop_setpoint") == 1
    i_off = names.index("send_stop_setpoint")
    assert "send_position_setpoint" not in names[i_off:], "nothing after the motors off"
    landed = commands[i_off]
    assert landed["position_m"][2] == pytest.approx(0.0, abs=1e-6), "motors off on the floor"
    assert landed["falls"] == 0 and not landed["locked"], "landed, not dropped; not locked"
    assert any(s["phase"] == "landing" for s in probe.json("tether/cf1/bridge"))
    assert bridge.stop(signal.SIGTERM) == 0
    assert service.stop(signal.SIGTERM) == 0


def test_a_killed_service_mid_hover_holds_then_lands_the_fake_drone(
    procs: Procs, make_probe: Any, tmp_path: Path
) -> None:
    """Take off through the bridge, kill ``serve`` (SIGKILL: no goodbye) mid-hover: the bridge
    reports the hold, the landing and the motors off, in that order, and the fake firmware's
    height goes to the floor at the landing rate, without a fall or a lock."""
    record = tmp_path / "commands.jsonl"
    cfg = tmp_path / "bridge.toml"
    cfg.write_text(
        '[crazyflie]\nmocap_key = "mocap/{drone}"\nmocap_stale_s = 0.5\nland_speed_mps = 0.25\n'
    )
    probe, service, bridge, _ = _start(
        procs, make_probe, f"fake://floor?record={record}", "--config", str(cfg)
    )
    done = threading.Event()

    def mocap() -> None:  # the drone on the floor, for the take-off's start
        while not done.wait(0.02):
            probe.publish_json("mocap/cf1", {"position_m": [0.0, 0.0, 0.0]})

    thread = threading.Thread(target=mocap, daemon=True)
    thread.start()
    try:
        probe.wait_for(
            lambda: len(probe.json("tether/cf1/estimate")) > 100, 40, "the service's estimates"
        )
        probe.publish_json("tether/cf1/cmd/takeoff", {"height_m": 0.5, "speed_mps": 0.5})
        probe.wait_for(
            lambda: any(c["position_m"][2] > 0.49 for c in _commands(record)[-5:]),
            20,
            "the fake drone hovering at 0.5 m",
        )
    finally:
        done.set()
        thread.join(2)
    probe.wait_for(
        lambda: probe.json("tether/cf1/bridge")[-1]["phase"] == "flying", 10, "flying reported"
    )
    service.stop(signal.SIGKILL)
    t_kill = time.monotonic()
    probe.wait_for(
        lambda: "send_stop_setpoint" in _names(record), 20, "the bridge's landing, motors off"
    )
    probe.wait_for(
        lambda: probe.json("tether/cf1/bridge")[-1]["phase"] == "idle", 10, "idle reported"
    )
    statuses = probe.json("tether/cf1/bridge")
    phases = [s["phase"] for s in statuses]
    phases = [p for i, p in enumerate(phases) if i == 0 or phases[i - 1] != p]
    assert phases[-4:] == ["flying", "holding", "landing", "idle"], phases
    assert statuses[-1]["motors_off"] and "silent" in statuses[-1]["landing_reason"]
    commands = [c for c in _commands(record) if c["t"] > t_kill]
    off = next(c for c in commands if c["cmd"] == "send_stop_setpoint")
    assert off["position_m"][2] == pytest.approx(0.0, abs=1e-6), "motors off on the floor"
    assert off["falls"] == 0 and not off["locked"], "landed, not dropped; not locked"
    # the descent (the firmware's height, logged with each setpoint): 0.4 m -> 0.1 m
    t_hi = next(c["t"] for c in commands if c["position_m"][2] < 0.4)
    t_lo = next(c["t"] for c in commands if c["position_m"][2] < 0.1)
    assert 0.3 / (t_lo - t_hi) == pytest.approx(0.25, rel=0.25)
    # the hold began within about silence_s + hold_s (0.4 s) of the kill, the landing after
    assert t_hi - t_kill < 0.4 + 0.1 / 0.25 + 1.0
    assert "stop_motors" not in _names(record) and "close" not in _names(record)
    assert bridge.stop(signal.SIGTERM) == 0


def test_a_dropped_link_stops_telemetry_and_reconnects(
    procs: Procs, make_probe: Any, tmp_path: Path
) -> None:
    """A link lost for a few seconds: the bridge stops publishing and reconnects, and a real
    service marks the drone stale meanwhile and estimates again once telemetry resumes."""
    record = tmp_path / "commands.jsonl"
    port = free_port()
    procs.router(port)
    probe: Probe = make_probe(port)
    probe.collect("tether/cf1/telemetry")
    probe.collect("tether/cf1/estimate")
    ep = f"tcp/127.0.0.1:{port}"
    service = procs.groundstation("serve", "serve", "--connect", ep, "--headless")
    deadline = time.monotonic() + 30.0
    while not any(  # the service is up before the drone flies
        r.ok is not None
        for r in probe.bus.session.liveliness().get("groundstation/service/*", timeout=1.0)
    ):
        assert time.monotonic() < deadline, "no service liveliness token"
    bridge = procs.groundstation(
        "bridge",
        "crazyflie",
        "--uri",
        f"fake://hover?record={record}&drop_after_s=3&down_s=2",
        "--drone",
        "cf1",
        "--connect",
        ep,
        "--rate-hz",
        "50",
    )
    probe.wait_for(
        lambda: len(probe.json("tether/cf1/estimate")) > 20,
        timeout_s=30,
        what="estimates before the drop",
    )

    def stale() -> bool:
        status = _service_status(probe)
        return status is not None and status["stale"]

    probe.wait_for(
        lambda: "lost" in _names(record) and stale(),
        timeout_s=15,
        what="the service marking the drone stale once the link dropped",
    )
    before = probe.json("tether/cf1/estimate")
    n_stale = len(before)
    probe.wait_for(
        lambda: (
            _names(record).count("open") >= 3
            and len(probe.json("tether/cf1/estimate")) > n_stale + 50
        ),
        timeout_s=30,
        what="telemetry and estimates again after the link came back",
    )
    probe.wait_for(lambda: not stale(), timeout_s=10, what="the drone no longer stale")
    status = _service_status(probe)
    assert status is not None
    assert status["drops"].get("stamp_backwards", 0) == 0, status["drops"]
    tel = probe.json("tether/cf1/telemetry")
    seqs = [t["seq"] for t in tel]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs))), "seq without gaps or repeats"
    stamps = np.array([t["stamp_s"] for t in tel])
    assert np.all(np.diff(stamps) > 0)
    assert np.median(np.diff(stamps)) == pytest.approx(0.02), "--rate-hz 50: a 20 ms period"
    resumed = probe.json("tether/cf1/estimate")[n_stale:]
    assert all(e["stamp_s"] > before[-1]["stamp_s"] for e in resumed), "of the new telemetry"
    assert bridge.stop(signal.SIGINT) == 0
    out = bridge.output()
    assert out.count(" lost (") == 1, out
    assert "no answer" in out  # the refused reconnection attempt, logged once
    assert service.stop(signal.SIGTERM) == 0


def test_missing_log_variables_fail_at_start_naming_them() -> None:
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "groundstation",
            "crazyflie",
            "--uri",
            "fake://hover?missing=stateEstimate.qz,motor.m2",
            "--drone",
            "cf1",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2, out.stderr
    assert "stateEstimate.qz" in out.stderr and "motor.m2" in out.stderr


def test_a_uri_that_is_not_cflib_fails_at_start() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "groundstation", "crazyflie", "--uri", "bogus://", "--drone", "c"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2 and "not a cflib URI" in out.stderr


def test_the_bridge_over_cflib_udp_to_a_crtp_responder(procs: Procs, make_probe: Any) -> None:
    """The real cflib path (``--uri udp://``) against tests/crtp_firmware.py, which stands in
    for a software-in-the-loop firmware: estimates come, and a Stop reaches it once."""
    from groundstation.bridges.crazyflie.fake import FAKE_TOC, pwm_for_thrust
    from tests.crtp_firmware import CrtpFirmware

    hover_pwm = pwm_for_thrust((0.030 * 9.81 + 0.05) / 4, (2.130295e-11, 1.032633e-6, 5.484560e-4))
    firmware = CrtpFirmware(FAKE_TOC, motor_pwm=round(hover_pwm))
    try:
        probe, service, bridge, _ = _start(procs, make_probe, firmware.uri)
        probe.wait_for(
            lambda: sum(1 for e in probe.json("tether/cf1/estimate") if e["converged"]) > 100,
            timeout_s=40,
            what="converged estimates through cflib",
        )
        late = [e for e in probe.json("tether/cf1/estimate") if e["converged"]][-50:]
        assert np.median([e["vertical_n"] for e in late]) == pytest.approx(0.05, abs=0.01)
        probe.publish_json("tether/cf1/cmd/stop", {"stamp_s": 0.0, "reason": "test"})

        def stops() -> int:
            return sum(1 for ch, d in firmware.packets(0x09) if ch == 1 and d == b"\x03")

        probe.wait_for(lambda: stops() >= 1, 10, "the supervisor's emergency stop")
        probe.wait_for(
            lambda: any(s["latched"] for s in probe.json("tether/cf1/bridge")), 10, "latched"
        )
        assert stops() == 1
        assert bridge.stop(signal.SIGTERM) == 0
        assert service.stop(signal.SIGTERM) == 0
    finally:
        firmware.close()


# ------------------------------------------------------------------ more that goes wrong


def test_one_bridge_process_runs_two_links_served_as_two_drones(
    procs: Procs, make_probe: Any, tmp_path: Path
) -> None:
    """``--uri`` repeated with a ``--drone`` each: one process, two links; the service
    estimates both, and a Stop for one reaches only that link."""
    rec1, rec2 = tmp_path / "cf1.jsonl", tmp_path / "cf2.jsonl"
    port = free_port()
    procs.router(port)
    probe: Probe = make_probe(port)
    for drone in ("cf1", "cf2"):
        probe.collect(f"tether/{drone}/estimate")
        probe.collect(f"tether/{drone}/bridge")
    ep = f"tcp/127.0.0.1:{port}"
    procs.groundstation("serve", "serve", "--connect", ep, "--headless")
    bridge = procs.groundstation(
        "bridge",
        "crazyflie",
        "--uri",
        f"fake://hover?record={rec1}",
        "--drone",
        "cf1",
        "--uri",
        f"fake://tug?record={rec2}",
        "--drone",
        "cf2",
        "--connect",
        ep,
    )
    probe.wait_for(
        lambda: all(
            sum(1 for e in probe.json(f"tether/{d}/estimate") if e["converged"]) > 100
            for d in ("cf1", "cf2")
        ),
        timeout_s=40,
        what="converged estimates of both drones",
    )
    # Each link is its own drone: the hover pulls 0.05 N down, the tug 0.2 N.
    for drone, pull_n in (("cf1", 0.05), ("cf2", 0.20)):
        late = [e for e in probe.json(f"tether/{drone}/estimate") if e["converged"]][-50:]
        assert np.median([e["vertical_n"] for e in late]) == pytest.approx(pull_n, abs=0.01)
    stamp = probe.json("tether/cf1/estimate")[-1]["stamp_s"]
    probe.publish_json("tether/cf1/cmd/stop", {"stamp_s": stamp, "reason": "test"})
    probe.wait_for(lambda: "stop_motors" in _names(rec1), 10, "stop_motors on cf1's link")
    n = len(probe.json("tether/cf2/estimate"))
    probe.wait_for(
        lambda: len(probe.json("tether/cf2/estimate")) > n + 100, 10, "cf2 still estimated"
    )
    assert "stop_motors" not in _names(rec2)
    assert bridge.popen.poll() is None
    bridge.popen.send_signal(signal.SIGINT)
    assert bridge.popen.wait(15) == 0


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "groundstation", "crazyflie", *args],
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_scan_lists_what_answers_and_serial_or_unpaired_uris_are_refused() -> None:
    """``--scan`` connects to nothing: the fakes given answer unless absent; ``serial://``
    fails at once with the reason; a --uri without its --drone is refused."""
    found = _cli("--scan", "--uri", "fake://hover", "--uri", "fake://floor?absent=1")
    assert found.returncode == 0, found.stderr
    assert found.stdout.split() == ["fake://hover"]
    none = _cli("--scan", "--uri", "fake://floor?absent=1")
    assert none.returncode == 1 and "no Crazyflie answered" in none.stderr
    serial = _cli("--uri", "serial://ttyUSB0", "--drone", "cf1")
    assert serial.returncode == 2
    assert "serial:// is not supported" in serial.stderr and "radio://" in serial.stderr
    unpaired = _cli("--uri", "fake://hover", "--uri", "fake://floor", "--drone", "cf1")
    assert unpaired.returncode == 2 and "one --drone per --uri" in unpaired.stderr
    twice = _cli(
        "--uri", "fake://hover", "--drone", "cf1", "--uri", "fake://floor", "--drone", "cf1"
    )
    assert twice.returncode == 2 and "cf1 given twice" in twice.stderr
