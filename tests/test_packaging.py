"""Packaging: every third-party module the code imports is a declared dependency, and every module imports.

The README's test line installs into a brand-new virtual environment (``.ci/run`` runs it), so an
undeclared dependency fails there too; these tests name the culprit directly.
"""

import ast
import importlib.metadata
import pathlib
import re
import subprocess
import sys
import tomllib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGES = ("meshing", "volspring", "validation")


def _declared() -> dict:
    """Distribution name (normalised) -> extra ('' for the core dependencies)."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    declared = {}
    for extra, requirements in [("", project["dependencies"])] + list(project.get("optional-dependencies", {}).items()):
        for requirement in requirements:
            name = re.split(r"[<>=!~;\[ ]", requirement, maxsplit=1)[0]
            declared.setdefault(_normalise(name), extra)
    return declared


def _normalise(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _imported_top_level() -> dict:
    """Top-level module name -> first file importing it, over the three packages."""
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.Import):
                    names = [alias.name for alias in node.names]
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    names = [node.module]
                else:
                    continue
                for name in names:
                    found.setdefault(name.split(".")[0], str(path.relative_to(ROOT)))
    return found


def test_every_third_party_import_is_declared():
    distributions = importlib.metadata.packages_distributions()
    declared = _declared()
    missing = []
    for module, where in sorted(_imported_top_level().items()):
        if module in sys.stdlib_module_names or module in PACKAGES or module == "__future__":
            continue
        owners = [_normalise(name) for name in distributions.get(module, [module])]
        if not any(owner in declared for owner in owners):
            missing.append(f"{module} (imported by {where}; distribution {', '.join(owners)})")
    assert not missing, "imported but not declared in pyproject.toml: " + "; ".join(missing)


def test_core_code_needs_no_test_extra():
    # The library runs without the test extra: nothing in the packages imports pytest.
    assert "pytest" not in _imported_top_level()


@pytest.mark.parametrize("package", PACKAGES)
def test_every_module_imports_from_an_empty_folder(package, tmp_path):
    # From an empty folder the import resolves to the installed copy (or the editable one), not to
    # the working directory; a module that imports an absent package fails here.
    modules = sorted(".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
                     for path in (ROOT / package).rglob("*.py"))
    code = "import importlib, sys\nfor name in sys.argv[1:]:\n    importlib.import_module(name)\n"
    done = subprocess.run([sys.executable, "-c", code, *modules], cwd=tmp_path, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
