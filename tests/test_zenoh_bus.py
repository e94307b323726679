"""The zenoh adapter: nothing listens beyond loopback unless configured; liveliness."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from groundstation.config import ZenohSection
from groundstation.zenoh_bus import ZenohBus, make_zenoh_config


def _listen(section: ZenohSection) -> object:
    return json.loads(make_zenoh_config(section).get_json("listen/endpoints"))


@pytest.mark.parametrize(
    ("mode", "expected"), [("peer", []), ("client", []), ("router", ["tcp/127.0.0.1:7447"])]
)
def test_no_default_listener_on_every_interface(
    tmp_path: Path, mode: str, expected: list[str]
) -> None:
    # zenoh's own default would be tcp/[::]:0 for a peer (every interface, a random port),
    # also when a JSON5 file (TLS settings) is given that does not list endpoints.
    tls_like = tmp_path / "tls.json5"
    tls_like.write_text("{ transport: { link: { tls: {} } } }")
    assert _listen(ZenohSection(mode=mode)) == expected  # type: ignore[arg-type]
    assert _listen(ZenohSection(mode=mode, config_file=str(tls_like))) == expected  # type: ignore[arg-type]


def test_the_files_and_the_tables_endpoints_are_kept(tmp_path: Path) -> None:
    listening = tmp_path / "l.json5"
    listening.write_text('{ listen: { endpoints: ["tcp/127.0.0.1:0"] } }')
    assert _listen(ZenohSection(config_file=str(listening))) == ["tcp/127.0.0.1:0"]
    section = ZenohSection(config_file=str(listening), listen=("tcp/127.0.0.1:7999",))
    assert _listen(section) == ["tcp/127.0.0.1:7999"]


def test_alive_lists_the_liveliness_tokens_of_this_session() -> None:
    # The dashboard finds a running service by its token, also in ``demo``, where service and
    # dashboard share this one session.
    with ZenohBus(ZenohSection(mode="peer")) as bus:
        token = bus.liveliness_token("groundstation/service/abc")
        assert bus.alive("groundstation/service/*", timeout_s=1.0) == ["groundstation/service/abc"]
        token.close()
        assert bus.alive("groundstation/service/*", timeout_s=0.5) == []


_EXIT_SCRIPT = """
import threading
import time
from groundstation.config import ZenohSection
from groundstation.zenoh_bus import ZenohBus

bus = ZenohBus(ZenohSection(mode="peer"))
subs = [bus.subscribe(f"exit/test/{i}", lambda s: time.sleep(0.3)) for i in range(4)]
for i in range(4):
    bus.publish(f"exit/test/{i}", b"{}")
time.sleep(0.1)  # every callback thread is inside its handler
for sub in subs:
    sub.close()
bus.close()
print(sum("pyo3-closure" in t.name for t in threading.enumerate()))
"""


def test_closing_the_last_bus_lets_zenohs_callback_threads_end_before_exit() -> None:
    # A callback thread still waiting in Rust at interpreter finalization aborts the process
    # (status 134, "FATAL: exception not rethrown") after a clean exit: seen in CI on
    # `crazyflie` exiting with code 2. Closing the last bus joins them.
    import subprocess
    import sys

    out = subprocess.run(
        [sys.executable, "-c", _EXIT_SCRIPT], capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "0", out.stdout
