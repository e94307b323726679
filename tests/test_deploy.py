"""Deployment files: compose file, Dockerfile, router/TLS/ACL configs, reel.toml, systemd unit.

No Docker engine runs here: the compose file is validated with the compose CLI when one is
installed (``docker compose`` or Debian's ``docker-compose``) and its structure is checked
from the text (PyYAML is not a dependency). The healthcheck script from the compose file is
run for real against a router-mode session and a liveliness token in separate processes.
"""

from __future__ import annotations

import importlib.metadata
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from groundstation.cli import build_parser
from groundstation.config import load_settings

REPO = Path(__file__).resolve().parents[1]
COMPOSE = REPO / "docker-compose.yml"
DOCKERFILE = REPO / "Dockerfile"


# --------------------------------------------------------------------------- compose


def compose_cli() -> list[str] | None:
    """``docker compose`` (v2 plugin) or ``docker-compose`` (Debian package), if usable."""
    candidates = [["docker", "compose"], ["docker-compose"]]
    for cmd in candidates:
        if shutil.which(cmd[0]) is None:
            continue
        probe = subprocess.run([*cmd, "version"], capture_output=True, text=True, timeout=60)
        if probe.returncode == 0:
            return cmd
    return None


def services() -> dict[str, list[str]]:
    """Top-level service blocks of the compose file, as lists of their lines."""
    blocks: dict[str, list[str]] = {}
    current: list[str] | None = None
    in_services = False
    for line in COMPOSE.read_text().splitlines():
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        if not line.startswith(" "):
            in_services = line.rstrip() == "services:"
            current = None
            continue
        if not in_services:
            continue
        m = re.fullmatch(r"  ([A-Za-z0-9_-]+):\s*", line)
        if m:
            current = blocks.setdefault(m.group(1), [])
        elif current is not None:
            current.append(line)
    return blocks


def block_value(lines: list[str], key: str) -> list[str]:
    """The lines nested under ``key:`` (4-space level) of a service block."""
    out: list[str] = []
    inside = False
    for line in lines:
        if re.match(rf"    {key}:", line):
            inside = True
            rest = line.split(":", 1)[1].strip()
            if rest:
                out.append(rest)
            continue
        if inside:
            if re.match(r"    \S", line):
                break
            out.append(line)
    return out


def command_of(service: str) -> list[str]:
    value = block_value(services()[service], "command")
    if len(value) == 1 and value[0].startswith("["):
        return [str(x) for x in json.loads(value[0])]
    return [line.strip()[2:].strip() for line in value if line.strip().startswith("- ")]


def test_compose_file_validates_with_the_compose_cli() -> None:
    cmd = compose_cli()
    if cmd is None:
        pytest.skip("no compose CLI: apt-get install docker-compose (validates offline)")
    for extra in ([], ["--profile", "sim"]):
        run = subprocess.run(
            [*cmd, "-f", str(COMPOSE), *extra, "config", "-q"],
            capture_output=True,
            text=True,
            timeout=120,
            cwd=REPO,
        )
        assert run.returncode == 0, run.stderr


def test_compose_services_and_profiles() -> None:
    blocks = services()
    assert set(blocks) == {"zenohd", "groundstation", "sim"}
    # A real deployment runs without the simulator: only `--profile sim` starts it.
    assert block_value(blocks["sim"], "profiles") == ['["sim"]']
    assert not block_value(blocks["zenohd"], "profiles")
    assert not block_value(blocks["groundstation"], "profiles")
    for name, lines in blocks.items():
        assert block_value(lines, "restart") == ["unless-stopped"], name
    assert block_value(blocks["groundstation"], "healthcheck")


def test_zenoh_image_is_pinned_to_the_python_binding_version() -> None:
    images = re.findall(r"image:\s*(\S+)", COMPOSE.read_text())
    zenoh_images = [i for i in images if i.startswith("eclipse/zenoh")]
    assert zenoh_images == [f"eclipse/zenoh:{importlib.metadata.version('eclipse-zenoh')}"]


def test_host_ports_bind_loopback_only() -> None:
    ports = re.findall(r'^\s+- "([^"]+)"\s*$', COMPOSE.read_text(), flags=re.M)
    published = [p for p in ports if re.fullmatch(r"[\d.]+:\d+:\d+(/\w+)?", p)]
    assert sorted(published) == ["127.0.0.1:7447:7447/tcp", "127.0.0.1:8080:8080/tcp"]


