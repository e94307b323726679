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
