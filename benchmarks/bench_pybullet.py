"""volspring's implicit step against PyBullet's mass-spring soft body on the same mesh: speed and answer, one run.

The README beam (1 m x 0.2 m x 0.2 m, structured cells 5k x k x k, pinned at x = 0, gravity 9.81 m/s^2; E = 1e7 Pa,
nu = 0.45, density 1000 kg/m^3) is stepped from rest for ``--seconds`` of simulated time at the README's
dt = 0.01 s by volspring (springs, ``ImplicitEuler()`` defaults) and by PyBullet (``DIRECT`` mode, deformable world,
``loadSoftBody(useMassSpring=1)`` of the same tets written as a legacy VTK file, the x = 0 nodes anchored to the
world). Every ``stepSimulation`` advances the same 0.01 s. The script prints the median CPU seconds per 0.01 s step
of each after ``--warmup`` steps, their ratio, the time per internal sub-step, and the answer of each: the tip
deflection (mean z displacement of the x = 1 face) against the linear P2 FEM reference on the same mesh
(``validation.solve_fem_static``).

What PyBullet is given, and why:

- Stiffness. PyBullet takes one spring constant for the whole body (``springElasticStiffness`` [N/m], every tet
  edge alike); volspring's van Gelder rule gives each edge its own, k_e = sum over the tets t at e of E V_t / l_e^2
  (``volspring/elements/spring_rules.py``). The same rule with the body's volume spread over all edges gives one
  constant: k = sum_e k_e l_e^2 / sum_e l_e^2 = 6 E V / sum_e l_e^2 (each tet puts E V_t into six edges), the
  single k whose network stores the same energy as volspring's under any uniform dilation. That is what is passed.
- Mass. ``mass`` = the body's mass (density x volume); PyBullet spreads it equally over the nodes (volspring lumps
  each tet's mass onto its corners). The anchors make the x = 0 nodes immovable (PyBullet sets their mass to 0).
- No damping (``springDampingStiffness=0``, as volspring's default springs), no bending springs, no collisions
  that could touch the beam (no other body), sleeping disabled.

What PyBullet does with it. Its deformable world integrates the elastic forces explicitly: with the world's default
(``m_implicit = false``, which pybullet offers no way to change) only damping enters the solve, the spring force is
evaluated at the predicted positions and the velocity updated from it, which is stable only for
h omega_max < 2, as symplectic Euler (measured on this beam at 99 nodes: 15 sub-steps per 0.01 s diverge, 16 do
not, and 2 / omega_max asks for 15.06). At dt = 0.01 s one ``stepSimulation`` is 35 (936 nodes) to 61 (4,600
nodes) times beyond that, so PyBullet is run twice:

- ``1 sub-step``: dt = 0.01 s as is, the comparison at equal dt the issue asked for. It diverges within the first
  steps (the tip ends metres away; PyBullet caps each node's speed at the body's bounding-box size per step, so
  nothing overflows), so only ``DIVERGED_STEPS`` steps after the warm-up are run. Its time is that of a diverged
  body, 15 to 18 times that of a healthy sub-step (the ms/sub-step column).
- ``N sub-steps``: ``setPhysicsEngineParameter(numSubSteps=N)``, N = ceil(dt / (0.9 x 2 / omega_max)), with
  omega_max of PyBullet's own network (equal masses, one k, the anchors) from
  :func:`volspring.stability.omega_max_estimate`: the cheapest PyBullet run that gives an answer at this frame rate.

Answers. Neither model is damped; volspring's implicit Euler damps numerically (the first bending mode, period
0.3 s, loses about 2% of its amplitude per step), PyBullet's stable run hardly at all, so after a start from rest
the tip still swings about its equilibrium. Each answer is the middle of the tip's range over the second half of the
run, printed with the half-width of that range; at the default 2 s both lie within 1% of their model's equilibrium
(shorter runs leave volspring's decaying swing a bias of a few per cent). Beside them, the static equilibrium of each
model (:func:`volspring.statics.solve_static` on volspring's springs and on PyBullet's network rebuilt as a volspring
model) separates the model's error from the run's.

Size limit. PyBullet 3.2.7 segfaults in ``loadSoftBody`` once the body it sends back to the client outgrows its
8 MiB buffer (gdb: ``btSoftBody::serialize`` from ``PhysicsServerCommandProcessor::createBodyInfoStream``): on this
beam k = 9 (4,600 nodes, 21,870 tets) loads and k = 10 (6,171 nodes, 30,000 tets) crashes the process.

Run (numpy/scipy threads are held to one before numpy is imported; PyBullet's DIRECT mode uses one thread)::

    pip install -e '.[bench]'                          # pybullet
    python benchmarks/bench_pybullet.py                # k = 5 and 9: 936 and 4,600 nodes, 2 s each (about 3 min)
    python benchmarks/bench_pybullet.py --cells 5 --seconds 1 --warmup 3

Without pybullet it says so and exits with status 2. This is a script, not a test.
"""

