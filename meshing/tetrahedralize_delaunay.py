"""The Delaunay backend of :func:`meshing.tetrahedralize.tetrahedralize`: Delaunay of Steiner points
(the seed's method).

A BCC lattice of cube edge ``size``, jittered by a seeded random generator, is kept inside the surface
and away from it; with the surface vertices and a band of points just outside, scipy's Delaunay
triangulates everything, and the tets whose centroid lies inside the surface are kept, so every
surface vertex is a mesh node. Before that, the surface vertices slide slightly along the surface
(:func:`_slid_along_surface`) so that grids of cocircular points stop being degenerate. After it,
flat and sliver tets on the boundary are peeled off (:func:`_peel_slivers`), surface vertices left in
no tet get one (:func:`_covering`), and boundary edges or vertices that are not manifold are fixed by
adding the band tets around them or dropping kept ones (:func:`_repair_boundary`); each step is logged.

The enclosing band (default): the facets of a curved surface are chords that cut inside it by their sag, about
``h^2 / (8 rho)`` for edges ``h`` on a radius of curvature ``rho``, so a finer render surface of the same shape
would lie mostly outside tets whose boundary is the facets. First, :func:`_enclosing_offsets` moves every
vertex outward by 1.5 x the sag of its facets (and of the flipped facet pairs Delaunay may produce instead),
so the tets' boundary is a thin sheet above the smooth surface; flat facets and creases stay where they are.
The sag of a triangle is the height of its PN triangle (the cubic patch through its corners and their normals)
above its plane, so that the S-shaped and one-sided bulges at the folds of a coarse scan are counted too.
Where a vertex's triangles fan out too widely for one sag-weighted direction (the folds of a coarse scan), it takes
the shortest move that lifts every one of its triangles' planes by its sag instead (:func:`_least_lift`), so that
no fan folds over the vertex's old position.
Then, after the Delaunay build, the curved surface edges that no kept tet has (Delaunay took the other diagonal of
their two facets, or points outside the surface kept it from both) and under which that modelled surface pokes out
of the tets (:func:`_poking`) are split at their midpoints and the tets built once more: shorter edges are joined,
as in the edge splitting by which constrained Delaunay meshers recover a surface.
The sheet's volume goes as ``(h / rho)^2``: measured +1 to +2% of the body at 4-6 edges per radius.
"""

from __future__ import annotations

import logging

import numpy as np

from meshing.geometry import signed_tet_volumes
from meshing.mesh import TET_FACES
from meshing.surface_winding import winding_numbers
from meshing.tolerances import SAME_PLANE_COSINE, ZERO_VOLUME

__all__: list[str] = []

# The logger of tetrahedralize(), which this backend serves: one name to configure for both.
logger = logging.getLogger("meshing.tetrahedralize")

# The tuning, in units of `size`, in one place.
_JITTER = 0.1  # lattice points move by up to this much in each coordinate (breaks ties, stays well shaped)
_CLEARANCE = 0.5  # lattice points closer than this to the surface are dropped (they would make slivers)
_BAND = 0.5  # band points sit this far outside the surface, along the vertex normals
_SLIVER_RADIUS_RATIO = 0.05  # boundary tets below this radius ratio are peeled off
_REPAIR_ROUNDS = 8
_SMOOTH_COSINE = np.cos(np.radians(30.0))  # a vertex whose faces all lie within 30 deg of its normal is smooth
# The enclosing band (see _enclosing_offsets).
_BAND_MARGIN = 1.5  # offset by 1.5x the estimated chord sag: the curvature from discrete normals is approximate
_BAND_SAMPLES = 8  # the sag of a facet is the largest of its PN patch's height on a grid of 8 divisions per edge
_FLIP_ANGLE = np.radians(150.0)  # facet pairs whose opposite angles sum past 150 deg may come out flipped
# No vertex moves by more than 0.5 x its shortest edge (keeps the offset surface unfolded; 0.25 left 17 of the
# finer bunny's vertices outside the moved facets at its folds, 0.5 leaves 5, for 0.4% more volume [measured]).
_BAND_CAP = 0.5


