"""What the dashboard publishes, and the checks a follow setting passes before it is sent.

Payloads are built with the models of :mod:`groundstation.messages` (FollowCommand,
TetherParams, Stop), so what the panel sends is what the service accepts. A follow setting
the operator types is checked against the selected drone here, with the service's own rules
(its threshold floor ``[service] follow_threshold_min_n``, the tether's reach, no follow
without a trusted position), and a refusal is a sentence on the panel, never a silent clamp.
What the service refuses anyway comes back on ``tether/{drone}/events`` and is
shown in the same place.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from groundstation.messages import FollowCommand, Stop, TetherParams

__all__ = [
    "NOISE_SIGMAS",
    "FollowLimits",
    "check_tether",
    "follow_blocker",
    "follow_command",
    "params_command",
    "stop_command",
]

NOISE_SIGMAS = 3.0
"""A threshold must exceed this many standard deviations of the drone's tension estimate:
below that, noise alone crosses it and the drone "follows" a pull nobody makes."""

THRESHOLD_HELP = (
    "Threshold: how hard someone must pull, beyond the tether's own tension (its weight "
    "hanging from the drone), before the drone follows the pull. Newtons, > 0."
)
LAND_HELP = (
    "Land height: after a tug, the motors stop once the drone is below this height "
    "(world z, metres); it must lie between the floor and the top of the tether's reach."
)


def _compact(model: FollowCommand | TetherParams | Stop) -> bytes:
    return model.model_dump_json(exclude_none=True).encode()


def follow_command(
    enabled: bool,
    *,
    threshold_n: float | None = None,
    land: bool | None = None,
    land_below_m: float | None = None,
) -> bytes:
    """A FollowCommand payload for ``tether/{drone}/follow``; absent fields keep the setting.

    Args:
        enabled: tension following on or off.
        threshold_n: follow threshold, newtons, > 0 (the pull beyond the tether's own tension).
        land: tug-to-land on (True) or off (False).
        land_below_m: tug-to-land height, metres (world z).

    Raises:
        ValueError: a threshold that is not finite and > 0, or a non-finite height.
    """
    try:
        cmd = FollowCommand.model_validate(
            {
                "enabled": bool(enabled),
                "threshold_n": None if threshold_n is None else float(threshold_n),
                "land": None if land is None else bool(land),
                "land_below_m": None if land_below_m is None else float(land_below_m),
            }
        )
    except ValueError as exc:  # pydantic's ValidationError is a ValueError
        raise ValueError(f"not a valid FollowCommand: {exc}") from None
    return _compact(cmd)


def params_command(*, weight_n_per_m: float | None = None, length_m: float | None = None) -> bytes:
    """A TetherParams payload for ``tether/{drone}/params``; at least one field.

    Args:
        weight_n_per_m: tether weight per length ω, N/m, > 0.
        length_m: tether length, metres, > 0.

    Raises:
        ValueError: no field, or a value that is not finite and > 0.
    """
    if weight_n_per_m is None and length_m is None:
        raise ValueError("params needs weight_n_per_m or length_m")
    try:
        cmd = TetherParams.model_validate(
            {
                "weight_n_per_m": None if weight_n_per_m is None else float(weight_n_per_m),
                "length_m": None if length_m is None else float(length_m),
            }
        )
    except ValueError as exc:
        raise ValueError(f"not valid tether parameters: {exc}") from None
    return _compact(cmd)


def check_tether(weight_n_per_m: float, length_m: float | None) -> str | None:
    """None if these tether parameters may be sent, else the sentence the panel shows.

    The panel's number fields have no browser minimum (it would replace a typed ``-1``
    silently); a value the service would refuse is refused here with the reason instead.

    Args:
        weight_n_per_m: tether weight per length ω typed, N/m.
        length_m: tether length typed, metres (None: not editable, a reel reports it).
    """
    if not math.isfinite(weight_n_per_m) or weight_n_per_m <= 0.0:
        return (
            f"ω {weight_n_per_m:g} N/m refused: it must be a number > 0 N/m (weigh a "
            "measured piece of the tether: ω = m·g / L)."
        )
    if length_m is not None and (not math.isfinite(length_m) or length_m <= 0.0):
        return f"Length {length_m:g} m refused: it must be a number > 0 m."
    return None


def stop_command(stamp_s: float, reason: str = "operator") -> bytes:
    """A Stop payload for ``tether/{drone}/cmd/stop``.

    Args:
        stamp_s: wall-clock time of the request, seconds (``time.time()``).
        reason: why.
    """
    return Stop(stamp_s=float(stamp_s), reason=reason).to_json()


@dataclass(frozen=True)
class FollowLimits:
    """What a follow setting typed into the panel must respect, for one drone.

    Attributes:
        threshold_floor_n: lowest accepted threshold, newtons: the larger of the service's
            floor (``[service] follow_threshold_min_n``) and :data:`NOISE_SIGMAS` × |σ_T| of
            the latest Estimate.
        tension_std_n: |σ_T| used, newtons (None: no Estimate yet).
        floor_z_m: the floor, world z, metres; a land height must lie above it.
        reach_top_m: base exit height + tether length, metres; nothing above it is reachable.
        min_threshold_n: the service's floor, newtons (``[service] follow_threshold_min_n``).
        follow_blocked: why the service would refuse to switch follow on now (see
            :func:`follow_blocker`), or None.
    """

    threshold_floor_n: float
    tension_std_n: float | None
    floor_z_m: float
    reach_top_m: float
    min_threshold_n: float
    follow_blocked: str | None = None

    @classmethod
    def for_drone(
        cls,
        tension_std_n: tuple[float, float, float] | None,
        floor_z_m: float,
        base_z_m: float,
        length_m: float,
        *,
        min_threshold_n: float,
        follow_blocked: str | None = None,
    ) -> FollowLimits:
        """Limits from the drone's latest σ_T (world, N), its floor, base height and tether,
        and the service's threshold floor (N)."""
        std_n = None if tension_std_n is None else math.hypot(*tension_std_n)
        floor_n = min_threshold_n if std_n is None else max(min_threshold_n, NOISE_SIGMAS * std_n)
        return cls(floor_n, std_n, floor_z_m, base_z_m + length_m, min_threshold_n, follow_blocked)

    def check_threshold(self, threshold_n: float) -> str | None:
        """None if ``threshold_n`` may be sent, else the sentence the panel shows."""
        if not math.isfinite(threshold_n) or threshold_n <= 0.0:
            return f"Threshold {threshold_n:g} N refused: it must be a number > 0 N."
        if threshold_n < self.threshold_floor_n:
            noise = (
                f"{NOISE_SIGMAS:g} σ of this drone's tension estimate "
                f"(σ = {1e3 * self.tension_std_n:.1f} mN)"
                if self.tension_std_n is not None and self.threshold_floor_n > self.min_threshold_n
                else "the service's floor ([service] follow_threshold_min_n)"
            )
            return (
                f"Threshold {threshold_n:g} N refused: below {self.threshold_floor_n:.3f} N, "
                f"{noise}; noise alone would cross it and the drone would follow a pull "
                "nobody makes."
            )
        return None

    def check_land_height(self, land_below_m: float) -> str | None:
        """None if ``land_below_m`` may be sent, else the sentence the panel shows."""
        if not math.isfinite(land_below_m):
            return f"Land height {land_below_m:g} m refused: it must be a number."
        if not self.floor_z_m < land_below_m < self.reach_top_m:
            return (
                f"Land height {land_below_m:.2f} m refused: outside the tether's reach "
                f"(above the floor at {self.floor_z_m:.2f} m, below base + tether "
                f"{self.reach_top_m:.2f} m)."
            )
        return None


