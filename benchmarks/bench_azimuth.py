"""Position error per azimuth source, from a plumb tether to a nearly taut one.

Run from the repository root::

    .venv/bin/python -m benchmarks.bench_azimuth            # writes docs/azimuth_sources.md
    .venv/bin/python -m benchmarks.bench_azimuth --quick    # 4 spots, 4 s, one table; prints
    .venv/bin/python -m benchmarks.bench_azimuth --profile ideal   # the ideal profile instead

Method. The simulator (``[sim] profile``, default ``realistic``; ``[sim] exit_angles`` on: the
base sensor of ``groundstation/sim/base_sensor.py`` publishes the tether's exit azimuth and
elevation in Reel at 10 Hz, noise 0.02 rad each, the azimuth's growing as 1/cos(elevation))
hovers the drone at spots 0.25 m above the base's exit (z = 1.0 m, base at 0.754 m, L = 1.6 m,
ω = 0.05 N/m) at azimuth 40°, from straight above the base (r = 0, plumb) to 97 % of L (nearly
taut). The realistic profile runs twice: with the error classes a calibration removes
(``CALIBRATED_OFF``: thrust map, battery, misalignment, accelerometer scale and bias, thrust
axis) switched off, i.e. a calibrated drone, and with every class on (uncalibrated: the
pipelines are given no ``[calibration]``, though they would apply one). Each simulated sample
goes, in lock-step, through one :class:`Pipeline` per row below, which differ only in
``[localization]``; the published ``position_m`` is compared with the simulator's truth for
the same sample, after a 2 s warm-up. Motion capture is published (the ``mocap`` row needs
it; no other row reads it for localization).

Rows (``[localization] azimuth`` / ``elevation``):

* ``tension``: β from the horizontal tension's direction; r, z from the tension (the paper's
  localization without motion capture).
* ``tension + elevation``: the same β; the exit elevation fused with the tension in (a, s2).
* ``reel``: β from the reel's exit azimuth; r, z from the tension.
* ``mocap (paper)``: β from the motion-capture position; r, z from the tension (the paper).
* ``auto``: β fused from the tension and the reel by their σ; r, z from the tension.
* ``auto + elevation`` (the default configuration): β fused; the elevation fused too.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.figures import AT_START, DOCS, kept_reading, marker, write_figures
from groundstation.config import Settings, load_settings
from groundstation.pipeline import Pipeline
from groundstation.sim import Simulator
from groundstation.sim.scenarios import SCENARIOS, Scenario, Waypoint

DOC_PATH = Path(__file__).resolve().parent.parent / "docs" / "azimuth_sources.md"
BASE_M = (0.0, 0.0, 0.754)
LENGTH_M = 1.6
HEIGHT_M = 1.0
AZIMUTH_RAD = math.radians(40.0)
SPOTS_R_M = (0.0, 0.1, 0.2, 0.35, 0.6, 0.9, 1.2, 1.4, 1.53)
QUICK_R_M = (0.0, 0.2, 0.9, 1.53)
WARMUP_S = 2.0
CALIBRATED_OFF = (
    "thrust_map",
    "battery",
    "misalignment",
    "accel_scale",
    "accel_bias",
    "thrust_axis",
)
ROWS: tuple[tuple[str, str, bool], ...] = (
    ("tension", "tension", False),
    ("tension + elevation", "tension", True),
    ("reel", "reel", False),
    ("mocap (paper)", "mocap", False),
    ("auto", "auto", False),
    ("auto + elevation", "auto", True),
)


@dataclass
class Errors:
    """3-D position errors of one row at one spot, m, and what was published."""

    errors_m: list[float] = field(default_factory=list)
    samples: int = 0
    with_position: int = 0
    determined: int = 0
    tension_err_n: list[list[float]] = field(default_factory=list)
    """Filtered tension minus the truth, per sample, N (the same filter in every row)."""
    tension_std_n: list[list[float]] = field(default_factory=list)
    """The filter's reported σ per axis, per sample, N."""


