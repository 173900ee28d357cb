"""Packaging facts: one version, a licence file matching the declared licence."""

from __future__ import annotations

import importlib.metadata
import re
from pathlib import Path

import pytest

import coloradar

ROOT = Path(__file__).resolve().parents[1]


def _pyproject() -> dict:
    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11
    return tomllib.loads((ROOT / "pyproject.toml").read_text())


def test_version_is_written_in_one_place():
    project = _pyproject()["project"]
    # No literal version in pyproject.toml: setuptools reads coloradar/_version.py.
    assert "version" not in project
    assert "version" in project["dynamic"]
    attr = _pyproject()["tool"]["setuptools"]["dynamic"]["version"]["attr"]
    assert attr == "coloradar._version.__version__"
    # The package and its installed metadata report that same string.
    from coloradar import _version

    assert coloradar.__version__ == _version.__version__
    assert importlib.metadata.version("coloradar") == coloradar.__version__
    # And nothing else in the package spells a version out.
    hits = [p for p in (ROOT / "src" / "coloradar").rglob("*.py") if p.name != "_version.py"
            and re.search(r"__version__\s*=", p.read_text(encoding="utf-8"))]
    assert hits == []


def test_license_file_matches_declared_licence():
    text = (ROOT / "LICENSE").read_text(encoding="utf-8")
    assert text.startswith("MIT License")
    assert "coloradar contributors" in text
    assert _pyproject()["project"]["license"] == {"text": "MIT"}


def _project_texts():
    for folder in ("src", "tests", "docs", "benchmarks"):
        for p in (ROOT / folder).rglob("*"):
            if p.suffix in (".py", ".md") and p.is_file():
                yield p
    yield ROOT / "README.md"


def test_citations_point_at_sections_of_docs_conventions():
    sections = set(re.findall(r"^## (\d+)\. ", (ROOT / "docs" / "conventions.md").read_text(
        encoding="utf-8"), flags=re.M))
    assert sections == {"1", "2", "3", "4"}
    cited = set()
    for p in _project_texts():
        text = p.read_text(encoding="utf-8")
        # The design notes the project started from are not shipped; cite our own document.
        assert "DESIGN" + ".md" not in text, p
        cited |= set(re.findall(r"conventions(?:\.md)? §(\d+)", text))
    assert cited and cited <= sections


def test_ci_tests_the_oldest_declared_numpy_and_scipy():
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    for dep in _pyproject()["project"]["dependencies"]:
        name, low = re.fullmatch(r"(numpy|scipy)>=([\d.]+)", dep).groups()
        pinned = re.search(rf"OLDEST_{name.upper()}=([\d.]+)", ci).group(1)
        # The CI pin is the newest patch release of the declared lowest minor version.
        assert pinned.split(".")[:2] == low.split(".")[:2], (dep, pinned)
