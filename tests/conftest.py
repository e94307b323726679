"""How ``./dev test`` shares the tests among its worker processes (pytest-xdist).

``./dev test`` runs the suite in parallel (``-n`` cores + 1 ``--dist loadgroup``: three
workers on a 2-core machine; ``./dev test -n 0`` runs it in one process). Two kinds of test:

- **Real-time** tests wait on the wall clock: real Zenoh sessions, subprocesses that fly a
  simulator at real time, a Chromium drawing with software GL, threads polled against a
  deadline. Each of ``CHAINS`` (one: the browser tests, then every other real-time test)
  runs serially on a worker of its own, at normal priority, and never runs a CPU test.
- **CPU** tests (simulations run faster than real time, fits, the results command) run on
  the remaining workers, which lower their own priority (``nice`` +10, inherited by the
  subprocesses they start): whatever the real-time tests leave of the two cores goes to
  them, and a real-time test never waits for a core behind a simulation.

Each worker takes the longest work first (by ``durations.json`` beside this file: seconds
measured in one process on the shared 2-core machine; a test not in it counts as short and
keeps its place; ``scripts/durations.py`` refreshes it), so that no 2-minute test starts
last. ``UNITS``: modules whose module-scoped fixture is expensive run whole on one worker.

xdist's own ``xdist_group`` mark does not group under pytest 9 (it renames
``item._nodeid``, which pytest 9 no longer reads), hence the scheduler below, which groups
by path. A run in one process (plain ``pytest``) keeps pytest's order and priority.
"""

from __future__ import annotations

import json
import os
import platform
import sys
from pathlib import Path
from typing import Any

import pytest

PORTABLE_FLOAT_KERNELS = {
    "NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR",
    "OPENBLAS_CORETYPE": "Nehalem",
}
"""Kernels the suite runs numpy with on x86-64, whatever the CPU: several tests demand that a
rewrite on Python floats gives the very bits of the numpy code it replaced (a batch against
one-by-one localization, the simulator's float step against its numpy step). On a CPU with
AVX-512 numpy dispatches its own vector loops and OpenBLAS its SkylakeX kernels, which round
3-vector dot products and some transcendentals differently (by an ULP) from Python's float
arithmetic; the portable kernels (SSE4.2, numpy's X86_V3 loops at most) round as Python does,
so those tests decide the same on every x86-64 machine. Set before numpy is imported, and
inherited by every process a test starts; production is unaffected (the results differ by an
ULP, not in meaning)."""

if platform.machine() in ("x86_64", "AMD64"):
    if "numpy" in sys.modules:  # too late: the kernels are chosen at import
        raise RuntimeError("tests/conftest.py: numpy was imported before the kernels were set")
    for _name, _value in PORTABLE_FLOAT_KERNELS.items():
        os.environ.setdefault(_name, _value)

DURATIONS = Path(__file__).with_name("durations.json")

CHAINS: dict[str, tuple[str, ...]] = {
    # One chain: the browser tests never run beside the integration tests' processes (a
    # parallel run that did so lost a browser test's wait once), at little cost in wall time.
    "realtime": (
        "tests/browser/",  # a Chromium drawing with software GL
        "tests/integration/",  # processes on a real Zenoh router, simulators at real time
        "tests/test_crazyflie.py::",  # the bridge's threads against deadlines
        "tests/test_service.py::",  # the service's threads polled against deadlines
        "tests/test_dashboard.py::",  # a viser server; an update within 2 s
        "tests/test_recording.py::",  # recorder threads, a replay with timing
        "tests/test_zenoh_bus.py::",  # real Zenoh sessions
        "tests/test_bus.py::",  # callback threads
        "tests/test_cli.py::",  # a bound port
        "tests/test_deploy.py::",  # docker-compose, Zenoh configs
    ),
}
"""Real-time tests: each chain runs serially, on a worker of its own."""

UNITS = (
    "tests/test_cross_power_on.py::",  # `calibrated`: three fits
    "tests/test_calibrate_cli.py::",  # a module-scoped fit
    "tests/test_nanobench_cli.py::",
    "tests/test_sim_calibration.py::",  # one simulated flight, recorded and replayed
    "tests/test_thrust_model_nanobench.py::",  # two fits and six replays
)
"""CPU modules that run whole on one worker (an expensive module-scoped fixture)."""

