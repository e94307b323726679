"""The latest of each drone, kept as bytes until a scene is drawn (live and offline).

A bus callback (or offline replay's loop) calls :meth:`DroneBoard.put` per message: one
attribute assignment, no parsing. :meth:`DroneBoard.build`, at the scene rate, parses what
changed with the contract's models and builds every drone's scene. ``put`` may run on other
threads than ``build``: each payload is one assignment, and the counter it bumps afterwards
tells ``build`` to re-read.
"""

from __future__ import annotations

import logging

from groundstation import messages
from groundstation.config import ConfigError, DroneParams, Settings
from groundstation.foxglove.scene import DroneInputs, DroneScene, build_drone_scene

__all__ = ["SCENE_KINDS", "DroneBoard"]

_log = logging.getLogger(__name__)

SCENE_KINDS = ("estimate", "telemetry", "truth")
"""The message kinds a scene is drawn from."""


class _Latest:
    __slots__ = ("estimate", "n", "telemetry", "truth")

    def __init__(self) -> None:
        self.estimate: bytes | None = None
        self.telemetry: bytes | None = None
        self.truth: bytes | None = None
        self.n = 0


class _Parsed:
    __slots__ = ("inputs", "n", "params")

    def __init__(self, drone_id: str, params: DroneParams) -> None:
        self.inputs = DroneInputs(drone_id)
        self.params = params
        self.n = 0


class DroneBoard:
    """Per drone: the latest estimate, telemetry and truth, and the scene drawn from them.

    Args:
        settings: per-drone configuration (base, floor, tether) and ``[foxglove]``.
    """

    def __init__(self, settings: Settings) -> None:
        self._settings = settings
        self._latest: dict[str, _Latest] = {}
        self._parsed: dict[str, _Parsed] = {}
        self._logged: set[str] = set()

    def put(self, drone_id: str, kind: str, payload: bytes) -> bool:
        """Keep ``payload`` if ``kind`` is one the scene is drawn from; True if kept."""
        if kind not in SCENE_KINDS:
            return False
        latest = self._latest.get(drone_id)
        if latest is None:
            latest = self._latest.setdefault(drone_id, _Latest())
        setattr(latest, kind, payload)
        latest.n += 1
        return True

    @property
    def drones(self) -> list[str]:
        """Drones seen so far."""
        return sorted(self._latest)

    def _log_once(self, kind: str, msg: str, *args: object) -> None:
        if kind not in self._logged:
            self._logged.add(kind)
            _log.warning(msg, *args)

    def _read(self, drone_id: str, parsed: _Parsed, latest: _Latest) -> None:
        i = parsed.inputs
        est, quat, mocap = i.estimate, i.quat_wxyz, i.mocap_m
        truth_m, truth_base, truth_len = i.truth_m, i.truth_base_m, i.truth_length_m
        try:
            if latest.estimate is not None:
                est = messages.Estimate.read(latest.estimate)
            if latest.telemetry is not None:
                tel = messages.Telemetry.parse(latest.telemetry)
                quat, mocap = tel.quat_wxyz, tel.position_m
            if latest.truth is not None:
                truth = messages.Truth.read(latest.truth)
                truth_m, truth_base, truth_len = truth.position_m, truth.base_m, truth.length_m
        except messages.InvalidMessage as exc:
            self._log_once(f"invalid-{drone_id}", "foxglove: unparsable from %s: %s", drone_id, exc)
        parsed.inputs = DroneInputs(drone_id, est, quat, mocap, truth_m, truth_base, truth_len)

    def build(self, drones: list[str] | None = None) -> list[DroneScene]:
        """The scenes of ``drones`` (default: every drone seen), from the latest payloads."""
        scenes = []
        for drone_id in self.drones if drones is None else drones:
            latest = self._latest.get(drone_id)
            if latest is None:
                continue
            parsed = self._parsed.get(drone_id)
            if parsed is None:
                try:
                    params = self._settings.for_drone(drone_id)
                except ConfigError as exc:
                    self._log_once(f"config-{drone_id}", "foxglove: %s", exc)
                    continue
                parsed = self._parsed[drone_id] = _Parsed(drone_id, params)
            n = latest.n
            if n != parsed.n:
                parsed.n = n
                self._read(drone_id, parsed, latest)
            scenes.append(
                build_drone_scene(
                    parsed.inputs,
                    parsed.params,
                    arrow_m_per_n=self._settings.foxglove.arrow_m_per_n,
                )
            )
        return scenes

    def changed_since(self, counts: dict[str, int]) -> list[str]:
        """Drones whose payloads changed since ``counts`` (drone → counter), which is updated."""
        out = []
        for drone_id, latest in self._latest.items():
            if counts.get(drone_id) != latest.n:
                counts[drone_id] = latest.n
                out.append(drone_id)
        return sorted(out)