def _delaunay_tets(surface, size, seed, movable_surface, enclosing_band=True, feature_angle=40.0):
    """(points, tets) filling ``surface`` (a checked ``trimesh.Trimesh``) with tets of edge about ``size`` [m];
    ``movable_surface``: whether the surface's own vertices may move (a built-in shape's triangulation; a
    loaded surface keeps them where they are); ``enclosing_band``: first move the vertices outward by
    :func:`_enclosing_offsets`, so that the tets enclose the smooth surface the facets are chords of, with
    edges sharper than ``feature_angle`` [degrees] taken as creases."""
    import trimesh

    if not enclosing_band:
        return _built(surface, size, seed, movable_surface)[:2]
    offsets = _enclosing_offsets(surface, feature_angle)
    moved = np.linalg.norm(offsets, axis=1)
    logger.info("delaunay: enclosing band: %d of %d surface vertices moved outward, by up to %.3g (median %.3g)",
                (moved > 0).sum(), len(moved), moved.max(), np.median(moved[moved > 0]) if moved.any() else 0.0)
    points, tets, built, lattice = _built(trimesh.Trimesh(surface.vertices + offsets, surface.faces, process=False),
                                          size, seed, movable_surface)
    # Where Delaunay did not join a curved edge of the surface (it took the other diagonal of the two facets, or
    # points outside kept it from both), and the smooth surface the band models pokes out above that diagonal,
    # split the edge at its midpoint (on the moved facets, so the sheet keeps its shape) and rebuild once: most of
    # the shorter edges are joined (a recovery by edge splitting, as constrained Delaunay meshers do). On the
    # finer-bunny test 24 of the 285 such edges are split, and the finer vertices under flipped edges fall from 84
    # to 22 [measured]; the built-in shapes' flips lie above their smooth surface (none split).
    missing = _missing_edges(built, tets, feature_angle)
    count = len(built.vertices)
    edge_key = built.edges_unique[:, 0] * count + built.edges_unique[:, 1]
    pairs = np.sort(surface.face_adjacency_edges, axis=1)  # the input's own edges keep their vertices' indices
    rows = np.flatnonzero(np.isin(pairs[:, 0] * count + pairs[:, 1], edge_key[missing]))
    poking = rows[_poking(surface, built, rows, feature_angle)]
    split = np.isin(edge_key, pairs[poking, 0] * count + pairs[poking, 1])
    if split.any():
        logger.info("delaunay: enclosing band: %d curved surface edge(s) flipped under the modelled surface (of %d "
                    "edges no kept tet has); split them and rebuilt", split.sum(), missing.sum())
        built = _split_edges(built, split)
        points, tets = _kept_tets(built, lattice, size)
    return points, tets


def _built(surface, size, seed, movable_surface):
    """(points, tets, the surface they fill, the lattice points): ``surface`` subdivided to edges <= ``size``,
    slid (:func:`_slid_along_surface`), then filled by :func:`_kept_tets` with a jittered BCC lattice."""
    import trimesh
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(seed)
    movable = np.ones(len(surface.vertices), dtype=bool) if movable_surface else np.zeros(len(surface.vertices), bool)
    # Edges up to sqrt(2) size are what a grid of spacing size has across its diagonals: leave those alone.
    if surface.edges_unique_length.max() > 1.5 * size:
        vertices, faces = trimesh.remesh.subdivide_to_size(surface.vertices, surface.faces, max_edge=size, max_iter=30)
        movable = np.r_[movable, np.ones(len(vertices) - len(movable), dtype=bool)]  # new vertices come last
        surface = trimesh.Trimesh(vertices, faces, process=False)
        logger.info("subdivided the surface to edges <= size: %d vertices", len(surface.vertices))
    surface = _slid_along_surface(surface, movable, rng)
    # Distances to the surface, approximated by a dense sample of it (vertices, edge midpoints, face centres).
    sample = np.concatenate([surface.vertices, surface.vertices[surface.edges_unique].mean(axis=1),
                             surface.triangles_center])
    # BCC lattice (cube corners plus cube centres): its Delaunay tets are well shaped, unlike a cubic lattice's.
    low, high = surface.bounds
    grid = np.stack(np.meshgrid(*(np.arange(a - size, b + size, size) for a, b in zip(low, high)), indexing="ij"), -1)
    lattice = np.concatenate([grid.reshape(-1, 3), grid.reshape(-1, 3) + size / 2])
    lattice += rng.uniform(-_JITTER * size, _JITTER * size, lattice.shape)
    lattice = lattice[winding_numbers(surface.vertices, surface.faces, lattice) > 0]
    lattice = lattice[cKDTree(sample).query(lattice)[0] >= _CLEARANCE * size]
    return (*_kept_tets(surface, lattice, size), surface, lattice)