def follow_blocker(
    drone_id: str,
    *,
    telemetry_age_s: float | None,
    stale_after_s: float,
    has_mocap: bool | None,
    calibration: str | None,
) -> str | None:
    """Why the service would refuse ``{"enabled": true}`` for this drone now, or None.

    The panel's copy of the service's rules (``Pipeline._refuse_follow``; docs/contract.md,
    "what is refused"), read from what the dashboard last saw, so that ticking Follow mode
    is refused with the reason on the page instead of unticking itself. The service still
    decides; its own refusal comes back on ``tether/{drone}/events``.

    Args:
        drone_id: the drone.
        telemetry_age_s: seconds since its last Telemetry arrived here (None: none seen
            here, e.g. a dashboard that may read Estimates only: then the service decides).
        stale_after_s: ``[service] stale_after_s``, seconds.
        has_mocap: its latest Telemetry carried ``position_m`` (None: no Telemetry yet).
        calibration: the calibration in force as the service reports it (Estimate or status
            ``calibration``; None: not reported yet).
    """
    if telemetry_age_s is not None and telemetry_age_s > stale_after_s:
        return (
            f"{drone_id} is stale (no telemetry for {telemetry_age_s:.1f} s): the service "
            "keeps follow off until it is heard again."
        )
    if has_mocap is False and calibration == "none":
        return (
            f"{drone_id} has no motion capture (its telemetry carries no position_m) and no "
            "calibration is in force ([calibration] source = none): follow would fly it to "
            "its tether-based position, off by up to ~1 m uncalibrated, so the service "
            "refuses it. Calibrate the drone (groundstation calibrate, docs/calibration.md) "
            "or give it motion capture."
        )
    return None
