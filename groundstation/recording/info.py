"""``groundstation info FILE.mcap``: what a recording holds, as ``mcap info`` does for any file.

Keys with message counts and rates, drones, the span on the receive clock and on each drone's
own clock, where each drone's attitude and position came from, the calibration its estimates
applied, battery range, and the gaps in each drone's telemetry. Reads finished and truncated
files (what is readable of a damaged one, with the reader's warning); writes nothing.
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from itertools import pairwise
from pathlib import Path
from typing import Any

from groundstation import messages
from groundstation.recording.reader import is_complete, iter_messages

__all__ = ["GAP_PERIODS", "RecordingInfo", "format_info", "recording_info"]

GAP_PERIODS = 5.0
"""A gap is an interval between consecutive telemetry receive times longer than this many
median periods (a display choice: at 250 Hz, 20 ms; one or two lost samples are not listed)."""


@dataclass
class KeyInfo:
    """One key's messages: count and receive-time span."""

    count: int = 0
    first_ns: int = 0
    last_ns: int = 0
    payload_bytes: int = 0


@dataclass
class DroneInfo:
    """What one drone's messages say."""

    telemetry: int = 0
    invalid_telemetry: int = 0
    estimates: int = 0
    stamp_s: tuple[float, float] | None = None
    """The drone's own clock (Telemetry ``stamp_s``) at its first and last message, s."""
    with_mocap: int = 0
    attitude_sources: dict[str, int] = field(default_factory=dict)
    """Telemetry per ``attitude_source`` (``not said``: the field absent, the service then
    takes ``[drone] attitude_source``)."""
    position_sources: dict[str, int] = field(default_factory=dict)
    """Telemetry with a ``position_m`` per ``position_source`` (absent: ``mocap``)."""
    vbat_v: tuple[float, float] | None = None
    armed: int = 0
    reel: int = 0
    calibrations: list[str] = field(default_factory=list)
    """The calibration sources its recorded estimates applied, in order of appearance."""
    median_period_s: float | None = None
    gaps: list[tuple[float, float]] = field(default_factory=list)
    """(start, length) of each telemetry gap, s since the recording's first message."""


@dataclass
class RecordingInfo:
    """A recording's summary (:func:`recording_info`)."""

    path: str
    size_bytes: int
    finished: bool
    messages: int
    first_ns: int | None
    last_ns: int | None
    keys: dict[str, KeyInfo]
    drones: dict[str, DroneInfo]

    @property
    def span_s(self) -> float:
        if self.first_ns is None or self.last_ns is None:
            return 0.0
        return (self.last_ns - self.first_ns) / 1e9

    def as_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["span_s"] = self.span_s
        return out


def recording_info(path: str | Path) -> RecordingInfo:
    """Read the whole recording once and summarise it.

    Raises:
        RecordingError: the file cannot be opened or is not MCAP.
    """
    path = Path(path)
    keys: dict[str, KeyInfo] = defaultdict(KeyInfo)
    drones: dict[str, DroneInfo] = defaultdict(DroneInfo)
    receive_ns: dict[str, list[int]] = defaultdict(list)
    first_ns: int | None = None
    last_ns: int | None = None
    total = 0
    for msg in iter_messages(path):
        total += 1
        first_ns = msg.log_time_ns if first_ns is None else min(first_ns, msg.log_time_ns)
        last_ns = msg.log_time_ns if last_ns is None else max(last_ns, msg.log_time_ns)
        k = keys[msg.key]
        if k.count == 0:
            k.first_ns = msg.log_time_ns
        k.count += 1
        k.last_ns = max(k.last_ns, msg.log_time_ns)
        k.payload_bytes += len(msg.payload)
        try:
            drone, kind = messages.parse_key(msg.key)
        except messages.InvalidMessage:
            continue
        d = drones[drone]
        if kind == "reel":
            d.reel += 1
        elif kind == "estimate":
            d.estimates += 1
            try:
                source = json.loads(msg.payload).get("calibration")
            except (ValueError, AttributeError):
                source = None
            if isinstance(source, str) and source not in d.calibrations:
                d.calibrations.append(source)
        elif kind == "telemetry":
            try:
                tel = messages.Telemetry.parse(msg.payload)
            except messages.InvalidMessage:
                d.invalid_telemetry += 1
                continue
            d.telemetry += 1
            receive_ns[drone].append(msg.log_time_ns)
            lo, hi = d.stamp_s or (tel.stamp_s, tel.stamp_s)
            d.stamp_s = (min(lo, tel.stamp_s), max(hi, tel.stamp_s))
            d.with_mocap += tel.position_m is not None
            att = tel.attitude_source or "not said"
            d.attitude_sources[att] = d.attitude_sources.get(att, 0) + 1
            if tel.position_m is not None:
                pos = tel.position_source or "mocap"
                d.position_sources[pos] = d.position_sources.get(pos, 0) + 1
            d.armed += bool(tel.armed)
            if tel.vbat_v is not None and math.isfinite(tel.vbat_v):
                vlo, vhi = d.vbat_v or (tel.vbat_v, tel.vbat_v)
                d.vbat_v = (min(vlo, tel.vbat_v), max(vhi, tel.vbat_v))
    for drone, times in receive_ns.items():
        d = drones[drone]
        intervals = sorted(b - a for a, b in pairwise(times))
        if not intervals:
            continue
        median_ns = intervals[len(intervals) // 2]
        d.median_period_s = median_ns / 1e9
        limit = GAP_PERIODS * max(median_ns, 1)
        t0 = first_ns or 0
        d.gaps = [((a - t0) / 1e9, (b - a) / 1e9) for a, b in pairwise(times) if b - a > limit]
    return RecordingInfo(
        path=str(path),
        size_bytes=path.stat().st_size,
        finished=is_complete(path),
        messages=total,
        first_ns=first_ns,
        last_ns=last_ns,
        keys=dict(sorted(keys.items())),
        drones=dict(sorted(drones.items())),
    )


def _utc(ns: int) -> str:
    return datetime.fromtimestamp(ns / 1e9, UTC).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3] + "Z"