import os

if __name__ == "__main__":  # before numpy is imported; not when a test imports these functions
    for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS"):
        os.environ[_variable] = "1"

import argparse  # noqa: E402
import contextlib  # noqa: E402
import math  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

DT = 0.01  # [s], the README's step
SIZE = (1.0, 0.2, 0.2)  # [m]
MATERIAL = (1e7, 0.45, 1000.0)  # E [Pa], nu, density [kg/m^3]: the README's rubber
SAFETY = 0.9  # PyBullet's sub-step is this fraction of its critical step 2 / omega_max
DIVERGED_STEPS = 20  # steps timed of the run at dt as is: it has diverged long before
INSTALL = "pip install -e '.[bench]'"


def import_pybullet():
    """The pybullet module; an ImportError naming the extra that installs it when it is missing."""
    try:
        import pybullet
    except ImportError as error:
        raise ImportError(f"pybullet is not installed ({error}); install the bench extra: {INSTALL}") from error
    return pybullet


@contextlib.contextmanager
def quiet_stdout():
    """Send file descriptor 1 to /dev/null: PyBullet's C code prints the node, link and tet counts of every load."""
    import ctypes

    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
        yield
    finally:
        ctypes.CDLL(None).fflush(None)  # what C buffered goes to /dev/null, not later to the terminal
        os.dup2(saved, 1)
        os.close(saved)


@dataclass(frozen=True)
class Beam:
    """The scene both engines step: mesh, volspring scene, pinned and tip nodes."""

    mesh: object  # meshing.TetMesh
    scene: object  # volspring.Scene
    pinned: np.ndarray  # (p,) int, the x = 0 nodes
    tip: np.ndarray  # (t,) int, the x = 1 nodes


def build_beam(k: int) -> Beam:
    """The README beam of 5k x k x k cells with volspring's springs, pinned at x = 0, under gravity."""
    from meshing import structured_box
    from volspring import Gravity, Material, Model, Pins, Scene

    mesh = structured_box((5 * k, k, k), SIZE)
    pinned = np.flatnonzero(mesh.points[:, 0] == 0.0)
    model = Model.from_mesh(mesh, Material(*MATERIAL))
    scene = Scene(model, forces=[Gravity()], pins=Pins(pinned))
    return Beam(mesh, scene, pinned, np.flatnonzero(mesh.points[:, 0] == SIZE[0]))


def pybullet_stiffness(model) -> float:
    """One spring constant [N/m] for every edge: sum k_e l_e^2 / sum l_e^2 of volspring's springs (module docstring)."""
    springs = model.spring_elements
    return float((springs.stiffness * springs.rest_lengths**2).sum() / (springs.rest_lengths**2).sum())


def pybullet_network(beam: Beam):
    """PyBullet's body as a volspring scene: the same springs with one k, the mass spread equally, the same pins."""
    from volspring import Gravity, Model, Pins, Scene

    model = beam.scene.model
    masses = np.full(model.node_count, model.masses.sum() / model.node_count)
    network = Model.from_arrays(model.rest_positions, masses, model.spring_elements.pairs,
                                stiffness=pybullet_stiffness(model))
    return Scene(network, forces=[Gravity()], pins=Pins(beam.pinned))


def stable_substeps(beam: Beam, dt: float = DT) -> int:
    """Sub-steps per ``dt`` that keep PyBullet's explicit elastic forces stable, with the margin ``SAFETY``."""
    from volspring.stability import critical_step, omega_max_estimate

    critical = critical_step("symplectic_euler", omega_max_estimate(pybullet_network(beam)))
    return max(1, math.ceil(dt / (SAFETY * critical)))


