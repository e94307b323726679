"""Stream gate: which telemetry messages enter the estimator, and the time step they bring.

Control only (PX4's ``*_control``): no physics. A message is refused when it repeats or
goes back in the stream (``seq`` or ``stamp_s`` not increasing), unless the stream has
*resumed*: the drone was stale, or silent for more than ``[service] stale_after_s`` of
receive time (one definition of a lost stream at receive time: the service's tick marks the
drone stale after as long, and a pipeline driven without ticks sees the same), after which
any order is accepted as a fresh start (a rebooted drone counts from 0 again) and the
tension filter restarts. Forward ``seq`` jumps are counted as gaps, not refused.

Pure: :func:`gate_step` maps ``(state, message's seq and stamp, receive time)`` to the next
state and a frozen :class:`GateVerdict`; a refused message leaves the state as it was.
"""

from __future__ import annotations

from typing import NamedTuple

__all__ = ["GateState", "GateVerdict", "gate_step", "mark_stale"]


class GateState(NamedTuple):
    """What the gate remembers of one drone's stream.

    Attributes:
        last_seq: ``seq`` of the last accepted message (None: none yet).
        last_stamp_s: its ``stamp_s``, s (drone clock).
        last_seen_s: its receive time, s (service clock).
        stale: silent for ``[service] stale_after_s`` (set by :func:`mark_stale`), or never
            heard; the next message resumes the stream.
    """

    last_seq: int | None = None
    last_stamp_s: float | None = None
    last_seen_s: float | None = None
    stale: bool = True


class GateVerdict(NamedTuple):
    """The gate's decision on one message.

    Attributes:
        drop_kind: None when accepted, else the drop counter's kind (``seq_repeated``,
            ``seq_backwards``, ``stamp_backwards``).
        detail: what to log for a refused message ("" when accepted).
        resumed: the stream restarts with this message (stale or after a long silence):
            the tension filter must restart.
        dt_s: time since the previous accepted message, drone clock, s (0 for the first and
            at a restart: nothing integrates across a gap).
        seq_gap: messages missing just before this one (0 when contiguous or resumed).
    """

    drop_kind: str | None
    detail: str = ""
    resumed: bool = False
    dt_s: float = 0.0
    seq_gap: int = 0


def gate_step(
    state: GateState,
    *,
    seq: int,
    stamp_s: float,
    now_s: float,
    max_gap_s: float,
    drone: str = "",
) -> tuple[GateState, GateVerdict]:
    """One message through the gate.

    Args:
        state: the gate's state before the message.
        seq: the message's sequence number.
        stamp_s: its timestamp, drone clock, s.
        now_s: its receive time, service clock, s.
        max_gap_s: receive-time silence after which the stream resumes and the tension
            filter restarts (the tension may have changed meanwhile), s: ``[service]
            stale_after_s``.
        drone: the drone id, for the refusal's text.

    Returns:
        ``(next state, verdict)``; a refused message returns ``state`` itself.
    """
    last_seq, last_stamp_s, last_seen_s = state.last_seq, state.last_stamp_s, state.last_seen_s
    resumed = state.stale or (last_seen_s is not None and now_s - last_seen_s > max_gap_s)
    if not resumed:
        if last_seq is not None and seq <= last_seq:
            kind = "seq_repeated" if seq == last_seq else "seq_backwards"
            return state, GateVerdict(kind, f"seq {seq} after {last_seq} on {drone}")
        if last_stamp_s is not None and stamp_s <= last_stamp_s:
            return state, GateVerdict(
                "stamp_backwards", f"stamp_s {stamp_s} after {last_stamp_s} on {drone}"
            )
    seq_gap = 0
    if last_seq is not None and seq > last_seq + 1 and not resumed:
        seq_gap = seq - last_seq - 1
    dt_s = 0.0 if last_stamp_s is None or resumed else stamp_s - last_stamp_s
    return GateState(seq, stamp_s, now_s, False), GateVerdict(None, "", resumed, dt_s, seq_gap)


def mark_stale(state: GateState) -> GateState:
    """The drone fell silent: its next message resumes the stream."""
    return GateState(state.last_seq, state.last_stamp_s, state.last_seen_s, True)
