"""Figures of the results page (matplotlib, Agg backend), one function per figure.

Each function takes the traces or the summarised results and writes one PNG; it returns the
file name (relative to the figures directory) for the page to link.
"""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from benchmarks import results_paper as rp
from benchmarks.results_envelope import (
    BASELINE_NOISE_MPS2,
    TRUST_P95_M,
    EnvelopeResult,
    size_text,
)
from benchmarks.results_peers import (
    SERVICE_TARGET_P99_MS,
    CatenaryResult,
    DashboardResult,
    ServiceResult,
)
from benchmarks.results_sim import Trace
from groundstation.sim import PAPER_HOVER_SPOTS_M, SCENARIOS

AXIS_COLORS = ("tab:blue", "tab:orange", "tab:green")
TRUTH: dict[str, Any] = {"color": "black", "linestyle": "--", "linewidth": 1.2}
DPI = 100


IDEAL_PROFILE = (
    "simulator profile: ideal (quasi-static catenary; error classes: white accelerometer noise "
    "0.3 m/s², thrust noise 3 mN, both told to the service; no others)"
)


def _save(fig: Figure, out_dir: Path, name: str, profile: str | None = None) -> str:
    """Write ``fig``; ``profile``: a line naming the simulator profile, under the figure."""
    if profile is not None:
        fig.text(0.5, -0.01, profile, ha="center", va="top", fontsize=8, color="0.3")
    out_dir.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_dir / name, dpi=DPI, bbox_inches="tight")
    plt.close(fig)
    return name


def _shade(ax: Axes, t0: float, t1: float, label: str | None, color: str = "0.85") -> None:
    ax.axvspan(t0, t1, color=color, alpha=0.6, linewidth=0, label=label)


def vertical_tension(traces: dict[str, Trace], out_dir: Path) -> str:
    fig, axes = plt.subplots(3, 2, figsize=(13, 10), sharex="col")
    for col, name in enumerate(("takeoff_0.3", "takeoff_1.3")):
        tr = traces[f"{name}/0"]
        t = tr.t_s
        gt = 1e3 * tr.weight_n_per_m * tr.true_pos_m[:, 2]
        ours = 1e3 * -tr.est_tension_n[:, 2]
        naive = 1e3 * -tr.naive_tension_n[:, 2]
        ground = t[tr.true_on_ground]
        lift = float(t[np.flatnonzero(~tr.true_on_ground)[0]])
        h = float(SCENARIOS[name].waypoints[0].position_m[2])
        ax = axes[0, col]
        _shade(ax, float(ground.min()), lift, "drone on the floor (truth)")
        ax.plot(
            t,
            naive,
            color="tab:red",
            lw=1.2,
            label="same filter, no ground detection (paper's behaviour)",
        )
        ax.plot(t, ours, color="tab:blue", lw=1.4, label="ours (0 N while on_ground)")
        ax.plot(t, gt, **TRUTH, label="ground truth ω·z")
        ax.axhline(-294.3, color="tab:red", lw=0.6, ls=":")
        ax.annotate(
            "floor reaction −m·g = −0.29 N\n(the paper's ~0.3 N)",
            (0.5, -285),
            fontsize=8,
            color="tab:red",
            va="bottom",
        )
        ax.set_title(f"Vertical take-off to {h:g} m: vertical tension T_v = −T_z")
        ax.set_ylabel("T_v (mN), downward pull +")
        ax.legend(loc="center right", fontsize=8)
        ax = axes[1, col]
        m = t >= lift - 0.5
        _shade(ax, lift - 0.5, lift, None)
        ax.plot(t[m], ours[m], color="tab:blue", lw=1.2, label="ours")
        ax.plot(t[m], naive[m], color="tab:red", lw=1.0, alpha=0.8, label="no ground detection")
        ax.plot(t[m], gt[m], **TRUTH, label="ω·z")
        ax.set_ylim(-5, max(gt.max() * 1.6, 30))
        ax.set_title("After lift-off (zoom)")
        ax.set_ylabel("T_v (mN)")
        ax.legend(loc="lower right", fontsize=8)
        ax = axes[2, col]
        horiz = 1e3 * np.hypot(tr.est_tension_n[:, 0], tr.est_tension_n[:, 1])
        ax.plot(t, horiz, color="tab:purple", lw=1.2, label="ours: H = |(T_x, T_y)|")
        ax.axhline(
            1e3 * rp.PAPER_H_VERTICAL_N,
            color="tab:red",
            ls=":",
            label="paper: H < 10 mN in vertical flight",
        )
        ax.axhline(0.0, **TRUTH, label="truth (tether plumb): 0")
        ax.set_ylim(-1, 15)
        ax.set_title("Horizontal tension in vertical flight")
        ax.set_ylabel("H (mN)")
        ax.set_xlabel("time (s)")
        ax.legend(loc="upper right", fontsize=8)
    return _save(fig, out_dir, "vertical_tension.png", IDEAL_PROFILE)


