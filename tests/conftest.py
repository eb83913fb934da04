"""Shared fixtures: the real data carried in tests/data (see its README) and small structured meshes."""

from pathlib import Path

import numpy as np
import pytest

from meshing import TetMesh, structured_box

# Copies of ../shared/data that travel with the repository, so that a clone with nothing beside it passes.
SHARED_DATA = Path(__file__).resolve().parent / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.fail(f"the test data is missing: expected it at {SHARED_DATA} (see tests/data/README.md)")
    return SHARED_DATA


def cube_mesh(cells=(2, 2, 2), size=(1.0, 1.0, 1.0)) -> TetMesh:
    """A box split into cells, each cell into 6 tets (Kuhn split, the same diagonal in every cell)."""
    return structured_box(cells, size, pattern="kuhn")


@pytest.fixture
def unit_cube() -> TetMesh:
    return cube_mesh()


def signal_when_ready(module_argv, ready, signum, *, settle=0.0, timeout=120.0):
    """Run ``python -m <module_argv>``, send ``signum`` once the file ``ready`` exists (plus ``settle`` s).

    Returns (exit status, stderr). The child is killed if anything goes wrong, so a failing test
    never leaves a run behind.
    """
    import subprocess
    import sys
    import time

    child = subprocess.Popen([sys.executable, "-m", *map(str, module_argv)], stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + timeout
        while not Path(ready).exists():
            assert child.poll() is None and time.monotonic() < deadline, child.communicate()[1]
            time.sleep(0.01)
        time.sleep(settle)
        child.send_signal(signum)
        _, stderr = child.communicate(timeout=60)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    return child.returncode, stderr


def rewritten_archive(path, target, **changes):
    """A copy of an .npz archive with some entries replaced (None: removed), written with plain numpy:
    how the file-format tests make damaged, foreign and future files."""
    with np.load(path) as archive:
        arrays = {name: archive[name] for name in archive.files}
    for name, value in changes.items():
        if value is None:
            del arrays[name]
        else:
            arrays[name] = value
    np.savez_compressed(target, **arrays)
    return target


def dense_blocks(element_set, blocks, node_count):
    """(3 n, 3 n) -- an element set's blocks (its block layout) summed into a dense matrix, by plain loops: the
    independent reference the sparse assembly is checked against."""
    A = np.zeros((3 * node_count, 3 * node_count))
    layout, stencil = element_set.block_map, element_set.stencil
    for q in range(len(layout.row)):
        rows, cols = stencil[:, layout.row[q]], stencil[:, layout.column[q]]
        for e in range(len(stencil)):
            A[3 * rows[e]:3 * rows[e] + 3, 3 * cols[e]:3 * cols[e] + 3] += layout.sign[q] * blocks[e, layout.block[q]]
    return A


EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def load_example(name):
    """The example script ``examples/NAME.py`` as a module (its main() not run)."""
    import importlib.util
    import sys

    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def energy_gradient(element_set, x, h=1e-6):
    """(n, 3) -- central differences of an element set's energy at x: the reference its forces are checked against."""
    gradient = np.zeros_like(x)
    for i in range(len(x)):
        for c in range(3):
            step = np.zeros_like(x)
            step[i, c] = h
            gradient[i, c] = (element_set.energy(x + step) - element_set.energy(x - step)) / (2 * h)
    return gradient


# ---------------------------------------------------------------------------- the public API (docstrings, typing)
PACKAGES = ("meshing", "volspring", "validation")


def public_modules(*, skip=()) -> list:
    """Dotted names of the public modules of the three packages: no component starting with ``_``; ``skip``
    names packages (and their submodules) to leave out."""
    import pathlib

    root = pathlib.Path(__file__).resolve().parents[1]
    names = []
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            parts = path.relative_to(root).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            name = ".".join(parts)
            if not any(part.startswith("_") for part in parts) and \
                    not any(name == left or name.startswith(left + ".") for left in skip):
                names.append(name)
    return names


def defined_here(obj) -> bool:
    """Whether ``obj`` is defined in one of the three packages (not re-exported from a dependency)."""
    return (getattr(obj, "__module__", None) or "").split(".")[0] in PACKAGES
