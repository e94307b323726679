"""What the dashboard knows about each drone: the latest payloads, parsed, with 20 s of history.

No viser here. Bus callbacks write raw bytes into an :class:`Inbox` (no parsing on the bus
thread); the update thread turns them into a :class:`DroneState` with :meth:`DroneState.ingest`
at the scene rate, so a 250 Hz feed costs one parse per drone and frame, not per sample.

Every payload is read with its model from :mod:`groundstation.messages` (the one definition
of each payload); a payload that does not validate is counted per kind and not shown.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from groundstation.messages import (
    Estimate,
    Event,
    FollowInfo,
    InvalidMessage,
    Reel,
    Status,
    StopIn,
    Telemetry,
    Truth,
)

__all__ = [
    "EVENTS_KEPT",
    "HISTORY_S",
    "THRUST_GONE_RATIO",
    "TRAIL_S",
    "DroneState",
    "FollowOutcome",
    "History",
    "Inbox",
    "Pending",
    "StopSeen",
    "Throttle",
    "fill_gaps",
    "reconcile",
    "tension_norm_n",
    "unit_quaternion",
]

HISTORY_S = 20.0
"""Chart window, seconds."""
TRAIL_S = 4.0
"""Length of the drawn trail of estimated positions, seconds."""
RATE_WINDOW_S = 1.0
"""Window of the message rates measured here, seconds."""
STATUS_STALE_S = 3.0
"""A status reply older than this is not shown as current, seconds."""
THRUST_GONE_RATIO = 0.05
"""After a Stop, telemetry confirms it when the drone is disarmed or its thrust is below this
fraction of its weight (motors off; a hovering drone reports about 1.0)."""
EVENTS_KEPT = 16
"""Events (``tether/{drone}/events``) kept per drone between two update passes: the service
sends at most 20 per drone and second, and an operator's answer is among the last few."""

Vec3 = tuple[float, float, float]


def tension_norm_n(est: Estimate) -> float:
    """|T| of an Estimate, newtons."""
    x, y, z = est.tension_n
    return math.sqrt(x * x + y * y + z * z)


def unit_quaternion(quat_wxyz: Sequence[float]) -> tuple[float, float, float, float]:
    """``quat_wxyz`` normalised (telemetry need not send a unit quaternion).

    Raises:
        ValueError: a zero quaternion.
    """
    w, x, y, z = (float(q) for q in quat_wxyz)
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    if norm < 1e-6:
        raise ValueError(f"quat_wxyz has zero norm: {tuple(quat_wxyz)!r}")
    return (w / norm, x / norm, y / norm, z / norm)


# --------------------------------------------------------------------------------------------
# Small state helpers.
# --------------------------------------------------------------------------------------------


class Throttle:
    """Lets an action through at most ``rate_hz`` times per second."""

    def __init__(self, rate_hz: float) -> None:
        if not rate_hz > 0.0:
            raise ValueError(f"rate_hz must be > 0, got {rate_hz!r}")
        self.period_s = 1.0 / rate_hz
        self._next_s = -math.inf

    def due(self, now_s: float) -> bool:
        """True (and re-arms) when at least one period has passed since the last True."""
        if now_s < self._next_s:
            return False
        # Re-arm from now, not from the schedule: after a stall, no burst of catch-up work.
        self._next_s = now_s + self.period_s
        return True

    @property
    def next_s(self) -> float:
        """When the next action is due (-inf before the first)."""
        return self._next_s


@dataclass(frozen=True)
class Pending:
    """A value the operator requested and the time after which the report wins again."""

    value: Any
    until_s: float


def reconcile(reported: Any, pending: Pending | None, now_s: float) -> tuple[Any, Pending | None]:
    """What a setting should show: the service's report, or a fresh request not yet reported.

    Returns:
        (value to show, the pending request still held or None).
    """
    if pending is None or reported == pending.value or now_s >= pending.until_s:
        return reported, None
    return pending.value, pending


def fill_gaps(column: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], bool]:
    """Replace NaN by the previous value (the first ones by the first value).

    uPlot draws a NaN as a bridge and breaks on a leading NaN; it only knows ``null`` for gaps,
    which a typed array cannot hold. So a missing motion-capture or position sample is drawn
    as "held" and a series with no value at all is hidden (the returned flag).

    Returns:
        (filled column, whether the column had any finite value).
    """
    col = np.asarray(column, dtype=np.float64)
    valid = np.isfinite(col)
    if not valid.any():
        return np.zeros_like(col), False
    if valid.all():
        return col, True
    idx = np.where(valid, np.arange(len(col)), 0)
    np.maximum.accumulate(idx, out=idx)
    first = int(np.argmax(valid))
    idx[:first] = first
    return col[idx], True