def coin(traces: dict[str, Trace], out_dir: Path) -> str:
    tr = traces["coin/0"]
    fig, ax = plt.subplots(figsize=(10, 4.5))
    raw = 1e3 * np.hypot(tr.raw_tension_n[:, 0], tr.raw_tension_n[:, 1])
    est = 1e3 * np.hypot(tr.est_tension_n[:, 0], tr.est_tension_n[:, 1])
    gt = 1e3 * rp.coin_truth_h_n(tr.true_pos_m)
    ax.plot(tr.t_s, raw, color="0.7", lw=0.5, label="raw observation (one sample)")
    ax.plot(tr.t_s, est, color="tab:blue", lw=1.5, label="ours: filtered H")
    ax.plot(tr.t_s, gt, **TRUTH, label="ground truth H = cos(γ)·m_coin·g")
    ax.set_ylim(0, 80)
    ax.set_title("Horizontal tension, 4.1 g coin on a thread over an arm at (0.3, 0, 1) m")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("H (mN)")
    ax.legend(loc="upper right", fontsize=9)
    return _save(fig, out_dir, "coin.png", IDEAL_PROFILE)


def position_spots(traces: dict[str, Trace], out_dir: Path) -> str:
    n = len(PAPER_HOVER_SPOTS_M)
    fig, axes = plt.subplots(n, 3, figsize=(14, 2.1 * n + 0.8), sharex=True)
    for i, spot in enumerate(PAPER_HOVER_SPOTS_M):
        tr = traces[f"spot{i}/0"]
        for k, name in enumerate("xyz"):
            ax = axes[i, k]
            est = tr.est_pos_m[:, k]
            std = tr.est_pos_std_m[:, k]
            ax.fill_between(
                tr.t_s,
                est - std,
                est + std,
                color=AXIS_COLORS[k],
                alpha=0.2,
                linewidth=0,
                label="±1σ (reported)",
            )
            ax.plot(tr.t_s, est, color=AXIS_COLORS[k], lw=1.0, label=f"estimate {name}")
            ax.plot(tr.t_s, tr.true_pos_m[:, k], **TRUTH, label="truth")
            ax.set_ylim(spot[k] - 0.25, spot[k] + 0.25)
            if k == 0:
                ax.set_ylabel(f"spot {i + 1}\n({spot[0]:g}, {spot[1]:g}, {spot[2]:g})\n(m)")
            if i == 0:
                ax.set_title(f"{name} (m), no motion capture")
                ax.legend(loc="upper right", fontsize=7, ncol=3)
            if i == n - 1:
                ax.set_xlabel("time (s)")
    fig.suptitle("Position from tension at the paper's six hover spots: estimate vs truth", y=1.0)
    fig.tight_layout()
    return _save(fig, out_dir, "position_spots.png", IDEAL_PROFILE)


