"""Figures from a (replayed) recording: tension and position over time per drone."""

from __future__ import annotations

import logging
import re
from collections import defaultdict
from pathlib import Path
from typing import Any

from groundstation.messages import Estimate, Telemetry, Truth
from groundstation.recording.format import (
    RecordingError,
)
from groundstation.recording.reader import iter_messages

_log = logging.getLogger(__name__)


def write_figures(path: str | Path, figures_dir: str | Path) -> list[Path]:
    """Draw tension and position over time per drone from a (replayed) recording.

    Per drone ``{drone}_tension.png`` (estimate ± 1 σ, and truth when recorded) and
    ``{drone}_position.png`` (tether-based estimate, truth and motion capture when recorded).
    Needs matplotlib (the ``dev`` extra); draws with the Agg backend, no display.

    Returns:
        The PNG files written.

    Raises:
        RecordingError: matplotlib is missing, or the recording is unreadable.
    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise RecordingError("figures need matplotlib: pip install matplotlib") from None

    series: dict[str, dict[str, list[tuple[float, Any]]]] = defaultdict(lambda: defaultdict(list))
    t0_ns: int | None = None
    for msg in iter_messages(path):
        m = re.fullmatch(r"tether/([^/]+)/(estimate|truth|telemetry)", msg.key)
        if m is None:
            continue
        if t0_ns is None:
            t0_ns = msg.log_time_ns
        # One definition of each payload: the contract's models read them (an invalid one,
        # which the service would have dropped too, is not drawn).
        data: Estimate | Truth | Telemetry
        try:
            if m.group(2) == "estimate":
                data = Estimate.read(msg.payload)
            elif m.group(2) == "truth":
                data = Truth.read(msg.payload)
            else:
                data = Telemetry.parse(msg.payload)
        except ValueError:  # InvalidMessage
            continue
        series[m.group(1)][m.group(2)].append(((msg.log_time_ns - t0_ns) / 1e9, data))

    out_dir = Path(figures_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    axes_names = ("x", "y", "z")
    for drone, kinds in sorted(series.items()):
        est = kinds.get("estimate", [])
        truth = kinds.get("truth", [])
        tele = kinds.get("telemetry", [])
        if not est and not truth:
            continue

        fig, axs = plt.subplots(3, 1, sharex=True, figsize=(9, 7))
        for i, ax in enumerate(axs):
            if est:
                t = [s for s, _ in est]
                v = [d.tension_n[i] for _, d in est]
                sd = [d.tension_std_n[i] for _, d in est]
                ax.plot(t, v, lw=1, label="estimate")
                ax.fill_between(
                    t,
                    [a - b for a, b in zip(v, sd, strict=True)],
                    [a + b for a, b in zip(v, sd, strict=True)],
                    alpha=0.25,
                    lw=0,
                    label="±1σ",
                )
            _plot_truth(ax, truth, "tension_n", i)
            ax.set_ylabel(f"T{axes_names[i]} [N]")
        title = f"{drone}: tether tension on the drone (world frame)"
        written.append(_save(plt, fig, axs, title, out_dir / f"{drone}_tension.png"))

        fig, axs = plt.subplots(3, 1, sharex=True, figsize=(9, 7))
        for i, ax in enumerate(axs):
            pts = [(s, d.position_m[i]) for s, d in est if d.position_m is not None]
            if pts:
                ax.plot(*zip(*pts, strict=True), lw=1, label="tether estimate")
            mocap = [(s, d.position_m[i]) for s, d in tele if d.position_m is not None]
            if mocap:
                ax.plot(*zip(*mocap, strict=True), lw=1, alpha=0.7, label="motion capture")
            _plot_truth(ax, truth, "position_m", i)
            ax.set_ylabel(f"{axes_names[i]} [m]")
        title = f"{drone}: position (world frame)"
        written.append(_save(plt, fig, axs, title, out_dir / f"{drone}_position.png"))
    return written


def _plot_truth(ax: Any, truth: list[tuple[float, Any]], field: str, i: int) -> None:
    """The simulator's truth of ``field``'s component ``i`` as a dashed line, if recorded."""
    if truth:
        values = [getattr(d, field)[i] for _, d in truth]
        ax.plot([s for s, _ in truth], values, "k--", lw=1, label="truth")


def _save(plt: Any, fig: Any, axs: Any, title: str, target: Path) -> Path:
    """Legend, title and time axis of a 3-row figure; written to ``target`` and closed."""
    axs[0].legend(loc="upper right", fontsize=8)
    axs[0].set_title(title)
    axs[-1].set_xlabel("time [s]")
    fig.savefig(target, dpi=100)
    plt.close(fig)
    return target
