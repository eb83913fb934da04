"""Several deformable bodies seen as one: the static, concatenated topology collision queries run on.

Built from a :class:`~volspring.Model` (:meth:`CollisionBodies.from_model`: its topology's tet mesh
split by ``node_body``) or from tet meshes directly.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from meshing.mesh import TET_EDGES, TET_FACES, TetMesh, boundary_face_mask
from typing import TYPE_CHECKING, cast

if TYPE_CHECKING:
    from collections.abc import Iterable, Sequence

    from numpy.typing import ArrayLike
    from volspring.model import Model

__all__ = ["CollisionBodies"]


@dataclass(frozen=True, eq=False)
class CollisionBodies:
    """The tet meshes of a scene's deformable bodies, numbered globally.

    Node ``i`` of body ``b`` has global id ``node_offsets[b] + i``, tet ``t`` of body ``b`` has
    global id ``tet_offsets[b] + t``; every array below uses global ids. The positions of a step
    are passed separately (one ``(N, 3)`` array, or one array per body), so this object is built
    once per scene.

    Parameters
    ----------
    meshes : sequence of TetMesh
        the bodies, in body-id order
    model_nodes : (N,) int, optional
        the model node of each global node id (:meth:`from_model`); default ``arange(N)``

    Examples
    --------
    >>> from meshing import TetMesh
    >>> from volspring.collision import CollisionBodies
    >>> import numpy as np
    >>> tet = TetMesh(np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2, 3]]))
    >>> bodies = CollisionBodies((tet, tet))
    >>> bodies.node_count, bodies.tets[1].tolist(), bodies.node_body.tolist()
    (8, [4, 5, 6, 7], [0, 0, 0, 0, 1, 1, 1, 1])
    """

    meshes: tuple
    model_nodes: np.ndarray = cast("np.ndarray", None)  # None (the default) is filled in by __post_init__

    if TYPE_CHECKING:  # what the constructor takes (__post_init__ checks and converts it)
        def __init__(self, meshes: Iterable[TetMesh], model_nodes: ArrayLike | None = None) -> None: ...

    def __post_init__(self):
        meshes = tuple(self.meshes)
        if not meshes:
            raise ValueError("CollisionBodies needs at least one TetMesh, got none")
        for index, mesh in enumerate(meshes):
            if not isinstance(mesh, TetMesh):
                raise TypeError(f"meshes[{index}] must be a TetMesh, got {type(mesh).__name__}")
        object.__setattr__(self, "meshes", meshes)
        count = sum(mesh.node_count for mesh in meshes)
        nodes = np.arange(count) if self.model_nodes is None else np.array(self.model_nodes)
        if not np.issubdtype(nodes.dtype, np.integer) or nodes.shape != (count,):
            raise ValueError(f"model_nodes has shape {nodes.shape} and dtype {nodes.dtype}; expected ({count},) "
                             "integers, one model node per mesh node")
        object.__setattr__(self, "model_nodes", _frozen(nodes.astype(np.int64)))

    @classmethod
    def from_model(cls, model: Model) -> "CollisionBodies":
        """The bodies of a :class:`~volspring.Model`: its topology's tet mesh split by ``model.node_body``.

        Body b's mesh holds the model's mesh nodes of body b in ascending order and the tets among
        them, in the model's order; ``model_nodes`` maps the global ids back to model nodes (for a
        model from :meth:`Model.from_bodies <volspring.Model.from_bodies>`, ``arange(N)``).

        Bodies numbered after every body of the mesh, with no mesh node (a cloth or a string joined to
        the tet bodies by :func:`volspring.structures.combine`), are not part of the result:
        ``body_count`` is then less than ``model.body_count``, and the body ids of both agree.

        Raises
        ------
        ValueError
            For a model without a tet mesh (built from arrays), a body with no tet (other than those
            trailing bodies without mesh nodes), or a tet whose nodes belong to different bodies
            (naming the tet).

        Examples
        --------
        >>> import numpy as np
        >>> from meshing import TetMesh
        >>> from volspring import Material, Model
        >>> from volspring.bodies import Body
        >>> tet = TetMesh(np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2, 3]]))
        >>> rubber = Material(E=1e5, nu=0.3, density=1000.0)
        >>> bodies = CollisionBodies.from_model(Model.from_bodies([Body(tet, rubber), Body(tet, rubber, translation=(2, 0, 0))]))
        >>> bodies.body_count, bodies.meshes[1].points[:, 0].tolist(), bodies.model_nodes.tolist()
        (2, [2.0, 3.0, 2.0, 2.0], [0, 1, 2, 3, 4, 5, 6, 7])
        """
        if model.topology is None:
            raise ValueError("the model has no tet mesh to collide (built from arrays); build it with "
                             "Model.from_mesh or Model.from_bodies")
        mesh = model.topology.mesh
        node_body = model.node_body[: mesh.node_count]
        tet_body = node_body[mesh.tets[:, 0]]
        mixed = (node_body[mesh.tets] != tet_body[:, None]).any(axis=1)
        if mixed.any():
            tet = int(np.flatnonzero(mixed)[0])
            raise ValueError(f"tet {tet} = {mesh.tets[tet].tolist()} joins nodes of bodies "
                             f"{node_body[mesh.tets[tet]].tolist()}; expected every tet within one body")
        body_count = int(node_body.max()) + 1  # bodies after the last meshed one have no mesh node
        tet_counts = np.bincount(tet_body, minlength=body_count)
        if (tet_counts == 0).any():
            body = int(np.flatnonzero(tet_counts == 0)[0])
            raise ValueError(f"body {body} has no tet in the model's mesh; expected a tet mesh for every body")
        order = np.argsort(node_body, kind="stable")  # model node of each global id, body after body
        offsets = np.concatenate([[0], np.cumsum(np.bincount(node_body, minlength=body_count))])
        local = np.empty(mesh.node_count, dtype=np.int64)
        local[order] = np.arange(mesh.node_count) - np.repeat(offsets[:-1], np.diff(offsets))
        meshes = tuple(TetMesh(mesh.points[order[offsets[b]:offsets[b + 1]]], local[mesh.tets[tet_body == b]])
                       for b in range(body_count))  # a loop over bodies
        return cls(meshes, order)

    # ------------------------------------------------------------------ numbering
    @property
    def body_count(self) -> int:
        return len(self.meshes)

    @cached_property
    def node_offsets(self) -> np.ndarray:
        """(b + 1,) int64 -- first global node id of each body, then the node count."""
        return _frozen(np.concatenate([[0], np.cumsum([m.node_count for m in self.meshes])]).astype(np.int64))

    @cached_property
    def tet_offsets(self) -> np.ndarray:
        """(b + 1,) int64 -- first global tet id of each body, then the tet count."""
        return _frozen(np.concatenate([[0], np.cumsum([m.tet_count for m in self.meshes])]).astype(np.int64))

    @property
    def node_count(self) -> int:
        return int(self.node_offsets[-1])

    @property
    def tet_count(self) -> int:
        return int(self.tet_offsets[-1])

    @cached_property
    def node_body(self) -> np.ndarray:
        """(N,) int64 -- body id of each global node."""
        return _frozen(np.repeat(np.arange(self.body_count), np.diff(self.node_offsets)))

    @cached_property
    def tet_body(self) -> np.ndarray:
        """(M,) int64 -- body id of each global tet."""
        return _frozen(np.repeat(np.arange(self.body_count), np.diff(self.tet_offsets)))

    # ------------------------------------------------------------------ topology
    @cached_property
    def tets(self) -> np.ndarray:
        """(M, 4) int64 -- global node ids of each tet, positively oriented at rest."""
        return _frozen(np.concatenate([m.tets + o for m, o in zip(self.meshes, self.node_offsets)]))

    @cached_property
    def edges(self) -> np.ndarray:
        """(E, 2) int64 -- unique tet edges, global node ids, ``i < j``."""
        return _frozen(np.concatenate([m.edges + o for m, o in zip(self.meshes, self.node_offsets)]))

    @cached_property
    def boundary_faces(self) -> np.ndarray:
        """(F, 3) int64 -- outward-wound boundary triangles, global node ids."""
        return _frozen(np.concatenate([m.boundary_faces + o for m, o in zip(self.meshes, self.node_offsets)]))

    @cached_property
    def boundary_face_body(self) -> np.ndarray:
        """(F,) int64 -- body id of each boundary triangle."""
        counts = [len(m.boundary_faces) for m in self.meshes]
        return _frozen(np.repeat(np.arange(self.body_count), counts))

    @cached_property
    def tet_face_on_boundary(self) -> np.ndarray:
        """(M, 4) bool -- whether face k of each tet (``meshing.mesh.TET_FACES[k]``, outward wound for a
        positively oriented tet) is a boundary face."""
        return _frozen(boundary_face_mask(self.tets))

    @cached_property
    def tet_edge_on_boundary(self) -> np.ndarray:
        """(M, 6) bool -- whether edge e of each tet (``meshing.mesh.TET_EDGES[e]``) is an edge of a boundary face."""
        n = np.int64(self.node_count)
        faces = self.tets[:, TET_FACES][self.tet_face_on_boundary]  # (F, 3)
        pairs = np.sort(faces[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
        edges = np.sort(self.tets[:, TET_EDGES], axis=2)
        return _frozen(np.isin(edges[..., 0] * n + edges[..., 1], pairs[:, 0] * n + pairs[:, 1]))

    @cached_property
    def neighbours(self) -> tuple[np.ndarray, np.ndarray]:
        """CSR adjacency along tet edges: ``(indptr (N + 1,), indices (2E,))`` int64, global ids."""
        both = np.concatenate([self.edges, self.edges[:, ::-1]])
        both = both[np.lexsort((both[:, 1], both[:, 0]))]
        indptr = np.concatenate([[0], np.cumsum(np.bincount(both[:, 0], minlength=self.node_count))])
        return _frozen(indptr.astype(np.int64)), _frozen(both[:, 1].copy())

    @cached_property
    def mean_edge_lengths(self) -> np.ndarray:
        """(b,) float -- mean rest edge length of each body [m] (the penalty stiffness rule's l)."""
        return _frozen(np.array([mesh.edge_lengths.mean() for mesh in self.meshes]))

    @cached_property
    def mean_edge_length(self) -> float:
        """Average rest edge length over all bodies [m]: the default hash cell size (Teschner et al.)."""
        lengths = np.concatenate([m.edge_lengths for m in self.meshes])
        return float(lengths.mean())

    # ------------------------------------------------------------------ positions
    def stack_positions(self, positions: ArrayLike) -> np.ndarray:
        """One ``(N, 3)`` float64 array from a ``(N, 3)`` array or a sequence of ``(n_b, 3)`` arrays.

        Raises
        ------
        ValueError
            When the shapes do not match the bodies' node counts or a coordinate is not finite.
        """
        if isinstance(positions, np.ndarray):
            stacked = np.asarray(positions, dtype=np.float64)
        else:
            parts = [np.asarray(p, dtype=np.float64) for p in cast("Sequence[ArrayLike]", positions)]  # one per body
            if len(parts) != self.body_count:
                raise ValueError(f"got positions for {len(parts)} bodies, expected {self.body_count}")
            for b, (part, mesh) in enumerate(zip(parts, self.meshes)):
                if part.shape != (mesh.node_count, 3):
                    raise ValueError(f"positions[{b}] has shape {part.shape}, expected ({mesh.node_count}, 3)")
            stacked = np.concatenate(parts)
        if stacked.shape != (self.node_count, 3):
            raise ValueError(f"positions have shape {stacked.shape}, expected ({self.node_count}, 3)")
        if not np.isfinite(stacked).all():
            bad = np.flatnonzero(~np.isfinite(stacked).all(axis=1))
            raise ValueError(f"{len(bad)} position(s) are not finite, first is global node {bad[0]}")
        return stacked

    @property
    def rest_positions(self) -> np.ndarray:
        """(N, 3) float -- the meshes' own node positions, stacked [m]."""
        return np.concatenate([m.points for m in self.meshes])

    def __repr__(self) -> str:
        return f"CollisionBodies({self.body_count} bodies, {self.node_count} nodes, {self.tet_count} tets)"


def _frozen(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array