def _size(n: int) -> str:
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{n} B"


def _shares(counts: dict[str, int], total: int) -> str:
    """``onboard 100 %``-style shares of ``total``, largest first."""
    ranked = sorted(counts.items(), key=lambda kv: -kv[1])
    return ", ".join(f"{name} {100.0 * n / total:.0f} %" for name, n in ranked)


def format_info(info: RecordingInfo) -> str:
    """The summary as text (one screen for a flight)."""
    lines = [
        f"file:      {info.path} ({_size(info.size_bytes)}, "
        + ("finished" if info.finished else "NOT finished: read up to where it was cut")
        + ")",
    ]
    if info.first_ns is None or info.last_ns is None:
        lines.append("messages:  none readable")
        return "\n".join(lines)
    lines += [
        f"span:      {_utc(info.first_ns)} to {_utc(info.last_ns)} "
        f"({info.span_s:.1f} s, receive clock)",
        f"messages:  {info.messages:,} on {len(info.keys)} keys",
        f"drones:    {', '.join(info.drones) or 'none'}",
    ]
    for name, d in info.drones.items():
        lines.append(f"  {name}:")
        if d.telemetry:
            rate = f", {1.0 / d.median_period_s:.0f} Hz" if d.median_period_s else ""
            assert d.stamp_s is not None
            lines.append(
                f"    telemetry  {d.telemetry:,}{rate}; drone clock {d.stamp_s[0]:.2f} to "
                f"{d.stamp_s[1]:.2f} s ({d.stamp_s[1] - d.stamp_s[0]:.1f} s)"
            )
            lines.append(
                f"    motion capture in {100.0 * d.with_mocap / d.telemetry:.0f} % of them; "
                f"armed in {100.0 * d.armed / d.telemetry:.0f} %"
                + (
                    f"; battery {d.vbat_v[1]:.2f} to {d.vbat_v[0]:.2f} V"
                    if d.vbat_v is not None
                    else ""
                )
            )
        if d.telemetry:
            lines.append(
                "    attitude   "
                + _shares(d.attitude_sources, d.telemetry)
                + (
                    "; position   " + _shares(d.position_sources, d.telemetry)
                    if d.position_sources
                    else ""
                )
            )
        if d.invalid_telemetry:
            lines.append(f"    invalid telemetry: {d.invalid_telemetry:,} (the service drops them)")
        lines.append(
            f"    tether: {d.reel:,} reel messages" if d.reel else "    tether: no reel messages"
        )
        if d.estimates:
            cal = "; ".join(d.calibrations) or "not said"
            lines.append(f"    estimates  {d.estimates:,}; calibration applied: {cal}")
        else:
            lines.append("    estimates: none (replay --offline makes them)")
        if d.gaps:
            worst = max(d.gaps, key=lambda g: g[1])
            lines.append(
                f"    gaps in telemetry (> {GAP_PERIODS:g} periods): {len(d.gaps)}, longest "
                f"{worst[1]:.3f} s at +{worst[0]:.1f} s"
            )
        elif d.telemetry:
            lines.append(f"    gaps in telemetry (> {GAP_PERIODS:g} periods): none")
    lines.append("keys:")
    width = max(len(k) for k in info.keys)
    for key, k in info.keys.items():
        span = (k.last_ns - k.first_ns) / 1e9
        rate = f"{(k.count - 1) / span:8.1f} Hz" if k.count > 1 and span > 0 else " " * 11
        lines.append(f"  {key:<{width}}  {k.count:>9,}  {rate}  {_size(k.payload_bytes):>9}")
    return "\n".join(lines)
