"""benchmarks/bench_pybullet.py at a tiny size: PyBullet reads our VTK file, the stiffness it is given, its stable
sub-steps (and a negative control beyond them), both engines' answers, and the message without pybullet."""

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from volspring.stability import omega_max_estimate

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_pybullet.py"
HAS_PYBULLET = importlib.util.find_spec("pybullet") is not None


def needs_pybullet(test):
    """Marked ``bench`` (.ci/run runs them with the extra installed), skipped without pybullet."""
    skip = pytest.mark.skipif(not HAS_PYBULLET, reason="needs the bench extra: pip install -e '.[bench]'")
    return pytest.mark.bench(skip(test))


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("bench_pybullet", BENCH)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    yield module
    sys.modules.pop(spec.name, None)


def test_stiffness_is_van_gelder_spread_over_the_edges(bench):
    beam = bench.build_beam(1)
    model = beam.scene.model
    E, volume = bench.MATERIAL[0], beam.mesh.tet_volumes.sum()
    # k sum l^2 = 6 E V exactly (each tet gives E V_t to six edges); the tolerance is sums' round-off.
    k = bench.pybullet_stiffness(model)
    assert k * (model.spring_elements.rest_lengths**2).sum() == pytest.approx(6 * E * volume, rel=1e-12)


@needs_pybullet
def test_pybullet_reads_the_nodes_of_our_file_in_order(bench):
    beam = bench.build_beam(1)
    engine = bench.PyBulletBeam(beam, substeps=1)
    try:
        # The file writes 17 significant digits and PyBullet is built in double precision: the round trip is exact.
        np.testing.assert_array_equal(engine.positions(), beam.mesh.points)
    finally:
        engine.close()


@needs_pybullet
def test_stable_substeps_run_and_fewer_diverge(bench):
    beam = bench.build_beam(2)
    substeps = bench.stable_substeps(beam)
    critical_count = bench.DT * omega_max_estimate(bench.pybullet_network(beam)) / 2.0  # symplectic Euler's limit
    assert substeps == math.ceil(critical_count / bench.SAFETY)
    stable = bench.run(bench.PyBulletBeam(beam, substeps=substeps), beam, steps=40, warmup=1)
    assert np.abs(stable.tip).max() < 0.1  # [m]: bounded (the swing is 0 to 2 x 20 mm)
    # Negative control: 20% beyond the critical step the explicit spring forces blow up within 40 steps
    # (measured: 15 sub-steps diverge, 16 = ceil(15.06) do not).
    beyond = bench.run(bench.PyBulletBeam(beam, substeps=math.floor(0.8 * critical_count)), beam, steps=40, warmup=1)
    assert np.abs(beyond.tip).max() > 1.0


@needs_pybullet
def test_both_answers_match_their_static_equilibria(bench):
    result = bench.compare(2, seconds=0.8, warmup=2)
    runs, statics = result["runs"], result["statics"]
    assert set(runs) == {"volspring", "pybullet, 1 sub-step", f"pybullet, {result['substeps']} sub-steps"}
    # The middle of the tip's late range is the equilibrium up to the swing's asymmetry: measured 0.3% (volspring,
    # damped by implicit Euler) and 0.1% (PyBullet, undamped); 3% leaves room and still catches a wrong mass or k.
    assert runs["volspring"].answer()[0] == pytest.approx(statics["volspring"], rel=0.03)
    assert runs[f"pybullet, {result['substeps']} sub-steps"].answer()[0] == pytest.approx(statics["pybullet"],
                                                                                          rel=0.03)
    assert abs(runs["pybullet, 1 sub-step"].answer()[0]) > 1.0  # [m]: dt = 0.01 s as is diverges
    # Both spring networks are stiffer than FEM on this coarse mesh (volspring -36%, PyBullet -44% measured).
    assert 0.4 < statics["pybullet"] / result["fem"] < statics["volspring"] / result["fem"] < 0.8
    assert all(run.seconds_per_step > 0 for run in runs.values())


def test_main_without_pybullet_names_the_extra(bench, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "pybullet", None)  # import pybullet now raises ImportError
    assert bench.main(["--cells", "1"]) == 2
    assert "pip install -e '.[bench]'" in capsys.readouterr().err
