"""Integration helpers: real zenoh sessions in separate processes over TCP on 127.0.0.1.

Multicast scouting is off everywhere; every process gets its endpoints explicitly.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from groundstation.bus import Sample
from groundstation.config import ZenohSection
from groundstation.zenoh_bus import ZenohBus

REPO = Path(__file__).resolve().parents[2]
ROUTER_SCRIPT = Path(__file__).with_name("router.py")


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_for_port(port: int, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.settimeout(0.2)
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.05)
    raise TimeoutError(f"nothing listens on 127.0.0.1:{port} after {timeout_s} s")


@dataclass
class Proc:
    """A child process with its output captured to a file."""

    name: str
    popen: subprocess.Popen[bytes]
    log_path: Path

    def output(self) -> str:
        return self.log_path.read_text(errors="replace")

    def stop(self, sig: int = signal.SIGTERM, timeout_s: float = 5.0) -> int:
        if self.popen.poll() is None:
            self.popen.send_signal(sig)
            try:
                self.popen.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait(5)
                raise AssertionError(
                    f"{self.name} did not stop within {timeout_s} s of signal {sig}:\n"
                    + self.output()[-3000:]
                ) from None
        return int(self.popen.returncode)


class Procs:
    """Starts child processes and guarantees they are gone at the end of the test."""

    def __init__(self, tmp_path: Path) -> None:
        self.tmp_path = tmp_path
        self.procs: list[Proc] = []

    def start(self, name: str, args: list[str], env: dict[str, str] | None = None) -> Proc:
        log_path = self.tmp_path / f"{name}.log"
        full_env = dict(os.environ)
        full_env.pop("GROUNDSTATION_ZENOH__CONNECT", None)
        full_env["PYTHONUNBUFFERED"] = "1"
        full_env.update(env or {})
        with log_path.open("wb") as fh:  # the child keeps its own descriptor
            popen = subprocess.Popen(
                args, stdout=fh, stderr=subprocess.STDOUT, env=full_env, cwd=self.tmp_path
            )
        proc = Proc(name, popen, log_path)
        self.procs.append(proc)
        return proc

    def groundstation(self, name: str, *args: str) -> Proc:
        return self.start(name, [sys.executable, "-m", "groundstation", *args])

    def router(self, port: int) -> Proc:
        proc = self.start("router", [sys.executable, str(ROUTER_SCRIPT), f"tcp/127.0.0.1:{port}"])
        wait_for_port(port)
        return proc

    def close(self) -> None:
        for proc in reversed(self.procs):
            if proc.popen.poll() is None:
                proc.popen.kill()
                proc.popen.wait(5)


@pytest.fixture
def procs(tmp_path: Path) -> Iterator[Procs]:
    p = Procs(tmp_path)
    try:
        yield p
    finally:
        p.close()


@dataclass
class Probe:
    """A test's own zenoh client: collects samples and waits on conditions."""

    bus: ZenohBus
    samples: dict[str, list[Sample]] = field(default_factory=dict)
    parsed: dict[str, list[dict[str, Any]]] = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock)
    arrived: threading.Event = field(default_factory=threading.Event)

    def collect(self, keyexpr: str) -> None:
        def handler(sample: Sample) -> None:
            with self.lock:
                self.samples.setdefault(keyexpr, []).append(sample)
            self.arrived.set()

        self.bus.subscribe(keyexpr, handler)

    def got(self, keyexpr: str) -> list[Sample]:
        with self.lock:
            return list(self.samples.get(keyexpr, []))

    def json(self, keyexpr: str) -> list[dict[str, Any]]:
        """Parsed payloads (each parsed once, cached)."""
        raw = self.got(keyexpr)
        cache = self.parsed.setdefault(keyexpr, [])
        cache.extend(json.loads(s.payload) for s in raw[len(cache) :])
        return list(cache)

    def wait_for(self, predicate: Callable[[], bool], timeout_s: float, what: str) -> None:
        """Re-check ``predicate`` as samples arrive (at most every 0.2 s) until ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while not predicate():
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
            self.arrived.wait(min(remaining, 0.2))
            self.arrived.clear()
            time.sleep(min(0.2, max(0.0, deadline - time.monotonic())))  # batch re-checks

    def publish_json(self, key: str, payload: dict[str, Any]) -> None:
        self.bus.publish(key, json.dumps(payload).encode())


@pytest.fixture
def make_probe() -> Iterator[Callable[[int], Probe]]:
    buses: list[ZenohBus] = []

    def factory(port: int) -> Probe:
        bus = ZenohBus(ZenohSection(mode="client", connect=(f"tcp/127.0.0.1:{port}",)))
        buses.append(bus)
        return Probe(bus)

    try:
        yield factory
    finally:
        for bus in buses:
            bus.close()
