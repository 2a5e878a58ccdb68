"""Project hygiene a contributor relies on: layout, CI command, lint."""

from __future__ import annotations

import importlib
import re
import shutil
import subprocess

import pytest
from conftest import ROOT


def test_layout_and_packages() -> None:
    for name in ("db", "ingest", "samba", "export", "service", "tests", "bench"):
        assert (ROOT / name).is_dir(), name
    for package in ("db", "ingest", "samba", "export", "service"):
        assert importlib.import_module(package).__doc__


def test_ci_runs_the_readme_test_command() -> None:
    readme = (ROOT / "README.md").read_text()
    commands = re.findall(r"^    (python3 -m venv .*)$", readme, flags=re.MULTILINE)
    test_command = next(c for c in commands if "pytest" in c)
    assert test_command in (ROOT / ".ci" / "run").read_text()


def test_ruff_is_clean() -> None:
    ruff = shutil.which("ruff")
    if ruff is None:
        pytest.skip("ruff is not installed (pip install -e '.[test]' installs it)")
    result = subprocess.run([ruff, "check", str(ROOT)], capture_output=True, text=True)
    assert result.returncode == 0, result.stdout
