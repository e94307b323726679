"""Stand-in for ``zenohd`` in integration tests: a zenoh session in router mode.

Usage::

    python tests/integration/router.py [ENDPOINT ...] [--listen ENDPOINT ...]
        [--config ROUTER.json5] [--acl ACL.json5] [--set PATH=JSON ...]

e.g. ``router.py tcp/127.0.0.1:7447`` or ``router.py --listen tls/127.0.0.1:7448 --config
tls.json5`` (positional endpoints and ``--listen`` are the same thing). ``--acl`` takes the
``access_control`` table from another JSON5 file (``config/acl-router.json5``); ``--set``
overrides one entry, e.g. ``--set 'transport/link/tls/listen_certificate="/tmp/s.pem"'``.

It opens the session (multicast scouting off; the optional JSON5 file first, so TLS and
access control come from it, then the listen endpoints), prints ``ready <zid>`` on stdout
once it listens, and runs until SIGTERM or SIGINT; then it closes the session and exits 0.
A test waits for the ``ready`` line (with a timeout) before starting anything that connects.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
from pathlib import Path
from types import FrameType

import zenoh

# Runs as a script from any directory: make the repository importable.
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from groundstation.config import ZenohSection
from groundstation.zenoh_bus import open_session


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("endpoints", nargs="*", metavar="ENDPOINT", help="listen here")
    parser.add_argument("--listen", action="append", default=[], metavar="ENDPOINT")
    parser.add_argument("--config", metavar="JSON5", help="zenoh config file (TLS, ACL)")
    parser.add_argument("--acl", metavar="JSON5", help="take access_control from this file")
    parser.add_argument("--set", action="append", default=[], metavar="PATH=JSON")
    args = parser.parse_args(argv)
    listen = tuple(args.endpoints) + tuple(args.listen)
    if not listen:
        parser.error("give at least one endpoint to listen on")
    raw: dict[str, object] = {}
    if args.acl:
        acl = zenoh.Config.from_file(args.acl).get_json("access_control")
        raw["access_control"] = json.loads(acl)
    for item in args.set:
        path, sep, value = item.partition("=")
        if not sep:
            parser.error(f"--set wants PATH=JSON, got {item!r}")
        raw[path] = json.loads(value)

    stop = threading.Event()

    def on_signal(signum: int, frame: FrameType | None) -> None:
        stop.set()

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)

    section = ZenohSection(mode="router", listen=listen, config_file=args.config, raw=raw)
    session = open_session(section)
    try:
        print(f"ready {session.zid()}", flush=True)
        while not stop.wait(0.2):
            pass
    finally:
        session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
