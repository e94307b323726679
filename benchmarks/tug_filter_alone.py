"""The realistic simulator's 30 mN tug with the tension filter alone (a diagnosis, no page).

``python -m benchmarks.tug_filter_alone [--levels 1.0,2.0] [--seeds 8]``

The tug of ``benchmarks.bench_realistic`` (the same flights: seeds 300 on, 0.8-2 m/s^2 of
vibration, a 30 mN pull from 10 s for 5 s), served with the slow stage off: the
calibration is the simulator's full-model truth (``bench_realistic._true_full_calibration``:
the accelerometer's bias exact at the hover, ``accel_slow = false``), so no thrust balance
enters the filter (it needs the slow stage's hover test) and the tension filter's change
test and drift adaptation alone take the pull in. That is the regime of a lab that serves
with ``[calibration] accel_slow = false`` (a motion-capture attitude, docs/attitude_source.md)
or of a drone that does not hover. Prints, per level, what ``bench_realistic`` reports for
its tug: the t90 of the seed-averaged change along the pull, the median settle, the
detections per seed and the first detection's delay.

Takes ~2 min per level. It imports only ``benchmarks.bench_realistic``, so run from an older
checkout's root (``PYTHONPATH=. python <this file>``) it measures that checkout: a
before/after.
"""

from __future__ import annotations

import argparse

from benchmarks import bench_realistic as br


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", default="1.0,2.0", help="vibration levels, m/s^2 (1.0,2.0)")
    ap.add_argument("--seeds", type=int, default=8, help="seeds from 300 (8, as the page)")
    args = ap.parse_args(argv)
    br._true_calibration = br._true_full_calibration  # type: ignore[assignment]
    seeds = list(range(300, 300 + args.seeds))
    print("| noise | t90 | settle | detected | first detection per seed |")
    print("| --- | --- | --- | --- | --- |")
    for level in (float(x) for x in args.levels.split(",")):
        g = br.tug(level, seeds)
        first = ", ".join("-" if x is None else f"{x:.2f}" for x in g["first_detection_s"])
        print(
            f"| {level:g} m/s^2 | {br._s(g['t90_s'])} | {br._s(g['settle_median_s'])} | "
            f"{sum(x is not None for x in g['first_detection_s'])} of {len(seeds)} "
            f"| {first} |",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
