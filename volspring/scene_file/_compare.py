"""The ``[compare]`` table: the static problem of the body a scene compares with a reference, checked.

:func:`static_problem` turns a resolved scene and its assembled model into the
:class:`~volspring.comparisons.StaticProblem` a comparison (``static_fem``, :mod:`volspring.comparisons`)
solves: the body's mesh at rest as placed in the scene, its material, the nodes the pins hold and gravity.
It refuses, naming the key path, what a static linear-elastic reference has no counterpart for: a body that
is not meshed, supports that slide or move, fields other than gravity and drag (drag is zero at rest), and
contact or obstacles. Run before any step, so a scene that cannot be compared costs no simulation.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from volspring.scene_file._schema import SceneFileError, joined

if TYPE_CHECKING:
    from volspring.comparisons import StaticProblem
    from volspring.scene import Scene

__all__ = ["compare_final_state", "comparison_line", "comparison_reference", "static_problem"]

#: Fields a static reference reproduces: gravity is its load, drag vanishes at rest.
STATIC_FIELDS = ("gravity", "drag")


def static_problem(scene: dict, bodies: tuple, built: Scene) -> StaticProblem:
    """The :class:`~volspring.comparisons.StaticProblem` of ``scene["compare"]["body"]``.

    Parameters
    ----------
    scene : dict
        A resolved scene with a ``compare`` table.
    bodies : tuple of Body
        The scene's tet bodies, in order (the first ones of ``scene["bodies"]``).
    built : Scene
        The assembled scene (its model numbers the tet bodies first, their mesh nodes first in each body; its
        pins are the scene's pins at rest).

    Raises
    ------
    SceneFileError
        Naming the key path of what the reference cannot reproduce.
    """
    from meshing.mesh import TetMesh
    from volspring.comparisons import StaticProblem, check_name

    table = scene["compare"]
    refusal = check_name(table["case"])
    if refusal is not None:
        raise SceneFileError(f"compare.case = \"{table['case']}\" {refusal}")
    index, specs = table["body"], scene["bodies"]
    if not 0 <= index < len(specs):
        raise SceneFileError(f"compare.body = {index} is not a body index in [0, {len(specs) - 1}]")
    if specs[index]["kind"] != "tet":
        raise SceneFileError(f"compare.body = {index}: {joined('bodies', index)} is a {specs[index]['kind']}; "
                             "expected a tet body (a mesh or a shape): the reference is a tet mesh")
    for name in ("contact", "thin_contact"):
        if name in scene:
            raise SceneFileError(f"compare: the scene has [{name}]; a static reference has no contact (remove one)")
    if scene["obstacles"]:
        raise SceneFileError("compare: the scene has obstacles; a static reference has no contact (remove them)")
    gravity = np.zeros(3)
    for number, field in enumerate(scene["fields"]):
        if field["type"] not in STATIC_FIELDS:
            raise SceneFileError(f"compare: {joined('fields', number)} is a {field['type']} field; a static reference "
                                 f"has only {' and '.join(STATIC_FIELDS)} (drag vanishes at rest)")
        if field["type"] == "gravity":
            gravity += np.asarray(field.get("g", (0.0, 0.0, -9.81)), dtype=np.float64)
    for number, support in enumerate(scene["supports"]):
        if support["type"] != "pin" or "displacement" in support or "velocity" in support:
            raise SceneFileError(f"compare: {joined('supports', number)} is a {support['type']} support that moves or "
                                 "lets nodes slide; the static reference holds nodes at rest (type = \"pin\") only")
    body = bodies[index]
    mesh = body.body if isinstance(body.body, TetMesh) else body.body.mesh
    model = built.model
    nodes = model.body_nodes(index)[: mesh.node_count]
    held = np.zeros(model.node_count, dtype=bool)
    if built.pins is not None:
        held[built.pins.nodes] = True
    has_gravity = any(field["type"] == "gravity" for field in scene["fields"])
    return StaticProblem(TetMesh(model.rest_positions[nodes], mesh.tets), body.material, held=held[nodes],
                         gravity=gravity if has_gravity else None, body=index, nodes=nodes,
                         name=specs[index].get("name", ""))


def compare_final_state(scene: dict, problem: StaticProblem, positions: np.ndarray, *,
                        reference: Any = None) -> dict:
    """``scene["compare"]``'s comparison of the body at ``positions`` (the model's, at the end of the run), against
    ``reference`` when it is given (:func:`comparison_reference`, shared by runs of one body).

    Returns the comparison's numbers (:func:`volspring.comparisons.compare`).
    """
    from volspring.comparisons import compare

    table = scene["compare"]
    displacement = np.asarray(positions)[problem.nodes] - problem.mesh.points
    return compare(table["case"], problem, displacement, reference=reference, **_options(table))


def comparison_reference(scene: dict, problem: StaticProblem) -> Any:
    """The reference answer of ``scene["compare"]`` for ``problem`` (:func:`volspring.comparisons.reference`), or
    None when the comparison has none apart."""
    from volspring.comparisons import reference

    table = scene["compare"]
    return reference(table["case"], problem, **_options(table))


def _options(table: dict) -> dict:
    """The comparison's own options of a ``[compare]`` table."""
    return {name: table[name] for name in ("element", "cache") if table.get(name) is not None}


def comparison_line(scene: dict, numbers: dict) -> str:
    """One summary line: ``compare: static_fem on bodies[0] (beam): peak_ratio 0.967, rms_error 0.0321, ...``."""
    table = scene["compare"]
    name = scene["bodies"][table["body"]].get("name")
    shown = ", ".join(f"{key} {value:.4g}" if isinstance(value, float) else f"{key} {value}"
                      for key, value in numbers.items())
    return f"compare: {table['case']} on {joined('bodies', table['body'])}" + (f" ({name})" if name else "") + \
        f": {shown}"
