"""The hover's velocity scatter from flights under motion capture: σ_v and T_c, fitted.

Pure physics: numpy, and the estimator's own hover test (groundstation.slow_accel).

While the drone hovers the tension filter takes the thrust balance through the drone's
velocity (groundstation.tension_kalman.HoverVelocity): ``m·dv/dt = T − h`` with ``v = 0``
observed with variance ``σ_v²·T_c/dt`` per sample. How far the velocity strays in a hover
(σ_v) and how long it stays strayed (T_c, its correlation time) are properties of the drone
and its position controller, not of the estimator; a simulated hover and a real Crazyflie's
differ by 20× in σ_v. So they are measured where the velocity is known, in the calibration
flights::

    hover     = the service's hover test (slow_accel_step, without motion capture, as the
                service runs it), armed, above the floor
    d         = v_mocap − mean(v_mocap over the stretch)       # a constant velocity is no
                                                               # acceleration
    σ_v²      = mean(d²) over the stretches and the three axes
    T_c       = dt · τ_int,   τ_int = 1 + 2·Σ ρ_k               # per axis, Sokal's window,
                                                               # weighted by each axis' d²

``v_mocap`` is the positions' derivative on an even grid (:func:`bridged_velocity`: a lost
message or two bridged, as a Crazyflie's radio loses some). ``σ_v²·T_c`` is ``d``'s spectral
density at zero frequency (what a mean of ``v`` over a window much longer than T_c scatters
by), which the filter's observation variance is; it depends little on how the velocity was
smoothed, σ_v and T_c separately do more. A stretch is at least the hover test's own window
(``slow_accel.HOVER_MEAN_S``); a velocity that wanders over many seconds within a hover
(a slow drift of the spot) is partly taken out with each stretch's mean, which is what the
filter, whose velocity starts afresh with each hover, sees too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.signal import savgol_filter

from groundstation import slow_accel as slow_mod
from groundstation.airframe import MIN_HEIGHT_M
from groundstation.attitude import GRAVITY_MPS2, rotations_world_body, rows_from_quat_wxyz
from groundstation.calibration import (
    CalibrationData,
    RestCalibrator,
    _index_runs,
    _integrated_autocorr_time,
)
from groundstation.tension import (
    ObservationCalibration,
    TensionFilterParams,
    observe_tension,
    rotation_rows,
)
from groundstation.tension_change import exceedance_chi2, noise_warmup_samples
from groundstation.tension_noise import NoiseEstimate

__all__ = [
    "HOVER_FIT_MIN_S",
    "FlightFit",
    "FlightPhases",
    "HoverVelocityFit",
    "fit_flight",
    "fit_hover_velocity",
    "flight_phases",
    "hover_flags",
]

FloatArray = NDArray[np.float64]

VELOCITY_WINDOW_S = 0.25
"""Width of the Savitzky–Golay derivative (cubic) of the motion-capture positions, s: the
airframe fit's (``airframe.mocap_kinematics``)."""

BRIDGE_PERIODS = 5.0
"""A step of the drone's clock up to this many median periods is bridged (the positions
interpolated onto an even grid; a lost Telemetry message or two: a Crazyflie's radio drops
some), a longer one cuts the run: hand-set, well inside T_c's scale (0.05 s at 100 Hz)."""

HOVER_FIT_MIN_S = 3.0
"""Hover (stretches of at least ``slow_accel.HOVER_MEAN_S``) under motion capture needed to
fit σ_v and T_c, s: hand-set, the same minimum as ``calibrate``'s steady hover
(``recording.calibrate.MIN_HOVER_S``); below it the defaults stand."""


@dataclass(frozen=True)
class HoverVelocityFit:
    """Result of :func:`fit_hover_velocity`.

    Attributes:
        std_mps: σ_v, the velocity's scatter about each stretch's mean, per world axis, m/s.
        time_s: T_c, its correlation time, s.
        hover_s: seconds of hover used.
        stretches: hover stretches used.
    """

    std_mps: float
    time_s: float
    hover_s: float
    stretches: int


@dataclass(frozen=True)
class FlightPhases:
    """Per sample of a recording, what the service's stages say (:func:`flight_phases`).

    Attributes:
        hovering: (n,) the hover test's verdict.
        airborne: (n,) the slow stage's phase is "air".
        rest_mean_body_mps2: (n, 3) the latest rest window's mean of ``f − Rᵀ·g·e3`` (the
            configured bias subtracted) in the recording so far, m/s²; NaN before any.
    """

    hovering: NDArray[np.bool_]
    airborne: NDArray[np.bool_]
    rest_mean_body_mps2: FloatArray