def _kept_tets(surface, lattice, size):
    """(points, tets): the Delaunay tets of the surface vertices, the ``lattice`` points inside and a band of points
    outside, that fill ``surface``: the surface vertices are the first points."""
    from scipy.spatial import Delaunay, cKDTree

    from meshing.quality import _raw_metrics

    vertices, faces = surface.vertices, surface.faces
    sample = np.concatenate([vertices, vertices[surface.edges_unique].mean(axis=1), surface.triangles_center])
    near = cKDTree(sample)

    band = vertices + _BAND * size * surface.vertex_normals
    # In tight concave spots the offset points can land inside the body or crowd the surface: drop those.
    band = band[(winding_numbers(vertices, faces, band) == 0) & (near.query(band)[0] >= 0.5 * _BAND * size)]
    band = band[_thinned(band, 0.5 * size)]

    points = np.concatenate([vertices, lattice, band])
    surface_count = len(vertices)
    triangulation = Delaunay(points)
    if len(triangulation.coplanar):
        logger.warning("qhull left out %d point(s) as coincident", len(triangulation.coplanar))
    tets = triangulation.simplices.astype(np.int64)
    flip = signed_tet_volumes(points, tets) < 0
    tets[flip] = tets[flip][:, [0, 1, 3, 2]]
    centroids = points[tets].mean(axis=1)
    inside = winding_numbers(vertices, faces, centroids) > 0
    # The band: tets outside the surface whose centroid lies within the offset surface through the band points.
    offset = vertices + _BAND * size * surface.vertex_normals
    in_band = ~inside & (winding_numbers(offset, faces, centroids) > 0)
    # Tets made of band points only are the slivers of the convex hull's skin, not part of the band layer.
    in_band &= ~(tets >= surface_count + len(lattice)).all(axis=1)
    volumes, _, ratio = _raw_metrics(points, tets)
    flat = volumes <= ZERO_VOLUME * np.ptp(points[tets], axis=1).max(axis=1) ** 3  # the TetMesh zero-volume rule
    sliver = flat | (ratio < _SLIVER_RADIUS_RATIO)
    keep = inside & ~flat
    logger.info("delaunay: %d points (%d surface, %d lattice, %d band), %d tets, %d kept (%s)", len(points),
                surface_count, len(lattice), len(band), len(tets), keep.sum(), "centroid inside")
    keep = _peel_slivers(tets, keep, sliver)
    # Band tets glued to a flat tet would wall it in: a zero-volume void with two different triangulations
    # of one planar quad on its sides, which no choice of tets can make manifold. Never add those.
    addable = in_band & ~sliver & ~_touches_flat(tets, flat, len(points))
    keep = _covering(tets, keep, addable | (inside & ~flat), ratio, surface_count)
    keep = _repair_boundary(tets, keep, addable, len(points), surface_count)
    interior_slivers = (keep & sliver).sum()
    if interior_slivers:
        logger.info("delaunay: kept %d interior sliver(s) (radius ratio < %g) to avoid voids",
                    interior_slivers, _SLIVER_RADIUS_RATIO)
    return points, tets[keep]


def _missing_edges(surface, tets, feature_angle):
    """(e,) bool over ``surface.edges_unique`` -- the curved edges (their two facets neither coplanar nor meeting
    at a crease sharper than ``feature_angle`` [degrees]) that are edges of no tet in ``tets`` (whose first nodes
    are the surface's vertices): there the tets' boundary is not the surface."""
    node_count = int(tets.max()) + 1
    tet_edges = np.sort(tets[:, [0, 1, 0, 2, 0, 3, 1, 2, 1, 3, 2, 3]].reshape(-1, 2), axis=1)
    key = surface.edges_unique[:, 0] * node_count + surface.edges_unique[:, 1]  # sorted pairs
    present = np.isin(key, tet_edges[:, 0] * node_count + tet_edges[:, 1])
    cosine = np.einsum("ej,ej->e", *(surface.face_normals[surface.face_adjacency[:, i]] for i in (0, 1)))
    smooth = (cosine < 1 - SAME_PLANE_COSINE) & (cosine > np.cos(np.radians(feature_angle)))
    pairs = np.sort(surface.face_adjacency_edges[smooth], axis=1)
    return ~present & np.isin(key, pairs[:, 0] * node_count + pairs[:, 1])


def _barycentric_grid(divisions):
    """(g, 3) float -- the barycentric coordinates of a triangular grid of ``divisions`` per edge."""
    return np.array([(i, j, divisions - i - j) for i in range(divisions + 1) for j in range(divisions + 1 - i)],
                    dtype=np.float64) / divisions


def _corner_normals(surface, triangles, triangle_normals, feature_cosine):
    """(t, 3, 3) float -- unit normals at the corners of ``triangles`` (t, 3) (vertices of ``surface``, outward unit
    normals ``triangle_normals``): the faces around each corner within ``feature_cosine`` of the triangle (its side
    of creases), weighted after N. Max 1999 ("Weights for computing vertex normals from facet normals"): each face's
    normal times sin(angle) / (product of its two edges at the corner), exact for vertices on a sphere."""
    vertices, faces, normals = surface.vertices, surface.faces, surface.face_normals
    x = vertices[faces]
    to_next, to_previous = np.roll(x, -1, axis=1) - x, np.roll(x, 1, axis=1) - x
    weights = np.linalg.norm(np.cross(to_next, to_previous), axis=2) / (
        np.einsum("fcj,fcj->fc", to_next, to_next) * np.einsum("fcj,fcj->fc", to_previous, to_previous))
    vertex_faces = surface.vertex_faces  # (n, k) padded with -1
    padded_faces = np.vstack([faces, np.full((1, 3), -1)])
    slot = np.argmax(padded_faces[vertex_faces] == np.arange(len(vertices))[:, None, None], axis=2)  # (n, k)
    around_normals = np.vstack([normals, np.zeros((1, 3))])[vertex_faces]  # (n, k, 3), zero padding
    around_weights = np.vstack([weights, np.zeros((1, 3))])[vertex_faces, slot]  # (n, k)
    smooth = np.einsum("tckj,tj->tck", around_normals[triangles], triangle_normals) > feature_cosine
    return _unit(np.einsum("tck,tckj->tcj", around_weights[triangles] * smooth, around_normals[triangles]))


