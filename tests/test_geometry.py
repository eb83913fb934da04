"""The shared geometric kernels of meshing.geometry against cases with known answers."""

import numpy as np
import pytest
from conftest import cube_mesh

from meshing.geometry import (
    area_weighted_vertex_normals,
    barycentric_frames,
    closest_points_on_triangles,
    nearest_surface_points,
    rigid_body_modes,
    signed_tet_volumes,
    triangle_area_normals,
)
from meshing.tolerances import ON_SURFACE, ZERO_VOLUME

# Results built from a few operations on O(1) coordinates carry round-off of a few 1e-16; 1e-12 is far
# above that and far below any error a wrong formula would make (O(0.1) on these cases).
ROUND_OFF = 1e-12

REFERENCE_CORNERS = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


def _random_tets(count, seed):
    """(count, 4, 3) positively oriented, well-shaped tets: the reference tet under random affine maps."""
    rng = np.random.default_rng(seed)
    maps = np.eye(3) + rng.uniform(-0.3, 0.3, (count, 3, 3))  # close to the identity: determinant > 0
    corners = np.einsum("mij,kj->mki", maps, REFERENCE_CORNERS) + rng.uniform(-2, 2, (count, 1, 3))
    assert (signed_tet_volumes(corners.reshape(-1, 3), np.arange(4 * count).reshape(-1, 4)) > 0).all()
    return corners


# ---------------------------------------------------------------------------------------------- barycentric
def test_barycentric_weights_of_the_vertices_are_unit_vectors_and_of_the_centroid_a_quarter():
    corners = _random_tets(50, seed=1)
    frames = barycentric_frames(corners)
    assert not frames.flat.any()
    tets = np.repeat(np.arange(50), 4)
    at_vertices = frames.weights(corners.reshape(-1, 3), tets).reshape(50, 4, 4)
    np.testing.assert_allclose(at_vertices, np.broadcast_to(np.eye(4), (50, 4, 4)), atol=ROUND_OFF)
    at_centroids = frames.weights(corners.mean(axis=1), np.arange(50))
    np.testing.assert_allclose(at_centroids, 0.25, atol=ROUND_OFF)


def test_barycentric_weights_reproduce_any_point_and_test_inside():
    corners = _random_tets(200, seed=2)
    rng = np.random.default_rng(3)
    points = corners.mean(axis=1) + rng.normal(scale=0.3, size=(200, 3))
    inside, weights = barycentric_frames(corners).contains(points, np.arange(200))
    np.testing.assert_allclose(weights.sum(axis=1), 1.0, atol=ROUND_OFF)
    np.testing.assert_allclose(np.einsum("mk,mkd->md", weights, corners), points, atol=ROUND_OFF)
    np.testing.assert_array_equal(inside, weights.min(axis=1) >= -ON_SURFACE)
    assert 20 < inside.sum() < 180, "the sample must hold points inside and outside for the test to mean anything"


def test_a_point_on_a_face_shared_by_two_tets_is_inside_at_least_one():
    # Two tets on either side of the face (1, 2, 3); its centroid lies on both, to round-off of either sign.
    corners = np.array([REFERENCE_CORNERS, REFERENCE_CORNERS[[1, 3, 2, 0]]])
    corners[1, 3] = [1.0, 1.0, 1.0]
    on_face = np.full((2, 3), 1.0 / 3.0)
    inside, weights = barycentric_frames(corners).contains(on_face, np.array([0, 1]))
    assert inside.all()
    assert np.abs(weights.min(axis=1)).max() < ROUND_OFF  # the weight of the opposite corner is 0


def test_flat_tets_contain_nothing():
    # The apex 1e-13 above the base: |V| = 1.7e-14 <= ZERO_VOLUME * 1^3 = 1e-12 is flat; 1e-3 above is not.
    corners = np.array([REFERENCE_CORNERS, REFERENCE_CORNERS])
    corners[0, 3] = [0.2, 0.2, 1e-13]
    corners[1, 3] = [0.2, 0.2, 1e-3]
    frames = barycentric_frames(corners)
    assert frames.flat.tolist() == [True, False]
    assert abs(signed_tet_volumes(corners[0], np.array([[0, 1, 2, 3]]))[0]) <= ZERO_VOLUME
    inside, _ = frames.contains(np.array([[0.1, 0.1, 0.0], [0.1, 0.1, 1e-4]]), np.array([0, 1]))
    assert inside.tolist() == [False, True]


# ---------------------------------------------------------------------------------------------- closest points
TRIANGLE = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


