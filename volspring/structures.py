"""Strings, hair and cloth: bodies built as models of springs and angle springs.

Cloth (:func:`cloth_grid`, :func:`cloth_mesh`, Provot 1995: structural, shear and bend springs, masses from
the triangle areas, stiffness from the membrane's E t) is at the end of the module, with Provot's strain
limit (:func:`cloth_strain_limit`). What follows here is about the one-dimensional bodies.

Both builders return a plain :class:`~volspring.Model` (from :meth:`Model.from_arrays`, plus
:class:`~volspring.elements.AngleSprings` through :meth:`Model.with_elements` for hair), so every
integrator, the static and modal solves and the writers take them as they take a meshed body.
Nodes are numbered along the strand from its start: pin node 0 to hang a string or clamp a
strand (nodes 0 and 1 hold its direction too), node ``count - 1`` for the far end.

Units are SI: positions [m], masses [kg], linear density [kg/m], spring stiffness [N/m], axial
stiffness EA [N], bending and torsional stiffness EI, GJ [N m^2], dampers [N s/m].

Discretisation (``count`` nodes, ``count - 1`` segments of rest length l_s):

- mass: every segment's mass split half and half over its two nodes (lumped);
- stretching: one spring per segment, k = EA / l_s (Hooke, ``Model.from_arrays``);
- bending (hair): one angle spring per inner node j, k_j = EI / l_j with l_j the mean rest length of
  its two segments (:mod:`volspring.elements.angles`), rest angle from the rest shape;
- twist (hair with a curl): one dihedral spring per chain of two bent joints (i .. i + 3),
  k = GJ / l_middle on the dihedral angle psi about the middle segment, rest psi from the rest shape
  (:class:`~volspring.elements.angles.DihedralSprings`): the discrete torsion psi / l of the centre
  line held with the rod's GJ. Lengths, joint angles and dihedrals fix a chain's shape (as bond
  lengths, angles and dihedrals do a molecule's), so a curl keeps its radius and pitch.

Limits. The twist is the centre line's geometric torsion, a stand-in for the material twist of a
Kirchhoff rod: exact for a helix that stays a helix (a coil spring pulled along its axis, whose
extension per length of wire is F R^2 (cos^2 a / GJ + sin^2 a / EI), a the helix angle), but stiffer
than the rod against out-of-plane bending of a joint that turns by phi0, by about GJ / (EI phi0^2);
joints turning less than :data:`TWIST_MIN_TURN` get no twist spring. A discrete elastic rod with
material frames (Bergou et al. 2008) is the accurate model.

Examples
--------
>>> from volspring.structures import string
>>> chain = string([0, 0, 0], [1, 0, 0], count=11, linear_density=0.1, axial_stiffness=100.0)
>>> chain.node_count, chain.spring_count, round(chain.total_mass, 12)
(11, 10, 0.1)
"""

from __future__ import annotations

import numpy as np

from meshing.topology import SPRING_KINDS, vector_lengths
from volspring.elements import AngleSprings, Springs
from volspring.elements.angles import DihedralSprings
from volspring.material import _real_array, _real_number
from volspring.model import Model
from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from numpy.typing import ArrayLike
    from volspring.constraints import StrainLimit
    from volspring.elements import ElementSet

__all__ = ["CLOTH_SPRING_KINDS", "TWIST_MIN_TURN", "cloth_grid", "cloth_mesh", "cloth_springs", "cloth_strain_limit",
           "combine", "hair", "sheet_grid", "strand_points", "string"]

#: Twist springs go on chains of joints that turn by at least this much at rest [rad]: the dihedral is
#: undefined at a straight joint, and its spring stiffens out-of-plane bending by about 1 / turn^2 there.
TWIST_MIN_TURN = 0.1


