"""A Foxglove client for the benchmarks: subscribes to every channel a Foxglove WebSocket
server advertises (scene, transforms and each message channel; or those whose topic starts
with one of the given prefixes) and reads until SIGTERM.

Run:  python -m benchmarks.foxglove_client PORT [TOPIC_PREFIX ...]

Prints one JSON line at the end: messages and bytes received per topic. A plain WebSocket
client speaking Foxglove's protocol (subprotocol ``foxglove.sdk.v1``), as the app does: it
exists so that ``bench_service --foxglove`` measures the service with a client subscribed,
the server doing all of its work.
"""

from __future__ import annotations

import asyncio
import json
import signal
import struct
import sys

import websockets


async def run(port: int, prefixes: tuple[str, ...] = ()) -> dict[str, list[int]]:
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    loop.add_signal_handler(signal.SIGTERM, stop.set)
    loop.add_signal_handler(signal.SIGINT, stop.set)
    counts: dict[str, list[int]] = {}
    async with websockets.connect(
        f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"], max_size=None
    ) as ws:
        subs: dict[int, str] = {}
        print("connected", flush=True)
        while not stop.is_set():
            recv = asyncio.ensure_future(ws.recv())
            halt = asyncio.ensure_future(stop.wait())
            done, _ = await asyncio.wait({recv, halt}, return_when=asyncio.FIRST_COMPLETED)
            if recv not in done:
                recv.cancel()
                break
            halt.cancel()
            raw = recv.result()
            if isinstance(raw, str):
                msg = json.loads(raw)
                if msg["op"] == "advertise":
                    new = []
                    for ch in msg["channels"]:
                        if prefixes and not ch["topic"].startswith(prefixes):
                            continue
                        sub_id = len(subs) + 1
                        subs[sub_id] = ch["topic"]
                        new.append({"id": sub_id, "channelId": ch["id"]})
                    if new:
                        await ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
                continue
            if raw[0] == 1:
                (sub_id,) = struct.unpack_from("<I", raw, 1)
                row = counts.setdefault(subs.get(sub_id, "?"), [0, 0])
                row[0] += 1
                row[1] += len(raw) - 13
    return counts


def main() -> None:
    counts = asyncio.run(run(int(sys.argv[1]), tuple(sys.argv[2:])))
    print(json.dumps({"foxglove_client": counts}), flush=True)


if __name__ == "__main__":
    main()
