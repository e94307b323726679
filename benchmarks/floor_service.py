"""The contract floor: the least any service honouring the contract and the house rules does.

Run:  python -m benchmarks.floor_service ENDPOINT
      python -m benchmarks.floor_service --offline    # its µs per message, no bus

A zenoh client of the router at ENDPOINT that answers each ``tether/{drone}/telemetry`` with
an :class:`~groundstation.messages.Estimate` on ``tether/{drone}/estimate`` (the contract: one
per accepted Telemetry), computed inside the subscriber callback (no queue, no worker) by the
steps no implementation can skip:

* the payload validated (``Telemetry.parse``, pydantic: the contract's "bad input gets a
  clear error");
* the tension observed from the IMU and the thrust (``tension.observe_tension``,
  ``eq:NE_tether``);
* one predict + update of the Kalman filter per drone, its Q and R set once: three scalar
  filters in closed form, as the service's (a filterpy ``KalmanFilter`` step costs
  ~20 µs, which the floor of the earlier pages of docs/service_profile.md used);
* the Estimate encoded (``messages.encode_estimate``) and published.

Everything else the service does is left out: no noise learning, no change test,
no drift adaptation, no contact state, no localization (``position_m`` null), no follow, no
reel, no status. So this is a lower bound on the cost per message of *any* estimator that
keeps the contract and steps a Kalman filter once per message: the load benchmarks
(:mod:`benchmarks.bench_bursts`) measure it beside the bare echo and the service, through
the same router with the same client, in the same run.
"""

from __future__ import annotations

import gc
import sys
import time

from benchmarks.echo_service import serve_telemetry
from benchmarks.service_rig import MASS_KG, telemetry_payloads
from groundstation.messages import FollowInfo, InvalidMessage, Telemetry, encode_estimate
from groundstation.tension import observe_tension
from groundstation.tension_kalman import DiagonalKalman

_FOLLOW = FollowInfo(enabled=False, active=False, threshold_n=0.1, reason="floor rig").model_dump()


class FloorFilter:
    """One drone's Kalman step: three scalar filters in closed form (the service's
    ``tension_kalman.DiagonalKalman``, the per-message filter's form,
    tested equal to filterpy's ``KalmanFilter`` in tests/test_tension_equivalence.py), with
    Q and R fixed."""

    def __init__(self, r_n2: float, q_n2: float) -> None:
        self.kf = DiagonalKalman()
        self.kf.set((0.0, 0.0, 0.0), (r_n2, r_n2, r_n2))
        self.q = (q_n2, q_n2, q_n2)
        self.r = (r_n2, r_n2, r_n2)

    @property
    def x(self) -> list[float]:
        return list(self.kf.x)


def _new_filter(r_n2: float = 4e-4, q_n2: float = 1e-8) -> FloorFilter:
    return FloorFilter(r_n2, q_n2)


def estimate_bytes(kf: FloorFilter, payload: bytes) -> bytes | None:
    """One Telemetry payload → the Estimate's JSON (None for a rejected payload)."""
    try:
        msg = Telemetry.parse(payload)
    except InvalidMessage:
        return None
    obs = observe_tension(msg.accel_mps2, msg.quat_wxyz, msg.thrust_n, MASS_KG, msg.armed)
    kalman = kf.kf
    kalman.predict(kf.q)
    if obs.tension_world_n is not None:
        kalman.update(obs.tension_world_n.tolist(), kf.r)
    x = list(kalman.x)
    p = kalman.P
    std = [p[0] ** 0.5, p[1] ** 0.5, p[2] ** 0.5]
    return encode_estimate(
        seq=msg.seq,
        stamp_s=msg.stamp_s,
        tension_n=x,
        tension_std_n=std,
        horizontal_n=(x[0] ** 2 + x[1] ** 2) ** 0.5,
        vertical_n=-x[2],
        position_m=None,
        follow=_FOLLOW,
        on_ground=obs.on_ground,
        converged=True,
    )


def offline_us_per_msg(messages: int = 4000, repeats: int = 5) -> float:
    """CPU µs per message of :func:`estimate_bytes` in this thread, no bus (best repeat,
    after 1000 messages of warm-up; the garbage collector off while timing, as timeit)."""
    rows = [row[0] for row in telemetry_payloads(1, 1000 + messages * repeats, seed=1)]
    kf = _new_filter()
    for payload in rows[:1000]:
        estimate_bytes(kf, payload)
    best = float("inf")
    gc.disable()
    try:
        for k in range(repeats):
            chunk = rows[1000 + k * messages : 1000 + (k + 1) * messages]
            t0 = time.process_time()
            for payload in chunk:
                estimate_bytes(kf, payload)
            best = min(best, (time.process_time() - t0) / messages * 1e6)
    finally:
        gc.enable()
    return best


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if args == ["--offline"]:
        print(f"contract floor offline: {offline_us_per_msg():.1f} µs CPU per message")
        return 0
    filters: dict[str, FloorFilter] = {}

    def answer(prefix: str, payload: bytes) -> bytes | None:
        kf = filters.get(prefix)
        if kf is None:
            kf = filters[prefix] = _new_filter()
        return estimate_bytes(kf, payload)

    return serve_telemetry(args, __doc__.splitlines()[2], "floor", answer)


if __name__ == "__main__":
    sys.exit(main())
