"""``groundstation crazyflie``: a Crazyflie on the bus, over cflib (docs/real-lab.md).

* :mod:`.link`: the small :class:`Link` interface to the drone and :class:`CflibLink`;
* :mod:`.bridge`: units, log blocks, alignment by firmware timestamp, thrust map, the
  command gate (watchdog, stop latch), without threads or I/O;
* :mod:`.runner`: :class:`CrazyflieBridge`, the loop between link and bus;
* :mod:`.fake`: TEST SUPPORT, a fake link (``--uri fake://hover``), not a drone.
"""

from __future__ import annotations

from groundstation.bridges.crazyflie.link import CflibLink, Link, LinkError, LogBlock
from groundstation.bridges.crazyflie.runner import CrazyflieBridge, bridge_keys
from groundstation.config import Settings

__all__ = [
    "CflibLink",
    "CrazyflieBridge",
    "Link",
    "LinkError",
    "LogBlock",
    "bridge_keys",
    "make_link",
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
