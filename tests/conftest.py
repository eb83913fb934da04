"""Shared fixtures: the real data carried in tests/data (see its README) and small structured meshes."""

from pathlib import Path

import pytest

from meshing import structured_box
from volspring import TetMesh

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
