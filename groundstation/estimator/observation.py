"""Observation stage: one Telemetry message to a tension observation (``eq:NE_tether``).

Control around the physics of :func:`groundstation.tension.observe_tension` (the equation)
and :mod:`groundstation.slow_accel` (the accelerometer's slow error, our bias estimator):

1. the accelerometer reading, less the rest calibration's x/y offset when that is in force
   (``[calibration] rest`` without the slow stage: with it, the slow stage owns every
   per-power-on error of the accelerometer, the rest offset is measured and reported only);
2. with the slow stage on (``[calibration] accel_slow``), less β
   (:func:`slow_accel.correct_accel_body_mps2`); the rotor drag's velocity from the same
   state;
3. :func:`observe_tension` with the calibration in force.

After the contact stage has decided ground or air, :func:`learn_slow` feeds the same
sample back into the slow stage (rest, air or hold).

Pure functions of frozen inputs; a malformed reading raises
:class:`~groundstation.tension.TensionError` (the drone counts it as a drop).
"""

from __future__ import annotations

import math
from typing import NamedTuple

from groundstation import slow_accel as slow_mod
from groundstation.attitude import GRAVITY_MPS2, Rows
from groundstation.messages import Telemetry
from groundstation.tension import (
    ObservationCalibration,
    TensionObservation,
    observe_tension,
    rotation_rows,
)

__all__ = ["Observed", "learn_slow", "observe"]

Vec3 = tuple[float, float, float]


class Observed(NamedTuple):
    """The observation stage's output for one message.

    Attributes:
        observation: the tension observation (None tension below the thrust ratio).
        accel_read_body_mps2: the accelerometer as read, less a rest offset in force and
            before the slow correction (what the slow stage learns from), body, m/s².
        rotation_rows_world_body: the message's attitude as ``R_world_body`` rows, computed
            once here for every stage (observation, contact, slow stage).
        accel_model_world_n: the accelerometer model's tension ``m·R·(f − β) − R·u·F``
            (``eq:NE_tether``), world frame, N: the observation's tension as a tuple of
            floats; None when no tension is observed.
        hover_model_world_n: the thrust balance ``m·g·e3 − R·u·F`` (+ the rotor drag),
            world frame, N: the accelerometer model less ``m·a``, the acceleration the
            accelerometer reads (``accel_model − m·(R·(f − β) − g·e3)``); what the tension
            is when the drone does not accelerate. Computed only while the slow stage
            says the drone hovers (the filter uses it only then); None otherwise, and as
            ``accel_model_world_n``.
    """

    observation: TensionObservation
    accel_read_body_mps2: Vec3
    rotation_rows_world_body: Rows
    accel_model_world_n: Vec3 | None = None
    hover_model_world_n: Vec3 | None = None


def observe(
    msg: Telemetry,
    *,
    mass_kg: float,
    calibration: ObservationCalibration | None,
    rest_offset_xy_mps2: tuple[float, float] | None,
    slow: slow_mod.SlowAccelState | None,
    ground_thrust_ratio: float,
) -> Observed:
    """The tension observation of one message (module doc, steps 1–3).

    Args:
        msg: the validated Telemetry.
        mass_kg: the drone's mass, kg.
        calibration: the sensor corrections in force (None: none).
        rest_offset_xy_mps2: the rest calibration's x/y offset to subtract (None: none in
            force, or the slow stage is on).
        slow: the slow stage's state (None: ``[calibration] accel_slow`` off).
        ground_thrust_ratio: below this fraction of the weight no tension is observed.

    Raises:
        TensionError: a degenerate quaternion or a non-finite reading.
    """
    rows = rotation_rows(msg.quat_wxyz)  # raises DegenerateQuaternionError first
    accel = msg.accel_mps2
    if rest_offset_xy_mps2 is not None:
        ox, oy = rest_offset_xy_mps2
        accel = (accel[0] - ox, accel[1] - oy, accel[2])
    accel_read = accel
    velocity = None
    if slow is not None:
        accel = slow_mod.correct_accel_body_mps2(slow, accel)
        velocity = slow_mod.drag_velocity_world_mps(slow)
    obs = observe_tension(
        accel,
        msg.quat_wxyz,
        msg.thrust_n,
        mass_kg,
        armed=msg.armed,
        calibration=calibration,
        vbat_v=msg.vbat_v,
        ground_thrust_ratio=ground_thrust_ratio,
        velocity_world_mps=velocity,
        rotation_rows_world_body=rows,
    )
    accel_model: Vec3 | None = None
    hover_model: Vec3 | None = None
    tension = obs.tension_world_n
    if tension is not None:
        t0, t1, t2 = tension.tolist()
        accel_model = (t0, t1, t2)
        if slow is not None and slow.quasi_static:
            # − m·(R·(f − β) − g·e3): f − β as observe_tension read it (its own bias
            # subtracted).
            (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = rows
            bx, by, bz = slow.bias_body_mps2
            ax, ay, az = accel_read[0] - bx, accel_read[1] - by, accel_read[2] - bz
            if calibration is not None:
                bx, by, bz = calibration.accel_bias_mps2
                ax, ay, az = ax - bx, ay - by, az - bz
            hover_model = (
                accel_model[0] - mass_kg * (r00 * ax + r01 * ay + r02 * az),
                accel_model[1] - mass_kg * (r10 * ax + r11 * ay + r12 * az),
                accel_model[2] - mass_kg * (r20 * ax + r21 * ay + r22 * az - GRAVITY_MPS2),
            )
    return Observed(obs, accel_read, rows, accel_model, hover_model)


def learn_slow(
    state: slow_mod.SlowAccelState,
    params: slow_mod.SlowAccelParams,
    msg: Telemetry,
    observed: Observed,
    *,
    dt_s: float,
    on_ground: bool,
    calibration: ObservationCalibration | None,
    still: bool,
    rest_mean_body_mps2: Vec3 | None,
    accel_density_m2ps3: float | None = None,
    hover_chi2: float = math.inf,
) -> slow_mod.SlowAccelState:
    """One accepted sample into the slow stage: at rest (disarmed and still: ``still`` and
    ``rest_mean_body_mps2`` from the rest detector, :class:`~groundstation.calibration.
    RestCalibrator`, the one test of stillness), in the air (observing a tension), or held
    (spool-up, landing, a dip). ``accel_density_m2ps3``: the accelerometer's noise density
    for the velocity filter and the hover test, and ``hover_chi2`` the hover test's threshold
    (``slow_accel_step``'s; infinite: no hover)."""
    accel_read = observed.accel_read_body_mps2
    phase: slow_mod.Phase
    if not msg.armed and still:
        phase = "rest"
    elif not on_ground and observed.observation.tension_world_n is not None:
        phase = "air"
    else:
        phase = "hold"
    if calibration is not None:
        # β is what remains beyond a configured bias, which observe_tension subtracts.
        bx, by, bz = calibration.accel_bias_mps2
        accel_read = (accel_read[0] - bx, accel_read[1] - by, accel_read[2] - bz)
    return slow_mod.slow_accel_step(
        state,
        params,
        dt_s=dt_s,
        stamp_s=msg.stamp_s,
        accel_body_mps2=accel_read,
        R_world_body=observed.rotation_rows_world_body,
        phase=phase,
        mocap_world_m=msg.position_m,
        rest_mean_body_mps2=rest_mean_body_mps2 if phase == "rest" else None,
        accel_density_m2ps3=accel_density_m2ps3,
        hover_chi2=hover_chi2,
    )
