"""The envelope on the realistic profile: which error costs how many cm, and what calibration buys.

Section (d) of the results page. Every flight is the ``realistic`` profile of
:mod:`groundstation.sim` (rigid body, lumped-mass tether, 100 Hz IMU; docs/simulator.md), no
motion capture reaches the service, and the service is not told the noise level
(``[drone] accel_noise_mps2`` stays at its 0.3 m/s² default).

**Baseline**: vibration noise 1.0 m/s² per axis (white + coloured, lag-1 0.2) and *every other
error class off* (``[sim.realistic]`` switches), L = 1.6 m, ω = 0.05 N/m known exactly.

**Error classes** (:func:`error_classes`): one at a time on top of the baseline, swept over its
real range (off, half, the figure measured on the real flights, twice that; the
thrust map also at newer firmware's +60 %; the dynamics classes off, real, twice), each value
flown *uncalibrated* (``[calibration]`` at its defaults, ``source = "none"``). Where the
calibration model has parameters for the class (accelerometer misalignment, scale and bias
→ ``accel_bias_mps2``; thrust axis; thrust map and its battery term), the real size (battery:
every size) is flown again with *calibration = truth*: ``[calibration]`` set to the
simulator's drawn errors (their equivalent calibration, as
:func:`benchmarks.bench_realistic._true_calibration` computes it), the best any calibration
can do. Vibration, motor lag, rotor drag, yaw and IMU timing have no calibration parameter
(their truth is the defaults: tests/test_results_envelope.py checks it). Motion-capture
timing acts only on motion-capture frames, which never reach the service here: no row.
``--quick`` flies a few classes at their real size only (:data:`QUICK_CLASSES`).

The flights are :func:`benchmarks.bench_realistic.fly` (the service's pipeline in lock-step
with the simulator), so the rows agree with docs/realistic_benchmark.md's method. A last row
flies every class at once at its real value (the realistic profile's defaults).

**Model sweeps** (:func:`model_sweeps`): ω configured vs true, tether length, distance from
the base, on the same baseline, through :class:`benchmarks.results_sim.SimJob` (the pipeline
can be configured apart from the simulator there, which ω error needs).

Each point pools three of the paper's hover spots (quick: one), 12 s per flight and errors
from 6 s on (quick: 6 s and 3 s), each spot flown with the same
seed for every class and value (the per-flight draws scale with the size, the noise stream
is shared, so a row differs from the baseline by its error and not by luck). The jobs run
on :func:`benchmarks.results_sim.run_jobs`'s process pool beside section (a)'s.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from benchmarks import bench_realistic as br
from benchmarks.results_sim import ErrorTrace, SimJob, hover_scenario
from groundstation.sim import PAPER_HOVER_SPOTS_M

FloatArray = NDArray[np.float64]

PROFILE = "realistic"
BASELINE_NOISE_MPS2 = 1.0
NOMINAL_WEIGHT_N_PER_M = 0.05
TRUST_P95_M = 0.10  # "trust the estimate" when the 95th percentile error is within this
THRUST_AXIS_RAD = (-0.037, -0.016)  # the airframe's thrust axis, as measured
SEED0 = 500

BASELINE: dict[str, Any] = {
    **{c: False for c in br.ALL_CLASSES},
    "vibration": True,
    "accel_noise_mps2": BASELINE_NOISE_MPS2,
}
"""``[sim.realistic]`` of the baseline: vibration 1.0 m/s², every other class off."""


# ---------------------------------------------------------------------------- error classes


@dataclass(frozen=True)
class ErrorClass:
    """One error class of the realistic profile: its sizes and how a size becomes settings.

    Attributes:
        name: identifier (a ``[sim.realistic]`` switch, or ``all``).
        label: what the value is, with its unit.
        values: sizes flown (0: the class off, i.e. the baseline).
        real: the size measured on the real flights, one of ``values``.
        settings: size -> ``[sim.realistic]`` overrides on top of :data:`BASELINE`.
        calibratable: the calibration model has parameters for this class.
        drawn: what the simulator drew per flight for this class, reported beside the size
            (``None``: the size is set exactly).
    """

    name: str
    label: str
    values: tuple[float, ...]
    real: float
    settings: Callable[[float], dict[str, Any]]
    calibratable: bool
    drawn: str | None = None
    baseline: float = 0.0
    calibrate_all: bool = False  # fly calibration = truth at every size, not only the real one


def _vibration(v: float) -> dict[str, Any]:
    # 0: vibration off, only the sensor's own floor noise (0.02 m/s²) remains
    return {"vibration": v > 0.0, "accel_noise_mps2": v if v > 0.0 else BASELINE_NOISE_MPS2}


def _misalignment(v: float) -> dict[str, Any]:
    return {"misalignment": v > 0.0, "misalignment_max_rad": math.radians(v)}


def _accel_scale(v: float) -> dict[str, Any]:
    return {"accel_scale": v > 0.0, "accel_scale_max": v / 100.0}


def _accel_bias(v: float) -> dict[str, Any]:
    return {"accel_bias": v > 0.0, "accel_bias_std_mps2": v}


def _thrust_axis(v: float) -> dict[str, Any]:
    return {
        "thrust_axis": v > 0.0,
        "thrust_axis_rad": (v * THRUST_AXIS_RAD[0], v * THRUST_AXIS_RAD[1]),
    }


def _thrust_map(v: float) -> dict[str, Any]:
    # battery off: the voltage stays at thrust_vbat_ref_v, so reported/true is exactly 1 + e
    return {
        "thrust_map": v != 0.0,
        "thrust_report_error": v / 100.0,
        "thrust_report_error_std": 0.0,
    }


def _battery(v: float) -> dict[str, Any]:
    # the map's drift alone: a map exact at V_ref (e = 0) read through a sagging battery
    if v <= 0.0:
        return {}
    return {
        "thrust_map": True,
        "thrust_report_error": 0.0,
        "thrust_report_error_std": 0.0,
        "battery": True,
        "battery_soc_start": v,
    }


def _motor_lag(v: float) -> dict[str, Any]:
    return {"motor_lag": v > 0.0, "motor_tau_s": v / 1000.0}


def _rotor_drag(v: float) -> dict[str, Any]:
    return {"rotor_drag": v > 0.0, "rotor_drag_n_s_per_m": v / 1000.0}


def _yaw(v: float) -> dict[str, Any]:
    return {"yaw_motion": v > 0.0, "yaw_amplitude_rad": v}


def _imu_timing(v: float) -> dict[str, Any]:
    return {"imu_timing": v > 0.0, "imu_jitter_std_s": 0.0015 * v, "imu_late_prob": 0.05 * v}


def _all(v: float) -> dict[str, Any]:
    # every class on at the realistic profile's defaults (the real flights' figures)
    return {c: True for c in br.ALL_CLASSES} if v > 0.0 else {}


DYNAMICS_CLASSES = ("motor_lag", "rotor_drag", "yaw_motion", "imu_timing")
QUICK_CLASSES = ("vibration", "misalignment", "thrust_map", "motor_lag", "all")


def error_classes(quick: bool) -> tuple[ErrorClass, ...]:
    """The classes and their sizes (quick: a few classes at their real size only)."""
    full = (
        ErrorClass(
            "vibration",
            "vibration noise σ at hover (m/s² per axis)",
            (0.0, 0.5, 1.0, 2.0),
            1.0,
            _vibration,
            False,
            baseline=BASELINE_NOISE_MPS2,
        ),
        ErrorClass(
            "misalignment",
            "accelerometer misalignment, per-boot max (deg)",
            (0.0, 1.5, 3.0, 6.0),
            3.0,
            _misalignment,
            True,
            "misalignment_deg",
        ),
        ErrorClass(
            "accel_scale",
            "accelerometer scale error, per-boot max (%)",
            (0.0, 1.25, 2.5, 5.0),
            2.5,
            _accel_scale,
            True,
            "accel_scale_pct",
        ),
        ErrorClass(
            "accel_bias",
            "accelerometer bias, per-boot std per axis (m/s²)",
            (0.0, 0.025, 0.05, 0.1),
            0.05,
            _accel_bias,
            True,
            "accel_bias_mps2",
        ),
        ErrorClass(
            "thrust_axis",
            "thrust axis offset (× the airframe's (−0.037, −0.016) rad = 2.3°)",
            (0.0, 0.5, 1.0, 2.0),
            1.0,
            _thrust_axis,
            True,
        ),
        ErrorClass(
            "thrust_map",
            "thrust map error, reported/true − 1 (%)",
            (0.0, -4.5, -9.1, 60.0),
            -9.1,
            _thrust_map,
            True,
        ),
        ErrorClass(
            "battery",
            "battery drift of the thrust map: state of charge at take-off (0: no battery model)",
            (0.0, 1.0, 0.6, 0.3),
            1.0,
            _battery,
            True,
            "hover_vbat_v",
            calibrate_all=True,
        ),
        ErrorClass("motor_lag", "motor lag τ (ms)", (0.0, 30.0, 60.0), 30.0, _motor_lag, False),
        ErrorClass(
            "rotor_drag", "rotor drag (mN per m/s)", (0.0, 7.3, 14.6), 7.3, _rotor_drag, False
        ),
        ErrorClass(
            "yaw_motion",
            "yaw: random start ±π + swing of this amplitude (rad)",
            (0.0, 0.3, 0.6),
            0.3,
            _yaw,
            False,
        ),
        ErrorClass(
            "imu_timing",
            "IMU timing jitter (× the real 1.5 ms std, 5 % late up to 27 ms)",
            (0.0, 1.0, 2.0),
            1.0,
            _imu_timing,
            False,
        ),
        ErrorClass(
            "all",
            "every class at its real size (the realistic profile's defaults)",
            (0.0, 1.0),
            1.0,
            _all,
            True,
        ),
    )
    if not quick:
        return full
    # quick (CI): the real size of a few classes, enough to exercise every path
    return tuple(
        ErrorClass(
            c.name,
            c.label,
            (c.baseline,) if c.real == c.baseline else (c.baseline, c.real),
            c.real,
            c.settings,
            c.calibratable,
            c.drawn,
            c.baseline,
            c.calibrate_all,
        )
        for c in full
        if c.name in QUICK_CLASSES
    )


_SIZE_TEXT: dict[str, Callable[[float], str]] = {
    "vibration": lambda v: f"σ {v:g} m/s²" if v else "off (sensor floor 0.02 m/s²)",
    "misalignment": lambda v: f"≤ {v:g}°",
    "accel_scale": lambda v: f"≤ {v:g} %",
    "accel_bias": lambda v: f"σ {v:g} m/s² per axis",
    "thrust_axis": lambda v: f"{v:g} × 2.3°",
    "thrust_map": lambda v: f"{v:+g} %".replace("-", "−"),
    "battery": lambda v: f"{100 * v:.0f} % charge",
    "motor_lag": lambda v: f"τ {v:g} ms",
    "rotor_drag": lambda v: f"{v:g} mN per m/s",
    "yaw_motion": lambda v: f"swing ±{v:g} rad",
    "imu_timing": lambda v: f"{v:g} × the real jitter",
    "all": lambda v: "every class at its real size",
}


def size_text(cls: ErrorClass, value: float) -> str:
    """A size as the tables print it, with its unit ('off' for a class switched off)."""
    if value == 0.0 and cls.name != "vibration":
        return "off"
    return _SIZE_TEXT[cls.name](value)


def is_baseline(cls: ErrorClass, value: float) -> bool:
    """Whether ``value`` of ``cls`` flies the baseline (one set of flights shared by all)."""
    return value == cls.baseline


# ---------------------------------------------------------------------------- model sweeps


@dataclass(frozen=True)
class Sweep:
    """One model factor (ω error, tether length, distance) on the realistic baseline."""

    name: str
    label: str  # axis label with unit
    values: tuple[float, ...]
    nominal: float
    settings: Callable[[float], dict[str, Any]]
    by_distance: bool = False


def _omega(v: float) -> dict[str, Any]:
    return {"pipeline": {"tether": {"weight_n_per_m": NOMINAL_WEIGHT_N_PER_M * (1 + v / 100)}}}


def _length(v: float) -> dict[str, Any]:
    return {"shared": {"tether": {"length_m": v}}}


def _distance(v: float) -> dict[str, Any]:
    return {}


def model_sweeps(quick: bool) -> tuple[Sweep, ...]:
    if quick:
        return (
            Sweep("omega_error", "ω configured vs true (%)", (0.0, 10.0), 0.0, _omega),
            Sweep("length", "tether length L (m)", (1.6, 3.0), 1.6, _length),
            Sweep(
                "distance",
                "horizontal distance from the base r (m)",
                (0.0,),
                1.0,
                _distance,
                by_distance=True,
            ),
        )
    return (
        Sweep(
            "omega_error",
            "ω configured vs true (%)",
            (-10.0, -5.0, 0.0, 5.0, 10.0),
            0.0,
            _omega,
        ),
        Sweep("length", "tether length L (m)", (1.6, 2.0, 2.5, 3.0), 1.6, _length),
        Sweep(
            "distance",
            "horizontal distance from the base r (m)",
            (0.0, 0.3, 0.6, 1.0),
            1.0,
            _distance,
            by_distance=True,
        ),
    )


# ---------------------------------------------------------------------------- the plan


@dataclass(frozen=True)
class EnvelopePlan:
    quick: bool
    seconds: float
    steady_from_s: float
    spots: tuple[int, ...]  # which of the paper's spots (indices) each point flies
    azimuths: int  # distance sweep: azimuths per point


def plan(quick: bool) -> EnvelopePlan:
    if quick:
        return EnvelopePlan(True, 6.0, 3.0, (0,), 1)
    # The far spot, the low one and the near-plumb one: three geometries.
    return EnvelopePlan(False, 12.0, 6.0, (0, 3, 4), 2)


@dataclass(frozen=True)
class FlightErrors:
    """What a point needs from one flight, per telemetry sample with an estimate (n)."""

    key: str
    t_s: FloatArray  # (n,)
    pos_error_m: FloatArray  # (n,) 3D, NaN where no position was published
    pos_error_h_m: FloatArray  # (n,) horizontal
    pos_error_z_m: FloatArray  # (n,) estimate − truth
    tension_error_n: FloatArray  # (n,) |T_est − T_true|
    drawn: Mapping[str, float] = field(default_factory=dict)  # the flight's drawn sizes


def drawn_sizes(errors: Mapping[str, Any]) -> dict[str, float]:
    """The per-flight sizes the simulator drew (``Truth.errors``), for the table."""
    return {
        "misalignment_deg": math.degrees(math.hypot(*errors["misalignment_rad"])),
        "accel_scale_pct": 100.0 * abs(float(errors["accel_scale_error"])),
        "accel_bias_mps2": float(np.linalg.norm(errors["accel_bias_mps2"])),
        "hover_vbat_v": float(errors["hover_vbat_v"]),
        # reported / true thrust at the first hover voltage, (1 + e)·(V_ref/V)^γ
        "thrust_report_factor": float(
            (1.0 + errors["thrust_report_error"])
            * (errors["thrust_vbat_ref_v"] / errors["hover_vbat_v"])
            ** errors["thrust_vbat_exponent"]
        ),
    }


@dataclass(frozen=True)
class ClassJob:
    """One flight of an error class; picklable, so
    :func:`benchmarks.results_sim.run_jobs` runs it on a worker (through :meth:`run`)."""

    key: str
    spot: int  # index into the paper's hover spots
    seconds: float
    seed: int
    realistic: Mapping[str, Any]  # the flight's [sim.realistic] (switches and sizes)
    calibrated: bool  # [calibration] = the simulator's truth, else the defaults
    want_drawn: bool = False  # also report the drawn sizes (one more simulator start-up)

    def run(self) -> FlightErrors:
        classes = dict(self.realistic)
        noise = float(classes.pop("accel_noise_mps2"))
        f = br.fly(
            br._scenario_for_spot(self.spot),
            self.seconds,
            noise,
            self.seed,
            classes=classes,
            calibrated=self.calibrated,
        )
        drawn: dict[str, float] = {}
        if self.want_drawn:
            settings = br._settings(noise, self.seed, classes, None)
            errors = br.Simulator(settings, br._NullBus(), "hover").drawn_errors(br.DRONE)  # type: ignore[arg-type]
            assert errors is not None
            drawn = drawn_sizes(errors)
        d = f.est_pos_m - f.true_pos_m
        return FlightErrors(
            key=self.key,
            t_s=f.t_s,
            pos_error_m=np.linalg.norm(d, axis=1),
            pos_error_h_m=np.hypot(d[:, 0], d[:, 1]),
            pos_error_z_m=d[:, 2],
            tension_error_n=np.linalg.norm(f.est_tension_n - f.true_tension_n, axis=1),
            drawn=drawn,
        )


def _seed(spot: int) -> int:
    return SEED0 + spot


def class_key(cls: ErrorClass, value: float, calibrated: bool) -> str:
    """Results key prefix of a point's flights (the baseline's flights are shared)."""
    tag = "cal" if calibrated else "raw"
    return f"envr/baseline/{tag}" if is_baseline(cls, value) else f"envr/{cls.name}/{value:g}/{tag}"


def jobs(p: EnvelopePlan) -> list[ClassJob | SimJob]:
    """Every flight of the section: :class:`ClassJob` per error class and value, and
    :class:`~benchmarks.results_sim.SimJob` for the model sweeps."""
    out: dict[str, ClassJob | SimJob] = {}
    for cls in error_classes(p.quick):
        for v in cls.values:
            # calibration = truth at the real size (at the baseline the truth is the
            # calibration's defaults: nothing to calibrate)
            at = cls.values if cls.calibrate_all else (cls.real,)
            with_cal = cls.calibratable and v in at and not is_baseline(cls, v)
            cals = (False, True) if with_cal else (False,)
            for cal in cals:
                for spot in p.spots:
                    k = f"{class_key(cls, v, cal)}/{spot}"
                    out[k] = ClassJob(
                        k,
                        spot,
                        p.seconds,
                        _seed(spot),
                        {**BASELINE, **cls.settings(v)},
                        cal,
                        want_drawn=not cal and cls.drawn is not None,
                    )
    base_sim = {"profile": PROFILE, "mocap": False, "realistic": dict(BASELINE)}
    for sw in model_sweeps(p.quick):
        for vi, v in enumerate(sw.values):
            if v == sw.nominal and not sw.by_distance:
                continue  # the baseline's flights
            extra = sw.settings(v)
            if sw.by_distance:
                runs = []
                for a in range(p.azimuths):
                    az = 2.0 * math.pi * a / p.azimuths + 0.3
                    pos = (round(v * math.cos(az), 6), round(v * math.sin(az), 6), 1.0)
                    runs.append(
                        (a, SEED0 + 37 * (vi + 1) + a, hover_scenario(f"env_r{vi}_{a}", pos))
                    )
            else:
                runs = [
                    (s, _seed(s), hover_scenario(f"bench_hover_{s}", PAPER_HOVER_SPOTS_M[s]))
                    for s in p.spots
                ]
            for k, seed, sc in runs:
                key = f"envm/{sw.name}/{vi}/{k}"
                out[key] = SimJob(
                    key=key,
                    scenario=sc,
                    seconds=p.seconds,
                    sim={**base_sim, "seed": seed},
                    shared=extra.get("shared", {}),
                    pipeline=extra.get("pipeline"),
                    reduce="error",
                )
    return list(out.values())


# ---------------------------------------------------------------------------- summaries


@dataclass(frozen=True)
class Stats:
    """Errors pooled over a point's flights from ``steady_from_s`` on."""

    median_m: float  # 3D position error
    p95_m: float
    horizontal_median_m: float
    vertical_median_m: float  # median |Δz|
    tension_median_n: float  # |T_est − T_true|
    tension_p95_n: float
    availability: float  # share of samples with a position


