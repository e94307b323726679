"""The rooms of the package and what each may import (docs/architecture.md, kept in step).

A static check over every module's ``import`` statements, lazy ones inside functions
included: a physics module that reaches for zenoh, an edge that imports the service, or a
simulator that runs the estimator's code fails here with the offending line. A new module
must be given a room below (and in docs/architecture.md) before it can land.
"""

from __future__ import annotations

import ast
import importlib
import re
import sys
from pathlib import Path

import numpy as np
import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "groundstation"
STDLIB = set(sys.stdlib_module_names)

PHYSICS = (
    "catenary",
    "tension",
    "tension_kalman",
    "tension_noise",
    "tension_change",
    "tension_drift",
    "localization",
    "follow",
    "calibration",
    "contact",
    "slow_accel",
    "bias_kalman",
    "airframe",
    "hover_fit",
    "thrust_model",
    "smoother",
    "frozen",
    "attitude",
)
CONTRACT = ("messages", "config", "bus")

# room -> (module prefixes in it, groundstation modules it may import, third-party it may import)
ROOMS: dict[str, tuple[tuple[str, ...], tuple[str, ...], tuple[str, ...]]] = {
    "physics": (PHYSICS, PHYSICS, ("numpy", "scipy", "filterpy")),
    "contract": (CONTRACT, CONTRACT, ("pydantic", "pydantic_settings")),
    # One drone's estimator: the stages' control around the physics (PX4 EKF2's split).
    "estimator": (("estimator",), ("estimator", *PHYSICS, *CONTRACT), ("numpy",)),
    "seam": (("pipeline",), ("estimator", *PHYSICS, *CONTRACT), ("numpy",)),
    "adapter": (("zenoh_bus",), CONTRACT, ("zenoh",)),
    "service": (("service",), ("pipeline", *CONTRACT, "recording"), ()),
    "sim": (("sim",), ("sim", "catenary", *CONTRACT), ("numpy",)),
    "dashboard": (
        ("dashboard",),
        ("dashboard", "catenary", "attitude", *CONTRACT),
        ("numpy", "viser", "trimesh"),
    ),
    "foxglove": (
        ("foxglove",),
        ("foxglove", "catenary", *CONTRACT),
        ("numpy", "foxglove", "pydantic"),
    ),
    "recording": (
        ("recording",),
        (
            "recording",
            "foxglove",
            "pipeline",
            # calibrate runs the service's own hover test (estimator.drone.slow_accel_params)
            "estimator",
            "calibration",
            "airframe",
            "hover_fit",
            "catenary",
            "smoother",
            "zenoh_bus",
            "outputs",
            *CONTRACT,
        ),
        ("mcap", "zstandard", "pydantic", "numpy", "matplotlib"),
    ),
    # Writing a user's files without destroying one: the standard library only.
    "outputs": (("outputs",), (), ()),
    "bridges": (("bridges",), ("bridges", "zenoh_bus", *CONTRACT), ("numpy", "cflib")),
    # Entry points and the lock-step harness may wire anything together.
    "entry": (("cli", "__main__", "__init__", "evaluation"), ("*",), ("*",)),
}
NEVER = {
    # A simulator that runs the estimator's code proves nothing about it.
    "sim": (
        "estimator",
        "tension",
        "tension_kalman",
        "tension_noise",
        "tension_change",
        "tension_drift",
        "localization",
        "pipeline",
        "follow",
        "calibration",
        "contact",
        "slow_accel",
        "bias_kalman",
        "airframe",
        "hover_fit",
        "thrust_model",
    ),
}


def _room(module: str) -> str:
    top = module.split(".")[0]
    for room, (prefixes, _, _) in ROOMS.items():
        if top in prefixes:
            return room
    raise AssertionError(
        f"groundstation.{module} is in no room: add it to ROOMS in {Path(__file__).name} "
        "and to docs/architecture.md"
    )


def _modules() -> list[tuple[str, Path]]:
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).with_suffix("")
        parts = [p for p in rel.parts if p != "__init__"] or ["__init__"]
        out.append((".".join(parts), path))
    return out


def _absolute(node: ast.ImportFrom, path: Path) -> str:
    """The absolute module name of a ``from`` import, relative ones resolved."""
    if node.level == 0:
        return node.module or ""
    # The importing module's package: its folder, as a dotted name under groundstation.
    package = ["groundstation", *path.parent.relative_to(PACKAGE).parts]
    if node.level - 1 >= len(package):
        raise AssertionError(f"{path}: line {node.lineno} imports beyond the package")
    base = package[: len(package) - (node.level - 1)]
    return ".".join([*base, node.module] if node.module else base)


