"""The three packages import one way: meshing (geometry) <- volspring (physics) <- validation (reference).

Every ``.py`` file of the three packages is parsed with ``ast`` and every import in it checked, at any
depth: the imports inside functions (the lazy ones that keep ``import volspring`` light) count as much
as those at the top, and so do relative imports, resolved against the importing module.
"""

import ast
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
#: Each package, lowest layer first; a package may import those before it, never those after.
LAYERS = ("meshing", "volspring", "validation")


def imported_modules(path: pathlib.Path, source: str | None = None):
    """(line, module) for every import in a file, relative ones resolved to absolute names."""
    module = ".".join(path.relative_to(ROOT).with_suffix("").parts)
    package = module.rsplit(".", 1)[0] if path.name != "__init__.py" else module.removesuffix(".__init__")
    tree = ast.parse(path.read_text() if source is None else source, filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module
            yield node.lineno, name


def layer_violations(path: pathlib.Path, source: str | None = None) -> list:
    """``"file:line imports module"`` for each import of a higher layer than the file's own package."""
    own = LAYERS.index(path.relative_to(ROOT).parts[0])
    found = []
    for line, module in imported_modules(path, source):
        top = module.split(".")[0]
        if top in LAYERS and LAYERS.index(top) > own:
            found.append(f"{path.relative_to(ROOT)}:{line} imports {module} "
                         f"({path.relative_to(ROOT).parts[0]} must not import {top})")
    return found


def package_files():
    return [path for package in LAYERS for path in sorted((ROOT / package).rglob("*.py"))]


def test_the_packages_hold_files():
    # A guard for the test below: an empty walk would pass it vacuously.
    counts = {package: len(list((ROOT / package).rglob("*.py"))) for package in LAYERS}
    assert all(count > 3 for count in counts.values()), counts


def test_imports_run_one_way():
    violations = [violation for path in package_files() for violation in layer_violations(path)]
    assert not violations, "imports against the layers meshing <- volspring <- validation:\n" + "\n".join(violations)


@pytest.mark.parametrize("source, expected", [
    ("from volspring.mesh import TetMesh\n", ["meshing/example.py:1 imports volspring.mesh"]),
    ("def f():\n    import validation.fem\n", ["meshing/example.py:2 imports validation.fem"]),
    ("import numpy\nfrom meshing import geometry\nfrom . import shells\n", []),
])
def test_the_check_sees_imports_at_any_depth(source, expected):
    # Negative controls: a top-level and a function-level import against the layers are both named
    # with their line; imports of the same or a lower layer (relative ones included) are not.
    found = layer_violations(ROOT / "meshing" / "example.py", source)
    assert [violation.split(" (")[0] for violation in found] == expected


def test_relative_imports_resolve_to_their_package():
    lines = list(imported_modules(ROOT / "volspring" / "collision" / "example.py",
                                  "from ..model import Model\nfrom . import bodies\n"))
    assert lines == [(1, "volspring.model"), (2, "volspring.collision")]
