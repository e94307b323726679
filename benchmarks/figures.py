"""Each benchmark's figures as a file beside its page, and the code they measure.

A benchmark whose figures README.md or a page in docs/ quotes writes them to
``docs/<page>.json`` beside ``docs/<page>.md`` with :func:`write_figures`::

    {
      "benchmark": "pipeline_benchmark",
      "command": ".venv/bin/python -m benchmarks.bench_pipeline",
      "commit": "dc8d3ff0a1b2",             # HEAD when it ran
      "uncommitted": [],                    # measured files that differed from HEAD
      "generated_utc": "2026-12-04T18:30:00Z",
      "measures": {"groundstation/tension.py": "<code hash>", ...},
      "figures": {"total_median_us": 86.4, ...}
    }

A page or README.md quotes a figure with a marker right after the number (the marker is an
HTML comment, so it does not show once rendered)::

    86 µs<!-- fig pipeline_benchmark.json total_median_us -->
    111.0 cm<!-- fig results_envelope.json classes.all.uncalibrated.median_cm -->
    0.5 cm<!-- fig realistic_benchmark.json hover.0.ours_median_m ×100 -->

``python -m benchmarks.figures`` lists the figures files, current or stale, with the command
to rerun. ``tests/test_docs_numbers.py`` reads every such marker: the number just before it (at most
a unit between) must equal the figure in the named file (``docs/`` is implied; a dotted key
walks nested tables and lists) rounded to the quote's decimals, times the factor if the
marker ends with one; and every file's ``measures`` must still match the code, or the test
names the command to rerun.

What a benchmark measures is listed here, in :data:`BENCHMARKS`, by hand: the estimator's
modules, the simulator where it draws the flights, the benchmark's own modules, and for
``groundstation/config.py`` its default values only (a new check or flag there changes no
figure). The command line, the dashboard, the Zenoh adapter, the service's wiring and the
docs are not listed, so a change to them leaves the figures current (``nanobench_cli`` runs
``calibrate`` and ``replay --offline`` through ``groundstation.cli``: what they run counts,
the parsing of their flags does not). A file's hash is of its code: its syntax tree
with the docstrings left out, so a comment or a docstring edited does not make a page stale.
"""

from __future__ import annotations

import ast
import datetime
import functools
import hashlib
import json
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from benchmarks import REPO, git, git_commit

DOCS = REPO / "docs"

CONFIG_DEFAULTS = "groundstation/config.py:defaults"
"""The pseudo-file for the configuration's default values (:func:`config_defaults_hash`)."""

TENSION_FILTER: tuple[str, ...] = (
    "groundstation/attitude.py",
    "groundstation/tension.py",
    "groundstation/tension_change.py",
    "groundstation/tension_drift.py",
    "groundstation/tension_kalman.py",
    "groundstation/tension_noise.py",
)
"""The tension filter alone (what a benchmark that drives ``TensionFilter`` directly runs)."""

ESTIMATOR: tuple[str, ...] = (
    "groundstation/airframe.py",
    "groundstation/attitude.py",
    "groundstation/bias_kalman.py",
    "groundstation/calibration.py",
    "groundstation/catenary.py",
    "groundstation/contact.py",
    "groundstation/estimator",
    "groundstation/follow.py",
    "groundstation/frozen.py",
    "groundstation/localization.py",
    "groundstation/messages.py",
    "groundstation/pipeline.py",
    "groundstation/slow_accel.py",
    "groundstation/tension.py",
    "groundstation/tension_change.py",
    "groundstation/tension_drift.py",
    "groundstation/tension_kalman.py",
    "groundstation/tension_noise.py",
    "groundstation/thrust_model.py",
    CONFIG_DEFAULTS,
)
"""One drone's estimator and the pipeline that routes messages to it."""

SIMULATOR: tuple[str, ...] = ("groundstation/sim", "groundstation/evaluation.py")
"""The simulator and the closed loop that flies it against a pipeline."""

