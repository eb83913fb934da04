"""benchmarks/bench_ladder.py at a tiny size: the rungs stepped side by side in the order its docstring states, and a
table whose ratio is the median of the rounds' ratios printed beside it. No figure is timed against a bound."""

import importlib.util
import sys
from pathlib import Path

import pytest

from volspring.integrators.implicit import ImplicitEuler
from volspring.ladder import MODELS

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_ladder.py"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("bench_ladder", BENCH)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    yield module
    sys.modules.pop(spec.name, None)


def test_the_runs_step_in_turn_forward_then_backward(bench, monkeypatch):
    scenes = {rung: bench.build(rung, (2, 1, 1)) for rung in ("springs", "smoothed")}
    names = {id(scene): rung for rung, scene in scenes.items()}
    order = []
    step = ImplicitEuler.step

    def logged(self, scene, state, dt, cache=None):
        order.append(names[id(scene)])
        return step(self, scene, state, dt, cache=cache)

    monkeypatch.setattr(ImplicitEuler, "step", logged)
    result = bench.time_side_by_side(scenes, 3, 0.01)
    # Two warm-up steps of each run, then step k of every run: in order for even k, reversed for odd k.
    assert order == ["springs"] * 2 + ["smoothed"] * 2 + ["springs", "smoothed", "smoothed", "springs",
                                                          "springs", "smoothed"]
    assert set(result) == {(None, "springs"), (None, "smoothed")}
    assert all(seconds > 0.0 and iterations >= 1.0 for seconds, iterations in result.values())


def test_the_ratio_is_the_median_of_the_rounds_printed_beside_it(bench, monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["bench_ladder.py", "--cells", "2", "1", "1", "--steps", "2", "--rounds", "3",
                                      "--kernels", "numpy"])
    bench.main()
    rows = {fields[0]: fields for fields in map(str.split, capsys.readouterr().out.splitlines())
            if fields and fields[0] in MODELS}
    assert set(rows) == set(MODELS)
    for rung, fields in rows.items():
        ratio, rounds = fields[2], fields[-3:]
        # Three rounds: the median is the middle round's ratio itself, printed with the same two decimals.
        assert ratio == sorted(rounds, key=float)[1], (rung, fields)
    assert rows["springs"][-3:] == ["1.00"] * 3
