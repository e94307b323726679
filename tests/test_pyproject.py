"""pyproject.toml builds without warnings from the build backend (``./dev`` installs with it).

``./dev`` runs ``pip install --no-build-isolation -e .``: the venv's setuptools reads
pyproject.toml, and pip shows what it warns. A deprecated key printed its notice as a table,
twice, on every fresh ``./dev demo``.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def test_the_package_metadata_builds_without_a_warning(tmp_path: Path) -> None:
    # A copy: the backend writes its egg-info beside pyproject.toml.
    shutil.copy(REPO / "pyproject.toml", tmp_path)
    shutil.copy(REPO / "README.md", tmp_path)
    (tmp_path / "groundstation").mkdir()
    (tmp_path / "groundstation" / "__init__.py").write_text("")
    (tmp_path / "meta").mkdir()
    code = (
        "from setuptools import build_meta; "
        "print(build_meta.prepare_metadata_for_build_editable('meta'))"
    )
    run = subprocess.run(
        [sys.executable, "-W", "error", "-c", code],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode == 0, run.stderr
    noise = [line for line in run.stderr.splitlines() if "arning" in line or "eprecat" in line]
    assert not noise, run.stderr
    metadata = (tmp_path / "meta" / run.stdout.split()[-1] / "METADATA").read_text()
    assert "License-Expression: Apache-2.0" in metadata