def _stats(runs: list[FlightErrors] | list[ErrorTrace], steady_from_s: float) -> Stats:
    e, h, z, t, avail = [], [], [], [], []
    for tr in runs:
        m = tr.t_s >= steady_from_s
        pe = tr.pos_error_m[m]
        ok = np.isfinite(pe)
        e.append(pe[ok])
        h.append(tr.pos_error_h_m[m][ok])
        z.append(np.abs(tr.pos_error_z_m[m][ok]))
        t.append(tr.tension_error_n[m])
        avail.append(float(ok.mean()) if ok.size else 0.0)

    def q(parts: list[FloatArray], pct: float) -> float:
        a = np.concatenate(parts) if parts else np.zeros(0)
        return float(np.percentile(a, pct)) if a.size else math.inf

    return Stats(
        median_m=q(e, 50),
        p95_m=q(e, 95),
        horizontal_median_m=q(h, 50),
        vertical_median_m=q(z, 50),
        tension_median_n=q(t, 50),
        tension_p95_n=q(t, 95),
        availability=float(np.mean(avail)) if avail else 0.0,
    )


@dataclass(frozen=True)
class ClassPoint:
    value: float
    raw: Stats  # uncalibrated
    cal: Stats | None  # calibration = truth; None: not flown (see ``jobs``)
    drawn: Mapping[str, float]  # the drawn sizes, mean over the flights


