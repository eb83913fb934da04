"""TetMesh: validation of input, derived geometry and topology, meshio round trips."""

import re

import numpy as np
import pytest

from meshing import TetMesh
from meshing.geometry import signed_tet_volumes

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
    from meshing.mesh import TET_EDGES

    rebuilt = np.sort(mesh.tets[:, TET_EDGES], axis=2)
    assert np.array_equal(edges[mesh.tet_edge_index], rebuilt)
    # The index is made on request, not kept with the mesh (48 bytes a tet, read once by a model).
    assert not any(isinstance(value, np.ndarray) and value.size == mesh.tets.size + len(mesh.tets) * 2
                   for value in vars(mesh).values())
    assert all(not isinstance(value, tuple) for value in vars(mesh).values())


def test_raw_array_edges_and_boundary_faces_agree_with_the_mesh():
    """meshing.mesh.tet_edges and boundary_face_mask on bare arrays: the mesh's edges, and its boundary faces."""
    from meshing.mesh import TET_FACES, boundary_face_mask, tet_edges

    mesh = cube_mesh((3, 2, 2))
    assert np.array_equal(tet_edges(mesh.tets), mesh.edges)
    mask = boundary_face_mask(mesh.tets)
    faces = mesh.tets[:, TET_FACES][mask]
    as_set = [np.unique(np.sort(f, axis=1), axis=0) for f in (faces, mesh.boundary_faces)]
    assert len(faces) == len(mesh.boundary_faces) and np.array_equal(*as_set)
    # Two tets sharing a face: each has three boundary faces and the shared one inside.
    two = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    assert boundary_face_mask(two).sum(axis=1).tolist() == [3, 3] and len(tet_edges(two)) == 9


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
    mesh = TetMesh.read(shared_data / "coarse_bunny.mesh", units="mm")
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


# ---------------------------------------------------------------------- orientation and tangles
def pushed_through_mesh():
    """The 2 x 2 x 2 Kuhn cube with its centre node pushed up through the top face: 6 of 48 tets invert.

    Flipping those 6 would count the region they fold over twice: the sum of |volumes| is 1.1 times the cube's.
    """
    mesh = cube_mesh()
    centre = np.flatnonzero((np.abs(mesh.points - 0.5) < 1e-12).all(axis=1))[0]
    points = mesh.points.copy()
    points[centre] = [0.5, 0.5, 1.2]
    return points, np.array(mesh.tets)


def test_pushed_through_mesh_is_what_the_tests_below_assume():
    points, tets = pushed_through_mesh()
    volumes = signed_tet_volumes(points, tets)
    assert (volumes < 0).sum() == 6 and len(volumes) == 48
    # The Kuhn tets' volumes are multiples of 1/240 summing to 264/240: only round-off of 48 terms remains.
    assert np.abs(volumes).sum() == pytest.approx(1.1, rel=1e-12)


def tangled_message(points, tets):
    volumes = signed_tet_volumes(points, tets)
    first = np.flatnonzero(volumes < 0)[0]
    return (rf"the mesh is tangled: 6 of 48 tets are inverted .*first is tet {first} with signed volume "
            rf"{volumes[first]:.3g} m\^3")


def test_partly_inverted_mesh_is_refused_as_tangled():
    points, tets = pushed_through_mesh()
    with pytest.raises(ValueError, match=tangled_message(points, tets)):
        TetMesh.oriented(points, tets)


def test_partly_inverted_mesh_file_is_refused(tmp_path):
    import meshio

    points, tets = pushed_through_mesh()
    path = tmp_path / "tangled.vtu"
    meshio.write(path, meshio.Mesh(points, [("tetra", tets)]))  # meshio, not TetMesh.write: it checks nothing
    with pytest.raises(ValueError, match=tangled_message(points, tets)):
        TetMesh.read(path)


def test_compact_refuses_a_tangle_too():
    points, tets = pushed_through_mesh()
    # Flipped, an inverted tet lies on the same side as each neighbour that was not inverted: count those faces.
    inverted = signed_tet_volumes(points, tets) < 0
    sharing = {}
    for index, tet in enumerate(tets.tolist()):  # 48 tets of a test mesh
        for left_out in range(4):
            sharing.setdefault(frozenset(tet[:left_out] + tet[left_out + 1:]), []).append(index)
    mixed = sum(len(pair) == 2 and inverted[pair[0]] != inverted[pair[1]] for pair in sharing.values())
    assert mixed > 0
    with pytest.raises(ValueError, match=rf"the mesh is tangled: with each tet in positive order, {mixed} face\(s\) "
                                         r"have their two tets on the same side \(the tets overlap\), first are tets"):
        TetMesh.compact(points, tets)


def test_mixed_numbering_without_a_tangle_is_refused_by_oriented_and_fixed_by_compact():
    mesh = cube_mesh()
    tets = np.array(mesh.tets)
    tets[::3, 2:] = tets[::3, 3:1:-1]  # every third tet numbered the other way round: 16 of 48 inverted
    with pytest.raises(ValueError, match=r"16 of 48 tets are inverted .* not tangled .*TetMesh.compact"):
        TetMesh.oriented(mesh.points, tets)
    fixed = TetMesh.compact(mesh.points, tets)
    assert fixed.volume == pytest.approx(1.0, rel=1e-12)  # a tiling of the unit cube: round-off only