def _pn_points(corners, normals, grid):
    """(t, g, 3) float -- the PN triangles (Vlachos et al. 2001: the cubic Bezier patch through a triangle's corners
    with their normals) of ``corners`` (t, 3, 3) with ``normals`` (t, 3, 3), at the barycentric ``grid`` (g, 3)."""
    from math import factorial

    def control(i, j):  # the edge control point near corner i towards corner j
        w = np.einsum("tj,tj->t", corners[:, j] - corners[:, i], normals[:, i])[:, None]
        return (2 * corners[:, i] + corners[:, j] - w * normals[:, i]) / 3

    terms = {(3, 0, 0): corners[:, 0], (0, 3, 0): corners[:, 1], (0, 0, 3): corners[:, 2],
             (2, 1, 0): control(0, 1), (1, 2, 0): control(1, 0), (0, 2, 1): control(1, 2),
             (0, 1, 2): control(2, 1), (1, 0, 2): control(2, 0), (2, 0, 1): control(0, 2)}
    edge_mean = sum(point for powers, point in terms.items() if 3 not in powers) / 6
    terms[(1, 1, 1)] = edge_mean + (edge_mean - corners.mean(axis=1)) / 2
    points = np.zeros((len(corners), len(grid), 3))
    for (i, j, k), point in terms.items():  # ten Bernstein terms, each over every triangle and grid point at once
        weight = 6 / (factorial(i) * factorial(j) * factorial(k)) * grid[:, 0] ** i * grid[:, 1] ** j * grid[:, 2] ** k
        points += weight[None, :, None] * point[:, None, :]
    return points


def _poking(surface, built, rows, feature_angle):
    """(r,) bool -- for the facet pairs ``rows`` of ``surface`` (face-adjacency rows), whether the smooth surface
    the band models (the two facets' PN triangles, from their corner normals) pokes out above the pair's other
    diagonal, the two triangles Delaunay makes when it flips the pair, at the moved positions of ``built`` (whose
    first vertices are those of ``surface``)."""
    if len(rows) == 0:
        return np.zeros(0, dtype=bool)
    pairs = surface.face_adjacency[rows]
    edge, opposite = surface.face_adjacency_edges[rows], surface.face_adjacency_unshared[rows]
    grid = _barycentric_grid(_BAND_SAMPLES)
    faces = surface.faces[pairs.ravel()]
    corners = surface.vertices[faces]
    normals = _corner_normals(surface, faces, surface.face_normals[pairs.ravel()], np.cos(np.radians(feature_angle)))
    bulge = _pn_points(corners, normals, grid).reshape(len(rows), -1, 3)  # both facets' samples per pair
    x = built.vertices
    outward = surface.face_normals[pairs].sum(axis=1)
    height = []
    for end in (0, 1):  # the flipped triangles (c, d, a) and (c, d, b), their normals turned outward
        a, c, d = x[edge[:, end]], x[opposite[:, 0]], x[opposite[:, 1]]
        normal = _unit(np.cross(d - c, a - c))
        normal *= np.sign(np.einsum("rj,rj->r", normal, outward))[:, None]
        height.append(np.einsum("rgj,rj->rg", bulge - c[:, None], normal))
    return (np.minimum(*height) > 0).any(axis=1)


def _opposite_angles(surface):
    """(e,) float -- for each pair of adjacent facets, the sum of the two angles opposite their shared edge [rad]."""
    vertices = surface.vertices
    edge, opposite = surface.face_adjacency_edges, surface.face_adjacency_unshared
    return sum(np.arccos(np.clip(np.einsum("ej,ej->e", _unit(vertices[edge[:, 0]] - vertices[opposite[:, i]]),
                                           _unit(vertices[edge[:, 1]] - vertices[opposite[:, i]])), -1, 1))
               for i in (0, 1))


