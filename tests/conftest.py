"""How ``./dev test`` shares the tests among its worker processes (pytest-xdist).

A parallel run ends when the last long test ends: started last, a 60 s simulation keeps one
core busy for a minute while the other idles. So each worker collects the tests longest first
(by ``durations.json`` beside this file: seconds measured on a shared 2-core machine; a test
not in it counts as short and keeps its place; ``scripts/durations.py`` refreshes it).

``GROUPS`` run on one worker each, in file order: the browser tests (one Chromium at a time,
its software GL is busy enough, and each module shares one page) and the modules whose
module-scoped fixture is expensive. xdist's own ``xdist_group`` mark does not group under
pytest 9 (it renames ``item._nodeid``, which pytest 9 no longer reads), hence the scheduler
below, which groups by path. A run in one process keeps pytest's order.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

DURATIONS = Path(__file__).with_name("durations.json")
GROUPS = {
    "tests/browser/": "browser",
    "tests/test_cross_power_on.py::": "cross_power_on",  # `calibrated`: three fits
    "tests/integration/test_security.py::": "security",  # `pki`: a CA and certificates
}


def _group(nodeid: str) -> str | None:
    return next((g for prefix, g in GROUPS.items() if nodeid.startswith(prefix)), None)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if not hasattr(config, "workerinput"):  # not an xdist worker
        return
    seconds = json.loads(DURATIONS.read_text(encoding="utf-8"))
    weight: dict[str, float] = {}
    for item in items:
        key = _group(item.nodeid) or item.nodeid
        weight[key] = weight.get(key, 0.0) + seconds.get(item.nodeid, 0.0)
    # Stable: a group's tests share its weight and keep their order.
    items.sort(key=lambda item: -weight[_group(item.nodeid) or item.nodeid])


def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class PathGroups(LoadScopeScheduling):
        """Each test is its own unit of work, but each of ``GROUPS`` is one unit."""

        def _split_scope(self, nodeid: str) -> str:
            return _group(nodeid) or nodeid

    return PathGroups(config, log)
