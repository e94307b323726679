"""Calibration of thrust scale, thrust axis and accelerometer offsets from recorded samples.

Pure physics: numpy and scipy only; time enters as ``stamp_s``. Two estimators:

* :func:`fit_calibration` fits, per drone, the parameters of the observation model of
  :class:`groundstation.config.CalibrationSection` (the tension observation eq:NE_tether with
  corrections)::

      f = accel_mps2 − b                                  # body frame, m/s²
      F = thrust_n · (s + k · (vbat_v − v_ref))           # N
      u = R_x(about_x) · R_y(about_y) · e3                # thrust axis, body frame
      T = m · R · f − R · u · F                           # eq:NE_tether, world frame, N

  by robust least squares against the tension the catenary gives at the motion-capture
  position (:func:`groundstation.catenary.tether_force`), on hover segments only (or against
  zero for an untethered drone). Optionally the tether's ω and a base offset too.
* :class:`RestCalibrator` estimates the accelerometer's x/y offset while the drone sits
  disarmed and still on the floor, against the attitude it reports (at rest the specific
  force is ``R_world_bodyᵀ · (0, 0, g)`` whatever else pulls on the drone: the floor and the
  tether together carry its weight). Assumption: the floor under the drone is what the
  attitude says; a tilted floor that the attitude does not show becomes an offset.

What the data can tell apart (see docs/calibration.md). In the body frame the model's
residual is ``m·(a − b) − u·F·s − R_world_bodyᵀ·T_ref``: ``b`` enters as a constant, ``s·u``
multiplied by the nominal thrust. So a z accelerometer bias and the thrust scale are told
apart only by the spread of the thrust (different vertical tensions at different spots,
manoeuvres), and an x/y bias and the thrust axis likewise; the attitude does not help.
Samples at rest (disarmed, still) carry the bias alone and separate all of it. Whatever the
data leave undetermined (its standard error above a physical scale, from the Jacobian) is
fixed to a convention (:data:`CONVENTIONS`) and said so.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares

from groundstation.attitude import (
    GRAVITY_MPS2,
    QUAT_MIN_NORM,
    STILL_WINDOW_S,
    rotations_world_body,
    rows_from_quat_wxyz,
)
from groundstation.catenary import CatenaryError, locate_with_floor, tether_force
from groundstation.tension import GAP_S, thrust_axis_body

__all__ = [
    "CONVENTIONS",
    "GRAVITY_MPS2",
    "PARAMETERS",
    "CalibrationData",
    "CalibrationError",
    "CalibrationFit",
    "FixedParameter",
    "HoverCriteria",
    "RestCalibrator",
    "RestCriteria",
    "RestOffset",
    "SpotError",
    "fit_calibration",
    "hover_mask",
    "rest_mask",
]

FloatArray = NDArray[np.float64]

PARAMETERS: tuple[str, ...] = (
    "thrust_scale",
    "about_x_rad",
    "about_y_rad",
    "bias_x_mps2",
    "bias_y_mps2",
    "bias_z_mps2",
    "vbat_slope_per_v",
    "weight_n_per_m",
    "base_dx_m",
    "base_dy_m",
    "base_dz_m",
)
"""The parameter vector, in order. ``base_d*`` is an offset added to the recorded base."""

_SCALES = np.array([0.05, 0.02, 0.02, 0.2, 0.2, 0.2, 0.1, 0.01, 0.05, 0.05, 0.05])
"""Typical magnitude of each parameter: a combination whose standard error exceeds half of
it (:data:`UNDETERMINED_RATIO`) is taken as undetermined by the data."""
_SCALES.setflags(write=False)  # after its docstring, which would otherwise describe nothing

UNDETERMINED_RATIO = 0.5
_PRIOR_RATIO = 10.0

CONVENTIONS: tuple[tuple[str, str], ...] = (
    (
        "bias_z_mps2",
        "not separable from thrust_scale with this little spread of thrust (hover); fixed at "
        "0: thrust_scale absorbs m·b_z/F, exact at the thrust of the calibration hover",
    ),
    (
        "about_y_rad",
        "not separable from the x accelerometer bias with this little spread of thrust (one "
        "spot, or spots of similar tension); fixed at 0: bias_x absorbs it",
    ),
    (
        "about_x_rad",
        "not separable from the y accelerometer bias with this little spread of thrust; "
        "fixed at 0: bias_y absorbs it",
    ),
    ("vbat_slope_per_v", "battery voltage does not vary enough apart from thrust; fixed at 0"),
    ("base_dz_m", "not determined by these spots; base height kept as recorded/configured"),
    ("base_dx_m", "not determined by these spots; base x kept as recorded/configured"),
    ("base_dy_m", "not determined by these spots; base y kept as recorded/configured"),
    ("weight_n_per_m", "not determined by these spots; ω kept as configured"),
    ("bias_x_mps2", "not determined; fixed at 0"),
    ("bias_y_mps2", "not determined; fixed at 0"),
)
"""Order in which undetermined parameters are fixed, and the reason printed for each."""

_CONVENTION_VALUE = MappingProxyType(
    {
        "thrust_scale": 1.0,
        "about_x_rad": 0.0,
        "about_y_rad": 0.0,
        "bias_x_mps2": 0.0,
        "bias_y_mps2": 0.0,
        "bias_z_mps2": 0.0,
        "vbat_slope_per_v": 0.0,
        "base_dx_m": 0.0,
        "base_dy_m": 0.0,
        "base_dz_m": 0.0,
    }
)


class CalibrationError(ValueError):
    """The samples cannot be calibrated from (too few, no motion capture, ...)."""


# ------------------------------------------------------------------------------- the data


@dataclass(frozen=True)
class CalibrationData:
    """Telemetry samples of one drone, as arrays (one row per sample).

    Attributes:
        stamp_s: (n,) sample time, s, increasing within a segment.
        accel_body_mps2: (n, 3) IMU specific force, body frame, m/s² (raw).
        quat_wxyz: (n, 4) reported attitude, body → world.
        thrust_n: (n,) nominal collective thrust, N.
        armed: (n,) motors armed.
        position_world_m: (n, 3) motion-capture position, m; NaN where absent.
        gyro_rps: (n, 3) body rates, rad/s; NaN where absent.
        vbat_v: (n,) battery voltage, V; NaN where absent.
        length_m: (n,) tether length at the sample, m (ignored untethered).
        base_world_m: (n, 3) base exit point at the sample, m (ignored untethered).
        segment: (n,) int, the recording (power-on) each sample belongs to: hover runs and
            rest windows never span two segments.
    """

    stamp_s: FloatArray
    accel_body_mps2: FloatArray
    quat_wxyz: FloatArray
    thrust_n: FloatArray
    armed: NDArray[np.bool_]
    position_world_m: FloatArray
    gyro_rps: FloatArray
    vbat_v: FloatArray
    length_m: FloatArray
    base_world_m: FloatArray
    segment: NDArray[np.int64]

    @classmethod
    def from_arrays(
        cls,
        stamp_s: ArrayLike,
        accel_body_mps2: ArrayLike,
        quat_wxyz: ArrayLike,
        thrust_n: ArrayLike,
        *,
        armed: ArrayLike | None = None,
        position_world_m: ArrayLike | None = None,
        gyro_rps: ArrayLike | None = None,
        vbat_v: ArrayLike | None = None,
        length_m: ArrayLike | float = 1.0,
        base_world_m: ArrayLike | None = None,
        segment: ArrayLike | None = None,
    ) -> CalibrationData:
        """Build from array-likes, filling absent columns (NaN, armed, zeros).

        Raises:
            CalibrationError: shapes that do not agree.
        """
        t = np.asarray(stamp_s, dtype=float).reshape(-1)
        n = t.size

        def col(value: ArrayLike | None, width: int, fill: float) -> FloatArray:
            if value is None:
                return np.full((n, width) if width > 1 else n, fill)
            arr = np.asarray(value, dtype=float)
            if width > 1 and arr.shape == (width,):
                arr = np.tile(arr, (n, 1))
            elif width == 1 and arr.ndim == 0:
                arr = np.full(n, float(arr))
            expect = (n, width) if width > 1 else (n,)
            if arr.shape != expect:
                raise CalibrationError(f"column of shape {arr.shape}, expected {expect}")
            return arr

        return cls(
            stamp_s=t,
            accel_body_mps2=col(accel_body_mps2, 3, math.nan),
            quat_wxyz=col(quat_wxyz, 4, math.nan),
            thrust_n=col(thrust_n, 1, math.nan),
            armed=np.ones(n, bool) if armed is None else np.asarray(armed, bool).reshape(n),
            position_world_m=col(position_world_m, 3, math.nan),
            gyro_rps=col(gyro_rps, 3, math.nan),
            vbat_v=col(vbat_v, 1, math.nan),
            length_m=col(length_m, 1, 1.0),
            base_world_m=col(base_world_m, 3, 0.0),
            segment=(
                np.zeros(n, np.int64)
                if segment is None
                else np.asarray(segment, np.int64).reshape(n)
            ),
        )

    def __len__(self) -> int:
        return int(self.stamp_s.size)


# -------------------------------------------------------------------- sample selection


@dataclass(frozen=True)
class HoverCriteria:
    """What counts as a hover sample (motion from the motion-capture track).

    Attributes:
        max_speed_mps: speed limit, m/s (from a ±``window_s`` central difference).
        max_accel_mps2: acceleration limit, m/s².
        max_gyro_rps: body-rate limit, rad/s (when the gyro is present).
        min_thrust_ratio: thrust at least this fraction of the weight (else on the ground).
        settle_s: samples this close to any excluded one are excluded too (transients).
        min_run_s: shortest hover run kept, s.
        window_s: half-width of the differences for speed and acceleration, s.

    A stamp gap longer than :data:`~groundstation.tension.GAP_S` ends a run.
    """

    max_speed_mps: float = 0.10
    max_accel_mps2: float = 0.6
    max_gyro_rps: float = 0.5
    min_thrust_ratio: float = 0.5
    settle_s: float = 1.0
    min_run_s: float = 1.0
    window_s: float = 0.1


def _runs(ok: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """Half-open index ranges of the True runs of ``ok``."""
    edges = np.diff(np.concatenate(([0], ok.astype(np.int8), [0])))
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1)
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


def _erode(stamp_s: FloatArray, ok: NDArray[np.bool_], margin_s: float) -> NDArray[np.bool_]:
    """``ok`` minus every sample within ``margin_s`` of a not-ok sample (same array)."""
    bad_t = stamp_s[~ok]
    if bad_t.size == 0 or margin_s <= 0.0:
        return ok.copy()
    bad_t = np.sort(bad_t)
    idx = np.searchsorted(bad_t, stamp_s)
    after = np.abs(bad_t[np.minimum(idx, bad_t.size - 1)] - stamp_s)
    before = np.abs(stamp_s - bad_t[np.maximum(idx - 1, 0)])
    return ok & (np.minimum(after, before) >= margin_s)


def _segments(data: CalibrationData) -> list[NDArray[np.int64]]:
    return [np.flatnonzero(data.segment == s) for s in np.unique(data.segment)]


def _keep_long_runs(
    stamp_s: FloatArray, ok: NDArray[np.bool_], min_run_s: float, max_gap_s: float
) -> NDArray[np.bool_]:
    out = np.zeros_like(ok)
    gaps = np.concatenate(([False], np.diff(stamp_s) > max_gap_s))
    for i0, i1 in _runs(ok):
        # split at stamp gaps
        cuts = [i0, *[int(i) for i in np.flatnonzero(gaps[i0 + 1 : i1]) + i0 + 1], i1]
        for a, b in itertools.pairwise(cuts):
            if b - a >= 2 and stamp_s[b - 1] - stamp_s[a] >= min_run_s:
                out[a:b] = True
    return out


def hover_mask(
    data: CalibrationData, mass_kg: float, criteria: HoverCriteria = HoverCriteria()
) -> NDArray[np.bool_]:
    """Samples taken in steady hover under motion capture (transients, ground excluded).

    A sample qualifies when it is armed, has a motion-capture position, thrust at least
    ``min_thrust_ratio`` of the weight, and speed, acceleration and body rate within the
    limits; then everything within ``settle_s`` of a sample that does not qualify is dropped
    (take-off, landing, the move between spots), and runs shorter than ``min_run_s``.

    Returns:
        (n,) bool.
    """
    c = criteria
    out = np.zeros(len(data), bool)
    for idx in _segments(data):
        t = data.stamp_s[idx]
        p = data.position_world_m[idx]
        have_p = np.all(np.isfinite(p), axis=1)
        ok = data.armed[idx] & have_p
        ok &= data.thrust_n[idx] >= c.min_thrust_ratio * mass_kg * GRAVITY_MPS2
        if np.count_nonzero(have_p) >= 3:
            tp, pp = t[have_p], p[have_p]
            h = c.window_s
            fwd = np.stack([np.interp(t + h, tp, pp[:, k]) for k in range(3)], 1)
            mid = np.stack([np.interp(t, tp, pp[:, k]) for k in range(3)], 1)
            bwd = np.stack([np.interp(t - h, tp, pp[:, k]) for k in range(3)], 1)
            speed = np.linalg.norm(fwd - bwd, axis=1) / (2 * h)
            acc = np.linalg.norm(fwd - 2 * mid + bwd, axis=1) / (h * h)
            # the ends of the track, where interp clamps, are not known to be still
            inside = (t - h >= tp[0]) & (t + h <= tp[-1])
            ok &= inside & (speed <= c.max_speed_mps) & (acc <= c.max_accel_mps2)
        else:
            ok &= False
        g = data.gyro_rps[idx]
        have_g = np.all(np.isfinite(g), axis=1)
        ok &= ~have_g | (
            np.linalg.norm(np.where(have_g[:, None], g, 0.0), axis=1) <= c.max_gyro_rps
        )
        ok = _erode(t, ok, c.settle_s)
        out[idx] = _keep_long_runs(t, ok, c.min_run_s, GAP_S)
    return out


@dataclass(frozen=True)
class RestCriteria:
    """What counts as sitting still on the floor (for :data:`STILL_WINDOW_S` at least).

    Attributes:
        max_gyro_rps: body-rate limit per sample, rad/s (when the gyro is present).
        max_accel_dev_mps2: largest deviation of a sample from the window's mean, per axis.
        max_gravity_dev_mps2: largest | |f| − g | of the window's mean (an accelerometer
            that does not read about g is not at rest, or is not calibrated at all).

    A stamp gap longer than :data:`~groundstation.tension.GAP_S` restarts the window.
    """

    max_gyro_rps: float = 0.05
    max_accel_dev_mps2: float = 0.15
    max_gravity_dev_mps2: float = 1.0


def rest_mask(data: CalibrationData, criteria: RestCriteria = RestCriteria()) -> NDArray[np.bool_]:
    """Samples taken disarmed and still (the same test :class:`RestCalibrator` applies)."""
    out = np.zeros(len(data), bool)
    for idx in _segments(data):
        cal = RestCalibrator(criteria)
        still = np.zeros(idx.size, bool)
        for j, i in enumerate(idx.tolist()):
            cal.update(
                float(data.stamp_s[i]),
                data.accel_body_mps2[i],
                data.quat_wxyz[i],
                bool(data.armed[i]),
                None if not np.all(np.isfinite(data.gyro_rps[i])) else data.gyro_rps[i],
            )
            if cal.window_samples and cal.window_duration_s >= STILL_WINDOW_S:
                still[j - cal.window_samples + 1 : j + 1] = True
        out[idx] = still
    return out


# ------------------------------------------------------------------------ rest estimator


@dataclass(frozen=True)
class RestOffset:
    """The accelerometer offset found at rest, to add to the configured bias.

    Attributes:
        offset_body_mps2: (3,) offset, body frame, m/s²; z is 0 (x/y only, see module doc).
        std_mps2: (3,) its standard error per axis (white-noise: σ/√n; z 0).
        samples: samples in the still window.
        duration_s: length of the window, s.
        stamp_s: time of the window's last sample, s.
    """

    offset_body_mps2: FloatArray
    std_mps2: FloatArray
    samples: int
    duration_s: float
    stamp_s: float


class RestCalibrator:
    """The accelerometer's x/y offset from a still, disarmed drone; and the one test of
    "still on the floor" the estimator has (the slow stage learns its β at rest from
    :attr:`still` and :attr:`rest_mean_body_mps2`).

    Feed every telemetry sample to :meth:`update`. While the drone is disarmed and still
    (every sample's gyro within ``max_gyro_rps``, its accelerometer within
    ``max_accel_dev_mps2`` of the window mean) for at least :data:`STILL_WINDOW_S`, the
    offset is::

        o = mean(a − b_cfg − R_world_bodyᵀ · (0, 0, g))     # x, y; z set to 0

    (``b_cfg`` the configured bias, so that configured bias + offset is what the rest shows).
    It holds from then on, through the flight, until the next disarm clears it; a move during
    the window restarts the window, so a drone that is never still gets no offset.

    Assumption (stated, tested): the floor under the drone is what the attitude says, i.e.
    the specific force at rest is ``R_world_bodyᵀ · (0, 0, g)``; the floor and the tether
    together carry the weight whatever the tether pulls. A tilt the attitude does not show
    becomes an offset of g·tilt (0.17 m/s² per degree).

    Args:
        criteria: the stillness test.
        bias_body_mps2: the configured accelerometer bias (subtracted first), m/s².
    """

    def __init__(
        self,
        criteria: RestCriteria = RestCriteria(),
        bias_body_mps2: ArrayLike = (0.0, 0.0, 0.0),
        gravity_mps2: float = GRAVITY_MPS2,
    ) -> None:
        self.criteria = criteria
        self._bias = np.asarray(bias_body_mps2, dtype=float).reshape(3)
        self._g = float(gravity_mps2)
        self._offset: RestOffset | None = None
        self._armed_prev: bool | None = None
        self._sum = self._sum2 = self._sum_a = self._first_accel = np.zeros(3)
        self._still = False
        self._mean: tuple[float, float, float] | None = None
        self._clear_window()

    def _clear_window(self) -> None:
        # The sums restart with the window's first sample (cheap while armed: every sample).
        self._n = 0
        self._t0 = self._t_last = math.nan
        self._mean = None

    @property
    def still(self) -> bool:
        """The last sample was taken disarmed and still (it entered the still window)."""
        return self._still

    @property
    def rest_mean_body_mps2(self) -> tuple[float, float, float] | None:
        """The still window's mean of ``a − b_cfg − R_world_bodyᵀ·(0, 0, g)`` on all three
        axes, body frame, m/s², once the window has lasted :data:`STILL_WINDOW_S` and reads
        about g
        (None before, and from the next sample that is not still)."""
        return self._mean

    @property
    def offset(self) -> RestOffset | None:
        """The offset in force (None: none since the last disarm, or never still enough)."""
        return self._offset

    @property
    def armed(self) -> bool | None:
        """The last sample's ``armed`` (None before any sample)."""
        return self._armed_prev

    @property
    def window_samples(self) -> int:
        """Samples in the current still window."""
        return self._n

    @property
    def window_duration_s(self) -> float:
        """Length of the current still window, s (0 when empty)."""
        return 0.0 if self._n < 2 else self._t_last - self._t0

    def update(
        self,
        stamp_s: float,
        accel_body_mps2: ArrayLike,
        quat_wxyz: ArrayLike,
        armed: bool,
        gyro_rps: ArrayLike | None = None,
    ) -> RestOffset | None:
        """Feed one sample; returns the offset in force after it.

        Non-finite inputs are ignored (the window restarts).
        """
        c = self.criteria
        if self._armed_prev is True and not armed:
            self._offset = None  # cleared at disarm: the next rest measures afresh
            self._clear_window()
        self._armed_prev = armed
        self._still = False
        if armed:
            if self._n:
                self._clear_window()
            return self._offset
        a = np.asarray(accel_body_mps2, dtype=float).reshape(3)
        q = np.asarray(quat_wxyz, dtype=float).reshape(4)
        qn = float(np.linalg.norm(q)) if np.all(np.isfinite(q)) else math.nan
        if not (np.all(np.isfinite(a)) and qn > QUAT_MIN_NORM and math.isfinite(stamp_s)):
            self._clear_window()
            return self._offset
        moving = False
        if gyro_rps is not None:
            g = np.asarray(gyro_rps, dtype=float).reshape(3)
            moving = not (np.all(np.isfinite(g)) and float(np.linalg.norm(g)) <= c.max_gyro_rps)
        if self._n and (stamp_s - self._t_last > GAP_S or stamp_s <= self._t_last):
            self._clear_window()
        if self._n and not moving:
            mean_a = self._first_accel + self._sum_a / self._n
            moving = bool(np.any(np.abs(a - mean_a) > c.max_accel_dev_mps2))
        if moving:
            self._clear_window()
            return self._offset
        down_body = np.array(rows_from_quat_wxyz(q.tolist())[2])  # Rᵀ·e3
        d = a - self._bias - down_body * self._g  # a − b − Rᵀ (0, 0, g)
        if self._n == 0:
            self._t0 = stamp_s
            self._first_accel = a.copy()
            self._sum = np.zeros(3)  # Σ (a − b − Rᵀ g e3)
            self._sum2 = np.zeros(3)
            self._sum_a = np.zeros(3)  # Σ (a − first a): the window's mean accelerometer
        self._sum_a = self._sum_a + (a - self._first_accel)
        self._n += 1
        self._t_last = stamp_s
        self._sum += d
        self._sum2 += d * d
        self._still = True
        if self.window_duration_s >= STILL_WINDOW_S:
            mean = self._sum / self._n
            gravity_dev = abs(
                float(np.linalg.norm(mean + self._bias + down_body * self._g)) - self._g
            )
            if gravity_dev <= c.max_gravity_dev_mps2:
                self._mean = (float(mean[0]), float(mean[1]), float(mean[2]))
                var = np.maximum(self._sum2 / self._n - mean * mean, 0.0)
                std = np.sqrt(var / max(self._n - 1, 1))
                self._offset = RestOffset(
                    offset_body_mps2=np.array([mean[0], mean[1], 0.0]),
                    std_mps2=np.array([std[0], std[1], 0.0]),
                    samples=self._n,
                    duration_s=self.window_duration_s,
                    stamp_s=stamp_s,
                )
        return self._offset