def _split_edges(surface, split):
    """``surface`` with the edges ``split`` ((e,) bool over ``surface.edges_unique``) split at their midpoints,
    each facet into 2, 3 or 4 (one, two or three split edges; no hanging vertices); the old vertices keep their
    indices, the midpoints come after them."""
    import trimesh

    vertices, faces = surface.vertices, surface.faces
    midpoint = np.full(len(split), -1)
    midpoint[split] = len(vertices) + np.arange(split.sum())
    vertices = np.concatenate([vertices, vertices[surface.edges_unique[split]].mean(axis=1)])
    mids = midpoint[surface.faces_unique_edges]  # (f, 3): edge i runs from corner i to corner i + 1
    count = (mids >= 0).sum(axis=1)
    # Roll each face so that its split edge is edge 0 (one split) or its unsplit edge is edge 2 (two splits).
    first = np.where(count == 1, np.argmax(mids >= 0, axis=1), (np.argmax(mids < 0, axis=1) + 1) % 3)
    roll = (np.arange(3)[None, :] + first[:, None]) % 3
    c = np.take_along_axis(faces, roll, axis=1)
    m = np.take_along_axis(mids, roll, axis=1)
    one, two, three = (count == 1), (count == 2), (count == 3)
    new = [faces[count == 0],
           np.c_[c[one, 0], m[one, 0], c[one, 2]], np.c_[m[one, 0], c[one, 1], c[one, 2]],
           np.c_[c[three, 0], m[three, 0], m[three, 2]], np.c_[m[three, 0], c[three, 1], m[three, 1]],
           np.c_[m[three, 2], m[three, 1], c[three, 2]], np.c_[m[three, 0], m[three, 1], m[three, 2]],
           np.c_[m[two, 0], c[two, 1], m[two, 1]]]
    # Two splits leave a quad (corner 0, midpoint 0, midpoint 1, corner 2): cut it along its shorter diagonal.
    quad = np.c_[c[two, 0], m[two, 0], m[two, 1], c[two, 2]]
    short = (np.linalg.norm(vertices[quad[:, 0]] - vertices[quad[:, 2]], axis=1)
             <= np.linalg.norm(vertices[quad[:, 1]] - vertices[quad[:, 3]], axis=1))
    new += [quad[short][:, [0, 1, 2]], quad[short][:, [0, 2, 3]],
            quad[~short][:, [0, 1, 3]], quad[~short][:, [1, 2, 3]]]
    return trimesh.Trimesh(vertices, np.concatenate(new), process=False)


