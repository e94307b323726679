"""HTML readouts of the panel. viser renders HTML as is, so every string from the bus is
escaped here."""

from __future__ import annotations

import html
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

from groundstation.dashboard.model import StopSeen, tension_norm_n
from groundstation.messages import Estimate, FollowInfo, Status, Truth

__all__ = [
    "SMOOTH_VIEW_NOTE",
    "BusView",
    "LinkStats",
    "follow_html",
    "health_html",
    "link_warning_html",
    "stop_html",
    "tension_html",
]

SMOOTH_VIEW_NOTE = (
    "A smooth 3D view needs hardware WebGL: a GPU and the browser's hardware acceleration "
    "on. With software rendering (no GPU, a remote desktop, a VM, --disable-gpu) the view "
    "runs at 2–6 frames/s (docs/dashboard.md); the readouts and buttons are not affected."
)


def _fmt(value: float | None, unit: str, digits: int = 3) -> str:
    return "—" if value is None else f"{value:.{digits}f} {unit}"


def _fmt_vec(value: Sequence[float] | None, digits: int = 3) -> str:
    if value is None:
        return "—"
    return "(" + ", ".join(f"{v:+.{digits}f}" for v in value) + ")"


def _table(rows: Iterable[tuple[str, str]]) -> str:
    body = "".join(
        f'<tr><td style="padding:1px 8px 1px 0;color:#666;white-space:nowrap">{k}</td>'
        f'<td style="padding:1px 0;font-variant-numeric:tabular-nums">{v}</td></tr>'
        for k, v in rows
    )
    return f'<table style="width:100%;font-size:0.8rem;border-collapse:collapse">{body}</table>'


def badge(text: str, rgb: str) -> str:
    """A small coloured tag (text escaped)."""
    return (
        f'<span style="background:{rgb};color:white;border-radius:4px;padding:0 5px;'
        f'margin-right:4px;font-size:0.75rem">{html.escape(text)}</span>'
    )


def note_html(text: str, color: str = "#666") -> str:
    """A line of small text (escaped)."""
    return f'<div style="font-size:0.75rem;color:{color}">{html.escape(text, quote=False)}</div>'


def warning_html(text: str) -> str:
    """A boxed warning (escaped)."""
    return (
        '<div role="alert" style="font-size:0.8rem;color:#c92a2a;background:#fff5f5;'
        'border:1px solid #ffc9c9;border-radius:4px;padding:3px 6px">'
        f"{html.escape(text, quote=False)}</div>"
    )


def tension_html(est: Estimate | None, truth: Truth | None = None) -> str:
    """Readouts of the tension and the position estimate (|T|, H, T_v, position ± std)."""
    if est is None:
        return '<div style="font-size:0.8rem;color:#888">no Estimate yet</div>'
    rows = [
        ("|T|", f"<b>{tension_norm_n(est):.3f} N</b>"),
        ("H", _fmt(est.horizontal_n, "N")),
        ("T_v", _fmt(est.vertical_n, "N")),
        ("T (world)", _fmt_vec(est.tension_n) + " N"),
        ("σ_T", "(" + ", ".join(f"{1e3 * v:.1f}" for v in est.tension_std_n) + ") mN"),
        ("position", _position(est)),
        ("σ_position", _fmt_vec(est.position_std_m) + (" m" if est.position_std_m else "")),
    ]
    if est.radial_m is not None:
        radial = _fmt(est.radial_m, "m")
        if est.radial_interval_m is not None:
            lo, hi = est.radial_interval_m
            radial += f" [{lo:.2f}, {hi:.2f}]"
        rows.append(("radial r", radial))
    if est.length_m is not None:
        rows.append(("tether length", _fmt(est.length_m, "m")))
    if est.azimuth_source is not None:
        rows.append(("azimuth from", html.escape(est.azimuth_source)))
    rows.append(("calibration", html.escape(est.calibration)))
    if truth is not None:
        rows.append(("|T| truth (sim)", _fmt(math.hypot(*truth.tension_n), "N")))
        if est.position_m is not None:
            error_m = math.dist(est.position_m, truth.position_m)
            rows.append(("position error (sim)", f"{100.0 * error_m:.1f} cm"))
        rows.append(("tether on floor (sim)", "yes" if truth.floor_contact else "no"))
    badges = []
    if est.on_ground:
        badges.append(badge("on ground", "#868e96"))
    if not est.converged:
        badges.append(badge("converging", "#f08c00"))
    if est.floor_contact:
        badges.append(badge("tether on floor", "#96703c"))
    if est.azimuth_determined is False:
        badges.append(badge("azimuth undetermined", "#f08c00"))
    if est.calibration == "none":
        badges.append(badge("uncalibrated", "#f08c00"))
    if est.calibration_extrapolated:
        badges.append(badge("battery outside calibration", "#e03131"))
    warn = warning_html(UNCALIBRATED_NOTE) if _uncalibrated_position(est) else ""
    return (
        _table(rows)
        + warn
        + (f'<div style="margin-top:3px">{"".join(badges)}</div>' if badges else "")
    )


