"""The dashboard: a viser scene and control panel that speaks to the service over the bus.

It is an edge, like the simulator: everything it shows comes from the bus and everything it
does is a message on the bus, so it can run in the service's process or in its own.

Reads (subscriptions): ``tether/*/estimate``, ``tether/*/telemetry``, ``tether/*/truth``,
``tether/*/reel`` and ``tether/*/cmd/stop``; about once a second it queries
``tether/*/status`` (the service's health per drone). Writes: ``tether/{drone}/follow``
(FollowCommand), ``tether/{drone}/params`` (tether ω and length) and
``tether/{drone}/cmd/stop`` (the emergency Stop, after a confirmation).

Threads. Bus callbacks only store the latest payload bytes and count them (telemetry comes
at 250 Hz per drone); nothing is parsed there. The dashboard's own update thread parses the
latest payloads and pushes the scene at ``settings.web.scene_rate_hz`` (≤ 30 Hz), the panel
readouts at ≤ 10 Hz and the charts at 4 Hz; a second small thread polls the status. GUI
callbacks run on viser's thread pool and only publish commands.

Truth is the service. The "Follow mode" checkbox and the other settings show what the
service reports in its Estimates and status, so every open browser sees a change made from
anywhere; a click publishes a command and the checkbox holds the requested value for at most
:data:`PENDING_HOLD_S` until the service's report catches up.

Everything is served by viser from the local package: no CDN, fonts or HDRIs from outside
(checked by the browser test). The GUI is shared by every browser (viser's server-level GUI),
including the drone selector; the Stop confirmation is per browser.
"""

from __future__ import annotations

import functools
import html
import importlib
import json
import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import viser
import viser.uplot

from groundstation.bus import Bus, Sample, Subscription
from groundstation.config import Settings
from groundstation.messages import DRONE_ID_RE

__all__ = [
    "CHART_RATE_HZ",
    "HISTORY_S",
    "PANEL_RATE_HZ",
    "PENDING_HOLD_S",
    "Dashboard",
    "DashboardStats",
    "EstimateView",
    "FollowView",
    "History",
    "ReelView",
    "TelemetryView",
    "Throttle",
    "TruthView",
    "camera_framing",
    "fill_gaps",
    "follow_command",
    "health_html",
    "load_quadrotor_mesh",
    "params_command",
    "parse_estimate",
    "parse_reel",
    "parse_telemetry",
    "parse_truth",
    "polyline_segments",
    "reconcile",
    "stop_command",
    "tension_arrow",
    "tension_html",
    "tether_points",
]

_log = logging.getLogger(__name__)

HISTORY_S = 20.0
"""Chart window, seconds."""
TRAIL_S = 4.0
"""Length of the drawn trail of estimated positions, seconds."""
PANEL_RATE_HZ = 10.0
"""Readouts of the selected drone are refreshed at most this often."""
CHART_RATE_HZ = 4.0
"""Charts are re-sent at this rate (each push carries the whole 20 s window)."""
STATUS_PERIOD_S = 1.0
"""How often ``tether/*/status`` is queried."""
STATUS_TIMEOUT_S = 0.5
PENDING_HOLD_S = 3.0
"""A clicked setting shows the requested value this long at most while the service's report
still says otherwise; then the report wins again."""
EDIT_HOLD_S = 30.0
"""A number being edited (not yet applied) is not overwritten by reports for this long."""
ARROW_M_PER_N = 4.0
"""Drawn length of the tension arrow per newton."""
QUAD_DRAW_SCALE = 2.0
"""The 92 mm quadrotor is drawn this much larger than life so that it reads at room scale."""
RATE_WINDOW_S = 1.0
STATUS_STALE_S = 3.0
"""A status reply older than this is not shown as current."""
NO_DRONE = "(no drone yet)"

_PALETTE: tuple[tuple[int, int, int], ...] = (
    (34, 139, 230),
    (240, 140, 0),
    (55, 178, 77),
    (174, 62, 201),
    (224, 49, 49),
    (16, 152, 173),
    (247, 103, 7),
    (112, 72, 232),
)
_TETHER_RGB = (40, 40, 40)
_FLOOR_RUN_RGB = (150, 110, 60)
_TENSION_RGB = (224, 49, 49)
_MOCAP_RGB = (47, 158, 68)
_TRUTH_RGB = (134, 142, 150)
_BASE_RGB = (134, 142, 150)

_MESH_PATHS = (
    # Shipped with the package if package-data carries it, else the repository's web/.
    Path(__file__).resolve().parent.parent / "assets" / "quadrotor.stl",
    Path(__file__).resolve().parent.parent.parent / "web" / "quadrotor.stl",
)


# --------------------------------------------------------------------------------------------
# Parsing: bytes from the bus -> small frozen views. Unknown fields are ignored, as the
# contract says; a missing or malformed required field raises ValueError.
# --------------------------------------------------------------------------------------------


def _finite(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"{name} must be a number, got {value!r}")
    out = float(value)
    if not math.isfinite(out):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return out


def _vec(value: Any, n: int, name: str) -> tuple[float, ...]:
    if not isinstance(value, list | tuple) or len(value) != n:
        raise ValueError(f"{name} must be a list of {n} numbers, got {value!r}")
    return tuple(_finite(v, f"{name}[{i}]") for i, v in enumerate(value))


def _opt_vec(obj: Mapping[str, Any], key: str, n: int) -> tuple[float, ...] | None:
    value = obj.get(key)
    return None if value is None else _vec(value, n, key)


def _opt_float(obj: Mapping[str, Any], key: str) -> float | None:
    value = obj.get(key)
    return None if value is None else _finite(value, key)


def _opt_bool(obj: Mapping[str, Any], key: str) -> bool | None:
    value = obj.get(key)
    if value is None:
        return None
    if not isinstance(value, bool):
        raise ValueError(f"{key} must be a bool, got {value!r}")
    return value


def _load_object(payload: bytes) -> dict[str, Any]:
    try:
        obj = json.loads(payload)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"not JSON: {exc}") from None
    if not isinstance(obj, dict):
        raise ValueError(f"not a JSON object: {type(obj).__name__}")
    return obj


Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class FollowView:
    """The ``follow`` object of an Estimate (or of the status)."""

    enabled: bool = False
    active: bool = False
    threshold_n: float | None = None
    land_below_m: float | None = None
    """None: tug-to-land is off."""
    landing_armed: bool = False
    stopped: bool = False
    reason: str = ""

    @classmethod
    def from_obj(cls, obj: Any) -> FollowView:
        if not isinstance(obj, dict):
            raise ValueError(f"follow must be an object, got {obj!r}")
        reason = obj.get("reason", "")
        return cls(
            enabled=bool(_opt_bool(obj, "enabled")),
            active=bool(_opt_bool(obj, "active")),
            threshold_n=_opt_float(obj, "threshold_n"),
            land_below_m=_opt_float(obj, "land_below_m"),
            landing_armed=bool(_opt_bool(obj, "landing_armed")),
            stopped=bool(_opt_bool(obj, "stopped")),
            reason=reason if isinstance(reason, str) else "",
        )


@dataclass(frozen=True)
class EstimateView:
    """An Estimate as the dashboard uses it (contract fields plus the added ones)."""

    seq: int
    stamp_s: float
    tension_n: Vec3
    tension_std_n: Vec3
    horizontal_n: float
    vertical_n: float
    position_m: Vec3 | None
    follow: FollowView
    position_std_m: Vec3 | None = None
    radial_m: float | None = None
    radial_interval_m: tuple[float, float] | None = None
    azimuth_determined: bool | None = None
    floor_contact: bool | None = None
    on_ground: bool = False
    converged: bool = False
    length_m: float | None = None
    base_m: Vec3 | None = None

    @property
    def tension_norm_n(self) -> float:
        """|T|, newtons."""
        return math.sqrt(sum(c * c for c in self.tension_n))


