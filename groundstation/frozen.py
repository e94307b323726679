"""``dataclasses.replace`` for the per-message states, at a fraction of its cost.

The per-message states (contact, slow accelerometer, follow) are frozen dataclasses: each
step returns a new one. ``dataclasses.replace`` builds it through ``__init__``, which for a
frozen dataclass sets every field with ``object.__setattr__`` (~4–8 µs for the 15–18
fields of these states, several times per message). :func:`evolve` copies the instance's
``__dict__`` instead (~0.5 µs), which is what ``replace`` amounts to for a frozen dataclass
without ``__post_init__``, ``InitVar`` or ``slots`` — the only kind it accepts.
"""

from __future__ import annotations

from dataclasses import fields, is_dataclass
from typing import Any, TypeVar

__all__ = ["evolve"]

T = TypeVar("T")


def evolve(instance: T, /, **changes: Any) -> T:
    """A copy of the frozen dataclass ``instance`` with ``changes`` (names are not checked:
    callers pass field names; :func:`check_evolvable` is what the tests run on each type).
    """
    cls = type(instance)
    new = object.__new__(cls)
    values = new.__dict__
    values.update(instance.__dict__)
    values.update(changes)
    return new


def check_evolvable(cls: type) -> None:
    """Raise TypeError unless :func:`evolve` equals ``dataclasses.replace`` on ``cls``: a
    frozen dataclass with a ``__dict__`` (no slots) and no ``__post_init__``."""
    if not is_dataclass(cls) or not cls.__dataclass_params__.frozen:  # type: ignore[attr-defined]
        raise TypeError(f"{cls.__name__} is not a frozen dataclass")
    if "__slots__" in cls.__dict__:
        raise TypeError(f"{cls.__name__} has slots: evolve needs its __dict__")
    if hasattr(cls, "__post_init__"):
        raise TypeError(f"{cls.__name__} has __post_init__, which evolve would skip")
    assert fields(cls)