def _settings(
    profile: str, seed: int, azimuth: str, elevation: bool, calibrated: bool = False
) -> Settings:
    sim: dict[str, Any] = {"profile": profile, "seed": seed, "mocap": True, "exit_angles": True}
    if calibrated:
        sim["realistic"] = dict.fromkeys(CALIBRATED_OFF, False)
    return load_settings(
        None,
        {"sim": sim, "localization": {"azimuth": azimuth, "elevation": elevation}},
        use_env=False,
    )


def _spot(r_m: float) -> tuple[float, float, float]:
    return (
        BASE_M[0] + r_m * math.cos(AZIMUTH_RAD),
        BASE_M[1] + r_m * math.sin(AZIMUTH_RAD),
        HEIGHT_M,
    )


def run_spot(
    profile: str, r_m: float, seconds: float, seed: int, calibrated: bool
) -> tuple[dict[str, Errors], dict[str, bool] | None]:
    """One hover at radius ``r_m``; every row's errors, and the sim's error classes."""
    spot = _spot(r_m)
    name = f"bench_azimuth_{r_m:g}"
    # A scenario for this spot, registered for this process only.
    SCENARIOS[name] = Scenario(
        name,
        f"hover at r = {r_m} m, z = {HEIGHT_M} m (bench_azimuth)",
        start_m=spot,
        waypoints=(Waypoint(0.0, spot),),
        base_m=BASE_M,
        length_m=LENGTH_M,
    )
    sim = Simulator(_settings(profile, seed, "auto", True, calibrated), None, scenario=name)  # type: ignore[arg-type]
    pipes = {row: Pipeline(_settings(profile, seed, az, el, calibrated)) for row, az, el in ROWS}
    out = {row: Errors() for row, _, _ in ROWS}
    pending: dict[str, dict[str, Any] | None] = dict.fromkeys(pipes)
    for _ in range(round(seconds / sim.dt_s)):
        now_s = sim.t_s
        for sample in sim.step():
            kind = sample.key.split("/", 2)[2]
            if kind == "truth":
                # The truth of the telemetry sample just processed.
                truth = json.loads(sample.payload)
                if truth["stamp_s"] < WARMUP_S:
                    continue
                for row, est in pending.items():
                    if est is None:
                        continue
                    e = out[row]
                    e.samples += 1
                    if est["position_m"] is not None:
                        e.with_position += 1
                        err = np.subtract(est["position_m"], truth["position_m"])
                        e.errors_m.append(float(np.linalg.norm(err)))
                    e.determined += bool(est.get("azimuth_determined"))
                    if not est["on_ground"]:
                        e.tension_err_n.append(
                            np.subtract(est["tension_n"], truth["tension_n"]).tolist()
                        )
                        e.tension_std_n.append(est["tension_std_n"])
                continue
            for row, pipe in pipes.items():
                for published in pipe.handle(sample, now_s):
                    if published.key.endswith("/estimate"):
                        pending[row] = json.loads(published.payload)
        for pipe in pipes.values():
            pipe.tick(now_s)
    del SCENARIOS[name]
    drawn = sim.drawn_errors(next(iter(sim.drones)))
    return out, (drawn or {}).get("classes")


def _chord_ratio(r_m: float) -> float:
    return math.hypot(r_m, HEIGHT_M - BASE_M[2]) / LENGTH_M


def _cell(e: Errors) -> str:
    if not e.errors_m:
        return "—"
    med = float(np.median(e.errors_m)) * 100
    p95 = float(np.percentile(e.errors_m, 95)) * 100
    return f"{med:.1f} / {p95:.1f}"


