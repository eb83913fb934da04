"""Lattice bodies: mass points on a regular grid with structural, shear and bend springs (volumetric model 1).

The geometry (cells, node pairs, trilinear anchoring) is :mod:`meshing.lattice`; this module gives it
masses and stiffness from a :class:`~volspring.Material` and returns a :class:`~volspring.Model`.

Masses. Node i gets density x (inside volume of each of its cells) / 8: the body weighs density x the
lattice's volume (:attr:`meshing.lattice.Lattice.volume`), exact for a box on the grid.

The stiffness rule (``rule="isotropic"``). Under a uniform small strain eps, a central spring of stiffness
k, rest length l and direction n stores k/2 l^2 (n . eps . n)^2, so springs of density k l^2 / V per cell
volume V give the elastic tensor C_ijkl = sum k l^2 n_i n_j n_k n_l / V: fully symmetric, hence
C12 = C44 (the Cauchy relation). Per node of an unbounded cubic lattice of cell size h there are 3 edge
springs (k1, length h), 6 face diagonals (k2, h sqrt 2), 4 body diagonals (k3, h sqrt 3) and 3 bend
springs (kb, 2h), which gives the cubic constants

    C11 = (k1 + 2 k2 + 4/3 k3 + 4 kb) / h,    C12 = C44 = (k2 + 4/3 k3) / h.

Right-angle joints of the cell faces with angle springs ka (12 per node) leave C11 and C12 alone (normal
strains keep right angles) and add 4 ka / h^3 to C44 only: the one non-central term. An isotropic solid
with Lame constants (lambda, mu) needs C11 = lambda + 2 mu, C12 = lambda, C44 = mu, so

    k2 + 4/3 k3 = lambda h,   k1 + 4 kb = (2 mu - (1 - s) lambda) h,   ka = (mu - lambda) h^3 / 4

with s = ``BODY_DIAGONAL_SHARE`` the part of lambda carried by the body diagonals (k3 = 3/4 s lambda h,
k2 = (1 - s) lambda h) and ``BEND_SHARE`` the part of k1 + 4 kb carried by the bend springs. Every
spring constant must be >= 0, hence what the lattice reaches, E always exact:

- springs only (``angles=False``): lambda = mu, i.e. nu = 1/4 whatever nu is asked (the Cauchy limit,
  where the tet network reaches 0.08 to 0.21); G = E / 2.5 (4% stiffer in shear than nu = 0.3 asks);
- with angle springs: nu_eff = nu for 0 <= nu <= 1/4; above 1/4 the angle springs get ka = 0 and
  nu_eff = 1/4 (they can only add shear stiffness); below 0, nu_eff = 0;
- without shear springs (``shear=False``) the diagonals are gone: lambda = 0, nu_eff = 0, and the
  angle springs carry all the shear (without them the lattice is a mechanism, refused).

The volume change under uniaxial stress is then (1 - 2 nu_eff) per unit axial strain: 0.5 at the Cauchy
limit where nu = 0.3 asks 0.4 and nu = 0.45 asks 0.1 (the pure-spring volume loss the tet springs show too).

Each spring's constant is its family's constant times its share of cells (:meth:`Lattice.pairs`; 1/2 on
the body's faces, 1/4 on its edges, scaled by the cells' inside fractions), and an edge whose bend springs
are cut off by the boundary takes their stiffness in series (2 kb per missing bend spring): every cell then
holds exactly the energy of the continuum under a uniform strain, so a box lattice has these constants
exactly (checked in tests/test_lattice.py by a uniaxial stress test), as a finite element patch would.

Examples
--------
>>> import trimesh
>>> from volspring import Material
>>> from volspring.lattice import lattice_body
>>> rubber = Material(E=1e5, nu=0.3, density=1000.0)
>>> body = lattice_body(trimesh.creation.box(extents=(1.0, 0.5, 0.5)), 0.25, rubber)
>>> body.model.node_count, round(body.model.total_mass, 9), body.effective_nu
(45, 250.0, 0.25)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshing.lattice import LATTICE_FAMILIES, Lattice, LatticeAnchor, anchor_lattice, box_lattice, voxelize
from meshing.topology import SPRING_KINDS
from volspring.elements import AngleSprings, ElementSet, Springs
from volspring.material import Material, _real_number
from volspring.model import Model
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from meshing.mesh import TetMesh
    import trimesh
    from meshing.shapes import Shape

__all__ = ["BEND_SHARE", "BODY_DIAGONAL_SHARE", "LATTICE_RULES", "LatticeBody", "LatticeConstants",
           "box_lattice_model", "lattice_body", "lattice_constants", "lattice_model"]

LATTICE_RULES = ("isotropic",)
#: Part of the axial central stiffness k1 + 4 kb carried by the bend springs (module docstring). Any value in
#: [0, 1) gives the same elastic constants; a half keeps the structural springs doing most of the work along
#: the grid lines, where one-cell-thin parts have no bend springs.
BEND_SHARE = 0.5
#: Part of lambda (C12) carried by the body diagonals, the rest by the face diagonals. Any value in [0, 1]
#: gives the same elastic constants; a half shares it evenly.
BODY_DIAGONAL_SHARE = 0.5
#: Relative slack on comparing a grid mesh's nodes with the lattice's (:func:`box_lattice_model`).
GRID_MATCH = 1e-9


@dataclass(frozen=True)
class LatticeConstants:
    """Per-spring constants of an unbounded lattice (module docstring) and the solid they make.

    Parameters
    ----------
    structural, face, body, bend : float
        k1, k2, k3, kb [N/m] of a spring with share 1
    joint : float
        ka [N m / rad^2] of a right-angle joint with share 1
    lame_lambda, shear_modulus : float
        the lattice's Lame constants [Pa]
    E : float
        its Young's modulus [Pa] (the material's)
    nu : float
        its Poisson ratio [-]
    """

    structural: float
    face: float
    body: float
    bend: float
    joint: float
    lame_lambda: float
    shear_modulus: float
    E: float
    nu: float


def lattice_constants(material: Material, cell_size: float, *, shear: bool = True, bend: bool = True,
                      angles: bool = False) -> LatticeConstants:
    """The spring constants that make a cubic lattice the isotropic solid nearest the material (E exact).

    Parameters
    ----------
    material : Material
    cell_size : float
        h [m]
    shear, bend, angles : bool
        which families the lattice has (module docstring)

    Raises
    ------
    ValueError
        For ``shear=False`` without ``angles``: nothing resists shear (a mechanism).
    """
    if not shear and not angles:
        raise ValueError("shear=False and angles=False: nothing resists shear, the lattice is a mechanism; "
                         "keep the shear springs or add angle springs")
    h, E = float(cell_size), material.E
    if not shear:
        nu = 0.0
    elif angles:
        nu = min(max(material.nu, 0.0), 0.25)
    else:
        nu = 0.25
    mu = E / (2.0 * (1.0 + nu))
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    s = BODY_DIAGONAL_SHARE if shear else 0.0
    axial = (2.0 * mu - (1.0 - s) * lam) * h
    share = BEND_SHARE if bend else 0.0
    return LatticeConstants(
        structural=(1.0 - share) * axial, face=(1.0 - s) * lam * h if shear else 0.0,
        body=0.75 * s * lam * h if shear else 0.0, bend=share * axial / 4.0,
        joint=(mu - lam) * h**3 / 4.0 if angles else 0.0,
        lame_lambda=lam, shear_modulus=mu, E=E, nu=nu)


@dataclass(frozen=True, eq=False)
class LatticeBody:
    """A lattice body: its model, its geometry, and its surface anchored into it.

    Parameters
    ----------
    model : Model
        masses, springs (and angle springs); node i is ``lattice.points[i]``
    lattice : Lattice
        cells, fractions, nodes
    constants : LatticeConstants
        the rule's constants and the solid they make
    spring_family : (s,) int8
        index into :data:`meshing.lattice.LATTICE_FAMILIES` of each spring of ``model.springs``
    anchor : LatticeAnchor or None
        the body's own surface, bound to the lattice (for the output writers, e.g. ``BlenderWriter(directory,
        body.anchor)``); None for a lattice built without one
    """

    model: Model
    lattice: Lattice
    constants: LatticeConstants
    spring_family: np.ndarray
    anchor: LatticeAnchor | None = None

    @property
    def effective_nu(self) -> float:
        """The Poisson ratio the lattice reaches (module docstring)."""
        return self.constants.nu

    def family_counts(self) -> dict:
        """Springs per family, by name (:data:`meshing.lattice.LATTICE_FAMILIES`), and the angle joints."""
        counts = np.bincount(self.spring_family, minlength=len(LATTICE_FAMILIES))
        result = {name: int(count) for name, count in zip(LATTICE_FAMILIES, counts)}
        result["angles"] = sum(e.joint_count for e in self.model.elements if isinstance(e, AngleSprings))
        return result


def lattice_model(lattice: Lattice, material: Material, *, shear: bool = True, bend: bool = True,
                  angles: bool = False, rule: str = "isotropic", damping_ratio: float | None = None) -> LatticeBody:
    """Masses and springs of a lattice from a material (module docstring).

    Parameters
    ----------
    lattice : Lattice
    material : Material
    shear, bend, angles : bool
        spring families: shear (face and body diagonals), bend (skip-one along grid lines), angle springs at the
        right-angle corners of the cell faces
    rule : {"isotropic"}
        the stiffness rule
    damping_ratio : float, optional
        zeta >= 0: each spring gets k_d = 2 zeta sqrt(k m_i m_j / (m_i + m_j)) (critical damping of the two-body
        oscillator), as for tet springs

    Returns
    -------
    LatticeBody
        without anchor (see :func:`lattice_body`, or :func:`meshing.lattice.anchor_lattice`)
    """
    if not isinstance(lattice, Lattice):
        raise TypeError(f"lattice must be a meshing.lattice.Lattice, got {type(lattice).__name__}")
    if not isinstance(material, Material):
        raise TypeError(f"material must be a volspring.Material, got {type(material).__name__}")
    if rule not in LATTICE_RULES:
        raise ValueError(f"unknown lattice rule {rule!r}; known: {', '.join(LATTICE_RULES)}")
    if damping_ratio is not None:
        damping_ratio = _real_number("damping_ratio", damping_ratio)
        if not (np.isfinite(damping_ratio) and damping_ratio >= 0):
            raise ValueError(f"damping_ratio = {damping_ratio} is not finite and >= 0")
    constants = lattice_constants(material, lattice.cell_size, shear=shear, bend=bend, angles=angles)
    pairs, family, weights, missing_bends = lattice.pairs(shear=shear, bend=bend)
    per_family = np.array([constants.structural, constants.face, constants.body, constants.bend])
    # An edge whose bend springs the boundary cut off carries them in series: 2 kb per missing spring.
    stiffness = per_family[family] * weights + 2.0 * constants.bend * missing_bends
    keep = stiffness > 0  # families the rule leaves at 0 (e.g. the diagonals at nu = 0) are not built
    pairs, family, stiffness = pairs[keep], family[keep], stiffness[keep]
    masses = material.density * lattice.node_volumes
    x = lattice.points
    lengths = np.linalg.norm(x[pairs[:, 1]] - x[pairs[:, 0]], axis=1)
    damping = 0.0
    if damping_ratio is not None:
        m_i, m_j = masses[pairs[:, 0]], masses[pairs[:, 1]]
        damping = 2.0 * damping_ratio * np.sqrt(stiffness * m_i * m_j / (m_i + m_j))
    kinds = SPRING_KINDS.index("lattice_" + LATTICE_FAMILIES[0]) + family  # the families' kinds, in order
    elements: list[ElementSet] = [Springs(lattice.node_count, pairs, stiffness, damping, lengths, kinds)]
    if angles and constants.joint > 0:
        triples, joint_weights = lattice.joints()
        elements.append(AngleSprings(lattice.node_count, triples, constants.joint * joint_weights, np.pi / 2))
    model = Model(x, masses, tuple(elements), material=material, rule="lattice")
    family.setflags(write=False)
    return LatticeBody(model, lattice, constants, family)


def lattice_body(body: trimesh.Trimesh | Shape, cell_size: float, material: Material, *, shear: bool = True,
                 bend: bool = True, angles: bool = False, rule: str = "isotropic", samples: int = 4,
                 damping_ratio: float | None = None, surface_size: float | None = None) -> LatticeBody:
    """A lattice body filling a closed surface or a built-in shape, its surface anchored into it.

    Parameters
    ----------
    body : trimesh.Trimesh or Shape
        closed, outward-wound surface [m], or a :class:`meshing.Shape`
    cell_size : float
        edge of the cubic cells [m]
    material : Material
    shear, bend, angles, rule, damping_ratio
        see :func:`lattice_model`
    samples : int
        sub-grid points per axis for the inside fraction of boundary cells (:func:`meshing.lattice.voxelize`)
    surface_size : float, optional
        for a Shape: edge length of its triangle surface [m]; default a quarter cell (faceting then changes a sphere's
        volume by about 0.1% at 10 cells across)

    Returns
    -------
    LatticeBody
        with ``anchor``, the surface bound to the lattice

    Raises
    ------
    ValueError
        For a bad cell size or sample count, an open surface, ``shear=False`` without angles.

    Examples
    --------
    >>> from meshing import sphere
    >>> from volspring import Material
    >>> body = lattice_body(sphere(0.5), 0.25, Material(E=1e5, nu=0.3, density=1000.0))
    >>> body.model.node_count, body.anchor.outside_count
    (125, 0)
    """
    from meshing.shapes import Shape

    cell_size = _real_number("cell_size", cell_size)
    if not (np.isfinite(cell_size) and cell_size > 0):
        raise ValueError(f"cell_size = {cell_size} m is not a positive finite length")
    if isinstance(body, Shape):
        size = 0.25 * cell_size if surface_size is None else _real_number("surface_size", surface_size)
        surface = body.surface(size=size)
    elif hasattr(body, "vertices") and hasattr(body, "faces"):
        surface = body
    else:
        raise TypeError(f"body must be a trimesh.Trimesh or a meshing.Shape, got {type(body).__name__}")
    lattice = voxelize(surface, cell_size, samples=samples)
    result = lattice_model(lattice, material, shear=shear, bend=bend, angles=angles, rule=rule,
                           damping_ratio=damping_ratio)
    return LatticeBody(result.model, lattice, result.constants, result.spring_family, anchor_lattice(lattice, surface))


def box_lattice_model(mesh: TetMesh, material: Material, **options: Any) -> LatticeBody:
    """The lattice of a structured box mesh (a validation case's beam, bar or cube), on the same nodes.

    For a mesh of :func:`meshing.structured_box` with cubic cells, the lattice's nodes are the mesh's,
    in the same order, so the case's clamps, loads and tip nodes apply to the lattice model unchanged
    (``validation.springs.spring_static(case, body.model)``, ``spring_frequencies``,
    ``effective_constants(case.mesh, body.model)``).

    Parameters
    ----------
    mesh : TetMesh
        a structured box with cubic cells
    material : Material
    **options
        for :func:`lattice_model` (shear, bend, angles, rule, damping_ratio)

    Raises
    ------
    ValueError
        If the mesh's nodes are not those of a grid of cubic cells filling its bounding box.
    """
    low, high = mesh.bounds
    points = np.asarray(mesh.points)
    # The cell size is the smallest nonzero coordinate step along any axis.
    steps = [np.diff(np.unique(np.round((points[:, a] - low[a]) / (high[a] - low[a]) / GRID_MATCH) * GRID_MATCH))
             for a in range(3)]
    cells = [len(step) for step in steps]
    try:
        lattice = box_lattice(cells, high - low, origin=low)
    except ValueError as error:
        raise ValueError(f"the mesh is not a structured box of cubic cells, which a lattice on the same nodes "
                         f"needs ({error})") from None
    if lattice.node_count != mesh.node_count or not np.allclose(
            lattice.points, points, rtol=0, atol=GRID_MATCH * float(np.linalg.norm(high - low))):
        raise ValueError(f"the mesh's {mesh.node_count} nodes are not those of a {cells[0]} x {cells[1]} x {cells[2]} "
                         f"grid ({lattice.node_count} nodes) in lexicographic order: not a structured box")
    return lattice_model(lattice, material, **options)
