"""Command line: ``groundstation serve | sim | demo | router | record | replay | info |
crazyflie | calibrate | dashboard | foxglove``.

Flags of the public contract are kept exactly (``docs/contract.md``); the ones added beside
them are listed there too. Every long-running command stops on SIGINT or SIGTERM, closes its
zenoh session and exits 0. A bad configuration, an unknown scenario or a zenoh session that
cannot open (a router that is down, an endpoint that is not one) is one line on stderr and
exit status 2.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
import tomllib
from collections.abc import Sequence
from types import FrameType
from typing import Any

from groundstation import __version__
from groundstation.config import ConfigError, Settings, load_settings
from groundstation.outputs import OutputError

__all__ = ["main"]

_log = logging.getLogger("groundstation")


# --------------------------------------------------------------------------- helpers


class _JsonFormatter(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        entry: dict[str, Any] = {
            "ts": round(record.created, 6),
            "level": record.levelname,
            "logger": record.name,
            "msg": record.getMessage(),
        }
        if record.exc_info:
            entry["exc"] = self.formatException(record.exc_info)
        return json.dumps(entry)


def _setup_logging(level: str, as_json: bool) -> None:
    handler = logging.StreamHandler(sys.stderr)
    if as_json:
        handler.setFormatter(_JsonFormatter())
    else:
        handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(level)
    # viser's websocket server logs every browser connection at INFO.
    logging.getLogger("websockets").setLevel(max(logging.WARNING, root.level))


def _stop_on_signals(*, child: bool = False) -> threading.Event:
    """An event set by SIGINT/SIGTERM; a second signal exits at once (status 1).

    ``child``: a process that ``serve`` started (its dashboard). Its parent stops it with
    SIGTERM, so it ignores the terminal's Ctrl-C (which reaches the whole process group: it
    would count as the first of two signals and exit abruptly) and says nothing at INFO
    (the parent has said "stopping": one line, not one per process).
    """
    stop = threading.Event()

    def handler(signum: int, frame: FrameType | None) -> None:
        if stop.is_set():
            os._exit(1)
        _log.log(logging.DEBUG if child else logging.INFO, "signal %d: stopping", signum)
        stop.set()

    signal.signal(signal.SIGINT, signal.SIG_IGN if child else handler)
    signal.signal(signal.SIGTERM, handler)
    return stop


def _wait(stop: threading.Event, children: dict[str, Any] | None = None) -> None:
    """Until ``stop`` is set (Event.wait with a timeout keeps the main thread responsive
    to signals). A child process (name → Popen) that exits meanwhile is said once at ERROR,
    with its status: the service goes on estimating without it (its own message, e.g. a
    port another process took between our check and its bind, is on stderr above)."""
    watched = dict(children or {})
    while not stop.wait(0.2):
        for name, child in list(watched.items()):
            status = child.poll()
            if status is not None:
                _log.error(
                    "the %s (pid %s) exited with status %s; the service goes on without it",
                    name,
                    child.pid,
                    status,
                )
                del watched[name]


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--config", metavar="PATH", help="TOML configuration file (layout: docs/contract.md)"
    )
    p.add_argument(
        "--connect",
        metavar="ENDPOINT",
        action="append",
        default=[],
        help="zenoh endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable); alone it "
        "makes this a client of that router",
    )
    p.add_argument(
        "--listen",
        metavar="ENDPOINT",
        action="append",
        default=[],
        help="zenoh endpoint to listen on for peers, e.g. tcp/127.0.0.1:7447 (repeatable; "
        "default: none, a router tcp/127.0.0.1:7447)",
    )
    p.add_argument("--mode", choices=["peer", "client", "router"], help="zenoh mode ([zenoh] mode)")
    p.add_argument(
        "--log-level", choices=["DEBUG", "INFO", "WARNING", "ERROR"], help="log level (INFO)"
    )
    p.add_argument("--log-json", action="store_true", help="log JSON lines on stderr")


def _cli_overrides(args: argparse.Namespace) -> dict[str, Any]:
    over: dict[str, Any] = {}
    zenoh: dict[str, Any] = {}
    if getattr(args, "connect", None):
        zenoh["connect"] = list(args.connect)
    if getattr(args, "listen", None):
        zenoh["listen"] = list(args.listen)
    if getattr(args, "mode", None):
        zenoh["mode"] = args.mode
    if zenoh:
        over["zenoh"] = zenoh
    service: dict[str, Any] = {}
    if getattr(args, "log_level", None):
        service["log_level"] = args.log_level
    if getattr(args, "log_json", False):
        service["log_json"] = True
    if getattr(args, "drones", None) and args.command == "serve":
        service["drones"] = args.drones
    if getattr(args, "record", None):
        service["record"] = args.record
    if service:
        over["service"] = service
    web: dict[str, Any] = {}
    if getattr(args, "web_host", None):
        web["host"] = args.web_host
    if getattr(args, "web_port", None) is not None:
        web["port"] = args.web_port
    if web:
        over["web"] = web
    foxglove: dict[str, Any] = {}
    if getattr(args, "foxglove_host", None):
        foxglove["host"] = args.foxglove_host
    if getattr(args, "foxglove_port", None) is not None:
        foxglove["port"] = args.foxglove_port
    if foxglove:
        over["foxglove"] = foxglove
    return over


def _mode_in_file(path: str | None) -> bool:
    if path is None:
        return False
    try:
        with open(path, "rb") as fh:
            return "mode" in tomllib.load(fh).get("zenoh", {})
    except (OSError, tomllib.TOMLDecodeError):
        return False  # load_settings reports it


def _load(args: argparse.Namespace, base: dict[str, Any] | None = None) -> Settings:
    overrides = _cli_overrides(args)
    zenoh = overrides.get("zenoh", {})
    # Told where to connect and nothing else: be a client of it (a router), unless the
    # file or the environment chose a mode.
    if (
        "connect" in zenoh
        and "listen" not in zenoh
        and "mode" not in zenoh
        and not _mode_in_file(args.config)
        and "GROUNDSTATION_ZENOH__MODE" not in os.environ
    ):
        zenoh["mode"] = "client"
    extra = getattr(args, "sim_overrides", None)
    if extra:
        overrides["sim"] = extra
    crazyflie = getattr(args, "crazyflie_overrides", None)
    if crazyflie:
        overrides["crazyflie"] = crazyflie
    settings = load_settings(args.config, overrides, base=base)
    _setup_logging(settings.service.log_level, settings.service.log_json)
    args.loaded_settings = settings  # for the error messages of main()
    return settings


def _check_scenario(name: str) -> None:
    from groundstation.sim import SCENARIOS

    if name not in SCENARIOS:
        raise ConfigError(
            f"unknown scenario {name!r} (--scenario / [sim] scenario); known: "
            + ", ".join(sorted(SCENARIOS))
        )


def _until_scenario_end(settings: Settings) -> Settings:
    """``--once`` (sim, demo): the simulated run ends at the scenario's natural end, or at
    ``[sim] duration_s`` (``sim --duration``) if that comes first. A scenario without an end
    is a configuration error."""
    from groundstation.sim import SCENARIOS

    name = settings.sim.scenario
    natural_s = SCENARIOS[name].duration_s
    if natural_s is None:
        raise ConfigError(
            f"scenario {name!r} runs until stopped; --once needs a scenario with an end "
            "(see sim --list), or a duration"
        )
    asked_s = settings.sim.duration_s
    end_s = natural_s if asked_s is None else min(asked_s, natural_s)
    return settings.model_copy(
        update={"sim": settings.sim.model_copy(update={"duration_s": end_s})}
    )


def _zenoh_error_line(exc: Exception, settings: Settings | None) -> str:
    """One line for a zenoh session that could not open (no Rust source locations)."""
    detail = re.sub(r"\s+at /\S+\.rs:\d+\.?", "", str(exc)).strip()
    detail = re.sub(r"\s+", " ", detail)
    if settings is not None and "Unable to connect" in detail:
        z = settings.zenoh
        return (
            f"no router reachable at {', '.join(z.connect) or '(nothing to connect to)'} "
            f"(mode {z.mode}): is it up, is the address right? (zenoh: {detail})"
        )
    return f"zenoh could not open a session: {detail}"


ROUTER_ENDPOINT = "tcp/127.0.0.1:7447"
"""Where ``groundstation router`` listens by default, and what the others ``--connect`` to
(docker-compose's zenohd publishes the same port)."""


class PortInUse(RuntimeError):
    """A fixed port this command must bind is taken (one line, exit status 2)."""


def _port_free(host: str, port: int) -> bool:
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as s:
        try:
            s.bind((host, port))
        except OSError:
            return False
    return True


def _check_web_port(settings: Settings) -> None:
    """Fail before starting anything when the dashboard's port is taken (never a silent move:
    viser would take the next free one, and the operator would open the other one's page)."""
    host, port = settings.web.host, settings.web.port
    if port != 0 and not _port_free(host, port):
        raise PortInUse(
            f"the dashboard's port {host}:{port} is in use (another groundstation "
            "serve, demo or dashboard?): stop it, or pass --web-port N (0: any free port)"
        )


def _check_foxglove_port(settings: Settings) -> None:
    """Fail before starting anything when Foxglove's WebSocket port is taken."""
    host, port = settings.foxglove.host, settings.foxglove.port
    if port is not None and port != 0 and not _port_free(host, port):
        raise PortInUse(
            f"the Foxglove WebSocket port {host}:{port} is in use (another groundstation "
            "serve, demo or foxglove, or a Foxglove bridge?): stop it, or pass "
            "--foxglove-port N (0: any free port)"
        )


def _start_foxglove(settings: Settings, bus: Any) -> Any:
    """Foxglove's WebSocket server in this process; prints where it listens."""
    from groundstation.foxglove.live import FoxgloveLive, ServerBindError

    live = FoxgloveLive(settings, bus)
    try:
        live.start()
    except ServerBindError as exc:
        live.close()
        raise PortInUse(f"{exc} (pass --foxglove-port N; 0: any free port)") from None
    print(f"foxglove: {live.url}", flush=True)
    return live


def _free_port(host: str, preferred: int) -> int:
    for port in (preferred, 0):
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            try:
                s.bind((host, port))
            except OSError:
                continue
            return int(s.getsockname()[1])
    raise OSError(f"no free TCP port on {host}")


def _start_dashboard(settings: Settings, bus: Any) -> Any:
    from groundstation.dashboard import Dashboard

    dashboard = Dashboard(settings, bus)
    dashboard.start()
    _check_bound(dashboard, settings)
    print(f"dashboard: {dashboard.url}", flush=True)
    return dashboard


def _check_bound(dashboard: Any, settings: Settings) -> None:
    """The port checked free may be taken before viser binds it: viser then moves on."""
    wanted, bound = settings.web.port, dashboard.server.get_port()
    if wanted != 0 and bound != wanted:
        dashboard.close()
        raise PortInUse(
            f"the dashboard's port {settings.web.host}:{wanted} was taken while "
            f"starting (the server went to {bound}): pass --web-port N (0: any free port)"
        )


# --------------------------------------------------------------------------- commands


def _dashboard_endpoint(settings: Settings) -> tuple[Settings, str]:
    """Where a dashboard process reaches this service's bus, and the settings that make it so.

    A client reaches the same router; a peer or router gets a loopback listener (added when
    it has none on a fixed port) that the dashboard connects to.
    """
    z = settings.zenoh
    if z.mode == "client" and z.connect:
        return settings, z.connect[0]
    # A router with no listen endpoint listens on ROUTER_ENDPOINT (make_zenoh_config):
    # keep that one rather than make it listen on a random port only.
    listen = z.listen or ((ROUTER_ENDPOINT,) if z.mode == "router" else ())
    if listen != z.listen:
        settings = settings.model_copy(update={"zenoh": z.model_copy(update={"listen": listen})})
        z = settings.zenoh
    for ep in z.listen:
        m = re.fullmatch(r"tcp/(127\.0\.0\.1|0\.0\.0\.0|\[::\]|localhost):(\d+)", ep)
        if m and m.group(2) != "0":
            return settings, f"tcp/127.0.0.1:{m.group(2)}"
    ep = f"tcp/127.0.0.1:{_free_port('127.0.0.1', 0)}"
    zenoh = z.model_copy(update={"listen": (*z.listen, ep)})
    return settings.model_copy(update={"zenoh": zenoh}), ep


def _spawn_foxglove(args: argparse.Namespace, settings: Settings, endpoint: str) -> Any:
    """``groundstation foxglove`` as a child process, for the dashboard's reason: scenes and
    the relay of every message never take the interpreter from estimation."""
    cmd = [sys.executable, "-m", "groundstation", "foxglove", "--connect", endpoint]
    cmd += ["--foxglove-host", settings.foxglove.host]
    cmd += ["--foxglove-port", str(settings.foxglove.port)]
    cmd += ["--parent-pid", str(os.getpid())]
    if args.config:
        cmd += ["--config", args.config]
    return subprocess.Popen(cmd, stdin=subprocess.DEVNULL)


def _spawn_dashboard(args: argparse.Namespace, settings: Settings, endpoint: str) -> Any:
    """``groundstation dashboard`` as a child process: its own interpreter, so drawing the
    scene never takes the GIL from estimation (measured: p99 latency ×10 in one process)."""
    cmd = [sys.executable, "-m", "groundstation", "dashboard", "--connect", endpoint]
    cmd += ["--web-host", settings.web.host, "--web-port", str(settings.web.port)]
    cmd += ["--parent-pid", str(os.getpid())]
    if args.config:
        cmd += ["--config", args.config]
    return subprocess.Popen(cmd, stdin=subprocess.DEVNULL)


CHILD_KILL_WAIT_S = 10.0
"""How long ``serve`` waits for a child (dashboard, Foxglove server) to be reaped after
SIGKILL, s: on a busy machine it can take more than a second."""


def _stop_child(child: Any, timeout_s: float = 1.5, *, signalled: bool = False) -> None:
    """SIGTERM (unless ``signalled``: sent already), then SIGKILL after ``timeout_s``. Never
    raises: a child slow to die (a busy machine) is waited for up to
    :data:`CHILD_KILL_WAIT_S` and then left with a warning, so the service's own exit status
    says how the service stopped, not how fast its child did (it was a traceback and status
    1)."""
    if child.poll() is not None:
        return
    if not signalled:
        child.send_signal(signal.SIGTERM)
    try:
        child.wait(timeout_s)
        return
    except subprocess.TimeoutExpired:
        child.kill()
    try:
        child.wait(CHILD_KILL_WAIT_S)
    except subprocess.TimeoutExpired:
        _log.warning(
            "a child process (pid %s) had not exited %g s after SIGKILL; not waiting longer",
            child.pid,
            CHILD_KILL_WAIT_S,
        )


def cmd_serve(args: argparse.Namespace) -> int:
    from groundstation.service import OwnershipConflict, Service
    from groundstation.zenoh_bus import ZenohBus

    settings = _load(args)
    if settings.service.record:
        from groundstation.outputs import check_output, expand_time

        record = expand_time(settings.service.record, time.time())
        check_output(record, force=args.force, flag="--record")
        service_section = settings.service.model_copy(update={"record": record})
        settings = settings.model_copy(update={"service": service_section})
    endpoint = None
    if not args.headless:
        _check_web_port(settings)
    foxglove = settings.foxglove.port is not None
    if foxglove:
        _check_foxglove_port(settings)
    if not args.headless or foxglove:
        settings, endpoint = _dashboard_endpoint(settings)
    stop = _stop_on_signals()
    with ZenohBus(settings.zenoh) as bus:
        service = Service(settings, bus, replace_recording=args.force)
        children: dict[str, Any] = {}
        try:
            try:
                service.start()
            except OwnershipConflict as exc:
                print(f"groundstation serve: {exc}", file=sys.stderr, flush=True)
                return 2
            if endpoint is not None and not args.headless:
                children["dashboard"] = _spawn_dashboard(args, settings, endpoint)
            if endpoint is not None and foxglove:
                children["Foxglove server"] = _spawn_foxglove(args, settings, endpoint)
            print(f"groundstation serve: running (instance {service.instance})", flush=True)
            _wait(stop, children)
        finally:
            # The children stop while the service closes (each waits for its own bus).
            for child in children.values():
                if child.poll() is None:
                    child.send_signal(signal.SIGTERM)
            service.close()
            for child in children.values():
                _stop_child(child, signalled=True)
    return 0


FOXGLOVE_NICE = 10
"""Niceness ``serve`` adds to its Foxglove process (relays every message, draws scenes)."""


def cmd_foxglove(args: argparse.Namespace) -> int:
    from groundstation.zenoh_bus import ZenohBus

    settings = _load(args)
    if args.parent_pid:
        # Started by `serve`: a client of its bus, listening on nothing, and behind the
        # service for a core (a viewer waits; estimation does not): measured with a client
        # subscribed, it takes about a fifth of a core at 8 drones × 250 Hz.
        zenoh = settings.zenoh.model_copy(update={"mode": "client", "listen": ()})
        settings = settings.model_copy(update={"zenoh": zenoh})
        os.nice(FOXGLOVE_NICE)
    if settings.foxglove.port is None:
        settings = settings.model_copy(
            update={"foxglove": settings.foxglove.model_copy(update={"port": 8765})}
        )
    _check_foxglove_port(settings)
    stop = _stop_on_signals(child=bool(args.parent_pid))
    with ZenohBus(settings.zenoh) as bus:
        live = _start_foxglove(settings, bus)
        try:
            while not stop.wait(0.2):
                if args.parent_pid and os.getppid() != args.parent_pid:
                    break  # the service that started us is gone
        finally:
            live.close()
    return 0


def cmd_dashboard(args: argparse.Namespace) -> int:
    from groundstation.dashboard import Dashboard
    from groundstation.zenoh_bus import ZenohBus

    settings = _load(args)
    if args.parent_pid:
        # Started by `serve`: a client of its bus, listening on nothing (the configuration
        # file's listen endpoints are the service's). The file's TLS settings still apply.
        zenoh = settings.zenoh.model_copy(update={"mode": "client", "listen": ()})
        settings = settings.model_copy(update={"zenoh": zenoh})
    _check_web_port(settings)
    stop = _stop_on_signals(child=bool(args.parent_pid))
    with ZenohBus(settings.zenoh) as bus:
        dashboard = Dashboard(settings, bus)
        try:
            dashboard.start()
            _check_bound(dashboard, settings)
            print(f"dashboard: {dashboard.url}", flush=True)
            while not stop.wait(0.2):
                if args.parent_pid and os.getppid() != args.parent_pid:
                    break  # the service that started us is gone
        finally:
            dashboard.close()
    return 0


def cmd_sim(args: argparse.Namespace) -> int:
    from groundstation.sim import SCENARIOS, Simulator
    from groundstation.zenoh_bus import ZenohBus

    if args.list:
        for name in sorted(SCENARIOS):
            print(f"{name:14s} {SCENARIOS[name].description}")
        return 0
    from groundstation.bus import PeerWatch, describe_endpoints

    settings = _load(args)
    _check_scenario(settings.sim.scenario)
    if args.once:
        settings = _until_scenario_end(settings)
    stop = _stop_on_signals()
    z = settings.zenoh
    with ZenohBus(z) as bus:
        watch = PeerWatch(
            bus.peer_count,
            describe_endpoints(z.mode, z.connect, z.listen),
            "groundstation sim",
            _log,
        )
        sim = Simulator(settings, bus, scenario=args.scenario)
        sim.start()
        try:
            print(
                f"groundstation sim: scenario {sim.scenario.name} ({sim.profile} profile"
                f"{', untethered' if sim.untethered else ''}) for "
                f"{', '.join(sim.drones)}",
                flush=True,
            )
            while not stop.wait(0.2):
                watch.poll(time.monotonic())
                if sim.wait(0.0):
                    break
        finally:
            sim.close()
    return 0


DEMO_DEFAULTS: dict[str, Any] = {
    "zenoh": {"mode": "peer", "listen": ["tcp/127.0.0.1:7447"]},
    "sim": {"scenario": "hover_spots", "drones": ["cf1"]},
    "web": {"host": "127.0.0.1", "port": 8080},
}
"""The embedded demo configuration: peer on loopback, one simulated drone, dashboard."""


def _check_listen_free(endpoints: Sequence[str], hint: str) -> None:
    """Fail before opening a session when a TCP endpoint to listen on is taken (zenoh would
    otherwise fail later with a Rust error, or a demo would move without being asked)."""
    for ep in endpoints:
        m = re.fullmatch(r"tcp/([0-9.]+|localhost|\[[0-9a-fA-F:]+\]):(\d+)", ep)
        if m and m.group(2) != "0":
            host = m.group(1).strip("[]")
            if not _port_free(host, int(m.group(2))):
                raise PortInUse(
                    f"{ep} is in use ({hint}); stop it, or pass --listen tcp/127.0.0.1:N"
                )


def _demo_bus(args: argparse.Namespace, settings: Settings) -> tuple[Settings, str]:
    """The demo's own bus, and the line the banner prints about it.

    Everything runs in this one process, so it needs no router; a configuration written for
    separate processes (config/sim.toml: a client of a router on 7447) would otherwise
    connect to itself, so the file's [zenoh] mode, connect and listen are not used. The
    command line is: ``--connect`` joins a router (listening only where ``--listen`` says);
    ``--listen`` listens exactly there (an endpoint in use is an error that names it). Only
    the default, ROUTER_ENDPOINT, moves to a free port when taken, and says so.
    """
    z = settings.zenoh
    listen = tuple(args.listen)
    if args.connect:
        _check_listen_free(listen, "a router, or another demo?")
        zenoh = z.model_copy(update={"listen": listen})
        line = f"zenoh: {zenoh.mode} of {', '.join(zenoh.connect)}"
        if listen:
            line += f", listening on {', '.join(listen)}"
        return settings.model_copy(update={"zenoh": zenoh}), line
    if listen:
        _check_listen_free(listen, "a router, or another demo?")
        zenoh = z.model_copy(update={"mode": "peer", "connect": (), "listen": listen})
        return settings.model_copy(update={"zenoh": zenoh}), f"zenoh: peer on {', '.join(listen)}"
    if z.mode != "peer" or z.connect:
        origin = args.config or "the environment"
        print(
            f"groundstation demo: runs its own bus in this process; [zenoh] mode "
            f"{z.mode!r} and connect {list(z.connect)} of {origin} are not used (to join a "
            "router: --connect ENDPOINT, or run serve and sim as separate processes)",
            flush=True,
        )
    host, port = "127.0.0.1", int(ROUTER_ENDPOINT.rsplit(":", 1)[1])
    line = f"zenoh: peer on tcp/{host}:{port}"
    if not _port_free(host, port):
        port = _free_port(host, 0)
        line = f"zenoh: peer on tcp/{host}:{port}"
        _log.warning(
            "groundstation demo: %s is in use (a router or another demo?): this demo's bus "
            "listens on tcp/%s:%d instead (connect other processes there)",
            ROUTER_ENDPOINT,
            host,
            port,
        )
    zenoh = z.model_copy(update={"mode": "peer", "connect": (), "listen": (f"tcp/{host}:{port}",)})
    return settings.model_copy(update={"zenoh": zenoh}), line


def _demo_web_port(args: argparse.Namespace, settings: Settings) -> Settings:
    """The demo's dashboard port: as asked (``--web-port``, a file's [web] port: in use is an
    error); by default 8080, or, with 8080 in use, a free one said loudly."""
    if args.web_port is not None or settings.web.port != DEMO_DEFAULTS["web"]["port"]:
        _check_web_port(settings)
        return settings
    host = settings.web.host
    if _port_free(host, settings.web.port):
        return settings
    port = _free_port(host, 0)
    _log.warning(
        "groundstation demo: the dashboard's port %s:%d is in use (another demo or serve?): "
        "this demo's dashboard is on port %d instead (the URL below)",
        host,
        settings.web.port,
        port,
    )
    return settings.model_copy(update={"web": settings.web.model_copy(update={"port": port})})


def cmd_demo(args: argparse.Namespace) -> int:
    from groundstation.service import Service
    from groundstation.sim import Simulator
    from groundstation.zenoh_bus import ZenohBus

    base = json.loads(json.dumps(DEMO_DEFAULTS))
    settings = _load(args, base=base)
    _check_scenario(settings.sim.scenario)
    if args.once:
        settings = _until_scenario_end(settings)
    settings, bus_line = _demo_bus(args, settings)
    if not args.headless:
        settings = _demo_web_port(args, settings)
    _check_foxglove_port(settings)
    stop = _stop_on_signals()
    with ZenohBus(settings.zenoh) as bus:
        service = Service(settings, bus, alone_ok=True)
        sim = Simulator(settings, bus, scenario=args.scenario)
        dashboard = foxglove = None
        try:
            service.start()
            if not args.headless:
                dashboard = _start_dashboard(settings, bus)
            if settings.foxglove.port is not None:
                foxglove = _start_foxglove(settings, bus)
            sim.start()
            print(
                f"groundstation demo: scenario {sim.scenario.name}, drones "
                f"{', '.join(sim.drones)}; {bus_line}; Ctrl-C stops",
                flush=True,
            )
            deadline = time.monotonic() + args.duration if args.duration else None
            while not stop.wait(0.2):
                if deadline is not None and time.monotonic() > deadline:
                    break
                if args.once and sim.wait(0.0):  # the scenario's end (_until_scenario_end)
                    break
        finally:
            sim.close()
            if foxglove is not None:
                foxglove.close()
            if dashboard is not None:
                dashboard.close()
            service.close()
    return 0


def cmd_router(args: argparse.Namespace) -> int:
    """A zenoh router session (what docker-compose runs as zenohd): the hub the other
    processes of one machine or lab connect to. Listens on ROUTER_ENDPOINT unless told."""
    from groundstation.zenoh_bus import open_session

    settings = _load(args)
    z = settings.zenoh
    # The file's connect endpoints are where its clients go (this router), not routers to
    # join: only --connect makes this router connect to others.
    listen = z.listen or (ROUTER_ENDPOINT,)
    section = z.model_copy(
        update={"mode": "router", "listen": listen, "connect": tuple(args.connect)}
    )
    _check_listen_free(listen, "another router, zenohd, or a demo?")
    stop = _stop_on_signals()
    session = open_session(section)
    try:
        print(
            f"groundstation router: listening on {', '.join(listen)} (zenoh {session.zid()}); "
            f"the others connect with --connect {listen[0]}; Ctrl-C stops",
            flush=True,
        )
        _wait(stop)
    finally:
        session.close()
    return 0


def cmd_record(args: argparse.Namespace) -> int:
    from groundstation.outputs import check_output, expand_time
    from groundstation.recording import run_record

    out = expand_time(args.out, time.time())
    check_output(out, force=args.force)  # before the session opens
    settings = _load(args)
    stop = _stop_on_signals()
    return int(run_record(settings, out, args.key or ["tether/**"], stop, force=args.force))


def cmd_replay(args: argparse.Namespace) -> int:
    from groundstation import recording

    if args.offline and not args.out:
        print(
            "groundstation: replay --offline needs --out OUT.mcap (where to write the "
            "re-estimated recording)",
            file=sys.stderr,
        )
        return 2
    if not args.offline and (args.out or args.figures):
        print(
            "groundstation: replay --out and --figures need --offline (a replay on the bus "
            "writes no file; `groundstation record` records it)",
            file=sys.stderr,
        )
        return 2
    settings = _load(args)
    if args.offline:
        return int(
            recording.run_replay_offline(
                settings, args.file, args.out, figures_dir=args.figures, force=args.force
            )
        )
    stop = _stop_on_signals()
    return int(recording.run_replay(settings, args.file, speed=args.speed, stop_event=stop))


def cmd_info(args: argparse.Namespace) -> int:
    from groundstation.recording.info import format_info, recording_info

    _setup_logging("WARNING", False)
    for index, path in enumerate(args.files):
        if not os.path.isfile(path):
            raise FileNotFoundError(f"{path!r}: no such file")
        info = recording_info(path)
        if args.json:
            print(json.dumps(info.as_dict(), separators=(",", ":")), flush=True)
        else:
            if index:
                print()
            print(format_info(info), flush=True)
    return 0


def cmd_crazyflie(args: argparse.Namespace) -> int:
    from groundstation.bridges.crazyflie import (
        CrazyflieBridge,
        LinkError,
        make_link,
        run_bridges,
        scan,
    )
    from groundstation.messages import DRONE_ID_RE
    from groundstation.zenoh_bus import ZenohBus

    uris: list[str] = args.uri or []
    drones: list[str] = args.drone or []
    if args.scan:
        try:
            found = scan(uris)
        except LinkError as exc:
            print(f"groundstation: {exc}", file=sys.stderr)
            return 2
        for uri in found:
            print(uri, flush=True)
        if not found:
            print("groundstation crazyflie --scan: no Crazyflie answered", file=sys.stderr)
        return 0 if found else 1
    if not uris or len(uris) != len(drones):
        print(
            f"groundstation: {len(uris)} --uri and {len(drones)} --drone: give one --drone per "
            "--uri (or --scan)",
            file=sys.stderr,
        )
        return 2
    for name, values in (("--uri", uris), ("--drone", drones)):
        repeated = sorted({v for v in values if values.count(v) > 1})
        if repeated:
            print(f"groundstation: {name} {', '.join(repeated)} given twice", file=sys.stderr)
            return 2
    for drone in drones:
        if not DRONE_ID_RE.fullmatch(drone):
            print(f"groundstation: --drone {drone!r}: not [A-Za-z0-9_-]{{1,64}}", file=sys.stderr)
            return 2
    if args.rate_hz is not None:
        args.crazyflie_overrides = {"rate_hz": args.rate_hz}
    settings = _load(args)
    # cflib logs every connection step at INFO, and warns on each connection that it has no
    # TOC cache directory (an optional [crazyflie] toc_cache_dir).
    cflib_level = logging.DEBUG if settings.service.log_level == "DEBUG" else logging.WARNING
    logging.getLogger("cflib").setLevel(cflib_level)
    if settings.crazyflie.toc_cache_dir is None:
        logging.getLogger("cflib.crazyflie.toccache").setLevel(max(cflib_level, logging.ERROR))
    try:
        links = [make_link(uri, settings, drone) for uri, drone in zip(uris, drones, strict=True)]
    except LinkError as exc:
        print(f"groundstation: {exc}", file=sys.stderr)
        return 2
    stop = _stop_on_signals()
    with ZenohBus(settings.zenoh) as bus:
        bridges = []
        for drone, link in zip(drones, links, strict=True):
            params = settings.for_drone(drone)
            bridges.append(
                CrazyflieBridge(
                    settings.crazyflie,
                    bus,
                    drone,
                    link,
                    floor_z_m=params.base.floor_z_m,
                    reach=(params.base.position_m, params.tether.length_m),
                )
            )
            print(
                f"groundstation crazyflie: {link.uri} as tether/{drone} "
                f"every {settings.crazyflie.log_period_ms} ms",
                flush=True,
            )
        # One process, several links: cflib shares the Crazyradio between them.
        return run_bridges(bridges, stop)


def cmd_calibrate(args: argparse.Namespace) -> int:
    from groundstation.recording.calibrate import run_calibrate

    settings = _load(args)
    return run_calibrate(
        settings,
        args.config,
        args.files,
        args.out,
        drone=args.drone,
        fit_tether=args.fit_tether,
        model=args.model,
        untethered=args.untethered,
        tether_detached=args.tether_detached,
        force=args.force,
    )


# --------------------------------------------------------------------------- parser


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="groundstation",
        description="Ground station for tethered micro drones (Zenoh service, simulator, "
        "dashboard, recorder).",
    )
    parser.add_argument("--version", action="version", version=f"groundstation {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("serve", help="run the estimation service")
    _add_common(p)
    p.add_argument("--headless", action="store_true", help="no dashboard")
    p.add_argument("--web-host", metavar="HOST", help="dashboard bind address (127.0.0.1)")
    p.add_argument("--web-port", metavar="N", type=int, help="dashboard port (8080)")
    p.add_argument(
        "--drones", metavar="CHUNK", help="own only drones matching tether/CHUNK/* (e.g. lab-a-*)"
    )
    p.add_argument(
        "--record",
        metavar="FILE",
        help="also record the bus to this MCAP file (a new one; {time} in it becomes the UTC "
        "time, e.g. session-{time}.mcap)",
    )
    p.add_argument("--force", action="store_true", help="let --record replace an existing file")
    p.add_argument(
        "--foxglove-port",
        metavar="N",
        type=int,
        help="serve the 3D scene and the messages to Foxglove on this WebSocket port "
        "(off unless given; 8765 is Foxglove's usual; 0: any free port)",
    )
    p.add_argument(
        "--foxglove-host", metavar="HOST", help="Foxglove WebSocket bind address (127.0.0.1)"
    )
    p.set_defaults(func=cmd_serve)

    p = sub.add_parser(
        "router",
        help=f"a zenoh router for the other processes to connect to ({ROUTER_ENDPOINT})",
        description=f"A zenoh router session (as zenohd): listens on {ROUTER_ENDPOINT} unless "
        "--listen or [zenoh] listen says otherwise, with multicast scouting off; serve, sim, "
        f"record and dashboard then run as separate processes with --connect {ROUTER_ENDPOINT}. "
        "The file's [zenoh] connect is where its clients go, not a router to join.",
    )
    p.add_argument(
        "--config", metavar="PATH", help="TOML configuration ([zenoh] listen, config_file: TLS/ACL)"
    )
    p.add_argument(
        "--listen",
        metavar="ENDPOINT",
        action="append",
        default=[],
        help=f"endpoint to listen on (repeatable; default {ROUTER_ENDPOINT})",
    )
    p.add_argument(
        "--connect",
        metavar="ENDPOINT",
        action="append",
        default=[],
        help="another router to join (repeatable; default none)",
    )
    p.add_argument(
        "--log-level", choices=["DEBUG", "INFO", "WARNING", "ERROR"], help="log level (INFO)"
    )
    p.add_argument("--log-json", action="store_true", help="log JSON lines on stderr")
    p.set_defaults(func=cmd_router)

    p = sub.add_parser("dashboard", help="the operator dashboard alone, as a bus client")
    _add_common(p)
    p.add_argument("--web-host", metavar="HOST", help="bind address (127.0.0.1)")
    p.add_argument("--web-port", metavar="N", type=int, help="port (8080)")
    p.add_argument("--parent-pid", type=int, help=argparse.SUPPRESS)
    p.set_defaults(func=cmd_dashboard)

    p = sub.add_parser(
        "foxglove",
        help="Foxglove's WebSocket server alone, as a bus client (3D scene and messages)",
        description="Foxglove's WebSocket server fed from the bus: the contract's messages as "
        "JSON channels, each drone's 3D scene (foxglove.SceneUpdate on 'scene', "
        "foxglove.FrameTransforms on 'tf'); docs/foxglove.md.",
    )
    _add_common(p)
    p.add_argument("--foxglove-host", metavar="HOST", help="bind address (127.0.0.1)")
    p.add_argument("--foxglove-port", metavar="N", type=int, help="port (8765; 0: any free port)")
    p.add_argument("--parent-pid", type=int, help=argparse.SUPPRESS)
    p.set_defaults(func=cmd_foxglove)

    p = sub.add_parser("sim", help="run the drone + tether simulator")
    _add_common(p)
    p.add_argument("--scenario", metavar="NAME", help="scenario (see --list)")
    p.add_argument("--list", action="store_true", help="list the scenarios")
    p.add_argument("--drones", metavar="ID", nargs="+", help="drone ids to simulate")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S simulated seconds")
    p.add_argument(
        "--once",
        action="store_true",
        help="stop when the scenario ends (its natural length; with --duration, the earlier)",
    )
    p.add_argument(
        "--speed", type=float, metavar="X", help="real-time factor (1 = wall clock, 2 = twice)"
    )
    p.add_argument("--seed", type=int, metavar="N", help="random seed of the sensor noise (0)")
    p.add_argument("--rate", type=float, metavar="HZ", help="telemetry rate (250)")
    p.add_argument("--no-mocap", action="store_true", help="omit motion-capture position_m")
    p.add_argument("--thrust-bias", type=float, metavar="RATIO", help="e.g. 0.02 for +2 %%")
    p.add_argument(
        "--profile",
        choices=("ideal", "realistic"),
        help="ideal: the estimator's assumptions; realistic: rigid body, lumped-mass tether, "
        "real sensor errors ([sim.realistic], docs/simulator.md)",
    )
    p.add_argument(
        "--untethered",
        action="store_true",
        help="fly without a tether: no tether force, no reel messages ([sim] untethered; "
        "a flight for calibrate --untethered, docs/calibration.md)",
    )
    p.set_defaults(func=cmd_sim)

    p = sub.add_parser("demo", help="simulator + service + dashboard in one process")
    _add_common(p)
    p.add_argument("--scenario", metavar="NAME", help="scenario (default hover_spots)")
    p.add_argument("--headless", action="store_true", help="no dashboard")
    p.add_argument("--web-host", metavar="HOST", help="dashboard bind address (127.0.0.1)")
    p.add_argument("--web-port", metavar="N", type=int, help="dashboard port (8080, or a free one)")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S wall seconds")
    p.add_argument("--once", action="store_true", help="stop when the scenario ends")
    p.add_argument(
        "--profile", choices=("ideal", "realistic"), help="simulator profile (docs/simulator.md)"
    )
    p.add_argument(
        "--foxglove-port",
        metavar="N",
        type=int,
        help="serve the 3D scene and the messages to Foxglove on this WebSocket port "
        "(off unless given; 8765 is Foxglove's usual; 0: any free port)",
    )
    p.add_argument(
        "--foxglove-host", metavar="HOST", help="Foxglove WebSocket bind address (127.0.0.1)"
    )
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser("record", help="record the bus into MCAP")
    _add_common(p)
    p.add_argument(
        "--out",
        required=True,
        metavar="FILE.mcap",
        help="the MCAP file to write (required; an existing file only with --force; "
        "{time} in it becomes the UTC time, e.g. flight-{time}.mcap)",
    )
    p.add_argument("--force", action="store_true", help="replace an existing --out file")
    p.add_argument(
        "--key",
        action="append",
        metavar="KEYEXPR",
        help="key expression to record (repeatable; default tether/**)",
    )
    p.set_defaults(func=cmd_record)

    p = sub.add_parser("replay", help="play a recording back (or re-estimate it offline)")
    _add_common(p)
    p.add_argument("file", metavar="FILE.mcap", help="the recording to play")
    p.add_argument(
        "--speed",
        type=float,
        default=1.0,
        metavar="X",
        help="playback speed (1 = as recorded, 2 = twice as fast)",
    )
    p.add_argument(
        "--offline",
        action="store_true",
        help="re-run estimation on the recording, no bus (needs --out)",
    )
    p.add_argument(
        "--out", metavar="OUT.mcap", help="with --offline: write the re-estimated recording here"
    )
    p.add_argument("--figures", metavar="DIR", help="with --offline: draw figures here")
    p.add_argument(
        "--force",
        action="store_true",
        help="with --offline: replace an existing --out file and figures (never the input)",
    )
    p.set_defaults(func=cmd_replay)

    p = sub.add_parser(
        "info",
        help="what a recording holds: keys, counts, drones, time span, calibration, gaps",
        description="Summarise MCAP recordings (finished or cut): keys with counts and rates, "
        "the drones, the span on the receive clock and each drone's own clock, motion capture, "
        "battery, the calibration its estimates applied, and gaps in its telemetry. Reads "
        "only.",
    )
    p.add_argument("files", metavar="FILE.mcap", nargs="+", help="recordings")
    p.add_argument("--json", action="store_true", help="one JSON object per file")
    p.set_defaults(func=cmd_info)

    p = sub.add_parser("crazyflie", help="bridge a Crazyflie (cflib) to the bus")
    _add_common(p)
    p.add_argument(
        "--uri",
        action="append",
        metavar="URI",
        help="cflib URI (radio://0/80/2M/E7E7E7E7E7, usb://0, udp://HOST:PORT); repeat it, with "
        "a --drone each, for several drones on one Crazyradio; fake://hover is a test fake, "
        "not a drone",
    )
    p.add_argument(
        "--drone", action="append", metavar="ID", help="drone id on the bus, one per --uri"
    )
    p.add_argument(
        "--scan",
        action="store_true",
        help="list the Crazyflies that answer (cflib's scan, and each --uri's address), "
        "connecting to none, and exit",
    )
    p.add_argument("--rate-hz", type=float, metavar="HZ", help="telemetry rate (100)")
    p.set_defaults(func=cmd_crazyflie)

    p = sub.add_parser(
        "calibrate",
        help="fit the airframe's thrust scale, thrust axis, battery term, rotor drag",
        description="Fit each drone's [calibration] from recordings with motion capture and "
        "write the configuration plus [drones.<id>.calibration] (docs/calibration.md). "
        "Without --drone every drone in the recordings is calibrated, and said so; when the "
        "configuration has [drones.<id>] tables, a recorded drone without one is an error "
        "(name it with --drone to fit it with the shared tables).",
    )
    p.add_argument("files", metavar="FILE.mcap", nargs="+", help="recordings with motion capture")
    p.add_argument("--config", metavar="PATH", help="TOML configuration (the output's base)")
    p.add_argument(
        "--drone",
        metavar="ID",
        help="calibrate this drone only (default: every drone in the recordings, each of "
        "which needs a [drones.<id>] table when the configuration has any)",
    )
    p.add_argument(
        "--out",
        required=True,
        metavar="PATH.toml",
        help="configuration to write (a new file, or an existing one with --force; never an input)",
    )
    p.add_argument("--force", action="store_true", help="replace an existing --out file")
    p.add_argument(
        "--untethered",
        action="store_true",
        help="flights without the tether: the true tension is zero (the cleanest reference); "
        "refused on recordings with tether messages unless --tether-detached",
    )
    p.add_argument(
        "--tether-detached",
        action="store_true",
        help="with --untethered: the recordings hold reel or tether messages, but the tether "
        "was detached from the drone",
    )
    p.add_argument(
        "--model",
        choices=["airframe", "full"],
        default="airframe",
        help="airframe (default): the airframe's constants (thrust scale, battery term, thrust "
        "axis, rotor drag) across flights, each power-on's accelerometer offsets printed and "
        "not written; full: the earlier accelerometer-based fit (bias written, --fit-tether; "
        "worse than the default in 9 of 10 cases on the realistic simulator, up to 12x: "
        "docs/calibration.md)",
    )
    p.add_argument(
        "--fit-tether",
        action="store_true",
        help="also fit the tether's ω and the base position (--model full)",
    )
    p.add_argument(
        "--log-level", choices=["DEBUG", "INFO", "WARNING", "ERROR"], help="log level (INFO)"
    )
    p.set_defaults(func=cmd_calibrate)
    return parser


def _sim_overrides(args: argparse.Namespace) -> dict[str, Any]:
    over: dict[str, Any] = {}
    if args.command not in ("sim", "demo"):
        return over
    if getattr(args, "scenario", None):
        over["scenario"] = args.scenario
    if getattr(args, "profile", None):
        over["profile"] = args.profile
    if args.command == "sim":
        if args.drones:
            over["drones"] = list(args.drones)
        if args.duration is not None:
            over["duration_s"] = args.duration
        if args.speed is not None:
            over["speed"] = args.speed
        if args.seed is not None:
            over["seed"] = args.seed
        if args.rate is not None:
            over["rate_hz"] = args.rate
        if args.no_mocap:
            over["mocap"] = False
        if args.untethered:
            over["untethered"] = True
        if args.thrust_bias is not None:
            over["thrust_bias_ratio"] = args.thrust_bias
    return over


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``groundstation`` console script."""
    args = build_parser().parse_args(argv)
    args.sim_overrides = _sim_overrides(args)
    try:
        return int(args.func(args))
    except ConfigError as exc:
        print(f"groundstation: {exc}", file=sys.stderr)
        return 2
    except (FileNotFoundError, IsADirectoryError, PermissionError) as exc:
        print(f"groundstation: {exc}", file=sys.stderr)
        return 2
    except PortInUse as exc:
        print(f"groundstation {args.command}: {exc}", file=sys.stderr)
        return 2
    except OutputError as exc:
        print(f"groundstation {args.command}: {exc}", file=sys.stderr)
        return 2
    except Exception as exc:
        import zenoh

        from groundstation.recording import RecordingError

        if isinstance(exc, RecordingError):  # names the file and the cause
            print(f"groundstation: {exc}", file=sys.stderr)
            return 2
        if isinstance(exc, zenoh.ZError):  # a session that cannot open
            line = _zenoh_error_line(exc, getattr(args, "loaded_settings", None))
            print(f"groundstation: {line}", file=sys.stderr)
            return 2
        raise


if __name__ == "__main__":
    sys.exit(main())