class History:
    """A fixed-size ring of rows (time first), for the 20 s charts."""

    def __init__(self, n_cols: int, capacity: int) -> None:
        self._data = np.full((capacity, n_cols), np.nan)
        self._next = 0
        self._count = 0

    def append(self, row: Sequence[float]) -> None:
        self._data[self._next] = row
        self._next = (self._next + 1) % len(self._data)
        self._count = min(self._count + 1, len(self._data))

    def __len__(self) -> int:
        return self._count

    def window(self, since_s: float) -> npt.NDArray[np.float64]:
        """Rows with time ≥ ``since_s``, oldest first (a copy)."""
        if self._count < len(self._data):
            rows = self._data[: self._count]
        else:
            rows = np.roll(self._data, -self._next, axis=0)
        return rows[rows[:, 0] >= since_s].copy()


# --------------------------------------------------------------------------------------------
# Per-drone state.
# --------------------------------------------------------------------------------------------

KINDS = ("estimate", "telemetry", "truth", "reel", "stop")


class Inbox:
    """Latest payloads of one drone, written by bus callbacks, read by the update thread.

    Each field is a single reference assignment or an int increment under the GIL; the
    reader only needs "the latest", so no lock is taken on the 250 Hz path.
    """

    __slots__ = (
        "estimate",
        "events",
        "last_rx_s",
        "n_estimate",
        "n_events",
        "n_reel",
        "n_stop",
        "n_telemetry",
        "n_truth",
        "reel",
        "status",
        "status_rx_s",
        "stop",
        "stop_rx_s",
        "telemetry",
        "telemetry_rx_s",
        "truth",
    )

    def __init__(self) -> None:
        self.estimate: bytes | None = None
        self.n_estimate = 0
        self.telemetry: bytes | None = None
        self.n_telemetry = 0
        self.telemetry_rx_s: float | None = None
        self.truth: bytes | None = None
        self.n_truth = 0
        self.reel: bytes | None = None
        self.n_reel = 0
        self.stop: bytes | None = None
        self.n_stop = 0
        self.stop_rx_s = 0.0
        self.status: bytes | None = None
        self.status_rx_s = 0.0
        self.events: deque[tuple[int, bytes]] = deque(maxlen=EVENTS_KEPT)
        """The latest Events as ``(n_events when it came, payload)``, oldest first: every
        answer to a command counts, not only the last payload (a deque's append costs as
        little as a reference assignment)."""
        self.n_events = 0
        self.last_rx_s = time.monotonic()
        """When a sample (not a status reply) last arrived for this drone."""


@dataclass(frozen=True)
class FollowOutcome:
    """The service's latest answer about follow for one drone (``tether/{drone}/events``):
    a follow command refused or applied, or follow switched off by the service."""

    n: int
    """Counts the answers seen for this drone (a panel shows each one once)."""
    event: Event

    @property
    def refused(self) -> bool:
        return self.event.kind == "rejected"


@dataclass(frozen=True)
class StopSeen:
    """A Stop seen on ``tether/{drone}/cmd/stop`` and whether telemetry has confirmed it."""

    rx_s: float
    """When the Stop was seen, ``time.monotonic()`` seconds."""
    reason: str
    confirmed_s: float | None = None
    """When telemetry received after the Stop first showed the motors off; None: not yet."""
    confirmed_by: str = ""
    """``disarmed`` or ``thrust gone``."""


# History columns.
H_T, H_TX, H_TY, H_TZ, H_TN, H_THR = range(6)
H_EX, H_EY, H_EZ, H_MX, H_MY, H_MZ = range(6, 12)
H_COLS = 12

LogOnce = Callable[..., None]