def string(start: ArrayLike, end: ArrayLike | None = None, *, count: int, length: float | None = None,
           direction: ArrayLike = (0.0, 0.0, -1.0), linear_density: float | None = None, mass: float | None = None,
           axial_stiffness: float | None = None, stiffness: float | None = None, tension: float | None = None,
           rest_length: float | None = None, damping: float = 0.0) -> Model:
    """A string (chain of masses and springs) from ``start`` to ``end``, or hanging ``length`` from ``start``.

    Parameters
    ----------
    start : (3,) float
        first node [m]
    end : (3,) float, optional
        last node [m]; without it the string runs ``length`` along ``direction``
    count : int
        nodes, >= 2
    length : float, optional
        length [m] when ``end`` is not given
    direction : (3,) float
        direction from ``start`` when ``end`` is not given (default down, -z)
    linear_density : float, optional
        mass per length of the string as built [kg/m] ...
    mass : float, optional
        ... or its total mass [kg] (one of the two)
    axial_stiffness : float, optional
        EA [N]: segment springs k = EA / l_s ...
    stiffness : float, optional
        ... or the stiffness of every segment spring k [N/m] (one of the two)
    tension : float, optional
        rest lengths chosen so that the string as built carries this tension [N] ...
    rest_length : float, optional
        ... or the total rest length [m]; default: the built length (no tension)
    damping : float
        damper of every segment k_d [N s/m]

    Returns
    -------
    Model
        nodes 0 .. count - 1 from start to end

    Raises
    ------
    ValueError
        A count below 2, both or neither of a pair of alternatives, a length, density, mass or
        stiffness <= 0, a tension that would need a rest length <= 0, start and end at one point.

    Examples
    --------
    A taut string: 10 N in 21 nodes over 1 m.

    >>> from volspring.structures import string
    >>> taut = string([0, 0, 0], [1, 0, 0], count=21, mass=0.01, axial_stiffness=1e4, tension=10.0)
    >>> round(float(taut.stiffness[0] * (0.05 - taut.rest_lengths[0])), 9)   # k (l - l0) = T
    10.0
    """
    start = _point("start", start)
    count = _count(count)
    if end is None:
        if length is None:
            raise ValueError("give end= or length= (with direction=): the string needs a second point or a length")
        length = _positive("length", length)
        end = start + length * _unit("direction", direction)
    else:
        if length is not None:
            raise ValueError(f"give end= or length=, not both (end = {np.asarray(end).tolist()}, length = {length})")
        end = _point("end", end)
    built = float(np.linalg.norm(end - start))
    if not built > 0:
        raise ValueError(f"start and end are the same point {start.tolist()} m; expected a string of length > 0")
    positions = start + np.linspace(0.0, 1.0, count)[:, None] * (end - start)
    segment = built / (count - 1)
    masses = _lumped_masses(np.full(count - 1, segment), linear_density, mass)
    if (axial_stiffness is None) == (stiffness is None):
        raise ValueError("give axial_stiffness= (EA [N]) or stiffness= (k per segment [N/m]), one of the two")
    if tension is not None and rest_length is not None:
        raise ValueError(f"give tension= or rest_length=, not both (tension = {tension}, rest_length = {rest_length})")
    if rest_length is not None:
        rest = _positive("rest_length", rest_length) / (count - 1)
    elif tension is not None:
        tension = _real_number("tension", tension)
        if not np.isfinite(tension):
            raise ValueError(f"tension = {tension} N is not finite")
        # T = EA (l - l0) / l0  or  T = k (l - l0)
        rest = (segment / (1.0 + tension / _positive("axial_stiffness", axial_stiffness)) if stiffness is None
                else segment - tension / _positive("stiffness", stiffness))
        if not rest > 0:
            raise ValueError(f"tension = {tension} N would need a rest length {rest} m <= 0 per segment; "
                             "expected a tension below the springs' strength")
    else:
        rest = segment
    k = (_positive("axial_stiffness", axial_stiffness) / rest if stiffness is None
         else _positive("stiffness", stiffness))
    pairs = np.column_stack([np.arange(count - 1), np.arange(1, count)])
    return Model.from_arrays(positions, masses, pairs, stiffness=k, damping=damping, rest_lengths=rest)


def strand_points(start: ArrayLike, direction: ArrayLike, length: float, count: int, *, curl_radius: float = 0.0,
                  curl_pitch: float | None = None) -> np.ndarray:
    """(count, 3) float -- a straight or helical strand, nodes equally spaced in arc length [m].

    Parameters
    ----------
    start : (3,) float
        the root [m]
    direction : (3,) float
        the strand's direction (the helix axis) from the root
    length : float
        arc length of the strand [m]
    count : int
        nodes, >= 2
    curl_radius : float
        helix radius R [m]; 0 (default) for a straight strand
    curl_pitch : float, optional
        rise per turn of the helix along its axis [m], > 0; needed when R > 0

    Notes
    -----
    The helix passes through the root and turns about the axis through start + R n, n a unit
    vector normal to the direction: x(s) = start + R (1 - cos t) n + R sin t b + p t / (2 pi) d,
    t = 2 pi s / sqrt((2 pi R)^2 + p^2), s the arc length.
    """
    start, d = _point("start", start), _unit("direction", direction)
    length, count = _positive("length", length), _count(count)
    s = np.linspace(0.0, length, count)
    radius = _real_number("curl_radius", curl_radius)
    if not (np.isfinite(radius) and radius >= 0):
        raise ValueError(f"curl_radius = {radius} m is not finite and >= 0")
    if radius == 0:
        return start + s[:, None] * d
    if curl_pitch is None:
        raise ValueError(f"curl_radius = {radius} m needs curl_pitch= (rise per turn [m], > 0)")
    pitch = _positive("curl_pitch", curl_pitch)
    helper = np.eye(3)[np.argmin(np.abs(d))]
    normal = np.cross(d, helper)
    normal /= np.linalg.norm(normal)
    binormal = np.cross(d, normal)
    t = 2 * np.pi * s / np.hypot(2 * np.pi * radius, pitch)
    return (start + radius * (1 - np.cos(t))[:, None] * normal + radius * np.sin(t)[:, None] * binormal
            + (pitch * t / (2 * np.pi))[:, None] * d)