# ------------------------------------------------------------------------------ the fit


@dataclass(frozen=True)
class FixedParameter:
    """A parameter the data could not determine, fixed to a convention."""

    name: str
    value: float
    reason: str


@dataclass(frozen=True)
class SpotError:
    """The predicted position error at one hover spot (a hover run).

    Attributes:
        position_world_m: (3,) mean motion-capture position of the run, m.
        samples: samples in the run.
        before_m: |position offset| from the mean tension residual before the fit, m.
        after_m: the same after the fit, m.
        uncertainty_m: position standard deviation from the parameters' covariance, m.
    """

    position_world_m: FloatArray
    samples: int
    before_m: float
    after_m: float
    uncertainty_m: float


@dataclass(frozen=True)
class CalibrationFit:
    """Result of :func:`fit_calibration`.

    Attributes:
        values: every parameter of :data:`PARAMETERS` (fitted, fixed or as given).
        std: standard error of each fitted parameter (None for fixed or not fitted), with
            the residual variance and inflated for autocorrelation (``n / n_eff``).
        fitted: names of the parameters the data determined.
        fixed: parameters fixed to a convention, with the reason.
        rms_before_n: (3,) RMS of the tension residual per world axis with the starting
            calibration, N (hover samples).
        rms_after_n: (3,) the same after the fit, N.
        mean_before_n / mean_after_n: (3,) mean residual, N.
        hover_samples: hover samples used; rest_samples: still, disarmed samples used.
        hover_s: hover time used, s.
        n_eff: effective sample size of the hover residuals (autocorrelation).
        condition: condition number of the scaled Jacobian of the parameters fitted.
        spots: predicted position error per hover run (empty untethered).
        notes: lines to print (what was fixed and why, assumptions).
    """

    values: dict[str, float]
    std: dict[str, float | None]
    fitted: tuple[str, ...]
    fixed: tuple[FixedParameter, ...]
    rms_before_n: FloatArray
    rms_after_n: FloatArray
    mean_before_n: FloatArray
    mean_after_n: FloatArray
    hover_samples: int
    rest_samples: int
    hover_s: float
    n_eff: float
    condition: float
    spots: tuple[SpotError, ...]
    notes: tuple[str, ...]
    vbat_ref_v: float
    vbat_range_v: tuple[float, float] | None = None
    """Battery voltage range of the hover samples, V (None without ``vbat_v``)."""