def _enclosing_offsets(surface, feature_angle=40.0):
    """(n, 3) float -- outward moves of the vertices [m] after which the facets enclose the smooth surface they
    sample (the chords of a curved surface cut inside it by their sag).

    The triangles to lift are the facets and, across each edge whose two facets are far from Delaunay in their
    tangent plane (opposite angles summing to more than :data:`_FLIP_ANGLE`), the two flipped ones: scipy's
    Delaunay recovers the surface only up to such flips, and a flipped pair cuts deeper than the facets.
    Each triangle's corners get normals from the incident faces within ``feature_angle`` of the triangle
    (:func:`_corner_normals`: Max's weights, exact for vertices on a sphere; a crease stays sharp, as a renderer's
    auto-smooth normals). The smooth surface over the triangle is modelled by its PN triangle (Vlachos et al. 2001,
    the cubic patch through the corners with those normals); its sag is the largest height of that patch over the
    triangle's plane, with the edge control points below the plane (concave edge ends) counted as on it (an upper
    bound), times :data:`_BAND_MARGIN`. Along an edge whose ends' normals lean symmetrically, that height is the
    quadratic surface's ``kappa L^2 / 8`` with ``kappa L^2 = (n_a - n_b) . (x_a - x_b)``; where only one end's normal
    leans it is 32/27 of that, and where both lean the same way (the S-shaped edges at a coarse scan's folds, which
    a quadratic model takes as straight) it keeps the bulge of the convex half. A vertex then moves along the
    sag-weighted normal of its triangles, far enough that every triangle's plane rises by at least its sag; flat
    facets (no sag) keep their planes, so boxes and cylinder caps stay exact.
    """
    import trimesh

    vertices, faces = surface.vertices, surface.faces
    normals = surface.face_normals
    feature_cosine = np.cos(np.radians(feature_angle))
    # The facets, then the flipped pairs across edges far from Delaunay.
    pairs = surface.face_adjacency  # (e, 2) faces
    edge, opposite = surface.face_adjacency_edges, surface.face_adjacency_unshared  # (e, 2) vertices each
    flip = _opposite_angles(surface) > _FLIP_ANGLE
    flipped = np.concatenate([np.c_[opposite[flip], edge[flip, 0]], np.c_[opposite[flip], edge[flip, 1]]])
    triangles = np.concatenate([faces, flipped])
    pair_normal = np.tile(normals[pairs[flip]].sum(axis=1), (2, 1))
    triangle_normals = np.concatenate([normals, _unit(np.cross(vertices[flipped[:, 1]] - vertices[flipped[:, 0]],
                                                               vertices[flipped[:, 2]] - vertices[flipped[:, 0]]))])
    outward = np.r_[np.ones(len(faces)), np.sign(np.einsum("tj,tj->t", triangle_normals[len(faces):], pair_normal))]
    triangle_normals *= outward[:, None]

    corner = _corner_normals(surface, triangles, triangle_normals, feature_cosine)
    corners = vertices[triangles]
    # The PN triangle's height over the triangle's plane: a cubic in the barycentrics whose control heights are
    # h_ij = -((x_j - x_i) . n_i) (n_i . n_t) / 3 (the edge control point near corner i towards j; the corners are
    # at 0, the centre's is 1/4 of their sum). A negative control height (a concave edge end) counts as 0: an
    # upper bound, as it keeps the bulge of the convex edges around saddles and the S-shaped edges of folds.
    facing = np.einsum("tcj,tj->tc", corner, triangle_normals)
    grid = _barycentric_grid(_BAND_SAMPLES)
    height = np.zeros((len(triangles), len(grid)))
    control_sum = np.zeros(len(triangles))
    for i, j in ((0, 1), (1, 0), (1, 2), (2, 1), (2, 0), (0, 2)):
        control = np.maximum(-np.einsum("tj,tj->t", corners[:, j] - corners[:, i], corner[:, i]) * facing[:, i] / 3, 0)
        height += 3 * control[:, None] * (grid[:, i] ** 2 * grid[:, j])[None, :]
        control_sum += control
    height += 6 * (control_sum / 4)[:, None] * grid.prod(axis=1)[None, :]
    sag = _BAND_MARGIN * height.max(axis=1)  # (t,)

    # Each vertex: direction = normalized sum of sag_t n_t; length so that n_t . offset >= sag_t on every triangle.
    corner_vertex, corner_triangle = triangles.ravel(), np.repeat(np.arange(len(triangles)), 3)
    pull = np.zeros((len(vertices), 3))
    np.add.at(pull, corner_vertex, sag[corner_triangle, None] * triangle_normals[corner_triangle])
    length = np.linalg.norm(pull, axis=1)
    direction = np.divide(pull, length[:, None], out=np.zeros_like(pull), where=length[:, None] > 0)
    facing = np.maximum(np.einsum("cj,cj->c", triangle_normals[corner_triangle], direction[corner_vertex]), 0.5)
    distance = np.zeros(len(vertices))
    np.maximum.at(distance, corner_vertex, sag[corner_triangle] / facing)
    offsets = distance[:, None] * direction
    # Where a vertex's triangles fan out by more than 60 deg from that direction (the folds of a coarse scan),
    # the facing floor leaves some triangle's plane short of its sag, or even lowered: the moved fan then folds
    # over the vertex's own old position, which ends up outside the offset surface. There, take the shortest
    # move that lifts every plane by its sag.
    lifted = np.einsum("cj,cj->c", triangle_normals[corner_triangle], offsets[corner_vertex])
    short = np.unique(corner_vertex[lifted < sag[corner_triangle] * (1 - 1e-9)])
    for vertex in short:
        at = corner_vertex == vertex
        lift = _least_lift(triangle_normals[corner_triangle[at]], sag[corner_triangle[at]])
        if lift is None:  # the flipped pairs' planes and the facets' face all ways: lift the facets only
            at &= corner_triangle < len(faces)
            lift = _least_lift(triangle_normals[corner_triangle[at]], sag[corner_triangle[at]])
        if lift is not None:
            offsets[vertex] = lift
    if len(short):
        logger.info("delaunay: enclosing band: %d vertex offset(s) re-solved to lift each of their triangles "
                    "by its sag (fans wider than the facing floor)", len(short))
    distance = np.linalg.norm(offsets, axis=1)
    direction = _unit(offsets)
    shortest = np.full(len(vertices), np.inf)
    np.minimum.at(shortest, surface.edges_unique.ravel(), np.repeat(surface.edges_unique_length, 2))
    capped = distance > _BAND_CAP * shortest
    if capped.any():
        logger.info("delaunay: enclosing band: %d vertex offset(s) capped at %g x the shortest edge", capped.sum(),
                    _BAND_CAP)
    offsets = np.minimum(distance, _BAND_CAP * shortest)[:, None] * direction
    # Keep no move that turns a face over (not seen on sane surfaces; checked anyway).
    turned = np.einsum("ij,ij->i", trimesh.triangles.normals((vertices + offsets)[faces])[0], normals) < 0.5
    if turned.any():
        logger.warning("delaunay: enclosing band: %d face(s) would turn over; their vertices stay put", turned.sum())
        offsets[np.unique(faces[turned])] = 0.0
    return offsets


def _least_lift(normals, heights):
    """(3,) float -- the shortest ``d`` with ``normals @ d >= heights`` (k unit normals, k heights >= 0): the
    minimum-norm point of an intersection of half-spaces, found among the solutions with 1 to 3 active planes
    (``d = N_A^T lambda``, ``lambda >= 0``). None if no such ``d`` exists (normals facing all ways)."""
    from itertools import combinations

    best, best_norm = None, np.inf
    if not (heights > 0).any():
        return np.zeros(3)
    for count in (1, 2, 3):
        for active in combinations(range(len(normals)), count):
            active = list(active)
            gram = normals[active] @ normals[active].T
            if abs(np.linalg.det(gram)) < 1e-12:
                continue
            weights = np.linalg.solve(gram, heights[active])
            if (weights < 0).any():
                continue
            d = weights @ normals[active]
            norm = np.linalg.norm(d)
            if norm < best_norm and (normals @ d >= heights * (1 - 1e-9) - 1e-15).all():
                best, best_norm = d, norm
    return best


def _unit(vectors):
    """Rows scaled to unit length (zero rows stay zero)."""
    length = np.linalg.norm(vectors, axis=-1, keepdims=True)
    return np.divide(vectors, length, out=np.zeros_like(vectors), where=length > 0)


