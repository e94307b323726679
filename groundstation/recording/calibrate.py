"""``groundstation calibrate``: fit the calibration from recordings with motion capture (an edge).

Reads recordings made by ``groundstation record``, turns each drone's Telemetry (with the
motion-capture ``position_m``), Reel and tether-parameter messages into arrays, calls the
pure fit (:func:`groundstation.calibration.fit_calibration`), prints the result and writes a
configuration file: the input configuration plus ``[drones.<id>.calibration]`` tables
(comment lines say when and from what), which ``groundstation serve --config`` accepts as it
is. Nothing is written when any input is unusable; the error names the file and what is
missing.
"""

from __future__ import annotations

import math
import re
import tomllib
from collections import Counter, defaultdict
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from groundstation import messages
from groundstation.airframe import AirframeFit, fit_airframe
from groundstation.calibration import (
    CalibrationData,
    CalibrationError,
    CalibrationFit,
    RestCalibrator,
    fit_calibration,
    hover_mask,
)
from groundstation.config import CalibrationSection, ConfigError, Settings, load_settings
from groundstation.estimator.drone import calibration_from_config, slow_accel_params
from groundstation.hover_fit import (
    HOVER_FIT_MIN_S,
    balance_world_n,
    bridged_velocity,
    fit_flight,
    fit_hover_balance,
    fit_hover_velocity,
    flight_phases,
)
from groundstation.outputs import NewFile, OutputError, check_output
from groundstation.recording.format import RecordingError
from groundstation.recording.reader import iter_messages

__all__ = [
    "CalibrateInputError",
    "DroneCalibration",
    "DroneRecording",
    "format_fit",
    "read_recordings",
    "run_calibrate",
    "toml_dumps",
]

MIN_HOVER_S = 3.0
"""Steady hover under motion capture each recording must hold, s."""

MIN_REST_COVERAGE = 0.9
"""Share of the hover samples that must carry a rest offset for the fit to leave the x/y
bias to the rest calibration (and fit the thrust axis on top of the rest offsets)."""


class CalibrateInputError(RecordingError):
    """A recording cannot be calibrated from; the message names the file and what is missing."""


@dataclass
class _Columns:
    stamp_s: list[float] = field(default_factory=list)
    accel: list[tuple[float, float, float]] = field(default_factory=list)
    quat: list[tuple[float, float, float, float]] = field(default_factory=list)
    thrust: list[float] = field(default_factory=list)
    armed: list[bool] = field(default_factory=list)
    position: list[tuple[float, float, float]] = field(default_factory=list)
    gyro: list[tuple[float, float, float]] = field(default_factory=list)
    vbat: list[float] = field(default_factory=list)
    length: list[float] = field(default_factory=list)
    base: list[tuple[float, float, float]] = field(default_factory=list)
    weight: list[float] = field(default_factory=list)
    with_mocap: int = 0
    base_from_reel: bool = False
    tether_messages: int = 0
    """Reel and tether-parameter messages of this drone: a tether was attached."""
    attitude_sources: Counter[messages.AttitudeSource] = field(default_factory=Counter)
    """Telemetry per attitude source (its ``attitude_source``, else ``[drone]``'s)."""


@dataclass(frozen=True)
class DroneRecording:
    """One drone's samples from one or more recordings."""

    drone: str
    data: CalibrationData
    files: tuple[str, ...]
    weight_n_per_m: float
    base_from_reel: bool
    invalid: int
    tether_messages: tuple[int, ...] = ()
    """Per file (as ``files``): reel and tether-parameter messages of this drone."""
    segments: tuple[int, ...] = ()
    """``data.segment`` of each of :attr:`files`, in order (the file's index on the command
    line); empty: 0, 1, 2, ..."""
    attitude_source: messages.AttitudeSource = "onboard"
    """The attitude every Telemetry was recorded with (mixed sources are refused)."""


_NAN3 = (math.nan, math.nan, math.nan)


def _read_file(path: Path, settings: Settings) -> tuple[dict[str, _Columns], int]:
    """Per-drone columns of one recording, and the count of invalid messages skipped."""
    cols: dict[str, _Columns] = {}
    tether: dict[str, tuple[float, tuple[float, float, float]]] = {}
    weight: dict[str, float] = {}
    invalid = 0
    for rec in iter_messages(path, require_messages=True):
        try:
            drone, kind = messages.parse_key(rec.key)
        except messages.InvalidMessage:
            continue
        try:
            if kind in ("reel", "params"):
                cols.setdefault(drone, _Columns()).tether_messages += 1
            if kind == "telemetry":
                tel = messages.Telemetry.parse(rec.payload)
            elif kind == "reel":
                reel = messages.Reel.parse(rec.payload)
                prev = tether.get(drone)
                base = reel.base_m if reel.base_m is not None else None
                if prev is None:
                    params = settings.for_drone(drone)
                    prev = (params.tether.length_m, params.base.position_m)
                tether[drone] = (reel.length_m, base if base is not None else prev[1])
                if base is not None:
                    cols.setdefault(drone, _Columns()).base_from_reel = True
                continue
            elif kind == "params":
                tp = messages.TetherParams.parse(rec.payload)
                if tp.weight_n_per_m is not None:
                    weight[drone] = tp.weight_n_per_m
                continue
            else:
                continue
        except messages.InvalidMessage:
            invalid += 1
            continue
        c = cols.setdefault(drone, _Columns())
        if drone not in tether:
            params = settings.for_drone(drone)
            tether[drone] = (params.tether.length_m, params.base.position_m)
        if drone not in weight:
            weight[drone] = settings.for_drone(drone).tether.weight_n_per_m
        length, base = tether[drone]
        c.attitude_sources[
            tel.attitude_source or settings.for_drone(drone).drone.attitude_source
        ] += 1
        c.stamp_s.append(tel.stamp_s)
        c.accel.append(tel.accel_mps2)
        c.quat.append(tel.quat_wxyz)
        c.thrust.append(tel.thrust_n)
        c.armed.append(tel.armed)
        c.position.append(tel.position_m if tel.position_m is not None else _NAN3)
        c.with_mocap += tel.position_m is not None
        c.gyro.append(tel.gyro_rps if tel.gyro_rps is not None else _NAN3)
        c.vbat.append(tel.vbat_v if tel.vbat_v is not None else math.nan)
        c.length.append(length)
        c.base.append(base)
        c.weight.append(weight[drone])
    return cols, invalid