def parse_estimate(payload: bytes) -> EstimateView:
    """Parse an Estimate payload.

    Raises:
        ValueError: not JSON, or a required field missing or malformed.
    """
    obj = _load_object(payload)
    seq = obj.get("seq")
    if isinstance(seq, bool) or not isinstance(seq, int):
        raise ValueError(f"seq must be an int, got {seq!r}")
    interval = _opt_vec(obj, "radial_interval_m", 2)
    return EstimateView(
        seq=seq,
        stamp_s=_finite(obj.get("stamp_s"), "stamp_s"),
        tension_n=_vec(obj.get("tension_n"), 3, "tension_n"),  # type: ignore[arg-type]
        tension_std_n=_vec(obj.get("tension_std_n"), 3, "tension_std_n"),  # type: ignore[arg-type]
        horizontal_n=_finite(obj.get("horizontal_n"), "horizontal_n"),
        vertical_n=_finite(obj.get("vertical_n"), "vertical_n"),
        position_m=_opt_vec(obj, "position_m", 3),  # type: ignore[arg-type]
        follow=FollowView.from_obj(obj.get("follow", {})),
        position_std_m=_opt_vec(obj, "position_std_m", 3),  # type: ignore[arg-type]
        radial_m=_opt_float(obj, "radial_m"),
        radial_interval_m=interval,  # type: ignore[arg-type]
        azimuth_determined=_opt_bool(obj, "azimuth_determined"),
        floor_contact=_opt_bool(obj, "floor_contact"),
        on_ground=bool(_opt_bool(obj, "on_ground")),
        converged=bool(_opt_bool(obj, "converged")),
        length_m=_opt_float(obj, "length_m"),
        base_m=_opt_vec(obj, "base_m", 3),  # type: ignore[arg-type]
    )


@dataclass(frozen=True)
class TelemetryView:
    """What the dashboard takes from Telemetry: attitude and the motion-capture position."""

    seq: int
    quat_wxyz: tuple[float, float, float, float]
    position_m: Vec3 | None
    armed: bool = True


def parse_telemetry(payload: bytes) -> TelemetryView:
    """Parse a Telemetry payload (only the fields the dashboard draws).

    Raises:
        ValueError: not JSON, or ``quat_wxyz``/``position_m`` malformed.
    """
    obj = _load_object(payload)
    seq = obj.get("seq", 0)
    quat = _vec(obj.get("quat_wxyz"), 4, "quat_wxyz")
    norm = math.sqrt(sum(q * q for q in quat))
    if norm < 1e-6:
        raise ValueError(f"quat_wxyz has zero norm: {quat!r}")
    armed = obj.get("armed", True)
    return TelemetryView(
        seq=seq if isinstance(seq, int) and not isinstance(seq, bool) else 0,
        quat_wxyz=tuple(q / norm for q in quat),  # type: ignore[arg-type]
        position_m=_opt_vec(obj, "position_m", 3),  # type: ignore[arg-type]
        armed=armed if isinstance(armed, bool) else True,
    )


@dataclass(frozen=True)
class TruthView:
    """The simulator's ground truth (optional; shown when present)."""

    position_m: Vec3
    tension_n: Vec3 | None
    length_m: float | None
    base_m: Vec3 | None
    floor_contact: bool | None


def parse_truth(payload: bytes) -> TruthView:
    """Parse a Truth payload.

    Raises:
        ValueError: not JSON, or ``position_m`` missing or malformed.
    """
    obj = _load_object(payload)
    return TruthView(
        position_m=_vec(obj.get("position_m"), 3, "position_m"),  # type: ignore[arg-type]
        tension_n=_opt_vec(obj, "tension_n", 3),  # type: ignore[arg-type]
        length_m=_opt_float(obj, "length_m"),
        base_m=_opt_vec(obj, "base_m", 3),  # type: ignore[arg-type]
        floor_contact=_opt_bool(obj, "floor_contact"),
    )


@dataclass(frozen=True)
class ReelView:
    length_m: float
    base_m: Vec3 | None


def parse_reel(payload: bytes) -> ReelView:
    """Parse a Reel payload.

    Raises:
        ValueError: not JSON, or ``length_m`` missing, malformed or not positive.
    """
    obj = _load_object(payload)
    length_m = _finite(obj.get("length_m"), "length_m")
    if length_m <= 0.0:
        raise ValueError(f"length_m must be > 0, got {length_m!r}")
    return ReelView(length_m=length_m, base_m=_opt_vec(obj, "base_m", 3))  # type: ignore[arg-type]


def _parse_stop_reason(payload: bytes) -> str:
    try:
        reason = _load_object(payload).get("reason", "")
    except ValueError:
        return "?"
    return reason if isinstance(reason, str) else "?"


# --------------------------------------------------------------------------------------------
# Commands: what the dashboard publishes.
# --------------------------------------------------------------------------------------------


def _positive(value: float, name: str) -> float:
    out = float(value)
    if not math.isfinite(out) or out <= 0.0:
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    return out


def follow_command(
    enabled: bool,
    *,
    threshold_n: float | None = None,
    land: bool | None = None,
    land_below_m: float | None = None,
) -> bytes:
    """A FollowCommand payload for ``tether/{drone}/follow``; absent fields keep the setting.

    Args:
        enabled: tension following on or off.
        threshold_n: follow threshold, newtons, > 0.
        land: tug-to-land on (True) or off (False).
        land_below_m: tug-to-land height, metres (world z).

    Raises:
        ValueError: a threshold that is not positive, or a non-finite height.
    """
    cmd: dict[str, Any] = {"enabled": bool(enabled)}
    if threshold_n is not None:
        cmd["threshold_n"] = _positive(threshold_n, "threshold_n")
    if land is not None:
        cmd["land"] = bool(land)
    if land_below_m is not None:
        height_m = float(land_below_m)
        if not math.isfinite(height_m):
            raise ValueError(f"land_below_m must be finite, got {land_below_m!r}")
        cmd["land_below_m"] = height_m
    return json.dumps(cmd, separators=(",", ":")).encode()


def params_command(*, weight_n_per_m: float | None = None, length_m: float | None = None) -> bytes:
    """A params payload for ``tether/{drone}/params``; at least one field.

    Args:
        weight_n_per_m: tether weight per length ω, N/m, > 0.
        length_m: tether length, metres, > 0.

    Raises:
        ValueError: no field, or a value that is not positive.
    """
    cmd: dict[str, float] = {}
    if weight_n_per_m is not None:
        cmd["weight_n_per_m"] = _positive(weight_n_per_m, "weight_n_per_m")
    if length_m is not None:
        cmd["length_m"] = _positive(length_m, "length_m")
    if not cmd:
        raise ValueError("params needs weight_n_per_m or length_m")
    return json.dumps(cmd, separators=(",", ":")).encode()


def stop_command(stamp_s: float, reason: str = "operator") -> bytes:
    """A Stop payload for ``tether/{drone}/cmd/stop``.

    Args:
        stamp_s: wall-clock time of the request, seconds (``time.time()``).
        reason: why.
    """
    return json.dumps({"stamp_s": float(stamp_s), "reason": reason}, separators=(",", ":")).encode()


# --------------------------------------------------------------------------------------------
# Geometry for drawing.
# --------------------------------------------------------------------------------------------

_catenary_points: Callable[..., Any] | None = None
_catenary_checked = False


def _catenary_tether_points() -> Callable[..., Any] | None:
    """``groundstation.catenary.tether_points`` once it exists, else None (straight line)."""
    global _catenary_points, _catenary_checked
    if not _catenary_checked:
        try:
            module = importlib.import_module("groundstation.catenary")
        except ImportError:
            module = None
        _catenary_points = getattr(module, "tether_points", None)
        _catenary_checked = True
    return _catenary_points


def tether_points(
    base_world_m: Sequence[float],
    drone_world_m: Sequence[float],
    length_m: float,
    floor_z_m: float = -math.inf,
    n: int = 64,
) -> npt.NDArray[np.float64]:
    """Points (n, 3) along the tether for drawing, world frame, metres.

    Uses ``groundstation.catenary.tether_points`` (catenary with the floor run); falls back to
    the straight chord when that module is not there or has no curve for these inputs (a taut
    tether: length shorter than the chord).
    """
    base = np.asarray(base_world_m, dtype=np.float64)
    drone = np.asarray(drone_world_m, dtype=np.float64)
    if math.isfinite(floor_z_m):
        # An estimate a little below the floor (noise) is drawn on it, not rejected.
        base = np.array([base[0], base[1], max(base[2], floor_z_m)])
        drone = np.array([drone[0], drone[1], max(drone[2], floor_z_m)])
    fn = _catenary_tether_points()
    if fn is not None:
        try:
            pts = np.asarray(fn(base, drone, float(length_m), floor_z_m=floor_z_m, n=n))
            if pts.ndim == 2 and pts.shape[1] == 3 and len(pts) >= 2 and np.all(np.isfinite(pts)):
                return pts.astype(np.float64)
        except ValueError:
            pass
    s = np.linspace(0.0, 1.0, n)[:, None]
    return base + s * (drone - base)


def polyline_segments(points: npt.ArrayLike) -> npt.NDArray[np.float32]:
    """Line segments (N-1, 2, 3) joining consecutive points (N, 3)."""
    pts = np.asarray(points, dtype=np.float32)
    if len(pts) < 2:
        return np.zeros((1, 2, 3), dtype=np.float32)
    return np.stack([pts[:-1], pts[1:]], axis=1)