def hover_flags(
    data: CalibrationData,
    params: slow_mod.SlowAccelParams,
    *,
    mass_kg: float,
    floor_z_m: float,
    ground_thrust_ratio: float,
    accel_bias_mps2: tuple[float, float, float] = (0.0, 0.0, 0.0),
    min_height_m: float = MIN_HEIGHT_M,
) -> NDArray[np.bool_]:
    """(n,) where the service's hover test says the drone hovers (:func:`flight_phases`)."""
    return flight_phases(
        data,
        params,
        mass_kg=mass_kg,
        floor_z_m=floor_z_m,
        ground_thrust_ratio=ground_thrust_ratio,
        accel_bias_mps2=accel_bias_mps2,
        min_height_m=min_height_m,
    ).hovering


def flight_phases(
    data: CalibrationData,
    params: slow_mod.SlowAccelParams,
    *,
    mass_kg: float,
    floor_z_m: float,
    ground_thrust_ratio: float,
    accel_bias_mps2: tuple[float, float, float] = (0.0, 0.0, 0.0),
    min_height_m: float = MIN_HEIGHT_M,
) -> FlightPhases:
    """``slow_accel_step`` run over each recording as the service runs it without motion
    capture ("rest" while the rest detector says disarmed and still, β its window mean; "air"
    while armed, at or above ``ground_thrust_ratio`` of the weight and ``min_height_m`` above
    the floor by motion capture; "hold" otherwise), the configured accelerometer bias
    subtracted: where it hovers, where it flies, and the rests' means. The vibration its
    hover test scales with is measured as the service's tension filter measures it
    (:class:`~groundstation.tension_noise.NoiseEstimate`, the filter's default settings),
    on the world-frame specific force ``R·f`` in the air: the observation less the
    thrust's share of its noise; the density at the recording's median sample spacing."""
    n = len(data)
    out = np.zeros(n, bool)
    airborne = np.zeros(n, bool)
    rest_mean = np.full((n, 3), math.nan)
    weight_n = mass_kg * GRAVITY_MPS2
    bx, by, bz = accel_bias_mps2
    noise_params = TensionFilterParams()
    prior_var = noise_params.accel_noise_mps2**2
    for seg in np.unique(data.segment):
        state = slow_mod.SlowAccelState()
        rest = RestCalibrator(bias_body_mps2=accel_bias_mps2)
        noise = NoiseEstimate(
            (prior_var,) * 3, noise_params.noise_prior_samples, noise_params.false_alarms_per_h
        )
        steps = np.diff(data.stamp_s[data.segment == seg])
        spacing_s = float(np.median(steps)) if steps.size else math.nan
        # The hover test's threshold at the recording's spacing (the service's, at its
        # measured one): the one false-alarm rate.
        hover_chi2 = exceedance_chi2(noise_params.false_alarms_per_h, spacing_s)
        last: float | None = None
        latest_rest = (math.nan, math.nan, math.nan)
        tau = noise_params.noise_time_constant_s
        warmup = noise_warmup_samples()
        for i in np.flatnonzero(data.segment == seg).tolist():
            stamp = float(data.stamp_s[i])
            dt = 0.0 if last is None else max(stamp - last, 0.0)
            last = stamp
            z = float(data.position_world_m[i, 2])
            armed = bool(data.armed[i])
            air = (
                armed
                and float(data.thrust_n[i]) >= ground_thrust_ratio * weight_n
                and math.isfinite(z)
                and z >= floor_z_m + min_height_m
            )
            a = data.accel_body_mps2[i]
            gyro = data.gyro_rps[i]
            rest.update(
                stamp, a, data.quat_wxyz[i], armed, gyro if np.all(np.isfinite(gyro)) else None
            )
            phase: slow_mod.Phase = "air" if air else "hold"
            if not armed and rest.still:
                phase = "rest"
            R = rows_from_quat_wxyz(tuple(data.quat_wxyz[i].tolist()))
            # The specific force less the configured bias, body frame: the hover test's input
            # and, rotated to the world, the vibration's measure.
            f = (float(a[0]) - bx, float(a[1]) - by, float(a[2]) - bz)
            density = None
            if air:
                world = [r[0] * f[0] + r[1] * f[1] + r[2] * f[2] for r in R]
                r0, r1, r2 = noise.push(world, dt, math.exp(-dt / tau), tau, warmup)
                if spacing_s > 0.0:
                    density = (r0 + r1 + r2) / 3.0 * spacing_s
            else:
                noise.break_chain()
            state = slow_mod.slow_accel_step(
                state,
                params,
                dt_s=dt,
                stamp_s=stamp,
                accel_body_mps2=f,
                R_world_body=R,
                phase=phase,
                mocap_world_m=None,
                rest_mean_body_mps2=rest.rest_mean_body_mps2 if phase == "rest" else None,
                accel_density_m2ps3=density,
                hover_chi2=hover_chi2,
            )
            out[i] = state.quasi_static
            airborne[i] = phase == "air"
            if phase == "rest" and rest.rest_mean_body_mps2 is not None:
                latest_rest = rest.rest_mean_body_mps2
            rest_mean[i] = latest_rest
    return FlightPhases(out, airborne, rest_mean)


