"""Shared fixtures: the real data in ../shared/data and small structured meshes."""

from pathlib import Path

import pytest

from meshing import structured_box
from volspring import TetMesh

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.fail(f"the shared test data is missing: expected it at {SHARED_DATA}")
    return SHARED_DATA


def cube_mesh(cells=(2, 2, 2), size=(1.0, 1.0, 1.0)) -> TetMesh:
    """A box split into cells, each cell into 6 tets (Kuhn split, the same diagonal in every cell)."""
    return structured_box(cells, size, pattern="kuhn")


@pytest.fixture
def unit_cube() -> TetMesh:
    return cube_mesh()
