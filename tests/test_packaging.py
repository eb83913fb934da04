"""Packaging: every third-party module the code imports is a declared dependency, every module imports, and
the PEP 561 markers (py.typed) ship.

The README's test line installs into a brand-new virtual environment (``.ci/run`` runs it), so an
undeclared dependency fails there too; these tests name the culprit directly.
"""

import ast
import importlib.metadata
import importlib.util
import json
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


#: Modules that import an extra's package at their top, and that package: the import test below imports them only
#: where the package is installed (.ci/run's last check imports every module with every extra installed).
NEEDS_EXTRA = {"volspring._compiled": "numba"}


def _module_name(path: pathlib.Path) -> str:
    return ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")


def test_the_modules_that_need_an_extra_are_the_listed_ones():
    # A module importing an extra's package at its top (not inside a function) fails to import without the extra.
    distributions, declared = importlib.metadata.packages_distributions(), _declared()
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            for node in ast.parse(path.read_text()).body:
                names = [alias.name for alias in node.names] if isinstance(node, ast.Import) else \
                    [node.module] if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module else []
                for name in names:
                    top = name.split(".")[0]
                    owners = [_normalise(owner) for owner in distributions.get(top, [top])]
                    if any(declared.get(owner) for owner in owners):
                        found[_module_name(path)] = top
    assert found == NEEDS_EXTRA


@pytest.mark.parametrize("package", PACKAGES)
def test_every_module_imports_from_an_empty_folder(package, tmp_path):
    # From an empty folder the import resolves to the installed copy (or the editable one), not to
    # the working directory; a module that imports an absent package fails here.
    modules = sorted(name for name in map(_module_name, (ROOT / package).rglob("*.py"))
                     if name not in NEEDS_EXTRA or importlib.util.find_spec(NEEDS_EXTRA[name]) is not None)
    code = "import importlib, sys\nfor name in sys.argv[1:]:\n    importlib.import_module(name)\n"
    done = subprocess.run([sys.executable, "-c", code, *modules], cwd=tmp_path, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]


def _installed_distribution():
    """The installed volspring distribution (its .dist-info), not the ``volspring.egg-info`` an in-tree build
    leaves in the checkout: that one is found first from the repository root, and lists source files."""
    path = [entry for entry in sys.path if entry and pathlib.Path(entry).resolve() != ROOT]
    found = [dist for dist in importlib.metadata.distributions(name="volspring", path=path)
             if dist.files is not None and not any(file.parts[0].endswith(".egg-info") for file in dist.files)]
    if not found:
        pytest.skip("volspring is not installed (pip install .)")
    return found[0]


def test_the_packages_carry_py_typed():
    # PEP 561: a py.typed marker in each import package tells type checkers to read its annotations.
    assert [package for package in PACKAGES if not (ROOT / package / "py.typed").is_file()] == []


def test_the_installed_distribution_ships_py_typed():
    # The markers are package data: without the entries in pyproject.toml's package-data, setuptools leaves
    # them out of the wheel and installed copies are untyped for mypy and pyright.
    distribution = _installed_distribution()
    direct_url = json.loads(distribution.read_text("direct_url.json") or "{}")
    if direct_url.get("dir_info", {}).get("editable"):
        pytest.skip("an editable install lists no package files; the README's `pip install .` (.ci/run) checks it")
    shipped = {str(file) for file in distribution.files}
    assert [package for package in PACKAGES if f"{package}/py.typed" not in shipped] == []
