"""The bus seen by the service, simulator, dashboard and recorder: bytes on key expressions.

:class:`Bus` is the interface; :class:`InMemoryBus` serves unit tests and single-process runs
(as httpx pairs a transport with ``MockTransport``), :class:`groundstation.zenoh_bus.ZenohBus`
is the real adapter. Both deliver callbacks on a thread that is not the caller's, so code
written against one behaves the same on the other: callbacks must only validate and hand over.
"""

from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

__all__ = [
    "Bus",
    "InMemoryBus",
    "PeerWatch",
    "QueryHandler",
    "Sample",
    "SampleHandler",
    "Subscription",
    "describe_endpoints",
    "keyexpr_matches",
    "patterns_overlap",
]

_log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class Sample:
    """One message on the bus."""

    key: str
    payload: bytes
    source: str | None = None
    """Who published it, where the transport says: the zenoh session id (hex) of the
    publisher, or None (an in-memory bus, a publisher that does not attach its id)."""


SampleHandler = Callable[[Sample], None]
QueryHandler = Callable[[str], "list[Sample]"]
"""Called with the query's key expression; returns the replies."""


class Subscription(Protocol):
    def close(self) -> None: ...


class Bus(Protocol):
    """Publish/subscribe/query on key expressions (zenoh's ``*`` and ``**`` wildcards)."""

    def publish(self, key: str, payload: bytes) -> None: ...

    def subscribe(self, keyexpr: str, handler: SampleHandler) -> Subscription: ...

    def queryable(self, keyexpr: str, handler: QueryHandler) -> Subscription: ...

    def query(self, selector: str, timeout_s: float = 1.0) -> list[Sample]: ...

    def liveliness_token(self, key: str) -> Subscription: ...

    def alive(self, keyexpr: str, timeout_s: float = 1.0) -> list[str]:
        """Keys of the liveliness tokens matching ``keyexpr`` that are alive now (e.g.
        ``groundstation/service/*``: the services running)."""
        ...

    def close(self) -> None: ...


class PeerWatch:
    """Says when a process is connected to nobody, and when that changes.

    ``poll`` is called now and then (a worker's tick, a CLI's wait loop) with the clock; it
    asks ``count()`` (:meth:`groundstation.zenoh_bus.ZenohBus.peer_count`) and logs: a warning
    once ``grace_s`` has passed with no peer or router ("no peer / no router reachable at
    ..."), info when the count goes from 0 to more, a warning when it drops back to 0.

    Args:
        count: returns the number of connected zenoh peers + routers.
        where: what to name in the message: the connect endpoints (or that there are none)
            and the listen endpoints, e.g. from :func:`describe_endpoints`.
        what: the process, e.g. ``"groundstation serve"``.
        logger: where to log.
        grace_s: how long connecting may take before "no peer" is said, s.
        alone_ok: being alone is normal (``demo``: everything in one process): the "no
            peer" message is only a debug line.
    """

    def __init__(
        self,
        count: Callable[[], int],
        where: str,
        what: str,
        logger: logging.Logger,
        grace_s: float = 2.0,
        *,
        alone_ok: bool = False,
    ) -> None:
        self._alone_level = logging.DEBUG if alone_ok else logging.WARNING
        self._count = count
        self.where = where
        self.what = what
        self._log = logger
        self.grace_s = grace_s
        self._started_s: float | None = None
        self._warned = False
        self.peers: int | None = None
        """The count at the last poll (None before the first)."""
        self.ever_connected = False

    def poll(self, now_s: float) -> int:
        """Check the count now; log what changed. Returns the count."""
        try:
            peers = int(self._count())
        except Exception:  # a closing session: keep the last count
            return self.peers or 0
        if self._started_s is None:
            self._started_s = now_s
        previous, self.peers = self.peers, peers
        if peers > 0:
            if not self.ever_connected or previous == 0:
                self._log.info("%s: connected to %d zenoh peer(s)/router(s)", self.what, peers)
            self.ever_connected = True
            self._warned = False
        elif self.ever_connected and previous:
            if self._alone_level == logging.WARNING:
                self._log.warning("%s: lost every zenoh peer and router; %s", self.what, self.where)
            else:  # alone is fine (demo): a client (record, a dashboard) went away
                self._log.info("%s: no zenoh peer connected any more", self.what)
            self._warned = True
        elif not self._warned and now_s - self._started_s >= self.grace_s:
            self._log.log(self._alone_level, "%s: %s", self.what, self.where)
            self._warned = True
        return peers


