"""docs/contract.md is the one reference: the public contract verbatim, the tables beside it
generated from the models / config / CLI, and the recorder's schemas from the same models."""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
from pathlib import Path
from types import ModuleType

import pytest
from pydantic import BaseModel

from groundstation import messages
from groundstation.recording import schema_for_key

REPO = Path(__file__).resolve().parents[1]
CONTRACT_MD = REPO / "docs" / "contract.md"
PUBLIC_CONTRACT_SHA256 = "c4fdb1937841db0082fd72920e26646a5617a74765e16312d3dcec1a1d1df8e9"
"""Digest of the public contract as shared (INTERFACE.md): the verbatim part must not move."""


def _script() -> ModuleType:
    spec = importlib.util.spec_from_file_location("contract_script", REPO / "scripts/contract.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _verbatim() -> str:
    text = CONTRACT_MD.read_text()
    return text.split("<!-- contract:start -->\n", 1)[1].split("\n<!-- contract:end -->", 1)[0]


def test_the_public_contract_is_kept_verbatim() -> None:
    assert hashlib.sha256(_verbatim().encode()).hexdigest() == PUBLIC_CONTRACT_SHA256
    # Where the shared original is at hand (next to the repository, or named by the
    # environment), compare byte for byte as well.
    for candidate in (
        os.environ.get("GROUNDSTATION_PUBLIC_CONTRACT"),
        REPO.parent / "shared" / "INTERFACE.md",
    ):
        if candidate and Path(candidate).is_file():
            assert _verbatim() == Path(candidate).read_text()


def test_the_generated_tables_match_the_code() -> None:
    current = CONTRACT_MD.read_text()
    assert _script().render(current) == current, (
        "docs/contract.md disagrees with groundstation/messages.py, config.py or cli.py: "
        "run `python scripts/contract.py`"
    )


def test_every_payload_field_is_documented() -> None:
    script = _script()
    for _, model, _ in script.PAYLOADS:
        for name, field in model.model_fields.items():
            assert field.description, f"{model.__name__}.{name} has no docstring"


def test_a_field_the_tables_do_not_show_is_caught() -> None:
    # The check can fail: a model field the page does not list makes render() differ.
    script = _script()
    current = CONTRACT_MD.read_text()
    stale = current.replace("| `vbat_v` |", "| `vbat_volts` |")
    assert stale != current
    assert script.render(stale) == current


@pytest.mark.parametrize(
    ("kind", "model"),
    [
        ("telemetry", messages.Telemetry),
        ("reel", messages.Reel),
        ("follow", messages.FollowCommand),
        ("params", messages.TetherParams),
        ("estimate", messages.Estimate),
        ("cmd/setpoint", messages.Setpoint),
        ("cmd/stop", messages.Stop),
        ("truth", messages.Truth),
        ("events", messages.Event),
    ],
)
def test_the_recorders_schemas_come_from_the_same_models(kind: str, model: type[BaseModel]) -> None:
    name, data = schema_for_key(f"tether/cf1/{kind}")
    assert name == f"groundstation.{model.__name__}"
    mode = "validation" if issubclass(model, messages._In) else "serialization"
    assert json.loads(data) == model.model_json_schema(mode=mode)
    # Descriptions travel with them: the same words as the page.
    first = next(iter(model.model_fields))
    assert json.loads(data)["properties"][first].get("description")


def test_the_docs_point_to_the_contract_in_the_repo() -> None:
    stale = []
    files = [REPO / "README.md", *(REPO / "docs").glob("*.md"), *(REPO / "config").rglob("*")]
    files += list((REPO / "groundstation").rglob("*.py"))
    for path in files:
        if path.is_file() and "shared/INTERFACE" in path.read_text(errors="replace"):
            stale.append(str(path.relative_to(REPO)))
    assert not stale, f"point to docs/contract.md instead of ../shared/INTERFACE.md: {stale}"
    assert "docs/contract.md" in (REPO / "README.md").read_text()