def position_start(traces: dict[str, Trace], out_dir: Path) -> str:
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(13, 4.8))
    cmap = plt.get_cmap("tab10")
    for i, spot in enumerate(PAPER_HOVER_SPOTS_M):
        tr = traces[f"spot{i}/0"]
        m = tr.t_s <= 1.0
        first = int(np.flatnonzero(np.isfinite(tr.est_pos_m[:, 2]))[0])
        label = f"spot {i + 1} ({spot[0]:g}, {spot[1]:g}, {spot[2]:g})"
        ax.plot(tr.t_s[m], tr.est_pos_m[m, 2], color=cmap(i), lw=1.2, label=label)
        ax.plot(tr.t_s[first], tr.est_pos_m[first, 2], "o", color=cmap(i), ms=5)
        ax.axhline(spot[2], color=cmap(i), lw=0.6, ls="--")
        m2 = tr.t_s <= 5.0
        ax2.plot(tr.t_s[m2], 100 * tr.pos_error_m[m2], color=cmap(i), lw=1.0, label=label)
    ax.axhline(
        rp.PAPER_FIRST_Z_M,
        color="magenta",
        lw=2.5,
        ls="-.",
        label="paper's first estimate z = 0.754 − 1.6 = −0.846 m",
    )
    ax.axhline(0.0, color="0.3", lw=1, label="floor")
    ax.set_xlim(-0.02, 1.0)
    ax.set_ylim(-1.0, 1.5)
    ax.set_title("Start of the estimate: z (first position at the dot; truth dashed)")
    ax.set_xlabel("time since the first telemetry (s)")
    ax.set_ylabel("z (m)")
    ax.legend(loc="lower right", fontsize=7)
    ax2.axhline(100 * rp.POSITION_TOL_M, color="tab:red", ls=":", label="10 cm")
    ax2.set_yscale("log")
    ax2.set_ylim(0.3, 100)
    ax2.set_title("3D position error over the first 5 s")
    ax2.set_xlabel("time (s)")
    ax2.set_ylabel("|estimate − truth| (cm)")
    ax2.legend(loc="upper right", fontsize=7, ncol=2)
    return _save(fig, out_dir, "position_start.png", IDEAL_PROFILE)


def tension(traces: dict[str, Trace], paper: rp.PaperResults, out_dir: Path) -> str:
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    ax = axes[0]
    p = paper.plan
    errs: list[list[float]] = [[], [], []]
    for key, tr in traces.items():
        if key.startswith("spot"):
            m = tr.t_s >= p.spot_steady_from_s
            for k in range(3):
                errs[k].extend(1e3 * (tr.est_tension_n[m, k] - tr.true_tension_n[m, k]))
    bins = np.linspace(-3, 3, 61)
    for k, name in enumerate("xyz"):
        rms = paper.position.tension_axis[k].rmse * 1e3
        ax.hist(
            errs[k],
            bins=bins,
            histtype="step",
            lw=1.5,
            color=AXIS_COLORS[k],
            label=f"T_{name}: RMS {rms:.2f} mN",
        )
    ax.set_title("Tension error at hover (six spots, all seeds)")
    ax.set_xlabel("estimate − truth (mN)")
    ax.set_ylabel("samples")
    ax.legend(fontsize=8)
    tr = traces["tug/0"]
    pull = SCENARIOS["tug"].pulls[0]
    for ax, t0, title in (
        (axes[1], pull.start_s, "30 mN tug toward the base: onset"),
        (axes[2], pull.end_s, "release"),
    ):
        m = (tr.t_s >= t0 - 0.3) & (tr.t_s <= t0 + 1.0)
        ax.plot(
            tr.t_s[m],
            1e3 * tr.raw_tension_n[m, 0],
            color="0.75",
            lw=0.5,
            label="raw observation T_x",
        )
        ax.plot(tr.t_s[m], 1e3 * tr.est_tension_n[m, 0], color="tab:blue", lw=1.5, label="ours T_x")
        ax.plot(tr.t_s[m], 1e3 * tr.true_tension_n[m, 0], **TRUTH, label="truth T_x")
        ax.axvline(t0, color="tab:red", lw=0.8, ls=":")
        ax.set_ylim(-80, 20)
        ax.set_title(title)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("T_x (mN)")
        ax.legend(loc="lower right" if t0 == pull.end_s else "upper right", fontsize=8)
    return _save(fig, out_dir, "tension.png", IDEAL_PROFILE)