RECORDING: tuple[str, ...] = (
    "groundstation/hover_fit.py",
    "groundstation/recording/calibrate.py",
    "groundstation/recording/format.py",
    "groundstation/recording/reader.py",
    "groundstation/recording/replay.py",
    "groundstation/recording/smoothed.py",
    "groundstation/recording/writer.py",
    "groundstation/smoother.py",
)
"""``calibrate`` and ``replay --offline``: what they read, fit and write (``hover_fit`` is
``calibrate``'s: nothing on the per-message path imports it)."""


@dataclass(frozen=True)
class Benchmark:
    """A benchmark whose page has a figures file.

    Attributes:
        command: the command that writes the page and its figures file, as its page says.
        measures: files and folders (every ``*.py`` in them), relative to the repository.
    """

    command: str
    measures: tuple[str, ...]
    page: str = ""
    """The page in docs/ whose figures these are, if its name is not the figures file's."""


BENCHMARKS: dict[str, Benchmark] = {
    "pipeline_benchmark": Benchmark(
        ".venv/bin/python -m benchmarks.bench_pipeline",
        (
            *ESTIMATOR,
            "groundstation/bus.py",
            "groundstation/evaluation.py",
            "groundstation/sim/rotation.py",
            "benchmarks/bench_pipeline.py",
            "benchmarks/bench_service.py",
            "benchmarks/service_rig.py",
        ),
    ),
    "nanobench_cli": Benchmark(
        ".venv/bin/python -m benchmarks.nanobench_cli",  # --out docs/nanobench_cli.md
        (*ESTIMATOR, *RECORDING, "benchmarks/nanobench.py", "benchmarks/nanobench_cli.py"),
    ),
    "nanobench_live": Benchmark(
        ".venv/bin/python -m benchmarks.nanobench_live",  # --speed 2 --out docs/nanobench_live.md
        (
            *ESTIMATOR,
            *RECORDING,
            "groundstation/bus.py",
            "benchmarks/nanobench.py",
            "benchmarks/nanobench_cli.py",
            "benchmarks/nanobench_live.py",
        ),
    ),
    "attitude_source": Benchmark(
        ".venv/bin/python -m benchmarks.attitude_source",  # --out docs/attitude_source.md
        (
            *ESTIMATOR,
            *RECORDING,
            "benchmarks/nanobench_cli.py",
            "benchmarks/attitude_source.py",
        ),
    ),
    "battery_model": Benchmark(
        ".venv/bin/python -m benchmarks.battery_model",  # --out docs/battery_model.md
        (
            *ESTIMATOR,
            *RECORDING,
            "groundstation/bridges/crazyflie/bridge.py",
            "benchmarks/nanobench.py",
            "benchmarks/nanobench_cli.py",
            "benchmarks/battery_model.py",
        ),
    ),
    "smoother": Benchmark(
        ".venv/bin/python -m benchmarks.bench_smoother",  # --seeds 2 --out docs/smoother.md
        (
            *ESTIMATOR,
            *RECORDING,
            *SIMULATOR,
            "benchmarks/bench_powerons.py",
            "benchmarks/nanobench.py",
            "benchmarks/nanobench_cli.py",
            "benchmarks/bench_smoother.py",
        ),
    ),
    "filter_benchmark": Benchmark(
        ".venv/bin/python -m benchmarks.bench_filter",
        (*TENSION_FILTER, "benchmarks/bench_filter.py"),
    ),
    "change_test_benchmark": Benchmark(
        # --minutes 60 --flights 60 --seed-base 10000 (--jobs N: the same figures)
        ".venv/bin/python -m benchmarks.bench_change_test",
        (*TENSION_FILTER, "groundstation/thrust_model.py", "benchmarks/bench_change_test.py"),
    ),
    "powerons_benchmark": Benchmark(
        ".venv/bin/python -m benchmarks.bench_powerons",  # --both --out docs/powerons_benchmark.md
        (*ESTIMATOR, *RECORDING, *SIMULATOR, "benchmarks/bench_powerons.py"),
    ),
    "azimuth_sources": Benchmark(
        ".venv/bin/python -m benchmarks.bench_azimuth",
        (*ESTIMATOR, *SIMULATOR, "benchmarks/bench_azimuth.py"),
    ),
    "reel_tug": Benchmark(
        ".venv/bin/python -m benchmarks.bench_reel_tug",  # --seeds 8 --out docs/reel_tug.md
        (*ESTIMATOR, *SIMULATOR, "benchmarks/bench_reel_tug.py", "benchmarks/told_noise.py"),
    ),
    "realistic_benchmark": Benchmark(
        ".venv/bin/python -m benchmarks.bench_realistic",  # --tug-seeds 8
        (
            *ESTIMATOR,
            *SIMULATOR,
            "groundstation/bus.py",
            "benchmarks/bench_realistic.py",
            "benchmarks/told_noise.py",
        ),
    ),
    "results_envelope": Benchmark(
        ".venv/bin/python -m benchmarks.results",  # or --only envelope
        (
            *ESTIMATOR,
            *SIMULATOR,
            "groundstation/bus.py",
            "benchmarks/bench_realistic.py",
            "benchmarks/told_noise.py",
            "benchmarks/results.py",
            "benchmarks/results_envelope.py",
            "benchmarks/results_paper.py",
            "benchmarks/results_sim.py",
        ),
        page="RESULTS.md",
    ),
}
"""Page name (``docs/<name>.md``, figures in ``docs/<name>.json``) → its benchmark."""


