"""docs/constants.md lists every tunable of the per-message path: keep it in sync with the code.

Every field of the four parameter classes is a row (``Class.field`` in the first column), every
such row names a field that exists, every public numeric module constant of the per-message
modules is a row, every ``module.NAME`` row resolves, and the count lines add up.
"""

from __future__ import annotations

import ast
import dataclasses
import importlib
import re
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

from groundstation.bias_kalman import BiasKalmanParams
from groundstation.calibration import RestCriteria
from groundstation.contact import ContactParams
from groundstation.slow_accel import SlowAccelParams
from groundstation.tension import TensionFilterParams

REPO = Path(__file__).resolve().parents[1]
PAGE = REPO / "docs" / "constants.md"
PACKAGE = REPO / "groundstation"

CLASSES: dict[str, type[Any]] = {
    cls.__name__: cls
    for cls in (TensionFilterParams, SlowAccelParams, BiasKalmanParams, ContactParams, RestCriteria)
}
SOURCES = ("physical", "derived", "fitted", "hand-set")

MODULES = [
    *sorted((PACKAGE / "estimator").glob("*.py")),
    *sorted(PACKAGE.glob("tension*.py")),
    PACKAGE / "slow_accel.py",
    PACKAGE / "bias_kalman.py",
    PACKAGE / "contact.py",
    PACKAGE / "calibration.py",
    PACKAGE / "localization.py",
    PACKAGE / "follow.py",
    PACKAGE / "catenary.py",
    PACKAGE / "attitude.py",
]
"""The modules a Telemetry message runs through (the page's scope)."""

OFFLINE_ONLY = {"calibration.UNDETERMINED_RATIO"}
"""Public numeric constants of those modules that no message reaches (the page says why)."""

GUARDS = {
    "attitude.QUAT_MIN_NORM",
    "localization.MIN_HORIZONTAL_N",
    "tension_noise.MIN_NOISE_VAR_N2",
    "tension_kalman.MOVING_MIN_LOG_ODDS",
    "tension_noise.BLOCK_MIN_SAMPLES",
}
"""Public numeric constants that change a result only for degenerate input or at rounding
level: listed under the page's *Not counted* (each by name), not in the table."""

_CELL_SPLIT = re.compile(r"(?<!\\)\|")
_COUNT = re.compile(
    r"(\d+) tunables: (\d+) physical, (\d+) derived, (\d+) fitted, (\d+) hand-set; "
    r"(\d+) configurable"
)
_CLASS_COUNT = re.compile(
    r"^- `?([\w ]+?)`?: (\d+) \((\d+) physical, (\d+) derived, (\d+) fitted, (\d+) hand-set; "
    r"(\d+) configurable\)",
    re.MULTILINE,
)


def _rows() -> list[list[str]]:
    """The cells of every table row (the lines that start with a pipe and a backtick)."""
    rows = []
    for line in PAGE.read_text(encoding="utf-8").splitlines():
        if line.startswith("| `"):
            cells = [c.strip() for c in _CELL_SPLIT.split(line.strip().strip("|"))]
            rows.append(cells)
    return rows


ROWS = _rows()
TEXT = PAGE.read_text(encoding="utf-8")


def _name(row: list[str]) -> str:
    return row[0].strip("`")


def _source(row: list[str]) -> str:
    return row[4]


def _configurable(row: list[str]) -> bool:
    return row[3] not in ("—", "-", "")


def _group(name: str) -> str:
    head = name.split(".", 1)[0]
    return head if head in CLASSES else "named constants"


def _resolve(name: str) -> object:
    """``module.NAME`` or ``module.Class.NAME`` under groundstation, by its longest importable
    module prefix."""
    parts = name.split(".")
    for cut in range(len(parts) - 1, 0, -1):
        try:
            obj: object = importlib.import_module("groundstation." + ".".join(parts[:cut]))
        except ModuleNotFoundError:
            continue
        for attr in parts[cut:]:
            obj = getattr(obj, attr)
        return obj
    raise LookupError(name)


def _is_number(node: ast.expr) -> bool:
    if isinstance(node, ast.Constant):
        return isinstance(node.value, (int, float)) and not isinstance(node.value, bool)
    if isinstance(node, ast.UnaryOp):
        return _is_number(node.operand)
    if isinstance(node, ast.Tuple):
        return bool(node.elts) and all(_is_number(e) for e in node.elts)
    return False


def _public_numeric_constants() -> set[str]:
    """``module.NAME`` for every module-level ``NAME = number`` (or tuple of numbers)."""
    found = set()
    for path in MODULES:
        module = ".".join(path.relative_to(PACKAGE).with_suffix("").parts)
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            if isinstance(node, ast.Assign):
                targets, value = node.targets, node.value
            elif isinstance(node, ast.AnnAssign) and node.value is not None:
                targets, value = [node.target], node.value
            else:
                continue
            for target in targets:
                if (
                    isinstance(target, ast.Name)
                    and re.fullmatch(r"[A-Z][A-Z0-9_]*", target.id)
                    and _is_number(value)
                ):
                    found.add(f"{module}.{target.id}")
    return found


def test_the_table_has_rows() -> None:
    assert ROWS, f"no table rows (lines starting with '| `') in {PAGE}"
    assert all(len(row) >= 6 for row in ROWS), [r[0] for r in ROWS if len(r) < 6]