def hair(points: np.ndarray, *, bending_stiffness: float, axial_stiffness: float, linear_density: float | None = None,
         mass: float | None = None, torsional_stiffness: float | None = None, damping: float = 0.0,
         root: str = "clamped") -> Model:
    """A hair strand through ``points`` (its rest shape): stretch springs, angle springs, twist springs.

    Parameters
    ----------
    points : (n, 3) float
        rest shape, root first [m], n >= 3 (e.g. :func:`strand_points`)
    bending_stiffness : float
        EI [N m^2], >= 0
    axial_stiffness : float
        EA [N], > 0
    linear_density : float, optional
        mass per length [kg/m] ...
    mass : float, optional
        ... or the total mass [kg] (one of the two)
    torsional_stiffness : float, optional
        GJ [N m^2], >= 0; default EI / (1 + nu) with nu = 0.3, a solid round fibre (GJ = G 2 I); 0 adds no twist
        springs, nor does a straight strand
    damping : float
        damper of every segment spring k_d [N s/m]
    root : {"clamped", "free"}
        "clamped" (default): the first segment is the root, held in place by the caller (pin nodes 0 and 1), so the
        joint at node 1 stands for half a segment of free strand and gets k = EI / (l_1 / 2); with the uniform EI / l_1
        the clamp would be too soft by that half segment, a relative error 2 / (count - 2) in the tip deflection of a
        cantilever. "free": every joint EI / l_j.

    Returns
    -------
    Model
        segment springs, one :class:`~volspring.elements.AngleSprings` and, for a curl, one
        :class:`~volspring.elements.angles.DihedralSprings`

    Examples
    --------
    A human hair, 10 cm, 40 um radius, E = 4 GPa: EI = E pi r^4 / 4, EA = E pi r^2.

    >>> import numpy as np
    >>> from volspring.structures import hair, strand_points
    >>> E, r = 4e9, 40e-6
    >>> curl = strand_points([0, 0, 0], [0, 0, -1], 0.1, 41, curl_radius=5e-3, curl_pitch=1e-2)
    >>> strand = hair(curl, bending_stiffness=E * np.pi * r**4 / 4, axial_stiffness=E * np.pi * r**2,
    ...               linear_density=1300 * np.pi * r**2)
    >>> strand.node_count, [type(element_set).__name__ for element_set in strand.elements]
    (41, ['Springs', 'AngleSprings', 'DihedralSprings'])
    """
    points = _checked_points(points, " (a strand needs a joint)")
    n = len(points)
    edges = np.diff(points, axis=0)
    lengths = np.linalg.norm(edges, axis=1)
    if not lengths.min() > 0:
        e = int(np.argmin(lengths))
        raise ValueError(f"points[{e}] and points[{e + 1}] are the same point {points[e].tolist()} m; expected a "
                         "strand of distinct consecutive points")
    bending = _real_number("bending_stiffness", bending_stiffness)
    if not (np.isfinite(bending) and bending >= 0):
        raise ValueError(f"bending_stiffness = {bending} N m^2 is not finite and >= 0")
    axial = _positive("axial_stiffness", axial_stiffness)
    twist = bending / 1.3 if torsional_stiffness is None else _real_number("torsional_stiffness", torsional_stiffness)
    if not (np.isfinite(twist) and twist >= 0):
        raise ValueError(f"torsional_stiffness = {twist} N m^2 is not finite and >= 0")
    if root not in ("clamped", "free"):
        raise ValueError(f"root = {root!r}; expected 'clamped' (nodes 0 and 1 held) or 'free'")
    masses = _lumped_masses(lengths, linear_density, mass)
    model = Model.from_arrays(points, masses, np.column_stack([np.arange(n - 1), np.arange(1, n)]),
                              stiffness=axial / lengths, damping=damping, rest_lengths=lengths)
    triples = np.column_stack([np.arange(n - 2), np.arange(1, n - 1), np.arange(2, n)])
    joint_lengths = 0.5 * (lengths[:-1] + lengths[1:])
    if root == "clamped":
        joint_lengths[0] = 0.5 * lengths[1]
    joints = AngleSprings.at_rest(points, triples, bending / joint_lengths)
    bent = np.pi - joints.rest_angles >= TWIST_MIN_TURN
    chains = np.flatnonzero(bent[:-1] & bent[1:])  # both joints of the chain (i, i + 1, i + 2, i + 3) bent
    if twist == 0 or not len(chains):
        return model.with_elements(joints)
    quads = chains[:, None] + np.arange(4)
    return model.with_elements(joints, DihedralSprings.at_rest(points, quads, twist / lengths[chains + 1]))


# ---------------------------------------------------------------------------- input checks
def _lumped_masses(segment_lengths, linear_density, mass) -> np.ndarray:
    """(s + 1,) float -- every segment's mass split half and half over its ends [kg]."""
    if (linear_density is None) == (mass is None):
        raise ValueError("give linear_density= (kg/m) or mass= (kg), one of the two")
    density = (_positive("linear_density", linear_density) if mass is None
               else _positive("mass", mass) / segment_lengths.sum())
    half = 0.5 * density * segment_lengths
    return np.concatenate([half, [0.0]]) + np.concatenate([[0.0], half])


def _point(name, value) -> np.ndarray:
    point = _real_array(name, value)
    if point.shape != (3,) or not np.isfinite(point).all():
        raise ValueError(f"{name} = {point.tolist()} is not 3 finite coordinates [m]")
    return point


def _unit(name, value) -> np.ndarray:
    vector = _point(name, value)
    norm = float(np.linalg.norm(vector))
    if not norm > 0:
        raise ValueError(f"{name} = {vector.tolist()} is the zero vector; expected a direction")
    return vector / norm


def _positive(name, value) -> float:
    number = _real_number(name, value)
    if not (np.isfinite(number) and number > 0):
        raise ValueError(f"{name} = {number} is not finite and > 0")
    return number


def _count(count) -> int:
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 2:
        raise ValueError(f"count = {count!r} nodes; expected an integer >= 2")
    return int(count)