def read_recordings(
    paths: Sequence[str | Path], settings: Settings, drone: str | None = None
) -> dict[str, DroneRecording]:
    """Each drone's samples from the recordings (one segment per file).

    Raises:
        CalibrateInputError: a file without telemetry, without the requested drone, or
            whose telemetry carries no motion-capture ``position_m``.
        RecordingError: a file that cannot be read.
    """
    per_drone: dict[str, list[tuple[int, str, _Columns]]] = defaultdict(list)
    invalid: dict[str, int] = defaultdict(int)
    for index, raw in enumerate(paths):
        path = Path(raw)
        if not path.is_file():
            raise CalibrateInputError(f"{str(path)!r}: no such file")
        cols, bad = _read_file(path, settings)
        cols = {d: c for d, c in cols.items() if c.stamp_s}
        if not cols:
            raise CalibrateInputError(f"{str(path)!r}: no telemetry in the recording")
        if drone is not None:
            if drone not in cols:
                raise CalibrateInputError(
                    f"{str(path)!r}: no telemetry from drone {drone!r} "
                    f"(drones in it: {', '.join(sorted(cols))})"
                )
            cols = {drone: cols[drone]}
        for d, c in cols.items():
            if c.with_mocap == 0:
                others = sorted(o for o in cols if o != d)
                raise CalibrateInputError(
                    f"{str(path)!r}: drone {d!r} has no motion capture "
                    "(no Telemetry carries position_m)"
                    + (f"; --drone ID calibrates one of {', '.join(others)}" if others else "")
                )
            per_drone[d].append((index, str(path), c))
            invalid[d] += bad
    out: dict[str, DroneRecording] = {}
    for d, parts in per_drone.items():
        source = _one_attitude_source(d, parts)
        arrays: dict[str, list[np.ndarray]] = defaultdict(list)
        for index, _, c in parts:
            n = len(c.stamp_s)
            arrays["stamp_s"].append(np.asarray(c.stamp_s, float))
            arrays["accel"].append(np.asarray(c.accel, float).reshape(n, 3))
            arrays["quat"].append(np.asarray(c.quat, float).reshape(n, 4))
            arrays["thrust"].append(np.asarray(c.thrust, float))
            arrays["armed"].append(np.asarray(c.armed, bool))
            arrays["position"].append(np.asarray(c.position, float).reshape(n, 3))
            arrays["gyro"].append(np.asarray(c.gyro, float).reshape(n, 3))
            arrays["vbat"].append(np.asarray(c.vbat, float))
            arrays["length"].append(np.asarray(c.length, float))
            arrays["base"].append(np.asarray(c.base, float).reshape(n, 3))
            arrays["segment"].append(np.full(n, index, np.int64))
            arrays["weight"].append(np.asarray(c.weight, float))
        cat = {k: np.concatenate(v) for k, v in arrays.items()}
        data = CalibrationData.from_arrays(
            cat["stamp_s"],
            cat["accel"],
            cat["quat"],
            cat["thrust"],
            armed=cat["armed"],
            position_world_m=cat["position"],
            gyro_rps=cat["gyro"],
            vbat_v=cat["vbat"],
            length_m=cat["length"],
            base_world_m=cat["base"],
            segment=cat["segment"],
        )
        out[d] = DroneRecording(
            drone=d,
            data=data,
            files=tuple(p for _, p, _ in parts),
            weight_n_per_m=float(np.median(cat["weight"])),
            base_from_reel=any(c.base_from_reel for _, _, c in parts),
            invalid=invalid[d],
            tether_messages=tuple(c.tether_messages for _, _, c in parts),
            segments=tuple(i for i, _, _ in parts),
            attitude_source=source,
        )
    return out


def _one_attitude_source(
    drone: str, parts: Sequence[tuple[int, str, _Columns]]
) -> messages.AttitudeSource:
    """The one attitude source of a drone's recordings.

    The thrust axis is fitted against the attitude (eq:NE_tether's ``R·u``): recordings
    with the drone's own attitude and with motion capture's would fit an axis that is right
    for neither, so mixed sources are refused, naming the files.

    Raises:
        CalibrateInputError: more than one source.
    """
    seen: Counter[messages.AttitudeSource] = Counter()
    for _, _, c in parts:
        seen.update(c.attitude_sources)
    if len(seen) > 1:
        per_file = "; ".join(
            f"{Path(p).name}: "
            + ", ".join(f"{n} {src}" for src, n in sorted(c.attitude_sources.items()))
            for _, p, c in parts
        )
        raise CalibrateInputError(
            f"drone {drone!r}: Telemetry with more than one attitude source ({per_file}); "
            "the thrust axis is fitted against one attitude: calibrate the recordings of "
            "the source the drone will fly with (Telemetry attitude_source, else [drone] "
            "attitude_source)"
        )
    return next(iter(seen)) if seen else "onboard"


def _rest_offsets(data: CalibrationData, bias: Sequence[float]) -> np.ndarray:
    """The rest offset the service would apply to each sample (NaN where none): the one in
    force when the sample arrives, as the pipeline applies it."""
    out = np.full((len(data), 3), math.nan)
    for seg in np.unique(data.segment):
        cal = RestCalibrator(bias_body_mps2=bias)
        for i in np.flatnonzero(data.segment == seg).tolist():
            off = cal.offset
            if off is not None:
                out[i] = off.offset_body_mps2
            gyro = data.gyro_rps[i]
            cal.update(
                float(data.stamp_s[i]),
                data.accel_body_mps2[i],
                data.quat_wxyz[i],
                bool(data.armed[i]),
                gyro if np.all(np.isfinite(gyro)) else None,
            )
    return out


@dataclass(frozen=True)
class DroneCalibration:
    """One drone's fit, and what its written ``[calibration]`` says about the rest."""

    fit: CalibrationFit
    rest: bool
    """``rest`` to write."""
    rest_required: bool
    """``rest_required`` to write: the x/y bias was left to the rest calibration."""
    rest_note: tuple[str, ...] = ()
    """What the rest settings mean for this drone (printed, and written as comments)."""


