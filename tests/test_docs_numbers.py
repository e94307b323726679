"""The numbers README.md and docs/ quote are their benchmarks' figures, and those are current.

A page quotes a figure with a marker right after the number (``benchmarks/figures.py``)::

    116 µs<!-- fig pipeline_benchmark.json handle_median_us -->

Each quote must equal the figure in the file it names, at the quote's decimals; each figures
file must have been made from the code its benchmark measures as it is now (else: rerun the
command the failure names), from committed code, and its page must name its commit.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from benchmarks import REPO
from benchmarks import figures as fig

PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]


def _quotes() -> tuple[list[fig.Quote], list[str]]:
    quotes, bad = [], []
    for page in PAGES:
        q, b = fig.find_quotes(page.read_text(encoding="utf-8"), str(page.relative_to(REPO)))
        quotes += q
        bad += b
    return quotes, bad


QUOTES, BAD_MARKERS = _quotes()


MADE = sorted(name for name in fig.BENCHMARKS if fig.figures_path(name).is_file())
"""The benchmarks whose figures file exists (a page without one quotes nothing checked)."""


def _record(name: str) -> dict[str, Any]:
    record: dict[str, Any] = json.loads(fig.figures_path(name).read_text(encoding="utf-8"))
    return record


def test_every_quote_is_its_figure() -> None:
    problems = [p for q in QUOTES if (p := fig.check_quote(q)) is not None]
    assert not problems, "\n".join(problems)


def test_every_marker_follows_a_number() -> None:
    assert not BAD_MARKERS, "\n".join(BAD_MARKERS)


def test_the_readme_quotes_each_benchmark_it_cites() -> None:
    cited = {q.file for q in QUOTES if q.where.startswith("README.md:")}
    assert {"pipeline_benchmark.json", "nanobench_cli.json", "results_envelope.json"} <= cited


def test_every_quoted_file_is_a_benchmark_s() -> None:
    files = {q.file for q in QUOTES}
    assert files <= {f"{name}.json" for name in fig.BENCHMARKS}, files


@pytest.mark.parametrize("name", MADE)
def test_figures_are_current(name: str) -> None:
    record = _record(name)
    stale = fig.stale_files(record)
    assert not stale, (
        f"docs/{name}.json was made at commit {record['commit']}; the code it measures has "
        f"changed since: {', '.join(stale)}. Rerun `{record['command']}` (and commit the page "
        "and its figures)"
    )
    assert not record["uncommitted"], (
        f"docs/{name}.json was made from uncommitted code ({', '.join(record['uncommitted'])}): "
        f"commit, then rerun `{record['command']}`"
    )


@pytest.mark.parametrize("name", MADE)
def test_each_page_names_the_commit_of_its_figures(name: str) -> None:
    record = _record(name)
    page = REPO / "docs" / (fig.BENCHMARKS[name].page or f"{name}.md")
    assert record["commit"][:7] in page.read_text(encoding="utf-8"), (
        f"{page.name} does not name commit {record['commit'][:7]} of docs/{name}.json: the page "
        f"and its figures come from different runs; rerun `{record['command']}`"
    )


@pytest.mark.parametrize("name", MADE)
def test_each_figures_file_is_quoted(name: str) -> None:
    assert any(q.file == f"{name}.json" for q in QUOTES), f"no page quotes docs/{name}.json"


# ---------------------------------------------------------------------------- the check itself


def _figures_dir(tmp_path: Path, figures: dict[str, Any]) -> Path:
    (tmp_path / "x.json").write_text(json.dumps({"figures": figures}))
    return tmp_path


def test_a_quote_that_differs_from_its_figure_fails(tmp_path: Path) -> None:
    docs = _figures_dir(tmp_path, {"a": {"median_cm": 111.04, "rows": [1.0, 2.26]}, "n": 1234.0})
    text = (
        "median 111.0 cm<!-- fig x.json a.median_cm -->, **111**<!-- fig x.json a.median_cm -->\n"
        "was 95 cm<!-- fig x.json a.median_cm --> and 2.3<!-- fig x.json a.rows.1 -->\n"
        "1,234 msg<!-- fig x.json n --> −2.26<!-- fig x.json a.rows.1 -->\n"
        "<!-- fig x.json a.nothing --> 7<!-- fig x.json a.nothing -->\n"
    )
    quotes, bad = fig.find_quotes(text, "p.md")
    verdicts = [fig.check_quote(q, docs) for q in quotes]
    assert [v is None for v in verdicts] == [True, True, False, True, True, False, False]
    assert "quotes 95 for x.json a.median_cm, which is 111.04" in str(verdicts[2])
    assert "has no figure" in str(verdicts[6])
    assert bad == ["p.md:4: 1 marker(s) follow no number"]


def test_the_code_hash_ignores_docstrings_and_comments_only(tmp_path: Path) -> None:
    f = tmp_path / "m.py"
    f.write_text(
        '"""Doc."""\n\nX = 1\n"""X\'s doc."""\n\n\ndef f(a):\n    """Doc."""\n    return a\n'
    )
    before = fig.code_hash(f)
    f.write_text('"""Other doc,\nlonger."""\n\n# a comment\nX = 1\n\n\ndef f(a):\n    return a\n')
    assert fig.code_hash(f) == before
    f.write_text('"""Doc."""\n\nX = 2\n\n\ndef f(a):\n    return a\n')
    assert fig.code_hash(f) != before


def test_a_changed_measured_file_makes_the_figures_stale() -> None:
    measures = fig.measured_hashes(fig.BENCHMARKS["pipeline_benchmark"].measures)
    record = {"benchmark": "pipeline_benchmark", "measures": measures}
    assert fig.stale_files(record) == []
    measures["groundstation/tension.py"] = "0" * 16
    assert fig.stale_files(record) == ["groundstation/tension.py"]


def test_the_command_line_and_the_dashboard_are_not_measured() -> None:
    for bench in fig.BENCHMARKS.values():
        files = fig.measured_files(bench.measures)
        assert not [f for f in files if f.startswith(("groundstation/dashboard", "docs/"))]
        assert "groundstation/cli.py" not in files
        assert "groundstation/config.py" not in files  # its defaults only


def test_every_module_the_pipeline_runs_is_measured() -> None:
    """A module the per-message path imports, left out of ``figures.ESTIMATOR``, could change
    every figure without a page going stale (groundstation.bias_kalman was, once)."""
    code = (
        "import sys, groundstation.pipeline\n"
        "print('\\n'.join(m for m in sys.modules if m.startswith('groundstation')))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=fig.REPO
    ).stdout.split()
    files = set(fig.measured_files(fig.ESTIMATOR))
    # The package itself, the bus interface (no estimate), and the configuration (measured
    # by its defaults: figures.CONFIG_DEFAULTS) stand outside the list.
    outside = {"groundstation", "groundstation.bus", "groundstation.config"}
    missing = sorted(
        m
        for m in out
        if m not in outside
        and m.replace(".", "/") + ".py" not in files
        and m.replace(".", "/") + "/__init__.py" not in files
    )
    assert not missing, f"not in benchmarks.figures.ESTIMATOR: {missing}"
