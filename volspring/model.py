"""The spring model: rest shape, lumped masses, springs with stiffness and damping.

A model is static data. Build it from a tet mesh (or a :class:`SpringTopology` with shells)
and a :class:`Material`, where masses come from density x volume and stiffness from a
published rule, or directly from arrays for strings, custom networks and tests.

Stiffness rules (``rule=``), per tet edge e, summed over the tets t that contain e:

``van_gelder``
    k_e = sum_t E V_t / l_e^2 (Van Gelder, "Approximate simulation of elastic membranes by
    triangulated spring meshes", JGT 3(2), 1998, 3D form).
``lloyd``
    k_e = sum_t (2 sqrt(2) / 25) E l_t with l_t = (6 sqrt(2) V_t)^(1/3), the edge length of the
    regular tet of volume V_t (Lloyd, Szekely, Harders, IEEE TVCG 13(5), 2007). A least-squares
    fit of six springs to one linear tet's FEM stiffness gives this exactly at nu = 1/4.
``uniform``
    k_e = ``stiffness`` for every spring: a raw constant, for comparisons with tools that take one.

Whatever the rule, a network of central springs behaves as an isotropic solid only with
lambda = mu, i.e. nu = 1/4 (the Cauchy limit): the material's nu is not reproduced.

Virtual shells. Between shell layer k-1 and k every shell triangle spans a prism of volume
V_p. Each spring of the prism (the 3 top edges, 3 straight and 6 diagonal springs) gets the
rule's contribution from V_p as if it were a tet of that volume (E V_p / l^2 for
``van_gelder``, (2 sqrt(2)/25) E (6 sqrt(2) V_p)^(1/3) for ``lloyd``), and the prism's mass
density x V_p goes in thirds to its 3 top nodes. The body's own nodes keep exactly the mass of
their tets, so the real body weighs density x mesh volume with or without shells.

Damping. ``damping_ratio`` zeta gives each spring k_d = 2 zeta sqrt(k_e m_ij), critical
damping of the two-body oscillator with reduced mass m_ij = m_i m_j / (m_i + m_j);
``damping`` gives k_d [N s/m] directly.

Force laws (``law=``) say how a raw constant is read: ``hooke`` f = k (l - l0) with k in N/m,
``strain`` f = k (l - l0) / l0 with k in N (the seed's strain form). The model stores the
effective linear stiffness k_e [N/m] either way; material rules give k_e directly.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from volspring.material import Material, _real_array, _real_number, _shown
from volspring.mesh import TetMesh
from volspring.topology import SPRING_KINDS, SpringTopology, vector_lengths

__all__ = ["STIFFNESS_RULES", "FORCE_LAWS", "SpringModel"]

STIFFNESS_RULES = ("van_gelder", "lloyd", "uniform")
#: Rules that build pure springs from E alone: they cannot honour a Poisson ratio (the Cauchy limit).
NU_IGNORING_RULES = STIFFNESS_RULES
FORCE_LAWS = ("hooke", "strain")


def _rule_stiffness(rule, E, volumes, lengths):
    """Per-(element, spring) contribution of one stiffness rule [N/m]."""
    if rule == "van_gelder":
        return E * volumes / lengths**2
    if rule == "lloyd":
        return (2.0 * np.sqrt(2.0) / 25.0) * E * np.cbrt(6.0 * np.sqrt(2.0) * volumes)
    raise ValueError(f"unknown stiffness rule {rule!r}; known: {', '.join(STIFFNESS_RULES)}")


def _pair_index(springs, node_count, pairs):
    """Index into ``springs`` of each (a, b) in ``pairs`` (either order); -1 where absent."""
    keys = springs.min(axis=1) * node_count + springs.max(axis=1)
    order = np.argsort(keys)
    query = pairs.min(axis=1) * node_count + pairs.max(axis=1)
    where = np.minimum(np.searchsorted(keys, query, sorter=order), len(keys) - 1)
    found = order[where]
    return np.where(keys[found] == query, found, -1)


def _as_spring_array(name, value, count, *, allow_zero):
    """(count,) float -- a number or array of numbers broadcast to one per spring (or node), checked."""
    array = _real_array(name, value)
    try:
        array = np.broadcast_to(array, (count,)).copy()
    except ValueError:
        raise ValueError(f"{name} has shape {array.shape}; expected a number or shape ({count},)") from None
    bad = ~np.isfinite(array) | (array < 0) | ((array == 0) & (not allow_zero))
    if bad.any():
        first = np.flatnonzero(bad)[0]
        expected = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name}[{first}] = {array[first]} is not finite and {expected}")
    return array


def _checked_positions(name, value) -> np.ndarray:
    """(n, 3) float -- finite node positions [m], n > 0."""
    x = _real_array(name, value)
    if x.ndim != 2 or x.shape[1] != 3 or len(x) == 0:
        raise ValueError(f"{name} must have shape (n, 3) with n > 0, got {x.shape}")
    bad = ~np.isfinite(x).all(axis=1)
    if bad.any():
        node = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{name}[{node}] = {x[node].tolist()} m is not finite ({int(bad.sum())} node(s) "
                         "with non-finite coordinates)")
    return x


def _checked_springs(springs, node_count) -> np.ndarray:
    """(s, 2) int64 -- node pairs: integers in [0, node_count), each joining two different nodes."""
    try:
        array = np.asarray(springs)
    except ValueError as error:  # ragged nested sequences
        raise ValueError(f"springs = {_shown(springs)} is not a regular (s, 2) array: {error}") from None
    if array.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    if array.dtype.kind not in "iu":
        raise TypeError(f"springs have dtype {array.dtype}; expected integer node indices (first pair "
                        f"{array.reshape(-1)[:2].tolist()}; integer-valued floats convert with "
                        "np.asarray(springs, dtype=int))")
    if array.ndim != 2 or array.shape[1] != 2:
        raise ValueError(f"springs have shape {array.shape}; expected (s, 2), one node pair per spring "
                         "(e.g. [[0, 1]] for one spring)")
    array = array.astype(np.int64)
    outside = ((array < 0) | (array >= node_count)).any(axis=1)
    if outside.any():
        e = int(np.flatnonzero(outside)[0])
        raise ValueError(f"springs[{e}] = {array[e].tolist()} indexes a node outside [0, {node_count - 1}] "
                         f"(the model has {node_count} nodes; {int(outside.sum())} spring(s) affected)")
    loops = array[:, 0] == array[:, 1]
    if loops.any():
        e = int(np.flatnonzero(loops)[0])
        raise ValueError(f"springs[{e}] = {array[e].tolist()} joins node {array[e, 0]} to itself; "
                         "expected two different nodes")
    return array


@dataclass(frozen=True, eq=False)
class SpringModel:
    """Immutable mass-spring network.

    Parameters
    ----------
    rest_positions : (n, 3) float -- rest positions of the nodes [m]
    masses : (n,) float -- lumped node masses [kg], > 0
    springs : (s, 2) int -- node pairs joined by a spring
    stiffness : (s,) float -- effective linear stiffness k_e [N/m]
    damping : (s,) float -- damper coefficient k_d along each spring [N s/m]
    rest_lengths : (s,) float -- rest lengths [m], > 0
    kinds : (s,) int -- index into ``SPRING_KINDS`` (all ``tet_edge`` when built from arrays)
    topology : SpringTopology or None -- where the model came from, if from a mesh
    material : Material or None
    rule : str -- the stiffness rule used, or "arrays"

    Use :meth:`from_mesh` or :meth:`from_arrays` rather than the constructor. All three refuse
    input they would misread: a TypeError for what is not numbers (bools, strings; numpy
    scalars are numbers) or for non-integer spring indices, a ValueError for wrong shapes,
    non-finite values, masses <= 0, negative stiffness or damping, rest lengths <= 0, and
    springs that leave the node range or join a node to itself, naming the first offender.

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import SpringModel
    >>> pair = SpringModel.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 1.0], [[0, 1]], stiffness=100.0)
    >>> pair.spring_count, float(pair.rest_lengths[0])
    (1, 1.0)
    """

    rest_positions: np.ndarray
    masses: np.ndarray
    springs: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    rest_lengths: np.ndarray
    kinds: np.ndarray
    topology: SpringTopology | None = None
    material: Material | None = None
    rule: str = "arrays"

    def __post_init__(self):
        x = _checked_positions("rest_positions", self.rest_positions)
        n = len(x)
        springs = _checked_springs(self.springs, n)
        s = len(springs)
        masses = _real_array("masses", self.masses).ravel()
        if masses.shape != (n,):
            raise ValueError(f"len(rest_positions) = {n}, but masses have shape {masses.shape}")
        masses = _as_spring_array("masses", masses, n, allow_zero=False)
        values = {
            "stiffness": _as_spring_array("stiffness", self.stiffness, s, allow_zero=True),
            "damping": _as_spring_array("damping", self.damping, s, allow_zero=True),
            "rest_lengths": _as_spring_array("rest_lengths", self.rest_lengths, s, allow_zero=False),
        }
        kinds = np.broadcast_to(np.asarray(self.kinds, dtype=np.int8), (s,)).copy()
        if s and (kinds.min() < 0 or kinds.max() >= len(SPRING_KINDS)):
            raise ValueError(f"kinds hold {kinds.min()} to {kinds.max()}; expected indices into SPRING_KINDS, "
                             f"0 to {len(SPRING_KINDS) - 1}")
        for name, array in (("rest_positions", x), ("masses", masses), ("springs", springs), ("kinds", kinds),
                            *values.items()):
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_arrays(cls, positions, masses, springs, *, stiffness, damping=0.0, rest_lengths=None,
                    law="hooke") -> "SpringModel":
        """A model from raw arrays (strings, custom networks, tests).

        Parameters
        ----------
        positions : (n, 3) float -- rest positions [m]
        masses : (n,) float -- node masses [kg]
        springs : (s, 2) int -- node pairs
        stiffness : float or (s,) float -- k [N/m] for ``law="hooke"``, [N] for ``law="strain"``
        damping : float or (s,) float -- k_d [N s/m]
        rest_lengths : (s,) float, optional -- defaults to the distances in ``positions`` [m]
        law : {"hooke", "strain"}

        Raises
        ------
        TypeError
            Numbers that are not numbers (bools, strings), spring indices that are not integers.
        ValueError
            See the class docstring; in particular a spring between two nodes at the same
            position without ``rest_lengths`` (its rest length would be 0), naming the spring.
        """
        positions = _checked_positions("positions", positions)
        springs = _checked_springs(springs, len(positions))
        if law not in FORCE_LAWS:
            raise ValueError(f"unknown force law {law!r}; known: {', '.join(FORCE_LAWS)}")
        if rest_lengths is None:
            rest_lengths = vector_lengths(positions[springs[:, 1]] - positions[springs[:, 0]])
            if (rest_lengths == 0).any():
                e = int(np.flatnonzero(rest_lengths == 0)[0])
                i, j = springs[e]
                raise ValueError(f"springs[{e}] = [{i}, {j}] joins two nodes at the same position "
                                 f"{positions[i].tolist()} m: its rest length would be 0; expected distinct "
                                 "positions, or rest_lengths > 0")
        else:
            rest_lengths = _as_spring_array("rest_lengths", rest_lengths, len(springs), allow_zero=False)
        stiffness = _as_spring_array("stiffness", stiffness, len(springs), allow_zero=True)
        stiffness = _effective_stiffness(stiffness, rest_lengths, law)
        return cls(positions, masses, springs, stiffness, damping, rest_lengths, kinds=0)

    @classmethod
    def from_mesh(cls, body, material: Material, *, rule="van_gelder", stiffness=None, law="hooke",
                  damping_ratio=None, damping=None) -> "SpringModel":
        """A model from a tet mesh (or a topology with shells) and a material.

        Parameters
        ----------
        body : TetMesh or SpringTopology
        material : Material
        rule : {"van_gelder", "lloyd", "uniform"} -- stiffness rule (see the module docstring)
        stiffness : float, optional -- the raw constant, >= 0, required by ``rule="uniform"`` only
        law : {"hooke", "strain"} -- how the raw ``uniform`` constant is read (``uniform`` only)
        damping_ratio : float, optional -- zeta >= 0 per spring (see the module docstring)
        damping : float or (s,) float, optional -- k_d [N s/m], instead of ``damping_ratio``
        """
        if not isinstance(body, (TetMesh, SpringTopology)):
            raise TypeError(f"body must be a TetMesh or SpringTopology, got {type(body).__name__}")
        topology = body if isinstance(body, SpringTopology) else SpringTopology.from_mesh(body)
        if not isinstance(topology.mesh, TetMesh):
            raise TypeError(f"body must be a TetMesh or SpringTopology, got {type(body).__name__}")
        if not isinstance(material, Material):
            raise TypeError(f"material must be a volspring.Material, got {type(material).__name__}")
        if not isinstance(rule, str) or rule not in STIFFNESS_RULES:
            raise ValueError(f"unknown stiffness rule {rule!r}; known: {', '.join(STIFFNESS_RULES)}")
        if (rule == "uniform") != (stiffness is not None):
            raise ValueError("stiffness= is required by rule='uniform' and only by it"
                             f" (rule={rule!r}, stiffness={stiffness!r})")
        if not isinstance(law, str) or law not in FORCE_LAWS:
            raise ValueError(f"unknown force law {law!r}; known: {', '.join(FORCE_LAWS)}")
        if law != "hooke" and rule != "uniform":
            raise ValueError(f"law={law!r} applies to rule='uniform' only: rule={rule!r} gives the stiffness "
                             "k_e [N/m] directly")
        if stiffness is not None:
            stiffness = _real_number("stiffness", stiffness)
            if not (np.isfinite(stiffness) and stiffness >= 0):
                raise ValueError(f"stiffness = {stiffness} is not finite and >= 0")
        if damping_ratio is not None and damping is not None:
            raise ValueError("give damping_ratio or damping, not both")
        if damping_ratio is not None:
            damping_ratio = _real_number("damping_ratio", damping_ratio)
            if not np.isfinite(damping_ratio) or damping_ratio < 0:
                raise ValueError(f"damping_ratio = {damping_ratio} is not finite and >= 0")

        mesh, n = topology.mesh, topology.node_count
        springs, lengths = topology.springs, topology.rest_lengths
        masses = np.zeros(n)
        masses[: mesh.node_count] = material.density * mesh.node_volumes()
        k = np.zeros(len(springs))
        if rule == "uniform":
            k[:] = _effective_stiffness(np.full(len(springs), stiffness), lengths, law)
        else:
            edge_of_spring = _pair_index(springs, n, mesh.edges)
            if (edge_of_spring < 0).any():
                raise ValueError("the topology lacks springs for some tet edges")
            tet_edges = edge_of_spring[mesh.tet_edge_index]  # (m, 6) spring index of each tet edge
            contributions = _rule_stiffness(rule, material.E, np.repeat(mesh.tet_volumes, 6),
                                            lengths[tet_edges.ravel()])
            k += np.bincount(tet_edges.ravel(), weights=contributions, minlength=len(springs))
        if topology.shell_node_count:
            prism_springs, prism_volumes, prism_tops = _shell_prisms(topology)
            masses += np.bincount(prism_tops.ravel(), weights=np.repeat(material.density * prism_volumes / 3, 3),
                                  minlength=n)
            if rule != "uniform":
                contributions = _rule_stiffness(rule, material.E, np.repeat(prism_volumes, 12),
                                                lengths[prism_springs.ravel()])
                k += np.bincount(prism_springs.ravel(), weights=contributions, minlength=len(springs))
        if (masses <= 0).any():
            raise ValueError(f"{(masses <= 0).sum()} node(s) got no mass (shell nodes in no shell triangle?)")
        if damping_ratio is not None:
            m_i, m_j = masses[springs[:, 0]], masses[springs[:, 1]]
            damping = 2.0 * damping_ratio * np.sqrt(k * m_i * m_j / (m_i + m_j))
        return cls(topology.points, masses, springs, k, 0.0 if damping is None else damping, lengths,
                   topology.kinds, topology=topology, material=material, rule=rule)

    # ------------------------------------------------------------------ sizes and derived data
    @property
    def node_count(self) -> int:
        return len(self.rest_positions)

    @property
    def spring_count(self) -> int:
        return len(self.springs)

    @property
    def total_mass(self) -> float:
        return float(self.masses.sum())

    @cached_property
    def incidence(self) -> sp.csr_matrix:
        """(n, s) sparse -- +1 at (i, e) and -1 at (j, e) for spring e = (i, j).

        ``incidence @ f`` scatters per-spring forces on i, shape (s, 3), to node forces (n, 3).
        """
        s = self.spring_count
        rows = self.springs.T.ravel()
        values = np.concatenate([np.ones(s), -np.ones(s)])
        return sp.csr_matrix((values, (rows, np.tile(np.arange(s), 2))), shape=(self.node_count, s))

    @cached_property
    def difference(self) -> sp.csr_matrix:
        """(s, n) sparse -- -1 at (e, i) and +1 at (e, j): ``difference @ x`` is x_j - x_i per spring.

        A sparse product gathers the spring vectors several times faster than fancy indexing.
        """
        return (-self.incidence.T).tocsr()

    def kind_counts(self) -> dict:
        counts = np.bincount(self.kinds, minlength=len(SPRING_KINDS))
        return {name: int(count) for name, count in zip(SPRING_KINDS, counts)}

    def __repr__(self) -> str:
        return (f"SpringModel({self.node_count} nodes, {self.spring_count} springs, rule={self.rule!r}, "
                f"mass {self.total_mass:.6g} kg)")


def _effective_stiffness(k, rest_lengths, law):
    if law == "hooke":
        return k
    if law == "strain":
        return k / rest_lengths
    raise ValueError(f"unknown force law {law!r}; known: {', '.join(FORCE_LAWS)}")


def _shell_prisms(topology):
    """Prisms between consecutive shell layers.

    Returns
    -------
    springs : (p, 12) int -- spring index of each prism's 3 top edges, 3 straight and 6 diagonal springs
    volumes : (p,) float -- prism volumes [m^3]
    tops : (p, 3) int -- the prism's top-layer nodes
    """
    n = topology.node_count
    straight = topology.springs[topology.kinds == SPRING_KINDS.index("shell")]
    layer = topology.shell_layer
    child = np.where(layer[straight[:, 0]] > layer[straight[:, 1]], straight[:, 0], straight[:, 1])
    parent_of = np.full(n, -1)
    parent_of[child] = straight.sum(axis=1) - child
    top = topology.shell_triangles
    bottom = parent_of[top]
    if (bottom < 0).any():
        raise ValueError("a shell triangle has a node with no straight spring to the layer below")
    a0, b0, c0 = bottom.T
    a1, b1, c1 = top.T
    pairs = np.stack([(a1, b1), (b1, c1), (c1, a1), (a0, a1), (b0, b1), (c0, c1),
                      (a0, b1), (b0, a1), (b0, c1), (c0, b1), (c0, a1), (a0, c1)], axis=1)  # (2, 12, p)
    springs = _pair_index(topology.springs, n, pairs.reshape(2, -1).T).reshape(12, -1).T
    if (springs < 0).any():
        raise ValueError("a shell prism lacks one of its 12 springs (top edges, straight or diagonal)")
    x = topology.points
    split = [(a0, b0, c0, a1), (b0, c0, a1, b1), (c0, a1, b1, c1)]
    volumes = sum(np.abs(np.einsum("ij,ij->i", x[q] - x[p], np.cross(x[r] - x[p], x[s] - x[p]))) / 6
                  for p, q, r, s in split)
    return springs, volumes, top