class DroneState:
    """What the update thread knows about one drone (only that thread touches it).

    Args:
        drone_id: the drone.
        inbox: where its bus callbacks put the latest payloads.
        color: its colour in the scene, RGB 0–255.
        capacity: history rows kept (≥ 20 s at the scene rate).
        weight_n: the drone's weight, newtons (to read "thrust gone" after a Stop).
    """

    def __init__(
        self,
        drone_id: str,
        inbox: Inbox,
        color: tuple[int, int, int],
        capacity: int,
        weight_n: float,
    ) -> None:
        self.id = drone_id
        self.inbox = inbox
        self.color = color
        self.weight_n = weight_n
        self.seen: dict[str, float] = dict.fromkeys((*KINDS, "status", "events"), 0)
        """What was last parsed: a count per kind, the arrival time for the status."""
        self.estimate: Estimate | None = None
        self.telemetry: Telemetry | None = None
        self.quat_wxyz: tuple[float, float, float, float] | None = None
        self.truth: Truth | None = None
        self.reel: Reel | None = None
        self.status: Status | None = None
        self.last_stop: StopSeen | None = None
        self.follow_outcome: FollowOutcome | None = None
        self._n_outcomes = 0
        self.invalid: dict[str, int] = {}
        self.history = History(H_COLS, capacity)
        self.trail: deque[Vec3] = deque()
        self.trail_t: deque[float] = deque()
        self.rate_mark: tuple[float, int, int] | None = None
        self.telemetry_hz = 0.0
        self.estimate_hz = 0.0
        self.drawn_s = -math.inf

    # ---------------------------------------------------------------- derived

    def telemetry_age_s(self, now_s: float) -> float | None:
        """Seconds since the last telemetry arrived (None: never)."""
        rx_s = self.inbox.telemetry_rx_s
        return None if rx_s is None else max(0.0, now_s - rx_s)

    def silent_s(self, now_s: float) -> float:
        """Seconds since a sample arrived for this drone (status replies do not count)."""
        return max(0.0, now_s - self.inbox.last_rx_s)

    def is_stale(self, now_s: float, stale_after_s: float) -> bool:
        """No telemetry for longer than ``stale_after_s`` (or never)."""
        age_s = self.telemetry_age_s(now_s)
        return age_s is None or age_s > stale_after_s

    def current_status(self, now_s: float) -> Status | None:
        """The service's last status reply, if it is recent."""
        if self.status is None or now_s - self.inbox.status_rx_s > STATUS_STALE_S:
            return None
        return self.status

    def follow(self, now_s: float) -> FollowInfo | None:
        """Follow state: from the latest Estimate, else from the status."""
        if self.estimate is not None:
            return self.estimate.follow
        status = self.current_status(now_s)
        return None if status is None else status.follow

    def calibration(self, now_s: float) -> str | None:
        """The calibration the service applies (Estimate, else status); None: not reported."""
        if self.estimate is not None:
            return self.estimate.calibration
        status = self.current_status(now_s)
        return None if status is None else status.calibration

    def body_position(self) -> Vec3 | None:
        """Where the drone is drawn: the estimate, else motion capture, else truth."""
        if self.estimate is not None and self.estimate.position_m is not None:
            return self.estimate.position_m
        if self.telemetry is not None and self.telemetry.position_m is not None:
            return self.telemetry.position_m
        if self.truth is not None:
            return self.truth.position_m
        return None

    def base_m(self, default_m: Vec3) -> Vec3:
        """The base exit point the service uses (Estimate, reel, status, truth, else config)."""
        for candidate in (
            self.estimate.base_m if self.estimate else None,
            self.reel.base_m if self.reel else None,
            self.status.base_m if self.status else None,
            self.truth.base_m if self.truth else None,
        ):
            if candidate is not None:
                return candidate
        return default_m

    def length_m(self, default_m: float) -> float:
        """The tether length the service uses (Estimate, reel, status, truth, else config)."""
        for candidate in (
            self.estimate.length_m if self.estimate else None,
            self.reel.length_m if self.reel else None,
            self.status.length_m if self.status else None,
            self.truth.length_m if self.truth else None,
        ):
            if candidate is not None and candidate > 0.0:
                return candidate
        return default_m

    # ---------------------------------------------------------------- ingest

    def _read(self, kind: str, payload: bytes, reader: Callable[[bytes], Any], log: LogOnce) -> Any:
        try:
            return reader(payload)
        except (InvalidMessage, ValueError) as exc:
            self.invalid[kind] = self.invalid.get(kind, 0) + 1
            log(f"invalid-{kind}", "unparsable %s from %s: %s", kind, self.id, exc)
            return None

    def ingest(self, now_s: float, log: LogOnce) -> tuple[bool, StopSeen | None]:
        """Parse what is new in the inbox.

        Args:
            now_s: ``time.monotonic()`` of this pass, seconds.
            log: ``log(kind, msg, *args)`` that logs once per kind.

        Returns:
            (anything new, the Stop if one arrived in this pass).
        """
        inbox, seen = self.inbox, self.seen
        changed = False
        new_estimate = False
        new_telemetry = False
        for kind, reader in (
            ("estimate", Estimate.read),
            ("telemetry", Telemetry.parse),
            ("truth", Truth.read),
            ("reel", Reel.parse),
            ("status", Status.read),
        ):
            count = getattr(inbox, f"n_{kind}") if kind != "status" else inbox.status_rx_s
            if count == seen[kind]:
                continue
            seen[kind] = count
            changed = True
            payload = getattr(inbox, kind)
            parsed = None if payload is None else self._read(kind, payload, reader, log)
            if parsed is None:
                continue
            if kind == "telemetry":
                try:
                    self.quat_wxyz = unit_quaternion(parsed.quat_wxyz)
                except ValueError as exc:
                    self.invalid[kind] = self.invalid.get(kind, 0) + 1
                    log("invalid-telemetry", "unparsable telemetry from %s: %s", self.id, exc)
                    continue
                new_telemetry = True
            new_estimate = new_estimate or kind == "estimate"
            setattr(self, kind, parsed)

        new_stop = None
        if inbox.n_stop != seen["stop"]:
            seen["stop"] = inbox.n_stop
            changed = True
            stop = None if inbox.stop is None else self._read("stop", inbox.stop, StopIn.parse, log)
            new_stop = StopSeen(inbox.stop_rx_s, stop.reason if stop is not None else "?")
            self.last_stop = new_stop
        if new_telemetry:
            self._confirm_stop()
        if inbox.n_events != seen["events"]:
            for n, payload in list(inbox.events):  # a copy: the bus thread appends
                if n > seen["events"]:
                    seen["events"] = n
                    changed = True
                    self._on_event(self._read("events", payload, Event.read, log))

        self._measure_rates(now_s)
        if new_estimate and self.estimate is not None:
            self._remember(self.estimate, now_s)
        while self.trail_t and self.trail_t[0] < now_s - TRAIL_S:
            self.trail_t.popleft()
            self.trail.popleft()
        return changed, new_stop

    def _on_event(self, event: Event | None) -> None:
        """Keep the service's answers about follow: a follow command refused or applied,
        or follow switched off by the service (a silent drone)."""
        if event is None or event.kind not in ("rejected", "follow"):
            return
        if event.input not in ("follow", "service"):
            return
        self._n_outcomes += 1
        self.follow_outcome = FollowOutcome(self._n_outcomes, event)

    def _confirm_stop(self) -> None:
        """A Stop is acknowledged by telemetry sent after it: disarmed, or thrust gone. Once
        acknowledged, telemetry that flies again (re-armed, thrust back) ends the stop."""
        stop, telemetry, rx_s = self.last_stop, self.telemetry, self.inbox.telemetry_rx_s
        if stop is None or telemetry is None or rx_s is None or rx_s <= stop.rx_s:
            return
        thrust_gone = telemetry.thrust_n < THRUST_GONE_RATIO * self.weight_n
        if stop.confirmed_s is None:
            if not telemetry.armed or thrust_gone:
                by = "disarmed" if not telemetry.armed else "thrust gone"
                self.last_stop = replace(stop, confirmed_s=rx_s, confirmed_by=by)
        elif telemetry.armed and not thrust_gone:
            self.last_stop = None  # re-armed and flying: the stop is over

    def _measure_rates(self, now_s: float) -> None:
        inbox, mark = self.inbox, self.rate_mark
        if mark is None:
            self.rate_mark = (now_s, inbox.n_telemetry, inbox.n_estimate)
        elif now_s - mark[0] >= RATE_WINDOW_S:
            dt_s = now_s - mark[0]
            self.telemetry_hz = (inbox.n_telemetry - mark[1]) / dt_s
            self.estimate_hz = (inbox.n_estimate - mark[2]) / dt_s
            self.rate_mark = (now_s, inbox.n_telemetry, inbox.n_estimate)

    def _remember(self, est: Estimate, now_s: float) -> None:
        mocap = self.telemetry.position_m if self.telemetry is not None else None
        nan3 = (math.nan, math.nan, math.nan)
        self.history.append(
            (
                now_s,
                *est.tension_n,
                tension_norm_n(est),
                est.follow.threshold_n,
                *(est.position_m or nan3),
                *(mocap or nan3),
            )
        )
        if est.position_m is not None:
            self.trail.append(est.position_m)
            self.trail_t.append(now_s)
