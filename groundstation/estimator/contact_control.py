"""Contact stage: ground or air for one accepted message (no ground without evidence).

Control around :func:`groundstation.contact.contact_step` (the state machine and its
evidence: the vertical specific force, the thrust against the weight, motion capture's
height, with hysteresis). The stage gives it this message's evidence — the calibrated
thrust of the observation stage, the world vertical acceleration of the IMU reading
(:func:`contact.vertical_accel_from_rows_mps2`, on the attitude's rotation that the
observation stage computed), the motion-capture height if the message carries
one — and says what the rest of the step takes as "on the ground": the contact state's
decision, or a disarmed drone.

A low thrust alone is no ground (a controller that cuts the thrust in mid-air would
latch it there): the contact state decides. Pure functions of frozen inputs.
"""

from __future__ import annotations

from typing import NamedTuple

from groundstation import contact as contact_mod
from groundstation.attitude import Rows
from groundstation.messages import Telemetry

__all__ = ["ContactOut", "contact_decide"]


class ContactOut(NamedTuple):
    """The contact stage's output for one message.

    Attributes:
        state: the contact state after the message.
        on_ground: what the later stages take as ground (the state's decision, or
            disarmed).
    """

    state: contact_mod.ContactState
    on_ground: bool


def contact_decide(
    state: contact_mod.ContactState,
    params: contact_mod.ContactParams,
    msg: Telemetry,
    *,
    thrust_n: float,
    mass_kg: float,
    dt_s: float,
    floor_z_m: float,
    rotation_rows_world_body: Rows,
    vertical_noise_var_mps4: float | None = None,
    sample_sigmas: float,
    bias_step_std_mps2: float,
    height_std_m: float,
) -> ContactOut:
    """One message's evidence into the contact state (module doc).

    Args:
        state: the contact state before the message.
        params: ``[contact]`` and ``[filter] ground_thrust_ratio``.
        msg: the accepted Telemetry (its accelerometer, attitude, arming, position).
        thrust_n: the calibrated collective thrust of the observation stage, N.
        mass_kg: the drone's mass, kg.
        dt_s: time since the previous accepted message, s.
        floor_z_m: the floor's height, m.
        rotation_rows_world_body: the message's attitude as ``R_world_body`` rows.
        vertical_noise_var_mps4: the vertical vibration the tension filter measured,
            (m/s^2)^2 (``contact_step``'s), or None.
        sample_sigmas: the per-sample tests' standard deviations (``contact_step``'s;
            the tension filter's ``sigmas_at``); infinite: nothing is judged.
        bias_step_std_mps2: σ_δ, the accelerometer bias's step from rest to flight, m/s^2
            (``contact_step``'s).
        height_std_m: σ_p, the motion-capture height's noise, m (``contact_step``'s).
    """
    position = msg.position_m
    new = contact_mod.contact_step(
        state,
        params,
        dt_s=dt_s,
        armed=msg.armed,
        thrust_n=thrust_n,
        mass_kg=mass_kg,
        vertical_accel_mps2=contact_mod.vertical_accel_from_rows_mps2(
            msg.accel_mps2, rotation_rows_world_body
        ),
        height_m=position[2] if position is not None else None,
        floor_z_m=floor_z_m,
        vertical_noise_var_mps4=vertical_noise_var_mps4,
        sample_sigmas=sample_sigmas,
        bias_step_std_mps2=bias_step_std_mps2,
        height_std_m=height_std_m,
    )
    return ContactOut(new, new.on_ground or not msg.armed)