def _slid_along_surface(surface, movable, rng):
    """Move the movable vertices within their flat neighbourhood or along their straight crease by up to
    0.1 x their shortest edge (curved ones: 0.05 x, in their tangent plane), so that grids of cocircular
    points stop being degenerate for Delaunay: qhull triangulates such ties with flat tets whose removal
    tears the boundary or leaves a void. Flat and crease moves leave the surface as a point set unchanged."""
    import trimesh

    vertex_faces = surface.vertex_faces  # (n, k) padded with -1
    normals = np.vstack([surface.face_normals, np.full((1, 3), np.nan)])[vertex_faces]  # (n, k, 3), nan padding
    first = normals[:, 0]
    along_first = np.abs(np.einsum("nkj,nj->nk", normals, first))
    # The incident normal least parallel to the first one: a crease's second plane.
    other = normals[np.arange(len(normals)), np.nanargmin(np.where(np.isnan(along_first), np.inf, along_first), axis=1)]
    along_other = np.abs(np.einsum("nkj,nj->nk", normals, other))
    same_plane = 1 - SAME_PLANE_COSINE  # normals of one flat facet agree to round-off
    padding = np.isnan(along_first)
    flat = ((along_first > same_plane) | padding).all(axis=1)
    crease = ~flat & ((along_first > same_plane) | (along_other > same_plane) | padding).all(axis=1)
    direction = rng.normal(size=(len(first), 3))
    direction[flat] -= np.einsum("nj,nj->n", direction[flat], first[flat])[:, None] * first[flat]
    line = np.cross(first[crease], other[crease])
    line /= np.linalg.norm(line, axis=1)[:, None]
    direction[crease] = line * rng.choice([-1.0, 1.0], size=(len(line), 1))
    # Curved vertices (movable ones only: built-in shapes) slide in their tangent plane, which breaks the
    # mirror symmetries of icospheres and tori; they leave the exact surface by (step)^2 / (2 rho) at most.
    # A sharp vertex (a box corner: three planes) is not curved: it stays where it is.
    curved = ~flat & ~crease
    spread = np.einsum("nkj,nj->nk", normals, surface.vertex_normals)
    smooth = (np.isnan(spread) | (spread > _SMOOTH_COSINE)).all(axis=1)
    normal = surface.vertex_normals[curved]
    direction[curved] -= np.einsum("nj,nj->n", direction[curved], normal)[:, None] * normal
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    shortest = np.full(len(first), np.inf)
    np.minimum.at(shortest, surface.edges_unique.ravel(), np.repeat(surface.edges_unique_length, 2))
    step = np.where(movable & (smooth | ~curved),
                    np.where(curved, 0.05, 0.1) * shortest * rng.uniform(0.2, 1.0, len(first)), 0.0)
    vertices = surface.vertices + step[:, None] * direction
    # Keep no move that turns a face over (cannot happen at 0.1 x the shortest edge on sane grids; checked anyway).
    turned = np.einsum("ij,ij->i", trimesh.triangles.normals(vertices[surface.faces])[0], surface.face_normals) < 0.5
    vertices[np.unique(surface.faces[turned])] = surface.vertices[np.unique(surface.faces[turned])]
    return trimesh.Trimesh(vertices, surface.faces, process=False)


def _touches_flat(tets, flat, node_count):
    """(m,) bool -- tets that share a face with a flat tet."""
    faces = np.sort(tets[:, TET_FACES], axis=2).reshape(-1, 3)
    key = (faces[:, 0] * node_count + faces[:, 1]) * node_count + faces[:, 2]
    flat_faces = key[np.repeat(flat, 4)]
    return np.isin(key, flat_faces).reshape(-1, 4).any(axis=1) & ~flat


def _thinned(points, distance):
    """(k,) bool -- keep at most one of any group of points closer than ``distance``."""
    from scipy.spatial import cKDTree

    pairs = cKDTree(points).query_pairs(distance, output_type="ndarray")
    keep = np.ones(len(points), dtype=bool)
    keep[pairs.max(axis=1)] = False
    return keep


def _face_counts(tets, keep, node_count):
    """For every tet, how many of its faces lie on the boundary of the kept set."""
    faces = np.sort(tets[:, TET_FACES], axis=2).reshape(-1, 3)
    key = (faces[:, 0] * node_count + faces[:, 1]) * node_count + faces[:, 2]
    kept_faces = np.repeat(keep, 4)
    _, inverse, counts = np.unique(key[kept_faces], return_inverse=True, return_counts=True)
    on_boundary = np.zeros(len(key), dtype=bool)
    on_boundary[np.flatnonzero(kept_faces)] = counts[inverse] == 1
    return on_boundary.reshape(-1, 4).sum(axis=1)


