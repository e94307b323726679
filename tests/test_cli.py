"""The command line without a bus: every flag of every command explains itself."""

from __future__ import annotations

import argparse
import signal

import pytest

from groundstation.cli import build_parser


def _subcommands() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(sub.choices)


@pytest.mark.parametrize("command", sorted(_subcommands()))
def test_every_flag_has_a_help_text(command: str) -> None:
    parser = _subcommands()[command]
    missing = [
        "/".join(action.option_strings) or action.dest
        for action in parser._actions
        if action.help is None
    ]
    assert not missing, f"groundstation {command}: flags without help: {missing}"


def test_demo_moves_off_a_busy_default_dashboard_port_loudly(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """``demo`` with 8080 busy once went to 46627 without a word. By default it still
    moves (one command must work) but says so at WARNING; asked for a port, it fails."""
    import socket

    from groundstation import cli
    from groundstation.config import load_settings

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        port = busy.getsockname()[1]
        monkeypatch.setitem(cli.DEMO_DEFAULTS["web"], "port", port)
        settings = load_settings(None, {"web": {"port": port}}, use_env=False)
        with caplog.at_level("WARNING", logger="groundstation"):
            moved = cli._demo_web_port(argparse.Namespace(web_port=None), settings)
        assert moved.web.port not in (port, 0)
        assert f"the dashboard's port 127.0.0.1:{port} is in use" in caplog.text
        assert f"on port {moved.web.port} instead" in caplog.text
        with pytest.raises(cli.PortInUse, match=f"127.0.0.1:{port} is in use"):
            cli._demo_web_port(argparse.Namespace(web_port=port), settings)


def test_demo_moves_off_a_busy_default_bus_port_loudly(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """Only the demo's default bus endpoint moves when taken, at WARNING, to a port that is
    free; the endpoint it listens on is the one it says."""
    import socket

    from groundstation import cli
    from groundstation.config import load_settings

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        port = busy.getsockname()[1]
        monkeypatch.setattr(cli, "ROUTER_ENDPOINT", f"tcp/127.0.0.1:{port}")
        settings = load_settings(None, {}, use_env=False)
        args = argparse.Namespace(listen=[], connect=[], config=None)
        with caplog.at_level("WARNING", logger="groundstation"):
            moved, line = cli._demo_bus(args, settings)
        (endpoint,) = moved.zenoh.listen
        moved_port = int(endpoint.rsplit(":", 1)[1])
        assert moved_port not in (port, 0) and moved.zenoh.mode == "peer"
        assert line == f"zenoh: peer on {endpoint}"
        assert f"tcp/127.0.0.1:{port} is in use" in caplog.text
        assert f"listens on {endpoint} instead" in caplog.text
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", moved_port))  # it was free to take


def test_serve_says_once_when_a_child_exits_and_goes_on(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """A dashboard or Foxglove child that dies (a port taken between serve's check and the
    child's bind) is said at ERROR once, with its status; serve keeps waiting for its stop."""
    import subprocess
    import sys
    import threading

    from groundstation import cli

    child = subprocess.Popen([sys.executable, "-c", "raise SystemExit(2)"])
    child.wait(30)
    stop = threading.Event()
    timer = threading.Timer(1.0, stop.set)
    timer.start()
    try:
        with caplog.at_level("ERROR", logger="groundstation"):
            cli._wait(stop, {"Foxglove server": child})
    finally:
        timer.cancel()
    assert stop.is_set()
    said = [r.getMessage() for r in caplog.records if "exited" in r.getMessage()]
    assert said == [
        f"the Foxglove server (pid {child.pid}) exited with status 2; the service goes on "
        "without it"
    ]


def test_stopping_a_child_that_ignores_sigterm_kills_it_without_raising() -> None:
    """``serve`` stops its dashboard / Foxglove child with SIGTERM, then SIGKILL; a child that
    does not go (ignores SIGTERM, or a busy machine) must not turn the service's exit into a
    traceback with status 1 (it did, seen in CI under load)."""
    import subprocess
    import sys

    from groundstation import cli

    code = (
        "import signal, time; signal.signal(signal.SIGTERM, signal.SIG_IGN); "
        "print(1, flush=True); time.sleep(60)"
    )
    with subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE) as child:
        assert child.stdout is not None and child.stdout.readline()  # SIGTERM ignored now
        cli._stop_child(child, timeout_s=0.2)
        assert child.returncode == -9  # killed


def test_stopping_a_child_that_outlives_the_kill_wait_warns_and_returns(
    caplog: pytest.LogCaptureFixture,
) -> None:
    import subprocess

    from groundstation import cli

    class Stuck:
        pid = 4242
        killed = False

        def poll(self) -> None:
            return None

        def __init__(self) -> None:
            self.signals: list[int] = []

        def send_signal(self, sig: int) -> None:
            self.signals.append(sig)

        def kill(self) -> None:
            self.killed = True

        def wait(self, timeout: float) -> None:
            raise subprocess.TimeoutExpired("child", timeout)

    stuck = Stuck()
    with caplog.at_level("WARNING", logger="groundstation"):
        cli._stop_child(stuck, timeout_s=0.01)
    assert stuck.killed and stuck.signals == [signal.SIGTERM]
    assert "4242" in caplog.text and "SIGKILL" in caplog.text
    # serve signals its children before it closes its own bus, then waits for them: no
    # second SIGTERM (a second signal makes a child exit at once, status 1).
    signalled = Stuck()
    cli._stop_child(signalled, timeout_s=0.01, signalled=True)
    assert signalled.killed and signalled.signals == []