@pytest.mark.parametrize("service", ["groundstation", "sim"])
def test_compose_commands_parse_with_the_cli(service: str) -> None:
    args = build_parser().parse_args(command_of(service))
    assert args.connect == ["tcp/zenohd:7447"]
    if service == "groundstation":
        assert args.command == "serve"
        assert args.config == "/etc/groundstation/reel.toml"
        assert args.web_host == "0.0.0.0"
    else:
        assert args.command == "sim"


def test_zenohd_command_loads_the_mounted_config() -> None:
    zenohd = services()["zenohd"]
    assert command_of("zenohd") == ["-c", "/etc/zenoh/zenohd.json5"]
    assert "      - ./config/zenohd.json5:/etc/zenoh/zenohd.json5:ro" in zenohd


# --------------------------------------------------------------------------- Dockerfile


def dockerfile_instructions() -> list[tuple[str, str]]:
    text = DOCKERFILE.read_text().replace("\\\n", " ")
    out = []
    for line in text.splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            op, _, rest = line.partition(" ")
            out.append((op.upper(), rest.strip()))
    return out


def test_dockerfile_slim_python_311_non_root_hash_pinned() -> None:
    ins = dockerfile_instructions()
    froms = [rest for op, rest in ins if op == "FROM"]
    assert froms and re.fullmatch(r"python:3\.11(\.\d+)?-slim(-\w+)?", froms[-1])
    runs = " ".join(rest for op, rest in ins if op == "RUN")
    assert "--require-hashes -r requirements-runtime.lock" in runs
    assert re.search(r"pip install --no-deps[^&]* \.", runs)
    users = [(i, rest) for i, (op, rest) in enumerate(ins) if op == "USER"]
    assert users, "the image must not run as root"
    last_user_index, user = users[-1]
    assert user.split(":")[0] not in {"root", "0"}
    # Everything after the USER line runs unprivileged, including the entrypoint.
    assert all(op != "RUN" for op, _ in ins[last_user_index:])
    assert ("ENTRYPOINT", '["groundstation"]') in ins


def test_dockerignore_keeps_keys_out_of_the_image() -> None:
    lines = (REPO / ".dockerignore").read_text().splitlines()
    assert "*" in lines  # allow-list: only what is re-included below reaches the build
    assert "config/tls/*.key" in lines
    assert "!groundstation/" in lines and "!requirements-runtime.lock" in lines


# --------------------------------------------------------------------------- configs


@pytest.mark.parametrize(
    "path",
    [
        "config/zenohd.json5",
        "config/acl-router.json5",
        "config/tls/router-tls.json5",
        "config/tls/router-mtls.json5",
        "config/tls/client-tls.json5",
        "config/tls/client-mtls.json5",
    ],
)
def test_zenoh_json5_configs_load(path: str) -> None:
    zenoh.Config.from_file(str(REPO / path))


def test_router_config_listens_on_7447_without_multicast() -> None:
    conf = zenoh.Config.from_file(str(REPO / "config/zenohd.json5"))
    assert json.loads(conf.get_json("mode")) == "router"
    assert json.loads(conf.get_json("listen/endpoints")) == ["tcp/0.0.0.0:7447"]
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is False


def test_no_private_key_is_committed() -> None:
    tracked = subprocess.run(
        ["git", "ls-files", "config", "deploy"], capture_output=True, text=True, cwd=REPO
    ).stdout.split()
    assert not [p for p in tracked if p.endswith((".key", ".pem", ".p12"))]
    for path in tracked:
        assert "PRIVATE KEY-----" not in (REPO / path).read_text(errors="replace"), path


def test_reel_toml_has_the_contract_layout() -> None:
    settings = load_settings(REPO / "config/reel.toml", use_env=False)
    assert settings.zenoh.mode == "client"
    assert settings.zenoh.connect == ("tcp/127.0.0.1:7447",)
    assert settings.zenoh.listen == ()
    assert settings.drone.mass_kg == pytest.approx(0.030)
    assert settings.tether.weight_n_per_m == pytest.approx(0.05)
    assert settings.tether.length_m == pytest.approx(1.6)
    assert settings.base.position_m == pytest.approx((0.0, 0.0, 0.754))
    assert settings.base.floor_z_m == 0.0
    assert settings.service.log_json is True
    text = (REPO / "config/reel.toml").read_text()
    for table in ("[zenoh]", "[drone]", "[tether]", "[base]", "[service]"):
        assert table in text


# --------------------------------------------------------------------------- systemd


