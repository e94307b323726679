"""Figures from a (replayed) recording: tension and position over the drone's clock, per drone.

Two steps: :func:`figure_series` reads a recording into the series a figure draws (the data, on
the drone's clock); :func:`write_figures` draws them. The x axis is Telemetry's ``stamp_s``
(Estimate, EstimateSmoothed and Truth carry the same clock), not the time the recorder
received a message: a flight recorded while it was replayed at ``--speed 2``, or recorded
from a simulator running faster than real time, keeps its own length.
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from groundstation.messages import Estimate, EstimateSmoothed, Telemetry, Truth
from groundstation.outputs import NewFile, OutputError
from groundstation.recording.format import (
    RecordingError,
)
from groundstation.recording.reader import iter_messages

__all__ = ["DroneSeries", "Trace", "figure_series", "write_figures"]

_log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]

_KEY_RE = re.compile(r"tether/([^/]+)/(estimate|estimate_smoothed|truth|telemetry)")

_NAN3 = (float("nan"),) * 3


@dataclass(frozen=True)
class Trace:
    """One line of a figure: a 3-vector over the drone's clock.

    Attributes:
        t_s: (n,) seconds since the drone's first stamp (``stamp_s − t0_s``).
        values_m_or_n: (n, 3) world-frame values, metres or newtons; NaN where the source had
            none (an Estimate without a position: a gap in the line).
        std: (n, 3) standard deviation per axis, same unit, or None.
    """

    t_s: FloatArray
    values_m_or_n: FloatArray
    std: FloatArray | None = None


@dataclass(frozen=True)
class DroneSeries:
    """What one drone's figures draw.

    Attributes:
        drone: the drone id.
        t0_s: the drone clock at t = 0 of the figures (its first stamp in the recording), s.
        tension: ``estimate``, ``smoothed``, ``truth``: tension on the drone, N (those present).
        position: ``estimate``, ``smoothed``, ``truth``, ``mocap`` (Telemetry's
            ``position_m``): position, m (those present).
    """

    drone: str
    t0_s: float
    tension: dict[str, Trace]
    position: dict[str, Trace]

    @property
    def span_s(self) -> float:
        """Drone-clock time from the first to the last point of any trace, s."""
        ends = [
            float(np.max(tr.t_s))
            for tr in (*self.tension.values(), *self.position.values())
            if tr.t_s.size
        ]
        return max(ends, default=0.0)


def figure_series(path: str | Path) -> dict[str, DroneSeries]:
    """Read the series of each drone's figures from a (replayed) recording.

    Reads ``tether/{drone}/estimate``, ``estimate_smoothed`` (``replay --offline``), ``truth``
    (the simulator) and ``telemetry`` (its motion-capture ``position_m``) with the contract's
    models; an invalid payload (which the service would have dropped too) is skipped. Times
    are the payloads' ``stamp_s`` less the drone's earliest stamp; the recorder's log time is
    not used. A drone with neither estimates nor truth has no figures and is left out.

    Returns:
        Drone id → its :class:`DroneSeries`, sorted by id.

    Raises:
        RecordingError: the recording is unreadable.
    """
    rows: dict[str, dict[str, list[Any]]] = {}
    for msg in iter_messages(path):
        m = _KEY_RE.fullmatch(msg.key)
        if m is None:
            continue
        drone, kind = m.group(1), m.group(2)
        data: Estimate | EstimateSmoothed | Truth | Telemetry
        try:
            if kind == "estimate":
                data = Estimate.read(msg.payload)
            elif kind == "estimate_smoothed":
                data = EstimateSmoothed.read(msg.payload)
            elif kind == "truth":
                data = Truth.read(msg.payload)
            else:
                data = Telemetry.parse(msg.payload)
        except ValueError:  # InvalidMessage
            continue
        rows.setdefault(drone, {}).setdefault(kind, []).append(data)

    out: dict[str, DroneSeries] = {}
    for drone, kinds in sorted(rows.items()):
        if not kinds.get("estimate") and not kinds.get("truth"):
            continue
        t0 = min(d.stamp_s for items in kinds.values() for d in items)
        est = kinds.get("estimate", [])
        smo = kinds.get("estimate_smoothed", [])
        tru = kinds.get("truth", [])
        mocap = [d for d in kinds.get("telemetry", []) if d.position_m is not None]
        tension: dict[str, Trace] = {}
        position: dict[str, Trace] = {}
        if est:
            tension["estimate"] = _trace(t0, est, "tension_n", "tension_std_n")
            position["estimate"] = _trace(t0, est, "position_m", "position_std_m")
        if smo:
            tension["smoothed"] = _trace(t0, smo, "tension_n", "tension_std_n")
            position["smoothed"] = _trace(t0, smo, "position_m", "position_std_m")
        if tru:
            tension["truth"] = _trace(t0, tru, "tension_n")
            position["truth"] = _trace(t0, tru, "position_m")
        if mocap:
            position["mocap"] = _trace(t0, mocap, "position_m")
        out[drone] = DroneSeries(drone, float(t0), tension, position)
    return out


def _trace(t0_s: float, items: list[Any], field: str, std_field: str | None = None) -> Trace:
    """The Trace of ``field`` (a 3-vector or None) over ``items``' stamps."""
    t = np.array([d.stamp_s for d in items], dtype=float) - t0_s
    v = np.array([getattr(d, field) or _NAN3 for d in items], dtype=float)
    std = None
    if std_field is not None:
        std = np.array([getattr(d, std_field) or _NAN3 for d in items], dtype=float)
    return Trace(t, v, std)


