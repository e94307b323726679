"""``groundstation crazyflie``: a Crazyflie on the bus, over cflib (docs/real-lab.md).

* :mod:`.link`: the small :class:`Link` interface to the drone and :class:`CflibLink`;
* :mod:`.bridge`: units, log blocks, alignment by firmware timestamp, thrust map, the
  command gate (watchdog, stop latch), without threads or I/O;
* :mod:`.runner`: :class:`CrazyflieBridge`, the loop between link and bus;
* :mod:`.fake`: TEST SUPPORT, a fake link (``--uri fake://hover``), not a drone.
"""

from __future__ import annotations

from collections.abc import Sequence

from groundstation.bridges.crazyflie.link import CflibLink, Link, LinkError, LogBlock, scan_cflib
from groundstation.bridges.crazyflie.runner import CrazyflieBridge, bridge_keys, run_bridges
from groundstation.config import Settings

__all__ = [
    "CflibLink",
    "CrazyflieBridge",
    "Link",
    "LinkError",
    "LogBlock",
    "bridge_keys",
    "make_link",
    "run_bridges",
    "scan",
]


def make_link(uri: str, settings: Settings, drone: str) -> Link:
    """The link for ``uri``: cflib for ``radio://``, ``usb://``, ``udp://``, ``tcp://``;
    the test fake for ``fake://SCENARIO`` (see :mod:`.fake`).

    Raises:
        LinkError: not a URI cflib or the fake understands.
    """
    if uri.startswith("fake://"):
        from groundstation.bridges.crazyflie.fake import FakeLink

        return FakeLink(
            uri,
            mass_kg=settings.for_drone(drone).drone.mass_kg,
            thrust_map=settings.crazyflie.thrust_map,
            realtime=True,
        )
    return CflibLink(uri, cache_dir=settings.crazyflie.toc_cache_dir)


def _radio_address(uri: str) -> int | None:
    """The address of a ``radio://DONGLE/CHANNEL/RATE/ADDRESS`` URI, or None (no address)."""
    parts = uri.split("://", 1)[1].split("/") if uri.startswith("radio://") else []
    if len(parts) < 4 or not parts[3]:
        return None
    try:
        return int(parts[3], 16)
    except ValueError:
        raise LinkError(f"--uri {uri!r}: the address {parts[3]!r} is not hexadecimal") from None


def scan(uris: Sequence[str] = ()) -> list[str]:
    """What answers, connecting to nothing: cflib's scan (the default address on every
    channel, and USB), each ``radio://`` URI's own address, and the test fakes given.

    Args:
        uris: ``--uri`` values; a radio URI with an address is looked for at that address
            (reported when a Crazyflie answers at its channel and rate), a ``fake://`` one
            answers unless its query says ``absent=1``.

    Raises:
        LinkError: a URI that cannot be scanned (``serial://``, a bad address).
    """
    found: list[str] = []
    real = [u for u in uris if not u.startswith("fake://")]
    for uri in real:
        CflibLink(uri)  # refuses what the bridge could not open (serial://, typos)
    if real or not uris:
        found.extend(scan_cflib())
    for address in sorted({a for a in map(_radio_address, real) if a is not None}):
        found.extend(u for u in scan_cflib(address) if u not in found)
    for uri in uris:
        if uri.startswith("fake://") and "absent=1" not in uri:
            found.append(uri)
    return found