def _imports(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(), filename=str(path))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            module = _absolute(node, path)
            if module == "groundstation" or (node.level > 0 and not node.module):
                # `from groundstation import x` / `from . import x`: each x is a module
                # (or a name of the package's __init__).
                found += [(node.lineno, f"{module}.{a.name}") for a in node.names]
            else:
                found.append((node.lineno, module))
    return found


def test_relative_imports_are_resolved() -> None:
    """`from ..pipeline import X` inside sim/ counts as groundstation.pipeline."""
    tree = ast.parse("from ..pipeline import Pipeline\nfrom . import rotation\n")
    path = PACKAGE / "sim" / "runner.py"
    names = [_absolute(n, path) for n in tree.body if isinstance(n, ast.ImportFrom)]
    assert names == ["groundstation.pipeline", "groundstation.sim"]


@pytest.mark.parametrize(("module", "path"), _modules(), ids=lambda v: str(v))
def test_module_imports_only_what_its_room_allows(module: str, path: Path) -> None:
    room = _room(module)
    _, own_allowed, third_allowed = ROOMS[room]
    never = NEVER.get(room, ())
    bad = []
    for lineno, name in _imports(path):
        top = name.split(".")[0]
        if top == "groundstation":
            parts = name.split(".")
            target = parts[1] if len(parts) > 1 else "__init__"
            if target == "__init__" and name == "groundstation":
                continue  # `from groundstation import __version__`
            if target in never or ("*" not in own_allowed and target not in own_allowed):
                bad.append(f"line {lineno}: {name}")
        elif top in STDLIB or top == "__future__":
            continue
        elif "*" not in third_allowed and top not in third_allowed:
            bad.append(f"line {lineno}: {name} (third-party)")
    assert not bad, f"groundstation.{module} ({room}) imports what its room may not: {bad}"


def test_every_room_is_described_in_the_architecture_page() -> None:
    text = (PACKAGE.parent / "docs" / "architecture.md").read_text()
    for room in ROOMS:
        assert f"**{room}**" in text, f"docs/architecture.md does not describe the {room} room"


def test_every_module_is_in_the_readme_table() -> None:
    """README's module table names every module and subpackage of groundstation/ (a cell
    may name several: ``groundstation/messages.py``, ``config.py``)."""
    rows = [
        line
        for line in (PACKAGE.parent / "README.md").read_text().splitlines()
        if line.startswith("| `groundstation/")
    ]
    named = set()
    for row in rows:
        cell = row.split("|")[1]
        named.update(re.findall(r"`(?:groundstation/)?([\w/]+?(?:\.py|/))`", cell))
    missing = [
        path.name + ("/" if path.is_dir() else "")
        for path in sorted(PACKAGE.iterdir())
        if (path.suffix == ".py" and path.stem not in ("__init__", "__main__"))
        or (path.is_dir() and (path / "__init__.py").exists())
    ]
    missing = [name for name in missing if name not in named]
    assert not missing, f"README's module table lacks {missing}"


def test_no_change_history_in_docstrings_or_comments() -> None:
    """The code says what is; git holds how it came to be ("issue N" belongs in commits)."""
    found = []
    for root in ("groundstation", "tests", "benchmarks", "scripts"):
        for path in sorted((PACKAGE.parent / root).rglob("*.py")):
            for lineno, line in enumerate(path.read_text().splitlines(), 1):
                if re.search(r"\bissues? #?\d+\b", line, re.IGNORECASE):
                    found.append(f"{path.relative_to(PACKAGE.parent)}:{lineno}")
    assert not found, f"change history in the code: {found}"


@pytest.mark.parametrize("module", PHYSICS)
def test_physics_modules_hold_no_mutable_global_state(module: str) -> None:
    """No module-level list, dict, set or writable array: a pure module has no memory
    (constants are tuples, read-only arrays or mapping proxies)."""
    mod = importlib.import_module(f"groundstation.{module}")
    for name, value in vars(mod).items():
        if name.startswith("__"):
            continue
        assert not isinstance(value, list | dict | set | bytearray), f"{module}.{name}"
        if isinstance(value, np.ndarray):
            assert not value.flags.writeable, f"{module}.{name}"
