"""Packaging: dependencies as used, one version, the library without matplotlib.

`pyproject.toml` must declare what `lagjax/` imports and nothing it does not; the
version lives in `pyproject.toml` only; matplotlib is the `plot` extra, so importing
every module of the package must work without it.
"""

import ast
import importlib.metadata
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import lagjax

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10: pytest brings tomli
    import tomli as tomllib

ROOT = Path(__file__).resolve().parent.parent
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
# Distribution name → the module it installs, where they differ.
MODULE_OF = {"pyyaml": "yaml"}


def _requirement_name(requirement: str) -> str:
    return re.split(r"[<>=!~\[ ;]", requirement, maxsplit=1)[0].lower()


def _top_level_imports(top_level_only: bool) -> set[str]:
    """Modules imported by the package: at module level, or anywhere."""
    found = set()
    for path in (ROOT / "lagjax").rglob("*.py"):
        tree = ast.parse(path.read_text())
        nodes = tree.body if top_level_only else ast.walk(tree)
        for node in nodes:
            if isinstance(node, ast.Import):
                found |= {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                found.add(node.module.split(".")[0])
    return found - set(sys.stdlib_module_names) - {"lagjax", "__future__"}


def test_declared_dependencies_are_exactly_what_the_package_imports():
    declared = {
        MODULE_OF.get(name, name)
        for name in map(_requirement_name, PYPROJECT["project"]["dependencies"])
    }
    imported_at_load = _top_level_imports(top_level_only=True)
    assert imported_at_load <= declared, imported_at_load - declared  # undeclared
    assert declared <= _top_level_imports(top_level_only=False), (
        declared - _top_level_imports(top_level_only=False)  # declared, never used
    )
    # Plots are an extra; lineax is imported (the projection's in-kernel fallback).
    assert "matplotlib" not in declared and "lineax" in declared


def test_plotting_is_an_extra_that_the_tests_include():
    extras = PYPROJECT["project"]["optional-dependencies"]
    assert any(_requirement_name(r) == "matplotlib" for r in extras["plot"])
    assert "lagjax[plot]" in extras["test"]  # the notebooks and the README plot
    assert {"mkdocs", "mkdocs-material", "mkdocstrings"} <= {
        _requirement_name(r) for r in extras["docs"]
    }


def test_the_library_imports_without_matplotlib():
    script = textwrap.dedent(
        """
        import importlib, pkgutil, sys
        sys.modules["matplotlib"] = None  # any `import matplotlib` now fails
        import lagjax
        for module in pkgutil.walk_packages(lagjax.__path__, "lagjax."):
            importlib.import_module(module.name)
        print("imported", len(sys.modules))
        """
    )
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr[-2000:]


def test_one_version_from_the_metadata():
    assert PYPROJECT["project"]["version"] == lagjax.__version__
    assert importlib.metadata.version("lagjax") == lagjax.__version__
    init = (ROOT / "lagjax" / "__init__.py").read_text()
    assert PYPROJECT["project"]["version"] not in init  # not written twice


def test_license_and_type_marker_ship():
    assert PYPROJECT["project"]["license"] == "Apache-2.0"
    license_text = (ROOT / "LICENSE").read_text()
    assert (
        "Apache License" in license_text and "Version 2.0, January 2004" in license_text
    )
    assert (ROOT / "lagjax" / "py.typed").exists()
    assert "py.typed" in PYPROJECT["tool"]["setuptools"]["package-data"]["lagjax"]
    changelog = (ROOT / "CHANGELOG.md").read_text()
    assert "## Unreleased" in changelog
    assert f"## {lagjax.__version__}" in changelog
