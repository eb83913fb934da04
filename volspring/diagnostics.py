"""Energies, momenta and centre of mass of a state: small functions of (scene or model, state).

Each takes a :class:`Scene` or a :class:`Model` (for the model-only quantities) and a
:class:`State`. Energies are in J, momenta in kg m/s and kg m^2/s, positions in m.

Examples
--------
>>> from volspring import Scene, Model
>>> from volspring.diagnostics import kinetic_energy, linear_momentum
>>> pair = Model.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 3.0], [[0, 1]], stiffness=10.0)
>>> state = Scene(pair).initial_state(v=[[2, 0, 0], [0, 0, 0]])
>>> kinetic_energy(pair, state), linear_momentum(pair, state).tolist()
(2.0, [2.0, 0.0, 0.0])
"""

from __future__ import annotations

import numpy as np

from typing import TYPE_CHECKING, NamedTuple

from meshing.geometry import signed_tet_volumes
from volspring.model import Model
from volspring.forces import Gravity
from volspring.scene import Scene, State
from volspring.springs import spring_energy as _spring_energy

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = ["kinetic_energy", "spring_energy", "gravitational_energy", "potential_energy", "total_energy",
           "linear_momentum", "angular_momentum", "centre_of_mass", "TetInversion", "tet_inversion"]


def _model(system) -> Model:
    if isinstance(system, Scene):
        return system.model
    if isinstance(system, Model):
        return system
    raise TypeError(f"expected a Scene or Model, got {type(system).__name__}")


def _scene(system) -> Scene:
    if isinstance(system, Scene):
        return system
    if isinstance(system, Model):
        return Scene(system)
    raise TypeError(f"expected a Scene or Model, got {type(system).__name__}")


def kinetic_energy(system: Scene | Model, state: State) -> float:
    """sum 1/2 m_i |v_i|^2 [J]."""
    return _scene(system).kinetic_energy(state.v)


def spring_energy(system: Scene | Model, state: State) -> float:
    """Elastic energy of the springs, sum 1/2 k_e (l - l0)^2 [J]."""
    return _spring_energy(_model(system), state.x)


def gravitational_energy(system: Scene | Model, state: State) -> float:
    """Potential of the scene's :class:`Gravity` forces, -sum m_i g . x_i [J] (0 for a bare model)."""
    if isinstance(system, Model):
        return 0.0
    scene = _scene(system)
    return float(sum(force.potential_energy(scene.model, state.x, state.t) for force in scene.forces
                     if isinstance(force, Gravity)))


def potential_energy(system: Scene | Model, state: State) -> float:
    """Springs plus every conservative force of the scene (those with ``potential_energy``) [J]."""
    return _scene(system).potential_energy(state.x, state.t)


def total_energy(system: Scene | Model, state: State) -> float:
    """Kinetic plus potential energy [J]."""
    return kinetic_energy(system, state) + potential_energy(system, state)


def linear_momentum(system: Scene | Model, state: State) -> np.ndarray:
    """(3,) float -- sum m_i v_i [kg m/s]."""
    return _model(system).masses @ state.v


def centre_of_mass(system: Scene | Model, state: State) -> np.ndarray:
    """(3,) float -- sum m_i x_i / sum m_i [m]."""
    model = _model(system)
    return model.masses @ state.x / model.total_mass


def angular_momentum(system: Scene | Model, state: State, *, about: ArrayLike | None = None) -> np.ndarray:
    """(3,) float -- sum m_i (x_i - c) x v_i [kg m^2/s], about the centre of mass unless ``about`` (3,) [m]."""
    model = _model(system)
    centre = centre_of_mass(model, state) if about is None else np.asarray(about, dtype=np.float64)
    return model.masses @ np.cross(state.x - centre, state.v)


class TetInversion(NamedTuple):
    """How many tets of a deformed body are turned inside out, and the worst of them.

    Parameters
    ----------
    count : int
        tets whose signed volume is <= 0 (inverted or flat)
    worst_volume_ratio : float
        smallest V / V_rest over all tets [-] (negative once one inverts; NaN for a model without tets)
    tet_count : int
        tets checked (0 for a model built from arrays)
    """

    count: int  # type: ignore[assignment]  # public field name; it shadows tuple.count, which mypy refuses
    worst_volume_ratio: float
    tet_count: int


def tet_inversion(system: Scene | Model, x: ArrayLike) -> TetInversion:
    """Inverted tets of the model's tet mesh at positions ``x``.

    A spring network has no notion of orientation: soft settings let tets turn inside out
    without any force resisting it (E = 1e4 Pa: 76 of 821 tets of a hanging beam at t = 1 s).
    Counted here so runs can report it; a model without a tet mesh reports no tets.

    Parameters
    ----------
    system : Scene or Model
    x : (n, 3) float
        node positions [m]

    Returns
    -------
    TetInversion

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import Material, Model, TetMesh
    >>> mesh = TetMesh(np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2, 3]]))
    >>> model = Model.from_mesh(mesh, Material(1e6, 0.3, 1000.0))
    >>> flipped = model.rest_positions * [1, 1, -1]   # mirrored: the tet is inside out
    >>> tet_inversion(model, flipped)
    TetInversion(count=1, worst_volume_ratio=-1.0, tet_count=1)
    """
    model = _model(system)
    mesh = None if model.topology is None else model.topology.mesh
    if mesh is None:
        return TetInversion(0, float("nan"), 0)
    ratio = signed_tet_volumes(np.asarray(x)[: mesh.node_count], mesh.tets) / mesh.tet_volumes
    return TetInversion(int(np.count_nonzero(ratio <= 0.0)), float(ratio.min()), int(mesh.tet_count))