def _checked_points(points, why="") -> np.ndarray:
    """(n, 3) float -- finite positions of at least three nodes [m]; a ValueError names the shape or the first
    non-finite point."""
    points = _real_array("points", points)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 3:
        raise ValueError(f"points have shape {points.shape}; expected (n, 3) with n >= 3{why}")
    if not np.isfinite(points).all():
        node = int(np.flatnonzero(~np.isfinite(points).all(axis=1))[0])
        raise ValueError(f"points[{node}] = {points[node].tolist()} m is not finite")
    return points


# ---------------------------------------------------------------------------- cloth
#: The spring kinds of a cloth and their labels in :data:`meshing.topology.SPRING_KINDS` (select them with
#: :func:`cloth_springs`).
CLOTH_SPRING_KINDS = {"structural": "cloth_structural", "shear": "cloth_shear", "bend": "cloth_bend"}


def sheet_grid(width: float, height: float, nx: int, ny: int, *, origin: ArrayLike = (0.0, 0.0, 0.0),
               axes: tuple[ArrayLike, ArrayLike] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
               ) -> tuple[np.ndarray, np.ndarray]:
    """A rectangle of (nx + 1) x (ny + 1) nodes and its triangles: the rest shape of :func:`cloth_grid`.

    Parameters
    ----------
    width, height : float
        side lengths [m], > 0
    nx, ny : int
        cells along the width and the height, >= 1
    origin : (3,) float
        corner node 0 [m]
    axes : ((3,) float, (3,) float)
        directions of the width and the height, orthogonal; a flag hangs from its top edge with ``axes=((1, 0, 0), (0,
        0, -1))``

    Returns
    -------
    points : (n, 3) float
        node (i, j), i = 0 .. nx along the width, j = 0 .. ny along the height, is number j (nx + 1) + i [m]; the
        corners are 0, nx, ny (nx + 1) and n - 1
    triangles : (2 nx ny, 3) int
        every cell cut along its diagonal from node (i, j), normals along axes[0] x axes[1] (the render surface;
        :func:`cloth_grid`'s springs do not depend on the cut)
    """
    width, height = _positive("width", width), _positive("height", height)
    nx, ny = _cells("nx", nx), _cells("ny", ny)
    origin = _point("origin", origin)
    if len(axes) != 2:
        raise ValueError(f"axes has {len(axes)} directions; expected 2 (width and height)")
    u, v = _unit("axes[0]", axes[0]), _unit("axes[1]", axes[1])
    if abs(float(u @ v)) > _ORTHOGONAL:
        shown = [np.asarray(axes[0]).tolist(), np.asarray(axes[1]).tolist()]
        raise ValueError(f"axes = {shown} are not orthogonal (cosine {float(u @ v):.3g})")
    i, j = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1))
    points = origin + (width / nx) * i.reshape(-1, 1) * u + (height / ny) * j.reshape(-1, 1) * v
    a = _grid_nodes(nx, np.arange(nx), np.arange(ny))  # (ny, nx) corner (i, j) of every cell
    b, c, d = a + 1, a + nx + 2, a + nx + 1
    triangles = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return points, triangles