def bridged_velocity(data: CalibrationData) -> FloatArray:
    """Motion-capture velocity at each sample, world frame, (n, 3), m/s; NaN where unknown.

    Per run of consecutive samples with a position (within one recording, the clock's steps
    at most :data:`BRIDGE_PERIODS` median periods), the positions are interpolated onto an
    even grid at the run's median period, differentiated there (Savitzky–Golay, cubic,
    :data:`VELOCITY_WINDOW_S`) and read back at the samples' times.
    """
    n = len(data)
    vel = np.full((n, 3), math.nan)
    for seg in np.unique(data.segment):
        idx = np.flatnonzero((data.segment == seg) & np.all(np.isfinite(data.position_world_m), 1))
        if idx.size < 9:
            continue
        t_all = data.stamp_s[idx]
        steps = np.diff(t_all)
        period = float(np.median(steps))
        if not period > 0:
            continue
        cuts = np.flatnonzero(~(steps > 0) | (steps > BRIDGE_PERIODS * period)) + 1
        for piece in np.split(idx, cuts):
            t = data.stamp_s[piece]
            if piece.size < 9 or t[-1] - t[0] < VELOCITY_WINDOW_S:
                continue
            grid = np.arange(t[0], t[-1] + 0.5 * period, period)
            win = max(round(VELOCITY_WINDOW_S / period) | 1, 7)
            if win > grid.size:
                continue
            p = data.position_world_m[piece]
            pg = np.stack([np.interp(grid, t, p[:, k]) for k in range(3)], 1)
            vg = savgol_filter(pg, win, 3, deriv=1, delta=period, axis=0)
            vel[piece] = np.stack([np.interp(t, grid, vg[:, k]) for k in range(3)], 1)
    return vel


def _velocity_runs(
    data: CalibrationData, mask: NDArray[np.bool_], velocity_world_mps: FloatArray | None = None
) -> tuple[FloatArray, NDArray[np.int64], list[tuple[int, int]], list[float], float]:
    """The motion-capture velocity (:func:`bridged_velocity`) and the runs of ``mask`` where it
    is known that last at least the hover test's window (``slow_accel.HOVER_MEAN_S``) and 3
    samples: ``(velocity, indices, runs into the indices, each run's median period, seconds
    they span)``."""
    vel = bridged_velocity(data) if velocity_world_mps is None else velocity_world_mps
    idx = np.flatnonzero(mask & np.all(np.isfinite(vel), axis=1))
    runs: list[tuple[int, int]] = []
    dts: list[float] = []
    for a, b in _index_runs(idx, data.segment):
        t = data.stamp_s[idx[a:b]]
        if b - a >= 3 and t[-1] - t[0] >= slow_mod.HOVER_MEAN_S:
            runs.append((a, b))
            dts.append(float(np.median(np.diff(t))))
    seconds = float(sum((b - a) * dt for (a, b), dt in zip(runs, dts, strict=True)))
    return vel, idx, runs, dts, seconds


def _correlation_time_s(
    v: FloatArray, runs: list[tuple[int, int]], dts: list[float], var_axes: FloatArray
) -> float:
    """dt · τ_int per axis (Sokal's window, on the runs' mean-removed series), weighted by
    each axis' variance, s."""
    tau = np.array([_integrated_autocorr_time(v[:, k], runs) for k in range(3)])
    return float(np.median(dts)) * float((var_axes * tau).sum() / var_axes.sum())