UNCALIBRATED_NOTE = (
    "Uncalibrated: this position can be about 1 m off (realistic simulator, real Crazyflie "
    "errors: median 95 cm, p95 128 cm; calibrated 8 cm; real flights 0.9-1.4 m), even on the "
    "wrong side of the base. Calibrate: groundstation calibrate (docs/calibration.md)."
)
"""Said where the position is shown (a small badge alone went unnoticed at 167 cm off). The
figures are docs/results_summary.md's (realistic profile, every error class at its size)."""


def _uncalibrated_position(est: Estimate) -> bool:
    """A tether-based position with no calibration in force (motion capture as the azimuth
    source still takes r and z from the uncalibrated tension)."""
    return est.calibration == "none" and est.position_m is not None


def _position(est: Estimate) -> str:
    if est.position_m is None:
        return _fmt_vec(None) + " (undetermined)"
    text = _fmt_vec(est.position_m) + " m"
    if _uncalibrated_position(est):
        text += ' <span style="color:#c92a2a;font-weight:600">± ~1 m uncalibrated</span>'
    return text


def stop_html(stop: StopSeen | None, now_s: float, telemetry_age_s: float | None) -> str:
    """The last Stop seen on the bus: sent, then acknowledged once telemetry confirms it.

    Args:
        stop: the Stop and its confirmation (None: none seen).
        now_s: ``time.monotonic()``, seconds.
        telemetry_age_s: seconds since the last telemetry (None: never).
    """
    if stop is None:
        return ""
    age_s = max(0.0, now_s - stop.rx_s)
    reason = html.escape(stop.reason)
    if stop.confirmed_s is not None:
        after_s = max(0.0, stop.confirmed_s - stop.rx_s)
        return (
            '<div style="color:#2b8a3e;font-weight:600;font-size:0.8rem">'
            f"Stop acknowledged: {html.escape(stop.confirmed_by)} {after_s:.1f} s after it "
            f"was sent ({reason}, {age_s:.0f} s ago)</div>"
        )
    waiting = (
        "no telemetry since: not confirmed"
        if telemetry_age_s is None or telemetry_age_s > age_s
        else "waiting for telemetry to confirm (disarmed or thrust gone)"
    )
    return (
        '<div style="color:#e03131;font-weight:600;font-size:0.8rem">'
        f"Stop sent {age_s:.1f} s ago ({reason}); {waiting}</div>"
    )


def follow_html(follow: FollowInfo | None) -> str:
    """State of tension following and tug-to-land."""
    parts: list[str] = []
    if follow is None:
        parts.append('<span style="color:#888">no follow state reported</span>')
    else:
        if follow.enabled:
            parts.append(
                badge(
                    "following" if follow.active else "armed, below threshold",
                    "#2f9e44" if follow.active else "#1c7ed6",
                )
            )
        else:
            parts.append(badge("follow off", "#868e96"))
        if follow.land_below_m is not None:
            parts.append(badge(f"tug-to-land below {follow.land_below_m:.2f} m", "#1098ad"))
        if follow.landing_armed:
            parts.append(badge("landing armed", "#f08c00"))
        if follow.stopped:
            parts.append(badge("STOPPED", "#e03131"))
        if follow.reason:
            parts.append(f'<span style="color:#666">reason: {html.escape(follow.reason)}</span>')
    return f'<div style="font-size:0.8rem">{" ".join(parts)}</div>'


