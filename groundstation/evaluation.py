"""Deterministic closed loop for tests and benchmarks: simulator ⇄ pipeline, no bus, no clock.

The simulator's samples go through :meth:`Pipeline.handle` (the service's own seam) and the
pipeline's commands go back to the simulator, exactly as over the bus but in lock-step.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

from groundstation.bus import Sample
from groundstation.config import Settings, load_settings
from groundstation.pipeline import Pipeline
from groundstation.sim import Simulator


class _NullBus:
    def publish(self, key: str, payload: bytes) -> None:  # pragma: no cover - unused
        pass


@dataclass
class Run:
    estimates: list[dict[str, Any]] = field(default_factory=list)
    truth: dict[float, dict[str, Any]] = field(default_factory=dict)
    setpoints: list[dict[str, Any]] = field(default_factory=list)
    stops: list[dict[str, Any]] = field(default_factory=list)
    telemetry: int = 0

    def truth_at(self, stamp_s: float) -> dict[str, Any]:
        return self.truth[round(stamp_s, 6)]


def settings_for(**sim: Any) -> Settings:
    return load_settings(None, {"sim": sim}, use_env=False)


class ClosedLoop:
    """``scenario`` flown in lock-step, resumable: :meth:`run_to` flies on from where it is.

    ``inject[step]`` adds samples to that simulator step's.
    """

    def __init__(
        self,
        settings: Settings,
        scenario: str,
        *,
        inject: dict[int, list[Sample]] | None = None,
        pipeline: Pipeline | None = None,
    ) -> None:
        self.sim = Simulator(settings, _NullBus(), scenario=scenario)  # type: ignore[arg-type]
        self.pipe = pipeline or Pipeline(settings)
        self.run = Run()
        self.steps = 0
        self._inject = inject or {}

    def run_to(self, seconds: float) -> None:
        """Fly on until ``seconds`` of simulated time (the step count ``closed_loop`` takes)."""
        sim, pipe, run = self.sim, self.pipe, self.run
        steps = round(seconds / sim.dt_s)
        for step in range(self.steps, steps):
            now_s = sim.t_s
            samples = sim.step()
            samples.extend(self._inject.get(step, []))
            for sample in samples:
                kind = sample.key.split("/", 2)[2]
                if kind == "truth":
                    t = json.loads(sample.payload)
                    run.truth[round(t["stamp_s"], 6)] = t
                    continue
                if kind == "telemetry":
                    run.telemetry += 1
                for out in pipe.handle(sample, now_s):
                    payload = json.loads(out.payload)
                    if out.key.endswith("/estimate"):
                        run.estimates.append(payload)
                    elif out.key.endswith("/cmd/setpoint"):
                        run.setpoints.append(payload)
                        sim._on_command(out)
                    elif out.key.endswith("/cmd/stop"):
                        run.stops.append(payload)
                        sim._on_command(out)
            pipe.tick(now_s)
        self.steps = max(self.steps, steps)


def closed_loop(
    settings: Settings,
    scenario: str,
    seconds: float,
    *,
    inject: dict[int, list[Sample]] | None = None,
    pipeline: Pipeline | None = None,
) -> tuple[Run, Pipeline, Simulator]:
    """Run ``scenario`` for ``seconds`` of simulated time; ``inject[step]`` adds samples."""
    loop = ClosedLoop(settings, scenario, inject=inject, pipeline=pipeline)
    loop.run_to(seconds)
    return loop.run, loop.pipe, loop.sim
