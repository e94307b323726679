"""Write the generated tables of ``docs/contract.md`` from the code that defines them.

    .venv/bin/python scripts/contract.py           # rewrite the generated regions
    .venv/bin/python scripts/contract.py --check   # exit 1 (and say where) when they are stale

The payload tables come from the pydantic models of ``groundstation/messages.py`` (their
field docstrings, types and constraints), the configuration tables from
``groundstation/config.py``, the flag tables from the argparse parser of
``groundstation/cli.py``: the code is the one definition and the page follows it.
``tests/test_contract.py`` runs the check. Everything outside the
``<!-- generated:NAME:start -->`` / ``<!-- generated:NAME:end -->`` markers is written by hand,
and the public contract between ``<!-- contract:start -->`` and ``<!-- contract:end -->`` is
kept verbatim.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import types
from pathlib import Path
from typing import Annotated, Any, Literal, Union, get_args, get_origin

import annotated_types
from pydantic import BaseModel
from pydantic.fields import FieldInfo

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from groundstation import config, messages  # noqa: E402
from groundstation.cli import build_parser  # noqa: E402

CONTRACT_MD = REPO / "docs" / "contract.md"

PAYLOADS: tuple[tuple[str, type[BaseModel], str], ...] = (
    ("`tether/{drone}/telemetry`", messages.Telemetry, "drone → ground station"),
    ("`tether/{drone}/reel`", messages.Reel, "reel → ground station"),
    ("`tether/{drone}/follow`", messages.FollowCommand, "operator/anyone → ground station"),
    ("`tether/{drone}/params`", messages.TetherParams, "operator → ground station (added)"),
    ("`tether/{drone}/estimate`", messages.Estimate, "ground station → anyone"),
    (
        "`tether/{drone}/estimate_smoothed`",
        messages.EstimateSmoothed,
        "`replay --offline` → its output file (added)",
    ),
    ("`follow` of Estimate and status", messages.FollowInfo, "inside Estimate and status"),
    ("`tether/{drone}/cmd/setpoint`", messages.Setpoint, "ground station → drone"),
    ("`tether/{drone}/cmd/stop`", messages.Stop, "ground station or operator → drone"),
    ("`tether/{drone}/events`", messages.Event, "ground station → anyone (added)"),
    ("`tether/{drone}/status`", messages.Status, "query (zenoh get) → ground station (added)"),
    ("`tether/{drone}/truth`", messages.Truth, "simulator → anyone (added)"),
    ("`tether/{drone}/cmd/takeoff`", messages.TakeoffIn, "operator → Crazyflie bridge (added)"),
    ("`tether/{drone}/cmd/land`", messages.LandIn, "operator → Crazyflie bridge (added)"),
    ("`[crazyflie] mocap_key`", messages.MocapPoseIn, "motion capture → Crazyflie bridge (added)"),
)
"""Each payload: where it travels, its model, who sends it to whom."""

ADDED_MODELS = frozenset(
    {
        "TetherParams",
        "EstimateSmoothed",
        "Event",
        "Status",
        "Truth",
        "TakeoffIn",
        "LandIn",
        "MocapPoseIn",
    }
)
"""Payloads that are added beside the contract as a whole (every field is added)."""

CONTRACT_CONFIG = {
    "zenoh": {"mode", "connect", "listen"},
    "drone": {"mass_kg"},
    "tether": {"weight_n_per_m", "length_m"},
    "base": {"position_m", "floor_z_m"},
}
"""The configuration keys of the public contract; every other key is added."""

CONTRACT_FLAGS = {
    "serve": {"--config", "--connect", "--listen", "--headless", "--web-host", "--web-port"},
    "sim": {"--config", "--connect", "--scenario"},
    "demo": set(),
    "record": {"--out", "--connect", "--key"},
    "replay": {"file", "--connect", "--speed"},
}
"""The flags of the public contract per command; every other flag (and command) is added."""


# --------------------------------------------------------------------------- types


def _constraint(metadata: list[Any]) -> str:
    bounds = {type(m): m for m in metadata}
    lo, hi = bounds.get(annotated_types.Ge), bounds.get(annotated_types.Le)
    if lo is not None and hi is not None:
        return f"in [{lo.ge:g}, {hi.le:g}]"
    parts = []
    for m in metadata:
        if isinstance(m, annotated_types.Gt):
            parts.append(f"> {m.gt:g}")
        elif isinstance(m, annotated_types.Ge):
            parts.append(f"≥ {m.ge:g}")
        elif isinstance(m, annotated_types.Lt):
            parts.append(f"< {m.lt:g}")
        elif isinstance(m, annotated_types.Le):
            parts.append(f"≤ {m.le:g}")
    return " ".join(parts)


def type_text(annotation: Any) -> str:
    """A short, reader's name for a field's type: ``[3] float``, ``float or null``, ..."""
    origin = get_origin(annotation)
    args = get_args(annotation)
    if origin is Annotated:
        return type_text(args[0])
    if origin in (Union, types.UnionType):
        rest = [a for a in args if a is not type(None)]
        inner = " or ".join(type_text(a) for a in rest)
        return f"{inner} or null" if len(rest) < len(args) else inner
    if origin is Literal:
        return "one of " + ", ".join(f"`{a}`" for a in args)
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"[ ] {type_text(args[0])}"
        names = {type_text(a) for a in args}
        if len(names) == 1:
            return f"[{len(args)}] {names.pop()}"
        return "[" + ", ".join(type_text(a) for a in args) + "]"
    if origin is dict:
        return f"object {{{type_text(args[0])}: {type_text(args[1])}}}"
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return f"object ({annotation.__name__})"
    if annotation is Any:
        return "any"
    return getattr(annotation, "__name__", str(annotation))


def _default_text(field: FieldInfo) -> str:
    if field.is_required():
        return ""
    if field.default_factory is not None:
        value: Any = field.default_factory()  # type: ignore[call-arg]
    else:
        value = field.default
    if value is None:
        return "optional"
    if isinstance(value, dict | list | tuple) and not value:
        return "optional, default empty"
    return f"optional, default `{json.dumps(value)}`"


def _markdown(doc: str | None) -> str:
    """A docstring as one Markdown line: reST ````code```` as `code`, pipes escaped."""
    text = " ".join((doc or "").split())
    return text.replace("``", "`").replace("|", "\\|")


def _meaning(field: FieldInfo) -> tuple[str, bool]:
    text = _markdown(field.description)
    added = text.startswith("(added)")
    return text.removeprefix("(added)").strip(), added


def _kind(field: FieldInfo) -> str:
    kind = type_text(field.annotation)
    constraint = _constraint(field.metadata)
    if constraint:
        if kind.endswith(" or null"):
            kind = f"{kind.removesuffix(' or null')} {constraint} or null"
        else:
            kind += f" {constraint}"
    return kind


# --------------------------------------------------------------------------- tables


def payload_tables() -> str:
    out = []
    for where, model, direction in PAYLOADS:
        whole = model.__name__ in ADDED_MODELS
        head = f"#### {model.__name__} — {where}"
        doc = re.sub(r"^\(added\)\s*", "", _markdown(model.__doc__))
        out += [head, "", f"*{direction}.* {doc}", ""]
        out += ["| field | type | | meaning |", "| --- | --- | --- | --- |"]
        for name, field in model.model_fields.items():
            meaning, added = _meaning(field)
            kind = _kind(field)
            default = _default_text(field)
            if default:
                kind += f", {default}"
            tag = "added" if (whole or added) else "contract"
            out.append(f"| `{name}` | {kind} | {tag} | {meaning} |")
        out.append("")
    return "\n".join(out).rstrip() + "\n"


def config_tables() -> str:
    out = []
    pending: list[tuple[str, type[BaseModel]]] = []
    for table, field in config.Settings.model_fields.items():
        section = field.annotation
        if table == "drones":
            continue
        assert isinstance(section, type) and issubclass(section, BaseModel), table
        pending.append((table, section))
    while pending:
        table, section = pending.pop(0)
        out += [f"#### `[{table}]`", "", _markdown(section.__doc__), ""]
        out += ["| key | type | default | | meaning |", "| --- | --- | --- | --- | --- |"]
        contract = CONTRACT_CONFIG.get(table, set())
        nested: list[tuple[str, type[BaseModel]]] = []
        for name, sub in section.model_fields.items():
            meaning, _ = _meaning(sub)
            kind = _kind(sub)
            if sub.default_factory is not None:
                default_value: Any = sub.default_factory()  # type: ignore[call-arg]
            else:
                default_value = sub.default
            if isinstance(default_value, BaseModel):
                # A sub-table (e.g. [sim.realistic]): its own table follows this one.
                nested.append((f"{table}.{name}", type(default_value)))
                default = f"table `[{table}.{name}]`"
            else:
                default = "none" if default_value is None else f"`{json.dumps(default_value)}`"
            tag = "contract" if name in contract else "added"
            out.append(f"| `{name}` | {kind} | {default} | {tag} | {meaning} |")
        out.append("")
        pending[:0] = nested
    return "\n".join(out).rstrip() + "\n"


def cli_tables() -> str:
    parser = build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    helps = {choice.dest: choice.help for choice in sub._choices_actions}
    out = []
    for command, p in sub.choices.items():
        contract = CONTRACT_FLAGS.get(command)
        tag = "contract" if contract is not None else "added"
        out += [f"#### `groundstation {command}` ({tag}): {helps.get(command, '')}", ""]
        out += ["| flag | | meaning |", "| --- | --- | --- |"]
        for action in p._actions:
            if action.help == argparse.SUPPRESS or isinstance(action, argparse._HelpAction):
                continue
            name = "/".join(action.option_strings) or action.dest
            flag = name
            if action.metavar and action.option_strings:
                flag += f" {action.metavar}"
            elif action.choices and action.option_strings:
                flag += " {" + ",".join(map(str, action.choices)) + "}"
            elif not action.option_strings:
                flag = str(action.metavar or action.dest)
            key = action.option_strings[0] if action.option_strings else action.dest
            added = "contract" if contract and key in contract else "added"
            text = (action.help or "").replace("%%", "%").replace("|", "\\|")
            out.append(f"| `{flag}` | {added} | {text} |")
        out.append("")
    return "\n".join(out).rstrip() + "\n"


GENERATORS = {"payloads": payload_tables, "config": config_tables, "cli": cli_tables}


def render(text: str) -> str:
    """``text`` with every generated region rewritten from the code."""
    for name, generate in GENERATORS.items():
        start, end = f"<!-- generated:{name}:start -->", f"<!-- generated:{name}:end -->"
        if start not in text or end not in text:
            raise SystemExit(f"docs/contract.md lacks the markers {start} … {end}")
        head, rest = text.split(start, 1)
        _, tail = rest.split(end, 1)
        text = f"{head}{start}\n<!-- written by scripts/contract.py; do not edit -->\n\n"
        text += f"{generate()}\n{end}{tail}"
    return text


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="only check; exit 1 when stale")
    args = parser.parse_args(argv)
    current = CONTRACT_MD.read_text()
    fresh = render(current)
    if args.check:
        if fresh != current:
            print(
                "docs/contract.md is stale: run `python scripts/contract.py` (the models, the "
                "config or the CLI changed)",
                file=sys.stderr,
            )
            return 1
        return 0
    if fresh != current:
        CONTRACT_MD.write_text(fresh)
        print(f"wrote {CONTRACT_MD.relative_to(REPO)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
