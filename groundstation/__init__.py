"""Ground station for tethered micro drones.

Physics (pure): :mod:`groundstation.catenary`, :mod:`groundstation.tension`,
:mod:`groundstation.localization`, :mod:`groundstation.follow`.
I/O edges: :mod:`groundstation.service`, :mod:`groundstation.sim`,
:mod:`groundstation.dashboard`, :mod:`groundstation.recording`.
"""

__version__ = "0.1.0"