@pytest.mark.parametrize("query, closest, zeros", [
    ((0.2, 0.3, 0.7), (0.2, 0.3, 0.0), ()),           # the face region
    ((-1.0, -0.5, 0.4), (0.0, 0.0, 0.0), (1, 2)),      # corner a
    ((2.0, -0.5, -0.4), (1.0, 0.0, 0.0), (0, 2)),      # corner b
    ((-0.5, 2.0, 0.3), (0.0, 1.0, 0.0), (0, 1)),       # corner c
    ((0.4, -1.0, 0.2), (0.4, 0.0, 0.0), (2,)),         # edge ab
    ((-1.0, 0.7, -0.2), (0.0, 0.7, 0.0), (1,)),        # edge ac
    ((1.0, 0.8, 0.5), (0.6, 0.4, 0.0), (0,)),          # edge bc: (1, 0.8) projects to (0.6, 0.4)
])
def test_closest_point_in_each_voronoi_region_of_a_triangle(query, closest, zeros):
    found, barycentric = closest_points_on_triangles(np.array([query]), *TRIANGLE[:, None])
    np.testing.assert_allclose(found[0], closest, atol=ROUND_OFF)
    np.testing.assert_allclose(barycentric[0] @ TRIANGLE, closest, atol=ROUND_OFF)
    # Outside the face region the weights of the corners not involved are exactly 0 (not round-off).
    assert [i for i in range(3) if barycentric[0, i] == 0.0] == list(zeros)


def test_nearest_surface_points_equal_brute_force():
    rng = np.random.default_rng(4)
    vertices = rng.uniform(-1, 1, (60, 3))
    faces = rng.integers(0, 60, (40, 3))
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])]
    points = rng.uniform(-1.5, 1.5, (300, 3))
    face, closest, _, distance = nearest_surface_points(points, vertices, faces)
    pairs = np.repeat(points, len(faces), axis=0)
    every, _ = closest_points_on_triangles(pairs, *(np.tile(vertices[faces[:, i]], (len(points), 1)) for i in range(3)))
    brute = np.linalg.norm(every - pairs, axis=1).reshape(len(points), len(faces)).min(axis=1)
    np.testing.assert_allclose(distance, brute, atol=ROUND_OFF)
    np.testing.assert_allclose(np.linalg.norm(closest - points, axis=1), distance, atol=ROUND_OFF)


# ---------------------------------------------------------------------------------------------- normals
def _fan_cube():
    """A unit cube's surface, each face a fan of four triangles around its centre, wound outward."""
    corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=float)
    points, faces = list(corners), []
    for axis in range(3):
        for side in (0, 1):
            on_face = np.flatnonzero(corners[:, axis] == side)
            centre = corners[on_face].mean(axis=0)
            # Corners around the face centre, counter-clockwise seen from outside.
            u, v = (axis + 1) % 3, (axis + 2) % 3
            angle = np.arctan2(corners[on_face, v] - centre[v], corners[on_face, u] - centre[u])
            ring = on_face[np.argsort(angle if side == 1 else -angle)]
            points.append(centre)
            faces += [[len(points) - 1, ring[i], ring[(i + 1) % 4]] for i in range(4)]
    return np.array(points), np.array(faces)


def test_vertex_normals_of_a_cube_are_the_face_normals_and_the_corner_diagonals():
    points, faces = _fan_cube()
    outward = np.einsum("fd,fd->f", triangle_area_normals(points, faces), points[faces].mean(axis=1) - 0.5)
    assert (outward > 0).all(), "the fan cube must be wound outward"
    normals = area_weighted_vertex_normals(points, faces)
    # Corners: each lies on two triangles of each of its three faces, all of the same area: the diagonal.
    np.testing.assert_allclose(normals[:8], np.sign(points[:8] - 0.5) / np.sqrt(3), atol=ROUND_OFF)
    # Face centres: every triangle around them lies in the face, so the normal is the face's.
    face_normal = np.where(np.abs(points[8:] - 0.5) > 0.25, np.sign(points[8:] - 0.5), 0.0)
    np.testing.assert_allclose(normals[8:], face_normal, atol=ROUND_OFF)


def test_vertices_without_a_normal_get_zero_rows():
    # Vertex 3 is on no face; vertices 0-2 carry a triangle and the same triangle wound the other way.
    points = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5]])
    normals = area_weighted_vertex_normals(points, np.array([[0, 1, 2], [0, 2, 1]]))
    assert (normals == 0).all()
    normals = area_weighted_vertex_normals(points, np.array([[0, 1, 2]]), node_count=5)
    assert normals.shape == (5, 3) and normals[:3, 2].tolist() == [1.0, 1.0, 1.0] and (normals[3:] == 0).all()


