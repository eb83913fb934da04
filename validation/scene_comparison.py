"""A scene's body against the linear-elastic FEM answer of the same body: the ``static_fem`` comparison.

A scene file's ``[compare]`` table (``case = "static_fem"``) asks for it; volspring finds it through the
entry-point group ``volspring.comparisons`` (:mod:`volspring.comparisons`), which this package registers. The
reference is the static equilibrium of the body's own mesh, material, held nodes and gravity
(:func:`validation.fem.solve_fem_static`, through the on-disk cache :mod:`validation.cache`), Taylor-Hood by
default (free of volumetric locking as nu -> 1/2, the
ladder's reference: :data:`validation.ladder.STATIC_REFERENCE`). It is compared with the body's displacement at
the end of the run, so the run should have settled there (damped, long enough: the run's kinetic energy says
how far it is from rest). The reference can be made apart (:func:`static_fem_reference`, a :class:`FemReference`
that knows the problem it answers) and handed to :func:`static_fem`: a sweep makes one per body and shares it
among the runs (:func:`volspring.comparisons.reference`).

The numbers (:data:`MEASURES`), the same ones the validation report gives a model on its cases:

=========================  ============================================================================
``peak_ratio``             the displacement at the node FEM moves most, along FEM's direction there, over
                           FEM's (1 = FEM's deflection)
``rms_error``              RMS over the nodes of |u - u_FEM|, over the RMS of |u_FEM| [-]
``max_error``              max over the nodes of |u - u_FEM|, over the max of |u_FEM| [-]
``volume_change_ratio``    the body's volume change (its mesh moved by the nodes' displacements) over
                           FEM's (the integral of div u); None in bending, where FEM's net change is a
                           cancellation (:func:`validation.fem.volume_change_cancels`)
``reference_peak_m``       FEM's largest nodal displacement [m]
``reference_element``      the FEM element: "TH", "P2" or "P1"
=========================  ============================================================================

Examples
--------
>>> import numpy as np
>>> from meshing import structured_box
>>> from volspring.comparisons import StaticProblem, compare
>>> from volspring.material import Material
>>> mesh = structured_box((4, 1, 1), (1.0, 0.25, 0.25))
>>> problem = StaticProblem(mesh, Material(1e6, 0.3, 1000.0), held=mesh.points[:, 0] < 1e-9,
...                         gravity=np.array([0.0, 0.0, -9.81]), body=0, nodes=np.arange(mesh.node_count))
>>> exact = compare("static_fem", problem, np.zeros((mesh.node_count, 3)), cache=False)
>>> exact["peak_ratio"], exact["rms_error"]   # a body that did not move: none of FEM's sag
(0.0, 1.0)
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from validation import cache as reference_cache
from validation import fem
from validation._own_mesh import check_held
from validation.compare import displacement_errors
from validation.springs import deformed_volume_change

if TYPE_CHECKING:
    from volspring.comparisons import StaticProblem

__all__ = ["FemReference", "MEASURES", "problem_digest", "static_fem", "static_fem_reference"]

#: The numbers :func:`static_fem` returns, in this order (see the module docstring).
MEASURES = ("peak_ratio", "rms_error", "max_error", "volume_change_ratio", "reference_peak_m", "reference_element")


class _Held:
    """The clamp region of the held nodes: the mesh's own nodes, by number (FEM tests regions at the nodes)."""

    def __init__(self, held: np.ndarray):
        self.held = held

    def __call__(self, points: np.ndarray) -> np.ndarray:
        if len(points) != len(self.held):
            raise ValueError(f"the held nodes are {len(self.held)} mesh nodes' flags, asked about {len(points)} points")
        return self.held

    def __repr__(self) -> str:
        return f"the {int(self.held.sum())} held nodes"


@dataclass(frozen=True, eq=False)
class FemReference:
    """The FEM answer :func:`static_fem` compares with, made once for every run of one body (a sweep sends it to the
    runs that share it: :func:`static_fem_reference`).

    Parameters
    ----------
    digest : str
        SHA-256 of the problem and element it answers (:func:`problem_digest`), checked before it is used.
    element : str
    displacement : (n, 3) float
        [m]
    volume_change, gross_volume_change : float
        [m^3], as :class:`validation.fem.StaticSolution` has them.
    """

    digest: str
    element: str
    displacement: np.ndarray
    volume_change: float
    gross_volume_change: float