def _without_docstrings(tree: ast.AST) -> ast.AST:
    """Drop every statement that is a bare string: docstrings, attribute docstrings."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            node.body = [
                s
                for s in node.body
                if not (
                    isinstance(s, ast.Expr)
                    and isinstance(s.value, ast.Constant)
                    and isinstance(s.value.value, str)
                )
            ] or [ast.Pass()]
    return tree


def code_hash(path: Path) -> str:
    """SHA-256 (16 hex digits) of a Python file's code: its syntax tree without docstrings.

    Comments are not in the tree; line numbers are not hashed, so moving code down a file
    by a docstring edit does not change the hash.
    """
    return _text_hash(path.read_text(encoding="utf-8"), str(path))


@functools.cache
def _cached_hash(path: Path, mtime_ns: int) -> str:
    return code_hash(path)


@functools.cache
def config_defaults_hash() -> str:
    """SHA-256 (16 hex digits) of the configuration's default values, as JSON.

    ``model_construct`` builds the defaults without reading the environment or a file.
    """
    from groundstation.config import Settings

    defaults = Settings.model_construct().model_dump(mode="json")
    return hashlib.sha256(json.dumps(defaults, sort_keys=True).encode()).hexdigest()[:16]


def _text_hash(source: str, name: str) -> str:
    tree = _without_docstrings(ast.parse(source, name))
    return hashlib.sha256(ast.dump(tree).encode()).hexdigest()[:16]


def measured_files(measures: tuple[str, ...]) -> list[str]:
    """The files of ``measures``, folders expanded to their ``*.py``, relative to the repo."""
    files: list[str] = []
    for entry in measures:
        path = REPO / entry
        if entry == CONFIG_DEFAULTS:
            files.append(entry)
        elif path.is_dir():
            files += sorted(str(p.relative_to(REPO)) for p in path.rglob("*.py"))
        else:
            files.append(entry)
    return files


def measured_hashes(measures: tuple[str, ...]) -> dict[str, str]:
    """Each measured file (folders expanded) → its :func:`code_hash` ("missing" if gone)."""
    out: dict[str, str] = {}
    for name in measured_files(measures):
        if name == CONFIG_DEFAULTS:
            out[name] = config_defaults_hash()
        elif (REPO / name).is_file():
            path = REPO / name
            out[name] = _cached_hash(path, path.stat().st_mtime_ns)
        else:
            out[name] = "missing"
    return out


def kept_reading(page: Path, mark: str, *, above: bool = False) -> str:
    """The part of an existing page written by hand, from ``mark`` on ("" if none): a
    benchmark that writes its page's tables appends it, so a rerun keeps the reading. With
    ``above``, the part before ``mark`` instead (a reading above the generated runs, which
    ``mark`` begins; "" if the page starts with them).

    Args:
        page: the page the benchmark is about to write.
        mark: where the hand-written part begins, e.g. ``"\n## Reading"`` (with ``above``:
            where the generated part begins).
        above: the hand-written part is above ``mark``.
    """
    if not page.is_file():
        return ""
    old = page.read_text(encoding="utf-8")
    at = old.find(mark)
    if above:
        return old[:at] if at > 0 else ""
    return old[at:] if at >= 0 else ""


def figures_path(page: str) -> Path:
    return DOCS / f"{page}.json"


@dataclass(frozen=True)
class _Start:
    commit: str
    uncommitted: frozenset[str]
    measures: dict[str, str]


def _at_start() -> _Start:
    measures = measured_hashes(
        tuple(sorted({entry for bench in BENCHMARKS.values() for entry in bench.measures}))
    )
    real_files = [f for f in measures if f != CONFIG_DEFAULTS]
    changed = [line[3:] for line in git("status", "--porcelain", "--", *real_files).splitlines()]
    return _Start(
        git_commit(), frozenset(f for f in changed if _code_differs_from_head(f)), measures
    )


def write_figures(page: str, figures: Mapping[str, Any], argv: list[str] | None = None) -> Path:
    """Write ``docs/<page>.json``: the figures, the command, the commit and the code measured.

    The commit and the code are those when the run began (:data:`AT_START`, taken when the
    benchmark imported this module), as the page's own provenance is: a commit made while a
    long benchmark runs does not change what it measured.

    Args:
        page: a key of :data:`BENCHMARKS` (``docs/<page>.md`` is the page).
        figures: name → number (or a nested table of them), as the page and README quote them.
        argv: the command's arguments beyond :attr:`Benchmark.command`, if any.

    Returns:
        The path written.
    """
    bench = BENCHMARKS[page]
    files = measured_files(bench.measures)
    record = {
        "benchmark": page,
        "command": " ".join([bench.command, *(argv or [])]),
        "commit": AT_START.commit,
        "uncommitted": sorted(AT_START.uncommitted.intersection(files)),
        "generated_utc": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "measures": {f: AT_START.measures[f] for f in files},
        "figures": _finite(figures),
    }
    path = figures_path(page)
    text = json.dumps(record, indent=1, ensure_ascii=False, default=_plain)
    path.write_text(text + "\n", encoding="utf-8")
    print(f"wrote {path}")
    return path


def _code_differs_from_head(name: str) -> bool:
    """Whether a changed file's code (not only its docstrings or comments) differs from HEAD."""
    committed = git("show", f"HEAD:{name}")
    path = REPO / name
    if not committed or not path.is_file():
        return True
    return _text_hash(committed, name) != code_hash(path)