@dataclass(frozen=True)
class ClassResult:
    cls: ErrorClass
    points: tuple[ClassPoint, ...]

    def at(self, value: float) -> ClassPoint:
        return next(p for p in self.points if p.value == value)

    @property
    def real(self) -> ClassPoint:
        return self.at(self.cls.real)


@dataclass(frozen=True)
class Point:
    value: float
    stats: Stats
    azimuth_determined: float  # share of samples
    floor_contact: float  # share of samples with the tether on the floor (truth)


@dataclass(frozen=True)
class SweepResult:
    sweep: Sweep
    points: tuple[Point, ...]

    def trusted_range(self) -> tuple[float, float] | None:
        """The contiguous range of values around the nominal with p95 ≤ TRUST_P95_M."""
        vals = [pt.value for pt in self.points]
        ok = [pt.stats.p95_m <= TRUST_P95_M and pt.stats.availability > 0.5 for pt in self.points]
        if self.sweep.nominal not in vals:
            return None
        i = vals.index(self.sweep.nominal)
        if not ok[i]:
            return None
        lo = hi = i
        while lo > 0 and ok[lo - 1]:
            lo -= 1
        while hi < len(vals) - 1 and ok[hi + 1]:
            hi += 1
        return vals[lo], vals[hi]


@dataclass(frozen=True)
class EnvelopeResult:
    plan: EnvelopePlan
    classes: tuple[ClassResult, ...]
    sweeps: tuple[SweepResult, ...]

    def cls(self, name: str) -> ClassResult:
        return next(c for c in self.classes if c.cls.name == name)

    def sweep(self, name: str) -> SweepResult:
        return next(s for s in self.sweeps if s.sweep.name == name)


