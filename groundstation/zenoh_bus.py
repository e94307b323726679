"""The Zenoh adapter: :class:`groundstation.bus.Bus` on a real ``zenoh.Session``.

It only maps key expressions and bytes; validation and estimation live elsewhere. Publishers
declare ``application/json``. Multicast scouting is off unless configured, and there is no
scouting delay, so a session opens at once and connects only where it is told to.

The session must always be closed (:meth:`ZenohBus.close`, or use it as a context manager):
a declared callback subscriber keeps a Python process alive forever otherwise.
"""

from __future__ import annotations

import contextlib
import json
import logging
import threading
import time
from types import TracebackType
from typing import Any

import zenoh

from groundstation.bus import QueryHandler, Sample, SampleHandler, Subscription
from groundstation.config import ZenohSection

__all__ = ["ZenohBus", "make_zenoh_config", "open_session"]

_log = logging.getLogger(__name__)
_JSON = zenoh.Encoding.APPLICATION_JSON
_log_initialised = False
_STREAMS = ("/telemetry", "/estimate", "/truth", "/reel")
"""High-rate keys published without the publisher's id (about 1 µs per put saved): ``who``
matters for commands and events, not for sensor streams."""


def make_zenoh_config(section: ZenohSection) -> zenoh.Config:
    """Build a ``zenoh.Config`` from the ``[zenoh]`` table.

    Order: the optional JSON5 file (TLS, access control), then mode, endpoints, scouting,
    then ``raw`` entries.
    """
    conf = zenoh.Config.from_file(section.config_file) if section.config_file else zenoh.Config()
    conf.insert_json5("mode", json.dumps(section.mode))
    if section.connect:
        conf.insert_json5("connect/endpoints", json.dumps(list(section.connect)))
    if section.listen:
        conf.insert_json5("listen/endpoints", json.dumps(list(section.listen)))
    elif not isinstance(json.loads(conf.get_json("listen/endpoints")), list):
        # Neither the table nor the JSON5 file lists endpoints, so zenoh's per-mode defaults
        # would apply: every interface (a peer on a random port, a router on 7447). Nothing
        # listens beyond loopback unless configured.
        default = ["tcp/127.0.0.1:7447"] if section.mode == "router" else []
        conf.insert_json5("listen/endpoints", json.dumps(default))
    conf.insert_json5("scouting/multicast/enabled", json.dumps(section.multicast_scouting))
    # A session waits scouting/delay for peers before returning; we know our endpoints.
    conf.insert_json5("scouting/delay", "0")
    for path, value in section.raw.items():
        conf.insert_json5(path, json.dumps(value))
    return conf


def open_session(section: ZenohSection) -> zenoh.Session:
    """Open a zenoh session for the ``[zenoh]`` table (logging from ``RUST_LOG`` or errors)."""
    global _log_initialised
    if not _log_initialised:
        zenoh.init_log_from_env_or("error")
        _log_initialised = True
    return zenoh.open(make_zenoh_config(section))


def _source(sample: zenoh.Sample) -> str | None:
    """The publisher's session id, when it attached its source info (ours do)."""
    try:
        info = sample.source_info
    except AttributeError:  # the unstable API went away
        return None
    return None if info is None else str(info.source_id.zid)


_CALLBACK_THREAD = "pyo3-closure"
_open_lock = threading.Lock()
_open_buses = 0  # buses of this process that own an open session


def join_callback_threads(timeout_s: float = 2.0) -> int:
    """Wait for zenoh-python's callback threads to end once their session is closed.

    zenoh runs each Python callback on a daemon thread of its own (named ``pyo3-closure``)
    that waits in Rust for the next sample. One still waiting when the interpreter finalizes
    is torn down inside Rust code, which aborts the process ("FATAL: exception not rethrown",
    status 134) after an otherwise clean exit. Closing the session ends their channels; this
    lets them return before the interpreter does.

    Returns:
        How many such threads were still alive after ``timeout_s`` (0 when all ended).
    """
    deadline = time.monotonic() + timeout_s
    left = 0
    for thread in threading.enumerate():
        if _CALLBACK_THREAD in thread.name and thread is not threading.current_thread():
            thread.join(max(0.0, deadline - time.monotonic()))
            left += thread.is_alive()
    return left


