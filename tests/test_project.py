"""Project hygiene a contributor relies on: layout, faces, layers, install, CI command, lint."""

from __future__ import annotations

import ast
import importlib
import re
import subprocess
import sys
from pathlib import Path

from conftest import ROOT

PACKAGES = {"samba": "samba", "samba.db": "db", "samba.ingest": "ingest"}
PACKAGES |= {"samba.export": "export", "samba.service": "service"}
"""Installed package -> its folder in the repository."""
SOURCE_FOLDERS = (*PACKAGES.values(), "tests", "bench")
MAX_MODULE_LINES = 600


def _modules() -> list[Path]:
    """Every Python file of the packages, tests and benchmarks."""
    return sorted(p for folder in SOURCE_FOLDERS for p in (ROOT / folder).rglob("*.py"))


def test_layout_and_packages() -> None:
    for name in (*PACKAGES.values(), "tests", "bench", "docs"):
        assert (ROOT / name).is_dir(), name
    for package in PACKAGES:
        assert importlib.import_module(package).__doc__, package


def test_samba_holds_only_subpackages_and_the_command() -> None:
    top = {p.name for p in (ROOT / "samba").glob("*.py")}
    assert top == {"__init__.py", "cli.py"}
    subpackages = [p.parent for p in (ROOT / "samba").glob("*/__init__.py")]
    assert len(subpackages) >= 8
    for folder in subpackages:
        face = ast.get_docstring(ast.parse((folder / "__init__.py").read_text()))
        assert face and len(face.split()) >= 12, f"{folder.name}/__init__.py: say what it owns"


def test_every_package_face_says_what_it_owns() -> None:
    for folder in PACKAGES.values():
        for init in (ROOT / folder).rglob("__init__.py"):
            assert ast.get_docstring(ast.parse(init.read_text())), init.relative_to(ROOT)


def test_no_module_is_over_600_lines() -> None:
    long = {
        str(p.relative_to(ROOT)): n
        for p in _modules()
        if (n := len(p.read_text().splitlines())) > MAX_MODULE_LINES
    }
    assert not long, long


def test_the_install_holds_only_samba_and_keeps_its_layers(tmp_path: Path) -> None:
    """`pip install` puts one package at the top of site-packages (the repository's db/,
    ingest/, export/ and service/ go under samba/), and import-linter's contracts hold on
    it: layers, markerless independent of the marker chain, no cycles, faces."""
    site = tmp_path / "site"
    result = subprocess.run(
        [str(ROOT / ".ci" / "lint-imports"), "--site", str(site), sys.executable],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-2000:]
    assert re.search(r"Contracts: \d+ kept, 0 broken", result.stdout)
    top = {p.name for p in site.iterdir() if p.name != "bin"}
    assert {n for n in top if not n.endswith(".dist-info")} == {"samba"}, top
    for package, folder in PACKAGES.items():
        installed = site / package.replace(".", "/")
        sources = {p.relative_to(ROOT / folder) for p in (ROOT / folder).rglob("*.py")}
        copied = {p.relative_to(installed) for p in installed.rglob("*.py")}
        assert sources <= copied, sorted(sources - copied)
    assert (site / "samba/service/viewer_page/index.html").is_file()


def test_ci_runs_the_readme_test_commands() -> None:
    """CI installs as the README says and runs its full suite command (the last one)."""
    readme = (ROOT / "README.md").read_text()
    install = next(
        c
        for c in re.findall(r"^    (python3 -m venv .*)$", readme, flags=re.MULTILINE)
        if "[test]" in c
    )
    suite = re.findall(r"^    (\.venv/bin/python -m pytest .*)$", readme, flags=re.MULTILINE)
    assert suite and "-m" not in suite[-1].split()[4:], suite  # the whole suite, unfiltered
    ci = (ROOT / ".ci" / "run").read_text()
    assert install in ci and suite[-1] in ci
    assert ".ci/lint-imports" in ci and "mkdocs build --strict" in ci


def test_ruff_is_clean() -> None:
    ruff = Path(sys.executable).with_name("ruff")  # the test extra installs it beside python
    assert ruff.is_file(), f"{ruff} missing: pip install -e '.[test]' installs it"
    result = subprocess.run([str(ruff), "check", str(ROOT)], capture_output=True, text=True)
    assert result.returncode == 0, result.stdout