def describe_endpoints(mode: str, connect: tuple[str, ...], listen: tuple[str, ...]) -> str:
    """ "no peer / no router reachable at ..." for the ``[zenoh]`` table's endpoints.

    A router given no listen endpoint listens on ``tcp/127.0.0.1:7447``
    (:func:`groundstation.zenoh_bus.make_zenoh_config`): said so, not "nothing".
    """
    if not listen and mode == "router":
        listen = ("tcp/127.0.0.1:7447",)
    heard = f"; listening on {', '.join(listen)}" if listen else "; listening on nothing"
    if connect:
        return (
            f"no peer / no router reachable at {', '.join(connect)} (mode {mode}{heard}); "
            "still trying: is the router up, is the address right?"
        )
    return (
        f"no peer / no router connected: nothing to connect to ([zenoh] connect is empty, "
        f"mode {mode}{heard}); pass --connect tcp/HOST:7447 to reach a router"
        + (", or connect the others to the listen endpoint" if listen else "")
    )


def keyexpr_matches(keyexpr: str, key: str) -> bool:
    """Whether concrete ``key`` is matched by ``keyexpr`` (``*``: one chunk, ``**``: any).

    Chunks may also carry ``$*`` (or ``*``) inside them (``lab-a-$*``), as in zenoh.
    """
    return _match(keyexpr.replace("$*", "*").split("/"), key.split("/"))


def patterns_overlap(a: str, b: str) -> bool:
    """Whether two drone-id patterns (one key chunk each, ``*`` or zenoh's ``$*`` for any
    run of characters, e.g. ``lab-a-*``) match at least one common drone id.

    Two glob patterns share a match iff their characters can be walked together, a ``*`` on
    either side standing for any run of the other's characters (stars included).
    """
    p, q = a.replace("$*", "*"), b.replace("$*", "*")
    seen: set[tuple[int, int]] = set()
    stack = [(0, 0)]
    while stack:
        i, j = stack.pop()
        if (i, j) in seen:
            continue
        seen.add((i, j))
        if i == len(p) and j == len(q):
            return True
        if i < len(p) and p[i] == "*":
            stack.append((i + 1, j))  # the star matches nothing more
            if j < len(q):
                stack.append((i, j + 1))  # the star takes q's next character (or star)
        if j < len(q) and q[j] == "*":
            stack.append((i, j + 1))
            if i < len(p):
                stack.append((i + 1, j))
        if i < len(p) and j < len(q) and p[i] == q[j] != "*":
            stack.append((i + 1, j + 1))
    return False


def _chunk_matches(pattern: str, chunk: str) -> bool:
    if pattern == "*":
        return True
    if "*" not in pattern:
        return pattern == chunk
    parts = pattern.split("*")
    if not chunk.startswith(parts[0]) or not chunk.endswith(parts[-1]):
        return False
    pos = len(parts[0])
    end = len(chunk) - len(parts[-1])
    for mid in parts[1:-1]:
        idx = chunk.find(mid, pos, end)
        if idx < 0:
            return False
        pos = idx + len(mid)
    return pos <= end


def _match(pattern: list[str], chunks: list[str]) -> bool:
    if not pattern:
        return not chunks
    head = pattern[0]
    if head == "**":
        return any(_match(pattern[1:], chunks[i:]) for i in range(len(chunks) + 1))
    if not chunks:
        return False
    return _chunk_matches(head, chunks[0]) and _match(pattern[1:], chunks[1:])