# Drawing order and style: the motion capture a wide pale band under the truth's thin dashed
# line (the two agree to a millimetre, so a thin line would hide one behind the other), the
# estimates on top.
_STYLE: dict[str, dict[str, Any]] = {
    "mocap": {"color": "tab:orange", "lw": 4.0, "alpha": 0.45, "zorder": 1},
    "truth": {"color": "black", "lw": 1.0, "ls": "--", "zorder": 4},
    "estimate": {"color": "tab:blue", "lw": 0.9, "zorder": 2},
    "smoothed": {"color": "tab:green", "lw": 1.3, "zorder": 3},
}
_LABEL = {
    "mocap": "motion capture (position_m)",
    "truth": "simulator truth",
    "estimate": "estimate",
    "smoothed": "smoothed estimate",
}


def write_figures(path: str | Path, figures_dir: str | Path) -> list[Path]:
    """Draw tension and position over the drone's clock per drone from a (replayed) recording.

    Per drone ``{drone}_tension.png`` (estimate ± 1 σ, smoothed estimate, truth) and
    ``{drone}_position.png`` (tether-based estimate, smoothed estimate, truth and motion
    capture), each series where recorded (:func:`figure_series`); the legend sits below the
    axes, clear of the data. Each PNG is written beside its name and moved into place; an
    existing one is replaced (``run_replay_offline`` asks for ``--force`` first). Needs
    matplotlib (the ``dev`` extra); draws with the Agg backend, no display.

    Returns:
        The PNG files written.

    Raises:
        RecordingError: matplotlib is missing, the recording is unreadable, or a PNG cannot
            be written.
    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise RecordingError("figures need matplotlib: pip install matplotlib") from None

    series = figure_series(path)
    out_dir = Path(figures_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    for drone, s in series.items():
        title = f"{drone}: tether tension on the drone (world frame)"
        target = out_dir / f"{drone}_tension.png"
        written.append(_draw(plt, s, s.tension, "T", "N", title, target, band="estimate"))
        title = f"{drone}: position (world frame)"
        target = out_dir / f"{drone}_position.png"
        written.append(_draw(plt, s, s.position, "", "m", title, target, band=None))
    return written


def _draw(
    plt: Any,
    s: DroneSeries,
    traces: dict[str, Trace],
    prefix: str,
    unit: str,
    title: str,
    target: Path,
    *,
    band: str | None,
) -> Path:
    """One 3-row figure (x, y, z) of ``traces``, legend below the axes; written and closed."""
    fig, axs = plt.subplots(3, 1, sharex=True, figsize=(10, 7.5), layout="constrained")
    for i, ax in enumerate(axs):
        for name in ("mocap", "truth", "estimate", "smoothed"):
            tr = traces.get(name)
            if tr is None:
                continue
            style = _STYLE[name]
            ax.plot(tr.t_s, tr.values_m_or_n[:, i], label=_LABEL[name], **style)
            if name == band and tr.std is not None:
                v, sd = tr.values_m_or_n[:, i], tr.std[:, i]
                ax.fill_between(
                    tr.t_s,
                    v - sd,
                    v + sd,
                    color=style["color"],
                    alpha=0.2,
                    lw=0,
                    label="estimate ±1σ",
                    zorder=0,
                )
        _robust_ylim(ax, [tr.values_m_or_n[:, i] for tr in traces.values()])
        ax.set_ylabel(f"{prefix}{'xyz'[i]} [{unit}]")
        ax.grid(True, lw=0.4, alpha=0.5)
    axs[0].set_title(title)
    axs[-1].set_xlabel(f"drone clock [s] (Telemetry stamp_s − {s.t0_s:.3f})")
    axs[-1].set_xlim(0.0, max(s.span_s, 1e-3))
    handles, labels = axs[0].get_legend_handles_labels()
    # Below the axes: a legend inside them sat on the data.
    fig.legend(handles, labels, loc="outside lower center", ncol=len(labels), fontsize=8)
    try:
        # Whole or not at all; the caller decided whether an existing figure may be replaced
        # (run_replay_offline: --force).
        with NewFile(target, force=True) as out:
            fig.savefig(out.stream, format="png", dpi=100)
    except OutputError as exc:
        raise RecordingError(str(exc)) from None
    finally:
        plt.close(fig)
    return target


def _robust_ylim(ax: Any, columns: list[FloatArray]) -> None:
    """Y limits from the 0.5–99.5th percentiles of every series, widened by a quarter.

    A few samples far out (the truth's tether snapping taut at lift-off, an estimate's first
    steps) would otherwise squash the rest into a line; the axis says how many are beyond it.
    """
    values = np.concatenate([c[np.isfinite(c)] for c in columns]) if columns else np.empty(0)
    if values.size < 20:
        return
    lo, hi = np.percentile(values, [0.5, 99.5])
    full_lo, full_hi = float(values.min()), float(values.max())
    pad = max(0.25 * (hi - lo), 1e-3)
    lo, hi = max(lo - pad, full_lo - pad / 5), min(hi + pad, full_hi + pad / 5)
    outside = int(np.count_nonzero((values < lo) | (values > hi)))
    ax.set_ylim(lo, hi)
    if outside:
        ax.text(
            0.995,
            0.02,
            f"{outside} samples beyond the axis",
            transform=ax.transAxes,
            ha="right",
            va="bottom",
            fontsize=7,
            color="0.35",
        )