def test_systemd_unit() -> None:
    unit = (REPO / "deploy/groundstation.service").read_text()
    exec_start = re.search(r"^ExecStart=(.*)$", unit, flags=re.M)
    assert exec_start is not None
    argv = exec_start.group(1).split()
    args = build_parser().parse_args(argv[1:])
    assert args.command == "serve" and args.headless and args.log_json
    assert re.search(r"^User=groundstation$", unit, flags=re.M)
    assert re.search(r"^Restart=on-failure$", unit, flags=re.M)
    assert re.search(r"^KillSignal=SIGTERM$", unit, flags=re.M)
    if shutil.which("systemd-analyze") is None:
        return
    # Verify the unit's syntax with a stand-in executable (the venv path need not exist here).
    probe = REPO / ".pytest_cache" / "groundstation.service"
    probe.parent.mkdir(exist_ok=True)
    probe.write_text(unit.replace(argv[0], "/bin/true"))
    run = subprocess.run(
        ["systemd-analyze", "verify", str(probe)], capture_output=True, text=True, timeout=60
    )
    assert run.returncode == 0, run.stderr + run.stdout


# --------------------------------------------------------------------------- healthcheck


def healthcheck_script() -> str:
    lines = block_value(services()["groundstation"], "healthcheck")
    start = next(i for i, line in enumerate(lines) if line.strip() == "- |")
    indent = len(lines[start + 1]) - len(lines[start + 1].lstrip())
    body = []
    for line in lines[start + 1 :]:
        if len(line) - len(line.lstrip()) < indent:
            break
        body.append(line[indent:])
    return "\n".join(body) + "\n"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


TOKEN_HOLDER = r"""
import json, sys, zenoh
conf = zenoh.Config()
conf.insert_json5("mode", '"client"')
conf.insert_json5("connect/endpoints", json.dumps([sys.argv[1]]))
conf.insert_json5("scouting/multicast/enabled", "false")
with zenoh.open(conf) as session:
    token = session.liveliness().declare_token("groundstation/service/test")
    print("ready", flush=True)
    sys.stdin.read()
"""


@pytest.fixture
def router_endpoint() -> Iterator[str]:
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    proc = subprocess.Popen(
        [sys.executable, str(REPO / "tests/integration/router.py"), endpoint],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        cwd=REPO,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
    )
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline().startswith("ready")
        yield endpoint
    finally:
        proc.terminate()
        proc.wait(timeout=10)
        if proc.stdout is not None:
            proc.stdout.close()


@pytest.mark.integration
def test_compose_healthcheck_script(router_endpoint: str) -> None:
    """The healthcheck passes with the dashboard port open and the service alive, not before."""
    dashboard = socket.socket()
    dashboard.bind(("127.0.0.1", 0))
    dashboard.listen()
    script = (
        healthcheck_script()
        .replace("tcp/zenohd:7447", router_endpoint)
        .replace('("127.0.0.1", 8080)', f'("127.0.0.1", {dashboard.getsockname()[1]})')
    )
    assert router_endpoint in script

    def check() -> int:
        return subprocess.run(
            [sys.executable, "-c", script], capture_output=True, timeout=60
        ).returncode

    holder = None
    try:
        assert check() == 1  # router up, dashboard port open, no service token
        holder = subprocess.Popen(
            [sys.executable, "-c", TOKEN_HOLDER, router_endpoint],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert holder.stdout is not None
        assert holder.stdout.readline().strip() == "ready"
        deadline = time.monotonic() + 20.0
        while check() != 0:
            assert time.monotonic() < deadline, "healthcheck never passed"
        dashboard.close()
        assert check() != 0  # dashboard port closed
    finally:
        dashboard.close()
        if holder is not None:
            if holder.stdin is not None:
                holder.stdin.close()
            holder.wait(timeout=10)
            if holder.stdout is not None:
                holder.stdout.close()


@pytest.mark.parametrize(("argv", "rc"), [(["nonsense"], 2), (["help"], 0), ([], 0)])
def test_dev_script_help_is_its_usage_not_its_code(argv: list[str], rc: int) -> None:
    """``./dev nonsense`` once printed script lines (``set -euo pipefail``) as help."""
    out = subprocess.run(
        [str(REPO / "dev"), *argv], capture_output=True, text=True, timeout=30, check=False
    )
    assert out.returncode == rc, out
    text = out.stdout + out.stderr
    assert "./dev demo" in text and "./dev test" in text
    assert "set -euo" not in text and "cd " not in text and "# " not in text
    if rc:
        assert out.stderr.startswith("dev: unknown command 'nonsense'\n")