CPU_NICE = 10
"""Added to a CPU worker's niceness: the real-time tests come first for a core."""


def chain_of(nodeid: str) -> str | None:
    return next(
        (name for name, prefixes in CHAINS.items() if nodeid.startswith(prefixes)),
        None,
    )


def unit_of(nodeid: str) -> str:
    """The scheduler's unit of work: a chain, a whole module of ``UNITS``, or the test."""
    chain = chain_of(nodeid)
    if chain is not None:
        return chain
    return next((prefix for prefix in UNITS if nodeid.startswith(prefix)), nodeid)


def _worker_index(workerid: str) -> int:
    return int(workerid.removeprefix("gw"))


def _chain_of_worker(index: int) -> str | None:
    """Workers gw0, gw1, ... run the chains in order; the others run CPU tests."""
    names = list(CHAINS)
    return names[index] if index < len(names) else None


def pytest_configure(config: pytest.Config) -> None:
    workerinput = getattr(config, "workerinput", None)
    # A worker's "dist" option reads "no"; xdist keeps "loadgroup" in "loadgroup".
    if workerinput is None or not getattr(config.option, "loadgroup", False):
        return
    if _chain_of_worker(_worker_index(workerinput["workerid"])) is None:
        os.nice(CPU_NICE)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if not hasattr(config, "workerinput"):  # not an xdist worker: pytest's order
        return
    seconds = json.loads(DURATIONS.read_text(encoding="utf-8"))
    weight: dict[str, float] = {}
    for item in items:
        key = unit_of(item.nodeid)
        weight[key] = weight.get(key, 0.0) + seconds.get(item.nodeid, 0.0)
    # Stable: a unit's tests share its weight and keep their file order.
    items.sort(key=lambda item: -weight[unit_of(item.nodeid)])


def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class Chains(LoadScopeScheduling):
        """Units of work by ``unit_of``; a chain's worker runs that chain and nothing else,
        the other workers every other unit, in collection order (longest first)."""

        def __init__(self, config: pytest.Config, log: Any = None) -> None:
            super().__init__(config, log)
            if self.numnodes <= len(CHAINS):
                raise pytest.UsageError(
                    f"tests/conftest.py: --dist loadgroup needs more than {len(CHAINS)} "
                    "workers (one per real-time chain, the others for the CPU tests), "
                    f"got {self.numnodes}"
                )
            # Keep the collection's order (longest first), not xdist's most-tests-first.
            config.option.loadscopereorder = False

        def _split_scope(self, nodeid: str) -> str:
            return unit_of(nodeid)

        def _wants(self, node: Any) -> set[str | None]:
            """The chain of a chain's worker; None (CPU tests) for the others, and any chain
            whose worker is gone (a crashed worker's replacement is a new gwN)."""
            own = _chain_of_worker(_worker_index(node.gateway.id))
            if own is not None:
                return {own}
            alive = {_chain_of_worker(_worker_index(n.gateway.id)) for n in self.nodes}
            return {None} | (set(CHAINS) - alive)

        def _assign_work_unit(self, node: Any) -> None:
            wants = self._wants(node)
            for scope in self.workqueue:
                if chain_of(next(iter(self.workqueue[scope]))) in wants:
                    break
            else:
                return  # nothing left for this worker: _reschedule shuts it down
            work_unit = self.workqueue.pop(scope)
            self.assigned_work.setdefault(node, {})[scope] = work_unit
            collection = self.registered_collections[node]
            node.send_runtest_some([collection.index(nodeid) for nodeid in work_unit])

        def _reschedule(self, node: Any) -> None:
            if node.shutting_down:
                return
            wants = self._wants(node)
            if not any(chain_of(next(iter(unit))) in wants for unit in self.workqueue.values()):
                # Nothing more for this worker: it runs what it has and stops. (A worker holds
                # its last test until it knows the next one or that there is none.)
                node.shutdown()
                return
            if self._pending_of(self.assigned_work.get(node, {})) > 1:
                return
            self._assign_work_unit(node)

    return Chains(config, log)