class _Handle:
    def __init__(self, entity: Any) -> None:
        self._entity = entity
        self._lock = threading.Lock()

    def close(self) -> None:
        with self._lock:
            entity, self._entity = self._entity, None
        if entity is not None:
            with contextlib.suppress(zenoh.ZError):  # session already closed
                entity.undeclare()


class ZenohBus:
    """:class:`~groundstation.bus.Bus` over a zenoh session."""

    def __init__(self, section: ZenohSection | None = None, session: zenoh.Session | None = None):
        self._owns_session = session is None
        self.session = session if session is not None else open_session(section or ZenohSection())
        if self._owns_session:
            # The id other processes see as ``who`` in the service's action log.
            _log.info("zenoh session %s", self.session.info.zid())
            global _open_buses
            with _open_lock:
                _open_buses += 1
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._source_info: dict[str, Any] = {}
        self._lock = threading.Lock()
        self._closed = False

    def __enter__(self) -> ZenohBus:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def publish(self, key: str, payload: bytes) -> None:
        pub = self._publishers.get(key)
        if pub is None:
            with self._lock:
                if self._closed:
                    return
                pub = self._publishers.get(key)
                if pub is None:
                    pub = self.session.declare_publisher(key, encoding=_JSON)
                    if not key.endswith(_STREAMS):
                        with contextlib.suppress(AttributeError, zenoh.ZError):  # unstable API
                            self._source_info[key] = zenoh.SourceInfo(pub.id, 0)
                    self._publishers[key] = pub
        # The publisher's id travels with the sample, so a receiver can say who sent a
        # command (``Sample.source``; the service's operator log and events).
        info = self._source_info.get(key)
        if info is None:
            pub.put(payload)
        else:
            pub.put(payload, source_info=info)

    def subscribe(self, keyexpr: str, handler: SampleHandler) -> Subscription:
        def callback(sample: zenoh.Sample) -> None:
            try:
                handler(Sample(str(sample.key_expr), sample.payload.to_bytes(), _source(sample)))
            except Exception:  # never let a handler error unwind into zenoh's thread
                _log.exception("subscriber handler for %s raised", keyexpr)

        return _Handle(self.session.declare_subscriber(keyexpr, callback))

    def queryable(self, keyexpr: str, handler: QueryHandler) -> Subscription:
        def callback(query: zenoh.Query) -> None:
            try:
                for reply in handler(str(query.key_expr)):
                    query.reply(reply.key, reply.payload, encoding=_JSON)
            except Exception:
                _log.exception("queryable handler for %s raised", keyexpr)

        return _Handle(self.session.declare_queryable(keyexpr, callback))

    def query(self, selector: str, timeout_s: float = 1.0) -> list[Sample]:
        out: list[Sample] = []
        for reply in self.session.get(selector, timeout=timeout_s):
            ok = reply.ok
            if ok is not None:
                out.append(Sample(str(ok.key_expr), ok.payload.to_bytes()))
        return out

    def liveliness_token(self, key: str) -> Subscription:
        return _Handle(self.session.liveliness().declare_token(key))

    def alive(self, keyexpr: str, timeout_s: float = 1.0) -> list[str]:
        """Keys of the liveliness tokens matching ``keyexpr`` alive now, sorted."""
        keys = []
        for reply in self.session.liveliness().get(keyexpr, timeout=timeout_s):
            ok = reply.ok
            if ok is not None:
                keys.append(str(ok.key_expr))
        return sorted(keys)

    @property
    def zid(self) -> str:
        """This session's zenoh id (hex), as receivers see it in ``Sample.source``."""
        return str(self.session.info.zid())

    def peer_count(self) -> int:
        """Zenoh peers and routers this session is connected to now."""
        info = self.session.info
        return len(info.peers_zid()) + len(info.routers_zid())

    def close(self) -> None:
        with self._lock:
            if self._closed:
                return
            self._closed = True
            publishers = list(self._publishers.values())
            self._publishers.clear()
        for pub in publishers:
            with contextlib.suppress(zenoh.ZError):
                pub.undeclare()
        if self._owns_session:
            self.session.close()
            global _open_buses
            with _open_lock:
                _open_buses -= 1
                last = _open_buses == 0
            if last:  # another open session's threads would wait for its samples
                join_callback_threads()