def follow(traces: dict[str, Trace], out_dir: Path) -> str:
    sc = SCENARIOS["follow"]
    fig, axes = plt.subplots(2, 3, figsize=(15, 8.5))
    for row, tag in enumerate(("mocap", "tether")):
        tr = traces[f"follow_{tag}/0"]
        src = "motion capture" if tag == "mocap" else "the tether-based estimate"
        ax = axes[row, 0]
        ax.plot(
            tr.true_pos_m[:, 0], tr.true_pos_m[:, 1], color="black", lw=1.2, label="drone (truth)"
        )
        if len(tr.setpoints):
            ax.plot(
                tr.setpoints[:, 1],
                tr.setpoints[:, 2],
                ".",
                color="tab:orange",
                ms=2,
                label="setpoints sent",
            )
        ax.plot(*tr.true_pos_m[0, :2], "go", label="start")
        ax.plot(*tr.final_pos_m[:2], "rs", label="end")
        ax.plot(0, 0, "k^", ms=9, label="base")
        for pull in sc.pulls:
            i = int(np.searchsorted(tr.t_s, pull.start_s))
            p0 = tr.true_pos_m[i]
            f = np.asarray(pull.force_world_n[:2]) * 3.0
            ax.annotate("", p0[:2] + f, p0[:2], arrowprops={"arrowstyle": "->", "color": "red"})
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(f"Follow, setpoint from {src}: top view")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.legend(fontsize=7, loc="best")
        ax = axes[row, 1]
        for j, pull in enumerate(sc.pulls):
            _shade(ax, pull.start_s, pull.end_s, "pull (hand)" if j == 0 else None, "mistyrose")
        for k, name in enumerate("xyz"):
            ax.plot(
                tr.t_s, tr.true_pos_m[:, k], color=AXIS_COLORS[k], lw=1.3, label=f"{name} truth"
            )
            ax.plot(
                tr.t_s,
                tr.est_pos_m[:, k],
                color=AXIS_COLORS[k],
                lw=0.6,
                alpha=0.6,
                ls=":",
                label=f"{name} tether estimate",
            )
            if len(tr.setpoints):
                ax.plot(
                    tr.setpoints[:, 0], tr.setpoints[:, 1 + k], ".", ms=1.5, color=AXIS_COLORS[k]
                )
        ax.set_ylim(-2.0, 2.5)
        ax.set_title("Position (dots: setpoints)")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("position (m)")
        ax.legend(fontsize=6, ncol=2, loc="lower left")
        ax = axes[row, 2]
        for j, pull in enumerate(sc.pulls):
            _shade(ax, pull.start_s, pull.end_s, "pull" if j == 0 else None, "mistyrose")
        ax.plot(
            tr.t_s,
            1e3 * np.linalg.norm(tr.est_tension_n, axis=1),
            color="tab:blue",
            lw=1.2,
            label="|T| estimate",
        )
        ax.plot(tr.t_s, 1e3 * np.linalg.norm(tr.true_tension_n, axis=1), **TRUTH, label="|T| truth")
        thr = 150.0
        ax.axhline(thr, color="tab:red", ls=":", label="threshold 150 mN")
        ax.axhline(thr * 0.8, color="tab:red", ls="-.", lw=0.7, label="release 120 mN")
        active = np.where(tr.follow_active, 1.0, np.nan)
        ax.plot(tr.t_s, 260 * active, color="tab:green", lw=4, label="following active")
        ax.set_ylim(0, 300)
        ax.set_title("Tension and follow state")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("|T| (mN)")
        ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    return _save(fig, out_dir, "follow.png", IDEAL_PROFILE)


