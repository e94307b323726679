"""The latency floor: a bare echo in place of ``groundstation serve``.

Run:  python -m benchmarks.echo_service ENDPOINT

A zenoh client of the router at ENDPOINT that answers each ``tether/{drone}/telemetry`` with
``{"seq":N}`` on ``tether/{drone}/estimate``, from inside the subscriber callback (no queue,
no worker, no estimation): what transport, router and one Python callback cost. The load
benchmarks measure it with the same client, through the same router, in the same run.
"""

from __future__ import annotations

import json
import signal
import sys
import threading
from collections.abc import Callable
from types import FrameType

from groundstation.bus import Sample
from groundstation.config import ZenohSection
from groundstation.zenoh_bus import ZenohBus


def serve_telemetry(
    argv: list[str] | None, usage: str, name: str, answer: Callable[[str, bytes], bytes | None]
) -> int:
    """Answer every ``tether/{drone}/telemetry`` on ``tether/{drone}/estimate`` with
    ``answer(drone_prefix, payload)`` (None: no answer), inside the subscriber callback, as
    a zenoh client of the router at the one argument; until SIGTERM or SIGINT."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print(usage, file=sys.stderr)
        return 2
    stop = threading.Event()

    def on_signal(signum: int, frame: FrameType | None) -> None:
        stop.set()

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    with ZenohBus(ZenohSection(mode="client", connect=(args[0],))) as bus:
        publish = bus.publish

        def on_telemetry(sample: Sample) -> None:
            prefix = sample.key[: -len("telemetry")]
            out = answer(prefix, sample.payload)
            if out is not None:
                publish(prefix + "estimate", out)

        bus.subscribe("tether/*/telemetry", on_telemetry)
        print(f"{name}: running", flush=True)
        while not stop.wait(0.2):
            pass
    return 0


def main(argv: list[str] | None = None) -> int:
    def echo(prefix: str, payload: bytes) -> bytes:
        return b'{"seq":%d}' % json.loads(payload)["seq"]

    return serve_telemetry(argv, __doc__.splitlines()[2], "echo", echo)


if __name__ == "__main__":
    sys.exit(main())