def cloth_grid(width: float, height: float, nx: int, ny: int, *, origin: ArrayLike = (0.0, 0.0, 0.0),
               axes: tuple[ArrayLike, ArrayLike] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
               areal_density: float | None = None, mass: float | None = None, membrane_stiffness: float | None = None,
               stretch_stiffness: float | None = None, shear_stiffness: float | None = None,
               bend_stiffness: float = 0.0, damping: float = 0.0) -> Model:
    """A rectangular cloth after Provot (1995): structural, shear and bend springs on a grid of nodes.

    On the grid of :func:`sheet_grid` (cells a = width / nx by b = height / ny): structural springs
    join neighbours along the grid lines, shear springs both diagonals of every cell, bend springs
    every second node along the grid lines ((i, j)-(i + 2, j) and (i, j)-(i, j + 2)). Masses are
    lumped from the area: a quarter of every cell to each of its corners (the triangles of both
    cuts of the cell, averaged).

    The membrane rule (``membrane_stiffness`` = E t). A network of central springs is a membrane
    with C_abcd = (1 / A) sum k l^2 n_a n_b n_c n_d (sum over the springs of an area A, n their
    directions), whose C_1122 = C_1212 always: an isotropic one has nu = 1/3 (the Cauchy relation
    in 2D), C_11 = 9/8 E t and C_12 = C_66 = 3/8 E t. Each cell gives each of its four structural
    springs half of k_x = E t (9/8 b/a - 3/8 a/b) (along the width; k_y with a and b swapped) and
    each diagonal k_d = 3/16 E t d^2 / (a b), d^2 = a^2 + b^2: springs inside the sheet get two
    halves, springs on its edge one, and the sheet's energy under any small uniform strain is
    exactly A/2 eps:C:eps of the isotropic membrane (E t, nu = 1/3). On square cells k_x = 3/4 E t,
    k_d = 3/8 E t. A positive k_x needs cells with 1/sqrt(3) < a / b < sqrt(3).

    Parameters
    ----------
    width, height, nx, ny, origin, axes : as for :func:`sheet_grid`
    areal_density : float, optional
        mass per area [kg/m^2] ...
    mass : float, optional
        ... or the total mass [kg] (one of the two)
    membrane_stiffness : float, optional
        E t [N/m], the rule above ...
    stretch_stiffness : float, optional
        ... or k of every structural spring [N/m] (one of the two)
    shear_stiffness : float, optional
        k of every shear spring [N/m], with ``stretch_stiffness`` only; default half of it (the isotropic ratio on
        square cells)
    bend_stiffness : float
        k of every bend spring [N/m], >= 0; 0 (default) adds none. A spring across a straight run of the sheet resists a
        fold only to second order in the fold's angle (no linear bending stiffness D), so this is a spring constant, not
        a plate's E t^3 / 12 (1 - nu^2)
    damping : float
        damper of every spring k_d [N s/m], >= 0

    Returns
    -------
    Model
        springs of kinds structural, shear and bend (:func:`cloth_springs`)

    Examples
    --------
    A flag, 1 m by 0.6 m, 200 g/m^2, E t = 100 N/m, hanging in the xz plane from its top edge:

    >>> from volspring.structures import cloth_grid, cloth_springs
    >>> flag = cloth_grid(1.0, 0.6, 10, 6, axes=((1, 0, 0), (0, 0, -1)), areal_density=0.2,
    ...                   membrane_stiffness=100.0, bend_stiffness=1.0)
    >>> flag.node_count, round(flag.total_mass, 12), [int(cloth_springs(flag, kind).sum()) for kind in
    ...                                                 ("structural", "shear", "bend")]
    (77, 0.12, [136, 120, 118])
    """
    points, _ = sheet_grid(width, height, nx, ny, origin=origin, axes=axes)
    a, b = float(width) / nx, float(height) / ny
    cells = _grid_nodes(nx, np.arange(nx), np.arange(ny))
    corners = np.stack([cells, cells + 1, cells + nx + 2, cells + nx + 1], -1).reshape(-1, 4)
    masses = np.bincount(corners.ravel(), minlength=len(points)) * (0.25 * a * b)
    masses = masses * _areal_density(a * b * nx * ny, areal_density, mass)

    i, j = np.arange(nx + 1), np.arange(ny + 1)
    along_width = _pairs(_grid_nodes(nx, i[:-1], j), 1)
    along_height = _pairs(_grid_nodes(nx, i, j[:-1]), nx + 1)
    diagonals = np.concatenate([_pairs(cells, nx + 2), _pairs(cells + 1, nx)])
    bends = np.concatenate([_pairs(_grid_nodes(nx, i[:-2], j), 2), _pairs(_grid_nodes(nx, i, j[:-2]), 2 * (nx + 1))])
    if membrane_stiffness is not None:
        if stretch_stiffness is not None or shear_stiffness is not None:
            raise ValueError(f"give membrane_stiffness= (E t) or stretch_stiffness= (with shear_stiffness=), not both "
                             f"(membrane_stiffness = {membrane_stiffness}, stretch_stiffness = {stretch_stiffness}, "
                             f"shear_stiffness = {shear_stiffness})")
        membrane = _positive("membrane_stiffness", membrane_stiffness)
        k_width, k_height = membrane * (9 / 8 * b / a - 3 / 8 * a / b), membrane * (9 / 8 * a / b - 3 / 8 * b / a)
        if not (k_width > 0 and k_height > 0):
            raise ValueError(f"cells of {a:.6g} m by {b:.6g} m (aspect {a / b:.4g}) have no isotropic spring "
                             "network with positive stiffness; expected 1/sqrt(3) < a / b < sqrt(3) (choose nx, ny "
                             "closer to the sheet's aspect), or give stretch_stiffness= and shear_stiffness=")
        # Half of k per cell: two halves inside the sheet, one on its edge (j = 0 or ny; i = 0 or nx).
        cells_width = (along_width // (nx + 1) > 0).astype(float) + (along_width // (nx + 1) < ny)
        cells_height = (along_height % (nx + 1) > 0).astype(float) + (along_height % (nx + 1) < nx)
        structural = np.concatenate([0.5 * k_width * cells_width[:, 0], 0.5 * k_height * cells_height[:, 0]])
        shear = np.full(len(diagonals), 3 / 16 * membrane * (a * a + b * b) / (a * b))
    else:
        if stretch_stiffness is None:
            raise ValueError("give membrane_stiffness= (E t [N/m]) or stretch_stiffness= (k [N/m]), one of the two")
        k = _positive("stretch_stiffness", stretch_stiffness)
        structural = np.full(len(along_width) + len(along_height), k)
        shear = np.full(len(diagonals), 0.5 * k if shear_stiffness is None else _positive("shear_stiffness",
                                                                                             shear_stiffness))
    groups = {"structural": (np.concatenate([along_width, along_height]), structural), "shear": (diagonals, shear),
              "bend": (bends, np.full(len(bends), _nonnegative("bend_stiffness", bend_stiffness)))}
    return _cloth_model(points, masses, groups, damping)


def cloth_mesh(points: ArrayLike, triangles: ArrayLike, *, areal_density: float | None = None,
               mass: float | None = None, membrane_stiffness: float | None = None,
               stretch_stiffness: float | None = None, bend_stiffness: float = 0.0, damping: float = 0.0) -> Model:
    """A cloth on any triangle mesh: structural springs on the edges, bend springs across them.

    Structural springs are the triangles' edges; across each interior edge (two triangles) a bend
    spring joins the two vertices opposite it (the triangles already hold the sheet's shear, so no
    shear springs; on a grid cut into triangles the spring across a diagonal is the other diagonal,
    a shear spring of :func:`cloth_grid`). Masses are lumped from the triangle areas, a third of
    each triangle to each of its corners.

    The membrane rule (``membrane_stiffness`` = E t): Van Gelder's, k_e = E t sum_T A_T / l_e^2 over
    the one or two triangles T of edge e (Van Gelder, "Approximate simulation of elastic membranes
    by triangulated spring meshes", JGT 3(2), 1998). Exact on equilateral triangles, whose network
    is the isotropic membrane E t, nu = 1/3; an approximation on others (no choice of edge springs
    is exact on every mesh, Van Gelder shows).

    Parameters
    ----------
    points : (n, 3) float
        rest positions [m]
    triangles : (m, 3) int
        node indices; every node in a triangle, every edge in at most two
    areal_density : float, optional
        mass per area [kg/m^2] ...
    mass : float, optional
        ... or the total mass [kg] (one of the two)
    membrane_stiffness : float, optional
        E t [N/m], the rule above ...
    stretch_stiffness : float, optional
        ... or k of every structural spring [N/m] (one of the two)
    bend_stiffness : float
        k of every bend spring [N/m], >= 0; 0 (default) adds none (see :func:`cloth_grid` for what a bend spring does
        and does not model)
    damping : float
        damper of every spring k_d [N s/m], >= 0

    Returns
    -------
    Model
        springs of kinds structural and bend (:func:`cloth_springs`)

    Raises
    ------
    ValueError
        Bad shapes, indices outside the nodes, non-finite points, a triangle of zero area, a node in
        no triangle (it would have no mass), an edge in more than two triangles, naming the first.

    Examples
    --------
    Two triangles of a unit square: 5 edges, 1 bend spring across the diagonal.

    >>> from volspring.structures import cloth_mesh, cloth_springs
    >>> square = cloth_mesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]],
    ...                     areal_density=0.2, membrane_stiffness=100.0, bend_stiffness=1.0)
    >>> [int(cloth_springs(square, kind).sum()) for kind in ("structural", "bend")], square.masses.round(12).tolist()
    ([5, 1], [0.066666666667, 0.033333333333, 0.066666666667, 0.033333333333])
    """
    points = _checked_points(points)
    triangles = np.asarray(triangles)
    if triangles.ndim != 2 or triangles.shape[1] != 3 or not len(triangles) or triangles.dtype.kind not in "iu":
        raise ValueError(f"triangles have shape {triangles.shape} and dtype {triangles.dtype}; expected (m, 3) "
                         "integer node indices, m >= 1")
    triangles = triangles.astype(np.int64)
    outside = ((triangles < 0) | (triangles >= len(points))).any(axis=1)
    if outside.any():
        t = int(np.flatnonzero(outside)[0])
        raise ValueError(f"triangles[{t}] = {triangles[t].tolist()} indexes a node outside [0, {len(points) - 1}]")
    corners = points[triangles]
    areas = 0.5 * vector_lengths(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]))
    if not areas.min() > 0:
        t = int(np.argmin(areas))
        raise ValueError(f"triangles[{t}] = {triangles[t].tolist()} has area {areas[t]} m^2; expected > 0")
    masses = np.bincount(triangles.ravel(), weights=np.repeat(areas / 3, 3), minlength=len(points))
    if not masses.min() > 0:
        node = int(np.argmin(masses))
        raise ValueError(f"node {node} (at {points[node].tolist()} m) is in no triangle; it would have no mass")
    masses = masses * _areal_density(areas.sum(), areal_density, mass)

    # Every triangle's edges k -> k + 1 with the vertex opposite; an edge's occurrences grouped by np.unique.
    directed = np.stack([triangles, np.roll(triangles, -1, axis=1)], -1).reshape(-1, 2)
    opposite = np.roll(triangles, 1, axis=1).ravel()
    edges, edge_of, counts = np.unique(np.sort(directed, axis=1), axis=0, return_inverse=True, return_counts=True)
    edge_of = edge_of.ravel()
    if counts.max() > 2:
        e = int(np.argmax(counts))
        raise ValueError(f"edge {edges[e].tolist()} is in {counts[e]} triangles; expected a surface, at most 2")
    lengths = vector_lengths(points[edges[:, 1]] - points[edges[:, 0]])
    if membrane_stiffness is not None:
        if stretch_stiffness is not None:
            raise ValueError(f"give membrane_stiffness= or stretch_stiffness=, not both (membrane_stiffness = "
                             f"{membrane_stiffness}, stretch_stiffness = {stretch_stiffness})")
        edge_areas = np.bincount(edge_of, weights=np.repeat(areas, 3), minlength=len(edges))
        structural = _positive("membrane_stiffness", membrane_stiffness) * edge_areas / lengths**2
    elif stretch_stiffness is None:
        raise ValueError("give membrane_stiffness= (E t [N/m]) or stretch_stiffness= (k [N/m]), one of the two")
    else:
        structural = np.full(len(edges), _positive("stretch_stiffness", stretch_stiffness))
    order = np.argsort(edge_of, kind="stable")
    interior = order[counts[edge_of[order]] == 2].reshape(-1, 2)  # the two occurrences of each interior edge
    bends = np.unique(np.sort(opposite[interior], axis=1), axis=0)
    keys = lambda pairs: pairs[:, 0] * len(points) + pairs[:, 1]  # noqa: E731
    bends = bends[(bends[:, 0] != bends[:, 1]) & ~np.isin(keys(bends), keys(edges))]  # e.g. on a closed tetrahedron
    groups = {"structural": (edges, structural), "shear": (np.zeros((0, 2), dtype=np.int64), np.zeros(0)),
              "bend": (bends, np.full(len(bends), _nonnegative("bend_stiffness", bend_stiffness)))}
    return _cloth_model(points, masses, groups, damping)