def tug_landing(traces: dict[str, Trace], out_dir: Path) -> str:
    sc = SCENARIOS["tug_landing"]
    pull = sc.pulls[0]
    land = 0.25
    fig, axes = plt.subplots(1, 2, figsize=(14, 4.8))
    colors = {"mocap": "tab:blue", "tether": "tab:purple"}
    ax = axes[0]
    _shade(ax, pull.start_s, pull.end_s, "pull down (hand)", "mistyrose")
    for tag, color in colors.items():
        tr = traces[f"tug_landing_{tag}/0"]
        src = "motion capture" if tag == "mocap" else "tether estimate"
        ax.plot(
            tr.t_s, tr.true_pos_m[:, 2], color=color, lw=1.5, label=f"z truth, setpoint from {src}"
        )
        if len(tr.setpoints):
            ax.plot(tr.setpoints[:, 0], tr.setpoints[:, 3], ".", ms=1.5, color=color, alpha=0.5)
        for t_stop, _ in tr.stops:
            i = int(np.searchsorted(tr.t_s, t_stop))
            ax.plot(
                t_stop, tr.true_pos_m[i, 2], "X", color="tab:red", ms=11, label=f"Stop sent ({src})"
            )
    ax.axhline(land, color="tab:red", ls=":", label="land_below_m 0.25 m")
    ax.axhline(0.754 + 1.6, color="0.4", ls="-.", lw=0.8, label="tether reach (base z + L)")
    ax.set_title("Tug-to-land: height (dots: setpoints)")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("z (m)")
    ax.set_ylim(-0.1, 2.6)
    ax.legend(fontsize=7, loc="upper left")
    ax = axes[1]
    _shade(ax, pull.start_s, pull.end_s, "pull", "mistyrose")
    for tag, color in colors.items():
        tr = traces[f"tug_landing_{tag}/0"]
        ax.plot(
            tr.t_s,
            1e3 * np.linalg.norm(tr.est_tension_n, axis=1),
            color=color,
            lw=1.2,
            label=f"|T| estimate ({tag})",
        )
        ax.plot(
            tr.t_s,
            1e3 * np.linalg.norm(tr.true_tension_n, axis=1),
            color=color,
            ls="--",
            lw=0.8,
            label=f"|T| truth ({tag})",
        )
    ax.axhline(150, color="tab:red", ls=":", label="threshold 150 mN")
    ax.set_title("Tension (0 once the motors stop: on the ground)")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("|T| (mN)")
    ax.legend(fontsize=7, loc="upper right")
    return _save(fig, out_dir, "tug_landing.png", IDEAL_PROFILE)


def catenary(cat: CatenaryResult, out_dir: Path) -> str:
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(15, 4.8), gridspec_kw={"width_ratios": [1, 1.3]})
    names = [m.name for m in cat.methods]
    us = [m.us_per_solve for m in cat.methods]
    y = np.arange(len(names))
    bars = ax.barh(y, us, color=["tab:blue", "tab:blue", "tab:orange", "tab:red", "tab:gray"])
    for b, m in zip(bars, cat.methods, strict=True):
        ax.text(
            b.get_width() * 1.15,
            b.get_y() + b.get_height() / 2,
            f"{m.us_per_solve:.3g} µs, ok {100 * m.ok:.0f} %",
            va="center",
            fontsize=8,
        )
    ax.set_yticks(y, names, fontsize=8)
    ax.invert_yaxis()
    ax.set_xscale("log")
    ax.set_xlim(0.01, 1e4)
    ax.set_xlabel("time per solve (µs, log)")
    ax.set_title("Catenary through two points with a length: time per solve")
    cats = list(cat.methods[0].ok_by_category)
    width = 0.8 / len(cat.methods)
    x = np.arange(len(cats))
    for j, m in enumerate(cat.methods):
        ax2.bar(
            x + (j - len(cat.methods) / 2 + 0.5) * width,
            [100 * m.ok_by_category[c] for c in cats],
            width,
            label=m.name,
        )
    ax2.set_xticks(x, cats)
    ax2.set_ylim(0, 105)
    ax2.set_ylabel("cases within 1e-9 of a 50-digit reference (%)")
    ax2.set_title(f"Accuracy by case category ({cat.n_reference} reference cases)")
    ax2.legend(fontsize=7, loc="lower left")
    return _save(fig, out_dir, "catenary.png")


