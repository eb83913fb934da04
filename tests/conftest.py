"""Shared fixtures: the real data in ../shared/data and a few small meshes built by hand."""

from pathlib import Path

import numpy as np
import pytest

from volspring import TetMesh

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.fail(f"the shared test data is missing: expected it at {SHARED_DATA}")
    return SHARED_DATA


def cube_mesh(cells=(2, 2, 2), size=(1.0, 1.0, 1.0)) -> TetMesh:
    """A box split into cells, each cell into 6 tets (Kuhn split, conforming across cells)."""
    nx, ny, nz = cells
    grid = np.stack(np.meshgrid(*(np.linspace(0, s, c + 1) for s, c in zip(size, cells)), indexing="ij"), -1)
    points = grid.reshape(-1, 3)
    index = np.arange(len(points)).reshape(nx + 1, ny + 1, nz + 1)
    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"))
    corner = [index[i + a, j + b, k + c] for a in (0, 1) for b in (0, 1) for c in (0, 1)]
    # Kuhn's six tets along the diagonal 000 -> 111 of each cell (corner bits abc as a*4 + b*2 + c).
    paths = [(0, 4, 6, 7), (0, 4, 5, 7), (0, 2, 6, 7), (0, 2, 3, 7), (0, 1, 5, 7), (0, 1, 3, 7)]
    tets = np.concatenate([np.stack([corner[p] for p in path], axis=1) for path in paths])
    return TetMesh.oriented(points, tets)


@pytest.fixture
def unit_cube() -> TetMesh:
    return cube_mesh()
