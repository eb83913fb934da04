"""Supports and loads of a reference problem, and their resolution on a :class:`meshing.TetMesh`.

:class:`Clamp` and :class:`Traction` say where a body is held and loaded, on a region
(:mod:`volspring.regions`: :class:`~volspring.regions.Box`, re-exported here, a face or a half-space). The
``resolve_*`` functions turn them into plain numpy arrays on the TetMesh nodes, edges and boundary
faces (no scikit-fem here), checking that every region selects something and that the clamps hold
all six rigid-body modes. The FEM reference (:mod:`validation.fem`) assembles from these arrays,
and the FEM cache (:mod:`validation.cache`) hashes them, so a region is known by what it selects.

Examples
--------
>>> import numpy as np
>>> from meshing import TetMesh
>>> from validation.boundary import Box, Clamp, resolve_clamps
>>> corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=float)
>>> tets = [[0, 4, 6, 7], [0, 4, 5, 7], [0, 2, 6, 7], [0, 2, 3, 7], [0, 1, 5, 7], [0, 1, 3, 7]]
>>> cube = TetMesh.compact(corners, tets)
>>> fixed = resolve_clamps(cube, [Clamp(Box.plane(axis, 0.0), components=axis) for axis in "xyz"])
>>> fixed.node_mask.sum(axis=0)   # four nodes on each symmetry plane, one component each
array([4, 4, 4])
>>> resolve_clamps(cube, Clamp(Box.plane("z", 0.0), components="z"))
Traceback (most recent call last):
...
ValueError: the clamps leave 3 of the 6 rigid-body modes free (t = translation along, r = rotation about an axis): ...
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from meshing.geometry import rigid_body_modes
from volspring.regions import Box  # re-exported: validation.Box and validation.boundary.Box keep working
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from meshing.mesh import TetMesh

__all__ = [
    "Box",
    "Clamp",
    "FixedDofs",
    "Traction",
    "evaluate_vectors",
    "resolve_clamps",
    "resolve_point_loads",
    "resolve_tractions",
]

_COMPONENTS = {"x": 0, "y": 1, "z": 2}


@dataclass(frozen=True)
class Clamp:
    """Prescribed displacement of some components on the mesh nodes in a region.

    Parameters
    ----------
    region : callable (k, 3) float -> (k,) bool, or :class:`Box`, or (2, 3) float box corners [m]
    components : str or sequence of int
        the fixed components: ``"xyz"`` (all, the default), ``"x"`` for a sliding/symmetry support that fixes u_x only,
        or indices such as ``(0, 2)``
    displacement : (3,) float or callable (k, 3) float -> (k, 3) float
        prescribed value [m] of the fixed components (zero by default); a callable is evaluated at the dof locations

    Notes
    -----
    The region is tested at the mesh nodes. A P2 edge dof is fixed when both end nodes of its
    edge are, so the whole clamped surface is held, not only its vertices (clamping the vertex
    dofs alone leaks: a 12.6% error was seen, REFERENCE.md section 6). For a region that is not
    convex, an edge joining two clamped nodes is clamped even if it leaves the region.
    """

    region: object
    components: str | Sequence[int] = "xyz"
    displacement: object = (0.0, 0.0, 0.0)

    @property
    def component_indices(self) -> tuple:
        """The fixed components as indices 0, 1, 2."""
        names = self.components
        if isinstance(names, str):
            indices = tuple(_COMPONENTS.get(c, -1) for c in names.lower())
        else:
            indices = tuple(names)
        if not indices or any(i not in (0, 1, 2) for i in indices):
            raise ValueError(f"clamp components must be drawn from x, y, z (0, 1, 2), got {names!r}")
        return indices


@dataclass(frozen=True)
class Traction:
    """A uniform surface traction on the boundary faces lying wholly in a region.

    Parameters
    ----------
    region : as for :class:`Clamp`
        a boundary face is loaded when its three nodes are in it
    vector : (3,) float
        force per area [Pa]
    """

    region: object
    vector: tuple


def _region_mask(region, points: np.ndarray) -> np.ndarray:
    if not callable(region):
        corners = np.asarray(region, dtype=float)
        if corners.shape != (2, 3):
            raise TypeError(f"a region is a callable on (k, 3) points or (2, 3) box corners, got {region!r}")
        region = Box(tuple(corners[0]), tuple(corners[1]))
    mask = np.asarray(region(points), dtype=bool)
    if mask.shape != (len(points),):
        raise ValueError(f"region {_describe(region)} returned shape {mask.shape}, expected ({len(points)},)")
    return mask


def _describe(region) -> str:
    return getattr(region, "__name__", None) or repr(region)


def _bounds_text(points: np.ndarray) -> str:
    low, high = points.min(axis=0), points.max(axis=0)
    return " x ".join(f"[{a:g}, {b:g}]" for a, b in zip(low, high))


def _clamps(clamp) -> list:
    if clamp is None or (isinstance(clamp, Sequence) and len(clamp) == 0):
        raise ValueError("no clamp: all six rigid-body modes (3 translations, 3 rotations) are free, so the "
                         "stiffness matrix is singular; pass clamp=<region> or clamp=[Clamp(...), ...]")
    if isinstance(clamp, Clamp):
        return [clamp]
    if isinstance(clamp, Sequence) and all(isinstance(item, Clamp) for item in clamp):
        return list(clamp)
    return [Clamp(clamp)]


def evaluate_vectors(value: Any, points: np.ndarray) -> np.ndarray:
    """A constant (3,) vector or a callable on (k, 3) points, as (k, 3) values."""
    if callable(value):
        values = np.asarray(value(points), dtype=float)
    else:
        values = np.broadcast_to(np.asarray(value, dtype=float), (len(points), 3))
    if values.shape != (len(points), 3):
        raise ValueError(f"expected a (3,) vector or (k, 3) values, got shape {values.shape}")
    return values


@dataclass(frozen=True)
class FixedDofs:
    """Clamps reduced to masks and values on the TetMesh nodes and edges (no scikit-fem yet)."""

    node_mask: np.ndarray  # (n, 3) bool
    node_values: np.ndarray  # (n, 3) float [m]
    edge_mask: np.ndarray  # (e, 3) bool, along mesh.edges
    edge_values: np.ndarray  # (e, 3) float [m], at the edge midpoints


def resolve_clamps(mesh: TetMesh, clamp: Any) -> FixedDofs:
    """The dofs a clamp (a region, a :class:`Clamp` or a list of them) fixes on ``mesh``, and their values.

    Raises
    ------
    ValueError
        For no clamp, a clamp region without mesh nodes (naming the region and the mesh bounds), or
        clamps that leave a rigid-body mode free.
    """
    points, edges = mesh.points, mesh.edges
    midpoints = points[edges].mean(axis=1)
    node_mask, node_values = np.zeros((len(points), 3), bool), np.zeros((len(points), 3))
    edge_mask, edge_values = np.zeros((len(edges), 3), bool), np.zeros((len(edges), 3))
    for item in _clamps(clamp):
        inside = _region_mask(item.region, points)
        if not inside.any():
            raise ValueError(f"clamp region {_describe(item.region)} contains no mesh node; "
                             f"the mesh spans {_bounds_text(points)} m")
        on_edge = inside[edges].all(axis=1)
        nodes_value = evaluate_vectors(item.displacement, points[inside])
        edges_value = evaluate_vectors(item.displacement, midpoints[on_edge])
        for c in item.component_indices:
            node_mask[inside, c] = True
            node_values[inside, c] = nodes_value[:, c]
            edge_mask[on_edge, c] = True
            edge_values[on_edge, c] = edges_value[:, c]
    _check_rigid_modes(points, node_mask)
    return FixedDofs(node_mask, node_values, edge_mask, edge_values)


def _check_rigid_modes(points: np.ndarray, node_mask: np.ndarray) -> None:
    """Raise if the fixed node components leave an infinitesimal rigid-body motion free."""
    nodes, components = np.nonzero(node_mask)
    centre = points.mean(axis=0)
    restricted = rigid_body_modes(points[nodes], components=components, centre=centre,
                                  scale=np.abs(points - centre).max())
    values, vectors = np.linalg.eigh(restricted.T @ restricted)
    # Entries of the modes are O(1) after scaling, so B^T B has eigenvalues O(fixed dofs) for constrained
    # directions and round-off (1e-16 relative) for free ones; 1e-10 separates the two with room to spare.
    free = values <= 1e-10 * max(values.max(), 1.0)
    if free.any():
        names = ("tx", "ty", "tz", "rx", "ry", "rz")
        modes = "; ".join(" + ".join(f"{v:.2f} {n}" for v, n in zip(vector, names) if abs(v) > 1e-3)
                          for vector in vectors[:, free].T)
        raise ValueError(f"the clamps leave {free.sum()} of the 6 rigid-body modes free (t = translation along, "
                         f"r = rotation about an axis): {modes}; the stiffness matrix is singular, clamp more")


def resolve_tractions(mesh: TetMesh, traction: Any) -> list:
    """[(faces (k, 3) int, vector (3,) float [Pa]), ...] -- the boundary faces each traction loads."""
    if traction is None:
        return []
    items = [traction] if isinstance(traction, Traction) else list(traction)
    loaded = []
    for item in items:
        if not isinstance(item, Traction):
            raise TypeError(f"traction must be a Traction or a list of them, got {item!r}")
        faces = mesh.boundary_faces[_region_mask(item.region, mesh.points)[mesh.boundary_faces].all(axis=1)]
        if len(faces) == 0:
            raise ValueError(f"traction region {_describe(item.region)} contains no boundary face; "
                             f"the mesh spans {_bounds_text(mesh.points)} m")
        vector = np.asarray(item.vector, dtype=float)
        if vector.shape != (3,):
            raise ValueError(f"a traction vector has shape (3,) [Pa], got {vector.shape}")
        loaded.append((faces, vector))
    return loaded


def resolve_point_loads(mesh: TetMesh, point_loads: Any) -> np.ndarray:
    """(n, 3) float nodal forces [N] from an (n, 3) array or a mapping {node: (3,) force}."""
    forces = np.zeros((mesh.node_count, 3))
    if point_loads is None:
        return forces
    if isinstance(point_loads, Mapping):
        for node, force in point_loads.items():
            if not 0 <= int(node) < mesh.node_count:
                raise ValueError(f"point load at node {node}, but the mesh has nodes 0..{mesh.node_count - 1}")
            forces[int(node)] += np.asarray(force, dtype=float)
        return forces
    point_loads = np.asarray(point_loads, dtype=float)
    if point_loads.shape != forces.shape:
        raise ValueError(f"point_loads must be (n, 3) = {forces.shape} nodal forces [N], got {point_loads.shape}")
    return forces + point_loads
