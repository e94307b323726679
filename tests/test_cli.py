"""The command line without a bus: every flag of every command explains itself."""

from __future__ import annotations

import argparse

import pytest

from groundstation.cli import build_parser


def _subcommands() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(sub.choices)


@pytest.mark.parametrize("command", sorted(_subcommands()))
def test_every_flag_has_a_help_text(command: str) -> None:
    parser = _subcommands()[command]
    missing = [
        "/".join(action.option_strings) or action.dest
        for action in parser._actions
        if action.help is None
    ]
    assert not missing, f"groundstation {command}: flags without help: {missing}"
