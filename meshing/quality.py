"""Shape quality of tetrahedra: volume, minimum dihedral angle, radius ratio, and a summary.

Thresholds for a "poor" tet are collected in :data:`POOR_DIHEDRAL_DEGREES` and
:data:`POOR_RADIUS_RATIO`; every figure is normalised so that a regular tet scores its best.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshing.geometry import signed_tet_volumes, triangle_area_normals
from meshing.mesh import TET_EDGES, TET_FACES, TetMesh
from meshing.tolerances import ZERO_VOLUME

__all__ = [
    "POOR_DIHEDRAL_DEGREES",
    "POOR_RADIUS_RATIO",
    "QualitySummary",
    "min_dihedral_angles",
    "quality_summary",
    "radius_ratios",
    "tet_volumes",
]

#: A tet whose smallest dihedral angle is below this [degrees] counts as poor (a regular tet has 70.53).
POOR_DIHEDRAL_DEGREES = 10.0
#: A tet whose radius ratio is below this counts as poor (a regular tet has 1, a sliver tends to 0).
POOR_RADIUS_RATIO = 0.1

# The two faces (indices into TET_FACES) that meet at each edge of TET_EDGES: face k is opposite vertex k,
# so the edge (a, b) lies on the two faces opposite the other two vertices.
_EDGE_FACES = np.array([[k for k in range(4) if k not in edge] for edge in TET_EDGES.tolist()])


def _arrays(mesh_or_points, tets=None):
    if isinstance(mesh_or_points, TetMesh):
        return mesh_or_points.points, mesh_or_points.tets
    if tets is None:
        raise TypeError("pass a TetMesh, or points and tets")
    points = np.asarray(mesh_or_points, dtype=np.float64)
    tets = np.asarray(tets, dtype=np.int64)
    if points.ndim != 2 or points.shape[1] != 3 or tets.ndim != 2 or tets.shape[1] != 4:
        raise ValueError(f"expected points (n, 3) and tets (m, 4), got {points.shape} and {tets.shape}")
    return points, tets


def _checked_volumes(points, tets):
    volumes = signed_tet_volumes(points, tets)
    # The TetMesh rule (meshing.tolerances.ZERO_VOLUME): |V| below 1e-12 l^3 is the round-off of a flat tet.
    scale = np.ptp(points[tets], axis=1).max(axis=1) ** 3
    bad = volumes <= ZERO_VOLUME * scale
    if bad.any():
        first = np.flatnonzero(bad)[0]
        raise ValueError(
            f"{bad.sum()} tet(s) are inverted or of zero volume, first is tet {first} "
            f"(nodes {tets[first].tolist()}, volume {volumes[first]:.3g})"
        )
    return volumes


def _raw_metrics(points, tets):
    """Signed volume, minimum dihedral angle [degrees] and radius ratio, with no validity check."""
    x = points[tets]
    volumes = signed_tet_volumes(points, tets)
    # The four faces of each tet, wound outward: normals (m, 4, 3) of length their area.
    normals = 0.5 * triangle_area_normals(points, tets[:, TET_FACES].reshape(-1, 3)).reshape(-1, 4, 3)
    areas = np.linalg.norm(normals, axis=2)
    unit = normals / np.where(areas > 0, areas, 1.0)[..., None]
    # The interior dihedral angle at an edge is pi minus the angle between the outward normals of its faces.
    cosines = -np.einsum("mek,mek->me", unit[:, _EDGE_FACES[:, 0]], unit[:, _EDGE_FACES[:, 1]])
    min_dihedral = np.degrees(np.arccos(np.clip(cosines, -1.0, 1.0)).min(axis=1))
    # Inradius 3V / (total face area); circumradius |a^2 (b x c) + b^2 (c x a) + c^2 (a x b)| / (12 V).
    a, b, c = (x[:, k] - x[:, 0] for k in (1, 2, 3))
    numerator = (
        np.einsum("ij,ij->i", a, a)[:, None] * np.cross(b, c)
        + np.einsum("ij,ij->i", b, b)[:, None] * np.cross(c, a)
        + np.einsum("ij,ij->i", c, c)[:, None] * np.cross(a, b)
    )
    with np.errstate(divide="ignore", invalid="ignore"):
        inradius = 3.0 * volumes / areas.sum(axis=1)
        circumradius = np.linalg.norm(numerator, axis=1) / (12.0 * np.abs(volumes))
        ratio = np.where(np.abs(volumes) > 0, 3.0 * inradius / circumradius, 0.0)
    return volumes, np.where(volumes > 0, min_dihedral, 0.0), ratio


def tet_volumes(mesh_or_points: TetMesh | np.ndarray, tets: np.ndarray | None = None) -> np.ndarray:
    """Volume of each tet.

    Parameters
    ----------
    mesh_or_points : TetMesh or (n, 3) float
        a mesh, or node positions [m]
    tets : (m, 4) int, optional
        node indices, when points are given

    Returns
    -------
    (m,) float
        volumes [m^3], all positive

    Raises
    ------
    ValueError
        If any tet is inverted or of zero volume, naming how many and the first.
    """
    return _checked_volumes(*_arrays(mesh_or_points, tets))


def min_dihedral_angles(mesh_or_points: TetMesh | np.ndarray, tets: np.ndarray | None = None) -> np.ndarray:
    """Smallest of the six interior dihedral angles of each tet.

    Returns
    -------
    (m,) float
        angles [degrees]; 70.53 for a regular tet, near 0 for a sliver or needle

    Raises
    ------
    ValueError
        If any tet is inverted or of zero volume.
    """
    points, tets = _arrays(mesh_or_points, tets)
    _checked_volumes(points, tets)
    return _raw_metrics(points, tets)[1]


def radius_ratios(mesh_or_points: TetMesh | np.ndarray, tets: np.ndarray | None = None) -> np.ndarray:
    """Radius ratio ``3 r_in / R_circ`` of each tet.

    Returns
    -------
    (m,) float
        1 for a regular tet, tending to 0 as the tet degenerates

    Raises
    ------
    ValueError
        If any tet is inverted or of zero volume.

    Examples
    --------
    >>> import numpy as np
    >>> regular = np.array([[1., 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]])
    >>> float(np.round(radius_ratios(regular, [[0, 1, 3, 2]])[0], 12))
    1.0
    """
    points, tets = _arrays(mesh_or_points, tets)
    _checked_volumes(points, tets)
    return _raw_metrics(points, tets)[2]


@dataclass(frozen=True)
class QualitySummary:
    """Figures of merit of a tet mesh.

    Attributes
    ----------
    tet_count : int
    volume_min, volume_max, volume_total : float
        tet volumes [m^3]
    dihedral_min, dihedral_mean, dihedral_p1, dihedral_p5 : float
        minimum dihedral angle per tet, then its minimum, mean, 1st and 5th percentiles over the mesh [degrees]
    radius_ratio_min, radius_ratio_mean, radius_ratio_p1, radius_ratio_p5 : float
        radius ratio likewise
    poor_dihedral_count : int
        tets with a dihedral angle below :data:`POOR_DIHEDRAL_DEGREES`
    poor_radius_ratio_count : int
        tets with a radius ratio below :data:`POOR_RADIUS_RATIO`
    """

    tet_count: int
    volume_min: float
    volume_max: float
    volume_total: float
    dihedral_min: float
    dihedral_mean: float
    dihedral_p1: float
    dihedral_p5: float
    radius_ratio_min: float
    radius_ratio_mean: float
    radius_ratio_p1: float
    radius_ratio_p5: float
    poor_dihedral_count: int
    poor_radius_ratio_count: int

    def __str__(self) -> str:
        return "\n".join([
            f"tets: {self.tet_count}, volume {self.volume_total:.6g} "
            f"(per tet {self.volume_min:.3g} .. {self.volume_max:.3g})",
            f"min dihedral angle [deg]: min {self.dihedral_min:.2f}, 1% {self.dihedral_p1:.2f}, "
            f"5% {self.dihedral_p5:.2f}, mean {self.dihedral_mean:.2f}; "
            f"{self.poor_dihedral_count} below {POOR_DIHEDRAL_DEGREES:g}",
            f"radius ratio: min {self.radius_ratio_min:.3f}, 1% {self.radius_ratio_p1:.3f}, "
            f"5% {self.radius_ratio_p5:.3f}, mean {self.radius_ratio_mean:.3f}; "
            f"{self.poor_radius_ratio_count} below {POOR_RADIUS_RATIO:g}",
        ])


def quality_summary(mesh_or_points: TetMesh | np.ndarray, tets: np.ndarray | None = None) -> QualitySummary:
    """Summarise the volumes, minimum dihedral angles and radius ratios of a tet mesh.

    Parameters
    ----------
    mesh_or_points : TetMesh or (n, 3) float
        a mesh, or node positions [m]
    tets : (m, 4) int, optional
        node indices, when points are given

    Raises
    ------
    ValueError
        If any tet is inverted or of zero volume.

    Examples
    --------
    >>> import numpy as np
    >>> from meshing import TetMesh
    >>> mesh = TetMesh(np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2, 3]]))
    >>> summary = quality_summary(mesh)
    >>> summary.tet_count, round(summary.dihedral_min, 2), summary.poor_radius_ratio_count
    (1, 54.74, 0)
    """
    points, tets = _arrays(mesh_or_points, tets)
    volumes = _checked_volumes(points, tets)
    _, dihedral, ratio = _raw_metrics(points, tets)
    return QualitySummary(
        tet_count=len(tets),
        volume_min=float(volumes.min()),
        volume_max=float(volumes.max()),
        volume_total=float(volumes.sum()),
        dihedral_min=float(dihedral.min()),
        dihedral_mean=float(dihedral.mean()),
        dihedral_p1=float(np.percentile(dihedral, 1)),
        dihedral_p5=float(np.percentile(dihedral, 5)),
        radius_ratio_min=float(ratio.min()),
        radius_ratio_mean=float(ratio.mean()),
        radius_ratio_p1=float(np.percentile(ratio, 1)),
        radius_ratio_p5=float(np.percentile(ratio, 5)),
        poor_dihedral_count=int((dihedral < POOR_DIHEDRAL_DEGREES).sum()),
        poor_radius_ratio_count=int((ratio < POOR_RADIUS_RATIO).sum()),
    )