def service(svc: ServiceResult, dash: DashboardResult, out_dir: Path) -> str:
    rows = sorted(svc.rows, key=lambda r: r["drones"])
    n = np.array([r["drones"] for r in rows], dtype=float)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    ax = axes[0]
    ax.plot(n, [r["p50_ms"] for r in rows], "o-", label="p50")
    ax.plot(n, [r["p99_ms"] for r in rows], "s-", label="p99")
    for r in svc.dashboard_rows:
        ax.plot(r["drones"], r["p50_ms"], "d", color="tab:purple", label="p50 with dashboard")
        ax.plot(r["drones"], r["p99_ms"], "D", color="tab:red", label="p99 with dashboard")
    ax.axhline(SERVICE_TARGET_P99_MS, color="tab:red", ls=":", label="p99 target 10 ms")
    ax.set_yscale("log")
    ax.set_xlabel("drones × 250 Hz")
    ax.set_ylabel("publish → estimate latency (ms, log)")
    ax.set_title("Latency")
    ax.legend(fontsize=8)
    ax = axes[1]
    ax.plot(n, [100 * r["delivered"] for r in rows], "o-", label="estimates / telemetry sent")
    ax.axhline(99.9, color="tab:red", ls=":", label="target 99.9 %")
    low = min([100 * r["delivered"] for r in rows] + [99.0])
    ax.set_ylim(max(0.0, low - 0.25 * (100.5 - low)), 100.5)
    ax.set_xlabel("drones × 250 Hz")
    ax.set_ylabel("delivered (%)")
    ax.set_title("Delivery")
    ax.legend(fontsize=8, loc="lower left")
    ax = axes[2]
    ax.plot(n, [r["cpu_share"] for r in rows], "o-", label="service CPU (cores)")
    for r in svc.dashboard_rows:
        ax.plot(r["drones"], r["cpu_share"], "D", color="tab:red", label="service + dashboard")
    ax.set_xlabel("drones × 250 Hz")
    ax.set_ylim(0, 2.1)
    ax.axhline(1.0, color="0.5", lw=0.8, ls="--")
    ax.set_ylabel("CPU (cores; 1.0 = one core busy)")
    ax.set_title("Service CPU")
    ax2 = ax.twinx()
    ax2.plot(
        n, [r["cpu_us_per_msg"] for r in rows], "^--", color="tab:green", label="µs CPU per message"
    )
    ax2.set_ylabel("CPU per message (µs)")
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, fontsize=8, loc="center right")
    fig.suptitle(
        "Service at scale: router + groundstation serve + load client on 127.0.0.1 "
        f"({svc.seconds:g} s per case; load average {svc.load_before:.1f} at start)",
        y=1.02,
    )
    return _save(fig, out_dir, "service.png")


def envelope(env: EnvelopeResult, out_dir: Path) -> str:
    """Realistic profile: cm per error class at its real size, uncalibrated vs calibration =
    truth (left), and each class over its range, relative to its real size (right)."""
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(16, 6.2), gridspec_kw={"width_ratios": [1.5, 1.0]})
    base = env.cls("vibration").at(BASELINE_NOISE_MPS2).raw
    classes = [c for c in env.classes if c.cls.name != "vibration"]
    names = ["baseline\n(vibration\nonly)"] + [
        c.cls.name.replace("_", " ") + "\n" + textwrap.fill(size_text(c.cls, c.real.value), 12)
        for c in classes
    ]
    x = np.arange(len(names))
    raw_med = [base.median_m] + [c.real.raw.median_m for c in classes]
    raw_p95 = [base.p95_m] + [c.real.raw.p95_m for c in classes]
    cal = [c.real.cal for c in classes]
    w = 0.38
    ax.bar(x - w / 2, [100 * v for v in raw_med], w, color="tab:red", label="uncalibrated, median")
    ax.plot(x - w / 2, [100 * v for v in raw_p95], "v", color="darkred", label="uncalibrated, p95")
    xc = [i + 1 for i, c in enumerate(cal) if c is not None]
    ax.bar(
        [v + w / 2 for v in xc],
        [100 * c.median_m for c in cal if c is not None],
        w,
        color="tab:green",
        label="calibration = truth, median",
    )
    ax.plot(
        [v + w / 2 for v in xc],
        [100 * c.p95_m for c in cal if c is not None],
        "v",
        color="darkgreen",
        label="calibration = truth, p95",
    )
    for i, c in enumerate(cal):
        if c is None:
            ax.text(
                i + 1 + w / 2, 1.2, "nothing to calibrate", fontsize=6.5, ha="center", rotation=90
            )
    ax.axhline(100 * base.median_m, color="0.4", ls="--", lw=0.8, label="baseline median")
    ax.set_xticks(x)
    ax.set_xticklabels(names, fontsize=7.5)
    ax.set_yscale("log")
    ax.set_ylim(1, 500)
    ax.set_ylabel("3D position error (cm, log)")
    ax.set_title("Each error class at its real size, on top of the baseline")
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(alpha=0.3, axis="y", which="both")
    for c in env.classes:
        if c.cls.real == c.cls.baseline or c.cls.name in ("all", "battery"):
            continue  # no size to scale (battery: a state of charge; its table has it)
        pts = [p for p in c.points if p.value * c.cls.real >= 0 or p.value == 0]
        rel = [abs(p.value / c.cls.real) if c.cls.real else 0.0 for p in pts]
        order = np.argsort(rel)
        ax2.plot(
            np.array(rel)[order],
            [100 * pts[k].raw.median_m for k in order],
            "o-",
            ms=4,
            label=c.cls.name.replace("_", " "),
        )
    ax2.axhline(100 * base.median_m, color="0.4", ls="--", lw=0.8)
    ax2.set_yscale("log")
    ax2.set_ylim(1, 500)
    ax2.set_xlabel("size / its real size (0: off; 1: the real flights)")
    ax2.set_ylabel("median 3D position error, uncalibrated (cm, log)")
    ax2.set_title("Over the range (same sign as the real size)")
    ax2.legend(fontsize=7.5, ncol=2)
    ax2.grid(alpha=0.3, which="both")
    p = env.plan
    fig.suptitle(
        "Envelope, realistic profile (error classes one at a time on a baseline of vibration "
        f"{BASELINE_NOISE_MPS2:g} m/s², every other class off), no motion capture; "
        f"{len(p.spots)} of the paper's spots, errors from {p.steady_from_s:g} s",
        y=1.01,
    )
    fig.tight_layout()
    return _save(fig, out_dir, "envelope.png")


