"""Benchmarks: each a command that writes its page in docs/ (see docs/results_summary.md)."""

from __future__ import annotations

import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
"""The repository root (git runs there whatever the working directory)."""


def git(*args: str) -> str:
    """``git ARGS`` in the repository: its stdout, or "" if git fails or is missing."""
    try:
        return subprocess.run(
            ["git", *args], cwd=REPO, capture_output=True, text=True, check=True, timeout=10
        ).stdout
    except (OSError, subprocess.SubprocessError):
        return ""


def git_commit() -> str:
    """The checked-out commit, 12 hex digits, or ``unknown`` (for a page's provenance)."""
    return git("rev-parse", "--short=12", "HEAD").strip() or "unknown"
