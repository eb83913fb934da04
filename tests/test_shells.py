"""Virtual shells: spring counts against the surface's combinatorics, offsets along normals, outward layers."""

import logging

import numpy as np
import pytest
from conftest import cube_mesh

from meshing.shells import add_shells
from meshing import SpringTopology, TetMesh


def pitted_box() -> TetMesh:
    """A 3 x 3 x 2-cell unit box with the centre top cell removed: a square pit 1/3 wide and 1/2 deep."""
    box = cube_mesh((3, 3, 2))
    centroids = box.points[box.tets].mean(axis=1)
    pit = (np.abs(centroids[:, 0] - 0.5) < 1 / 6) & (np.abs(centroids[:, 1] - 0.5) < 1 / 6) & (centroids[:, 2] > 0.5)
    return TetMesh.compact(box.points, box.tets[~pit])


@pytest.fixture(scope="module")
def bunny_mesh(shared_data) -> TetMesh:
    return TetMesh.read(shared_data / "coarse_bunny.mesh", scale=1.0)  # the file's own units


def surface_of(mesh: TetMesh):
    """Boundary nodes (v,), faces in local indices (f, 3) and unique edges in local indices (e, 2)."""
    nodes, local = np.unique(mesh.boundary_faces, return_inverse=True)
    faces = local.reshape(-1, 3)
    edges = np.unique(np.sort(faces[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1), axis=0)
    return nodes, faces, edges


def enclosed_volume(points, triangles) -> float:
    """Signed volume enclosed by a closed triangle surface (divergence theorem); > 0 when wound outward."""
    corners = points[triangles]
    return float(np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])).sum() / 6.0)


MESHES = {
    "one tet": lambda: TetMesh(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2, 3]])),
    "box 2x3x2": lambda: cube_mesh((2, 3, 2), size=(1.0, 1.5, 0.8)),
    "pitted box": pitted_box,
}


@pytest.mark.parametrize("layers", [1, 3])
@pytest.mark.parametrize("name", sorted(MESHES))
def test_spring_counts_match_the_surface_combinatorics(name, layers):
    mesh = MESHES[name]()
    nodes, faces, edges = surface_of(mesh)
    vertex_count, edge_count = len(nodes), len(edges)
    assert vertex_count - edge_count + len(faces) == 2  # closed genus-0 surface: the counts below rely on it
    topology = add_shells(mesh, layers=layers, thickness=0.02)
    assert topology.kind_counts() == {
        "tet_edge": len(mesh.edges),
        "shell": layers * vertex_count,
        "shell_diagonal": layers * 2 * edge_count,  # sum of vertex degrees = 2E
        "shell_edge": layers * edge_count,
    }
    assert topology.node_count == mesh.node_count + layers * vertex_count
    assert np.array_equal(np.bincount(topology.shell_layer), [mesh.node_count] + [vertex_count] * layers)
    assert topology.shell_triangles.shape == (layers * len(faces), 3)
    assert topology.shell_thickness == 0.02
    assert np.array_equal(topology.springs[topology.kind_mask("tet_edge")], mesh.edges)


def test_diagonals_join_each_shell_vertex_to_the_one_ring_of_its_source():
    mesh = cube_mesh((2, 2, 2))
    nodes, _, edges = surface_of(mesh)
    topology = add_shells(mesh, layers=2, thickness=0.1)
    # Local surface index of every node: boundary nodes by position in `nodes`, layer-k nodes by their offset.
    local = np.full(topology.node_count, -1)
    local[nodes] = np.arange(len(nodes))
    local[mesh.node_count:] = np.tile(np.arange(len(nodes)), 2)
    directed = {tuple(edge) for edge in np.concatenate([edges, edges[:, ::-1]])}
    for layer in (1, 2):
        for kind, expected in (("shell", {(v, v) for v in range(len(nodes))}), ("shell_diagonal", directed)):
            springs = topology.springs[topology.kind_mask(kind)]
            springs = springs[topology.shell_layer[springs].max(axis=1) == layer]
            # Each spring as (node in this layer, node below).
            upper = topology.shell_layer[springs].argmax(axis=1)
            top, bottom = springs[np.arange(len(springs)), upper], springs[np.arange(len(springs)), 1 - upper]
            assert (topology.shell_layer[bottom] == layer - 1).all()
            assert {(int(a), int(b)) for a, b in zip(local[top], local[bottom])} == expected
            assert len(springs) == len(expected)
        shell_edges = topology.springs[topology.kind_mask("shell_edge")]
        shell_edges = shell_edges[topology.shell_layer[shell_edges[:, 0]] == layer]
        assert (topology.shell_layer[shell_edges] == layer).all()
        assert {tuple(sorted(pair)) for pair in local[shell_edges].tolist()} == {tuple(e) for e in edges.tolist()}


@pytest.mark.parametrize("name", sorted(MESHES))
def test_layers_are_offset_by_the_thickness_along_area_weighted_normals(name):
    mesh, thickness, layers = MESHES[name](), 0.03, 3
    nodes, faces, _ = surface_of(mesh)
    # The area-weighted vertex normals, computed here independently with np.add.at.
    corners = mesh.points[nodes][faces]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normals = np.zeros((len(nodes), 3))
    np.add.at(normals, faces, cross[:, None, :])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    topology = add_shells(mesh, layers=layers, thickness=thickness)
    for layer in range(1, layers + 1):
        layer_points = topology.points[topology.shell_layer == layer]
        # 1e-12: coordinates of order 1 moved by sums of order-1 products; round-off is ~1e-16 per operation.
        np.testing.assert_allclose(layer_points, mesh.points[nodes] + layer * thickness * normals, atol=1e-12)
    rest = topology.rest_lengths[topology.kind_mask("shell")]
    np.testing.assert_allclose(rest, thickness, rtol=1e-12)  # |n| = 1 to round-off