def fit_hover_velocity(
    data: CalibrationData,
    hovering: NDArray[np.bool_],
    *,
    min_hover_s: float = HOVER_FIT_MIN_S,
    velocity_world_mps: FloatArray | None = None,
) -> tuple[HoverVelocityFit | None, float]:
    """σ_v and T_c from the motion-capture velocity in the hover stretches (module doc).

    Args:
        data: the drone's samples (with motion-capture positions).
        hovering: (n,) the hover test's verdict per sample (:func:`hover_flags`).
        min_hover_s: below this much hover nothing is fitted.
        velocity_world_mps: :func:`bridged_velocity` of ``data`` if already computed
            (``calibrate`` computes it once for every fit), else None.

    Returns:
        ``(fit or None, seconds of hover found)``.
    """
    vel, idx, runs, dts, hover_s = _velocity_runs(data, hovering, velocity_world_mps)
    if not runs or hover_s < min_hover_s:
        return None, hover_s
    v = vel[idx]
    d = np.concatenate([v[a:b] - v[a:b].mean(axis=0) for a, b in runs])
    var_axes = (d * d).mean(axis=0)
    var = float(var_axes.mean())
    if not var > 0.0:
        return None, hover_s
    time_s = _correlation_time_s(v, runs, dts, var_axes)
    fit = HoverVelocityFit(
        std_mps=math.sqrt(var), time_s=time_s, hover_s=hover_s, stretches=len(runs)
    )
    return fit, hover_s


@dataclass(frozen=True)
class FlightFit:
    """Result of :func:`fit_flight`.

    Attributes:
        velocity_std_mps: σ_V, the airborne velocity's scatter about zero per world axis,
            m/s.
        velocity_time_s: T_V, its correlation time, s.
        bias_std_mps2: σ_δ, the RMS over flights and body axes of the bias in the air less
            the rest's before it, m/s²; None without a flight that followed a rest.
        airborne_s: seconds of flight under motion capture used.
        flights: airborne runs used for σ_δ.
    """

    velocity_std_mps: float
    velocity_time_s: float
    bias_std_mps2: float | None
    airborne_s: float
    flights: int


def fit_flight(
    data: CalibrationData,
    phases: FlightPhases,
    *,
    accel_bias_mps2: tuple[float, float, float] = (0.0, 0.0, 0.0),
    min_airborne_s: float = HOVER_FIT_MIN_S,
    velocity_world_mps: FloatArray | None = None,
) -> tuple[FlightFit | None, float]:
    """The bias filter's model of the flight (groundstation.bias_kalman) from the recording::

        σ_V²  = mean(v_mocap²) over the airborne samples and the three axes
        T_V   = dt · τ_int (Sokal's window, per axis, weighted by each axis' v²)
        δ     = mean over a flight of f − b_cfg − Rᵀ·(g·e3 + a_mocap)  −  the rest's mean before it
        σ_δ²  = mean(δ²) over the flights that follow a rest and the three axes

    ``v_mocap`` is :func:`bridged_velocity`, ``a_mocap`` its time derivative; a flight is a run
    of airborne samples of at least ``slow_accel.HOVER_MEAN_S`` with a velocity
    (``velocity_world_mps``: that velocity if already computed, else None).

    Returns:
        ``(fit or None, seconds of flight found)``.
    """
    vel, idx, runs, dts, airborne_s = _velocity_runs(data, phases.airborne, velocity_world_mps)
    if not runs or airborne_s < min_airborne_s:
        return None, airborne_s
    v = vel[idx]
    sq = np.concatenate([v[a:b] ** 2 for a, b in runs])
    var_axes = sq.mean(axis=0)
    var = float(var_axes.mean())
    if not var > 0.0:
        return None, airborne_s
    time_s = _correlation_time_s(v, runs, dts, var_axes)
    deltas: list[FloatArray] = []
    bias = np.asarray(accel_bias_mps2, float)
    for a, b in runs:
        piece = idx[a:b]
        rest = phases.rest_mean_body_mps2[piece[0]]
        if not np.all(np.isfinite(rest)):
            continue
        t = data.stamp_s[piece]
        acc = np.gradient(vel[piece], t, axis=0)
        ref = acc + np.array([0.0, 0.0, GRAVITY_MPS2])
        rot = rotations_world_body(data.quat_wxyz[piece])
        e = data.accel_body_mps2[piece] - bias - np.einsum("nji,nj->ni", rot, ref)  # f − b − Rᵀ·ref
        deltas.append(e.mean(axis=0) - rest)
    bias_std = float(np.sqrt(np.mean(np.square(deltas)))) if deltas else None
    fit = FlightFit(
        velocity_std_mps=math.sqrt(var),
        velocity_time_s=time_s,
        bias_std_mps2=bias_std,
        airborne_s=airborne_s,
        flights=len(deltas),
    )
    return fit, airborne_s


