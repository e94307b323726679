"""Do Stops get through while estimates flood the bus? Who loses what.

Run:  python -m benchmarks.stop_under_flood [--estimates 20000] [--every 1000] [--slow-ms 0.2]

Real zenoh sessions in separate processes over TCP on 127.0.0.1, through a router
(tests/integration/router.py):

* a publisher (this module with ``--publish``) puts ``--estimates`` Estimates on
  ``tether/d0/estimate`` back to back through :class:`~groundstation.zenoh_bus.ZenohBus`
  (the service's own publish path and QoS) and a Stop on ``tether/d0/cmd/stop`` after every
  ``--every`` of them, each Stop carrying its send time;
* a *bridge-like* subscriber (``--listen``, another process) takes ``cmd/stop`` only, as
  the Crazyflie bridge does;
* a *slow* subscriber (this process) takes the estimates and the Stops, and spends
  ``--slow-ms`` on each estimate (a dashboard on a busy laptop, a remote recorder).

Printed: estimates and Stops each subscriber received, and the Stops' latency (send to
arrival, same host clock). zenoh's default for a put is to drop a sample that a congested
link cannot take, so the slow subscriber loses estimates; the question is what happens to
the Stops on each side.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

from benchmarks import service_rig as sr
from groundstation.config import ZenohSection
from groundstation.zenoh_bus import ZenohBus

ESTIMATE = b'{"seq":%d,"stamp_s":1.0,"tension_n":[0.0123456789,0.0123456789,-0.0612345678],' + (
    b'"tension_std_n":[0.0012345678,0.0012345678,0.0012345678],"horizontal_n":0.0174,'
    b'"vertical_n":0.0612,"position_m":[0.51234567,0.61234567,1.01234567],"pad":"%s"}'
)


def _bus(endpoint: str) -> ZenohBus:
    return ZenohBus(ZenohSection(mode="client", connect=(endpoint,)))


def publish(endpoint: str, n: int, every: int) -> None:
    with _bus(endpoint) as bus:
        time.sleep(1.0)  # the subscribers' interests reach the router first
        pad = b"x" * 300  # about the size of a real Estimate
        for i in range(n):
            bus.publish("tether/d0/estimate", ESTIMATE % (i, pad))
            if i % every == every - 1:
                bus.publish("tether/d0/cmd/stop", json.dumps({"sent": time.time()}).encode())
        time.sleep(2.0)


def listen(endpoint: str, seconds: float) -> None:
    latencies: list[float] = []
    with _bus(endpoint) as bus:
        bus.subscribe(
            "tether/d0/cmd/stop",
            lambda s: latencies.append(time.time() - json.loads(s.payload)["sent"]),
        )
        time.sleep(seconds)
    print(json.dumps({"stops": len(latencies), "latency_s": sorted(latencies)}), flush=True)


def _summary(latencies: list[float]) -> str:
    if not latencies:
        return "none"
    ms = sorted(1e3 * x for x in latencies)
    return f"latency median {ms[len(ms) // 2]:.1f} ms, max {ms[-1]:.1f} ms"


def run(n: int, every: int, slow_s: float) -> dict[str, object]:
    port = sr.free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    env = dict(os.environ, PYTHONPATH=str(sr.REPO))
    me = [sys.executable, "-m", "benchmarks.stop_under_flood"]
    router = subprocess.Popen([sys.executable, str(sr.ROUTER), endpoint], stdout=subprocess.DEVNULL)
    try:
        sr.wait_port(port)
        bridge = subprocess.Popen(
            [*me, "--listen", endpoint, "--seconds", "40"],
            stdout=subprocess.PIPE,
            env=env,
            cwd=sr.REPO,
        )
        estimates = [0]
        stops: list[float] = []

        def on_estimate(_: object) -> None:
            estimates[0] += 1
            if slow_s:
                time.sleep(slow_s)

        with _bus(endpoint) as bus:
            bus.subscribe("tether/d0/estimate", on_estimate)
            bus.subscribe(
                "tether/d0/cmd/stop",
                lambda s: stops.append(time.time() - json.loads(s.payload)["sent"]),
            )
            publisher = subprocess.Popen(
                [*me, "--publish", endpoint, "--estimates", str(n), "--every", str(every)],
                env=env,
                cwd=sr.REPO,
            )
            publisher.wait(120)
            last = -1
            while estimates[0] != last:  # until the slow subscriber has drained
                last = estimates[0]
                time.sleep(1.0)
        out, _ = bridge.communicate(timeout=60)
        bridge_result = json.loads(out.decode().strip().splitlines()[-1])
    finally:
        router.terminate()
        router.wait(10)
    return {
        "estimates": n,
        "stops_sent": n // every,
        "slow_estimates": estimates[0],
        "slow_stops": len(stops),
        "slow_latency_s": sorted(stops),
        "bridge_stops": bridge_result["stops"],
        "bridge_latency_s": bridge_result["latency_s"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--estimates", type=int, default=20000)
    parser.add_argument("--every", type=int, default=1000)
    parser.add_argument("--slow-ms", type=float, default=0.2)
    parser.add_argument("--publish", metavar="ENDPOINT", help=argparse.SUPPRESS)
    parser.add_argument("--listen", metavar="ENDPOINT", help=argparse.SUPPRESS)
    parser.add_argument("--seconds", type=float, default=40.0, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.publish:
        publish(args.publish, args.estimates, args.every)
        return
    if args.listen:
        listen(args.listen, args.seconds)
        return
    r = run(args.estimates, args.every, args.slow_ms / 1000.0)
    sent = r["stops_sent"]
    print(f"published {r['estimates']} estimates and {sent} Stops back to back")
    print(
        f"slow subscriber ({args.slow_ms:g} ms per estimate): {r['slow_estimates']} estimates, "
        f"{r['slow_stops']} of {sent} Stops, {_summary(r['slow_latency_s'])}"  # type: ignore[arg-type]
    )
    print(
        f"bridge-like subscriber (cmd/stop only): {r['bridge_stops']} of {sent} Stops, "
        f"{_summary(r['bridge_latency_s'])}"  # type: ignore[arg-type]
    )


if __name__ == "__main__":
    main()