_AXIS = ("about_x_rad", "about_y_rad")
_REST_HOW = (
    "start each calibration recording with the drone on the floor, disarmed and still for at "
    "least 1 s, and calibrate again"
)


def calibrate_drone(
    rec: DroneRecording, settings: Settings, *, fit_tether: bool = False
) -> DroneCalibration:
    """Fit one drone's calibration, starting from its configured one.

    With ``[calibration] rest = true`` the rest offsets the service would apply are applied
    here too; where they cover the hover samples (:data:`MIN_REST_COVERAGE`), the configured
    x/y bias has no effect at run time (the rest measures x/y at every power-on), so it is
    kept, the thrust axis is fitted instead, and ``rest_required`` is written. Where they do
    not, the x/y bias is fitted; if the data then leave the thrust axis to it (fixed at 0,
    the x/y bias absorbing ``F·sin(a)/m``), ``rest = false`` is written: a rest offset at run
    time would replace that bias and lose the axis (63 cm instead of 2.7 cm in the audit's
    case, tests/test_calibrate_cli.py). When the axis is fitted anyway (spread of thrust,
    still samples in the fit), the fitted x/y bias is this power-on's own and the rest
    calibration may replace it: ``rest`` stays as configured.

    Raises:
        CalibrateInputError: too little hover in a file.
    """
    params = settings.for_drone(rec.drone)
    cal = params.calibration
    initial = {
        "thrust_scale": cal.thrust_scale,
        "about_x_rad": cal.thrust_axis_rad[0],
        "about_y_rad": cal.thrust_axis_rad[1],
        "bias_x_mps2": cal.accel_bias_mps2[0],
        "bias_y_mps2": cal.accel_bias_mps2[1],
        "bias_z_mps2": cal.accel_bias_mps2[2],
        "vbat_slope_per_v": cal.thrust_vbat_slope_per_v,
    }
    mass = params.drone.mass_kg
    hover = hover_mask(rec.data, mass)
    for seg, path in enumerate(rec.files):
        in_seg = rec.data.segment == np.unique(rec.data.segment)[seg]
        t = rec.data.stamp_s[in_seg & hover]
        # hover time of this file (sum of run lengths ≈ samples × median step)
        steps = np.diff(rec.data.stamp_s[in_seg])
        dt = float(np.median(steps)) if steps.size else 0.0
        held = t.size * dt
        if held < MIN_HOVER_S:
            raise CalibrateInputError(
                f"{path!r}: drone {rec.drone!r}: too short: {held:.1f} s of steady hover "
                f"under motion capture (need at least {MIN_HOVER_S:.0f} s)"
            )
    offsets = None
    fix: dict[str, str] = {}
    rest_xy = True
    coverage = 0.0
    if cal.rest:
        off = _rest_offsets(rec.data, cal.accel_bias_mps2)
        covered = np.all(np.isfinite(off[hover]), axis=1)
        coverage = float(covered.mean()) if covered.size else 0.0
        if coverage >= MIN_REST_COVERAGE:
            offsets = np.nan_to_num(off)
            rest_xy = False
            why = (
                "kept as configured: rest calibration ([calibration] rest = true) measures "
                "the x/y offset at every power-on, which replaces it"
            )
            fix = {"bias_x_mps2": why, "bias_y_mps2": why}
    try:
        fit = fit_calibration(
            rec.data,
            mass,
            weight_n_per_m=None if math.isnan(rec.weight_n_per_m) else rec.weight_n_per_m,
            floor_z_m=params.base.floor_z_m,
            initial=initial,
            vbat_ref_v=cal.thrust_vbat_ref_v,
            fit_tether=fit_tether,
            rest_offsets_body_mps2=offsets,
            hover=hover,
            rest_bias_xy=rest_xy,
            min_hover_s=MIN_HOVER_S,
            fix=fix,
        )
    except CalibrationError as exc:
        files = ", ".join(repr(f) for f in rec.files)
        raise CalibrateInputError(f"{files}: drone {rec.drone!r}: {exc}") from None
    if not cal.rest:
        return DroneCalibration(fit, rest=False, rest_required=False)
    if not rest_xy:
        return DroneCalibration(
            fit,
            rest=True,
            rest_required=True,
            rest_note=(
                "rest = true, rest_required = true: the x/y accelerometer bias is left to the "
                "rest calibration and the thrust axis fitted on top of it; before each flight "
                "let the drone sit disarmed and still on the floor for 1 s (the service warns "
                "when it arms without a rest offset)",
            ),
        )
    fixed = {f.name for f in fit.fixed}
    absorbed = [name for name in _AXIS if name in fixed]
    if not absorbed:
        return DroneCalibration(fit, rest=True, rest_required=False)
    return DroneCalibration(
        fit,
        rest=False,
        rest_required=False,
        rest_note=(
            f"rest = false (configured true): {', '.join(absorbed)} fixed at 0, so the fitted "
            "x/y bias carries the thrust axis; a rest offset at run time would replace that "
            "bias and lose the axis",
            f"a rest offset covers {100 * coverage:.0f} % of the hovers (at least "
            f"{100 * MIN_REST_COVERAGE:.0f} % needed to fit the axis on top of the rest "
            f"offsets); to calibrate the axis and keep the rest calibration, {_REST_HOW}",
        ),
    )


# ------------------------------------------------------------------------------- output


def _pm(fit: CalibrationFit, name: str, fmt: str, scale: float = 1.0) -> str:
    value = fit.values[name] * scale
    std = fit.std[name]
    if std is not None:
        return f"{value:{fmt}} ± {std * scale:{fmt}}"
    fixed = next((f for f in fit.fixed if f.name == name), None)
    if fixed is not None:
        return f"{value:{fmt}} (fixed)"
    return f"{value:{fmt}} (not fitted)"