def envelope_model(env: EnvelopeResult, out_dir: Path) -> str:
    """Realistic profile, baseline: ω error, tether length, distance from the base."""
    sweeps = env.sweeps
    fig, axes = plt.subplots(1, len(sweeps), figsize=(5 * len(sweeps), 4.3))
    for ax, sw in zip(np.atleast_1d(axes), sweeps, strict=True):
        v = [pt.value for pt in sw.points]
        ax.plot(v, [100 * pt.stats.median_m for pt in sw.points], "o-", label="median 3D error")
        ax.plot(v, [100 * pt.stats.p95_m for pt in sw.points], "s-", label="p95 3D error")
        ax.plot(
            v,
            [100 * pt.stats.vertical_median_m for pt in sw.points],
            "^:",
            lw=0.9,
            label="median |Δz|",
        )
        ax.plot(
            v,
            [100 * pt.stats.horizontal_median_m for pt in sw.points],
            "v:",
            lw=0.9,
            label="median horizontal error",
        )
        ax.axhline(100 * TRUST_P95_M, color="tab:red", ls=":", lw=1.0, label="10 cm")
        ax.axvline(sw.sweep.nominal, color="0.5", lw=0.8, ls="--", label="nominal")
        ax.set_yscale("log")
        ax.set_ylim(0.5, 500)
        ax.set_xlabel(sw.sweep.label)
        ax.set_ylabel("position error (cm, log)")
        ax.set_title(sw.sweep.label.split(" (")[0])
        ax.grid(alpha=0.3, which="both")
    np.atleast_1d(axes)[0].legend(fontsize=8)
    fig.suptitle(
        "The model's factors, realistic profile, baseline (vibration "
        f"{BASELINE_NOISE_MPS2:g} m/s², every other error class off), no motion capture",
        y=1.02,
    )
    fig.tight_layout()
    return _save(fig, out_dir, "envelope_model.png")


def all_figures(
    traces: dict[str, Any],
    paper: rp.PaperResults,
    cat: CatenaryResult,
    svc: ServiceResult,
    dash: DashboardResult,
    env: EnvelopeResult,
    out_dir: Path,
) -> dict[str, str]:
    return {
        "vertical_tension": vertical_tension(traces, out_dir),
        "coin": coin(traces, out_dir),
        "position_spots": position_spots(traces, out_dir),
        "position_start": position_start(traces, out_dir),
        "tension": tension(traces, paper, out_dir),
        "follow": follow(traces, out_dir),
        "tug_landing": tug_landing(traces, out_dir),
        "catenary": catenary(cat, out_dir),
        "service": service(svc, dash, out_dir),
        "envelope": envelope(env, out_dir),
        "envelope_model": envelope_model(env, out_dir),
    }