def test_every_tet_inverted_is_another_convention_flipped_and_logged(caplog):
    import logging

    mesh = cube_mesh()
    inverted = np.array(mesh.tets)[:, [0, 1, 3, 2]]
    with caplog.at_level(logging.INFO, logger="meshing.mesh"):
        flipped = TetMesh.oriented(mesh.points, inverted)
    assert "all 48 tets are negatively oriented" in caplog.text
    np.testing.assert_array_equal(flipped.tets, mesh.tets)
    assert flipped.volume == pytest.approx(1.0, rel=1e-12)  # a tiling of the unit cube: round-off only


# ---------------------------------------------------------------------- coordinates float64 cannot hold
@pytest.mark.parametrize("factor", [1e150, 1e103])
def test_overflowing_coordinates_are_called_too_large(factor):
    points = REFERENCE_TET[0] * factor
    expected = re.escape(f"coordinates too large: the largest absolute coordinate is {factor:.3g} (node 1)")
    with pytest.raises(ValueError, match=expected) as error:
        TetMesh(points, REFERENCE_TET[1])
    assert "zero volume" not in str(error.value)
    with pytest.raises(ValueError, match="too large"):
        TetMesh.oriented(points, REFERENCE_TET[1][:, [0, 2, 1, 3]])


def test_underflowing_coordinates_are_called_too_small():
    with pytest.raises(ValueError, match=r"too small: the mesh is 1e-110 across"):
        TetMesh(REFERENCE_TET[0] * 1e-110, REFERENCE_TET[1])


def test_large_but_representable_coordinates_are_fine():
    # 1e100 cubed is 1e300, below float64's 1.8e308: the mesh is valid (if absurd).
    assert TetMesh(REFERENCE_TET[0] * 1e100, REFERENCE_TET[1]).volume == pytest.approx(1e300 / 6, rel=1e-12)


# ---------------------------------------------------------------------- XDMF: the .xdmf and its .h5
def test_xdmf_names_its_h5_relatively_and_leaves_no_orphans(tmp_path):
    import shutil

    import meshio

    mesh = cube_mesh((2, 3, 1))
    first = tmp_path / "made"
    for _ in range(2):  # a rewrite must replace the pair, not add to it
        mesh.write(first / "cube.xdmf", point_data={"height": mesh.points[:, 2]})
    assert sorted(path.name for path in first.iterdir()) == ["cube.h5", "cube.xdmf"]
    text = (first / "cube.xdmf").read_text()
    assert "cube.h5:/" in text and str(tmp_path) not in text and ".cube." not in text
    moved = tmp_path / "elsewhere"
    shutil.copytree(first, moved)
    shutil.rmtree(first)
    back = meshio.read(moved / "cube.xdmf")
    np.testing.assert_array_equal(back.points, mesh.points)  # HDF5 float64: bit for bit
    np.testing.assert_array_equal(back.cells_dict["tetra"], mesh.tets)
    np.testing.assert_array_equal(back.point_data["height"], mesh.points[:, 2])


def test_failed_xdmf_write_leaves_nothing(tmp_path):
    mesh = cube_mesh()
    with pytest.raises(Exception):
        mesh.write(tmp_path / "cube.xdmf", point_data={"wrong_length": np.zeros(3)})
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------- units on read
def test_read_in_millimetres(shared_data, recwarn):
    metres = TetMesh.read(shared_data / "coarse_bunny.mesh", scale=1.0)  # explicit scale: no size warning
    millimetres = TetMesh.read(shared_data / "coarse_bunny.mesh", units="mm")
    assert len(recwarn) == 0
    np.testing.assert_allclose(millimetres.points, metres.points * 1e-3, rtol=1e-15)  # one multiplication
    assert millimetres.volume == pytest.approx(metres.volume * 1e-9, rel=1e-12)  # round-off of the sums only
    doubled = TetMesh.read(shared_data / "coarse_bunny.mesh", units="cm", scale=2.0)
    np.testing.assert_allclose(doubled.points, metres.points * 0.02, rtol=1e-15)  # units x scale


def test_bunny_read_in_metres_warns_about_its_size(shared_data, caplog):
    with pytest.warns(UserWarning, match=r"coarse_bunny.mesh is 262 m across .*units=\"mm\".*--units mm"):
        TetMesh.read(shared_data / "coarse_bunny.mesh")
    assert "262 m across" in caplog.text  # logged as well


@pytest.mark.parametrize("options, fragment", [
    ({"units": "inch"}, "units = 'inch' is not a known length unit; expected one of 'm', 'cm', 'mm'"),
    ({"scale": 0.0}, "scale = 0.0 is not a finite number > 0"),
])
def test_read_refuses_bad_units_before_reading(tmp_path, options, fragment):
    with pytest.raises(ValueError, match=fragment):
        TetMesh.read(tmp_path / "missing.vtu", **options)
