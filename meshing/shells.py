"""Virtual shells: layers of the tet mesh's boundary surface offset outward, tied to it by springs.

The seed's third volumetric model: ``layers`` copies of the boundary surface, each offset outward along the
surface's area-weighted vertex normals by ``thickness`` more than the one below. Every shell vertex is joined

- to its source vertex in the layer below by a straight spring (``shell``),
- to the one-ring neighbours of that source vertex by diagonal springs (``shell_diagonal``),
- to its neighbours within its own layer by springs along the shell's surface edges (``shell_edge``).

The result is a :class:`meshing.SpringTopology`, so the spring model consumes tet edges and shell springs alike.
"""

from __future__ import annotations

import logging
import numbers

import numpy as np

from meshing.geometry import area_weighted_vertex_normals, triangle_area_normals
from meshing.mesh import TetMesh
from meshing.topology import SPRING_KINDS, SpringTopology

__all__ = ["add_shells"]

logger = logging.getLogger(__name__)

# A shell triangle whose area falls below this fraction of its source triangle's area is nearly folded:
# the offset is close to self-intersecting there (concave region, thickness near the local feature size).
SHRINK_WARNING_RATIO = 0.1


def add_shells(mesh: TetMesh, *, layers: int, thickness: float) -> SpringTopology:
    """Add virtual shell layers around the boundary of a tet mesh.

    Layer ``k`` holds a copy of every boundary node ``i`` at ``x_i + k * thickness * n_i``, with ``n_i`` the
    area-weighted unit normal of the boundary surface at node ``i`` (the same normal for every layer, so the
    straight springs of a node form one straight column and consecutive layers lie ``thickness`` apart along it).

    Parameters
    ----------
    mesh : TetMesh
        the volumetric body; its boundary faces (wound outward) are the surface that is offset
    layers : int
        number of shell layers, >= 0; 0 gives the tet edges only
    thickness : float
        offset between consecutive layers along the vertex normals [m], > 0

    Returns
    -------
    SpringTopology
        Points: the mesh nodes, then layer 1's nodes, layer 2's nodes, ... (each layer in the order of
        ``mesh.boundary_nodes``). Springs: the tet edges (``tet_edge``), then per layer its ``shell``,
        ``shell_diagonal`` and ``shell_edge`` springs. ``shell_triangles``: each layer's triangles in global node
        indices, wound outward like the mesh's boundary faces; ``shell_layer`` and ``shell_thickness`` filled.
        For a closed surface with ``V`` vertices and ``E`` edges each layer adds ``V`` nodes, ``V`` shell,
        ``2 E`` diagonal and ``E`` shell-edge springs.

    Raises
    ------
    ValueError
        For ``layers`` not a non-negative integer, ``thickness`` not positive and finite, a boundary vertex
        without a normal (its faces cancel), or an offset that flips shell triangles against their source
        triangles (thickness too large for the local feature size: the shell would self-intersect).

    Notes
    -----
    The self-intersection check is local: it catches the fold of a concave region (a shell triangle turned over
    against its source), the usual failure when ``layers * thickness`` nears the local feature size, and warns
    (logging) when a triangle shrinks below ``SHRINK_WARNING_RATIO`` of its source's area. Shells grown from
    facing parts of the surface that cross each other across a narrow gap without folding are not detected.

    Examples
    --------
    >>> import numpy as np
    >>> from meshing import TetMesh, add_shells
    >>> mesh = TetMesh(np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2, 3]]))
    >>> topology = add_shells(mesh, layers=2, thickness=0.05)
    >>> topology.node_count, topology.kind_counts()
    (12, {'tet_edge': 6, 'shell': 8, 'shell_diagonal': 24, 'shell_edge': 12})
    """
    layers = _checked_layers(layers)
    thickness = _checked_thickness(thickness)
    if layers == 0:
        return SpringTopology.from_mesh(mesh)

    surface_nodes, local = np.unique(mesh.boundary_faces, return_inverse=True)
    local_faces = local.reshape(-1, 3)
    vertex_count = len(surface_nodes)
    surface_points = mesh.points[surface_nodes]
    normals = _vertex_normals(surface_points, local_faces, surface_nodes)
    edges = np.unique(np.sort(local_faces[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1), axis=0)
    # Both directions of each surface edge: shell vertex u -> neighbour v of its source, one diagonal each.
    directed = np.concatenate([edges, edges[:, ::-1]])
    surface_face_normals = triangle_area_normals(surface_points, local_faces)

    kind = {name: np.int8(code) for code, name in enumerate(SPRING_KINDS)}
    points = [mesh.points]
    springs = [mesh.edges]
    kinds = [np.full(len(mesh.edges), kind["tet_edge"])]
    triangles = []
    below_nodes = surface_nodes
    below_face_normals = surface_face_normals
    for layer in range(1, layers + 1):
        layer_points = surface_points + (layer * thickness) * normals
        layer_nodes = mesh.node_count + (layer - 1) * vertex_count + np.arange(vertex_count)
        layer_face_normals = triangle_area_normals(layer_points, local_faces)
        _check_offset(layer, thickness, layers, layer_face_normals, below_face_normals, surface_face_normals,
                      local_faces, surface_nodes)
        points.append(layer_points)
        springs += [
            np.stack([below_nodes, layer_nodes], axis=1),
            np.stack([layer_nodes[directed[:, 0]], below_nodes[directed[:, 1]]], axis=1),
            layer_nodes[edges],
        ]
        kinds += [
            np.full(vertex_count, kind["shell"]),
            np.full(len(directed), kind["shell_diagonal"]),
            np.full(len(edges), kind["shell_edge"]),
        ]
        triangles.append(layer_nodes[local_faces])
        below_nodes = layer_nodes
        below_face_normals = layer_face_normals

    topology = SpringTopology(
        mesh=mesh,
        points=np.concatenate(points),
        springs=np.concatenate(springs),
        kinds=np.concatenate(kinds),
        shell_triangles=np.concatenate(triangles),
        shell_layer=np.repeat(np.arange(layers + 1), [mesh.node_count] + [vertex_count] * layers),
        shell_thickness=thickness,
    )
    logger.info("added %d shell layer(s) of thickness %g: %r", layers, thickness, topology)
    return topology


def _checked_layers(layers) -> int:
    if isinstance(layers, bool) or not isinstance(layers, numbers.Integral):
        raise ValueError(f"layers = {layers!r} is not an integer; expected a whole number of shell layers >= 0")
    if layers < 0:
        raise ValueError(f"layers = {layers} is negative; expected a number of shell layers >= 0")
    return int(layers)


def _checked_thickness(thickness) -> float:
    if isinstance(thickness, bool) or not isinstance(thickness, numbers.Real):
        raise ValueError(f"thickness = {thickness!r} is not a number; expected a shell thickness > 0 [m]")
    if not np.isfinite(float(thickness)) or thickness <= 0:
        raise ValueError(f"thickness = {thickness} is not > 0 and finite; expected a shell thickness > 0 [m]")
    return float(thickness)


def _vertex_normals(points: np.ndarray, faces: np.ndarray, node_ids: np.ndarray) -> np.ndarray:
    """(v, 3) float -- unit area-weighted vertex normals of a triangle surface, refusing vertices without one."""
    normals = area_weighted_vertex_normals(points, faces)
    # Zero rows: faces that cancel out (meshing.tolerances.CANCELLED); every vertex here is on some face.
    degenerate = ~normals.any(axis=1)
    if degenerate.any():
        raise ValueError(
            f"{degenerate.sum()} boundary node(s) have no outward normal (their faces cancel out), first is node "
            f"{node_ids[np.flatnonzero(degenerate)[0]]}; shells cannot be offset from there"
        )
    return normals


def _check_offset(layer, thickness, layers, cross, below_cross, surface_cross, faces, node_ids) -> None:
    """Refuse shell triangles that flip against their source; warn about nearly folded ones."""
    flipped = (np.einsum("ij,ij->i", cross, below_cross) <= 0) | (np.einsum("ij,ij->i", cross, surface_cross) <= 0)
    if flipped.any():
        first = np.flatnonzero(flipped)[0]
        raise ValueError(
            f"thickness = {thickness} with layers = {layers} flips {flipped.sum()} of {len(faces)} shell triangles "
            f"in layer {layer} (first is the offset of boundary face {first}, "
            f"nodes {node_ids[faces[first]].tolist()}): "
            "the shell would self-intersect; expected layers * thickness well below the local feature size"
        )
    shrunk = np.linalg.norm(cross, axis=1) < SHRINK_WARNING_RATIO * np.linalg.norm(surface_cross, axis=1)
    if shrunk.any():
        logger.warning(
            "layer %d: %d shell triangle(s) shrink below %g of their source area; the shell is close to folding there",
            layer, shrunk.sum(), SHRINK_WARNING_RATIO,
        )