def cloth_springs(model: Model, *kinds: str) -> np.ndarray:
    """(s,) bool -- the springs of a cloth model of the given kinds ("structural", "shear", "bend")."""
    unknown = [kind for kind in kinds if kind not in CLOTH_SPRING_KINDS]
    if unknown or not kinds:
        raise ValueError(f"kinds = {list(kinds)}; expected one or more of {list(CLOTH_SPRING_KINDS)}")
    codes = [SPRING_KINDS.index(CLOTH_SPRING_KINDS[kind]) for kind in kinds]
    return np.isin(model.kinds, codes)


def cloth_strain_limit(model: Model, tau: float = 0.1, *, kinds: Sequence[str] = ("structural", "shear"),
                       iterations: int = 20, tolerance: float = 0.0, compression: float | None = None) -> StrainLimit:
    """Provot's strain limit on a cloth's springs: a constraint for ``Scene(..., constraints=[...])``.

    After every step, each selected spring longer than (1 + tau) l0 is pulled back to (1 + tau) l0 by
    moving its two nodes along it, mass-weighted (a pinned node does not move, the free one takes the
    whole correction), Gauss-Seidel over colours of springs that share no node, ``iterations``
    sweeps (:class:`volspring.constraints.StrainLimit`). Provot corrects positions only; here every
    node's velocity also changes by its correction over the step, dv = dx / dt, so that the step's
    velocity is again (x_new - x_start) / dt: the stretching motion the limit removes is gone from
    v too (inelastic, as in position-based dynamics), and the next step does not pull the springs
    out again.

    Parameters
    ----------
    model : Model
        from :func:`cloth_grid` or :func:`cloth_mesh`
    tau : float
        largest stretch (l - l0) / l0 [-], > 0 (Provot: 0.1)
    kinds : sequence of str
        spring kinds limited (default structural and shear, as Provot did; bend springs follow from them)
    iterations : int
        Gauss-Seidel sweeps per step, >= 1; the correction at a pinned corner reaches about one spring further per
        sweep, so large fine sheets need more sweeps, or ``tolerance``
    tolerance : float
        stop sweeping once no spring exceeds its bound by more than this [-]
    compression : float, optional
        also keep springs above (1 - compression) l0

    Returns
    -------
    StrainLimit
    """
    from volspring.constraints import StrainLimit

    select = cloth_springs(model, *kinds)
    if not select.any():
        raise ValueError(f"the model has no springs of kinds {list(kinds)} to limit ({model.kind_counts()})")
    return StrainLimit(model, tau, compression=compression, iterations=iterations, tolerance=tolerance,
                       springs=select)


