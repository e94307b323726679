"""Tension-filter stage: when the filter steps, coasts, restarts or learns its noise.

Control around :class:`groundstation.tension.TensionFilter` (the equations, ``eq:KF``),
given the contact stage's ground/air decision and the observation:

- **On the ground** the floor carries the drone: no tension is estimated (zeros, not
  converged). The filter restarts once per stay (again if the prior changes), from the
  prior that a tether resting on the floor pulls with next to nothing
  (:func:`liftoff_prior_std_n`) when the drone was seen resting (disarmed, or low thrust
  held still), else from its first observation in the air (a service started mid-flight).
  Observations taken on the floor, propellers spinning, teach the filter the propellers'
  vibration (:meth:`TensionFilter.learn_noise`), so the restart weighs its first samples
  with the flight's noise.
- **In the air** an observation updates the filter; none (thrust below the ratio: a dip, a
  hard descent, a touch-down not yet confirmed) coasts it on its last estimate.
- **With the slow stage** the filter observes the accelerometer model
  (``m·R·(f − β) − R·u·F``); **in a hover** it also takes the thrust balance (the hover
  model) through the drone's velocity (:class:`~groundstation.tension_kalman.HoverVelocity`):
  the hover's information enters as an equation of the filter, not as a replaced band of
  the observation, so a tug shows in the filter's own innovations at once. A change found
  while hovering ends the hover (``hover_change``: the caller ends it; the velocity no
  longer stays small once the tension has changed).
- A non-finite estimate restarts the filter before the drone's next message.

:class:`FilterControl` owns the drone's TensionFilter (a mutable object, stepped in place:
copying its windows each message would cost more than the step) and the two flags above;
:meth:`FilterControl.step` returns an immutable :class:`FilterOutput`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

from groundstation.attitude import GRAVITY_MPS2
from groundstation.contact import ContactParams
from groundstation.tension import (
    TensionEstimate,
    TensionFilter,
    TensionFilterParams,
    TensionObservation,
)

__all__ = ["FilterControl", "FilterOutput", "liftoff_prior_std_n"]


def liftoff_prior_std_n(push_free_weight_ratio: float, mass_kg: float) -> float:
    """Prior standard deviation of the tension at lift-off after a rest, N per world axis.

    Derived, ``½·push_free_weight_ratio·m·g``: the contact stage lets a rested drone go when
    the floor's load ``m·g − F``, which the observation of a drone at rest reads as vertical
    tension, stays below ``push_free_weight_ratio`` of the weight
    (:class:`~groundstation.contact.ContactParams`); that bound is taken as two standard
    deviations of the tension there. 5.0 mN at 30 g (it was a hand-set 5 mN for every
    mass), 0.33 N at 2 kg.

    Args:
        push_free_weight_ratio: ``ContactParams.push_free_weight_ratio``, dimensionless.
        mass_kg: The drone's mass, kg.
    """
    return 0.5 * push_free_weight_ratio * mass_kg * GRAVITY_MPS2


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

    __slots__ = ("change_detections", "filter", "liftoff_std_n", "prior", "rested")

    def __init__(
        self,
        params: TensionFilterParams,
        push_free_weight_ratio: float = ContactParams.push_free_weight_ratio,
    ) -> None:
        """``push_free_weight_ratio``: the contact stage's
        (:class:`~groundstation.contact.ContactParams`; its default unless given), for the
        lift-off prior (:func:`liftoff_prior_std_n` at ``params.mass_kg``)."""
        self.filter = TensionFilter(params)
        std = liftoff_prior_std_n(push_free_weight_ratio, params.mass_kg)
        self.liftoff_std_n = (std, std, std)
        """The lift-off prior's standard deviation per world axis, N."""
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
        self.prior = None

    def step(
        self,
        *,
        on_ground: bool,
        contact_reason: str,
        observation: TensionObservation,
        dt_s: float,
        accel_model_world_n: tuple[float, float, float] | None = None,
        hover_model_world_n: tuple[float, float, float] | None = None,
        hovering: bool = False,
    ) -> FilterOutput:
        """One accepted message (module doc). ``accel_model_world_n``: the accelerometer
        model's tension, which the filter observes in place of ``observation`` (None: the
        slow stage is off); ``hover_model_world_n``: the thrust balance, used while
        ``hovering``."""
        filt = self.filter
        tension_obs = observation.tension_world_n
        if on_ground:
            if contact_reason in _RESTING:
                self.rested = True
            # Once per stay on the ground (again if the prior changes), not per sample.
            if filt.initialized or self.prior != self.rested:
                if self.rested:
                    filt.reset(prior_world_n=_ZEROS3, prior_std_n=self.liftoff_std_n)
                else:
                    filt.reset()
                self.prior = self.rested
            if tension_obs is not None:
                filt.learn_noise(
                    tension_obs if accel_model_world_n is None else accel_model_world_n, dt_s
                )
            return _GROUND
        self.rested = False
        self.prior = None
        hover_change = False
        if tension_obs is None:
            est = filt.coast(dt_s)
            if est is None:  # nothing to coast before the first observation
                return _GROUND
        else:
            est = filt.update(
                tension_obs if accel_model_world_n is None else accel_model_world_n,
                dt_s,
                hover_model_world_n=hover_model_world_n if hovering else None,
                # The hover test runs with the slow stage (the accelerometer model):
                # outside a hover the drone manoeuvres.
                manoeuvring=accel_model_world_n is not None and not hovering,
            )
            if est.change_detected:
                self.change_detections += 1
                hover_change = hovering
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