@dataclass(frozen=True)
class LinkStats:
    """Link health the dashboard measures itself (beside the service's status)."""

    telemetry_hz: float
    estimate_hz: float
    telemetry_age_s: float | None
    invalid: Mapping[str, int] = field(default_factory=dict)
    """Payloads the dashboard itself could not parse, per kind."""


@dataclass(frozen=True)
class BusView:
    """What the dashboard knows of the services on its bus (from its last polls).

    Attributes:
        any_status: some service answered ``tether/*/status`` recently (it answers only for
            drones it has heard).
        services: the services' liveliness tokens alive at the last poll
            (``groundstation/service/{instance}``): a service is running even before any
            drone has reported to it.
        own_peers: zenoh peers and routers of the dashboard's own session (None: not known,
            an in-memory bus).
    """

    any_status: bool
    services: tuple[str, ...] = ()
    own_peers: int | None = None


def link_warning_html(view: BusView, status: Status | None = None) -> str:
    """What connects this dashboard to a service: a warning when nothing does, a note when a
    service runs but no drone has reported to it yet, empty when all is well.

    Args:
        view: what the dashboard's polls found.
        status: the selected drone's current status reply (its ``peers`` and ``alone_ok``).
    """
    if not view.any_status and not view.services:
        mine = (
            ""
            if view.own_peers is None
            else f" This dashboard is connected to {view.own_peers} zenoh peer(s)/router(s)."
        )
        return warning_html(
            "No service answers tether/*/status and none holds a liveliness token "
            "(groundstation/service/*): no router or peer reachable from this dashboard, or "
            f"no service running. Commands from this page reach nobody.{mine}"
        )
    if not view.any_status:
        names = ", ".join(t.rsplit("/", 1)[-1] for t in view.services)
        return note_html(
            f"Service running (instance {names}); no drone has reported to it yet, so it "
            "has no status to give.",
            color="#2f9e44",
        )
    if status is not None and status.peers == 0 and not status.alone_ok:
        return warning_html(
            "The service reports 0 peers: no router or peer is connected to it, so no drone "
            "or reel outside its process can reach it."
        )
    return ""


def health_html(status: Status | None, local: LinkStats, stale_after_s: float) -> str:
    """Link health: rates, age of the last message, invalid and dropped counts, stale state,
    and the service's peer count."""
    stale = local.telemetry_age_s is None or local.telemetry_age_s > stale_after_s
    if status is not None and status.stale is not None:
        stale = stale or status.stale
    rows: list[tuple[str, str]] = [
        ("link", badge("STALE", "#e03131") if stale else badge("live", "#2f9e44")),
        ("telemetry (here)", f"{local.telemetry_hz:.0f} Hz"),
        ("estimates (here)", f"{local.estimate_hz:.0f} Hz"),
        (
            "last telemetry",
            "—" if local.telemetry_age_s is None else f"{local.telemetry_age_s:.2f} s ago",
        ),
    ]
    if status is None:
        rows.append(("service status", '<span style="color:#888">no reply</span>'))
    else:

        def num(value: float | int | None, fmt: str) -> str:
            return "—" if value is None else fmt.format(value)

        rows += [
            ("telemetry (service)", num(status.telemetry_hz, "{:.0f} Hz")),
            ("estimates (service)", num(status.estimate_hz, "{:.0f} Hz")),
            ("last seen (service)", num(status.last_seen_age_s, "{:.2f} s ago")),
            (
                "received / accepted",
                f"{num(status.received, '{:d}')} / {num(status.accepted, '{:d}')}",
            ),
        ]
        if status.peers is not None:
            peers = f"{status.peers:d}"
            if status.peers == 0 and status.alone_ok:
                peers += " (in-process, as expected: demo)"
            elif status.peers == 0:
                peers = badge(peers, "#e03131")
            rows.append(("peers (service)", peers))
        if status.drops:
            text = ", ".join(f"{html.escape(k)}: {v}" for k, v in sorted(status.drops.items()))
            rows.append(("invalid / dropped", f"{sum(status.drops.values())} ({text})"))
        else:
            rows.append(("invalid / dropped", "0"))
        rows.append(("queue overflow", num(status.queue_overflow, "{:d}")))
    if local.invalid:
        text = ", ".join(f"{html.escape(k)}: {v}" for k, v in sorted(local.invalid.items()))
        rows.append(("unparsable (here)", text))
    return _table(rows)