def tension_arrow(
    position_m: Sequence[float], tension_n: Sequence[float], m_per_n: float = ARROW_M_PER_N
) -> npt.NDArray[np.float32]:
    """The arrow (1, 2, 3) from the drone along the tension, ``m_per_n`` metres per newton."""
    start = np.asarray(position_m, dtype=np.float32)
    end = start + np.asarray(tension_n, dtype=np.float32) * np.float32(m_per_n)
    return np.stack([start, end])[None]


def camera_framing(
    points_m: npt.ArrayLike, fov_rad: float = math.radians(60.0), min_radius_m: float = 0.6
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Camera (position, look_at) that frames all points, seen from the front-left, above.

    Args:
        points_m: (k, 3) world points (bases and drones), k ≥ 1.
        fov_rad: vertical field of view.
        min_radius_m: frame at least a sphere of this radius.

    Returns:
        (position, look_at), world frame, metres.
    """
    pts = np.atleast_2d(np.asarray(points_m, dtype=np.float64))
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    look_at = (lo + hi) / 2.0
    radius_m = max(min_radius_m, 0.5 * float(np.linalg.norm(hi - lo)))
    distance_m = 1.15 * radius_m / math.sin(fov_rad / 2.0)
    direction = np.array([-0.35, -1.0, 0.55])
    direction /= np.linalg.norm(direction)
    return look_at + distance_m * direction, look_at


# --------------------------------------------------------------------------------------------
# Readouts (HTML: viser renders it as is, so every string from the bus is escaped).
# --------------------------------------------------------------------------------------------


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


def _badge(text: str, rgb: str) -> str:
    return (
        f'<span style="background:{rgb};color:white;border-radius:4px;padding:0 5px;'
        f'margin-right:4px;font-size:0.75rem">{html.escape(text)}</span>'
    )


def tension_html(est: EstimateView | None, truth: TruthView | None = None) -> str:
    """Readouts of the tension and the position estimate (|T|, H, T_v, position ± std)."""
    if est is None:
        return '<div style="font-size:0.8rem;color:#888">no Estimate yet</div>'
    rows = [
        ("|T|", f"<b>{est.tension_norm_n:.3f} N</b>"),
        ("H", _fmt(est.horizontal_n, "N")),
        ("T_v", _fmt(est.vertical_n, "N")),
        ("T (world)", _fmt_vec(est.tension_n) + " N"),
        ("σ_T", "(" + ", ".join(f"{1e3 * v:.1f}" for v in est.tension_std_n) + ") mN"),
        ("position", _fmt_vec(est.position_m) + (" m" if est.position_m else " (undetermined)")),
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
    if truth is not None:
        if truth.tension_n is not None:
            norm = math.sqrt(sum(c * c for c in truth.tension_n))
            rows.append(("|T| truth (sim)", _fmt(norm, "N")))
        if est.position_m is not None:
            error_m = math.dist(est.position_m, truth.position_m)
            rows.append(("position error (sim)", f"{100.0 * error_m:.1f} cm"))
        if truth.floor_contact is not None:
            rows.append(("tether on floor (sim)", "yes" if truth.floor_contact else "no"))
    badges = []
    if est.on_ground:
        badges.append(_badge("on ground", "#868e96"))
    if not est.converged:
        badges.append(_badge("converging", "#f08c00"))
    if est.floor_contact:
        badges.append(_badge("tether on floor", "#96703c"))
    if est.azimuth_determined is False:
        badges.append(_badge("azimuth undetermined", "#f08c00"))
    return _table(rows) + (f'<div style="margin-top:3px">{"".join(badges)}</div>' if badges else "")


def follow_html(
    follow: FollowView | None, last_stop: tuple[float, str] | None, now_s: float
) -> str:
    """State of tension following, tug-to-land and the last Stop seen on the bus."""
    parts: list[str] = []
    if follow is None:
        parts.append('<span style="color:#888">no follow state reported</span>')
    else:
        if follow.enabled:
            parts.append(
                _badge(
                    "following" if follow.active else "armed, below threshold",
                    "#2f9e44" if follow.active else "#1c7ed6",
                )
            )
        else:
            parts.append(_badge("follow off", "#868e96"))
        if follow.land_below_m is not None:
            parts.append(_badge(f"tug-to-land below {follow.land_below_m:.2f} m", "#1098ad"))
        if follow.landing_armed:
            parts.append(_badge("landing armed", "#f08c00"))
        if follow.stopped:
            parts.append(_badge("STOPPED", "#e03131"))
        if follow.reason:
            parts.append(f'<span style="color:#666">reason: {html.escape(follow.reason)}</span>')
    if last_stop is not None:
        age_s = max(0.0, now_s - last_stop[0])
        parts.append(
            '<div style="color:#e03131;font-weight:600">'
            f"Stop sent {age_s:.1f} s ago ({html.escape(last_stop[1])})</div>"
        )
    return f'<div style="font-size:0.8rem">{" ".join(parts)}</div>'


@dataclass(frozen=True)
class LinkStats:
    """Link health the dashboard measures itself (beside the service's status)."""

    telemetry_hz: float
    estimate_hz: float
    telemetry_age_s: float | None
    invalid: Mapping[str, int] = field(default_factory=dict)
    """Payloads the dashboard itself could not parse, per kind."""


def health_html(status: Mapping[str, Any] | None, local: LinkStats, stale_after_s: float) -> str:
    """Link health: rates, age of the last message, invalid and dropped counts, stale state."""
    stale = local.telemetry_age_s is None or local.telemetry_age_s > stale_after_s
    if status is not None and isinstance(status.get("stale"), bool):
        stale = stale or bool(status["stale"])
    rows: list[tuple[str, str]] = [
        ("link", _badge("STALE", "#e03131") if stale else _badge("live", "#2f9e44")),
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

        def num(key: str, fmt: str) -> str:
            value = status.get(key)
            if isinstance(value, bool) or not isinstance(value, int | float):
                return "—"
            return fmt.format(value)

        rows += [
            ("telemetry (service)", num("telemetry_hz", "{:.0f} Hz")),
            ("estimates (service)", num("estimate_hz", "{:.0f} Hz")),
            ("last seen (service)", num("last_seen_age_s", "{:.2f} s ago")),
            ("received / accepted", f"{num('received', '{:d}')} / {num('accepted', '{:d}')}"),
        ]
        drops = status.get("drops")
        if isinstance(drops, dict) and drops:
            text = ", ".join(
                f"{html.escape(str(k))}: {v}"
                for k, v in sorted(drops.items())
                if isinstance(v, int)
            )
            total = sum(v for v in drops.values() if isinstance(v, int) and not isinstance(v, bool))
            rows.append(("invalid / dropped", f"{total} ({text})"))
        else:
            rows.append(("invalid / dropped", "0"))
        rows.append(("queue overflow", num("queue_overflow", "{:d}")))
    if local.invalid:
        text = ", ".join(f"{html.escape(k)}: {v}" for k, v in sorted(local.invalid.items()))
        rows.append(("unparsable (here)", text))
    return _table(rows)


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
    """A fixed-size ring of rows (time first), for the 20 s charts and the trail."""

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


def _set_value(handle: Any, value: Any) -> None:
    """Set a GUI input's value if it differs (viser's ``value`` setter is generic over
    ``T | ndarray``, which mypy reads as read-only through a subclass)."""
    if handle.value != value:
        handle.value = value


def _quat_to_wxyz(q: Sequence[float]) -> tuple[float, float, float, float]:
    return (float(q[0]), float(q[1]), float(q[2]), float(q[3]))


def load_quadrotor_mesh(
    path: Path | None = None,
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint32]]:
    """Vertices (V, 3) and faces (F, 3) of the quadrotor drawn for each drone, body frame, m.

    Reads the binary STL written by ``web/make_quadrotor.py``: ``path``, else
    ``groundstation/assets/quadrotor.stl`` (if packaged), else the repository's
    ``web/quadrotor.stl``; without any (a wheel without the asset) a plain cross of two bars
    stands in.
    """
    candidates = [path] if path is not None else list(_MESH_PATHS)
    for candidate in candidates:
        try:
            data = candidate.read_bytes()
        except OSError:
            continue
        if len(data) < 84:
            continue
        count = int(np.frombuffer(data, dtype="<u4", count=1, offset=80)[0])
        if len(data) != 84 + 50 * count or count == 0:
            _log.warning("%s is not a binary STL; drawing a plain cross", candidate)
            continue
        record = np.dtype([("normal", "<f4", (3,)), ("vertices", "<f4", (3, 3)), ("attr", "<u2")])
        tris = np.frombuffer(data, dtype=record, count=count, offset=84)["vertices"]
        vertices, inverse = np.unique(tris.reshape(-1, 3), axis=0, return_inverse=True)
        return vertices.astype(np.float32), inverse.reshape(-1, 3).astype(np.uint32)
    # Fallback: two crossed bars at ±45°.
    half_m, w_m = 0.046, 0.004
    bar = np.array(
        [
            [-half_m, -w_m, -w_m],
            [half_m, -w_m, -w_m],
            [half_m, w_m, -w_m],
            [-half_m, w_m, -w_m],
            [-half_m, -w_m, w_m],
            [half_m, -w_m, w_m],
            [half_m, w_m, w_m],
            [-half_m, w_m, w_m],
        ]
    )
    quads = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (2, 3, 7, 6), (1, 2, 6, 5), (0, 4, 7, 3)]
    faces = np.array([f for a, b, c, d in quads for f in ((a, b, c), (a, c, d))])
    verts, all_faces = [], []
    for k, yaw_rad in enumerate((math.pi / 4.0, -math.pi / 4.0)):
        cos, sin = math.cos(yaw_rad), math.sin(yaw_rad)
        R = np.array([[cos, -sin, 0.0], [sin, cos, 0.0], [0.0, 0.0, 1.0]])
        verts.append(bar @ R.T)
        all_faces.append(faces + 8 * k)
    return np.concatenate(verts).astype(np.float32), np.concatenate(all_faces).astype(np.uint32)


# --------------------------------------------------------------------------------------------
# Per-drone state.
# --------------------------------------------------------------------------------------------


class _Inbox:
    """Latest payloads of one drone, written by bus callbacks, read by the update thread.

    Each field is a single reference assignment or an int increment under the GIL; the
    reader only needs "the latest", so no lock is taken on the 250 Hz path.
    """

    __slots__ = (
        "estimate",
        "n_estimate",
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
        self.status: dict[str, Any] | None = None
        self.status_rx_s = 0.0


# History columns.
_H_T, _H_TX, _H_TY, _H_TZ, _H_TN, _H_THR = range(6)
_H_EX, _H_EY, _H_EZ, _H_MX, _H_MY, _H_MZ = range(6, 12)
_H_COLS = 12


@dataclass
class _DroneNodes:
    body: viser.FrameHandle
    quad: viser.MeshHandle
    name_label: viser.LabelHandle
    tether: viser.LineSegmentsHandle
    floor_run: viser.LineSegmentsHandle
    arrow: viser.ArrowsHandle
    arrow_label: viser.LabelHandle
    uncertainty: viser.IcosphereHandle
    mocap: viser.IcosphereHandle
    mocap_error: viser.LineSegmentsHandle
    mocap_label: viser.LabelHandle
    truth: viser.IcosphereHandle
    trail: viser.LineSegmentsHandle
    base_column: viser.BoxHandle
    base_exit: viser.IcosphereHandle
    base_drawn: Vec3 | None = None
    shown: dict[str, bool] = field(default_factory=dict)
    texts: dict[str, str] = field(default_factory=dict)

    def show(self, name: str, visible: bool) -> None:
        """Set a node's visibility, sending only changes (each assignment is a message)."""
        if self.shown.get(name) != visible:
            getattr(self, name).visible = visible
            self.shown[name] = visible

    def text(self, name: str, text: str) -> None:
        """Set a label's text, sending only changes."""
        if self.texts.get(name) != text:
            getattr(self, name).text = text
            self.texts[name] = text


class _Drone:
    """What the update thread knows about one drone (only that thread touches it)."""

    def __init__(self, drone_id: str, inbox: _Inbox, color: tuple[int, int, int], capacity: int):
        self.id = drone_id
        self.inbox = inbox
        self.color = color
        self.seen = {"estimate": 0, "telemetry": 0, "truth": 0, "reel": 0, "stop": 0}
        self.estimate: EstimateView | None = None
        self.telemetry: TelemetryView | None = None
        self.truth: TruthView | None = None
        self.reel: ReelView | None = None
        self.last_stop: tuple[float, str] | None = None
        self.invalid: dict[str, int] = {}
        self.history = History(_H_COLS, capacity)
        self.trail: deque[Vec3] = deque()
        self.trail_t: deque[float] = deque()
        self.rate_mark: tuple[float, int, int] | None = None
        self.telemetry_hz = 0.0
        self.estimate_hz = 0.0
        self.nodes: _DroneNodes | None = None
        self.drawn_s = -math.inf


# --------------------------------------------------------------------------------------------
# The dashboard.
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DashboardStats:
    """Cost of the dashboard's own update thread."""

    ticks: int
    update_cpu_s: float
    """CPU time spent in update passes (``time.thread_time``), seconds."""
    wall_s: float
    """Wall time since start, seconds."""


FOREIGN_EDIT_WAIT_S = 1.0
"""Longest wait for a browser edit's callback before the report wins again, s."""


class _Synced:
    """A GUI input that shows a reported value unless the operator has just changed it."""

    def __init__(self, handle: Any) -> None:
        self.handle = handle
        self.pending: Pending | None = None
        self.editing_until_s = -math.inf
        self.written: Any = handle.value
        """The value this class last wrote (an operator's edit makes the handle differ)."""
        self.foreign_since_s: float | None = None

    def reset(self) -> None:
        self.pending = None
        self.editing_until_s = -math.inf

    def show(self, reported: Any, now_s: float) -> None:
        if reported is None or now_s < self.editing_until_s:
            return
        if self.pending is None and self.handle.value != self.written:
            # viser stores a browser's edit before it calls our callback, which then turns
            # it into a pending request. Overwriting it in between would make the callback
            # read back the old value and send the opposite of the click; wait for it.
            if self.foreign_since_s is None:
                self.foreign_since_s = now_s
            if now_s - self.foreign_since_s < FOREIGN_EDIT_WAIT_S:
                return
        self.foreign_since_s = None
        value, self.pending = reconcile(reported, self.pending, now_s)
        _set_value(self.handle, value)
        self.written = value


class Dashboard:
    """The viser dashboard, talking to the service only over ``bus``.

    Args:
        settings: the root configuration (``[web]`` for host, port and scene rate; the
            per-drone defaults for base, floor, tether until the service reports them).
        bus: where Estimates etc. come from and where commands go.
        host: bind address; default ``settings.web.host`` (127.0.0.1).
        port: port; default ``settings.web.port`` (8080); 0 picks a free one. If the port is
            taken, viser tries the next ones; :attr:`url` tells the one bound.
        update_thread: False leaves the update passes to the caller (:meth:`update`,
            :meth:`poll_status`): tests and benchmarks drive it deterministically.
    """

    def __init__(
        self,
        settings: Settings,
        bus: Bus,
        *,
        host: str | None = None,
        port: int | None = None,
        update_thread: bool = True,
    ) -> None:
        self._settings = settings
        self._bus = bus
        self._host = settings.web.host if host is None else host
        self._port = settings.web.port if port is None else port
        self._use_thread = update_thread
        self._scene_rate_hz = min(30.0, settings.web.scene_rate_hz)
        self._scene_budget_hz = settings.web.scene_budget_hz
        self._capacity = math.ceil(HISTORY_S * self._scene_rate_hz * 1.25) + 8

        self._inbox_lock = threading.Lock()
        self._inboxes: dict[str, _Inbox] = {}
        self._drones: dict[str, _Drone] = {}
        self._gui_lock = threading.RLock()
        self._selected: str | None = None
        self._selection_changed = False

        self._server: viser.ViserServer | None = None
        self._subs: list[Subscription] = []
        self._threads: list[threading.Thread] = []
        self._stop_event = threading.Event()
        self._closed = False
        self._close_lock = threading.Lock()
        self._started_s = 0.0
        self._ticks = 0
        self._cpu_s = 0.0
        self._scene_throttle = Throttle(self._scene_rate_hz)
        self._panel_throttle = Throttle(min(PANEL_RATE_HZ, self._scene_rate_hz))
        self._chart_throttle = Throttle(min(CHART_RATE_HZ, self._scene_rate_hz))
        self._logged_kinds: set[str] = set()
        self._mesh = load_quadrotor_mesh()
        self._mocap_shown: bool | None = None

    # ---------------------------------------------------------------- lifecycle

    def start(self) -> None:
        """Start the viser server, subscribe, and start the update thread; returns at once.

        Raises:
            RuntimeError: already started or closed.
        """
        if self._server is not None or self._closed:
            raise RuntimeError("Dashboard.start() may be called once")
        self._started_s = time.monotonic()
        self._server = viser.ViserServer(
            host=self._host, port=self._port, label="groundstation", verbose=False
        )
        self._build_scene(self._server)
        self._build_gui(self._server)
        self._server.on_client_connect(self._on_client_connect)
        for kind, keyexpr in (
            ("estimate", "tether/*/estimate"),
            ("telemetry", "tether/*/telemetry"),
            ("truth", "tether/*/truth"),
            ("reel", "tether/*/reel"),
            ("stop", "tether/*/cmd/stop"),
        ):
            self._subs.append(self._bus.subscribe(keyexpr, functools.partial(self._receive, kind)))
        if self._use_thread:
            for target, name in (
                (self._run_updates, "dashboard-update"),
                (self._run_status, "dashboard-status"),
            ):
                thread = threading.Thread(target=target, name=name, daemon=True)
                thread.start()
                self._threads.append(thread)

    @property
    def url(self) -> str:
        """``http://HOST:PORT`` of the running dashboard (a wildcard host shows as loopback).

        Raises:
            RuntimeError: not started.
        """
        if self._server is None:
            raise RuntimeError("Dashboard not started")
        host = self._server.get_host()
        if host in ("", "0.0.0.0"):
            host = "127.0.0.1"
        elif host == "::":
            host = "[::1]"
        elif ":" in host:
            host = f"[{host}]"
        return f"http://{host}:{self._server.get_port()}"

    @property
    def server(self) -> viser.ViserServer:
        """The viser server (for tests and embedding).

        Raises:
            RuntimeError: not started.
        """
        if self._server is None:
            raise RuntimeError("Dashboard not started")
        return self._server

    def close(self) -> None:
        """Stop the threads and the server; idempotent."""
        with self._close_lock:
            if self._closed:
                return
            self._closed = True
        self._stop_event.set()
        for sub in self._subs:
            sub.close()
        self._subs.clear()
        for thread in self._threads:
            thread.join(timeout=1.0)
        if self._server is not None:
            self._server.stop()

    def __enter__(self) -> Dashboard:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def stats(self) -> DashboardStats:
        """Ticks and CPU time of the update passes so far."""
        wall_s = time.monotonic() - self._started_s if self._started_s else 0.0
        return DashboardStats(ticks=self._ticks, update_cpu_s=self._cpu_s, wall_s=wall_s)

    @property
    def drones(self) -> list[str]:
        """Drone ids seen so far, sorted."""
        with self._inbox_lock:
            return sorted(self._inboxes)

    @property
    def selected(self) -> str | None:
        """The drone the panel shows."""
        return self._selected

    def select(self, drone_id: str) -> None:
        """Show ``drone_id`` in the panel (as the selector does).

        Raises:
            KeyError: a drone not seen.
        """
        with self._inbox_lock:
            if drone_id not in self._inboxes:
                raise KeyError(f"drone {drone_id!r} has not been seen")
        with self._gui_lock:
            self._set_selected(drone_id)
            if self._server is not None:
                _set_value(self._drone_select, drone_id)

    # ---------------------------------------------------------------- bus callbacks (cheap)

    def _inbox(self, key: str) -> _Inbox | None:
        parts = key.split("/", 2)
        if len(parts) < 3:
            return None
        inbox = self._inboxes.get(parts[1])
        if inbox is None:
            if not DRONE_ID_RE.fullmatch(parts[1]):
                return None
            with self._inbox_lock:
                inbox = self._inboxes.setdefault(parts[1], _Inbox())
        return inbox

    def _receive(self, kind: str, sample: Sample) -> None:
        """Bus callback: keep the latest payload of ``kind``, count it (no parsing here)."""
        inbox = self._inbox(sample.key)
        if inbox is None:
            return
        setattr(inbox, kind, sample.payload)
        setattr(inbox, f"n_{kind}", getattr(inbox, f"n_{kind}") + 1)
        if kind in ("telemetry", "stop"):  # link health, and when the Stop was seen
            setattr(inbox, f"{kind}_rx_s", time.monotonic())

    # ---------------------------------------------------------------- status polling

    def poll_status(self) -> int:
        """Query ``tether/*/status`` once and store the replies. Returns how many arrived."""
        try:
            replies = self._bus.query("tether/*/status", timeout_s=STATUS_TIMEOUT_S)
        except Exception as exc:  # a bus error must not end the poller; logged once
            self._log_once("status-query", "status query failed: %s", exc)
            return 0
        now_s = time.monotonic()
        count = 0
        for reply in replies:
            try:
                status = _load_object(reply.payload)
            except ValueError as exc:
                self._log_once(
                    "status-invalid", "unparsable status reply on %s: %s", reply.key, exc
                )
                continue
            drone = status.get("drone")
            if not isinstance(drone, str):
                parts = reply.key.split("/")
                drone = parts[1] if len(parts) >= 3 else ""
            inbox = self._inbox(f"tether/{drone}/status")
            if inbox is None:
                continue
            inbox.status = status
            inbox.status_rx_s = now_s
            count += 1
        return count

    def _run_status(self) -> None:
        while not self._stop_event.is_set():
            self.poll_status()
            self._stop_event.wait(STATUS_PERIOD_S)

    # ---------------------------------------------------------------- commands

    def request_follow(
        self,
        drone_id: str,
        enabled: bool,
        *,
        threshold_n: float | None = None,
        land: bool | None = None,
        land_below_m: float | None = None,
    ) -> bytes:
        """Publish a FollowCommand to ``tether/{drone_id}/follow``; returns the payload."""
        payload = follow_command(
            enabled, threshold_n=threshold_n, land=land, land_below_m=land_below_m
        )
        self._bus.publish(f"tether/{drone_id}/follow", payload)
        return payload

    def request_params(
        self,
        drone_id: str,
        *,
        weight_n_per_m: float | None = None,
        length_m: float | None = None,
    ) -> bytes:
        """Publish tether parameters to ``tether/{drone_id}/params``; returns the payload."""
        payload = params_command(weight_n_per_m=weight_n_per_m, length_m=length_m)
        self._bus.publish(f"tether/{drone_id}/params", payload)
        return payload

    def request_stop(self, drone_id: str, reason: str = "operator") -> bytes:
        """Publish a Stop to ``tether/{drone_id}/cmd/stop`` at once; returns the payload.

        The GUI calls this only after the operator confirmed.
        """
        payload = stop_command(time.time(), reason)
        self._bus.publish(f"tether/{drone_id}/cmd/stop", payload)
        _log.warning("emergency Stop published for %s (%s)", drone_id, reason)
        return payload

    # ---------------------------------------------------------------- scene and GUI

    def _build_scene(self, server: viser.ViserServer) -> None:
        floor_z_m = self._settings.base.floor_z_m
        server.scene.add_grid(
            "/floor",
            width=6.0,
            height=6.0,
            cell_size=0.1,
            section_size=1.0,
            position=(0.0, 0.0, floor_z_m),
        )
        # Until drones appear, frame the configured base.
        position, look_at = camera_framing(
            [self._settings.base.position_m, (0.0, 0.0, floor_z_m), (1.0, 0.0, 1.0)]
        )
        server.initial_camera.position = position
        server.initial_camera.look_at = look_at

    def _build_gui(self, server: viser.ViserServer) -> None:
        gui = server.gui
        gui.configure_theme(control_width="large", show_share_button=False, show_logo=False)
        self._drone_select = gui.add_dropdown("Drone", (NO_DRONE,), initial_value=NO_DRONE)
        self._drone_select.on_update(self._on_select)
        self._stop_button = gui.add_button(
            "Emergency stop",
            color="red",
            icon=viser.Icon.HAND_STOP,
            disabled=True,
            hint="Stop the motors of the selected drone now (asks for confirmation)",
        )
        self._stop_button.on_click(self._on_stop_clicked)
        frame_button = gui.add_button("Frame all", color="gray", icon=viser.Icon.FOCUS_CENTERED)
        frame_button.on_click(self._on_frame_clicked)

        with gui.add_folder("Tension and position"):
            self._tension_html = gui.add_html(tension_html(None))
        with gui.add_folder(f"Charts (last {HISTORY_S:.0f} s)"):
            x0 = np.array([-HISTORY_S, 0.0])
            zeros = np.zeros(2)
            self._tension_chart = gui.add_uplot(
                (x0, zeros, zeros, zeros, zeros, zeros),
                self._tension_series(),
                title="Tension (N)",
                scales={"x": {"time": False}},
                height=190,
            )
            self._position_chart = gui.add_uplot(
                (x0, zeros, zeros, zeros, zeros, zeros, zeros),
                self._position_series(mocap=False),
                title="Position (m): estimate vs motion capture",
                scales={"x": {"time": False}},
                height=190,
            )
        with gui.add_folder("Follow"):
            self._follow = _Synced(
                gui.add_checkbox(
                    "Follow mode",
                    False,
                    disabled=True,
                    hint="Tension following: the drone yields when the tether is pulled",
                )
            )
            self._follow.handle.on_update(self._on_follow_toggled)
            self._land = _Synced(
                gui.add_checkbox(
                    "Tug-to-land",
                    False,
                    disabled=True,
                    hint="After a tug, stop the motors below the land height",
                )
            )
            self._land.handle.on_update(self._on_land_toggled)
            with gui.add_form("Follow settings") as follow_form:
                self._threshold = _Synced(
                    gui.add_number(
                        "Threshold (N)",
                        self._settings.follow.threshold_n,
                        min=0.001,
                        step=0.005,
                        disabled=True,
                    )
                )
                land_default_m = self._settings.follow.land_below_m
                self._land_height = _Synced(
                    gui.add_number(
                        "Land height (m)",
                        0.2 if land_default_m is None else land_default_m,
                        step=0.05,
                        disabled=True,
                    )
                )
                self._follow_apply = gui.add_button("Apply follow settings", disabled=True)
            self._follow_apply.on_click(lambda _event: follow_form.submit())
            follow_form.on_submit(self._on_follow_submit)
            for synced in (self._threshold, self._land_height):
                synced.handle.on_update(self._edit_marker(synced))
            self._follow_html = gui.add_html(follow_html(None, None, 0.0))
        with gui.add_folder("Tether"):
            with gui.add_form("Tether parameters") as tether_form:
                self._weight = _Synced(
                    gui.add_number(
                        "ω (N/m)",
                        self._settings.tether.weight_n_per_m,
                        min=0.0001,
                        step=0.005,
                        disabled=True,
                        hint="Tether weight per length",
                    )
                )
                self._length = _Synced(
                    gui.add_number(
                        "Length (m)",
                        self._settings.tether.length_m,
                        min=0.01,
                        step=0.05,
                        disabled=True,
                        hint="Editable only while no reel reports the length",
                    )
                )
                self._tether_apply = gui.add_button("Apply tether parameters", disabled=True)
            self._tether_apply.on_click(lambda _event: tether_form.submit())
            tether_form.on_submit(self._on_tether_submit)
            for synced in (self._weight, self._length):
                synced.handle.on_update(self._edit_marker(synced))
            self._tether_html = gui.add_html("")
        with gui.add_folder("Link health"):
            self._health_html = gui.add_html(health_html(None, LinkStats(0.0, 0.0, None), 0.5))

    @staticmethod
    def _tension_series() -> tuple[viser.uplot.Series, ...]:
        return (
            {"label": "t (s)"},
            {"label": "Tx", "stroke": "#e03131", "width": 1.2},
            {"label": "Ty", "stroke": "#2f9e44", "width": 1.2},
            {"label": "Tz", "stroke": "#1c7ed6", "width": 1.2},
            {"label": "|T|", "stroke": "#212529", "width": 2.0},
            {"label": "threshold", "stroke": "#f08c00", "width": 1.5, "dash": (6.0, 4.0)},
        )

    @staticmethod
    def _position_series(mocap: bool) -> tuple[viser.uplot.Series, ...]:
        colors = ("#e03131", "#2f9e44", "#1c7ed6")
        series: list[viser.uplot.Series] = [{"label": "t (s)"}]
        for axis, color in zip("xyz", colors, strict=True):
            series.append({"label": f"{axis} est", "stroke": color, "width": 1.5})
        for axis, color in zip("xyz", colors, strict=True):
            series.append(
                {
                    "label": f"{axis} mocap",
                    "stroke": color,
                    "width": 1.0,
                    "dash": (3.0, 3.0),
                    "show": mocap,
                }
            )
        return tuple(series)

    # ---------------------------------------------------------------- GUI callbacks

    def _on_select(self, event: viser.GuiEvent[Any]) -> None:
        if event.client_id is None:
            return
        value = self._drone_select.value
        with self._gui_lock:
            if value != NO_DRONE and value in self._drones:
                self._set_selected(value)

    def _set_selected(self, drone_id: str) -> None:
        if drone_id != self._selected:
            self._selected = drone_id
            self._selection_changed = True
            for synced in (
                self._follow,
                self._land,
                self._threshold,
                self._land_height,
                self._weight,
                self._length,
            ):
                synced.reset()

    def _edit_marker(self, synced: _Synced) -> Callable[[viser.GuiEvent[Any]], None]:
        def mark(event: viser.GuiEvent[Any]) -> None:
            if event.client_id is not None:
                synced.editing_until_s = time.monotonic() + EDIT_HOLD_S

        return mark

    def _on_follow_toggled(self, event: viser.GuiEvent[Any]) -> None:
        if event.client_id is None:  # our own sync from the reports
            return
        with self._gui_lock:
            drone = self._selected
            if drone is None:
                return
            enabled = bool(self._follow.handle.value)
            self._follow.pending = Pending(enabled, time.monotonic() + PENDING_HOLD_S)
            self.request_follow(drone, enabled)

    def _on_land_toggled(self, event: viser.GuiEvent[Any]) -> None:
        if event.client_id is None:
            return
        with self._gui_lock:
            drone = self._selected
            if drone is None:
                return
            land = bool(self._land.handle.value)
            self._land.pending = Pending(land, time.monotonic() + PENDING_HOLD_S)
            height_m = float(self._land_height.handle.value) if land else None
            self.request_follow(
                drone, bool(self._follow.handle.value), land=land, land_below_m=height_m
            )

    def _on_follow_submit(self, _event: Any) -> None:
        with self._gui_lock:
            drone = self._selected
            if drone is None:
                return
            now_s = time.monotonic()
            threshold_n = float(self._threshold.handle.value)
            land = bool(self._land.handle.value)
            height_m = float(self._land_height.handle.value)
            if not threshold_n > 0.0:
                self._log_once("bad-threshold", "threshold must be > 0, got %s", threshold_n)
                return
            self._threshold.editing_until_s = -math.inf
            self._threshold.pending = Pending(threshold_n, now_s + PENDING_HOLD_S)
            self._land_height.editing_until_s = -math.inf
            if land:
                self._land_height.pending = Pending(height_m, now_s + PENDING_HOLD_S)
            self.request_follow(
                drone,
                bool(self._follow.handle.value),
                threshold_n=threshold_n,
                land=land,
                land_below_m=height_m if land else None,
            )

    def _on_tether_submit(self, _event: Any) -> None:
        with self._gui_lock:
            drone = self._selected
            if drone is None:
                return
            now_s = time.monotonic()
            weight = float(self._weight.handle.value)
            length_m = None if self._length.handle.disabled else float(self._length.handle.value)
            try:
                self.request_params(drone, weight_n_per_m=weight, length_m=length_m)
            except ValueError as exc:
                self._log_once("bad-params", "tether parameters not sent: %s", exc)
                return
            self._weight.editing_until_s = -math.inf
            self._weight.pending = Pending(weight, now_s + PENDING_HOLD_S)
            self._length.editing_until_s = -math.inf
            if length_m is not None:
                self._length.pending = Pending(length_m, now_s + PENDING_HOLD_S)

    def _on_stop_clicked(self, event: viser.GuiEvent[Any]) -> None:
        client = event.client
        drone = self._selected
        if client is None or drone is None:
            return
        done = threading.Lock()
        with client.gui.add_modal(f"Emergency stop: {drone}") as modal:
            client.gui.add_markdown(
                f"Stop the motors of **{drone}** now? An airborne drone will fall."
            )
            confirm = client.gui.add_button("Confirm stop", color="red", icon=viser.Icon.HAND_STOP)
            cancel = client.gui.add_button("Cancel")

        def finish(stop: bool) -> None:
            if not done.acquire(blocking=False):  # the other button was faster
                return
            if stop:
                self.request_stop(drone)
            modal.close()

        confirm.on_click(lambda _event: finish(True))
        cancel.on_click(lambda _event: finish(False))

    def _on_frame_clicked(self, event: viser.GuiEvent[Any]) -> None:
        if event.client is not None:
            self._frame_client(event.client)

    def _on_client_connect(self, client: viser.ClientHandle) -> None:
        if self._drones:
            self._frame_client(client)

    def _framing_points(self) -> list[Sequence[float]]:
        points: list[Sequence[float]] = []
        for drone in list(self._drones.values()):
            points.append(self._base_of(drone))
            body = self._body_position(drone)
            if body is not None:
                points.append(body)
        if not points:
            points.append(self._settings.base.position_m)
        points.append((points[0][0], points[0][1], self._settings.base.floor_z_m))
        return points

    def _frame_client(self, client: viser.ClientHandle) -> None:
        position, look_at = camera_framing(self._framing_points())
        # viser moves look_at along with position; set look_at after to pin it.
        with client.atomic():
            client.camera.position = position
            client.camera.look_at = look_at

    # ---------------------------------------------------------------- update thread

    def _run_updates(self) -> None:
        # Sleep until the next pass is due, so the pass's own work is inside the period.
        while not self._stop_event.wait(max(0.001, self._scene_throttle.next_s - time.monotonic())):
            try:
                self.update()
            except Exception:  # keep drawing; a bug here must not freeze the dashboard
                _log.exception("dashboard update failed")

    def update(self, now_s: float | None = None) -> None:
        """One update pass: parse the latest payloads, push scene, panel and charts.

        The update thread calls this at the scene rate; pushes are throttled by ``now_s``
        (``time.monotonic()`` when None), so calling it more often does not send more.
        """
        if self._server is None:
            raise RuntimeError("Dashboard not started")
        cpu0_s = time.thread_time()
        now_s = time.monotonic() if now_s is None else now_s
        if self._scene_throttle.due(now_s):
            with self._gui_lock:
                self._update_all(now_s)
            self._ticks += 1
            # A bounded number of drone redraws per second in all (settings.web).
            per_drone_hz = self._scene_budget_hz / max(1, len(self._drones))
            self._scene_throttle.period_s = 1.0 / min(self._scene_rate_hz, per_drone_hz)
        self._cpu_s += time.thread_time() - cpu0_s

    def _update_all(self, now_s: float) -> None:
        server = self._server
        assert server is not None
        with self._inbox_lock:
            inboxes = sorted(self._inboxes.items())  # colours follow the ids, not arrival
        new_drones = False
        for drone_id, inbox in inboxes:
            if drone_id not in self._drones:
                color = _PALETTE[len(self._drones) % len(_PALETTE)]
                self._drones[drone_id] = _Drone(drone_id, inbox, color, self._capacity)
                new_drones = True
        with server.atomic():
            for drone in self._drones.values():
                # Redraw on new data, and once a second anyway (the stale flag is time).
                if self._ingest(drone, now_s) or now_s - drone.drawn_s >= 1.0:
                    self._draw(server, drone, now_s)
                    drone.drawn_s = now_s
        if new_drones:
            self._on_new_drones(server)
        selected = self._drones.get(self._selected) if self._selected else None
        if selected is not None:
            if self._panel_throttle.due(now_s) or self._selection_changed:
                self._update_panel(selected, now_s)
            if self._chart_throttle.due(now_s) or self._selection_changed:
                self._update_charts(selected, now_s)
            self._selection_changed = False

    def _on_new_drones(self, server: viser.ViserServer) -> None:
        ids = sorted(self._drones)
        self._drone_select.options = ids
        if self._selected is None:
            self._set_selected(ids[0])
            self._stop_button.disabled = False
            for synced in (
                self._follow,
                self._land,
                self._threshold,
                self._land_height,
                self._weight,
            ):
                synced.handle.disabled = False
            self._follow_apply.disabled = False
            self._tether_apply.disabled = False
        if self._selected is not None:
            _set_value(self._drone_select, self._selected)
        position, look_at = camera_framing(self._framing_points())
        server.initial_camera.position = position
        server.initial_camera.look_at = look_at
        for client in server.get_clients().values():
            self._frame_client(client)

    def _parse(
        self, drone: _Drone, kind: str, payload: bytes | None, parser: Callable[[bytes], Any]
    ) -> Any:
        if payload is None:
            return None
        try:
            return parser(payload)
        except ValueError as exc:
            drone.invalid[kind] = drone.invalid.get(kind, 0) + 1
            self._log_once(f"invalid-{kind}", "unparsable %s from %s: %s", kind, drone.id, exc)
            return None

    def _ingest(self, drone: _Drone, now_s: float) -> bool:
        """Parse what is new for ``drone``; True when anything was."""
        inbox = drone.inbox
        seen = drone.seen
        changed = any(getattr(inbox, f"n_{kind}") != count for kind, count in seen.items())
        new_estimate = inbox.n_estimate != seen["estimate"]
        parsers: tuple[tuple[str, Callable[[bytes], Any]], ...] = (
            ("estimate", parse_estimate),
            ("telemetry", parse_telemetry),
            ("truth", parse_truth),
            ("reel", parse_reel),
        )
        for kind, parser in parsers:
            count = getattr(inbox, f"n_{kind}")
            if count == seen[kind]:
                continue
            seen[kind] = count
            parsed = self._parse(drone, kind, getattr(inbox, kind), parser)
            if parsed is not None:
                setattr(drone, kind, parsed)
        if inbox.n_stop != seen["stop"]:
            seen["stop"] = inbox.n_stop
            reason = _parse_stop_reason(inbox.stop) if inbox.stop is not None else "?"
            drone.last_stop = (inbox.stop_rx_s, reason)
            self._notify_stop(drone.id, reason)

        # Rates over about a second, from the callbacks' counters.
        mark = drone.rate_mark
        if mark is None:
            drone.rate_mark = (now_s, inbox.n_telemetry, inbox.n_estimate)
        elif now_s - mark[0] >= RATE_WINDOW_S:
            dt_s = now_s - mark[0]
            drone.telemetry_hz = (inbox.n_telemetry - mark[1]) / dt_s
            drone.estimate_hz = (inbox.n_estimate - mark[2]) / dt_s
            drone.rate_mark = (now_s, inbox.n_telemetry, inbox.n_estimate)

        if new_estimate and drone.estimate is not None:
            est = drone.estimate
            mocap = drone.telemetry.position_m if drone.telemetry is not None else None
            threshold_n = est.follow.threshold_n
            nan3 = (math.nan, math.nan, math.nan)
            drone.history.append(
                (
                    now_s,
                    *est.tension_n,
                    est.tension_norm_n,
                    math.nan if threshold_n is None else threshold_n,
                    *(est.position_m or nan3),
                    *(mocap or nan3),
                )
            )
            if est.position_m is not None:
                drone.trail.append(est.position_m)
                drone.trail_t.append(now_s)
        while drone.trail_t and drone.trail_t[0] < now_s - TRAIL_S:
            drone.trail_t.popleft()
            drone.trail.popleft()
        return changed

    def _notify_stop(self, drone_id: str, reason: str) -> None:
        if self._server is None:
            return
        for client in self._server.get_clients().values():
            client.add_notification(
                f"Stop: {drone_id}",
                f"A Stop was sent to {drone_id} ({reason}).",
                color="red",
                auto_close_seconds=15.0,
            )

    def _base_of(self, drone: _Drone) -> Vec3:
        for candidate in (
            drone.estimate.base_m if drone.estimate else None,
            drone.reel.base_m if drone.reel else None,
            self._status_vec(drone, "base_m"),
            drone.truth.base_m if drone.truth else None,
        ):
            if candidate is not None:
                return candidate
        return self._settings.for_drone(drone.id).base.position_m

    def _length_of(self, drone: _Drone) -> float:
        for candidate in (
            drone.estimate.length_m if drone.estimate else None,
            drone.reel.length_m if drone.reel else None,
            self._status_float(drone, "length_m"),
            drone.truth.length_m if drone.truth else None,
        ):
            if candidate is not None and candidate > 0.0:
                return candidate
        return self._settings.for_drone(drone.id).tether.length_m

    def _status(self, drone: _Drone) -> dict[str, Any] | None:
        inbox = drone.inbox
        if inbox.status is None or time.monotonic() - inbox.status_rx_s > STATUS_STALE_S:
            return None
        return inbox.status

    def _status_vec(self, drone: _Drone, key: str) -> Vec3 | None:
        status = drone.inbox.status
        if status is None:
            return None
        try:
            return _opt_vec(status, key, 3)  # type: ignore[return-value]
        except ValueError:
            return None

    def _status_float(self, drone: _Drone, key: str) -> float | None:
        status = drone.inbox.status
        if status is None:
            return None
        try:
            return _opt_float(status, key)
        except ValueError:
            return None

    @staticmethod
    def _body_position(drone: _Drone) -> Vec3 | None:
        """Where the drone is drawn: the estimate, else motion capture, else truth."""
        if drone.estimate is not None and drone.estimate.position_m is not None:
            return drone.estimate.position_m
        if drone.telemetry is not None and drone.telemetry.position_m is not None:
            return drone.telemetry.position_m
        if drone.truth is not None:
            return drone.truth.position_m
        return None

    def _make_nodes(self, server: viser.ViserServer, drone: _Drone) -> _DroneNodes:
        scene = server.scene
        root = f"/drones/{drone.id}"
        vertices, faces = self._mesh
        empty = np.zeros((1, 2, 3), dtype=np.float32)
        return _DroneNodes(
            body=scene.add_frame(f"{root}/body", axes_length=0.12, axes_radius=0.004),
            quad=scene.add_mesh_simple(
                f"{root}/body/quad",
                vertices,
                faces,
                color=drone.color,
                scale=QUAD_DRAW_SCALE,
                side="double",
            ),
            name_label=scene.add_label(
                f"{root}/body/label", drone.id, position=(0.0, 0.0, 0.06), anchor="bottom-center"
            ),
            tether=scene.add_line_segments(f"{root}/tether", empty, _TETHER_RGB, thickness=0.006),
            floor_run=scene.add_line_segments(
                f"{root}/floor_run", empty, _FLOOR_RUN_RGB, thickness=0.008, visible=False
            ),
            arrow=scene.add_arrows(
                f"{root}/tension",
                np.array([[[0, 0, 0], [0, 0, 0.01]]], dtype=np.float32),
                _TENSION_RGB,
                shaft_radius=0.006,
                head_radius=0.016,
                head_length=0.04,
            ),
            arrow_label=scene.add_label(f"{root}/tension_label", "", anchor="center-left"),
            uncertainty=scene.add_icosphere(
                f"{root}/uncertainty",
                radius=1.0,
                color=drone.color,
                opacity=0.15,
                subdivisions=2,
                cast_shadow=False,
                receive_shadow=False,
                visible=False,
            ),
            mocap=scene.add_icosphere(
                f"{root}/mocap", radius=0.015, color=_MOCAP_RGB, visible=False
            ),
            mocap_error=scene.add_line_segments(
                f"{root}/mocap_error", empty, _MOCAP_RGB, thickness=0.004, visible=False
            ),
            mocap_label=scene.add_label(
                f"{root}/mocap_label", "", anchor="top-right", visible=False
            ),
            truth=scene.add_icosphere(
                f"{root}/truth", radius=0.012, color=_TRUTH_RGB, visible=False
            ),
            trail=scene.add_line_segments(
                f"{root}/trail", empty, drone.color, thickness=0.003, visible=False
            ),
            base_column=scene.add_box(
                f"{root}/base_column", color=_BASE_RGB, dimensions=(0.08, 0.08, 0.01)
            ),
            base_exit=scene.add_icosphere(f"{root}/base_exit", radius=0.02, color=_BASE_RGB),
        )

    def _draw(self, server: viser.ViserServer, drone: _Drone, now_s: float) -> None:
        if drone.nodes is None:
            drone.nodes = self._make_nodes(server, drone)
        nodes = drone.nodes
        params = self._settings.for_drone(drone.id)
        floor_z_m = params.base.floor_z_m
        base = self._base_of(drone)
        if nodes.base_drawn != base:
            height_m = max(0.01, base[2] - floor_z_m)
            nodes.base_column.dimensions = (0.05, 0.05, height_m)
            nodes.base_column.position = (base[0], base[1], floor_z_m + height_m / 2.0)
            nodes.base_exit.position = base
            nodes.base_drawn = base

        est = drone.estimate
        body = self._body_position(drone)
        nodes.show("body", body is not None)
        if body is not None:
            nodes.body.position = body
            if drone.telemetry is not None:
                nodes.body.wxyz = _quat_to_wxyz(drone.telemetry.quat_wxyz)
            flags = []
            stale = drone.inbox.telemetry_rx_s is None or (
                time.monotonic() - drone.inbox.telemetry_rx_s > self._settings.service.stale_after_s
            )
            if stale:
                flags.append("stale")
            if est is not None and est.position_m is None:
                flags.append("position undetermined")
            if drone.last_stop is not None or (est is not None and est.follow.stopped):
                flags.append("STOPPED")
            text = drone.id + (f" ({', '.join(flags)})" if flags else "")
            nodes.text("name_label", text)

            pts = tether_points(base, body, self._length_of(drone), floor_z_m=floor_z_m)
            on_floor = np.abs(pts[:, 2] - floor_z_m) < 1e-3
            nodes.tether.points = polyline_segments(pts)
            nodes.show("tether", True)
            if on_floor.sum() >= 2:
                nodes.floor_run.points = polyline_segments(pts[on_floor])
                nodes.show("floor_run", True)
            else:
                nodes.show("floor_run", False)
        else:
            nodes.show("tether", False)
            nodes.show("floor_run", False)

        show_arrow = est is not None and body is not None and not est.on_ground
        nodes.show("arrow", show_arrow)
        nodes.show("arrow_label", show_arrow)
        if show_arrow and est is not None and body is not None:
            arrow = tension_arrow(body, est.tension_n)
            nodes.arrow.points = arrow
            nodes.arrow_label.position = arrow[0, 1]
            nodes.text("arrow_label", f"|T| {est.tension_norm_n:.3f} N")

        std = est.position_std_m if est is not None else None
        if std is not None and est is not None and est.position_m is not None:
            nodes.uncertainty.position = est.position_m
            sx, sy, sz = (float(np.clip(2.0 * s, 0.005, 3.0)) for s in std)
            nodes.uncertainty.scale = (sx, sy, sz)
            nodes.show("uncertainty", True)
        else:
            nodes.show("uncertainty", False)

        mocap = drone.telemetry.position_m if drone.telemetry is not None else None
        nodes.show("mocap", mocap is not None)
        if mocap is not None:
            nodes.mocap.position = mocap
        has_error = mocap is not None and est is not None and est.position_m is not None
        nodes.show("mocap_error", has_error)
        nodes.show("mocap_label", has_error)
        if has_error and mocap is not None and est is not None and est.position_m is not None:
            nodes.mocap_error.points = np.array([[est.position_m, mocap]], dtype=np.float32)
            error_m = math.dist(est.position_m, mocap)
            nodes.mocap_label.position = mocap
            nodes.text("mocap_label", f"mocap Δ {100.0 * error_m:.1f} cm")

        nodes.show("truth", drone.truth is not None)
        if drone.truth is not None:
            nodes.truth.position = drone.truth.position_m

        if len(drone.trail) >= 2:
            nodes.trail.points = polyline_segments(np.asarray(drone.trail))
            nodes.show("trail", True)
        else:
            nodes.show("trail", False)

    def _update_panel(self, drone: _Drone, now_s: float) -> None:
        est = drone.estimate
        status = self._status(drone)
        follow = est.follow if est is not None else None
        if follow is None and status is not None and isinstance(status.get("follow"), dict):
            try:
                follow = FollowView.from_obj(status["follow"])
            except ValueError:
                follow = None
        self._tension_html.content = tension_html(est, drone.truth)
        self._follow_html.content = follow_html(follow, drone.last_stop, now_s)
        if follow is not None:
            self._follow.show(follow.enabled, now_s)
            self._land.show(follow.land_below_m is not None, now_s)
            self._threshold.show(follow.threshold_n, now_s)
            self._land_height.show(follow.land_below_m, now_s)

        length_source = status.get("length_source") if status is not None else None
        from_reel = length_source == "reel" or drone.reel is not None
        self._length.handle.disabled = from_reel
        weight = self._status_float(drone, "weight_n_per_m")
        self._weight.show(
            weight
            if weight is not None
            else self._settings.for_drone(drone.id).tether.weight_n_per_m,
            now_s,
        )
        self._length.show(self._length_of(drone), now_s)
        source = (
            "reel" if from_reel else (length_source if isinstance(length_source, str) else "config")
        )
        self._tether_html.content = (
            f'<div style="font-size:0.8rem;color:#666">length from {html.escape(source)}'
            + (" (not editable here)" if from_reel else "")
            + "</div>"
        )

        age_s = (
            None
            if drone.inbox.telemetry_rx_s is None
            else time.monotonic() - drone.inbox.telemetry_rx_s
        )
        local = LinkStats(drone.telemetry_hz, drone.estimate_hz, age_s, dict(drone.invalid))
        self._health_html.content = health_html(status, local, self._settings.service.stale_after_s)

    def _update_charts(self, drone: _Drone, now_s: float) -> None:
        rows = drone.history.window(now_s - HISTORY_S)
        if len(rows) < 2:
            return
        t = rows[:, _H_T] - now_s
        tension = [fill_gaps(rows[:, c])[0] for c in range(_H_TX, _H_THR + 1)]
        self._tension_chart.data = (t, *tension)
        est = [fill_gaps(rows[:, c])[0] for c in range(_H_EX, _H_EZ + 1)]
        mocap_cols = [fill_gaps(rows[:, c]) for c in range(_H_MX, _H_MZ + 1)]
        has_mocap = all(ok for _, ok in mocap_cols)
        if has_mocap != self._mocap_shown:
            self._position_chart.series = self._position_series(mocap=has_mocap)
            self._mocap_shown = has_mocap
        self._position_chart.data = (t, *est, *(col for col, _ in mocap_cols))

    def _log_once(self, kind: str, msg: str, *args: object) -> None:
        if kind not in self._logged_kinds:
            self._logged_kinds.add(kind)
            _log.warning(msg + " (logged once)", *args)