#: Two axes count as orthogonal when the cosine of their angle is below this: round-off of unit vectors
#: typed with ~16 digits is 1e-16; 1e-9 lets through axes computed in float, refuses a visible skew.
_ORTHOGONAL = 1e-9


def _grid_nodes(nx, i, j) -> np.ndarray:
    """(len(j), len(i)) int -- node numbers j (nx + 1) + i of the grid's nodes (i, j)."""
    return np.asarray(j)[:, None] * (nx + 1) + np.asarray(i)[None, :]


def _pairs(first, offset) -> np.ndarray:
    """(k, 2) int -- springs from each node in ``first`` to the node ``offset`` numbers on."""
    first = np.asarray(first, dtype=np.int64).ravel()
    return np.column_stack([first, first + offset])


def _cloth_model(points, masses, groups, damping) -> Model:
    """A model of the springs in ``groups`` ({kind: (pairs, stiffness)}), kinds stored as CLOTH_SPRING_KINDS."""
    kept = {kind: (pairs, k) for kind, (pairs, k) in groups.items() if len(pairs) and k.max() > 0}
    pairs = np.concatenate([pairs for pairs, _ in kept.values()])
    kinds = np.concatenate([np.full(len(p), SPRING_KINDS.index(CLOTH_SPRING_KINDS[kind])) for kind, (p, _) in
                            kept.items()])
    rest = vector_lengths(points[pairs[:, 1]] - points[pairs[:, 0]])
    springs = Springs(len(points), pairs, np.concatenate([k for _, k in kept.values()]),
                      _nonnegative("damping", damping), rest, kinds)
    return Model(points, masses, (springs,))


def _areal_density(area, areal_density, mass) -> float:
    if (areal_density is None) == (mass is None):
        raise ValueError("give areal_density= (kg/m^2) or mass= (kg), one of the two")
    return _positive("areal_density", areal_density) if mass is None else _positive("mass", mass) / area


def _nonnegative(name, value) -> float:
    number = _real_number(name, value)
    if not (np.isfinite(number) and number >= 0):
        raise ValueError(f"{name} = {number} is not finite and >= 0")
    return number