def _integrated_autocorr_time(z: FloatArray, runs: list[tuple[int, int]]) -> float:
    """τ = 1 + 2 Σ ρ_k of a residual series split in runs, Sokal's window (M ≥ 5τ).

    The runs' autocovariances are pooled (each run's own mean removed).
    """
    max_lag = max((b - a for a, b in runs), default=0) // 2
    if max_lag < 2:
        return 1.0
    max_lag = min(max_lag, 2000)
    acov = np.zeros(max_lag + 1)
    counts = np.zeros(max_lag + 1)
    for a, b in runs:
        x = z[a:b] - z[a:b].mean()
        n = x.size
        m = min(max_lag, n - 1)
        # autocovariance by FFT
        nfft = 1 << (2 * n - 1).bit_length()
        fx = np.fft.rfft(x, nfft)
        ac = np.fft.irfft(fx * np.conj(fx), nfft)[: m + 1]
        acov[: m + 1] += ac
        counts[: m + 1] += np.arange(n, n - m - 1, -1)
    valid = counts > 0
    if not valid[0] or acov[0] <= 0:
        return 1.0
    rho = np.where(valid, acov / np.maximum(counts, 1), 0.0) / (acov[0] / counts[0])
    tau = 1.0
    for k in range(1, max_lag + 1):
        tau += 2.0 * rho[k]
        if k >= 5.0 * tau:
            break
    return float(max(tau, 1.0))


