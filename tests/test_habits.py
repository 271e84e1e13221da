"""Habits of the project: one version source, a changelog section for it, every imported package declared,
and CI that lints, format-checks and type-checks before the README's test command."""

import ast
import re
import sys
from pathlib import Path

import pytest

import jaxbelt

ROOT = Path(__file__).resolve().parents[1]
tomllib = pytest.importorskip("tomllib")
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())


def _requirement_names(requirements) -> set:
    return {re.split(r"[\s<>=!~;\[]", r, maxsplit=1)[0].lower().replace("_", "-") for r in requirements}


def test_the_version_is_written_once():
    project = PYPROJECT["project"]
    assert "version" not in project and "version" in project["dynamic"]
    assert PYPROJECT["tool"]["hatch"]["version"]["path"] == "jaxbelt/__init__.py"
    assert re.fullmatch(r"\d+\.\d+\.\d+", jaxbelt.__version__)


def test_the_changelog_opens_with_this_version():
    text = (ROOT / "CHANGELOG.md").read_text()
    versions = re.findall(r"^## (\d+\.\d+\.\d+)", text, re.M)
    assert versions and versions[0] == jaxbelt.__version__, versions[:2]


def _imported_packages() -> set:
    """Top-level names of every package the library's modules import (at module level or inside functions)."""
    found = set()
    for path in (ROOT / "jaxbelt").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                found |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
                found.add(node.module.split(".")[0])
    return found - set(sys.stdlib_module_names) - {"jaxbelt", "__future__"}


def test_every_imported_package_is_a_declared_dependency():
    declared = _requirement_names(PYPROJECT["project"]["dependencies"])
    imported = {name.lower().replace("_", "-") for name in _imported_packages()}  # import name = distribution name
    assert {"jax", "equinox", "diffrax", "optax", "optimistix", "lineax", "jaxtyping"} <= imported
    missing = sorted(imported - declared)
    assert not missing, f"imported by jaxbelt/ but not in [project] dependencies: {missing}"


def test_the_tools_of_ci_and_the_tests_references_are_dev_dependencies():
    dev = _requirement_names(PYPROJECT["project"]["optional-dependencies"]["dev"])
    assert {"ruff", "pyright", "pytest", "pytest-xdist", "hypothesis", "scipy", "highspy"} <= dev


def test_ci_lints_formats_and_type_checks_before_the_readme_test_command():
    lines = [ln.strip() for ln in (ROOT / ".ci" / "run").read_text().splitlines()]
    lines = [ln for ln in lines if ln and not ln.startswith("#")]
    install = lines.index('python -m pip install -e ".[dev]"')
    commands = ("ruff check .", "ruff format --check .", "pyright", "python -m pytest -n 2 -q -m quick")
    order = [lines.index(cmd) for cmd in commands]
    assert install < order[0] and order == sorted(order)
    # the README's test command (the quick tier, tests/test_docs.py), then the full suite
    assert lines[-2:] == ["python -m pytest -n 2 -q -m quick", "python -m pytest -n 2 -q"]
    assert PYPROJECT["tool"]["pyright"]["typeCheckingMode"] in ("basic", "standard", "strict")


def test_ci_tests_exactly_the_declared_lower_bounds():
    """`.ci/lowest.txt` pins every core dependency at its declared lower bound (and nothing else), and `.ci/run`
    installs it in an environment of its own before the README's test command."""
    bounds = {}
    for requirement in PYPROJECT["project"]["dependencies"]:
        found = re.fullmatch(r"([A-Za-z0-9_.-]+)>=([0-9.]+)(,.*)?", requirement.split(";")[0].strip())
        assert found, f"{requirement!r}: a core dependency needs a lower bound"
        bounds[found.group(1).lower()] = found.group(2)
    pins = {}
    for line in (ROOT / ".ci" / "lowest.txt").read_text().splitlines():
        line = line.split("#")[0].strip()
        if line:
            name, version = line.split("==")
            pins[name.lower()] = version
    assert pins.keys() == bounds.keys()
    for name, version in bounds.items():
        # a bound like numpy>=2.0 is pinned as 2.0.0
        assert pins[name].split(".")[: len(version.split("."))] == version.split("."), (name, pins[name], version)
    run = (ROOT / ".ci" / "run").read_text()
    assert "-c .ci/lowest.txt" in run
    assert run.index("-c .ci/lowest.txt") < run.index("\npython -m pytest -n 2 -q")
