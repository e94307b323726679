"""Airframe constants from flights under motion capture, apart from per-power-on nuisances.

Pure physics: numpy and scipy only (docs/estimator_design.md, docs/calibration.md).

The model is the hover model with the motion-capture acceleration, ``eq:NE_tether`` with the
accelerometer's reading replaced by the kinematics it should read::

    T_ref = m·(g·e3 + p̈) − R·u·F + R·D·Rᵀ·v                  # world frame, N
    F     = thrust_n·(s + k·(vbat_v − v_ref))                 # thrust_model "vbat_linear"
    F     = 4·f_ref·(v_motor / v_ref)^n                       # thrust_model "motor_voltage"
    u     = R_x(about_x)·R_y(about_y)·e3
    D     = diag(D_xy, D_xy, 0)                              # rotor drag, body frame

(``v_motor`` the motor voltage the nominal thrust and the battery give,
groundstation.thrust_model)

with ``T_ref`` the catenary's force at the motion-capture position (tethered) or zero
(untethered), ``p̈`` and ``v`` the motion-capture acceleration and velocity. The
accelerometer does not appear: its bias and misalignment change at every power-on and belong
to that power-on (the online estimator learns them there, groundstation.slow_accel). So the
fit returns two kinds of numbers, kept apart:

* **airframe constants**, shared by every flight: thrust scale ``s`` and battery term ``k``
  (or the motor's ``f_ref`` and ``n``), thrust axis ``(about_x, about_y)``, rotor drag
  ``D_xy``. These are written to the configuration.
* **per-power-on nuisances**, one per flight (recording): the accelerometer's slow error
  (its mean reading minus what the kinematics say, body frame) and the tension residual that
  the constants leave in that flight (a flight's own tilt or thrust offset). These are
  printed, never written: nothing can carry them to another power-on.

The spread of the per-flight residuals is the honest out-of-sample figure: a new power-on will
differ from the constants by about as much.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.signal import savgol_filter

from groundstation.attitude import GRAVITY_MPS2, rotations_world_body
from groundstation.calibration import (
    CalibrationData,
    CalibrationError,
    HoverCriteria,
    _index_runs,
    _integrated_autocorr_time,
    _robust_scale,
    _unit_tension,
    hover_mask,
)
from groundstation.tension import thrust_axis_body
from groundstation.thrust_model import (
    EXPONENT_BOUNDS,
    NOMINAL_PWM_MAP,
    ROTOR_EXPONENT,
    ThrustModel,
    mean_motor_voltage_v_array,
)

__all__ = [
    "AIRFRAME_PARAMETERS",
    "MOTOR_VOLTAGE_PARAMETERS",
    "MOVING",
    "AirframeFit",
    "FlightNuisance",
    "fit_airframe",
    "mocap_kinematics",
]

FloatArray = NDArray[np.float64]

AIRFRAME_PARAMETERS: tuple[str, ...] = (
    "thrust_scale",
    "about_x_rad",
    "about_y_rad",
    "vbat_slope_per_v",
    "rotor_drag_n_s_per_m",
)
"""The constants of the ``vbat_linear`` thrust model, in order."""
MOTOR_VOLTAGE_PARAMETERS: tuple[str, ...] = (
    "thrust_motor_ref_n",
    "about_x_rad",
    "about_y_rad",
    "thrust_motor_exponent",
    "rotor_drag_n_s_per_m",
)
"""The constants of the ``motor_voltage`` thrust model, in order (the same slots)."""
_MOTOR_SCALES = np.array([0.005, 0.02, 0.02, 0.5, 0.01])
"""Typical magnitude of each of :data:`MOTOR_VOLTAGE_PARAMETERS` (the solver's scaling)."""
_MOTOR_SCALES.setflags(write=False)

_SCALES = np.array([0.05, 0.02, 0.02, 0.1, 0.01])
"""Typical magnitude of each (the solver's scaling)."""
_SCALES.setflags(write=False)

MOVING = HoverCriteria(max_speed_mps=2.0, max_accel_mps2=3.0, max_gyro_rps=3.0, settle_s=0.5)
"""Untethered: the model holds in motion too (the motion-capture acceleration carries it);
take-off, landing and hard manoeuvres are still left out."""

MIN_SPEED_FOR_DRAG_MPS = 0.3
"""Below this 90th-percentile horizontal speed the drag is not fitted (fixed at 0)."""
MIN_VBAT_SPAN_V = 0.1
"""Below this battery span the battery term is not fitted (fixed at 0)."""
MIN_HEIGHT_M = 0.15
"""Samples closer to the floor than this are left out (ground effect)."""


@dataclass(frozen=True)
class FlightNuisance:
    """What belongs to one power-on (one recording), printed and never written.

    Attributes:
        segment: the recording's index.
        samples: samples of it in the fit.
        accel_offset_body_mps2: (3,) mean accelerometer reading minus the kinematics'
            ``Rᵀ·(g·e3 + p̈)``, body frame, m/s²: this power-on's bias and misalignment.
        residual_mean_n: (3,) mean tension residual left by the constants, world frame, N.
        vbat_range_v: the flight's battery range, V (None without ``vbat_v``).
    """

    segment: int
    samples: int
    accel_offset_body_mps2: FloatArray
    residual_mean_n: FloatArray
    vbat_range_v: tuple[float, float] | None


@dataclass(frozen=True)
class AirframeFit:
    """Result of :func:`fit_airframe`.

    Attributes:
        values: each of :attr:`parameters`.
        std: its standard error (None when fixed), inflated for autocorrelation.
        fixed: name → why it was not fitted.
        flights: the per-power-on nuisances.
        rms_before_n / rms_after_n: (3,) residual RMS per world axis with the starting values
            (the nominal map, no axis, no drag) and after the fit, N.
        samples: samples used; n_eff: their effective number (autocorrelation).
        vbat_ref_v: voltage at which ``thrust_scale`` holds, V (``motor_voltage``: the
            samples' median battery voltage, assumed for a Telemetry without ``vbat_v``).
        vbat_range_v: battery range of the samples used, V, or None.
        tethered: the reference was the catenary (else zero tension).
        thrust_model: the model fitted; ``motor_voltage`` also its ``motor_ref_v`` (V) and
            ``pwm_map``.
    """

    values: dict[str, float]
    std: dict[str, float | None]
    fixed: dict[str, str]
    flights: tuple[FlightNuisance, ...]
    rms_before_n: FloatArray
    rms_after_n: FloatArray
    samples: int
    n_eff: float
    vbat_ref_v: float
    vbat_range_v: tuple[float, float] | None
    tethered: bool
    thrust_model: ThrustModel = "vbat_linear"
    motor_ref_v: float | None = None
    pwm_map: tuple[float, float, float] = NOMINAL_PWM_MAP
    exponent_bounds: tuple[float, float] = EXPONENT_BOUNDS

    @property
    def exponent_at_bound(self) -> bool:
        """``motor_voltage``: the fitted exponent sits on a bound (the data would put it
        outside the physical range: something else varies with the motor voltage)."""
        if self.thrust_model != "motor_voltage" or "thrust_motor_exponent" in self.fixed:
            return False
        n = self.values["thrust_motor_exponent"]
        return any(abs(n - b) < 1e-3 for b in self.exponent_bounds)

    @property
    def parameters(self) -> tuple[str, ...]:
        """The constants' names, in order (:data:`AIRFRAME_PARAMETERS` or
        :data:`MOTOR_VOLTAGE_PARAMETERS`)."""
        if self.thrust_model == "motor_voltage":
            return MOTOR_VOLTAGE_PARAMETERS
        return AIRFRAME_PARAMETERS

    @property
    def model_std_n(self) -> FloatArray:
        """(3,) the tension error the fitted constants leave, per world axis, N.

        The residual RMS after the fit with the degrees of freedom the fit used taken back,
        ``rms · sqrt(n_eff / (n_eff − p))`` (the unbiased residual variance of a least-squares
        fit, on the effective sample count: the residuals are autocorrelated): what is left
        between the thrust/attitude model and the motion-capture force, which the service
        cannot average away (it is the model's, not the vibration's), so its published σ
        carries it (``[calibration] tension_model_std_n``).
        """
        p = sum(1 for name in self.parameters if name not in self.fixed)
        dof = max(self.n_eff - p, 1.0)
        inflation: float = math.sqrt(max(self.n_eff, 1.0) / dof)
        out: FloatArray = self.rms_after_n * inflation
        return out

    @property
    def flight_spread_n(self) -> FloatArray:
        """(3,) standard deviation across flights of their mean residual, N (0 for one)."""
        if len(self.flights) < 2:
            return np.zeros(3)
        return np.std([f.residual_mean_n for f in self.flights], axis=0, ddof=1)


MOCAP_GAP_PERIODS = 1.5
"""A step of the drone's clock longer than this many median periods cuts a run of
motion-capture samples (derived: evenly spaced samples step by one period, give or take the
clock's jitter; a lost message makes a step of at least two)."""


def mocap_kinematics(
    data: CalibrationData, window_s: float = 0.25
) -> tuple[FloatArray, FloatArray]:
    """Motion-capture velocity and acceleration, world frame, (n, 3) each; NaN where unknown.

    Savitzky–Golay derivatives (cubic, ``window_s`` wide) per run of consecutive
    motion-capture samples, on the run's median sample period. The filter assumes evenly
    spaced samples: a run is also cut where the drone's clock steps by more than
    :data:`MOCAP_GAP_PERIODS` median periods (messages lost) or not forward.
    """
    n = len(data)
    vel = np.full((n, 3), math.nan)
    acc = np.full((n, 3), math.nan)
    for seg in np.unique(data.segment):
        idx = np.flatnonzero(data.segment == seg)
        have = np.all(np.isfinite(data.position_world_m[idx]), axis=1)
        # runs of consecutive samples with a position
        edges = np.diff(np.concatenate(([0], have.astype(np.int8), [0])))
        for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True):
            run = idx[a:b]
            if run.size < 2:
                continue
            steps = np.diff(data.stamp_s[run])
            dt_run = float(np.median(steps))
            if not dt_run > 0:
                continue
            cuts = np.flatnonzero(~(steps > 0) | (steps > MOCAP_GAP_PERIODS * dt_run)) + 1
            for piece in np.split(run, cuts):
                if piece.size < 9:
                    continue
                dt = float(np.median(np.diff(data.stamp_s[piece])))
                win = max(round(window_s / dt) | 1, 7)
                if win > piece.size:
                    continue
                p = data.position_world_m[piece]
                vel[piece] = savgol_filter(p, win, 3, deriv=1, delta=dt, axis=0)
                acc[piece] = savgol_filter(p, win, 3, deriv=2, delta=dt, axis=0)
    return vel, acc


