"""Tension-filter stage: when the filter steps, coasts, restarts or learns its noise.

Control around :class:`groundstation.tension.TensionFilter` (the equations, ``eq:KF``),
given the contact stage's ground/air decision and the observation:

- **On the ground** the floor carries the drone: no tension is estimated (zeros, not
  converged). The filter restarts once per stay (again if the prior changes), from the
  prior that a tether resting on the floor pulls with next to nothing
  (:data:`LIFTOFF_PRIOR_STD_N`) when the drone was seen resting (disarmed, or low thrust
  held still), else from its first observation in the air (a service started mid-flight).
  Observations taken on the floor, propellers spinning, teach the filter the propellers'
  vibration (:meth:`TensionFilter.learn_noise`), so the restart weighs its first samples
  with the flight's noise.
- **In the air** an observation updates the filter; none (thrust below the ratio: a dip, a
  hard descent, a touch-down not yet confirmed) coasts it on its last estimate.
- **In a hover** (the filter's observation took its low band from the hover model) the
  accelerometer model runs the fast change test beside it
  (:class:`~groundstation.tension_change.HoverChangeTest`): a tug restarts the filter from
  the accelerometer model's mean since the step, this sample is observed by the
  accelerometer model, and the output says so (``hover_change``: the caller ends the hover).
- A non-finite estimate restarts the filter before the drone's next message.

:class:`FilterControl` owns the drone's TensionFilter (a mutable object, stepped in place:
copying its windows each message would cost more than the step) and the two flags above;
:meth:`FilterControl.step` returns an immutable :class:`FilterOutput`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

from groundstation.tension import (
    TensionEstimate,
    TensionFilter,
    TensionFilterParams,
    TensionObservation,
)

__all__ = ["LIFTOFF_PRIOR_STD_N", "FilterControl", "FilterOutput"]

LIFTOFF_PRIOR_STD_N = (0.005, 0.005, 0.005)
"""Prior standard deviation of the tension at lift-off, N (per world axis)."""
_ZEROS3 = (0.0, 0.0, 0.0)
_RESTING = ("disarmed", "low_thrust")
"""Contact reasons that mean the drone was seen resting on the floor."""


class FilterOutput(NamedTuple):
    """The filter stage's output for one message.

    Attributes:
        tension_world_n: the tension, world frame, N (zeros on the ground or before the
            first observation).
        std_n: its standard deviation per axis, N.
        converged: enough observations since the last restart to use it.
        finite: False when the filter produced NaN/inf (it has restarted; no Estimate).
        estimate: the filter's estimate this step (None on the ground or before the first
            observation), with the covariance localization needs.
        hover_change: the accelerometer model found a tug under a hover this step (the
            hover is to end).
    """

    tension_world_n: Sequence[float]
    std_n: Sequence[float]
    converged: bool
    finite: bool = True
    estimate: TensionEstimate | None = None
    hover_change: bool = False


_GROUND = FilterOutput(_ZEROS3, _ZEROS3, False)


def _floats3(v: object) -> list[float]:
    tolist = getattr(v, "tolist", None)
    return tolist() if tolist is not None else [float(x) for x in v]  # type: ignore[attr-defined]


class FilterControl:
    """One drone's tension filter and when it runs (module doc)."""

    __slots__ = ("change_detections", "filter", "hover_test", "prior", "rested")

    def __init__(self, params: TensionFilterParams) -> None:
        self.filter = TensionFilter(params)
        self.hover_test = self.filter.hover_change_test()
        self.rested = False
        """Seen certainly on the ground (disarmed, low thrust) since the last lift-off: the
        filter then restarts from the lift-off prior."""
        self.prior: bool | None = None
        """The filter was restarted for this stay on the ground with (True) or without
        (False) the lift-off prior; None: not since its last step or restart elsewhere."""
        self.change_detections = 0
        """Tension changes (tugs) the filter detected."""

    def restart(self) -> None:
        """Forget the tension (a resumed stream, a non-finite estimate)."""
        self.filter.reset()
        self.hover_test.break_chain()
        self.prior = None

    def step(
        self,
        *,
        on_ground: bool,
        contact_reason: str,
        observation: TensionObservation,
        dt_s: float,
        accel_model_world_n: tuple[float, float, float] | None = None,
        hovering: bool = False,
        after_hover_change: bool = False,
    ) -> FilterOutput:
        """One accepted message (module doc). ``accel_model_world_n``: the accelerometer
        model's tension (None: the hover test does not run); ``hovering``: the
        observation's low band is the hover model's; ``after_hover_change``: the hover
        ended by a tug is held off (the observation is the accelerometer model, R its
        variance from the hover test)."""
        filt = self.filter
        tension_obs = observation.tension_world_n
        if on_ground:
            if contact_reason in _RESTING:
                self.rested = True
            # Once per stay on the ground (again if the prior changes), not per sample.
            if filt.initialized or self.prior != self.rested:
                if self.rested:
                    filt.reset(prior_world_n=_ZEROS3, prior_std_n=LIFTOFF_PRIOR_STD_N)
                else:
                    filt.reset()
                self.hover_test.break_chain()
                self.prior = self.rested
            if tension_obs is not None:
                filt.learn_noise(tension_obs, dt_s)
            return _GROUND
        self.rested = False
        self.prior = None
        hover_change = False
        if tension_obs is None:
            est = filt.coast(dt_s)
            if est is None:  # nothing to coast before the first observation
                return _GROUND
        else:
            noise_var = None
            z = tension_obs
            if accel_model_world_n is not None:
                test = self.hover_test
                found = test.push(accel_model_world_n, dt_s, filt.dt_mean_s, hovering)
                if found is not None:
                    filt.restart_from(found[0], found[1], test.noise_var_n2)
                    hover_change = True
                    self.change_detections += 1
                    # This sample observed by the accelerometer model too.
                    z = accel_model_world_n  # type: ignore[assignment]
                if hover_change or after_hover_change:
                    noise_var = test.noise_var_n2
            est = filt.update(z, dt_s, noise_var_n2=noise_var)
            if est.change_detected and not hover_change:
                self.change_detections += 1
        # Python floats from here on: a handful of numbers per message, for which numpy's
        # per-call overhead would cost more than the arithmetic.
        tension = _floats3(est.tension_world_n)
        std = _floats3(est.std_n)
        if not (_finite3(tension) and _finite3(std)):
            # Restarted here, not at the Estimate: before the drone's next message is
            # filtered (in a batch, before its localization).
            self.restart()
            return FilterOutput(tension, std, est.converged, False, None, hover_change)
        return FilterOutput(tension, std, est.converged, True, est, hover_change)


def _finite3(v: Sequence[float]) -> bool:
    return math.isfinite(v[0]) and math.isfinite(v[1]) and math.isfinite(v[2])
