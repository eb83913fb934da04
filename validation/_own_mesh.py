"""The case of a user's own mesh: :func:`own_mesh_case`, the check that its clamp holds it
(:func:`check_held`) and its clamp regions written as text (:func:`parse_region`).

``volspring-validate --mesh FILE --clamp REGION`` builds its case here, and the report runs every rung of
the ladder on it (``--model`` selects them; :mod:`validation.ladder`): the tip is the node the P2
reference moves most, a rung that refuses the material (``"springs+volume"`` below the spring network's
own nu, measured on this mesh) is reported as such. Import these names from :mod:`validation.cases`,
their one public home.

Examples
--------
>>> from meshing import structured_box
>>> from validation.cases import own_mesh_case, parse_region
>>> from volspring.material import Material
>>> mesh = structured_box((4, 1, 1), (1.0, 0.25, 0.25))
>>> case = own_mesh_case(mesh, parse_region("xmin", mesh), material=Material(1e6, 0.3, 1000.0))
>>> case.name, int(case.clamps[0].region(mesh.points).sum())
('own_mesh', 4)
"""

from __future__ import annotations

import numpy as np

from meshing import TetMesh
from validation._case import Case
from validation.boundary import Clamp
from volspring.material import Material
from volspring.regions import Region, describe_bounds
from volspring.regions import parse_region as parse_region_text
from collections.abc import Callable
from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from validation.boundary import Traction

__all__ = ["CLAMP_TOLERANCE", "check_held", "own_mesh_case", "parse_region"]

#: Slack of a clamp region given as text, relative to the diagonal of the mesh's bounding box. Looser
#: than the regions' default (``meshing.tolerances.ON_SURFACE``, 1e-9) so that a bound placed on a row of
#: nodes of a mesh file written with few digits, or in float32 (round-off ~6e-8 relative), still catches
#: them; far below any element of a mesh worth validating (a million elements across).
CLAMP_TOLERANCE = 1e-6


def parse_region(text: str, mesh: TetMesh) -> Region:
    """A clamp or load region on ``mesh`` from its text form.

    Parameters
    ----------
    text : str
        In the grammar of :func:`volspring.regions.parse_region`: ``xmin`` .. ``zmax`` (a face of the
        bounding box), ``x<0.01`` / ``z>=1.2`` (a half-space [m]), ``x=0`` (a plane), or
        ``box:x0,y0,z0,x1,y1,z1`` / ``x0,y0,z0,x1,y1,z1`` (a box [m]).
    mesh : TetMesh
        Sets the slack: :data:`CLAMP_TOLERANCE` times its diagonal.

    Returns
    -------
    volspring.regions.Region

    Raises
    ------
    ValueError
        For text in none of these forms, naming it (``region 'left' is not one of the region forms ...``).
    """
    size = float(np.linalg.norm(np.ptp(mesh.points, axis=0)))
    return parse_region_text(text, tolerance=CLAMP_TOLERANCE * size)


def own_mesh_case(mesh: TetMesh, clamp: Callable[[np.ndarray], np.ndarray], *, material: Material,
                  gravity: Sequence[float] | np.ndarray | None = (0.0, 0.0, -9.81), tractions: Sequence[Traction] = (),
                  source: str = "mesh") -> Case:
    """Any tet mesh with a clamp region and loads.

    Parameters
    ----------
    mesh : TetMesh
    clamp : region (callable (k, 3) -> (k,) bool, e.g. from :func:`parse_region`)
        its nodes are held
    material : Material
    gravity : (3,) float or None
        [m/s^2]
    tractions : sequence of Traction
        [Pa]
    source : str
        where the mesh came from, for the report

    Raises
    ------
    ValueError
        If the clamp region holds no node, or too few to hold the body (a singular problem).
    """
    held = np.asarray(clamp(mesh.points), dtype=bool)
    if not held.any():
        raise ValueError(f"the clamp region {_name(clamp)} contains no mesh node; the mesh spans "
                         f"{describe_bounds(mesh.points)} m")
    check_held(mesh, held)
    if gravity is None and not tractions:
        raise ValueError("no load: give gravity or a traction")
    return Case("own_mesh", f"Your mesh ({source})", "static", mesh, material, (Clamp(clamp),),
                gravity=None if gravity is None else tuple(float(g) for g in gravity), tractions=tuple(tractions),
                parameters={"source": source, "clamp": _name(clamp), "E_pa": material.E, "nu": material.nu,
                            "density_kg_per_m3": material.density,
                            "gravity_m_per_s2": None if gravity is None else [float(g) for g in gravity],
                            "tractions_pa": [list(map(float, t.vector)) for t in tractions]})


def check_held(mesh: TetMesh, held: np.ndarray) -> None:
    """Raise unless the held nodes fix every rigid motion of every connected part of the mesh.

    Parameters
    ----------
    mesh : TetMesh
    held : (n,) bool
        nodes held in place (all components)

    Raises
    ------
    ValueError
        Naming the part (its node count) that is free or can still rotate about a line.
    """
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    edges = mesh.edges
    graph = sp.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(mesh.node_count,) * 2)
    count, label = connected_components(graph, directed=False)
    held_per_part = np.bincount(label[held], minlength=count)
    free_parts = np.flatnonzero(held_per_part == 0)
    if free_parts.size:
        size = int((label == free_parts[0]).sum())
        raise ValueError(f"{free_parts.size} of the mesh's {count} connected part(s) have no clamped node "
                         f"(the first has {size} nodes): the problem is singular, every rigid motion of that "
                         "part is free; clamp a region in every part")
    for part in range(count):
        points = mesh.points[held & (label == part)]
        spread = np.linalg.svd(points - points.mean(axis=0), compute_uv=False) if len(points) > 1 else np.zeros(3)
        scale = float(np.ptp(mesh.points, axis=0).max())
        # A held set on one line leaves the rotation about it free (spread rank < 2); 1e-9 of the mesh
        # size separates collinear round-off from a real second direction.
        if len(points) < 3 or (spread[1] if len(spread) > 1 else 0.0) <= 1e-9 * scale * np.sqrt(len(points)):
            raise ValueError(f"the clamp holds {len(points)} node(s) on one line in a part of "
                             f"{int((label == part).sum())} nodes: the rotation about that line is free, so the "
                             "problem is singular; clamp a region with three non-collinear nodes")


def _name(region) -> str:
    return getattr(region, "__name__", None) or repr(region)