def _plain(value: Any) -> Any:
    """numpy scalars and arrays as Python numbers and lists (JSON's ``default``)."""
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(f"not a figure: {value!r}")


def _finite(value: Any) -> Any:
    """JSON has no NaN or infinity: such a figure is written as null."""
    if isinstance(value, Mapping):
        return {str(k): _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def stale_files(record: Mapping[str, Any]) -> list[str]:
    """The measured files whose code differs from when ``record``'s figures were made.

    The files are those the benchmark measures now (:data:`BENCHMARKS`) and those the record
    lists, so a file added to the list, or a file removed, counts as a change too.
    """
    page = record["benchmark"]
    recorded: dict[str, str] = record["measures"]
    now = measured_hashes(BENCHMARKS[page].measures) if page in BENCHMARKS else {}
    for name in recorded:
        if name not in now:
            now[name] = measured_hashes((name,))[name]
    return sorted(name for name in set(now) | set(recorded) if now.get(name) != recorded.get(name))


# ---------------------------------------------------------------------------- quotes

QUOTE = re.compile(
    r"(?P<number>[-−]?\d[\d,]*(?:\.\d+)?)(?P<unit>[^\d\n<]{0,16}?)"
    r"<!-- fig (?P<file>[\w./-]+\.json) (?P<key>[\w.-]+)(?: ×(?P<scale>[\d.e+-]+))? -->"
)
"""A number, at most a unit or a closing ``**`` after it, then the marker naming its figure
(and, if the page quotes it in other units than the file, the factor: ``×100`` for a figure
in metres quoted in cm)."""

MARKER = re.compile(r"<!-- fig\b[^>]*-->")


def marker(file: str, key: str, scale: str = "") -> str:
    """The marker a page writes after a number it quotes (:data:`QUOTE`): ``file`` the
    figures file (``reel_tug.json``), ``key`` the figure's dotted key, ``scale`` the factor
    if the page quotes it in other units (``"100"``: metres quoted in cm)."""
    return f"<!-- fig {file} {key}{' ×' + scale if scale else ''} -->"


@dataclass(frozen=True)
class Quote:
    """A number a page quotes, with the figure it names."""

    where: str  # "README.md:39"
    number: str  # as written, e.g. "1,234.5" or "−9.1"
    file: str  # relative to docs/
    key: str  # dotted path into the file's "figures"
    scale: float = 1.0  # the quote is the figure times this


def find_quotes(text: str, name: str) -> tuple[list[Quote], list[str]]:
    """The quotes in a page, and the markers that follow no number (each a problem)."""
    quotes, bad = [], []
    for line_no, line in enumerate(text.splitlines(), 1):
        matched = 0
        for m in QUOTE.finditer(line):
            matched += 1
            scale = float(m["scale"]) if m["scale"] else 1.0
            quotes.append(Quote(f"{name}:{line_no}", m["number"], m["file"], m["key"], scale))
        markers = len(MARKER.findall(line))
        if markers != matched:
            bad.append(f"{name}:{line_no}: {markers - matched} marker(s) follow no number")
    return quotes, bad


def lookup(figures: Any, key: str) -> Any:
    """``figures["a"]["b"][2]`` for key ``a.b.2``; KeyError naming the missing part."""
    value = figures
    for part in key.split("."):
        if isinstance(value, list) and part.isdigit() and int(part) < len(value):
            value = value[int(part)]
        elif isinstance(value, Mapping) and part in value:
            value = value[part]
        else:
            raise KeyError(f"{key!r}: no {part!r}")
    return value


def check_quote(quote: Quote, docs: Path = DOCS) -> str | None:
    """None if the quoted number is the named figure at the quote's decimals, else why not."""
    path = docs / quote.file
    if not path.is_file():
        return f"{quote.where}: {quote.file} does not exist"
    try:
        value = lookup(json.loads(path.read_text(encoding="utf-8"))["figures"], quote.key)
    except KeyError as exc:
        return f"{quote.where}: {quote.file} has no figure {exc.args[0]}"
    if not isinstance(value, int | float) or isinstance(value, bool):
        return f"{quote.where}: {quote.file} {quote.key} is {value!r}, not a number"
    written = quote.number.replace(",", "").replace("−", "-")
    decimals = len(written.split(".")[1]) if "." in written else 0
    value = value * quote.scale
    expected = f"{value:.{decimals}f}"
    if float(expected) == 0.0:
        expected = expected.lstrip("-")
    if expected != written:
        return (
            f"{quote.where}: quotes {quote.number} for {quote.file} {quote.key}, "
            f"which is {value!r} ({expected} at the quote's {decimals} decimal(s))"
        )
    return None


AT_START = _at_start()
"""The commit and the measured code when this module was first imported: a benchmark's start."""


def main() -> int:
    """``python -m benchmarks.figures``: each figures file, current or stale, and what to rerun.

    Exit status 1 if any is stale or missing (the check ``tests/test_docs_numbers.py`` makes).
    """
    bad = 0
    for name, bench in sorted(BENCHMARKS.items()):
        path = figures_path(name)
        if not path.is_file():
            print(f"{name}: no {path.name} yet: `{bench.command}`")
            bad += 1
            continue
        record = json.loads(path.read_text(encoding="utf-8"))
        stale = stale_files(record)
        if stale:
            changed = ", ".join(stale)
            print(f"{name}: stale since {record['commit']} ({changed}): `{record['command']}`")
            bad += 1
        else:
            print(f"{name}: current (commit {record['commit']})")
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
