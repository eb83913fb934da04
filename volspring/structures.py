"""Strings and hair: one-dimensional bodies built as models of springs and angle springs.

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

from volspring.elements import AngleSprings
from volspring.elements.angles import DihedralSprings
from volspring.material import _real_array, _real_number
from volspring.model import Model

__all__ = ["TWIST_MIN_TURN", "hair", "strand_points", "string"]

#: Twist springs go on chains of joints that turn by at least this much at rest [rad]: the dihedral is
#: undefined at a straight joint, and its spring stiffens out-of-plane bending by about 1 / turn^2 there.
TWIST_MIN_TURN = 0.1


def string(start, end=None, *, count, length=None, direction=(0.0, 0.0, -1.0), linear_density=None, mass=None,
           axial_stiffness=None, stiffness=None, tension=None, rest_length=None, damping=0.0) -> Model:
    """A string (chain of masses and springs) from ``start`` to ``end``, or hanging ``length`` from ``start``.

    Parameters
    ----------
    start : (3,) float -- first node [m]
    end : (3,) float, optional -- last node [m]; without it the string runs ``length`` along ``direction``
    count : int -- nodes, >= 2
    length : float, optional -- length [m] when ``end`` is not given
    direction : (3,) float -- direction from ``start`` when ``end`` is not given (default down, -z)
    linear_density : float, optional -- mass per length of the string as built [kg/m] ...
    mass : float, optional -- ... or its total mass [kg] (one of the two)
    axial_stiffness : float, optional -- EA [N]: segment springs k = EA / l_s ...
    stiffness : float, optional -- ... or the stiffness of every segment spring k [N/m] (one of the two)
    tension : float, optional -- rest lengths chosen so that the string as built carries this tension [N] ...
    rest_length : float, optional -- ... or the total rest length [m]; default: the built length (no tension)
    damping : float -- damper of every segment k_d [N s/m]

    Returns
    -------
    Model -- nodes 0 .. count - 1 from start to end

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


def strand_points(start, direction, length, count, *, curl_radius=0.0, curl_pitch=None) -> np.ndarray:
    """(count, 3) float -- a straight or helical strand, nodes equally spaced in arc length [m].

    Parameters
    ----------
    start : (3,) float -- the root [m]
    direction : (3,) float -- the strand's direction (the helix axis) from the root
    length : float -- arc length of the strand [m]
    count : int -- nodes, >= 2
    curl_radius : float -- helix radius R [m]; 0 (default) for a straight strand
    curl_pitch : float, optional -- rise per turn of the helix along its axis [m], > 0; needed when R > 0

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


def hair(points, *, bending_stiffness, axial_stiffness, linear_density=None, mass=None, torsional_stiffness=None,
         damping=0.0, root="clamped") -> Model:
    """A hair strand through ``points`` (its rest shape): stretch springs, angle springs, twist springs.

    Parameters
    ----------
    points : (n, 3) float -- rest shape, root first [m], n >= 3 (e.g. :func:`strand_points`)
    bending_stiffness : float -- EI [N m^2], >= 0
    axial_stiffness : float -- EA [N], > 0
    linear_density : float, optional -- mass per length [kg/m] ...
    mass : float, optional -- ... or the total mass [kg] (one of the two)
    torsional_stiffness : float, optional -- GJ [N m^2], >= 0; default EI / (1 + nu) with nu = 0.3, a solid
        round fibre (GJ = G 2 I); 0 adds no twist springs, nor does a straight strand
    damping : float -- damper of every segment spring k_d [N s/m]
    root : {"clamped", "free"} -- "clamped" (default): the first segment is the root, held in place by the
        caller (pin nodes 0 and 1), so the joint at node 1 stands for half a segment of free strand and
        gets k = EI / (l_1 / 2); with the uniform EI / l_1 the clamp would be too soft by that half segment, a
        relative error 2 / (count - 2) in the tip deflection of a cantilever. "free": every joint EI / l_j.

    Returns
    -------
    Model -- segment springs, one :class:`~volspring.elements.AngleSprings` and, for a curl, one
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
    points = _real_array("points", points)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 3:
        raise ValueError(f"points have shape {points.shape}; expected (n, 3) with n >= 3 (a strand needs a joint)")
    if not np.isfinite(points).all():
        node = int(np.flatnonzero(~np.isfinite(points).all(axis=1))[0])
        raise ValueError(f"points[{node}] = {points[node].tolist()} m is not finite")
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