def _peel_slivers(tets, keep, sliver):
    """Drop slivers that show a face on the boundary, repeatedly (each drop exposes the next layer)."""
    node_count = int(tets.max()) + 1
    dropped = 0
    for _ in range(_REPAIR_ROUNDS):  # a few rounds of whole-mesh vector operations
        exposed = keep & sliver & (_face_counts(tets, keep, node_count) > 0)
        if not exposed.any():
            break
        keep = keep & ~exposed
        dropped += exposed.sum()
    if dropped:
        logger.info("delaunay: dropped %d boundary sliver(s) (radius ratio < %g or flat)", dropped,
                    _SLIVER_RADIUS_RATIO)
    return keep


def _boundary_defects(tets, keep, node_count):
    """Nodes on boundary edges not shared by exactly two boundary faces, else nodes where boundary sheets touch."""
    kept = tets[keep]
    faces = kept[:, TET_FACES].reshape(-1, 3)
    key = np.sort(faces, axis=1)
    key = (key[:, 0] * node_count + key[:, 1]) * node_count + key[:, 2]
    _, first, counts = np.unique(key, return_index=True, return_counts=True)
    boundary = faces[first[counts == 1]]
    edges = np.sort(boundary[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    edge_key, edge_counts = np.unique(edges[:, 0] * node_count + edges[:, 1], return_counts=True)
    bad = edge_key[edge_counts != 2]
    if len(bad):
        return np.unique(np.concatenate([bad // node_count, bad % node_count]))
    return _multi_fan_nodes(boundary, node_count)


def _multi_fan_nodes(boundary, node_count):
    """Nodes around which the boundary faces form more than one fan (edge-connected group)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    import trimesh

    mesh = trimesh.Trimesh(np.zeros((node_count, 3)), boundary, process=False)
    pairs, shared = mesh.face_adjacency, mesh.face_adjacency_edges
    def corner(side, end):  # index of the face corner at the shared edge's end vertex
        return pairs[:, side] * 3 + np.argmax(boundary[pairs[:, side]] == shared[:, end, None], axis=1)

    rows = np.concatenate([corner(0, 0), corner(0, 1)])
    cols = np.concatenate([corner(1, 0), corner(1, 1)])
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(boundary.size, boundary.size))
    _, labels = connected_components(graph, directed=False)
    fan_key = np.unique(boundary.ravel() * boundary.size + labels)
    fans = np.bincount(fan_key // boundary.size, minlength=node_count)
    return np.flatnonzero(fans > 1)


def _covering(tets, keep, usable, ratio, surface_count):
    """Add, for each surface vertex in no kept tet, its best-shaped usable tet (logged)."""
    uncovered = np.flatnonzero(np.bincount(tets[keep].ravel(), minlength=surface_count)[:surface_count] == 0)
    if len(uncovered) == 0:
        return keep
    candidates = np.flatnonzero(~keep & usable & np.isin(tets, uncovered).any(axis=1))
    candidates = candidates[np.argsort(-ratio[candidates], kind="stable")]
    holds = np.isin(tets[candidates], uncovered)
    owner, owner_tet = tets[candidates][holds], np.repeat(candidates, holds.sum(axis=1))
    _, first = np.unique(owner, return_index=True)
    keep = keep.copy()
    keep[owner_tet[first]] = True
    logger.info("delaunay: %d surface vertices were in no kept tet; added %d tet(s) around them",
                len(uncovered), len(np.unique(owner_tet[first])))
    return keep


def _repair_boundary(tets, keep, addable, node_count, surface_count):
    """Make the boundary a 2-manifold: at each round, around the defective nodes, either add the band tets
    there or drop the kept tets that show two or more boundary faces, whichever leaves fewer defects."""
    added = removed = 0
    nodes = _boundary_defects(tets, keep, node_count)
    for _ in range(_REPAIR_ROUNDS):
        if len(nodes) == 0:
            break
        touching = np.isin(tets, nodes).any(axis=1)
        grow = touching & ~keep & addable
        shrink = touching & keep & (_face_counts(tets, keep, node_count) >= 2)
        # Never drop the last kept tet of a surface vertex.
        left = np.bincount(tets[keep & ~shrink].ravel(), minlength=node_count)
        shrink &= ~np.isin(tets, np.flatnonzero(left[:surface_count] == 0)).any(axis=1)
        options = [(keep | grow, grow.sum(), 0), (keep & ~shrink, 0, shrink.sum()),
                   (keep & ~shrink | grow, grow.sum(), shrink.sum())]
        results = [(len(_boundary_defects(tets, option, node_count)), i) for i, (option, _, _) in enumerate(options)]
        best_count, best = min(results)
        if best_count >= len(nodes) and best_count > 0 and _ > 2:
            break
        keep, plus, minus = options[best]
        added, removed = added + plus, removed + minus
        nodes = _boundary_defects(tets, keep, node_count)
    if added or removed:
        logger.info("delaunay: made the boundary manifold by adding %d band tet(s) and dropping %d tet(s)",
                    added, removed)
    remaining = _boundary_defects(tets, keep, node_count)
    if len(remaining):
        logger.warning("delaunay: %d boundary node(s) are still not manifold; try another size or seed",
                       len(remaining))
    return keep