def _cells(name, count) -> int:
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
        raise ValueError(f"{name} = {count!r} cells; expected an integer >= 1")
    return int(count)


# ---------------------------------------------------------------------------- several models in one
def combine(models: Sequence[Model]) -> Model:
    """One model from several: a meshed model (tet bodies) first, then cloths, strings and hair.

    The nodes are numbered model after model (model k's node i is ``offsets[k] + i``, ``offsets`` the
    running sum of the node counts), and every body of model k keeps its own body id plus the number
    of bodies before it: a cloth joined to ``Model.from_bodies([...])`` is one body more, with the
    material ``None`` (it has no volume; its contact takes ``stiffness=`` or the solid's rule).
    Springs join into one :class:`~volspring.elements.Springs`; angle and dihedral springs and the
    continuum element sets are renumbered.

    Only the first model may come from a tet mesh (``topology`` not None): the combined topology is
    its own, with the other models' nodes after its nodes (shell layer 0; they belong to no tet), so
    that :class:`~volspring.collision.ContactForce` collides the tet bodies as before and
    :class:`~volspring.collision.thin.ThinContactForce` finds the thin bodies after them.

    Parameters
    ----------
    models : sequence of Model
        at least one

    Returns
    -------
    Model
        ``node_body``, ``materials`` and ``body_names`` joined; ``rule`` and ``rung`` the common ones, or "mixed"

    Raises
    ------
    TypeError
        An item that is not a Model, or an element set that cannot be renumbered, naming it.
    ValueError
        No model, or a model with a tet mesh after the first.

    Examples
    --------
    >>> import numpy as np
    >>> from volspring.structures import cloth_grid, combine, string
    >>> sheet = cloth_grid(1.0, 1.0, 2, 2, areal_density=0.2, membrane_stiffness=100.0)
    >>> rope = string([0, 0, 1], [1, 0, 1], count=3, mass=0.1, stiffness=50.0)
    >>> both = combine([sheet, rope])
    >>> both.node_count, both.body_count, both.node_body[-3:].tolist(), both.springs[-2:].tolist()
    (12, 2, [1, 1, 1], [[9, 10], [10, 11]])
    """
    from dataclasses import replace

    from meshing.topology import SpringTopology
    from volspring.elements.angles import AngleSprings, DihedralSprings

    models = list(models)
    if not models:
        raise ValueError("combine needs at least one model, got none")
    for index, model in enumerate(models):
        if not isinstance(model, Model):
            raise TypeError(f"models[{index}] is a {type(model).__name__}; expected a volspring.Model")
        if index and model.topology is not None:
            raise ValueError(f"models[{index}] has a tet mesh; only models[0] may (the mesh nodes come first): "
                             "join tet bodies with Model.from_bodies, then combine the result with the others")
    counts = np.array([model.node_count for model in models])
    offsets = np.concatenate([[0], np.cumsum(counts)])
    n = int(offsets[-1])
    points = np.concatenate([model.rest_positions for model in models])
    body_offsets = np.concatenate([[0], np.cumsum([model.body_count for model in models])])
    node_body = np.concatenate([model.node_body + body_offsets[k] for k, model in enumerate(models)])
    springs = [model.spring_elements for model in models]
    pairs = np.concatenate([s.pairs + offset for s, offset in zip(springs, offsets)]).reshape(-1, 2)
    kinds = np.concatenate([s.kinds for s in springs])
    spring_set = Springs(n, pairs, np.concatenate([s.stiffness for s in springs]),
                         np.concatenate([s.damping for s in springs]),
                         np.concatenate([s.rest_lengths for s in springs]), kinds)
    others: list[ElementSet] = []
    for k, model in enumerate(models):  # a loop over models and their element sets, not over nodes
        node_map = offsets[k] + np.arange(model.node_count)
        for element_set in model.elements:
            if isinstance(element_set, Springs):
                continue
            if isinstance(element_set, AngleSprings):
                others.append(replace(element_set, node_count=n, triples=node_map[element_set.triples]))
            elif isinstance(element_set, DihedralSprings):
                others.append(replace(element_set, node_count=n, quads=node_map[element_set.quads]))
            elif hasattr(element_set, "placed"):
                others.append(element_set.placed(points, node_map))
            else:
                raise TypeError(f"models[{k}] holds a {type(element_set).__name__}, which combine cannot renumber")
    topology = models[0].topology
    if topology is not None and len(models) > 1:
        topology = SpringTopology(topology.mesh, points, pairs, kinds, topology.shell_triangles,
                                  np.concatenate([topology.shell_layer, np.zeros(n - topology.node_count, np.int64)]),
                                  topology.shell_thickness)
    materials = sum((tuple(model.materials) for model in models), ())
    names = sum((tuple(model.body_names) for model in models), ())
    rules, rungs = {model.rule for model in models}, {model.rung for model in models}
    elements = ((spring_set,) if spring_set.spring_count or not others else ()) + tuple(others)
    common = {material for material in materials}
    return Model(points, np.concatenate([model.masses for model in models]), elements, topology=topology,
                 material=common.pop() if len(common) == 1 else None, rule=rules.pop() if len(rules) == 1 else "mixed",
                 node_body=node_body, materials=materials, body_names=names,
                 rung=rungs.pop() if len(rungs) == 1 else "mixed")
