"""Time collisions per step at about 1k, 10k and 50k tets: detection, depths, penalty forces, Jacobian.

Two Kuhn-split unit boxes, the second tilted and pushed a third of its width into the first, as two
bodies of one model (:meth:`volspring.Model.from_bodies`) with a frictional
:class:`~volspring.collision.ContactForce`. For each size the script prints the colliding points
(contacts), then, per step:

- ``detect``: vertex-in-tet detection by spatial hashing (Teschner et al. 2003);
- ``depth``: consistent penetration depths (Heidelberger et al. 2004);
- ``force``: ``ContactForce.accumulate`` as a scene calls it once per step or stage, i.e. detection,
  depths, penalty, damping and friction scattered onto the nodes (it includes the two above);
- ``jacobian``: ``ContactForce.jacobian`` at the same positions (contacts cached): the 5-node blocks
  assembled into a (3N, 3N) CSR matrix, what implicit Euler adds per step;
- ``tet-tet``: :func:`~volspring.collision.tet_tet.crossing_tet_pairs`, the tet-box spatial hash and the
  exact tet-tet narrow phase that ``ContactForce(edges=True)`` adds to every detection (it finds bodies
  crossing with no vertex inside the other), also as a ratio to ``detect``; ``pairs`` how many tet pairs
  intersect;
- ``edges``: what edge contacts need per detection, boundary tets only:
  ``crossing_tet_pairs(..., boundary=True)`` then :func:`~volspring.collision.tet_tet.edge_crossing_contacts`
  (the same contacts as from all pairs), also as a ratio to ``detect``;
- ``SpMV``: one product with the 3N x 3N spring-stiffness pattern of the same N nodes, measured in the
  same run as this machine's yardstick, and the step (force + jacobian) in units of it.

Published figures to compare with (Pentium 4 1.8 GHz, 2003): detection 4.3 / 30.4 / 70 / 172.5 ms at
1k / 10k / 20k / 50k tets ("paper ms": scaled linearly from the nearest published size); depths
~35 us per colliding point (2004).

With ``--levers`` it then measures, per size and in the same run, each speed-up of issue 15 against the
code it replaced (put back for the measurement), alternating the two, best of ``--repeat``:

- ``dense grid, vertex-in-tet``: ``detect``, pairs from the dense grid (``spatial_hash.box_pairs``) against the
  hash of :class:`~volspring.collision.spatial_hash.SpatialHash` (binary searches per cell of every tet box);
- ``dense grid, edge-surface``: ``depth``, the same for the edge-triangle search of the border points;
- ``shared csr pattern``: ``jacobian``, one pattern for dF/dx and dF/dv (``penalty._StencilPattern``) against two
  ``csr_matrix((data, (rows, cols)))`` conversions;
- ``dense grid, tet-tet``: ``tet-tet``, the tet-box pairs of the exact tet-tet test from the dense grid.

Run: ``OMP_NUM_THREADS=1 python benchmarks/bench_collision.py`` (``--sizes 1000 20000`` to choose).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.spatial.transform import Rotation

from meshing import structured_box
from volspring import Material, Model
from volspring.assembly import stiffness_matrix
from volspring.bodies import Body
from volspring.collision import ContactForce, consistent_penetration_depths, detect_collisions
from volspring.collision import penalty, penetration, spatial_hash
from volspring.collision.tet_tet import crossing_tet_pairs, edge_crossing_contacts

PUBLISHED_DETECTION_MS = {1_000: 4.3, 10_000: 30.4, 20_000: 70.0, 50_000: 172.5}


def contact_scene(total_tets):
    """Two unit boxes of about ``total_tets / 2`` tets each, overlapping by a third of their width."""
    n = max(2, round((total_tets / 12) ** (1 / 3)))
    mesh = structured_box((n, n, n), (1.0, 1.0, 1.0), pattern="kuhn")
    tilt = Rotation.from_rotvec([0.1, 0.2, 0.05]).as_matrix()
    offset = np.array([0.5 + 0.67, 0.55, 0.45]) - tilt @ [0.5, 0.5, 0.5]  # (x - 0.5) R^T + c = x R^T + offset
    material = Material(E=1e5, nu=0.3, density=1000.0)
    model = Model.from_bodies([Body(mesh, material), Body(mesh, material, rotation=tilt, translation=offset)])
    return model, ContactForce(model, friction=0.3)


def best_time(function, repeat):
    """Smallest wall time of ``repeat`` calls [s] (the least disturbed by the other processes)."""
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        result = function()
        times.append(time.perf_counter() - start)
    return min(times), result


def hashed_pairs(item_lo, item_hi, query_lo, query_hi, *, cell_size, table_size=spatial_hash.DEFAULT_TABLE_SIZE,
                 item_group=None, query_group=None, rule="all"):
    """The box pairs as before issue 15: the sorted hash, binary searches per query cell."""
    grid = spatial_hash.SpatialHash.build(item_lo, item_hi, cell_size=cell_size, table_size=table_size,
                                          item_group=item_group)
    return grid.query(query_lo, query_hi, query_group=query_group, rule=rule)


class ConvertedPattern:
    """The Jacobian's matrices as before issue 15: each one its own csr_matrix((data, (rows, cols)))."""

    def __init__(self, nodes, weights, node_count):
        self.nodes, self.weights, self.node_count = nodes, weights, node_count

    def matrix(self, blocks):
        return penalty._stencil_matrix(self.nodes, self.weights, blocks, self.node_count)