def write_vtk_for_pybullet(mesh, path: Path) -> None:
    """The tets as the legacy VTK file PyBullet's loader (``btSoftBodyHelpers::CreateFromVtkFile``) reads.

    That loader reads line by line: after ``POINTS n ...`` exactly one ``x y z`` per line, after ``CELLS m ...``
    one ``4 a b c d`` per line, and it stops at ``CELL_TYPES``. With all points on one line (as meshio writes
    them) every node but the first is left unset, the load succeeds and ``stepSimulation`` segfaults; meshio's
    files as a whole are refused at load ("Only Tetrahedra are supported"): its cells are not one per line.
    """
    points, tets = np.asarray(mesh.points, float), np.asarray(mesh.tets)
    lines = ["# vtk DataFile Version 2.0", "volspring beam", "ASCII", "DATASET UNSTRUCTURED_GRID",
             f"POINTS {len(points)} double"]
    lines += [f"{x:.17g} {y:.17g} {z:.17g}" for x, y, z in points.tolist()]
    lines.append(f"CELLS {len(tets)} {5 * len(tets)}")
    lines += [f"4 {a} {b} {c} {d}" for a, b, c, d in tets.tolist()]
    lines.append(f"CELL_TYPES {len(tets)}")
    lines += ["10"] * len(tets)
    path.write_text("\n".join(lines) + "\n")


class PyBulletBeam:
    """The beam as a PyBullet soft body in a DIRECT client of its own; ``close()`` disconnects it."""

    def __init__(self, beam: Beam, *, substeps: int, dt: float = DT):
        pybullet = import_pybullet()
        self.pybullet, self.beam = pybullet, beam
        model = beam.scene.model
        self.client = pybullet.connect(pybullet.DIRECT)
        options = {"physicsClientId": self.client}
        pybullet.resetSimulation(pybullet.RESET_USE_DEFORMABLE_WORLD, **options)
        pybullet.setGravity(0.0, 0.0, -9.81, **options)  # before the load: the body's gravity force copies it
        pybullet.setTimeStep(dt, **options)
        pybullet.setPhysicsEngineParameter(numSubSteps=substeps, **options)
        with tempfile.TemporaryDirectory() as folder, quiet_stdout():
            path = Path(folder) / "beam.vtk"
            write_vtk_for_pybullet(beam.mesh, path)
            self.body = pybullet.loadSoftBody(
                str(path), mass=float(model.masses.sum()), useNeoHookean=0, useMassSpring=1, useBendingSprings=0,
                springElasticStiffness=pybullet_stiffness(model), springDampingStiffness=0.0, useSelfCollision=0,
                useFaceContact=0, frictionCoeff=0.0, collisionMargin=0.001, **options)
        for node in beam.pinned.tolist():
            pybullet.createSoftBodyAnchor(self.body, node, -1, -1, **options)
        pybullet.changeDynamics(self.body, -1, activationState=pybullet.ACTIVATION_STATE_DISABLE_SLEEPING, **options)

    def step(self) -> None:
        self.pybullet.stepSimulation(physicsClientId=self.client)

    def positions(self) -> np.ndarray:
        """(n, 3) float -- node positions [m], in the mesh's node order."""
        count, points = self.pybullet.getMeshData(self.body, -1, flags=self.pybullet.MESH_DATA_SIMULATION_MESH,
                                                  physicsClientId=self.client)
        return np.asarray(points, float).reshape(count, 3)

    def close(self) -> None:
        self.pybullet.disconnect(self.client)


class VolspringBeam:
    """The beam stepped by volspring's implicit Euler (defaults), with the same step/positions interface."""

    def __init__(self, beam: Beam, *, dt: float = DT):
        from volspring.integrators.implicit import ImplicitEuler

        self.scene, self.dt = beam.scene, dt
        self.integrator = ImplicitEuler()
        self.state = beam.scene.initial_state()

    def step(self) -> None:
        self.state = self.integrator.step(self.scene, self.state, self.dt)

    def positions(self) -> np.ndarray:
        return self.state.x

    def close(self) -> None:
        pass


