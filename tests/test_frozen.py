"""frozen.evolve is dataclasses.replace for the per-message states, at a fraction of the cost."""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import pytest

from groundstation.contact import ContactState
from groundstation.follow import FollowState
from groundstation.frozen import check_evolvable, evolve
from groundstation.slow_accel import SlowAccelState

STATES = (ContactState, SlowAccelState, FollowState)


@pytest.mark.parametrize("cls", STATES)
def test_every_state_stepped_with_evolve_is_evolvable(cls: type) -> None:
    check_evolvable(cls)


@pytest.mark.parametrize("cls", STATES)
def test_evolve_equals_replace_field_by_field(cls: type) -> None:
    base = cls()
    for i, f in enumerate(fields(cls)):
        value = (1.5 + i, -2.0, 0.25) if f.name.endswith(("_m", "_mps", "_mps2")) else 0.5 + i
        if f.type in ("bool", bool):
            value = not getattr(base, f.name)
        want = replace(base, **{f.name: value})
        got = evolve(base, **{f.name: value})
        assert got == want and got is not base and type(got) is cls
        assert getattr(base, f.name) == getattr(cls(), f.name)  # the original untouched
        with pytest.raises(AttributeError):
            setattr(got, f.name, value)  # still frozen


def test_check_evolvable_refuses_what_evolve_would_get_wrong() -> None:
    @dataclass(frozen=True, slots=True)
    class Slotted:
        x: float = 0.0

    @dataclass(frozen=True)
    class Checked:
        x: float = 0.0

        def __post_init__(self) -> None:
            if self.x < 0:
                raise ValueError("x < 0")

    @dataclass
    class Mutable:
        x: float = 0.0

    for cls in (Slotted, Checked, Mutable):
        with pytest.raises(TypeError):
            check_evolvable(cls)
