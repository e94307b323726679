"""TLS, mutual TLS and access control on the router, with the example configs of ``config/``.

A throwaway CA, router and client certificates are made with ``openssl`` per test session
(no private key is ever committed). The router is ``router.py`` (zenohd stand-in) loading
``config/tls/router-*.json5`` and ``config/acl-router.json5``; clients are separate processes
loading ``config/tls/client-*.json5``; only the certificate paths and endpoints are overridden.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.integration.test_record_cli import REPO, ROUTER, Proc, free_port

pytestmark = [
    pytest.mark.integration,
    pytest.mark.skipif(shutil.which("openssl") is None, reason="needs the openssl command"),
]

CONFIG = REPO / "config"

# A zenoh client: opens a session (exit 2 and "open-failed" when it cannot connect), then
# either subscribes and prints "got KEY PAYLOAD" per sample, or puts the given samples in
# order, each once a subscriber matches, and prints "sent". Holds the session until stdin closes.
CLIENT = r"""
import json, sys, threading, time
import zenoh

spec = json.loads(sys.argv[1])
conf = zenoh.Config.from_file(spec["config"]) if spec.get("config") else zenoh.Config()
conf.insert_json5("mode", '"client"')
conf.insert_json5("connect/endpoints", json.dumps([spec["connect"]]))
conf.insert_json5("scouting/multicast/enabled", "false")
for path, value in spec.get("set", {}).items():
    conf.insert_json5(path, json.dumps(value))
lock = threading.Lock()

def say(line):
    with lock:
        sys.stdout.write(line + "\n")
        sys.stdout.flush()

try:
    session = zenoh.open(conf)
except zenoh.ZError as exc:
    say(f"open-failed {exc}")
    sys.exit(2)
try:
    if spec["role"] == "sub":
        subs = [session.declare_subscriber(
                    k, lambda s: say(f"got {s.key_expr} {s.payload.to_string()}"))
                for k in spec["keys"]]
        say("ready")
    else:
        for key, payload in spec["puts"]:
            pub = session.declare_publisher(key)
            deadline = time.monotonic() + 10.0
            while not pub.matching_status.matching and time.monotonic() < deadline:
                time.sleep(0.01)  # polling a status
            pub.put(payload)
        say("sent")
    sys.stdin.read()
finally:
    session.close()