def fit_airframe(
    data: CalibrationData,
    mass_kg: float,
    *,
    weight_n_per_m: float | None,
    floor_z_m: float = 0.0,
    vbat_ref_v: float = 3.9,
    samples: NDArray[np.bool_] | None = None,
    min_samples_s: float = 3.0,
    thrust_model: ThrustModel = "vbat_linear",
    pwm_map: tuple[float, float, float] = NOMINAL_PWM_MAP,
    exponent_bounds: tuple[float, float] = EXPONENT_BOUNDS,
) -> AirframeFit:
    """Fit the airframe constants (module doc) across every flight in ``data``.

    Robust least squares (scipy ``least_squares``, Huber loss) of the world-frame residual
    ``m·(g·e3 + p̈) − R·u·F + R·D·Rᵀ·v − T_ref`` per sample, each axis whitened by its robust
    scale; standard errors from ``(JᵀJ)⁻¹`` times the residual variance and the integrated
    autocorrelation time. The battery term (``k``, or the exponent ``n``) is fitted only
    when the battery spans :data:`MIN_VBAT_SPAN_V` (else ``k`` is fixed at 0, ``n`` at
    :data:`~groundstation.thrust_model.ROTOR_EXPONENT`), the drag only when the drone moved
    (:data:`MIN_SPEED_FOR_DRAG_MPS`, else 0); each fixed one is said so.

    Args:
        data: one drone's samples, one segment per recording (power-on).
        mass_kg: drone mass, kg (known: a mass error is a thrust-scale error).
        weight_n_per_m: tether ω, N/m; None for an untethered flight (true tension zero).
        floor_z_m: floor height, m (catenary floor contact; ground-effect cut).
        vbat_ref_v: voltage at which ``thrust_scale`` holds, V.
        samples: (n,) which samples to use; None: steady hover (tethered) or flight within
            :data:`MOVING` (untethered), at least :data:`MIN_HEIGHT_M` above the floor.
        min_samples_s: less usable flight than this is refused, s.
        thrust_model: ``vbat_linear`` or ``motor_voltage`` (module doc); the latter needs
            ``vbat_v`` on at least 90 % of the samples.
        pwm_map: ``motor_voltage``: the per-motor map that made ``thrust_n``.
        exponent_bounds: ``motor_voltage``: the exponent is fitted within these
            (:data:`~groundstation.thrust_model.EXPONENT_BOUNDS`); equal bounds fix it.

    Returns:
        The :class:`AirframeFit`.

    Raises:
        CalibrationError: too little usable flight, no catenary reference, or no battery
            voltage for ``motor_voltage``.
    """
    tethered = weight_n_per_m is not None
    m = float(mass_kg)
    vel, acc = mocap_kinematics(data)
    if samples is None:
        crit = HoverCriteria() if tethered else MOVING
        use = hover_mask(data, m, crit)
        use &= data.position_world_m[:, 2] >= floor_z_m + MIN_HEIGHT_M
    else:
        use = np.asarray(samples, bool).copy()
    use &= np.all(np.isfinite(vel), 1) & np.all(np.isfinite(acc), 1)
    use &= np.all(np.isfinite(data.quat_wxyz), 1) & np.isfinite(data.thrust_n)
    idx = np.flatnonzero(use)
    ref = np.zeros((idx.size, 3))
    if weight_n_per_m is not None and idx.size:
        unit, ok = _unit_tension(data, idx, np.zeros(3), floor_z_m)
        idx, ref = idx[ok], float(weight_n_per_m) * unit[ok]
    dt_med = float(np.median(np.diff(data.stamp_s))) if len(data) > 1 else 0.0
    if idx.size * dt_med < min_samples_s:
        raise CalibrationError(
            f"too short: {idx.size * dt_med:.1f} s of usable flight under motion capture "
            f"(need at least {min_samples_s:.1f} s)"
        )
    R = rotations_world_body(data.quat_wxyz[idx])
    thr = data.thrust_n[idx]
    vb = data.vbat_v[idx]
    have_v = np.isfinite(vb)
    dv = np.where(have_v, vb - vbat_ref_v, 0.0)
    v_w = vel[idx]
    # body-horizontal velocity, back in the world frame: R·P·Rᵀ·v
    v_b = np.einsum("nji,nj->ni", R, v_w)
    v_b[:, 2] = 0.0
    drag_dir = np.einsum("nij,nj->ni", R, v_b)
    kin = m * (acc[idx] + np.array([0.0, 0.0, GRAVITY_MPS2]))

    motor = thrust_model == "motor_voltage"
    names = MOTOR_VOLTAGE_PARAMETERS if motor else AIRFRAME_PARAMETERS
    scales = _MOTOR_SCALES if motor else _SCALES
    fixed: dict[str, str] = {}
    vbat_span = float(np.ptp(vb[have_v])) if have_v.any() else 0.0
    if motor and not have_v.mean() > 0.9:
        raise CalibrationError(
            f'thrust_model = "motor_voltage" needs vbat_v: {100 * have_v.mean():.0f} % of the '
            'usable samples carry it (use thrust_model = "vbat_linear")'
        )
    n_lo, n_hi = exponent_bounds
    if motor and n_lo == n_hi:
        fixed[names[3]] = f"fixed at {n_lo:g} (asked)"
    elif not (have_v.mean() > 0.9 and vbat_span >= MIN_VBAT_SPAN_V):
        fixed[names[3]] = (
            f"battery spans {vbat_span:.2f} V (< {MIN_VBAT_SPAN_V} V, or no vbat_v): fixed at "
            + (f"{ROTOR_EXPONENT:g} (thrust ∝ ω², ω ∝ motor voltage)" if motor else "0")
        )
    speed_h = np.linalg.norm(v_w[:, :2], axis=1)
    p90 = float(np.percentile(speed_h, 90)) if speed_h.size else 0.0
    if p90 < MIN_SPEED_FOR_DRAG_MPS:
        fixed["rotor_drag_n_s_per_m"] = (
            f"90th-percentile horizontal speed {p90:.2f} m/s (< {MIN_SPEED_FOR_DRAG_MPS} m/s): "
            "fixed at 0"
        )
    free = np.array([name not in fixed for name in names])
    motor_ref_v: float | None = None
    v_rel = np.ones_like(thr)  # motor voltage / its reference (motor_voltage only)
    if motor:
        v_motor = mean_motor_voltage_v_array(thr, np.where(have_v, vb, np.nanmedian(vb)), pwm_map)
        motor_ref_v = round(float(np.median(v_motor)), 3)
        v_rel = v_motor / motor_ref_v

    def residual(theta: FloatArray) -> FloatArray:
        s, ax, ay, k, d = theta
        u = np.asarray(thrust_axis_body(ax, ay))
        F = 4.0 * s * v_rel**k if motor else thr * (s + k * dv)
        thrust_w = np.einsum("nij,j->ni", R, u) * F[:, None]
        return kin - thrust_w + d * drag_dir - ref  # (n, 3), N

    # the exponent: fitted from the middle of its bounds (least_squares starts inside them),
    # else where it is fixed (asked, or the rotor's 2 when the battery does not vary)
    n_fixed = n_lo if n_lo == n_hi else ROTOR_EXPONENT
    n0 = 0.5 * (n_lo + n_hi) if names[3] not in fixed else n_fixed
    theta0 = np.array([1.0, 0.0, 0.0, n0 if motor else 0.0, 0.0])
    lower = np.full(5, -np.inf)
    upper = np.full(5, np.inf)
    if motor:
        lower[3], upper[3] = n_lo, n_hi
    # Rotor drag opposes the motion (physical; the configuration refuses a negative one:
    # unbounded, a flight with little drag in it fitted −5e-5 and calibrate failed on writing).
    lower[4] = 0.0
    r0 = kin - R[:, :, 2] * thr[:, None] - ref  # the nominal thrust along body z
    # Start the scale where the hover says (the nominal map may be far off).
    theta0[0] = float(np.median(kin[:, 2] - ref[:, 2]) / max(np.median(thr), 1e-9))
    if motor:
        theta0[0] = float(np.median(kin[:, 2] - ref[:, 2])) / 4.0
    segs = data.segment[idx]

    def whiten_scale(r: FloatArray) -> FloatArray:
        centred = r.copy()
        for sg in np.unique(segs):
            sel = segs == sg
            centred[sel] -= np.median(r[sel], axis=0)
        return np.array([max(_robust_scale(centred[:, j]), 1e-5) for j in range(3)])

    sig = whiten_scale(residual(theta0))

    def fun(x: FloatArray) -> FloatArray:
        th = theta0.copy()
        th[free] = x
        return (residual(th) / sig).ravel()

    bounds = (lower[free], upper[free])
    sol = least_squares(
        fun, theta0[free], loss="huber", f_scale=1.5, x_scale=scales[free], bounds=bounds
    )
    theta = theta0.copy()
    theta[free] = sol.x
    sig = whiten_scale(residual(theta))
    sol = least_squares(
        fun, theta[free], loss="huber", f_scale=1.5, x_scale=scales[free], bounds=bounds
    )
    theta[free] = sol.x
    r1 = residual(theta)

    # Standard errors: Huber's sandwich-free form, inflated by the autocorrelation time.
    z = fun(theta[free])
    J = sol.jac
    psi = np.clip(z, -1.5, 1.5)
    dpsi = max(float(np.mean(np.abs(z) <= 1.5)), 1e-3)
    dof = max(z.size - int(free.sum()), 1)
    sigma2 = float((psi * psi).sum() / dof) / dpsi**2
    runs = _index_runs(idx, data.segment)
    zr = z.reshape(-1, 3)
    tau = max(_integrated_autocorr_time(zr[:, j], runs) for j in range(3))
    try:
        cov = np.linalg.inv(J.T @ J) * sigma2 * tau
        diag = np.sqrt(np.maximum(np.diag(cov), 0.0))
    except np.linalg.LinAlgError:
        diag = np.full(int(free.sum()), math.inf)
    std: dict[str, float | None] = dict.fromkeys(names)
    for c, i in enumerate(np.flatnonzero(free).tolist()):
        std[names[i]] = float(diag[c])

    flights = []
    R_all = R
    f_body = data.accel_body_mps2[idx]
    expected = np.einsum("nji,nj->ni", R_all, acc[idx] + np.array([0.0, 0.0, GRAVITY_MPS2]))
    for sg in np.unique(segs).tolist():
        sel = segs == sg
        vseg = vb[sel][have_v[sel]]
        flights.append(
            FlightNuisance(
                segment=int(sg),
                samples=int(sel.sum()),
                accel_offset_body_mps2=np.nanmean(f_body[sel] - expected[sel], axis=0),
                residual_mean_n=r1[sel].mean(axis=0),
                vbat_range_v=(float(vseg.min()), float(vseg.max())) if vseg.size else None,
            )
        )
    return AirframeFit(
        values={p: float(theta[i]) for i, p in enumerate(names)},
        std=std,
        fixed=fixed,
        flights=tuple(flights),
        rms_before_n=np.sqrt((r0**2).mean(axis=0)),
        rms_after_n=np.sqrt((r1**2).mean(axis=0)),
        samples=int(idx.size),
        n_eff=float(idx.size / tau),
        vbat_ref_v=round(float(np.median(vb[have_v])), 3) if motor else float(vbat_ref_v),
        vbat_range_v=(float(vb[have_v].min()), float(vb[have_v].max())) if have_v.any() else None,
        tethered=tethered,
        thrust_model=thrust_model,
        motor_ref_v=motor_ref_v,
        pwm_map=pwm_map,
        exponent_bounds=exponent_bounds,
    )