def _runs(results: Mapping[str, Any], prefix: str) -> list[Any]:
    return [results[k] for k in sorted(results) if k.startswith(prefix + "/")]


def summarize(results: Mapping[str, Any], p: EnvelopePlan) -> EnvelopeResult:
    classes = []
    for cls in error_classes(p.quick):
        points = []
        for v in cls.values:
            raw = _runs(results, class_key(cls, v, False))
            cal_runs = _runs(results, class_key(cls, v, True))
            drawn_keys = sorted({k for r in raw for k in r.drawn})
            raw_stats = _stats(raw, p.steady_from_s)
            if cal_runs:
                cal: Stats | None = _stats(cal_runs, p.steady_from_s)
            elif cls.calibratable and is_baseline(cls, v):
                cal = raw_stats  # the baseline's truth is the defaults: the same flights
            else:
                cal = None  # not flown (no calibration parameter, or not the real size)
            points.append(
                ClassPoint(
                    v,
                    raw_stats,
                    cal,
                    {k: float(np.mean([r.drawn[k] for r in raw])) for k in drawn_keys},
                )
            )
        classes.append(ClassResult(cls, tuple(points)))
    base_raw = _runs(results, "envr/baseline/raw")
    sweeps = []
    for sw in model_sweeps(p.quick):
        points = []
        for vi, v in enumerate(sw.values):
            runs = _runs(results, f"envm/{sw.name}/{vi}")
            if not runs:  # the nominal of ω and L: the baseline's flights
                points.append(Point(v, _stats(base_raw, p.steady_from_s), math.nan, math.nan))
                continue
            m = [r.t_s >= p.steady_from_s for r in runs]
            points.append(
                Point(
                    v,
                    _stats(runs, p.steady_from_s),
                    float(
                        np.mean(
                            [r.azimuth_determined[k].mean() for r, k in zip(runs, m, strict=True)]
                        )
                    ),
                    float(
                        np.mean([r.floor_contact[k].mean() for r, k in zip(runs, m, strict=True)])
                    ),
                )
            )
        sweeps.append(SweepResult(sw, tuple(points)))
    return EnvelopeResult(p, tuple(classes), tuple(sweeps))