BALANCE_BLOCK_S = VELOCITY_WINDOW_S
"""Block of the thrust balance's fit, s (:func:`fit_hover_balance`): derived, the velocity
derivative's width, so that the velocities at two block boundaries share no position and
their errors are independent (the model's third term is then a difference of independent
errors)."""

BALANCE_MIN_BLOCKS = 4
"""A hover stretch gives the balance fit its block differences only from this many blocks
on (derived: ``slow_mod.HOVER_MEAN_S`` / :data:`BALANCE_BLOCK_S`, the hover test's own
shortest stretch)."""


@dataclass(frozen=True)
class HoverBalanceFit:
    """Result of :func:`fit_hover_balance`.

    Attributes:
        wander_n2_per_s: q_w, the random walk's spectral density of the tension the thrust
            balance reads at hover (the true tension's wander and the balance's own slow
            error together: what the filter's tension state must follow), N²/s.
        balance_density_n2s: D, the thrust balance's white noise as a force density
            (the filter's velocity state's process noise at hover is D/m²), N²·s.
        velocity_error_std_mps: the motion-capture velocity's error at a block boundary,
            per axis, m/s (a nuisance of the fit, printed).
        wander_resolved: the data tell q_w from no wander at all: twice the log-likelihood
            ratio against q_w at :data:`WANDER_FLOOR_N2_PER_S` (D and σ_e fitted again)
            exceeds :data:`RESOLVED_LR` (q_w's ±2σ likelihood interval excludes zero); else
            the value is not a measurement and is not written.
        blocks: block differences used (per axis).
        hover_s: seconds of hover used.
        stretches: hover stretches used.
    """

    wander_n2_per_s: float
    balance_density_n2s: float
    velocity_error_std_mps: float
    wander_resolved: bool
    blocks: int
    hover_s: float
    stretches: int


RESOLVED_LR = 4.0
"""Twice the log-likelihood ratio at which the hover's wander counts as resolved: derived,
the square of the 2 standard errors at which the service's σ is read everywhere (a
χ² of one degree of freedom; the likelihood interval's ±2σ)."""

WANDER_FLOOR_N2_PER_S = 1e-14
"""Lower bound of q_w in the likelihood's search, N²/s: a numerical guard (a tension wander
of 0.1 µN over 1 s, a millionth of a 30 g drone's weight), not a tunable."""


def balance_blocks(
    stamp_s: FloatArray,
    balance_world_n: FloatArray,
    velocity_world_mps: FloatArray,
    mass_kg: float,
    block_s: float = BALANCE_BLOCK_S,
) -> FloatArray:
    """The tension the thrust balance reads, per block of one hover stretch, (K, 3), N::

        Y_k = (∫ h dt over block k) / Δt_k + m·(v(t_(k+1)) − v(t_k)) / Δt_k

    Newton at hover (``m·dv/dt = T − h``, groundstation.tension_kalman.HoverVelocity)
    integrated over the block: the block's mean tension, plus the balance's noise and the
    boundary velocities' errors. Blocks start at the stretch's first sample and at the
    first sample at or after each ``block_s`` from it; the last, shorter one is dropped.
    """
    t = np.asarray(stamp_s, float)
    k = np.floor((t - t[0]) / block_s + 1e-9).astype(np.int64)
    starts = np.flatnonzero(np.diff(np.concatenate(([-1], k))) != 0)
    if starts.size < 2:
        return np.empty((0, 3))
    dt = np.diff(t)
    hdt = balance_world_n[:-1] * dt[:, None]
    cum = np.vstack([np.zeros((1, 3)), np.cumsum(hdt, axis=0)])
    a, b = starts[:-1], starts[1:]
    span = (t[b] - t[a])[:, None]
    return (cum[b] - cum[a]) / span + mass_kg * (
        velocity_world_mps[b] - velocity_world_mps[a]
    ) / span