class _Closer:
    def __init__(self, fn: Callable[[], None]) -> None:
        self._fn: Callable[[], None] | None = fn

    def close(self) -> None:
        fn, self._fn = self._fn, None
        if fn is not None:
            fn()


class InMemoryBus:
    """A process-local bus with the :class:`Bus` interface.

    Publications are delivered in order on one dispatcher thread, like a transport would,
    so publishers never run subscriber code on their own stack.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._subs: dict[int, tuple[str, SampleHandler]] = {}
        self._queryables: dict[int, tuple[str, QueryHandler]] = {}
        self._tokens: set[str] = set()
        self._next_id = 0
        self._queue: queue.SimpleQueue[Sample | None] = queue.SimpleQueue()
        self._closed = False
        self._idle = threading.Condition()
        self._pending = 0
        self._thread = threading.Thread(target=self._dispatch, name="inmemory-bus", daemon=True)
        self._thread.start()

    def _new_id(self) -> int:
        self._next_id += 1
        return self._next_id

    def publish(self, key: str, payload: bytes) -> None:
        if self._closed:
            return
        with self._idle:
            self._pending += 1
        self._queue.put(Sample(key, bytes(payload)))

    def subscribe(self, keyexpr: str, handler: SampleHandler) -> Subscription:
        with self._lock:
            sid = self._new_id()
            self._subs[sid] = (keyexpr, handler)
        return _Closer(lambda: self._drop(self._subs, sid))

    def queryable(self, keyexpr: str, handler: QueryHandler) -> Subscription:
        with self._lock:
            qid = self._new_id()
            self._queryables[qid] = (keyexpr, handler)
        return _Closer(lambda: self._drop(self._queryables, qid))

    def query(self, selector: str, timeout_s: float = 1.0) -> list[Sample]:
        with self._lock:
            handlers = list(self._queryables.values())
        replies: list[Sample] = []
        for keyexpr, handler in handlers:
            if _intersects(keyexpr, selector):
                replies.extend(handler(selector))
        return replies

    def liveliness_token(self, key: str) -> Subscription:
        with self._lock:
            self._tokens.add(key)
        return _Closer(lambda: self._tokens.discard(key))

    def alive(self, keyexpr: str, timeout_s: float = 1.0) -> list[str]:
        """Liveliness tokens matching ``keyexpr``, sorted (``timeout_s`` unused: local)."""
        with self._lock:
            return sorted(t for t in self._tokens if keyexpr_matches(keyexpr, t))

    def flush(self, timeout_s: float = 5.0) -> bool:
        """Wait until every publication so far has been delivered. Returns False on timeout."""
        with self._idle:
            return self._idle.wait_for(lambda: self._pending == 0, timeout=timeout_s)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._queue.put(None)
        self._thread.join(timeout=2.0)

    def _drop(self, table: dict[int, Any], ident: int) -> None:
        with self._lock:
            table.pop(ident, None)

    def _dispatch(self) -> None:
        while True:
            sample = self._queue.get()
            if sample is None:
                return
            with self._lock:
                handlers = [h for k, h in self._subs.values() if keyexpr_matches(k, sample.key)]
            for handler in handlers:
                try:
                    handler(sample)
                except Exception:  # a bad handler must not kill delivery to the others
                    _log.exception("handler for %s raised", sample.key)
            with self._idle:
                self._pending -= 1
                if self._pending == 0:
                    self._idle.notify_all()


def _intersects(a: str, b: str) -> bool:
    """Whether two key expressions can match a common key (enough for queries here)."""
    if "*" not in b:
        return keyexpr_matches(a, b)
    if "*" not in a:
        return keyexpr_matches(b, a)
    return keyexpr_matches(a, b) or keyexpr_matches(b, a)