def _robust_scale(r: FloatArray) -> float:
    med = np.median(r)
    return float(1.4826 * np.median(np.abs(r - med)))


def fit_calibration(
    data: CalibrationData,
    mass_kg: float,
    *,
    weight_n_per_m: float | None,
    floor_z_m: float = -math.inf,
    initial: dict[str, float] | None = None,
    vbat_ref_v: float = 3.9,
    fit_vbat: bool | None = None,
    fit_tether: bool = False,
    rest_offsets_body_mps2: ArrayLike | None = None,
    hover: ArrayLike | None = None,
    hover_criteria: HoverCriteria = HoverCriteria(),
    rest: ArrayLike | None = None,
    rest_bias_xy: bool = True,
    min_hover_s: float = 3.0,
    fix: dict[str, str] | None = None,
) -> CalibrationFit:
    """Fit the calibration of one drone (module doc; eq:NE_tether against the catenary).

    Residual per hover sample, world frame, N::

        r = R·(m·(a − o − b) − u(about_x, about_y)·F) − T_ref
        F = thrust_n·(s + k·(vbat − v_ref)),  T_ref = tether_force(base + δbase, p, L, ω)

    (``T_ref = 0`` untethered; ``o`` the rest offset the service would apply, if given); per
    rest sample ``r = R·m·(a − o − b) − (0, 0, m·g)``. Each world axis is whitened by its
    robust scale (hover and rest apart, around each run's mean), fitted with scipy's
    ``least_squares`` (Huber loss), re-whitened with the fit's residuals and fitted again.
    Standard errors: Huber's ``(Σψ²/(n−p))/(mean ψ')²·(JᵀJ)⁻¹``, times τ, the residuals'
    integrated autocorrelation time (vibration and wobble are not white: n_eff = n/τ). A
    combination of parameters whose standard error exceeds half its typical magnitude is
    undetermined: the first parameter of :data:`CONVENTIONS` in it is fixed and the fit repeated.

    Args:
        data: the samples (see :class:`CalibrationData`).
        mass_kg: drone mass, kg (taken as known: a mass error is a thrust-scale error).
        weight_n_per_m: tether ω, N/m; None for an untethered drone (true tension 0).
        floor_z_m: floor height for the catenary, m.
        initial: starting values by name (missing: 1 for the scale, 0 else; ω from above).
            Parameters not fitted keep these values.
        vbat_ref_v: voltage at which ``thrust_scale`` holds, V.
        fit_vbat: fit the voltage slope; None: when the hover samples carry ``vbat_v`` and
            it varies at all (≥ 0.02 V); the detection then decides whether it is determined.
        fit_tether: fit ω and a base offset too (tethered only).
        rest_offsets_body_mps2: (n, 3) per-sample rest offset the service would subtract on
            top of the bias (from :class:`RestCalibrator`), or None.
        hover: (n,) hover mask; None: :func:`hover_mask` with ``hover_criteria``.
        rest: (n,) rest mask (disarmed, still); None: :func:`rest_mask`.
        rest_bias_xy: use the rest samples' x/y too (False when the service's rest
            calibration supplies x/y at every power-on: then only their z is used).
        min_hover_s: less hover than this is refused, s.
        fix: parameters to keep at their ``initial`` value from the start, name → reason
            (reported among :attr:`CalibrationFit.fixed`).

    Returns:
        The :class:`CalibrationFit`.

    Raises:
        CalibrationError: too little hover, or no usable catenary reference.
    """
    n = len(data)
    tethered = weight_n_per_m is not None
    init = {name: 0.0 for name in PARAMETERS}
    init["thrust_scale"] = 1.0
    init["weight_n_per_m"] = float(weight_n_per_m) if weight_n_per_m is not None else 0.0
    for key, val in (initial or {}).items():
        if key not in init:
            raise CalibrationError(f"unknown parameter {key!r}")
        init[key] = float(val)
    hov = hover_mask(data, mass_kg, hover_criteria) if hover is None else np.asarray(hover, bool)
    rst = rest_mask(data) if rest is None else np.asarray(rest, bool)
    finite = np.all(np.isfinite(data.accel_body_mps2), 1) & np.all(np.isfinite(data.quat_wxyz), 1)
    hov = hov & finite & np.isfinite(data.thrust_n)
    rst = rst & ~hov & finite
    offsets = (
        np.zeros((n, 3))
        if rest_offsets_body_mps2 is None
        else np.nan_to_num(np.asarray(rest_offsets_body_mps2, float).reshape(n, 3))
    )
    notes: list[str] = []

    # The catenary's tension per unit ω at each hover sample; taut samples are dropped.
    h_idx = np.flatnonzero(hov)
    if tethered:
        g0, ok = _unit_tension(data, h_idx, np.zeros(3), floor_z_m)
        g0 = g0 + 0.0
        if h_idx.size and not ok.all():
            notes.append(f"{int((~ok).sum())} hover samples dropped: no catenary there (taut)")
        h_idx, g0 = h_idx[ok], g0[ok]
    else:
        g0 = np.zeros((h_idx.size, 3))
    runs = _index_runs(h_idx, data.segment)
    hover_s = float(sum(data.stamp_s[h_idx[b - 1]] - data.stamp_s[h_idx[a]] for a, b in runs))
    if hover_s < min_hover_s:
        raise CalibrationError(
            f"too short: {hover_s:.1f} s of steady hover under motion capture "
            f"(need at least {min_hover_s:.1f} s)"
        )

    r_idx = np.flatnonzero(rst)
    R_h = rotations_world_body(data.quat_wxyz[h_idx])
    R_r = rotations_world_body(data.quat_wxyz[r_idx])
    acc_h = data.accel_body_mps2[h_idx] - offsets[h_idx]
    acc_r = data.accel_body_mps2[r_idx] - offsets[r_idx]
    thr_h = data.thrust_n[h_idx]
    vb = data.vbat_v[h_idx]
    have_v = np.isfinite(vb)
    dv = np.where(have_v, vb - vbat_ref_v, 0.0)
    if fit_vbat is None:
        fit_vbat = (
            bool(have_v.mean() > 0.9 and np.ptp(vb[have_v]) >= 0.02) if have_v.any() else False
        )
    if fit_tether and not tethered:
        fit_tether = False
        notes.append("--fit-tether ignored: untethered")

    cache: dict[tuple[float, float, float], FloatArray] = {(0.0, 0.0, 0.0): g0}

    def unit_tension(dbase: FloatArray) -> FloatArray:
        key = (float(dbase[0]), float(dbase[1]), float(dbase[2]))
        hit = cache.get(key)
        if hit is None:
            hit, _ = _unit_tension(data, h_idx, dbase, floor_z_m)
            if len(cache) > 32:
                cache.clear()
            cache[key] = hit
        return hit

    m = float(mass_kg)
    rest_axes = np.array([True, True, True]) if rest_bias_xy else np.array([False, False, True])
    weight_world = np.array([0.0, 0.0, m * GRAVITY_MPS2])

    def model(theta: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(hover residuals (nh, 3), rest residuals (nr, 3)), world frame, N."""
        s, ax, ay, bx, by, bz, k, om = theta[:8]
        u = np.asarray(thrust_axis_body(ax, ay))
        b = np.array([bx, by, bz])
        F = thr_h * (s + k * dv)
        body = m * (acc_h - b) - F[:, None] * u[None, :]  # m·f − u·F, body frame
        res_h = np.einsum("nij,nj->ni", R_h, body)  # T = R (m f − u F), eq:NE_tether
        if tethered:
            res_h = res_h - om * unit_tension(theta[8:11])
        res_r = np.einsum("nij,nj->ni", R_r, m * (acc_r - b)) - weight_world
        return res_h, res_r

    theta0 = np.array([init[p] for p in PARAMETERS])
    free = np.ones(len(PARAMETERS), bool)
    free[PARAMETERS.index("vbat_slope_per_v")] = fit_vbat
    for name in ("weight_n_per_m", "base_dx_m", "base_dy_m", "base_dz_m"):
        free[PARAMETERS.index(name)] = fit_tether

    res_h0, res_r0 = model(theta0)
    mean_before = res_h0.mean(axis=0)
    rms_before = np.sqrt((res_h0**2).mean(axis=0))

    def scales(res_h: FloatArray, res_r: FloatArray) -> tuple[FloatArray, FloatArray]:
        # Per axis, around each run's mean (a starting calibration's offsets are not noise).
        centred = np.concatenate([res_h[a:b] - res_h[a:b].mean(0) for a, b in runs])
        sh = np.array([max(_robust_scale(centred[:, k]), 1e-6) for k in range(3)])
        if res_r.shape[0] > 1:
            cr = res_r - res_r.mean(0)
            sr = np.array([max(_robust_scale(cr[:, k]), 1e-6) for k in range(3)])
        else:
            sr = sh.copy()
        return sh, sr

    sig = list(scales(res_h0, res_r0))
    huber = 1.5

    def whitened(theta: FloatArray) -> FloatArray:
        rh, rr = model(theta)
        parts = [(rh / sig[0]).ravel()]
        if rr.shape[0]:
            parts.append((rr / sig[1])[:, rest_axes].ravel())
        return np.concatenate(parts)

    def solve(theta_start: FloatArray, mask: NDArray[np.bool_]) -> FloatArray:
        prior_mean = theta0[mask]
        prior_w = 1.0 / (_PRIOR_RATIO * _SCALES[mask])

        def fun(x: FloatArray) -> FloatArray:
            th = theta_start.copy()
            th[mask] = x
            # A very weak prior at the start (10× each typical magnitude) keeps an
            # undetermined direction from wandering off before it is detected and fixed;
            # it is left out of the covariance and the detection.
            return np.concatenate((whitened(th), (x - prior_mean) * prior_w))

        res = least_squares(
            fun, theta_start[mask], loss="huber", f_scale=huber, x_scale=_SCALES[mask]
        )
        out = theta_start.copy()
        out[mask] = res.x
        return out

    def covariance(
        theta: FloatArray, mask: NDArray[np.bool_]
    ) -> tuple[FloatArray, FloatArray, float, float]:
        """(JᵀJ of the free parameters, σ̂²·(JᵀJ)⁻¹·τ, σ̂²·τ, τ)."""
        z0 = whitened(theta)
        idx = np.flatnonzero(mask)
        J = np.zeros((z0.size, idx.size))
        for c, i in enumerate(idx.tolist()):
            step = 1e-4 * _SCALES[i]
            tp, tm = theta.copy(), theta.copy()
            tp[i] += step
            tm[i] -= step
            J[:, c] = (whitened(tp) - whitened(tm)) / (2 * step)
        # Huber's M-estimator covariance: (Σψ²/(n − p)) / (mean ψ')² · (JᵀJ)⁻¹, with
        # ψ(z) = clip(z, ±k) (Huber 1981, sec. 7.6; statsmodels RLM "H1").
        psi = np.clip(z0, -huber, huber)
        dpsi = float(np.mean(np.abs(z0) <= huber))
        info = J.T @ J
        dof = max(z0.size - idx.size, 1)
        sigma2 = float((psi * psi).sum() / dof) / max(dpsi, 1e-3) ** 2
        zh = z0[: h_idx.size * 3].reshape(-1, 3)
        tau = max(_integrated_autocorr_time(zh[:, k], runs) for k in range(3))
        var = sigma2 * tau
        try:
            cov = np.asarray(np.linalg.inv(info), dtype=np.float64) * var
        except np.linalg.LinAlgError:
            cov = np.full((idx.size, idx.size), np.inf)
        return info, cov, var, tau

    fixed: list[FixedParameter] = []
    for name, why in (fix or {}).items():
        if name not in PARAMETERS:
            raise CalibrationError(f"unknown parameter {name!r}")
        if free[PARAMETERS.index(name)]:
            fixed.append(FixedParameter(name, init[name], why))
            free[PARAMETERS.index(name)] = False
    theta = theta0.copy()
    for _ in range(len(PARAMETERS)):
        theta = theta0.copy()
        for f in fixed:
            theta[PARAMETERS.index(f.name)] = f.value
        theta = solve(theta, free)
        sig[:] = scales(*model(theta))
        theta = solve(theta, free)
        info, cov, var, tau = covariance(theta, free)
        idx = np.flatnonzero(free)
        D = _SCALES[idx]
        # Eigen-decompose the information in scaled units (the covariance is its inverse;
        # its small eigenvalues, the undetermined directions, are accurate there).
        lam, evecs = np.linalg.eigh(info * np.outer(D, D))
        evals = var / np.maximum(lam, 1e-300)  # variance along each direction, scaled units
        cond = float(math.sqrt(lam.max() / max(lam.min(), 1e-300)))
        bad = evals > UNDETERMINED_RATIO**2
        if not bad.any():
            break
        # The undetermined subspace (eigenvalues of nearly equal size mix their vectors):
        # a parameter is in it when its unit vector projects onto it noticeably.
        basis = evecs[:, bad]
        weight = np.linalg.norm(basis, axis=1)  # |projection of e_j| for each free j
        involved = {
            PARAMETERS[i] for i, wj in zip(idx.tolist(), weight.tolist(), strict=True) if wj >= 0.3
        }
        pick = next(((nm, why) for nm, why in CONVENTIONS if nm in involved), None)
        if pick is None:
            raise CalibrationError("the samples do not determine the thrust scale")
        name, why = pick
        value = init[name] if name == "weight_n_per_m" else _CONVENTION_VALUE[name]
        fixed.append(FixedParameter(name, value, why))
        free[PARAMETERS.index(name)] = False
    else:  # pragma: no cover - the thrust scale alone is always determined by hover
        raise CalibrationError("the samples determine nothing")

    res_h1, _ = model(theta)
    idx = np.flatnonzero(free)
    std: dict[str, float | None] = {p: None for p in PARAMETERS}
    for c, i in enumerate(idx.tolist()):
        std[PARAMETERS[i]] = float(math.sqrt(max(cov[c, c], 0.0)))
    values = {p: float(theta[i]) for i, p in enumerate(PARAMETERS)}

    spots: tuple[SpotError, ...] = ()
    if tethered:
        spots = _spot_errors(data, h_idx, runs, theta, idx, cov, res_h0, res_h1, model, floor_z_m)
    vbat_range = (float(vb[have_v].min()), float(vb[have_v].max())) if have_v.any() else None
    if vbat_range is not None and not free[PARAMETERS.index("vbat_slope_per_v")]:
        notes.append(
            f"battery {vbat_range[0]:.2f}–{vbat_range[1]:.2f} V in these hovers: thrust_scale "
            "holds there; the battery's effect on thrust is not calibrated (calibrate over a "
            "wider voltage range to fit thrust_vbat_slope_per_v)"
        )
    if r_idx.size:
        notes.append(
            f"{r_idx.size} still, disarmed samples constrain the accelerometer bias"
            + ("" if rest_bias_xy else " (z only: rest calibration supplies x/y per power-on)")
        )
    return CalibrationFit(
        values=values,
        std=std,
        fitted=tuple(PARAMETERS[i] for i in idx.tolist()),
        fixed=tuple(fixed),
        rms_before_n=rms_before,
        rms_after_n=np.sqrt((res_h1**2).mean(axis=0)),
        mean_before_n=mean_before,
        mean_after_n=res_h1.mean(axis=0),
        hover_samples=int(h_idx.size),
        rest_samples=int(r_idx.size),
        hover_s=hover_s,
        n_eff=float(h_idx.size / tau),
        condition=cond,
        spots=spots,
        notes=tuple(notes),
        vbat_ref_v=float(vbat_ref_v),
        vbat_range_v=vbat_range,
    )


def _index_runs(idx: NDArray[np.int64], segment: NDArray[np.int64]) -> list[tuple[int, int]]:
    """Runs of consecutive sample indices within one segment, as ranges into ``idx``."""
    if idx.size == 0:
        return []
    cut = (np.diff(idx) != 1) | (np.diff(segment[idx]) != 0)
    starts = np.concatenate(([0], np.flatnonzero(cut) + 1))
    ends = np.concatenate((starts[1:], [idx.size]))
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


def _unit_tension(
    data: CalibrationData, idx: NDArray[np.int64], dbase: FloatArray, floor_z_m: float
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Catenary force on the drone per unit ω (it is linear in ω), (len(idx), 3), and where
    it exists (not taut)."""
    g = np.zeros((idx.size, 3))
    ok = np.ones(idx.size, bool)
    off = np.asarray(dbase, float)
    for j, i in enumerate(idx.tolist()):
        try:
            f = tether_force(
                data.base_world_m[i] + off,
                data.position_world_m[i],
                float(data.length_m[i]),
                1.0,
                floor_z_m,
            ).force_world_n
        except CatenaryError:
            ok[j] = False
            continue
        if np.all(np.isfinite(f)):
            g[j] = f
        else:
            ok[j] = False
    return g, ok


def _position_from_tension(
    tension_world_n: FloatArray,
    weight_n_per_m: float,
    length_m: float,
    base_world_m: FloatArray,
    floor_z_m: float,
) -> FloatArray:
    """Drone position from the tension on it (eq:posfull_*, with floor contact)."""
    h = float(math.hypot(tension_world_n[0], tension_world_n[1]))
    loc = locate_with_floor(
        h,
        -float(tension_world_n[2]),
        weight_n_per_m,
        length_m,
        float(base_world_m[2]),
        floor_z_m if math.isfinite(floor_z_m) else -1e9,
    )
    r = float(loc.r_m)
    u = -tension_world_n[:2] / h if h > 0 else np.zeros(2)  # T_xy = −H û
    return np.array([base_world_m[0] + r * u[0], base_world_m[1] + r * u[1], float(loc.z_m)])


def _spot_errors(
    data: CalibrationData,
    h_idx: NDArray[np.int64],
    runs: list[tuple[int, int]],
    theta: FloatArray,
    free_idx: NDArray[np.int64],
    cov: FloatArray,
    res_before: FloatArray,
    res_after: FloatArray,
    model: object,
    floor_z_m: float,
) -> tuple[SpotError, ...]:
    """Predicted position error at each hover run: the position the tension-based
    localization finds from the catenary tension plus the run's mean residual, against the
    one from the catenary tension alone; and the spread from the parameters' covariance."""
    f = model  # (theta) -> (res_h, res_r)
    # dT/dθ per hover sample (the model is smooth; central differences)
    jac = np.zeros((free_idx.size, h_idx.size, 3))
    for c, i in enumerate(free_idx.tolist()):
        step = 1e-4 * _SCALES[i]
        tp, tm = theta.copy(), theta.copy()
        tp[i] += step
        tm[i] -= step
        jac[c] = (f(tp)[0] - f(tm)[0]) / (2 * step)  # type: ignore[operator]
    omega = float(theta[PARAMETERS.index("weight_n_per_m")])
    dbase = theta[8:11]
    out = []
    for a, b in runs:
        ii = h_idx[a:b]
        p = data.position_world_m[ii].mean(0)
        base = data.base_world_m[ii].mean(0) + dbase
        length = float(data.length_m[ii].mean())
        try:
            t_ref = np.asarray(tether_force(base, p, length, omega, floor_z_m).force_world_n, float)
            p0 = _position_from_tension(t_ref, omega, length, base, floor_z_m)
            pb = _position_from_tension(
                t_ref + res_before[a:b].mean(0), omega, length, base, floor_z_m
            )
            pa = _position_from_tension(
                t_ref + res_after[a:b].mean(0), omega, length, base, floor_z_m
            )
            Jp = np.zeros((3, 3))
            for k in range(3):
                d = np.zeros(3)
                d[k] = 1e-4
                Jp[:, k] = (
                    _position_from_tension(t_ref + d, omega, length, base, floor_z_m)
                    - _position_from_tension(t_ref - d, omega, length, base, floor_z_m)
                ) / 2e-4
        except CatenaryError:
            continue
        JT = jac[:, a:b].mean(axis=1).T  # (3, p)
        cov_p = Jp @ JT @ cov @ JT.T @ Jp.T
        out.append(
            SpotError(
                position_world_m=p,
                samples=b - a,
                before_m=float(np.linalg.norm(pb - p0)),
                after_m=float(np.linalg.norm(pa - p0)),
                uncertainty_m=float(math.sqrt(max(np.trace(cov_p), 0.0))),
            )
        )
    return tuple(out)
