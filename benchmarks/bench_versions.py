"""This checkout's implicit step against a released version, installed in a second venv, timed in one run.

For each size (structured beams of about 1k and 10k nodes, 1 m x 0.2 m x 0.2 m, pinned at x = 0,
under gravity, E = 1e7 Pa, nu = 0.45 as in the README, dt = 0.01 s) both versions take the same
steps in child processes launched alternately (baseline, ours, baseline, ours, ...), and the script
prints the median CPU seconds per step of each (the median over the steps of a child, then over the
children) and their ratio, the same in sparse mat-vecs of the step's system matrix timed in the same
child (robust to the machine's speed drifting between children), the mean CG iterations per step, the
first step's extra time over a step in mat-vecs (the AMG build and the step's set-up), and the memory the
stepping added per node (peak resident size after the steps less that before them, KiB) beside the whole
process's peak per node (libraries, mesh and model included: issue 15's "peak memory").
A contact scene (two cubes, the lower one pinned at its base, the upper one pressed onto it by a
strong gravity through the penalty contact force) reports the CG iterations per step, where the
contact stiffness is a non-spring Jacobian.

The baseline is exported from git (``git archive <ref>``) into ``.bench/<ref>/src`` and installed
into ``.bench/<ref>/venv`` the first time (from PyPI); later runs reuse them.

Run::

    python benchmarks/bench_versions.py                      # v0.1.0, 1k and 10k nodes
    python benchmarks/bench_versions.py --ref v0.1.0 --nodes 1000 10000 --steps 20 --rounds 3
    python benchmarks/bench_versions.py --nodes 200000 --steps 3 --rounds 1     # the memory at 200k nodes
    python benchmarks/bench_versions.py --kernels numpy numba   # with and without the fast extra's kernels

Every child holds numpy/scipy to one thread. This is a script, not a test.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
THREADS = {name: "1" for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}

# The child uses only what both versions offer (0.1 names; ours accepts them with deprecation warnings).
CHILD = textwrap.dedent('''
    import json, resource, sys, time, warnings
    warnings.simplefilter("ignore")
    import numpy as np
    from meshing import structured_box
    import volspring
    from volspring import Gravity, Material, Pins, Scene
    from volspring.integrators.implicit import ImplicitEuler
    Model = getattr(volspring, "Model", None) or volspring.SpringModel

    kind, cells, steps = sys.argv[1], tuple(int(c) for c in sys.argv[2].split(",")), int(sys.argv[3])
    material = Material(1e7, 0.45, 1000.0)
    if kind == "beam":
        mesh = structured_box(cells, (1.0, 0.2, 0.2))
        model = Model.from_mesh(mesh, material)
        scene = Scene(model, forces=[Gravity(model.masses)], pins=Pins(np.flatnonzero(mesh.points[:, 0] == 0)))
        state = scene.initial_state()
    else:
        from volspring.collision import ContactForce
        from volspring.collision.multibody import Body, assemble_bodies
        cube = structured_box(cells, (0.2, 0.2, 0.2))
        system = assemble_bodies([Body(cube, material), Body(cube, material, translation=(0.0, 0.0, 0.199))])
        model = system.model
        below = np.flatnonzero(system.model.rest_positions[:, 2] == 0)
        scene = Scene(model, forces=[Gravity(model.masses, (0, 0, -100.0)), ContactForce(system)], pins=Pins(below))
        state = scene.initial_state()
    try:  # the compiled kernels (volspring.kernels, later than 0.1): loaded or compiled here, not in the first step
        from volspring.kernels import compiled
    except ImportError:
        pass
    else:
        if compiled() is not None:
            springs = model.spring_elements
            springs.linearize(model.rest_positions, stiffness_scale=1.0).dfdx_times(model.rest_positions)
    integrator = ImplicitEuler()
    resident = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # [KiB] with the libraries and the model
    first = []
    for _ in range(3):
        start = time.process_time()
        state = integrator.step(scene, state, 0.01)
        first.append(time.process_time() - start)
    iterations, seconds = [], []
    for _ in range(steps):
        start = time.process_time()  # CPU time of this process: other jobs on the machine do not count
        state = integrator.step(scene, state, 0.01)
        seconds.append(time.process_time() - start)
        iterations.append(integrator.last_solve.iterations)
    seconds = float(np.median(seconds))
    # One sparse mat-vec of this step's system matrix, timed in the same process: the step in mat-vecs
    # does not move with the machine's speed, which varies by 10-20 % from run to run here.
    matrix = integrator.linear_system(scene, state, 0.01)[0]
    vector, matvecs = np.ones(matrix.shape[0]), []
    for _ in range(200):
        start = time.process_time()
        matrix @ vector
        matvecs.append(time.process_time() - start)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(json.dumps({"nodes": model.node_count, "seconds": seconds, "iterations": float(np.mean(iterations)),
                      "matvec": float(np.median(matvecs)), "first_extra": first[0] - seconds,
                      "kib_per_node": (peak - resident) / model.node_count, "peak_kib_per_node": peak / model.node_count}))
''')


#: Releases by their commit, for a clone that did not bring its tags along (``git clone`` of a bare copy, a
#: submission): ``v0.1.0`` is the commit the reliability issue tagged.
KNOWN_RELEASES = {"v0.1.0": "090814f"}


def resolved_ref(ref: str) -> str:
    """``ref`` if git knows it, else the commit of a known release of that name (:data:`KNOWN_RELEASES`)."""
    known = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--verify", "--quiet", f"{ref}^{{commit}}"],
                           capture_output=True, text=True)
    if known.returncode == 0:
        return ref
    if ref in KNOWN_RELEASES:
        print(f"git has no ref {ref} here (tags not cloned): using its commit {KNOWN_RELEASES[ref]}", file=sys.stderr)
        return KNOWN_RELEASES[ref]
    raise SystemExit(f"bench_versions: git knows no ref {ref!r}; give a tag, branch or commit with --ref")


def baseline_python(ref: str) -> Path:
    """The Python of a venv holding ``ref`` installed, made on first use."""
    folder = ROOT / ".bench" / ref
    python = folder / "venv" / "bin" / "python"
    if python.exists():
        return python
    source = folder / "src"
    source.mkdir(parents=True, exist_ok=True)
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", resolved_ref(ref)], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(source)], input=archive, check=True)
    subprocess.run([sys.executable, "-m", "venv", str(folder / "venv")], check=True)
    subprocess.run([str(python), "-m", "pip", "install", "-q", str(source)], check=True)
    return python


def run(python: Path, script: Path, kind: str, cells: str, steps: int, kernels: str = "auto") -> dict:
    environment = {**os.environ, **THREADS, "VOLSPRING_KERNELS": kernels}
    result = subprocess.run([str(python), str(script), kind, cells, str(steps)], capture_output=True, text=True,
                            env=environment, cwd=tempfile.gettempdir())
    if result.returncode:
        raise RuntimeError(f"{python} {kind} {cells} failed:\n{result.stderr[-2000:]}")
    return json.loads(result.stdout.strip().splitlines()[-1])


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ref", default="v0.1.0", help="git ref of the baseline (default v0.1.0)")
    parser.add_argument("--nodes", type=int, nargs="+", default=[1000, 10000], help="beam sizes [nodes]")
    parser.add_argument("--steps", type=int, default=20, help="timed steps per child")
    parser.add_argument("--rounds", type=int, default=3, help="alternating child launches per version")
    parser.add_argument("--contact-cells", default="5,5,5", help="cells of each contact cube")
    parser.add_argument("--kernels", nargs="+", default=["auto"], choices=["auto", "numba", "numpy"],
                        help="what our children's hot loops run (volspring.kernels), one row each: "
                             "--kernels numpy numba compares the two in one run (default auto)")
    args = parser.parse_args(argv)

    ours, baseline = Path(sys.executable), baseline_python(args.ref)
    with tempfile.TemporaryDirectory() as folder:
        script = Path(folder) / "child.py"
        script.write_text(CHILD)
        cases = [("beam", _beam_cells(n)) for n in args.nodes] + [("contact", args.contact_cells)]
        print(f"implicit Euler, dt = 0.01 s, median of {args.rounds} alternating runs of {args.steps} steps")
        print(f"{'scene':>8} {'nodes':>7} {'kernels':>7} {args.ref + ' [ms]':>14} {'ours [ms]':>10} {'ratio':>6}"
              f" {args.ref + ' [mv]':>14} {'ours [mv]':>10} {'ratio':>6} {'CG ' + args.ref:>10} {'CG ours':>8}"
              f" {'build ' + args.ref:>13} {'build ours':>11} {'KiB/node ' + args.ref:>16} {'ours':>6}"
              f" {'peak ' + args.ref:>12} {'ours':>6}")
        for kind, cells in cases:
            measured: dict[str, list[dict]] = {"base": [], **{choice: [] for choice in args.kernels}}
            for _ in range(args.rounds):  # alternately: the machine's drift hits every version alike
                measured["base"].append(run(baseline, script, kind, cells, args.steps))
                for choice in args.kernels:
                    measured[choice].append(run(ours, script, kind, cells, args.steps, choice))
            seconds = {name: statistics.median(r["seconds"] for r in runs) for name, runs in measured.items()}
            in_matvecs = {name: statistics.median(r["seconds"] / r["matvec"] for r in runs)
                          for name, runs in measured.items()}
            build = {name: statistics.median(r["first_extra"] / r["matvec"] for r in runs)
                     for name, runs in measured.items()}
            memory = {name: statistics.median(r["kib_per_node"] for r in runs) for name, runs in measured.items()}
            peak = {name: statistics.median(r["peak_kib_per_node"] for r in runs) for name, runs in measured.items()}
            for choice in args.kernels:
                print(f"{kind:>8} {measured[choice][0]['nodes']:>7} {choice:>7} {1e3 * seconds['base']:>14.2f} "
                      f"{1e3 * seconds[choice]:>10.2f} {seconds[choice] / seconds['base']:>6.2f} "
                      f"{in_matvecs['base']:>14.1f} {in_matvecs[choice]:>10.1f} "
                      f"{in_matvecs[choice] / in_matvecs['base']:>6.2f} "
                      f"{measured['base'][0]['iterations']:>10.1f} {measured[choice][0]['iterations']:>8.1f}"
                      f" {build['base']:>10.0f} mv {build[choice]:>8.0f} mv {memory['base']:>16.1f}"
                      f" {memory[choice]:>6.1f} {peak['base']:>12.1f} {peak[choice]:>6.1f}")


def _beam_cells(nodes: int) -> str:
    """Cells (5 k, k, k) of a 1 x 0.2 x 0.2 beam with about ``nodes`` nodes: (5k+1)(k+1)^2."""
    k = max(1, round((nodes / 5) ** (1 / 3)))
    return f"{5 * k},{k},{k}"


if __name__ == "__main__":
    main()
