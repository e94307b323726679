"""NanoBench served live: router, serve, record and ``replay --speed 2`` as separate processes.

The procedure of :mod:`benchmarks.nanobench_cli` (the same recordings, the same
``calibrate --untethered`` per held-out day, the same per-flight measure), with the held-out
flight served the way a lab serves it instead of by ``replay --offline``: a ``groundstation
router`` on a free port of 127.0.0.1, ``groundstation serve --headless`` with the calibration,
``groundstation record`` of the bus, and ``groundstation replay --speed 2`` of the recording
without motion capture, each its own process over TCP. Beside each flight, the offline
result on the same calibration: the live service must answer as the offline pipeline does
(one Estimate per Telemetry, the same estimates up to the order messages arrive in).

Run:  python -m benchmarks.nanobench_live [--speed 2] [--flights NAME,...] [--data DIR] \
        > docs/nanobench_live.md
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.figures import AT_START, DOCS, write_figures
from benchmarks.nanobench_cli import DATA, DAYS, Judged, calibrate, check_data, judge, load, score
from benchmarks.service_rig import free_port

GS = [sys.executable, "-m", "groundstation"]


def _start(args: list[str], log: Path) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [*GS, *args],
        stdout=log.open("wb"),
        stderr=subprocess.STDOUT,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )


def _wait_text(log: Path, needle: str, proc: subprocess.Popen[bytes], timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if needle in log.read_text(errors="replace"):
            return
        if proc.poll() is not None:
            break
        time.sleep(0.1)
    raise RuntimeError(f"{log.name}: no {needle!r} within {timeout_s:.0f} s:\n{log.read_text()}")


def _stop(proc: subprocess.Popen[bytes], timeout_s: float = 10.0) -> int:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
    try:
        return proc.wait(timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.wait()


def serve_live(flight_name: str, nomocap: Path, config: Path, work: Path, speed: float) -> Path:
    """Serve one recording through separate processes; the recorded bus's path."""
    ep = f"tcp/127.0.0.1:{free_port()}"
    out = work / f"{flight_name}-live.mcap"
    logs = {n: work / f"{flight_name}-{n}.log" for n in ("router", "serve", "record", "replay")}
    router = _start(["router", "--listen", ep], logs["router"])
    procs = [router]
    try:
        _wait_text(logs["router"], "listening", router, 30)
        serve = _start(
            ["serve", "--headless", "--config", str(config), "--connect", ep], logs["serve"]
        )
        record = _start(["record", "--connect", ep, "--out", str(out)], logs["record"])
        procs += [serve, record]
        _wait_text(logs["record"], "recording ", record, 60)
        _wait_text(logs["serve"], "tether/", serve, 60)
        time.sleep(1.0)  # the service's subscriptions reach the router
        rc = subprocess.run(
            [*GS, "replay", str(nomocap), "--speed", f"{speed:g}", "--connect", ep],
            stdout=logs["replay"].open("wb"),
            stderr=subprocess.STDOUT,
            check=False,
        ).returncode
        if rc != 0:
            raise RuntimeError(f"replay exited {rc}:\n{logs['replay'].read_text()}")
        time.sleep(2.0)  # the last estimates reach the recorder
    finally:
        for p in reversed(procs):
            _stop(p)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--speed", type=float, default=2.0, help="replay speed (2)")
    ap.add_argument("--flights", help="held-out flights, comma-separated (all six)")
    ap.add_argument(
        "--out", help="write the markdown page here (docs/nanobench_live.md: and its figures)"
    )
    ap.add_argument(
        "--data",
        type=Path,
        default=DATA,
        help="the directory of the NanoBench CSV files (default: ../shared/data/nanobench "
        "beside the repository)",
    )
    args = ap.parse_args(argv)
    check_data(ap, args.data)
    names = list(DAYS) if args.flights is None else args.flights.split(",")
    unknown = [n for n in names if n not in DAYS]
    if unknown:
        ap.error(f"--flights: unknown {unknown}; choose from {list(DAYS)}")
    t0 = time.time()
    rows: list[tuple[str, Judged, Judged]] = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        flights = {n: load(n, args.data) for n in DAYS}
        for day in sorted({DAYS[n] for n in names}):
            train = [flights[n] for n in DAYS if DAYS[n] != day]
            cal, _ = calibrate(train, work, f"day-{day}", [])
            for n in (m for m in names if DAYS[m] == day):
                offline = judge(flights[n], cal, work)  # also writes the recording served
                live_mcap = serve_live(n, work / f"{n}-nomocap.mcap", cal, work, args.speed)
                live = score(flights[n], live_mcap)
                rows.append((day, offline, live))
                print(
                    f"{n}: live {live.median_abs_t_mn:.1f} mN, answered "
                    f"{100 * live.answered:.1f} %, airborne "
                    f"{100 * live.airborne_not_on_ground:.1f} %; "
                    f"offline {offline.median_abs_t_mn:.1f} mN",
                    file=sys.stderr,
                    flush=True,
                )
    meds = sorted(r[2].median_abs_t_mn for r in rows)
    mid = len(meds) // 2
    median = meds[mid] if len(meds) % 2 else 0.5 * (meds[mid - 1] + meds[mid])
    lines = [
        "# NanoBench served live (real untethered flights, separate processes)",
        "",
        f"`python -m benchmarks.nanobench_live --speed {args.speed:g} --out "
        f"docs/nanobench_live.md` (this page and its figures, docs/nanobench_live.json; "
        f"{time.time() - t0:.0f} s at commit {AT_START.commit}; data: "
        "../shared/data/nanobench): router + serve --headless + record + replay as separate "
        "processes over TCP on 127.0.0.1; calibration per held-out day as in "
        "docs/nanobench_cli.md (airframe + slow accelerometer, the default, with its "
        "configuration's motor-voltage battery model).",
        "",
        "| held-out day | flight | live median abs T mN | answered | airborne | offline mN |",
        "| --- | --- | ---: | ---: | ---: | ---: |",
    ]
    for day, off, live in rows:
        lines.append(
            f"| {day} | {live.flight} | {live.median_abs_t_mn:.1f} | {100 * live.answered:.1f} % "
            f"| {100 * live.airborne_not_on_ground:.1f} % | {off.median_abs_t_mn:.1f} |"
        )
    lines += [
        "",
        f"Live: median over flights {median:.1f}<!-- fig nanobench_live.json median_mn --> mN, "
        f"worst {max(meds):.1f}<!-- fig nanobench_live.json worst_mn -->.",
        "",
        "Answered: Estimates recorded per Telemetry served; airborne: airborne rows (motors "
        "on, Vicon z > 0.25 m) with an Estimate not `on_ground`; offline: `replay --offline` "
        "on the same recording and calibration (docs/nanobench_cli.md's measure).",
    ]
    page = "\n".join(lines) + "\n"
    sys.stdout.write(page)
    if args.out:
        Path(args.out).write_text(page, encoding="utf-8")
        if Path(args.out).resolve() == DOCS / "nanobench_live.md" and args.flights is None:
            figures = {
                "median_mn": median,
                "worst_mn": max(meds),
                "flights": [
                    [
                        day,
                        live.flight,
                        live.median_abs_t_mn,
                        off.median_abs_t_mn,
                        live.answered,
                        live.airborne_not_on_ground,
                    ]
                    for day, off, live in rows
                ],
            }
            write_figures(
                "nanobench_live", figures, ["--speed", f"{args.speed:g}", "--out", args.out]
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
