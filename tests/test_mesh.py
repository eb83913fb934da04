"""TetMesh: validation of input, derived geometry and topology, meshio round trips."""

import numpy as np
import pytest

from volspring import TetMesh
from volspring.mesh import signed_tet_volumes

from conftest import cube_mesh

REFERENCE_TET = (np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2, 3]]))


def test_cube_volume_edges_and_boundary():
    mesh = cube_mesh((3, 2, 2), size=(3.0, 1.0, 2.0))
    # A union of cells tiles the box exactly: only round-off (1e-12 of the volume 6) remains.
    assert mesh.volume == pytest.approx(6.0, rel=1e-12)
    assert (mesh.tet_volumes > 0).all()
    # Euler's formula for a triangulated sphere-like closed surface: V - E + F = 2.
    faces = mesh.boundary_faces
    face_edges = np.sort(faces[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
    unique_edges, counts = np.unique(face_edges, axis=0, return_counts=True)
    assert (counts == 2).all(), "every boundary edge is shared by exactly two boundary faces"
    assert len(mesh.boundary_nodes) - len(unique_edges) + len(faces) == 2
    # Outward normals: the divergence theorem gives the volume back from the boundary alone.
    x = mesh.points[faces]
    assert np.einsum("ij,ij->", x[:, 0], np.cross(x[:, 1], x[:, 2])) / 6 == pytest.approx(6.0, rel=1e-12)


def test_edges_are_unique_and_indexed_from_tets():
    mesh = cube_mesh()
    edges = mesh.edges
    assert (edges[:, 0] < edges[:, 1]).all()
    assert len(np.unique(edges, axis=0)) == len(edges)
    from volspring.mesh import TET_EDGES

    rebuilt = np.sort(mesh.tets[:, TET_EDGES], axis=2)
    assert np.array_equal(edges[mesh.tet_edge_index], rebuilt)


def test_node_volumes_sum_to_total():
    mesh = cube_mesh()
    assert mesh.node_volumes().sum() == pytest.approx(mesh.volume, rel=1e-14)


@pytest.mark.parametrize(
    "points, tets, message",
    [
        (np.zeros((4, 2)), np.array([[0, 1, 2, 3]]), "shape"),
        (REFERENCE_TET[0], np.array([[0, 1, 2, 4]]), "indices"),
        (np.vstack([REFERENCE_TET[0], [[5.0, 5, 5]]]), REFERENCE_TET[1], "used by no tet"),
        (np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]), REFERENCE_TET[1], "zero volume"),
        (REFERENCE_TET[0], np.array([[0, 2, 1, 3]]), "negatively oriented"),
        (np.array([[0.0, 0, 0], [1, 0, 0], [0, np.nan, 0], [0, 0, 1]]), REFERENCE_TET[1], "non-finite"),
        (np.empty((0, 3)), np.empty((0, 4), dtype=int), "needs nodes"),
    ],
)
def test_bad_input_is_refused_with_a_reason(points, tets, message):
    with pytest.raises(ValueError, match=message):
        TetMesh(points, tets)


def test_oriented_flips_inverted_tets():
    mesh = TetMesh.oriented(REFERENCE_TET[0], np.array([[0, 2, 1, 3]]))
    assert signed_tet_volumes(mesh.points, mesh.tets)[0] == pytest.approx(1 / 6)


def test_mesh_is_immutable():
    mesh = cube_mesh()
    with pytest.raises(ValueError):
        mesh.points[0, 0] = 1.0
    with pytest.raises(AttributeError):
        mesh.points = np.zeros((1, 3))


@pytest.mark.parametrize("suffix", [".vtu", ".msh", ".xdmf", ".mesh"])
def test_write_read_round_trip(tmp_path, suffix):
    mesh = cube_mesh((2, 3, 1))
    path = mesh.write(tmp_path / f"cube{suffix}")
    back = TetMesh.read(path)
    assert np.allclose(back.points, mesh.points, rtol=0, atol=1e-12)
    assert np.array_equal(back.tets, mesh.tets)


def test_unknown_extension_leaves_no_file(tmp_path):
    with pytest.raises(ValueError, match="unknown mesh file extension"):
        cube_mesh().write(tmp_path / "cube.nonsense")
    assert list(tmp_path.iterdir()) == []


def test_real_bunny_tet_mesh(shared_data):
    mesh = TetMesh.read(shared_data / "coarse_bunny.mesh")
    assert (mesh.node_count, mesh.tet_count) == (699, 2274)  # the data README's figures
    assert (mesh.tet_volumes > 0).all()


@pytest.mark.parametrize("name, content", [("broken.vtu", b"garbage\n"), ("empty.msh", b""), ("empty.vtu", b"")])
def test_unreadable_file_is_a_value_error_not_an_exit(tmp_path, name, content):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(ValueError, match=f"cannot read .*{name}"):
        TetMesh.read(path)


def test_msh_means_gmsh(tmp_path):
    import meshio

    path = cube_mesh().write(tmp_path / "cube.msh")
    # gmsh's own reader accepts what was written: the file is gmsh, not ansys (meshio's first pick).
    assert len(meshio.read(path, file_format="gmsh").points) == cube_mesh().node_count


def test_written_files_get_the_usual_permissions(tmp_path):
    import os

    umask = os.umask(0o022)
    try:
        path = cube_mesh().write(tmp_path / "cube.vtu")
    finally:
        os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o644  # 0666 less the umask, as open() would give
