"""The smoothed series of ``replay --offline``: the tension filter's trace, paired with the
Estimates it produced, smoothed after the pass (:mod:`groundstation.smoother`).

The one place that reads the pipeline's per-drone state (``pipeline.drones[drone]``: its
``filter``, tether length, weight, base and floor); a pipeline without it (a test's fake) gets
no smoothed series.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from groundstation.bus import Sample
from groundstation.messages import EstimateSmoothed
from groundstation.smoother import localize_smoothed, smooth_tension

_log = logging.getLogger(__name__)


@dataclass
class _Epoch:
    """One filter object's trace and the Estimates paired with its steps."""

    trace: list[Any]  # groundstation.tension.FilterStep
    rows: list[tuple[Any, ...]] = field(default_factory=list)
    """(trace index, log time ns, seq, stamp_s, weight, length, base, floor, model variance)
    per Estimate (the model variance: the calibration's misfit, N² per axis, zeros if none)."""


class SmoothingTap:
    """Watches an offline pass and yields, after it, one EstimateSmoothed per paired Estimate."""

    def __init__(self, pipeline: Any) -> None:
        self._pipeline = pipeline
        self._epochs: dict[str, list[tuple[Any, _Epoch]]] = {}

    def _runtime(self, drone: str) -> Any | None:
        drones = getattr(self._pipeline, "drones", None)
        runtime = drones.get(drone) if isinstance(drones, dict) else None
        return runtime if hasattr(runtime, "filter") else None

    def after(self, key: str, outs: Sequence[Sample], t_ns: int) -> None:
        """Called after the pipeline handled input ``key``: pairs the step it made."""
        if not key.endswith("/telemetry"):
            return
        drone = key.split("/")[1]
        runtime = self._runtime(drone)
        if runtime is None:
            return
        filt = runtime.filter
        epochs = self._epochs.setdefault(drone, [])
        if not epochs or epochs[-1][0] is not filt:
            # A new filter (first message, new parameters): its trace starts now.
            epochs.append((filt, _Epoch(filt.start_trace())))
            return
        epoch = epochs[-1][1]
        ests = [o for o in outs if o.key == f"tether/{drone}/estimate"]
        if len(ests) != 1 or not epoch.trace:
            return
        i = len(epoch.trace) - 1
        if epoch.trace[i].kind == "start" and i > 0:
            i -= 1  # the step's own record precedes a segment start it made (a merge)
        if epoch.trace[i].kind not in ("init", "update", "coast"):
            return
        if len(epoch.rows) and epoch.rows[-1][0] == i:
            return  # no new step for this Estimate
        est = json.loads(ests[0].payload)
        if est.get("on_ground"):
            return
        epoch.rows.append(
            (
                i,
                t_ns,
                int(est["seq"]),
                float(est["stamp_s"]),
                float(runtime.weight_n_per_m),
                float(runtime.length_m),
                np.asarray(runtime.base_world_m, dtype=float),
                float(runtime.params.base.floor_z_m),
                np.asarray(getattr(runtime, "model_var_n2", None) or (0.0, 0.0, 0.0), float),
            )
        )

    def samples(self) -> Iterator[tuple[str, bytes, int]]:
        """``(key, payload, log time ns)`` of every smoothed Estimate, drone by drone."""
        for drone, epochs in self._epochs.items():
            key = f"tether/{drone}/estimate_smoothed"
            for filt, epoch in epochs:
                filt.trace = None  # stop recording
                if not epoch.rows:
                    continue
                smoothed = smooth_tension(epoch.trace)
                idx = np.array([r[0] for r in epoch.rows])
                ten = smoothed.tension_world_n[idx]
                var = smoothed.variance_n2[idx]
                # The calibration's misfit, as the live Estimate carries it (in the air).
                model = np.array([r[8] for r in epoch.rows])
                pos, pos_std = localize_smoothed(
                    ten,
                    var,
                    np.array([r[4] for r in epoch.rows]),
                    np.array([r[5] for r in epoch.rows]),
                    np.array([r[6] for r in epoch.rows]),
                    np.array([r[7] for r in epoch.rows]),
                    model_var_n2=model,
                )
                written = 0
                for j, row in enumerate(epoch.rows):
                    if not np.all(np.isfinite(ten[j])):
                        continue
                    found = bool(np.all(np.isfinite(pos[j])))
                    msg = EstimateSmoothed(
                        seq=row[2],
                        stamp_s=row[3],
                        tension_n=_t3(ten[j]),
                        tension_std_n=_t3(np.sqrt(np.maximum(var[j], 0.0) + model[j])),
                        position_m=_t3(pos[j]) if found else None,
                        position_std_m=_t3(pos_std[j]) if found else None,
                    )
                    yield key, msg.to_json(), row[1]
                    written += 1
                _log.info("%s: %d smoothed estimates", drone, written)


def _t3(v: np.ndarray) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))