def format_fit(drone: str, fit: CalibrationFit, files: Sequence[str]) -> str:
    """The report printed for one drone."""
    mn = 1e3
    lines = [
        f"drone {drone}: {fit.hover_s:.1f} s of hover ({fit.hover_samples} samples, "
        f"n_eff {fit.n_eff:.0f} after autocorrelation), {fit.rest_samples} still samples "
        f"at rest, from {', '.join(files)}",
        f"  thrust_scale             {_pm(fit, 'thrust_scale', '.4f')}",
        "  thrust_axis_rad          ["
        + ", ".join(_pm(fit, n, ".4f") for n in ("about_x_rad", "about_y_rad"))
        + "]",
        "  accel_bias_mps2          ["
        + ", ".join(_pm(fit, n, ".3f") for n in ("bias_x_mps2", "bias_y_mps2", "bias_z_mps2"))
        + "]",
        f"  thrust_vbat_slope_per_v  {_pm(fit, 'vbat_slope_per_v', '.4f')}"
        f"  (about thrust_vbat_ref_v = {fit.vbat_ref_v:g} V)",
    ]
    vbat_range = _vbat_range(fit)
    lines.append(
        "  thrust_vbat_range_v      "
        + (
            "none (no vbat_v in the recordings: flight outside the calibrated battery "
            "range cannot be flagged)"
            if vbat_range is None
            else f"[{vbat_range[0]:.3f}, {vbat_range[1]:.3f}] (the hovers' battery: the "
            "service flags flight outside it as calibration_extrapolated)"
        )
    )
    if "weight_n_per_m" in fit.fitted:
        lines.append(f"  tether weight_n_per_m    {_pm(fit, 'weight_n_per_m', '.4f')}")
        lines.append(
            "  base offset_m            ["
            + ", ".join(_pm(fit, n, ".3f") for n in ("base_dx_m", "base_dy_m", "base_dz_m"))
            + "]"
        )
    for f in fit.fixed:
        lines.append(f"  fixed {f.name} = {f.value:g}: {f.reason}")
    for note in fit.notes:
        lines.append(f"  note: {note}")
    b, a = fit.rms_before_n * mn, fit.rms_after_n * mn
    mb, ma = fit.mean_before_n * mn, fit.mean_after_n * mn
    lines.append(
        f"  tension residual RMS x/y/z, mN: before {b[0]:.1f} {b[1]:.1f} {b[2]:.1f}"
        f"  after {a[0]:.1f} {a[1]:.1f} {a[2]:.1f}"
    )
    lines.append(
        f"  tension residual mean x/y/z, mN: before {mb[0]:.1f} {mb[1]:.1f} {mb[2]:.1f}"
        f"  after {ma[0]:.1f} {ma[1]:.1f} {ma[2]:.1f}"
    )
    if fit.spots:
        lines.append(
            "  predicted position error at hover (from the mean tension residual; ± from the"
            " parameters' standard errors):"
        )
        for s in fit.spots:
            p = s.position_world_m
            lines.append(
                f"    at ({p[0]:.2f}, {p[1]:.2f}, {p[2]:.2f}) m: before {s.before_m * 100:.1f} cm"
                f", after {s.after_m * 100:.1f} cm ± {s.uncertainty_m * 100:.1f} cm"
            )
    return "\n".join(lines)


def _vbat_range(fit: CalibrationFit | AirframeFit) -> list[float] | None:
    """The hover samples' battery range, rounded outward to the millivolt, or None."""
    if fit.vbat_range_v is None:
        return None
    lo, hi = fit.vbat_range_v
    return [math.floor(lo * 1e3) / 1e3, math.ceil(hi * 1e3) / 1e3]


def _calibration_table(cal: DroneCalibration, source: str, attitude_source: str) -> dict[str, Any]:
    fit = cal.fit
    v = fit.values
    vbat_range = _vbat_range(fit)
    return {
        "thrust_scale": round(v["thrust_scale"], 6),
        "thrust_axis_rad": [round(v["about_x_rad"], 6), round(v["about_y_rad"], 6)],
        "accel_bias_mps2": [
            round(v["bias_x_mps2"], 5),
            round(v["bias_y_mps2"], 5),
            round(v["bias_z_mps2"], 5),
        ],
        "thrust_vbat_slope_per_v": round(v["vbat_slope_per_v"], 6),
        "thrust_vbat_ref_v": fit.vbat_ref_v,
        # Where the thrust map holds: the service flags flight outside it.
        **({} if vbat_range is None else {"thrust_vbat_range_v": vbat_range}),
        "rest": cal.rest,
        "rest_required": cal.rest_required,
        # The full model's bias stands for the accelerometer's mean: trust it as read.
        "accel_slow": False,
        "attitude_source": attitude_source,
        "source": source,
    }


_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def _key(k: str) -> str:
    return k if _BARE_KEY.fullmatch(k) else '"' + k.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        escaped = v.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")
        return f'"{escaped}"'
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, Mapping):
        return "{" + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def toml_dumps(data: Mapping[str, Any], comments: Mapping[str, list[str]] | None = None) -> str:
    """TOML for nested dicts of scalars and lists; ``comments`` by dotted table name go
    above that table's header."""
    out: list[str] = []

    def table(prefix: tuple[str, ...], d: Mapping[str, Any]) -> None:
        scalars = {k: v for k, v in d.items() if not isinstance(v, Mapping)}
        tables = {k: v for k, v in d.items() if isinstance(v, Mapping)}
        if prefix and (scalars or not tables):
            name = ".".join(prefix)
            if out:
                out.append("")
            out.extend(f"# {c}" for c in (comments or {}).get(name, []))
            out.append("[" + ".".join(_key(p) for p in prefix) + "]")
        for k, v in scalars.items():
            out.append(f"{_key(k)} = {_value(v)}")
        for k, v in tables.items():
            table((*prefix, k), v)

    table((), data)
    return "\n".join(out) + "\n"


