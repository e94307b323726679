"""Health checks of one drone's inputs that the operator must hear about, once.

Control only: each check returns what it found; the drone estimator turns a first finding
into a ``warning`` Event (and the status carries the flag on every message).

- :func:`position_too_uncertain`: an onboard position whose own σ (``position_std_m``)
  exceeds ``[localization] position_max_std_m`` is no position to follow, tug-to-land,
  contact or the azimuth.
- :func:`battery_outside`: the thrust map holds over the battery range it was calibrated
  on (``[calibration] thrust_vbat_range_v``); outside it thrust, tension and position are
  extrapolated.
- :func:`rest_missing_at_arming`: with ``[calibration] rest_required`` a drone that arms
  with no rest offset in force flies with an x/y accelerometer bias nobody calibrated.
"""

from __future__ import annotations

from groundstation.messages import Telemetry

__all__ = ["battery_outside", "position_too_uncertain", "rest_missing_at_arming"]


def position_too_uncertain(msg: Telemetry, max_std_m: float) -> bool:
    """``msg`` carries a position whose σ exceeds ``max_std_m`` on some axis."""
    std = msg.position_std_m
    return msg.position_m is not None and std is not None and max(std) > max_std_m


def battery_outside(
    vbat_range_v: tuple[float, float] | None, vbat_v: float | None, on_ground: bool
) -> bool | None:
    """The battery outside the calibrated range (None: unknown, or on the ground).

    On the ground no tension is estimated from the thrust, and an unloaded battery reads
    well above its voltage in flight (0.5–0.6 V on the NanoBench Crazyflie 2.1 flights), so
    there the flag is None rather than a false alarm.
    """
    if vbat_range_v is None or vbat_v is None or on_ground:
        return None
    return not (vbat_range_v[0] <= vbat_v <= vbat_range_v[1])


def rest_missing_at_arming(
    *, was_armed: bool, armed: bool, offset_in_force: bool, missing_before: bool
) -> bool:
    """Whether the drone flies without the rest offset its calibration relies on: set when
    it arms with none in force, cleared at the next disarm."""
    if not armed:
        return False
    if not was_armed and not offset_in_force:
        return True
    return missing_before
