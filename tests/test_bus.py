"""The in-memory bus and key-expression matching."""

import threading

import pytest

from groundstation.bus import InMemoryBus, Sample, keyexpr_matches


@pytest.mark.parametrize(
    ("expr", "key", "ok"),
    [
        ("tether/*/telemetry", "tether/cf1/telemetry", True),
        ("tether/*/telemetry", "tether/cf1/reel", False),
        ("tether/*/telemetry", "tether/a/b/telemetry", False),
        ("tether/**", "tether/cf1/cmd/stop", True),
        ("tether/**", "tether", True),
        ("tether/lab-a-*/telemetry", "tether/lab-a-7/telemetry", True),
        ("tether/lab-a-*/telemetry", "tether/lab-b-7/telemetry", False),
        ("tether/**/stop", "tether/x/cmd/stop", True),
    ],
)
def test_keyexpr(expr: str, key: str, ok: bool) -> None:
    assert keyexpr_matches(expr, key) is ok


def test_publish_subscribe_in_order_on_another_thread() -> None:
    bus = InMemoryBus()
    got: list[Sample] = []
    threads: set[int] = set()

    def handler(s: Sample) -> None:
        got.append(s)
        threads.add(threading.get_ident())

    sub = bus.subscribe("tether/*/telemetry", handler)
    for i in range(100):
        bus.publish("tether/a/telemetry", str(i).encode())
    bus.publish("tether/a/reel", b"x")
    assert bus.flush()
    assert [s.payload for s in got] == [str(i).encode() for i in range(100)]
    assert threading.get_ident() not in threads
    sub.close()
    bus.publish("tether/a/telemetry", b"late")
    assert bus.flush()
    assert len(got) == 100
    bus.close()


def test_query_and_liveliness() -> None:
    bus = InMemoryBus()
    q = bus.queryable("tether/*/status", lambda sel: [Sample("tether/a/status", b"{}")])
    assert bus.query("tether/*/status") == [Sample("tether/a/status", b"{}")]
    assert bus.query("tether/a/status") == [Sample("tether/a/status", b"{}")]
    assert bus.query("other/**") == []
    q.close()
    assert bus.query("tether/*/status") == []
    tok = bus.liveliness_token("groundstation/service/1")
    assert bus.alive("groundstation/service/*") == ["groundstation/service/1"]
    tok.close()
    assert bus.alive("groundstation/service/*") == []
    bus.close()


def test_failing_handler_does_not_stop_delivery() -> None:
    bus = InMemoryBus()
    got: list[Sample] = []

    def bad(s: Sample) -> None:
        raise RuntimeError("boom")

    bus.subscribe("k", bad)
    bus.subscribe("k", got.append)
    bus.publish("k", b"1")
    assert bus.flush()
    assert got == [Sample("k", b"1")]
    bus.close()


def _glob_matches(pattern: str, s: str) -> bool:
    import re

    return re.fullmatch(re.escape(pattern).replace(r"\*", ".*"), s) is not None


def test_patterns_overlap_agrees_with_brute_force() -> None:
    # Every pattern of up to 3 characters over {a, b, *} against every other: they overlap
    # iff some id of up to 6 characters matches both (longer ids add nothing here).
    import itertools

    from groundstation.bus import patterns_overlap

    ids = ["".join(t) for k in range(7) for t in itertools.product("ab", repeat=k)]
    pats = ["".join(t) for k in range(1, 4) for t in itertools.product("ab*", repeat=k)]
    for p in pats:
        for q in pats:
            brute = any(_glob_matches(p, s) and _glob_matches(q, s) for s in ids)
            assert patterns_overlap(p, q) == brute, (p, q)


@pytest.mark.parametrize(
    ("a", "b", "overlap"),
    [
        ("lab-a-*", "lab-b-*", False),
        ("lab-a-*", "lab-*", True),
        ("lab-a-$*", "*", True),
        ("cf1", "cf1", True),
        ("cf1", "cf2", False),
        ("cf*", "*1", True),
        ("a*b", "b*a", False),
    ],
)
def test_patterns_overlap_on_drone_slices(a: str, b: str, overlap: bool) -> None:
    from groundstation.bus import patterns_overlap

    assert patterns_overlap(a, b) is overlap
    assert patterns_overlap(b, a) is overlap


def test_a_router_without_listen_endpoints_is_said_to_listen_on_7447() -> None:
    """``serve --mode router --headless`` once logged "listening on nothing" while zenoh
    listened on tcp/127.0.0.1:7447 (make_zenoh_config's router default)."""
    from groundstation.bus import describe_endpoints

    assert "listening on tcp/127.0.0.1:7447" in describe_endpoints("router", (), ())
    assert "listening on nothing" in describe_endpoints("peer", (), ())
    assert "listening on tcp/127.0.0.1:9" in describe_endpoints("router", (), ("tcp/127.0.0.1:9",))


@pytest.mark.parametrize(("alone_ok", "level"), [(True, "INFO"), (False, "WARNING")])
def test_losing_the_last_peer_warns_only_where_being_alone_is_wrong(
    caplog: pytest.LogCaptureFixture, alone_ok: bool, level: str
) -> None:
    """The in-process demo once warned "lost every zenoh peer and router… pass
    --connect" whenever a client (a recorder, a dashboard) disconnected."""
    import logging

    from groundstation.bus import PeerWatch

    count = [1]
    log = logging.getLogger("test.peerwatch")
    watch = PeerWatch(lambda: count[0], "where", "demo", log, alone_ok=alone_ok)
    with caplog.at_level(logging.DEBUG, logger="test.peerwatch"):
        watch.poll(0.0)
        count[0] = 0
        watch.poll(1.0)
    last = caplog.records[-1]
    assert last.levelname == level, caplog.text
    assert ("lost every zenoh peer" in last.getMessage()) is not alone_ok, last.getMessage()