def _figures(results: dict[float, dict[str, Errors]]) -> dict[str, Any]:
    """Per row: median and p95 position error, cm, per spot and over every spot."""
    out: dict[str, Any] = {}
    for row, _, _ in ROWS:
        pooled = [e for r in sorted(results) for e in results[r][row].errors_m]
        out[row] = {
            "all_spots_median_cm": 100 * float(np.median(pooled)) if pooled else None,
            "all_spots_p95_cm": 100 * float(np.percentile(pooled, 95)) if pooled else None,
            "per_spot": {
                f"{r:g}": [
                    100 * float(np.median(results[r][row].errors_m)),
                    100 * float(np.percentile(results[r][row].errors_m, 95)),
                ]
                if results[r][row].errors_m
                else None
                for r in sorted(results)
            },
        }
    return out


def _quoted(fig: dict[str, Any]) -> str:
    """One sentence that quotes the calibrated section's pooled figures (checked against
    docs/azimuth_sources.json by tests/test_docs_numbers.py)."""
    parts = [
        f"{row} {fig[row]['all_spots_median_cm']:.1f}"
        + marker("azimuth_sources.json", f"realistic_calibrated.{row}.all_spots_median_cm")
        for row, _, _ in ROWS
        if fig[row]["all_spots_median_cm"] is not None and " " not in row
    ]
    return "\n\nOver every spot, median cm: " + ", ".join(parts) + ".\n"


def render_header(profile: str, seconds: float, seed: int, quick: bool, elapsed_s: float) -> str:
    cmd = ".venv/bin/python -m benchmarks.bench_azimuth" + (" --quick" if quick else "")
    if profile != "realistic":
        cmd += f" --profile {profile}"
    profile = "realistic, then ideal" if profile == "realistic" and not quick else profile
    commit = AT_START.commit
    return "\n".join(
        [
            "# Position error per azimuth source, plumb to taut",
            "",
            f"From `{cmd}` (this page; the full run's figures in docs/azimuth_sources.json; "
            f"{elapsed_s:.0f} s on a shared 2-core machine; commit "
            f"`{commit}`, Python {platform.python_version()}, numpy "
            f"{np.__version__}). The method is in the benchmark's docstring.",
            "",
            f"Simulator profile **{profile}** (each section names its own); seed {seed}; "
            "base sensor (`[sim] exit_angles`): "
            "exit azimuth and elevation in Reel at 10 Hz, σ 0.02 rad each (the azimuth's σ "
            f"growing as 1/cos(elevation)). Hover {seconds:g} s per spot at z = {HEIGHT_M} m, "
            f"azimuth 40°, base at {BASE_M[2]} m, L = {LENGTH_M} m, ω = 0.05 N/m; errors after "
            f"a {WARMUP_S:g} s warm-up, 3-D distance between the published `position_m` and "
            "the truth of the same sample. Motion capture is in the Telemetry for every row; "
            "only `mocap (paper)` takes the azimuth from it.",
            "",
            "Cells: median / p95 position error, **cm**. Columns: horizontal distance r of "
            "the spot from the base (chord / L).",
            "",
        ]
    )