def _fields(cls: type[Any]) -> list[str]:
    """A class's fields, less those that hold another class of the table (a container: its
    own fields are the rows, e.g. ``SlowAccelParams.flight`` holds ``BiasKalmanParams``)."""
    containers = tuple(CLASSES.values())
    return [
        f.name
        for f in dataclasses.fields(cls)
        if not (
            f.default_factory is not dataclasses.MISSING
            and isinstance(f.default_factory(), containers)
        )
    ]


@pytest.mark.parametrize("cls", CLASSES.values(), ids=list(CLASSES))
def test_every_field_is_a_row(cls: type[Any]) -> None:
    names = {_name(row) for row in ROWS}
    missing = [
        f"{cls.__name__}.{name}" for name in _fields(cls) if f"{cls.__name__}.{name}" not in names
    ]
    assert not missing, f"docs/constants.md has no row for {missing}"


def test_every_class_row_is_a_field() -> None:
    stale = []
    for row in ROWS:
        name = _name(row)
        head, _, field = name.partition(".")
        if head in CLASSES and field not in _fields(CLASSES[head]):
            stale.append(name)
    assert not stale, f"docs/constants.md has rows for fields that do not exist: {stale}"


def test_every_public_numeric_constant_is_a_row() -> None:
    names = {_name(row) for row in ROWS}
    missing = sorted(_public_numeric_constants() - names - OFFLINE_ONLY - GUARDS)
    assert not missing, f"docs/constants.md has no row for {missing}"


def test_every_guard_is_named_where_the_page_does_not_count_it() -> None:
    """A guard is out of the table only where the page says so, by name; and it is a public
    constant of the page's modules (a guard that moved or went away leaves this list)."""
    not_counted = TEXT[TEXT.index("## Not counted") : TEXT.index("## Outside this table")]
    assert not [g for g in GUARDS if f"`{g}`" not in not_counted], not_counted
    assert _public_numeric_constants() >= GUARDS
    assert not GUARDS & {_name(row) for row in ROWS}


def test_every_constant_row_resolves() -> None:
    stale = []
    for row in ROWS:
        name = _name(row)
        if name.split(".", 1)[0] in CLASSES:
            continue
        try:
            value: Any = _resolve(name)
        except (LookupError, AttributeError):
            stale.append(name)
            continue
        if isinstance(value, ModuleType) or callable(value):
            stale.append(name)
    assert not stale, f"docs/constants.md has rows for names that do not exist: {stale}"


def _assigned_at_module_level(module: str, name: str) -> bool:
    path = PACKAGE.joinpath(*module.split(".")).with_suffix(".py")
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        targets = (
            node.targets
            if isinstance(node, ast.Assign)
            else [node.target]
            if isinstance(node, ast.AnnAssign)
            else []
        )
        if any(isinstance(t, ast.Name) and t.id == name for t in targets):
            return True
    return False


def test_a_module_constant_row_names_where_it_is_defined() -> None:
    """``module.NAME`` is assigned in that module, not imported into it (one definition,
    one row: g is attitude.GRAVITY_MPS2, wherever it is used)."""
    elsewhere = []
    for name in (_name(row) for row in ROWS):
        if name.split(".", 1)[0] in CLASSES:
            continue
        module, _, attr = name.rpartition(".")
        try:
            importlib.import_module("groundstation." + module)
        except ModuleNotFoundError:
            continue  # module.Class.NAME: a class-level constant, resolved above
        if not _assigned_at_module_level(module, attr):
            elsewhere.append(name)
    assert not elsewhere, f"rows for names imported, not defined, there: {elsewhere}"


def test_no_row_twice() -> None:
    names = [_name(row) for row in ROWS]
    assert len(names) == len(set(names)), sorted({n for n in names if names.count(n) > 1})


def test_each_source_is_one_of_the_four() -> None:
    bad = [(_name(row), _source(row)) for row in ROWS if _source(row) not in SOURCES]
    assert not bad, f"sources must be one of {SOURCES}: {bad}"


def test_the_count_line_adds_up() -> None:
    match = _COUNT.search(TEXT)
    assert match, "docs/constants.md has no count line 'N tunables: a physical, ...'"
    total, physical, derived, fitted, hand_set, configurable = map(int, match.groups())
    assert total == len(ROWS)
    assert (physical, derived, fitted, hand_set) == tuple(
        sum(_source(row) == s for row in ROWS) for s in SOURCES
    )
    assert configurable == sum(_configurable(row) for row in ROWS)


def test_the_count_lines_per_class_add_up() -> None:
    lines = {m.group(1): tuple(map(int, m.groups()[1:])) for m in _CLASS_COUNT.finditer(TEXT)}
    assert set(lines) == {*CLASSES, "named constants"}, sorted(lines)
    for group, (total, *per_source, configurable) in lines.items():
        rows = [row for row in ROWS if _group(_name(row)) == group]
        assert total == len(rows), group
        assert per_source == [sum(_source(row) == s for row in rows) for s in SOURCES], group
        assert configurable == sum(_configurable(row) for row in rows), group
        if group in CLASSES:
            assert total == len(_fields(CLASSES[group])), group


def test_the_readme_quotes_the_pages_count() -> None:
    """README.md's summary of the table says the page's total and hand-set count (it once
    said 85 / 76 while the page said 87 / 72)."""
    page = _COUNT.search(PAGE.read_text(encoding="utf-8"))
    assert page is not None
    total, hand_set = page.group(1), page.group(5)
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    quoted = re.search(r"`tests/test_constants_table.py`: (\d+), (\d+) of them hand-set", readme)
    assert quoted is not None, "README.md no longer quotes the count where this test looks"
    assert (quoted.group(1), quoted.group(2)) == (total, hand_set)