@dataclass(frozen=True)
class Run:
    """What one engine did: median CPU seconds per step after the warm-up, and the tip's z displacement per step."""

    seconds_per_step: float
    tip: np.ndarray  # (steps,) float [m]

    def answer(self) -> tuple[float, float]:
        """Middle and half-width of the tip's range over the second half of the run [m]."""
        late = self.tip[len(self.tip) // 2:]
        return (late.max() + late.min()) / 2, (late.max() - late.min()) / 2


def run(engine, beam: Beam, *, steps: int, warmup: int) -> Run:
    """Step ``engine`` ``steps`` times from rest, timing each step (CPU time) and recording the tip deflection."""
    rest_z = beam.mesh.points[beam.tip, 2].mean()
    seconds, tip = [], []
    try:
        for _ in range(steps):
            start = time.process_time()
            engine.step()
            seconds.append(time.process_time() - start)
            tip.append(engine.positions()[beam.tip, 2].mean() - rest_z)
    finally:
        engine.close()
    return Run(statistics.median(seconds[warmup:]), np.array(tip))


def fem_tip(beam: Beam) -> float:
    """Tip deflection [m] of linear P2 FEM on the same mesh, clamped at x = 0, under the same gravity."""
    from validation import Box, solve_fem_static

    solution = solve_fem_static(beam.mesh, MATERIAL, clamp=Box.plane("x", 0.0), gravity=(0.0, 0.0, -9.81))
    return float(solution.displacement[beam.tip, 2].mean())


def static_tip(scene, beam: Beam) -> float:
    """Tip deflection [m] of ``scene`` at static equilibrium (volspring's Newton solver)."""
    from volspring.statics import solve_static

    x = solve_static(scene).x
    return float(x[beam.tip, 2].mean() - beam.mesh.points[beam.tip, 2].mean())


def compare(k: int, *, seconds: float, warmup: int) -> dict:
    """Time and answer of each engine on the 5k x k x k beam (the rows the script prints)."""
    import_pybullet()
    beam = build_beam(k)
    steps = max(warmup + 2, round(seconds / DT))
    substeps = stable_substeps(beam)
    runs = {"volspring": run(VolspringBeam(beam), beam, steps=steps, warmup=warmup),
            "pybullet, 1 sub-step": run(PyBulletBeam(beam, substeps=1), beam,
                                        steps=min(steps, warmup + DIVERGED_STEPS), warmup=warmup),
            f"pybullet, {substeps} sub-steps": run(PyBulletBeam(beam, substeps=substeps), beam, steps=steps,
                                                    warmup=warmup)}
    statics = {"volspring": static_tip(beam.scene, beam), "pybullet": static_tip(pybullet_network(beam), beam)}
    return {"beam": beam, "steps": steps, "substeps": substeps, "runs": runs, "fem": fem_tip(beam),
            "statics": statics, "stiffness": pybullet_stiffness(beam.scene.model)}


def report(k: int, result: dict) -> None:
    beam, runs, fem, statics = result["beam"], result["runs"], result["fem"], result["statics"]
    model, stiffness = beam.scene.model, beam.scene.model.spring_elements.stiffness
    base = runs["volspring"].seconds_per_step
    print(f"\n{model.node_count} nodes, {beam.mesh.tet_count} tets (cells {5 * k} x {k} x {k}); dt = {DT} s, "
          f"{result['steps']} steps from rest; PyBullet k = {result['stiffness']:.4g} N/m "
          f"(volspring's k_e {stiffness.min():.3g} to {stiffness.max():.3g})")
    print(f"  FEM P2 tip deflection {1e3 * fem:.2f} mm; static equilibrium of volspring's springs "
          f"{1e3 * statics['volspring']:.2f} mm ({100 * (statics['volspring'] / fem - 1):+.1f}%), "
          f"of PyBullet's network {1e3 * statics['pybullet']:.2f} mm ({100 * (statics['pybullet'] / fem - 1):+.1f}%)")
    print(f"  {'engine':24s} {'ms/step':>9s} {'x volspring':>12s} {'ms/sub-step':>12s}   tip deflection, second half "
          "of the run")
    for (name, engine_run), substeps in zip(runs.items(), (1, 1, result["substeps"])):
        middle, swing = engine_run.answer()
        answer = (f"{1e3 * middle:9.2f} mm +- {1e3 * swing:.2f} ({100 * (middle / fem - 1):+.1f}% of FEM)"
                  if np.isfinite(middle) and abs(middle) < 10 * abs(fem) else f"diverged: {middle:.3g} m")
        seconds = engine_run.seconds_per_step
        print(f"  {name:24s} {1e3 * seconds:9.2f} {seconds / base:12.1f} {1e3 * seconds / substeps:12.2f}   {answer}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, nargs="+", default=[5, 9],
                        help="k of the 5k x k x k cells (default 5 9: 936 and 4,600 nodes; PyBullet "
                        "crashes from k = 10)")
    parser.add_argument("--seconds", type=float, default=2.0, help="simulated time per run [s] (default 2)")
    parser.add_argument("--warmup", type=int, default=3, help="steps not timed at the start of each run")
    args = parser.parse_args(argv)
    try:
        import_pybullet()
    except ImportError as error:
        print(f"bench_pybullet: {error}", file=sys.stderr)
        return 2
    from importlib.metadata import version

    print(f"PyBullet {version('pybullet')}, DIRECT mode; CPU time per step, one thread")
    for k in args.cells:
        report(k, compare(k, seconds=args.seconds, warmup=args.warmup))
    return 0


if __name__ == "__main__":
    sys.exit(main())
