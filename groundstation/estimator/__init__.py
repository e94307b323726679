"""One drone's estimator, stage by stage (PX4 EKF2's split: control here, equations in the
physics modules). :class:`DroneEstimator` in :mod:`.drone` composes the stages; each stage
reads alone:

- :mod:`.observation` — telemetry to a tension observation (``eq:NE_tether``), and the
  accelerometer's slow error learnt back (:mod:`groundstation.slow_accel`);
- :mod:`.gate` — the stream's order, gaps and resumption;
- :mod:`.checks` — battery range, position σ, rest offset at arming;
- contact — :func:`groundstation.contact.contact_step`, called by :meth:`.DroneEstimator.front`;
- :mod:`.filter_control` — when the tension filter steps, coasts, restarts, learns noise;
- :mod:`.localize_control` — what a tension is localized with;
- :mod:`.follow_control` — follow, tug-to-land, the operator's follow commands;
- :mod:`.output` — the Estimate's JSON.

The :class:`~groundstation.pipeline.Pipeline` routes messages to drones, applies commands
and hands on the outputs.
"""

from groundstation.estimator.drone import (
    MOCAP_HOLD_S,
    DroneEstimator,
    Front,
    calibration_from_config,
)

__all__ = ["MOCAP_HOLD_S", "DroneEstimator", "Front", "calibration_from_config"]