def lever_times(contact, model, x, v, hits, repeat):
    """``{lever: (before, after)}`` [s], the variants alternated in one loop (best of ``repeat`` each)."""
    bodies = contact.bodies
    levers = {
        "dense grid, vertex-in-tet": (spatial_hash, "box_pairs", hashed_pairs,
                                      lambda: detect_collisions(bodies, x)),
        "dense grid, edge-surface": (penetration, "box_pairs", hashed_pairs,
                                     lambda: consistent_penetration_depths(bodies, x, hits)),
        "shared csr pattern": (penalty, "_StencilPattern", ConvertedPattern,
                               lambda: contact.jacobian(model, x, v, 0.0)),
        "dense grid, tet-tet": (spatial_hash, "box_pairs", hashed_pairs, lambda: crossing_tet_pairs(bodies, x)),
    }
    times = {}
    for name, (module, attribute, before, function) in levers.items():
        after = getattr(module, attribute)
        best = {"before": np.inf, "after": np.inf}
        for _ in range(repeat):
            for variant, value in (("before", before), ("after", after)):
                setattr(module, attribute, value)
                try:
                    start = time.perf_counter()
                    function()
                    best[variant] = min(best[variant], time.perf_counter() - start)
                finally:
                    setattr(module, attribute, after)
        times[name] = (best["before"], best["after"])
    return times


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1_000, 10_000, 50_000], help="total tets")
    parser.add_argument("--repeat", type=int, default=5, help="timed runs per size (the best is kept)")
    parser.add_argument("--levers", action="store_true",
                        help="also time issue 15's speed-ups against what they replaced")
    args = parser.parse_args(argv)
    lever_rows = []
    print(f"{'tets':>7} {'nodes':>7} {'contacts':>8} {'detect ms':>9} {'paper ms':>8} {'depth ms':>8} "
          f"{'force ms':>8} {'jacobian ms':>11} {'us/contact':>10} {'SpMV ms':>8} {'step/SpMV':>9} "
          f"{'pairs':>7} {'tet-tet ms':>10} {'tet-tet/detect':>14} {'edges ms':>8} {'edges/detect':>12}")
    rng = np.random.default_rng(0)
    for size in args.sizes:
        model, contact = contact_scene(size)
        bodies = contact.bodies  # the model's tet mesh split by node_body
        x = np.array(model.rest_positions)
        v = rng.normal(scale=0.1, size=x.shape)
        out = np.zeros_like(x)

        def force():
            contact._cache = None  # detect afresh, as at every new step or stage
            contact.accumulate(model, x, v, 0.0, out)
            return contact.contacts(x)

        found = force()  # warm caches (edges, faces, adjacency are built once per scene)
        detect, hits = best_time(lambda: detect_collisions(bodies, x), args.repeat)
        depth, _ = best_time(lambda: consistent_penetration_depths(bodies, x, hits), args.repeat)
        forces, _ = best_time(force, args.repeat)
        jacobian, _ = best_time(lambda: contact.jacobian(model, x, v, 0.0), args.repeat)
        tet_tet, pairs = best_time(lambda: crossing_tet_pairs(bodies, x), args.repeat)
        edges, _ = best_time(lambda: edge_crossing_contacts(bodies, x, crossing_tet_pairs(bodies, x, boundary=True),
                                                            colliding=hits), args.repeat)
        matrix, vector = stiffness_matrix(model), np.ones(3 * model.node_count)
        spmv, _ = best_time(lambda: matrix @ vector, 20 * args.repeat)
        nearest = min(PUBLISHED_DETECTION_MS, key=lambda t: abs(np.log(t / bodies.tet_count)))
        paper = PUBLISHED_DETECTION_MS[nearest] * bodies.tet_count / nearest  # linear in tets, as published
        step = forces + jacobian
        print(f"{bodies.tet_count:>7} {bodies.node_count:>7} {found.count:>8} {1e3 * detect:>9.2f} {paper:>8.1f} "
              f"{1e3 * depth:>8.2f} {1e3 * forces:>8.2f} {1e3 * jacobian:>11.2f} "
              f"{1e6 * step / max(found.count, 1):>10.1f} {1e3 * spmv:>8.3f} {step / spmv:>9.0f} "
              f"{pairs.count:>7} {1e3 * tet_tet:>10.2f} {tet_tet / detect:>14.1f} "
              f"{1e3 * edges:>8.2f} {edges / detect:>12.1f}")
        if args.levers:
            lever_rows += [(bodies.tet_count, name, before, after)
                           for name, (before, after) in lever_times(contact, model, x, v, hits, args.repeat).items()]
    print("force = detection + depths + penalty/damping/friction; step = force + jacobian")
    if lever_rows:
        print(f"\n{'tets':>7} {'lever':<26} {'before ms':>9} {'after ms':>8} {'after/before':>12}")
        for tets, name, before, after in lever_rows:
            print(f"{tets:>7} {name:<26} {1e3 * before:>9.2f} {1e3 * after:>8.2f} {after / before:>12.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