def render_section(
    title: str, results: dict[float, dict[str, Errors]], classes: dict[str, bool] | None
) -> str:
    radii = sorted(results)
    on = ", ".join(k for k, v in (classes or {}).items() if v) if classes else ""
    lines = [
        f"## {title}",
        "",
        f"Error classes on: {on} (docs/simulator.md)."
        if classes
        else "White IMU (0.3 m/s²) and thrust (3 mN) noise, the catenary's own tether.",
        "",
        "| source | "
        + " | ".join(f"r = {r:g} m ({_chord_ratio(r):.0%})" for r in radii)
        + " | all spots |",
        "|---|" + "---|" * (len(radii) + 1),
    ]
    for row, _, _ in ROWS:
        pooled = Errors()
        for r in radii:
            pooled.errors_m += results[r][row].errors_m
        cells = [_cell(results[r][row]) for r in radii]
        lines.append(f"| {row} | " + " | ".join(cells) + f" | {_cell(pooled)} |")
    lines += [
        "",
        "Share of samples with the azimuth determined (σ ≤ 1/3 rad):",
        "",
        "| source | " + " | ".join(f"{r:g} m" for r in radii) + " |",
        "|---|" + "---|" * len(radii),
    ]
    for row, _, _ in ROWS:
        cells = [
            f"{results[r][row].determined / max(results[r][row].samples, 1):.0%}" for r in radii
        ]
        lines.append(f"| {row} | " + " | ".join(cells) + " |")
    filt = Errors()
    for r in radii:
        filt.tension_err_n += results[r][ROWS[0][0]].tension_err_n
        filt.tension_std_n += results[r][ROWS[0][0]].tension_std_n
    if filt.tension_err_n:
        rms = np.sqrt(np.mean(np.square(filt.tension_err_n), axis=0)) * 1e3
        std = np.mean(filt.tension_std_n, axis=0) * 1e3
        lines += [
            "",
            "The tension filter in these runs (every row shares it): error RMS per axis x / y / "
            f"z {rms[0]:.1f} / {rms[1]:.1f} / {rms[2]:.1f} mN, against a reported σ of "
            f"{std[0]:.1f} / {std[1]:.1f} / {std[2]:.1f} mN on average. Every fusion here "
            "weighs the tension by that reported σ.",
        ]
    lines.append("")
    return "\n".join(lines)


def run_table(
    profile: str, radii: tuple[float, ...], seconds: float, seed: int, calibrated: bool
) -> tuple[dict[float, dict[str, Errors]], dict[str, bool] | None]:
    results = {}
    classes: dict[str, bool] | None = None
    for k, r in enumerate(radii):
        results[r], classes = run_spot(profile, r, seconds, seed + k, calibrated)
        print(f"r = {r:g} m: " + ", ".join(f"{row} {_cell(e)}" for row, e in results[r].items()))
    return results, classes


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="4 spots, 4 s, one table; print")
    parser.add_argument("--profile", choices=("realistic", "ideal"), default="realistic")
    parser.add_argument("--seconds", type=float, default=None, help="hover per spot, s")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--out", type=Path, default=None, help="write here (default: docs/)")
    args = parser.parse_args(argv)
    radii = QUICK_R_M if args.quick else SPOTS_R_M
    seconds = args.seconds or (4.0 if args.quick else 6.0)
    t0 = time.monotonic()
    sections = []
    variants: list[tuple[str, bool, str]] = []
    if args.profile == "realistic":
        variants.append(
            ("realistic", True, "Realistic profile, calibrated drone (calibration-type errors off)")
        )
        if not args.quick:
            variants.append(("realistic", False, "Realistic profile, uncalibrated drone"))
    if args.profile == "ideal" or not args.quick:
        variants.append(("ideal", False, "Ideal profile (for comparison)"))
    figures: dict[str, Any] = {}
    for profile, calibrated, title in variants:
        print(title)
        results, classes = run_table(profile, radii, seconds, args.seed, calibrated)
        if profile == "ideal":
            classes = None
        key = (
            profile
            if profile == "ideal"
            else f"{profile}_{'calibrated' if calibrated else 'uncalibrated'}"
        )
        figures[key] = _figures(results)
        section = render_section(title, results, classes)
        if key == "realistic_calibrated":
            section += _quoted(figures[key])
        sections.append(section)
    header = render_header(args.profile, seconds, args.seed, args.quick, time.monotonic() - t0)
    text = "\n".join([header, *sections])
    text += kept_reading(args.out or DOC_PATH, READING_MARK)
    print(text)
    if not args.quick or args.out is not None:
        path = args.out or DOC_PATH
        path.write_text(text, encoding="utf-8")
        print(f"wrote {path}")
        if path.resolve() == DOC_PATH.resolve() == (DOCS / "azimuth_sources.md").resolve():
            write_figures("azimuth_sources", figures)
    return 0


READING_MARK = "\n## Reading the tables"
"""The page's reading, written by hand below the tables from this heading on: kept on a rerun."""


if __name__ == "__main__":
    sys.exit(main())
