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
* one predict + update of a filterpy ``KalmanFilter`` per drone (the house rule: filterpy
  for the Kalman filter), its Q and R set once, with the same ``inv`` hook as
  ``TensionFilter``;
* the Estimate encoded (``messages.encode_estimate``) and published.

Everything else the service does is left out: no noise learning, no change or step test,
no drift adaptation, no contact state, no localization (``position_m`` null), no follow, no
reel, no status. So this is a lower bound on the cost per message of *any* estimator that
keeps the contract and steps filterpy once per message: the load benchmarks
(:mod:`benchmarks.bench_bursts`) measure it beside the bare echo and the service, through
the same router with the same client, in the same run.
"""

from __future__ import annotations

import gc
import math
import sys
import time

import numpy as np
from filterpy.kalman import KalmanFilter

from benchmarks.echo_service import serve_telemetry
from benchmarks.service_rig import MASS_KG, telemetry_payloads
from groundstation.messages import FollowInfo, InvalidMessage, Telemetry, encode_estimate
from groundstation.tension import observe_tension

_FOLLOW = FollowInfo(enabled=False, active=False, threshold_n=0.1, reason="floor rig").model_dump()


def _inv3(S: np.ndarray) -> np.ndarray:
    """Inverse of a 3x3 matrix by its adjugate: S^-1 = adj(S) / det(S).

    Installed as ``KalmanFilter.inv`` (it was the tension filter's until that became three
    scalar filters in closed form), filterpy's hook for the inverse it needs in
    ``update`` (K = P- C' (C P- C' + R)^-1). There S is symmetric positive definite with
    eigenvalues at least (m sigma_a)^2 = (9 mN)^2, so the adjugate form is as accurate as
    np.linalg.inv's LU (agreement to rounding). A singular or non-finite S takes
    np.linalg.inv, which decides what happens, as before.

    Args:
        S: Shape (3, 3).

    Returns:
        The inverse, shape (3, 3).
    """
    (a, b, c), (d, e, f), (g, h, i) = S.tolist()
    c00, c01, c02 = e * i - f * h, c * h - b * i, b * f - c * e
    det = a * c00 + d * c01 + g * c02
    if not (det != 0.0 and math.isfinite(det)):
        return np.asarray(np.linalg.inv(S), dtype=np.float64)
    return (
        np.array(
            [
                [c00, c01, c02],
                [f * g - d * i, a * i - c * g, c * d - a * f],
                [d * h - e * g, b * g - a * h, a * e - b * d],
            ]
        )
        / det
    )


def _new_filter(r_n2: float = 4e-4, q_n2: float = 1e-8) -> KalmanFilter:
    kf = KalmanFilter(dim_x=3, dim_z=3)
    kf.F = np.eye(3)
    kf.H = np.eye(3)
    kf.Q = np.eye(3) * q_n2
    kf.R = np.eye(3) * r_n2
    kf.P = np.eye(3) * r_n2
    kf.inv = _inv3
    return kf


def estimate_bytes(kf: KalmanFilter, payload: bytes) -> bytes | None:
    """One Telemetry payload → the Estimate's JSON (None for a rejected payload)."""
    try:
        msg = Telemetry.parse(payload)
    except InvalidMessage:
        return None
    obs = observe_tension(msg.accel_mps2, msg.quat_wxyz, msg.thrust_n, MASS_KG, msg.armed)
    kf.predict()
    if obs.tension_world_n is not None:
        kf.update(np.asarray(obs.tension_world_n, dtype=float))
    x = kf.x.ravel().tolist()
    p = kf.P
    std = [float(p[0, 0]) ** 0.5, float(p[1, 1]) ** 0.5, float(p[2, 2]) ** 0.5]
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
    filters: dict[str, KalmanFilter] = {}

    def answer(prefix: str, payload: bytes) -> bytes | None:
        kf = filters.get(prefix)
        if kf is None:
            kf = filters[prefix] = _new_filter()
        return estimate_bytes(kf, payload)

    return serve_telemetry(args, __doc__.splitlines()[2], "floor", answer)


if __name__ == "__main__":
    sys.exit(main())