def problem_digest(problem: StaticProblem, element: str) -> str:
    """The hex SHA-256 of what the reference of ``problem`` depends on: mesh, material, held nodes, gravity,
    element."""
    digest = hashlib.sha256(element.encode())
    material = problem.material
    for array in (problem.mesh.points, problem.mesh.tets, problem.held, np.zeros(3) if problem.gravity is None
                  else problem.gravity, np.array([material.E, material.nu, material.density])):
        array = np.ascontiguousarray(array)
        digest.update(f"{array.dtype}{array.shape}".encode())
        digest.update(array.tobytes())
    return digest.hexdigest()


def static_fem_reference(problem: StaticProblem, *, element: str | None = None, cache: bool = True) -> FemReference:
    """The FEM static equilibrium of the problem's body (see :func:`static_fem` for the parameters).

    Raises
    ------
    ValueError
        When there is no gravity, the held nodes do not hold the body, or the element is unknown.
    """
    mesh, material = problem.mesh, problem.material
    if problem.gravity is None:
        raise ValueError("the scene has no gravity field: static_fem compares the body's sag under gravity; add "
                         "[[fields]] type = \"gravity\"")
    check_held(mesh, problem.held)
    element = element or ("TH" if material.nu > 0 else "P2")
    solve = reference_cache.cached_solve_static if cache else fem.solve_fem_static
    solution = solve(mesh, material, clamp=_Held(problem.held), gravity=problem.gravity, element=element)
    return FemReference(problem_digest(problem, element), element, solution.displacement, solution.volume_change,
                        solution.gross_volume_change)


def static_fem(problem: StaticProblem, displacement: np.ndarray, *, element: str | None = None,
               cache: bool = True, reference: FemReference | None = None) -> dict:
    """The body's displacement against the FEM static equilibrium of the same body.

    Parameters
    ----------
    problem : volspring.comparisons.StaticProblem
        The body's mesh at rest, material, held nodes and gravity.
    displacement : (n, 3) float
        The body's displacement at the end of the run [m].
    element : {"TH", "P2", "P1"}, optional
        The FEM element; default Taylor-Hood, or P2 for nu <= 0 (Taylor-Hood needs nu > 0).
    cache : bool
        Read and write the reference in :func:`validation.cache.default_folder` (``$VOLSPRING_CACHE``).
    reference : FemReference, optional
        The answer, made already by :func:`static_fem_reference` (a sweep's runs share one); made here if not given.

    Returns
    -------
    dict
        :data:`MEASURES`, by name.

    Raises
    ------
    ValueError
        When the held nodes do not hold the body (every rigid motion must be fixed for a static answer), there is
        no gravity, the element is not one of the three, or ``reference`` answers another problem.
    """
    mesh = problem.mesh
    if reference is None:
        reference = static_fem_reference(problem, element=element, cache=cache)
    elif reference.digest != problem_digest(problem, element or reference.element):
        raise ValueError("reference answers another problem than this body's (mesh, material, held nodes, gravity "
                         "or element differ); make it with static_fem_reference(problem)")
    answer = reference.displacement
    size = np.linalg.norm(answer, axis=1)
    peak = int(np.argmax(size))
    direction = answer[peak] / size[peak]
    # volspring's bodies are geometrically exact: their moved mesh's volume is their volume change (a rotation adds
    # nothing), against the reference's integral of div u (its moved mesh also grows as it rotates).
    bending = fem.volume_change_cancels(reference.volume_change, reference.gross_volume_change)
    volume = deformed_volume_change(mesh, displacement)
    errors = displacement_errors(displacement, answer)
    return {"peak_ratio": float(displacement[peak] @ direction / size[peak]),
            "rms_error": errors["rms_displacement_error"], "max_error": errors["max_displacement_error"],
            "volume_change_ratio": None if bending else float(volume / reference.volume_change),
            "reference_peak_m": float(size[peak]), "reference_element": reference.element}


#: The comparison's reference alone, which volspring.comparisons.reference calls to share one among runs.
static_fem.reference = static_fem_reference  # type: ignore[attr-defined]
