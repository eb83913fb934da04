"""Comparisons of a run with a reference, found through entry points: how a scene names "compare with FEM".

A scene file's ``[compare]`` table names a comparison (``case = "static_fem"``); the comparison itself lives in
a layer above this one (:mod:`validation` registers ``static_fem``, the linear-elastic finite-element answer of
the same body), so volspring finds it through the entry-point group :data:`GROUP` and imports nothing above its
own layer, as :mod:`volspring.command` finds its subcommands. What volspring hands over is plain data: the
static problem of one tet body (:class:`StaticProblem`: its mesh at rest, material, held nodes and gravity) and
the displacement of its mesh nodes at the end of the run. A comparison returns a dict of numbers (the same
inputs give the same numbers, bit for bit: the sweep table records them as measured quantities).

A comparison is ``NAME = "package.module:function"`` in the group, with
``function(problem, displacement, **options) -> dict``; :func:`available` lists the installed ones and
:func:`compare` runs one. A comparison whose reference is costly (a FEM solve) offers it apart,
``function.reference(problem, **options)``, so that the runs of one body share one (:func:`reference`).

Examples
--------
>>> from volspring.comparisons import available
>>> "static_fem" in available()   # validation's, installed with volspring
True
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from importlib.metadata import EntryPoint, entry_points
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from meshing.mesh import TetMesh
    from volspring.material import Material

__all__ = ["GROUP", "StaticProblem", "available", "check_name", "compare", "reference"]

#: The entry-point group of the comparisons: ``NAME = "package.module:function"``.
GROUP = "volspring.comparisons"


@dataclass(frozen=True, eq=False)
class StaticProblem:
    """The static problem of one tet body of a scene, as a reference solver needs it.

    Parameters
    ----------
    mesh : TetMesh
        The body at rest, placed as in the scene (translation and rotation applied) [m]; its nodes are the
        model's ``nodes``.
    material : Material
        The body's material (E, nu, density).
    held : (n,) bool
        The mesh nodes the scene's supports hold in place (all components).
    gravity : (3,) float or None
        The scene's gravity [m/s^2]; None without a gravity field.
    body : int
        The body's index in the scene (``bodies[body]``).
    nodes : (n,) int
        The model's node numbers of the mesh nodes (a body's shell nodes, if any, are not among them).
    name : str
        The body's name, for messages.
    """

    mesh: TetMesh
    material: Material
    held: np.ndarray
    gravity: np.ndarray | None
    body: int
    nodes: np.ndarray
    name: str = ""


def available() -> dict[str, EntryPoint]:
    """The comparisons installed: name -> :class:`importlib.metadata.EntryPoint` (not loaded), by name."""
    found = {point.name: point for point in entry_points(group=GROUP)}
    return {name: found[name] for name in sorted(found)}


def check_name(name: str) -> str | None:
    """None when ``name`` is an installed comparison, else the end of a message (what is installed)."""
    known = available()
    if name in known:
        return None
    close = difflib.get_close_matches(name, known, n=1)
    hint = f"; did you mean \"{close[0]}\"?" if close else ""
    listed = ", ".join(known) or f"none (no package registers the entry-point group {GROUP})"
    return f"is not an installed comparison (installed: {listed}){hint}"


def reference(name: str, problem: StaticProblem, **options: Any) -> Any:
    """The comparison's reference answer for ``problem``, made once to be shared by the runs of one body (a sweep's),
    or None for a comparison that has none apart (it then makes its own in every :func:`compare`).

    A comparison offers one as an attribute of its function, ``function.reference(problem, **options)``, and takes
    it back as ``function(problem, displacement, reference=..., **options)``.
    """
    maker = getattr(_loaded(name), "reference", None)
    return None if maker is None else maker(problem, **options)


def compare(name: str, problem: StaticProblem, displacement: np.ndarray, *, reference: Any = None,
            **options: Any) -> dict:
    """Run the comparison ``name`` on the displacement of the problem's mesh nodes.

    Parameters
    ----------
    name : str
        One of :func:`available`.
    problem : StaticProblem
    displacement : (n, 3) float
        The displacement of the body's mesh nodes at the end of the run [m].
    reference : object, optional
        The comparison's answer made already by :func:`reference` for this problem; None: it makes its own.
    **options
        The comparison's own options (``element`` for ``static_fem``).

    Returns
    -------
    dict
        The comparison's numbers, by name.

    Raises
    ------
    ValueError
        For a name no installed package registers, or a displacement of another shape than the mesh's nodes.
    """
    function = _loaded(name)
    displacement = np.asarray(displacement, dtype=np.float64)
    if displacement.shape != (problem.mesh.node_count, 3):
        raise ValueError(f"displacement has shape {displacement.shape}; expected ({problem.mesh.node_count}, 3), one "
                         "row per mesh node of the body")
    if reference is not None:
        options["reference"] = reference
    return dict(function(problem, displacement, **options))


def _loaded(name: str) -> Any:
    """The function of the installed comparison ``name``; ValueError naming what is installed otherwise."""
    refusal = check_name(name)
    if refusal is not None:
        raise ValueError(f"comparison \"{name}\" {refusal}")
    return available()[name].load()