"""


def openssl(*args: str) -> None:
    subprocess.run(["openssl", *args], check=True, capture_output=True, timeout=60)


def make_ca(directory: Path, name: str) -> tuple[Path, Path]:
    key, cert = directory / f"{name}.key", directory / f"{name}.pem"
    # fmt: off
    openssl("req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1",
            "-nodes", "-keyout", str(key), "-out", str(cert), "-days", "2",
            "-subj", f"/CN={name}",
            "-addext", "basicConstraints=critical,CA:TRUE",
            "-addext", "keyUsage=critical,keyCertSign,cRLSign")
    # fmt: on
    return key, cert


def make_leaf(
    directory: Path, ca: tuple[Path, Path], name: str, *, server: bool = False
) -> tuple[Path, Path]:
    """A certificate with common name ``name`` signed by ``ca``: ``(key, cert)``."""
    key, csr, cert = (directory / f"{name}.{ext}" for ext in ("key", "csr", "pem"))
    ext = directory / f"{name}.ext"
    san = "IP:127.0.0.1,DNS:localhost" if server else f"DNS:{name}"
    ext.write_text(
        "basicConstraints=CA:FALSE\n"
        "keyUsage=critical,digitalSignature\n"
        f"extendedKeyUsage={'serverAuth' if server else 'clientAuth'}\n"
        f"subjectAltName={san}\n"
    )
    # fmt: off
    openssl("req", "-new", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1",
            "-nodes", "-keyout", str(key), "-out", str(csr), "-subj", f"/CN={name}")
    openssl("x509", "-req", "-in", str(csr), "-CA", str(ca[1]), "-CAkey", str(ca[0]),
            "-CAcreateserial", "-out", str(cert), "-days", "2", "-extfile", str(ext))
    # fmt: on
    return key, cert


class Pki:
    def __init__(self, directory: Path) -> None:
        self.ca = make_ca(directory, "test-ca")
        self.router = make_leaf(directory, self.ca, "router", server=True)
        self.clients = {
            cn: make_leaf(directory, self.ca, cn)
            for cn in ("groundstation", "operator", "observer", "cf1")
        }
        rogue_dir = directory / "rogue"
        rogue_dir.mkdir()
        self.rogue_ca = make_ca(rogue_dir, "rogue-ca")
        self.rogue = make_leaf(rogue_dir, self.rogue_ca, "groundstation")


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> Pki:
    return Pki(tmp_path_factory.mktemp("pki"))


def start_router(pki: Pki, config: str, *, acl: bool = False) -> tuple[Proc, str]:
    port = free_port()
    endpoint = f"tls/127.0.0.1:{port}"
    tls = "transport/link/tls"
    args = [
        sys.executable,
        str(ROUTER),
        "--listen",
        endpoint,
        "--config",
        str(CONFIG / "tls" / config),
        "--set",
        f"{tls}/listen_private_key={json.dumps(str(pki.router[0]))}",
        "--set",
        f"{tls}/listen_certificate={json.dumps(str(pki.router[1]))}",
    ]
    if config == "router-mtls.json5":
        args += ["--set", f"{tls}/root_ca_certificate={json.dumps(str(pki.ca[1]))}"]
    if acl:
        args += ["--acl", str(CONFIG / "acl-router.json5")]
    proc = Proc(args)
    try:
        proc.wait_line("ready", 20.0)
    except BaseException:
        proc.stop()
        raise
    return proc, endpoint


def client(
    endpoint: str,
    *,
    role: str,
    config: str | None,
    ca: Path | None = None,
    cert: tuple[Path, Path] | None = None,
    keys: tuple[str, ...] = ("tether/**",),
    puts: tuple[tuple[str, str], ...] = (),
) -> Proc:
    overrides: dict[str, object] = {}
    if ca is not None:
        overrides["transport/link/tls/root_ca_certificate"] = str(ca)
    if cert is not None:
        overrides["transport/link/tls/connect_private_key"] = str(cert[0])
        overrides["transport/link/tls/connect_certificate"] = str(cert[1])
    spec = {
        "connect": endpoint,
        "config": str(CONFIG / "tls" / config) if config else None,
        "set": overrides,
        "role": role,
        "keys": list(keys),
        "puts": [list(p) for p in puts],
    }
    return Proc([sys.executable, "-c", CLIENT, json.dumps(spec)], stdin=True)


def assert_cannot_connect(proc: Proc) -> None:
    proc.wait_line("open-failed", 30.0)
    assert proc.wait(10.0) == 2


def received(proc: Proc) -> list[str]:
    out = []
    while not proc.lines.empty():
        out.append(proc.lines.get_nowait())
    return out


@pytest.fixture
def procs() -> Iterator[list[Proc]]:
    started: list[Proc] = []
    try:
        yield started
    finally:
        for proc in reversed(started):
            proc.stop()


def test_tls_server_authentication(pki: Pki, procs: list[Proc]) -> None:
    router, endpoint = start_router(pki, "router-tls.json5")
    procs.append(router)
    sub = client(endpoint, role="sub", config="client-tls.json5", ca=pki.ca[1])
    procs.append(sub)
    sub.wait_line("ready", 30.0)
    pub = client(
        endpoint,
        role="pub",
        config="client-tls.json5",
        ca=pki.ca[1],
        puts=(("tether/cf1/telemetry", "over-tls"),),
    )
    procs.append(pub)
    pub.wait_line("sent", 30.0)
    assert sub.wait_line("got", 15.0) == "got tether/cf1/telemetry over-tls"

    # Without our CA the client trusts only the public web roots: the router is refused.
    stranger = client(endpoint, role="sub", config=None)
    procs.append(stranger)
    assert_cannot_connect(stranger)
    # A router certificate from another CA is refused as well.
    wrong_ca = client(endpoint, role="sub", config="client-tls.json5", ca=pki.rogue_ca[1])
    procs.append(wrong_ca)
    assert_cannot_connect(wrong_ca)


def test_mutual_tls(pki: Pki, procs: list[Proc]) -> None:
    router, endpoint = start_router(pki, "router-mtls.json5")
    procs.append(router)
    sub = client(
        endpoint,
        role="sub",
        config="client-mtls.json5",
        ca=pki.ca[1],
        cert=pki.clients["groundstation"],
    )
    procs.append(sub)
    sub.wait_line("ready", 30.0)
    pub = client(
        endpoint,
        role="pub",
        config="client-mtls.json5",
        ca=pki.ca[1],
        cert=pki.clients["operator"],
        puts=(("tether/cf1/follow", '{"enabled":true}'),),
    )
    procs.append(pub)
    pub.wait_line("sent", 30.0)
    assert sub.wait_line("got", 15.0) == 'got tether/cf1/follow {"enabled":true}'

    # No client certificate (server-auth-only client config): refused.
    anonymous = client(endpoint, role="sub", config="client-tls.json5", ca=pki.ca[1])
    procs.append(anonymous)
    assert_cannot_connect(anonymous)
    # A client certificate from another CA, even with a trusted name: refused.
    rogue = client(endpoint, role="sub", config="client-mtls.json5", ca=pki.ca[1], cert=pki.rogue)
    procs.append(rogue)
    assert_cannot_connect(rogue)


def test_acl_operators_stop_the_ground_station_steers(pki: Pki, procs: list[Proc]) -> None:
    router, endpoint = start_router(pki, "router-mtls.json5", acl=True)
    procs.append(router)

    def mtls(
        cn: str,
        role: str,
        keys: tuple[str, ...] = ("tether/**",),
        puts: tuple[tuple[str, str], ...] = (),
    ) -> Proc:
        proc = client(
            endpoint,
            role=role,
            config="client-mtls.json5",
            ca=pki.ca[1],
            cert=pki.clients[cn],
            keys=keys,
            puts=puts,
        )
        procs.append(proc)
        return proc

    sub = mtls("groundstation", role="sub", keys=("tether/**", "acl-test/**"))
    sub.wait_line("ready", 30.0)

    # Denied puts followed by allowed ones from the same session: the router handles one
    # link's messages in order, so once the allowed ones have arrived the denied ones would
    # have arrived before them.
    operator = mtls(
        "operator",
        role="pub",
        puts=(
            ("tether/cf1/cmd/setpoint", '{"stamp_s":1.0,"position_m":[0,0,1]}'),
            ("tether/cf1/estimate", '{"forged":true}'),
            ("tether/cf1/events", '{"forged":true}'),
            ("tether/cf1/cmd/stop", '{"stamp_s":1.0,"reason":"operator"}'),
            ("tether/cf2/cmd/stop", '{"stamp_s":1.0,"reason":"operator"}'),
            ("tether/cf1/follow", '{"enabled":false}'),
        ),
    )
    operator.wait_line("sent", 30.0)
    # The operator role stops every drone (the dashboard's emergency Stop) ...
    lines = [sub.wait_line("got", 15.0) for _ in range(3)]
    assert lines == [
        'got tether/cf1/cmd/stop {"stamp_s":1.0,"reason":"operator"}',
        'got tether/cf2/cmd/stop {"stamp_s":1.0,"reason":"operator"}',
        'got tether/cf1/follow {"enabled":false}',
    ], lines
    # ... but setpoints, estimates and events stay the ground station's.

    # A drone's certificate may not command anything, not even a Stop.
    drone = mtls(
        "cf1",
        role="pub",
        puts=(
            ("tether/cf2/cmd/stop", '{"stamp_s":1.5,"reason":"forged"}'),
            ("acl-test/marker", "cf1"),
        ),
    )
    drone.wait_line("sent", 30.0)
    line = sub.wait_line("got", 15.0)
    assert line == "got acl-test/marker cf1", line

    ground_station = mtls(
        "groundstation",
        role="pub",
        puts=(("tether/cf1/cmd/stop", '{"stamp_s":2.0,"reason":"tug"}'),),
    )
    ground_station.wait_line("sent", 30.0)
    line = sub.wait_line("got", 15.0)
    assert line == 'got tether/cf1/cmd/stop {"stamp_s":2.0,"reason":"tug"}', line

    observer = mtls(
        "observer",
        role="pub",
        puts=(("tether/cf1/follow", '{"enabled":true}'), ("acl-test/marker", "observer")),
    )
    observer.wait_line("sent", 30.0)
    line = sub.wait_line("got", 15.0)
    assert line == "got acl-test/marker observer", line
    assert not [x for x in received(sub) if x.startswith("got tether/")]