def test_flat_face_vertices_move_straight_out():
    mesh = cube_mesh((4, 4, 4))
    topology = add_shells(mesh, layers=2, thickness=0.05)
    nodes = np.unique(mesh.boundary_faces)
    top_inner = nodes[(mesh.points[nodes, 2] == 1.0) & (np.abs(mesh.points[nodes, :2] - 0.5) < 0.3).all(axis=1)]
    assert len(top_inner) == 9
    shells = topology.points[mesh.node_count:].reshape(2, len(nodes), 3)[:, np.searchsorted(nodes, top_inner)]
    # A vertex inside a flat face has the face's normal (0, 0, 1) exactly, up to round-off of the normalisation.
    np.testing.assert_allclose(shells[1] - mesh.points[top_inner], [[0, 0, 0.1]] * 9, atol=1e-14)


@pytest.mark.parametrize("name", sorted(MESHES))
def test_shell_layers_are_closed_and_wound_outward(name):
    mesh = MESHES[name]()
    topology = add_shells(mesh, layers=3, thickness=0.02)
    per_layer = np.split(topology.shell_triangles, 3)
    volumes = [enclosed_volume(mesh.points, mesh.boundary_faces)]
    volumes += [enclosed_volume(topology.points, triangles) for triangles in per_layer]
    # The boundary encloses the mesh itself: 1e-12 relative is round-off of sums over a few hundred triangles.
    assert volumes[0] == pytest.approx(mesh.volume, rel=1e-12)
    assert np.all(np.diff(volumes) > 0), volumes
    for triangles in per_layer:
        # Every edge of a closed, consistently wound layer appears once in each direction.
        directed = triangles[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2)
        assert len(np.unique(directed, axis=0)) == len(directed)
        assert len(np.unique(np.sort(directed, axis=1), axis=0)) * 2 == len(directed)


def test_real_bunny_shells(bunny_mesh):
    nodes, faces, edges = surface_of(bunny_mesh)
    assert len(nodes) - len(edges) + len(faces) == 2  # the bunny's tet boundary is a closed genus-0 surface
    # The bunny is about 160 units across with tets about 7 units: a shell of 2 x 1 unit is thin against its features.
    topology = add_shells(bunny_mesh, layers=2, thickness=1.0)
    assert topology.kind_counts() == {"tet_edge": len(bunny_mesh.edges), "shell": 2 * len(nodes),
                                      "shell_diagonal": 4 * len(edges), "shell_edge": 2 * len(edges)}
    volumes = [enclosed_volume(topology.points, t) for t in np.split(topology.shell_triangles, 2)]
    assert bunny_mesh.volume < volumes[0] < volumes[1]


def test_no_layers_gives_the_tet_edges_only():
    mesh = cube_mesh()
    topology = add_shells(mesh, layers=0, thickness=0.1)
    reference = SpringTopology.from_mesh(mesh)
    assert np.array_equal(topology.springs, reference.springs)
    assert topology.node_count == mesh.node_count and topology.kind_counts()["shell"] == 0


@pytest.mark.parametrize(
    ("layers", "thickness", "message"),
    [
        (-1, 0.1, "layers = -1 is negative"),
        (1.5, 0.1, "layers = 1.5 is not an integer"),
        (True, 0.1, "layers = True is not an integer"),
        ("2", 0.1, "layers = '2' is not an integer"),
        (1, 0.0, "thickness = 0.0 is not > 0"),
        (1, -0.1, "thickness = -0.1 is not > 0"),
        (1, float("nan"), "thickness = nan is not > 0"),
        (1, float("inf"), "thickness = inf is not > 0"),
        (1, None, "thickness = None is not a number"),
    ],
)
def test_bad_parameters_are_refused(layers, thickness, message):
    with pytest.raises(ValueError, match=message):
        add_shells(cube_mesh(), layers=layers, thickness=thickness)


def test_keyword_only_options():
    with pytest.raises(TypeError):
        add_shells(cube_mesh(), 1, 0.1)


def test_a_shell_folding_into_a_pit_is_refused():
    mesh = pitted_box()
    add_shells(mesh, layers=2, thickness=0.1)  # 0.2 folds nothing yet (the pit is 1/3 wide, 1/2 deep)
    # A third layer reaches 0.3, past the 0.2 to 0.25 where the pit's triangles turn over (measured).
    with pytest.raises(ValueError, match=r"flips \d+ of 92 shell triangles in layer 3"):
        add_shells(mesh, layers=3, thickness=0.1)


def test_real_bunny_thick_shell_is_refused(bunny_mesh):
    # 10 units is more than the bunny's tets (about 7 units): the shell folds where the surface is concave.
    with pytest.raises(ValueError, match=r"thickness = 10.0 with layers = 1 flips \d+ of 1098 shell triangles"):
        add_shells(bunny_mesh, layers=1, thickness=10.0)


def test_nearly_folded_shell_is_reported(caplog):
    # In the pit the first triangles turn over between 0.2 and 0.25 (measured); at 0.2 two of them have shrunk
    # below a tenth of their area, at 0.1 none.
    with caplog.at_level(logging.WARNING, logger="meshing.shells"):
        add_shells(pitted_box(), layers=1, thickness=0.1)
    assert not caplog.records
    with caplog.at_level(logging.WARNING, logger="meshing.shells"):
        add_shells(pitted_box(), layers=1, thickness=0.2)
    assert "2 shell triangle(s) shrink below 0.1" in caplog.text