# ---------------------------------------------------------------------------------------------- rigid-body modes
def _spring_stiffness(mesh):
    """(3n, 3n) dense stiffness of unit springs on the tet edges at rest: k r r^T blocks, dof 3 i + c."""
    i, j = mesh.edges.T
    r = mesh.points[j] - mesh.points[i]
    blocks = np.einsum("ea,eb->eab", r, r) / mesh.edge_lengths[:, None, None] ** 3  # k = 1 / l
    K = np.zeros((mesh.node_count, 3, mesh.node_count, 3))
    np.add.at(K, (i, slice(None), i), blocks)
    np.add.at(K, (j, slice(None), j), blocks)
    np.add.at(K, (i, slice(None), j), -blocks)
    np.add.at(K, (j, slice(None), i), -blocks)
    return K.reshape(3 * mesh.node_count, 3 * mesh.node_count)


def _assert_null_space(K, modes):
    """K B ~ 0 relative to ||K|| ||B||, and the null space of K is exactly the span of B (6-dimensional)."""
    # Round-off of a product of O(||K||) entries summed over a few dozen terms: ~1e-15 relative; 1e-12 leaves margin.
    assert np.abs(K @ modes).max() <= ROUND_OFF * np.abs(K).max() * np.abs(modes).max()
    assert np.linalg.matrix_rank(modes) == 6
    values, vectors = np.linalg.eigh(K)
    # The seventh eigenvalue is that of the softest deformation, 3e-3 to 5e-2 of the largest on these meshes
    # (measured); the six of the rigid motions are round-off (below 3e-16 of it): 1e-9 separates them.
    assert (np.abs(values[:6]) < 1e-9 * values[-1]).all() and values[6] > 1e-4 * values[-1]
    basis, _ = np.linalg.qr(modes)
    residual = vectors[:, :6] - basis @ (basis.T @ vectors[:, :6])
    # The computed null space is accurate to round-off over the gap to the seventh eigenvalue (1e-16 / 1e-4).
    assert np.abs(residual).max() < 1e-9


def test_rigid_body_modes_span_the_null_space_of_a_free_spring_network():
    mesh = cube_mesh((2, 2, 1), (1.0, 0.8, 0.5))
    _assert_null_space(_spring_stiffness(mesh), rigid_body_modes(mesh.points))


@pytest.mark.parametrize("element", ["P1", "P2"])
def test_rigid_body_modes_span_the_null_space_of_a_free_fem_stiffness(element):
    from skfem import Basis, ElementTetP1, ElementTetP2, ElementVector, MeshTet, asm
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    mesh = cube_mesh((2, 1, 1), (1.0, 0.5, 0.5))
    skmesh = MeshTet(np.ascontiguousarray(mesh.points.T), np.ascontiguousarray(mesh.tets.T))
    basis = Basis(skmesh, ElementVector({"P1": ElementTetP1, "P2": ElementTetP2}[element]()))
    K = asm(linear_elasticity(*lame_parameters(1.0, 0.3)), basis).toarray()
    components = np.zeros(basis.N, dtype=np.int64)
    for component in range(3):
        components[basis.nodal_dofs[component]] = component
        if element == "P2":
            components[basis.edge_dofs[component]] = component
    centre = mesh.points.mean(axis=0)
    modes = rigid_body_modes(basis.doflocs.T, components=components, centre=centre, scale=0.5)
    _assert_null_space(K, modes)


def test_one_rigid_body_mode_layout_for_nodes_and_for_dofs():
    points = np.random.default_rng(5).uniform(-1, 1, (7, 3))
    by_node = rigid_body_modes(points)
    spread = np.sqrt(((points - points.mean(axis=0)) ** 2).sum(axis=1).mean())  # the default scale
    by_dof = rigid_body_modes(np.repeat(points, 3, axis=0), components=np.tile([0, 1, 2], 7),
                              centre=points.mean(axis=0), scale=spread)
    np.testing.assert_array_equal(by_node, by_dof)
    # Rotations are scaled to the root-mean-square spread q: sum over the three of |e x q|^2 = 2 |q|^2 per
    # point, so their squared norms add up to 2 p, and each translation has squared norm p.
    squared = (by_node**2).sum(axis=0)
    np.testing.assert_allclose(squared[:3], 7.0, rtol=ROUND_OFF)
    np.testing.assert_allclose(squared[3:].sum(), 14.0, rtol=ROUND_OFF)


def test_rigid_body_modes_refuse_bad_input():
    with pytest.raises(ValueError, match=r"points must have shape \(p, 3\), got \(4, 2\)"):
        rigid_body_modes(np.zeros((4, 2)))
    with pytest.raises(ValueError, match=r"components must be 2 values in \{0, 1, 2\}"):
        rigid_body_modes(np.zeros((2, 3)), components=[0, 3])
    with pytest.raises(ValueError, match="scale = 0.0 is not a finite length > 0"):
        rigid_body_modes(np.ones((2, 3)), scale=0.0)