def _balance_nll(
    theta: FloatArray, diffs: list[FloatArray], block_s: float, mass_kg: float
) -> float:
    """Negative log-likelihood (constants dropped) of the block differences ΔY of
    :func:`fit_hover_balance`'s model, θ = log(q_w, D, σ_e²); each column of each array one
    stretch and axis."""
    from scipy.linalg import cho_solve_banded, cholesky_banded

    q, dens, ev = np.exp(theta)
    c2 = (mass_kg / block_s) ** 2 * ev
    g0 = 2.0 * q * block_s / 3.0 + 2.0 * dens / block_s + 6.0 * c2
    g1 = q * block_s / 6.0 - dens / block_s - 4.0 * c2
    g2 = c2
    total = 0.0
    for d in diffs:
        n = d.shape[0]
        ab = np.zeros((3, n))
        ab[0, 2:] = g2
        ab[1, 1:] = g1
        ab[2, :] = g0
        try:
            ch = cholesky_banded(ab, lower=False)
        except np.linalg.LinAlgError:
            return math.inf
        x = cho_solve_banded((ch, False), d)
        total += 0.5 * (d.shape[1] * 2.0 * float(np.log(ch[2]).sum()) + float((d * x).sum()))
    return total


def fit_hover_balance(
    data: CalibrationData,
    hovering: NDArray[np.bool_],
    balance_world_n: FloatArray,
    *,
    mass_kg: float,
    min_hover_s: float = HOVER_FIT_MIN_S,
    block_s: float = BALANCE_BLOCK_S,
    velocity_world_mps: FloatArray | None = None,
    axes: tuple[int, ...] = (0, 1, 2),
) -> tuple[HoverBalanceFit | None, float]:
    """q_w and D of the hover's thrust balance from the recording, by maximum likelihood.

    In each hover stretch under motion capture (:func:`_velocity_runs`, the service's hover
    test), the block series ``Y_k`` of :func:`balance_blocks` is modelled per world axis as

        Y_k = L̄_k + e_k + (m/B)·(ε_(k+1) − ε_k)

    with L a random walk of density q_w (the tension as the balance reads it), e_k the
    balance's white noise over the block (variance D/B) and ε_k the motion-capture
    velocity's error at a boundary (variance σ_e², independent: :data:`BALANCE_BLOCK_S`).
    Differenced once (the level is unknown per stretch), ΔY is a moving average of order 2
    whose autocovariances are, with c² = (m/B)²·σ_e²:

        γ0 = 2·q_w·B/3 + 2·D/B + 6·c²      (a random walk's block means: 2B/3, B/6 at lag 1)
        γ1 = q_w·B/6 − D/B − 4·c²
        γ2 = c²

    and its exact Gaussian likelihood (banded Cholesky), summed over the stretches and the
    world axes ``axes`` (all three: one q_w and one D, as the filter has; one of them, for a
    diagnosis per axis), is maximised over log(q_w, D, σ_e²)
    (scipy L-BFGS-B). The three are told apart by the differences' autocovariance at lags
    0–2: the wander by its positive lag-1 share, the balance's noise by a negative one at
    lag 1 only, the velocity's error by lag 2.

    Args:
        data: the drone's samples (with motion-capture positions).
        hovering: (n,) the hover test's verdict per sample.
        balance_world_n: (n, 3) the thrust balance ``m·g·e3 − R·u·F`` per sample as the
            service computes it (NaN where unknown), N.
        mass_kg: the drone's mass, kg.
        min_hover_s: below this much hover nothing is fitted.
        block_s: the block, s.
        velocity_world_mps: :func:`bridged_velocity` of ``data`` if already computed
            (``calibrate`` computes it once for every fit), else None.
        axes: the world axes (0, 1, 2: x, y, z) whose likelihoods are summed.

    Returns:
        ``(fit or None, seconds of hover found)``.
    """
    from scipy.optimize import minimize

    ok = hovering & np.all(np.isfinite(balance_world_n), axis=1)
    vel, idx, runs, _dts, hover_s = _velocity_runs(data, ok, velocity_world_mps)
    diffs: list[FloatArray] = []
    used_s = 0.0
    for a, b in runs:
        piece = idx[a:b]
        y = balance_blocks(
            data.stamp_s[piece], balance_world_n[piece], vel[piece], mass_kg, block_s
        )
        if y.shape[0] < BALANCE_MIN_BLOCKS:
            continue
        diffs.append(np.diff(y, axis=0)[:, list(axes)])
        used_s += y.shape[0] * block_s
    if not diffs or used_s < min_hover_s:
        return None, hover_s
    # Start from the moments (γ0, γ2 pooled); the search spans the data's own scale, in
    # the units of q_w, D and σ_e² (``units``: γ0 taken as each one's alone).
    pooled = np.concatenate(diffs)
    g0 = float((pooled**2).mean())
    lag2 = [(d[2:] * d[:-2]).ravel() for d in diffs if len(d) > 2]
    g2 = max(float(np.concatenate(lag2).mean()), 0.0) if lag2 else 0.0
    velocity_units = (block_s / mass_kg) ** 2
    units = g0 * np.array([1.0 / block_s, block_s, velocity_units])
    c2_0 = max(g2, 1e-6 * g0)
    start = np.log(
        [
            max(0.1 * units[0], 10.0 * WANDER_FLOOR_N2_PER_S),
            max(0.25 * (g0 - 6.0 * c2_0) * block_s, 1e-6 * units[1]),
            c2_0 * velocity_units,
        ]
    )
    lo = np.log([WANDER_FLOOR_N2_PER_S, *(1e-9 * units[1:])])
    hi = np.log(1e3 * units)
    res = minimize(
        _balance_nll,
        np.clip(start, lo, hi),
        args=(diffs, block_s, mass_kg),
        method="L-BFGS-B",
        bounds=list(zip(lo.tolist(), hi.tolist(), strict=True)),
    )
    q, dens, ev = np.exp(res.x)
    # The same without wander (q_w at the floor), D and σ_e fitted again.
    nuisance = minimize(
        lambda x: _balance_nll(np.concatenate((lo[:1], x)), diffs, block_s, mass_kg),
        res.x[1:],
        method="L-BFGS-B",
        bounds=list(zip(lo[1:].tolist(), hi[1:].tolist(), strict=True)),
    )
    resolved = 2.0 * (float(nuisance.fun) - float(res.fun)) > RESOLVED_LR
    fit = HoverBalanceFit(
        wander_n2_per_s=float(q),
        balance_density_n2s=float(dens),
        velocity_error_std_mps=math.sqrt(float(ev)),
        wander_resolved=resolved,
        blocks=int(pooled.shape[0]),
        hover_s=used_s,
        stretches=len(diffs),
    )
    return fit, hover_s