def _merge(base: dict[str, Any], patch: Mapping[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in patch.items():
        if isinstance(v, Mapping) and isinstance(out.get(k), Mapping):
            out[k] = _merge(dict(out[k]), v)
        else:
            out[k] = v
    return out


def _compose(
    input_text: str,
    input_data: dict[str, Any],
    patch: dict[str, Any],
    comments: dict[str, list[str]],
) -> str:
    """The input file plus the new tables: appended verbatim when that yields the merged
    document, else the merged document written afresh (an input that already had them)."""
    merged = _merge(input_data, patch)
    appended = input_text.rstrip("\n") + "\n\n" if input_text.strip() else ""
    appended += toml_dumps(patch, comments).lstrip("\n")
    try:
        if tomllib.loads(appended) == tomllib.loads(toml_dumps(merged)):
            return appended
    except tomllib.TOMLDecodeError:
        pass
    head = [
        "# Rewritten by groundstation calibrate from the input configuration (its comments"
        " are not kept): it already had the tables below.",
        "",
    ]
    return "\n".join(head) + toml_dumps(merged, comments)


def _which_drones(
    recs: Mapping[str, DroneRecording], settings: Settings, drone: str | None
) -> list[str]:
    """Lines saying which drones are calibrated and with which tables.

    Raises:
        CalibrateInputError: without ``drone``, a recorded drone that the configuration's
            ``[drones.<id>]`` tables do not describe while they describe others.
    """
    configured = sorted(settings.drones)
    shared = [d for d in sorted(recs) if configured and d not in settings.drones]
    if drone is None and shared:
        files = sorted({f for d in shared for f in recs[d].files})
        raise CalibrateInputError(
            f"{', '.join(repr(f) for f in files)}: telemetry from drone(s) "
            f"{', '.join(shared)}, which the configuration does not describe (it has "
            f"[drones.<id>] tables for {', '.join(configured)} only): the tether and base "
            "would be the shared tables', maybe another drone's; pass --drone ID to calibrate "
            "one drone explicitly"
        )
    lines = []
    if drone is None:
        lines.append(
            f"calibrating every drone in the recordings: {', '.join(sorted(recs))} "
            "(--drone ID: one only)"
        )
    for d in shared:
        lines.append(
            f"{d}: no [drones.{d}] in the configuration: fitted with the shared [drone], "
            "[tether], [base] and [calibration]"
        )
    return lines


def airframe_drone(rec: DroneRecording, settings: Settings, *, untethered: bool) -> AirframeFit:
    """Fit one drone's airframe constants (groundstation.airframe) across its recordings.

    Raises:
        CalibrateInputError: too little usable flight.
    """
    params = settings.for_drone(rec.drone)
    model = params.calibration.thrust_model
    if model == "motor_voltage" and settings.crazyflie.thrust_model != "pwm_map":
        raise CalibrateInputError(
            f'drone {rec.drone!r}: [calibration] thrust_model = "motor_voltage" inverts the '
            "PWM map that made thrust_n, but [crazyflie] thrust_model = "
            f'"{settings.crazyflie.thrust_model}" (use thrust_model = "vbat_linear")'
        )
    try:
        return fit_airframe(
            rec.data,
            params.drone.mass_kg,
            weight_n_per_m=None if untethered else rec.weight_n_per_m,
            floor_z_m=params.base.floor_z_m,
            vbat_ref_v=params.calibration.thrust_vbat_ref_v,
            min_samples_s=MIN_HOVER_S,
            thrust_model=model,
            pwm_map=settings.crazyflie.thrust_map,
        )
    except CalibrationError as exc:
        files = ", ".join(repr(f) for f in rec.files)
        raise CalibrateInputError(f"{files}: drone {rec.drone!r}: {exc}") from None


def _pm_airframe(fit: AirframeFit, name: str, fmt: str) -> str:
    std = fit.std[name]
    value = fit.values[name]
    if std is not None:
        return f"{value:{fmt}} ± {std:{fmt}}"
    return f"{value:{fmt}} (fixed)"


def format_airframe(
    drone: str, fit: AirframeFit, files: Sequence[str], segments: Sequence[int] = ()
) -> str:
    """The report printed for one drone: constants, then each power-on's nuisances.

    ``segments``: the ``data.segment`` of each file (empty: 0, 1, 2, ...); a power-on with
    no usable sample has no nuisance and is left out, the others keep their file's name.
    """
    by_segment = dict(zip(segments or range(len(files)), files, strict=True))
    mn = 1e3
    ref = "the catenary at the motion-capture position" if fit.tethered else "zero (untethered)"
    lines = [
        f"drone {drone}: {fit.samples} samples (n_eff {fit.n_eff:.0f} after autocorrelation) "
        f"from {len(fit.flights)} power-on(s): {', '.join(files)}; reference tension: {ref}",
        "  airframe constants (written):",
    ]
    if fit.thrust_model == "motor_voltage":
        lines += [
            '    thrust_model             "motor_voltage"',
            f"    thrust_motor_ref_n       {_pm_airframe(fit, 'thrust_motor_ref_n', '.5f')}"
            f"  (one motor at thrust_motor_ref_v = {fit.motor_ref_v:g} V)",
            f"    thrust_motor_exponent    {_pm_airframe(fit, 'thrust_motor_exponent', '.3f')}"
            + (
                f"  (at its bound, {fit.exponent_bounds[0]:g}–{fit.exponent_bounds[1]:g}: "
                "the data would put it outside what a motor does)"
                if fit.exponent_at_bound
                else ""
            ),
        ]
    else:
        lines.append(f"    thrust_scale             {_pm_airframe(fit, 'thrust_scale', '.4f')}")
    lines.append(
        "    thrust_axis_rad          ["
        + ", ".join(_pm_airframe(fit, n, ".4f") for n in ("about_x_rad", "about_y_rad"))
        + "]"
    )
    if fit.thrust_model != "motor_voltage":
        lines.append(
            f"    thrust_vbat_slope_per_v  {_pm_airframe(fit, 'vbat_slope_per_v', '.4f')}"
            f"  (about thrust_vbat_ref_v = {fit.vbat_ref_v:g} V)"
        )
    lines.append(f"    rotor_drag_n_s_per_m     {_pm_airframe(fit, 'rotor_drag_n_s_per_m', '.4f')}")
    model = fit.model_std_n * mn
    lines.append(
        f"    tension_model_std_n      [{model[0]:.1f}, {model[1]:.1f}, {model[2]:.1f}] mN"
        "  (what the constants leave: the published σ carries it)"
    )
    for name, why in fit.fixed.items():
        lines.append(f"    fixed {name}: {why}")
    lines.append(
        "  per power-on (printed, NOT written: the service learns these at each power-on):"
    )
    for f in fit.flights:
        path = by_segment.get(f.segment, f"recording {f.segment}")
        a = f.accel_offset_body_mps2
        r = f.residual_mean_n * mn
        vr = "" if f.vbat_range_v is None else f", battery {f.vbat_range_v[0]:.2f}–"
        vr += "" if f.vbat_range_v is None else f"{f.vbat_range_v[1]:.2f} V"
        lines.append(
            f"    {Path(path).name}: accelerometer offset [{a[0]:+.3f}, {a[1]:+.3f}, "
            f"{a[2]:+.3f}] m/s²; tension left by the constants [{r[0]:+.1f}, {r[1]:+.1f}, "
            f"{r[2]:+.1f}] mN ({f.samples} samples{vr})"
        )
    spread = fit.flight_spread_n * mn
    if len(fit.flights) > 1:
        lines.append(
            f"  spread across power-ons x/y/z {spread[0]:.1f}/{spread[1]:.1f}/{spread[2]:.1f} mN:"
            " expect a new power-on to differ from the constants by about this much"
        )
    b, a2 = fit.rms_before_n * mn, fit.rms_after_n * mn
    lines.append(
        f"  tension residual RMS x/y/z, mN: nominal {b[0]:.1f} {b[1]:.1f} {b[2]:.1f}"
        f"  calibrated {a2[0]:.1f} {a2[1]:.1f} {a2[2]:.1f}"
    )
    return "\n".join(lines)


def _airframe_table(
    fit: AirframeFit, cal: Any, source: str, attitude_source: str
) -> dict[str, Any]:
    v = fit.values
    vbat = _vbat_range(fit)
    thrust: dict[str, Any]
    if fit.thrust_model == "motor_voltage":
        thrust = {
            "thrust_model": "motor_voltage",
            "thrust_scale": 1.0,
            "thrust_motor_ref_n": round(v["thrust_motor_ref_n"], 7),
            "thrust_motor_ref_v": fit.motor_ref_v,
            "thrust_motor_exponent": round(v["thrust_motor_exponent"], 5),
            "thrust_pwm_map": list(fit.pwm_map),
            "thrust_vbat_slope_per_v": 0.0,
        }
    else:
        thrust = {
            "thrust_scale": round(v["thrust_scale"], 6),
            "thrust_vbat_slope_per_v": round(v["vbat_slope_per_v"], 6),
        }
    return {
        **thrust,
        "thrust_axis_rad": [round(v["about_x_rad"], 6), round(v["about_y_rad"], 6)],
        # Per power-on: learnt by the service at each power-on, never carried.
        "accel_bias_mps2": [0.0, 0.0, 0.0],
        "thrust_vbat_ref_v": fit.vbat_ref_v,
        "rotor_drag_n_s_per_m": round(v["rotor_drag_n_s_per_m"], 6),
        # what the constants leave: the service's published σ carries it
        "tension_model_std_n": [round(float(x), 5) for x in fit.model_std_n],
        **({} if vbat is None else {"thrust_vbat_range_v": vbat}),
        "rest": cal.rest,
        "rest_required": False,
        "accel_slow": True,
        "attitude_source": attitude_source,
        "source": source,
    }


def run_calibrate(
    settings: Settings,
    config_path: str | None,
    files: Sequence[str],
    out_path: str,
    *,
    drone: str | None = None,
    fit_tether: bool = False,
    model: str = "airframe",
    untethered: bool = False,
    tether_detached: bool = False,
    force: bool = False,
    now: Callable[[], datetime] = lambda: datetime.now(UTC),
    echo: Callable[[str], None] = print,
) -> int:
    """Fit, print, write; returns the exit status (0). Nothing is written on error.

    Which drones: ``drone`` alone, else every drone in the recordings (said so), each with
    its ``[drones.<id>]``; when the configuration has such tables, a recorded drone without
    one is an error (its tether and base would be guessed from the shared tables): ``drone``
    names it explicitly.

    ``out_path`` is checked before any recording is read: it may be none of the inputs (the
    recordings, the configuration), and an existing file is replaced only with ``force``.
    ``untethered`` on recordings that carry tether messages (a reel's length, tether
    parameters) is refused unless ``tether_detached`` says the tether was off the drone
    while the reel published.

    Raises:
        CalibrateInputError, RecordingError, ConfigError: unusable input (names the file).
    """
    try:
        check_output(
            out_path,
            inputs=[*files, *([config_path] if config_path is not None else [])],
            force=force,
        )
    except OutputError as exc:
        raise CalibrateInputError(str(exc)) from None
    recs = read_recordings(files, settings, drone)
    if untethered and not tether_detached:
        _check_untethered(recs)
    for line in _which_drones(recs, settings, drone):
        echo(line)
    stamp = now().strftime("%Y-%m-%dT%H:%M:%SZ")
    names = ", ".join(Path(f).name for f in files)
    patch: dict[str, Any] = {"drones": {}}
    comments: dict[str, list[str]] = {}
    if model == "airframe":
        if fit_tether:
            raise CalibrateInputError("--fit-tether needs --model full")
        for d in sorted(recs):
            rec = recs[d]
            afit = airframe_drone(rec, settings, untethered=untethered)
            echo(format_airframe(d, afit, rec.files, rec.segments))
            source = f"groundstation calibrate {stamp} from {names}"
            table = _airframe_table(
                afit, settings.for_drone(d).calibration, source, rec.attitude_source
            )
            hover_keys, hover_line = hover_velocity_drone(rec, settings, table)
            echo(hover_line)
            echo(_attitude_line(d, rec.attitude_source))
            table.update(hover_keys)
            patch["drones"][d] = {"calibration": table}
            head = [
                f"groundstation calibrate (airframe constants), {stamp}, from {names}, "
                + ("untethered (reference tension zero):" if untethered else "tethered:"),
                f"{afit.samples} samples, residual RMS x/y/z "
                + "/".join(f"{x * 1e3:.1f}" for x in afit.rms_after_n)
                + " mN; accel_bias_mps2 is zero on purpose: the accelerometer's offsets "
                "belong to each power-on and the service learns them there",
            ]
            for name in afit.parameters:
                std = afit.std[name]
                if std is not None:
                    head.append(f"  {name} = {afit.values[name]:.6g} ± {std:.2g}")
            for name, why in afit.fixed.items():
                head.append(f"  {name}: {why}")
            comments[f"drones.{d}.calibration"] = head
        return _write_config(settings, config_path, patch, comments, out_path, echo, force)
    if untethered:
        recs = {d: replace(r, weight_n_per_m=math.nan) for d, r in recs.items()}
    cals = {d: calibrate_drone(r, settings, fit_tether=fit_tether) for d, r in recs.items()}
    for d in sorted(cals):
        fit = cals[d].fit
        rec = recs[d]
        echo(format_fit(d, fit, rec.files))
        source = f"groundstation calibrate {stamp} from {names}"
        cal_table = _calibration_table(cals[d], source, rec.attitude_source)
        hover_keys, hover_line = hover_velocity_drone(rec, settings, cal_table)
        echo(hover_line)
        echo(_attitude_line(d, rec.attitude_source))
        for note in cals[d].rest_note:
            echo(f"  {note}")
        params = settings.for_drone(d)
        tables: dict[str, Any] = {"calibration": cal_table | hover_keys}
        if params.calibration.thrust_model != "vbat_linear":
            # the full model fits the straight battery line only: say so in what it writes
            tables["calibration"]["thrust_model"] = "vbat_linear"
            echo(
                f"  {d}: --model full fits the straight battery line: thrust_model = "
                '"vbat_linear" written (the configured motor_voltage needs --model airframe)'
            )
        head = [
            f"groundstation calibrate, {stamp}, from {names}:",
            f"{fit.hover_s:.1f} s of hover under motion capture, {fit.rest_samples} still"
            f" samples at rest; residual RMS x/y/z {fit.rms_before_n[0] * 1e3:.1f}/"
            f"{fit.rms_before_n[1] * 1e3:.1f}/{fit.rms_before_n[2] * 1e3:.1f} mN before, "
            f"{fit.rms_after_n[0] * 1e3:.1f}/{fit.rms_after_n[1] * 1e3:.1f}/"
            f"{fit.rms_after_n[2] * 1e3:.1f} mN after.",
        ]
        for name in fit.fitted:
            std = fit.std[name]
            head.append(f"  {name} = {fit.values[name]:.6g} ± {std:.2g}")
        for f in fit.fixed:
            head.append(f"  {f.name} fixed at {f.value:g}: {f.reason}")
        head.extend(cals[d].rest_note)
        comments[f"drones.{d}.calibration"] = head
        if "weight_n_per_m" in fit.fitted:
            tables["tether"] = {"weight_n_per_m": round(fit.values["weight_n_per_m"], 6)}
            if not rec.base_from_reel:
                offset = [fit.values[n] for n in ("base_dx_m", "base_dy_m", "base_dz_m")]
                base = np.array(params.base.position_m) + np.array(offset)
                tables["base"] = {"position_m": [round(float(x), 5) for x in base]}
        patch["drones"][d] = tables
    return _write_config(settings, config_path, patch, comments, out_path, echo, force)


def hover_velocity_drone(
    rec: DroneRecording, settings: Settings, fitted: Mapping[str, Any] | None = None
) -> tuple[dict[str, float], str]:
    """σ_v and T_c of one drone's hovers, q_w and D of their thrust balance, σ_V, T_V and σ_δ
    of its flights (groundstation.hover_fit): the keys to write (none where there is too
    little under motion capture) and the lines to print. ``fitted``: the ``[calibration]``
    table this run writes, whose thrust model the balance is read with (None: the
    configured one)."""
    params = settings.for_drone(rec.drone)
    bias = params.calibration.accel_bias_mps2
    phases = flight_phases(
        rec.data,
        slow_accel_params(params),
        mass_kg=params.drone.mass_kg,
        floor_z_m=params.base.floor_z_m,
        ground_thrust_ratio=params.filter.ground_thrust_ratio,
        accel_bias_mps2=bias,
    )
    keys: dict[str, float] = {}
    lines: list[str] = []
    velocity = bridged_velocity(rec.data)  # motion capture's, once for every fit below
    fit, hover_s = fit_hover_velocity(rec.data, phases.hovering, velocity_world_mps=velocity)
    if fit is None:
        lines.append(
            f"    hover velocity           not fitted: {hover_s:.1f} s of hover under motion "
            f"capture (the service's hover test; need {HOVER_FIT_MIN_S:.0f} s): the "
            "filter's defaults stand"
        )
    elif refused := _outside_bounds(
        hover := {
            "hover_velocity_std_mps": round(fit.std_mps, 6),
            "hover_velocity_time_s": round(fit.time_s, 4),
        }
    ):
        lines.append(
            f"    hover velocity           not fitted: {refused}: the filter's defaults stand"
        )
    else:
        keys.update(hover)
        lines.append(
            f"    hover_velocity_std_mps   {fit.std_mps:.4f}  hover_velocity_time_s "
            f"{fit.time_s:.3f}  ({fit.hover_s:.1f} s of hover in {fit.stretches} stretches: "
            "the velocity's scatter and correlation time, which bound the hover's thrust "
            "balance)"
        )
    section = params.calibration
    if fitted is not None:
        section = CalibrationSection.model_validate({**section.model_dump(), **fitted})
    balance = balance_world_n(
        rec.data,
        phases.hovering,
        mass_kg=params.drone.mass_kg,
        calibration=calibration_from_config(section)[0],
        velocity_world_mps=velocity,
    )
    bfit, balance_s = fit_hover_balance(
        rec.data,
        phases.hovering,
        balance,
        mass_kg=params.drone.mass_kg,
        velocity_world_mps=velocity,
    )
    if bfit is None:
        lines.append(
            f"    hover balance            not fitted: {balance_s:.1f} s of hover under motion "
            f"capture (need {HOVER_FIT_MIN_S:.0f} s): the filter's defaults stand"
        )
    elif refused := _outside_bounds(
        balance_keys := {
            **(
                {"hover_wander_n2_per_s": float(f"{bfit.wander_n2_per_s:.4g}")}
                if bfit.wander_resolved
                else {}
            ),
            "hover_balance_density_n2s": float(f"{bfit.balance_density_n2s:.4g}"),
        }
    ):
        lines.append(
            f"    hover balance            not fitted: {refused}: the filter's defaults stand"
        )
    else:
        keys.update(balance_keys)
        lines.append(
            f"    hover_wander_n2_per_s    {bfit.wander_n2_per_s:.3g}"
            + ("" if bfit.wander_resolved else " (not resolved from no wander: not written)")
            + f"  hover_balance_density_n2s {bfit.balance_density_n2s:.3g}  "
            f"(motion-capture velocity error {bfit.velocity_error_std_mps * 1e3:.2f} mm/s; "
            f"{bfit.hover_s:.1f} s of hover in {bfit.stretches} stretches, "
            f"{bfit.blocks} block differences: the tension's wander and the thrust "
            "balance's noise, by maximum likelihood)"
        )
    flight, airborne_s = fit_flight(
        rec.data, phases, accel_bias_mps2=bias, velocity_world_mps=velocity
    )
    if flight is None:
        lines.append(
            f"    flight velocity          not fitted: {airborne_s:.1f} s of flight under "
            f"motion capture (need {HOVER_FIT_MIN_S:.0f} s): the bias filter's defaults stand"
        )
    elif refused := _outside_bounds(
        flight_keys := {
            "flight_velocity_std_mps": round(flight.velocity_std_mps, 6),
            "flight_velocity_time_s": round(flight.velocity_time_s, 4),
        }
    ):
        lines.append(
            f"    flight velocity          not fitted: {refused}: the bias filter's defaults stand"
        )
    else:
        keys.update(flight_keys)
        line = (
            f"    flight_velocity_std_mps  {flight.velocity_std_mps:.4f}  "
            f"flight_velocity_time_s {flight.velocity_time_s:.3f}  ({flight.airborne_s:.1f} s "
            "of flight: the velocity's scatter about zero and its correlation time, from "
            "which the bias filter learns the accelerometer's bias in the air)"
        )
        lines.append(line)
        if flight.bias_std_mps2 is None:
            lines.append(
                "    flight_bias_std_mps2     not fitted: no flight followed a rest on the "
                "floor (disarmed and still): the default stands"
            )
        elif refused := _outside_bounds(
            bias_step := {"flight_bias_std_mps2": round(flight.bias_std_mps2, 6)}
        ):
            lines.append(f"    flight_bias_std_mps2     not fitted: {refused}: the default stands")
        else:
            keys.update(bias_step)
            lines.append(
                f"    flight_bias_std_mps2     {flight.bias_std_mps2:.4f}  ({flight.flights} "
                "flights after a rest: how far the accelerometer's bias in the air strays "
                "from the rest's)"
            )
    return keys, "\n".join(lines)


def _outside_bounds(fitted: Mapping[str, float]) -> str | None:
    """Why a fitted ``[calibration]`` value, as it would be written (rounded), cannot be:
    it is outside the range its key accepts (e.g. a velocity scatter of 0 from a simulator's
    exact motion capture, which would make the hover's thrust balance exact); None when
    every value can be."""
    for key, value in fitted.items():
        lo, hi = -math.inf, math.inf
        for bound in CalibrationSection.model_fields[key].metadata:
            lo = getattr(bound, "gt", lo)
            hi = getattr(bound, "lt", hi)
        if not lo < value < hi:  # NaN too
            why = f"{key} = {value:.4g} is outside the key's range ({lo:g}, {hi:g})"
            if value == 0.0:
                why += " (no scatter at all: an ideal simulator's exact motion capture?)"
            return why
    return None


def _attitude_line(drone: str, source: str) -> str:
    """What calibrate tells about the attitude the thrust axis was fitted against."""
    other = "external" if source == "onboard" else "onboard"
    return (
        f"  {drone}: thrust axis fitted against the {source} attitude "
        f'([calibration] attitude_source = "{source}"); served with the {other} one, the '
        "service uses the accelerometer model instead of the hover model"
    )


def _check_untethered(recs: Mapping[str, DroneRecording]) -> None:
    """Refuse ``--untethered`` on recordings in which a tether published (see run_calibrate).

    The untethered fit takes the true tension as zero; a tether that pulled would be fitted
    into the thrust scale and axis without a word.
    """
    found = [
        f"{Path(f).name} ({n} for {d})"
        for d, rec in sorted(recs.items())
        for f, n in zip(rec.files, rec.tether_messages, strict=False)
        if n
    ]
    if found:
        raise CalibrateInputError(
            "--untethered takes the tether's force as zero, but these recordings hold tether "
            f"messages (reel length, tether parameters): {', '.join(found)}. Calibrate "
            "without --untethered, or, if the tether was detached from the drone while the "
            "reel published, say so with --tether-detached"
        )


def _write_config(
    settings: Settings,
    config_path: str | None,
    patch: dict[str, Any],
    comments: dict[str, list[str]],
    out_path: str,
    echo: Callable[[str], None],
    force: bool = False,
) -> int:
    """Merge the drones' tables into the input configuration, validate, write atomically."""
    input_text = ""
    input_data: dict[str, Any] = {}
    if config_path is not None:
        input_text = Path(config_path).read_text(encoding="utf-8")
        input_data = tomllib.loads(input_text)
    for d, tables in patch["drones"].items():
        # A range from an earlier calibration does not describe this one: drop it (the
        # document is then written afresh) when these recordings carry no vbat_v.
        old = input_data.get("drones", {}).get(d, {}).get("calibration", {})
        if "thrust_vbat_range_v" in old and "thrust_vbat_range_v" not in tables["calibration"]:
            del old["thrust_vbat_range_v"]
            input_text = toml_dumps(input_data)
    text = _compose(input_text, input_data, patch, comments)

    # Validate as serve would (load_settings resolves every [drones.<id>]), then move it in.
    try:
        with NewFile(out_path, force=force, text=True) as out:
            out.stream.write(text)
            out.stream.flush()
            try:
                load_settings(out.writing_path, use_env=False)
            except ConfigError as exc:
                raise CalibrateInputError(
                    f"the configuration to be written is invalid (nothing written): {exc}"
                ) from None
    except OutputError as exc:
        raise CalibrateInputError(str(exc)) from None
    echo(f"wrote {out.target}")
    return 0