def balance_world_n(
    data: CalibrationData,
    mask: NDArray[np.bool_],
    *,
    mass_kg: float,
    calibration: ObservationCalibration | None,
    velocity_world_mps: FloatArray | None = None,
) -> FloatArray:
    """(n, 3) the thrust balance ``m·g·e3 − R·u·F`` (+ the rotor drag at the motion-capture
    velocity) at the samples of ``mask``, world frame, N; NaN elsewhere and where no tension
    is observed (disarmed, low thrust). The service's own observation
    (:func:`~groundstation.tension.observe_tension`) of a drone that does not accelerate:
    the accelerometer as reading ``Rᵀ·g·e3`` (plus the calibration's bias, which it
    subtracts), so that ``m·R·f`` is ``m·g·e3``. ``velocity_world_mps``: :func:`bridged_velocity`
    of ``data`` if already computed, else None."""
    out = np.full((len(data), 3), math.nan)
    bias = np.zeros(3) if calibration is None else np.asarray(calibration.accel_bias_mps2)
    vel = bridged_velocity(data) if velocity_world_mps is None else velocity_world_mps
    for i in np.flatnonzero(mask).tolist():
        rows = rotation_rows(data.quat_wxyz[i])  # the service's, once for both uses
        f = np.array(rows[2]) * GRAVITY_MPS2 + bias  # Rᵀ·g·e3: R's third row
        v = vel[i]
        vbat = float(data.vbat_v[i])
        obs = observe_tension(
            f,
            data.quat_wxyz[i],
            float(data.thrust_n[i]),
            mass_kg,
            armed=bool(data.armed[i]),
            calibration=calibration,
            vbat_v=vbat if math.isfinite(vbat) and vbat > 0.0 else None,
            velocity_world_mps=(float(v[0]), float(v[1]), float(v[2]))
            if np.all(np.isfinite(v))
            else None,
            rotation_rows_world_body=rows,
        )
        if obs.tension_world_n is not None:
            out[i] = obs.tension_world_n
    return out
