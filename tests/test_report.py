"""volspring-validate end to end: the three outputs, their numbers against a direct computation, bad input."""

import json

import numpy as np
import pytest

from validation.cli import main
from validation.compare import tip_deflection
from validation.cases import cantilever_gravity
from validation.fem import solve_fem_static
from validation.springs import spring_model, spring_static
from validation.springs import VALIDATED_MODELS
from meshing import TetMesh


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    """One ``--quick`` run from an empty cache, as from a fresh clone (about 40 s on 2 cores)."""
    out = tmp_path_factory.mktemp("report")
    cache = tmp_path_factory.mktemp("cache")
    status = main(["--quick", "--out", str(out), "--cache", str(cache), "--no-progress"])
    return status, out


def test_quick_writes_the_three_outputs(quick_run):
    status, out = quick_run
    assert status == 0
    page = (out / "report.html").read_text()
    assert page.count("data:image/png;base64,") >= 5  # profiles, refinement, volume, speed, Cauchy
    assert "<img" in page and 'src="http' not in page and "<script" not in page  # self-contained
    results = json.loads((out / "results.json").read_text())
    vtu = sorted(path.name for path in (out / "vtu").glob("*.vtu"))
    assert "cantilever_gravity.vtu" in vtu and "cantilever_gravity_side_by_side.vtu" in vtu
    assert results["files"]["cantilever_gravity"]["models"][0] == "fem_P2"
    for name in ("numpy", "scipy", "scikit-fem", "pyamg", "volspring"):
        assert results["versions"][name]
    # The ladder: every rung on every built-in case (the held-out shapes are in the full run only), first on the page.
    rows = results["ladder"]["rows"]
    assert {(row["case"], row["rung"]) for row in rows} == {
        (case, rung) for case in ("cantilever_gravity", "cantilever_end_load", "hanging_bar", "uniaxial_compression",
                                  "cantilever_modes") for rung in VALIDATED_MODELS}
    assert page.index("<h2") == page.index("<h2 id='ladder'>") < page.index("<table")


def test_vtu_holds_fem_and_spring_shapes(quick_run):
    import meshio

    _, out = quick_run
    data = meshio.read(out / "vtu" / "cantilever_gravity.vtu")
    assert {"displacement_fem_P2", "displacement_springs_van_gelder", "error_springs_lloyd"} <= set(data.point_data)
    assert {"displacement_model_smoothed", "displacement_model_springs+volume"} <= set(data.point_data)
    side = TetMesh.read(out / "vtu" / "cantilever_gravity_side_by_side.vtu")
    # P2, P1, three spring rules, the two upper rungs and the lattice side by side (the springs rung is
    # springs_van_gelder).
    assert side.node_count == 8 * len(data.points)


def test_results_agree_with_a_direct_computation(quick_run):
    _, out = quick_run
    results = json.loads((out / "results.json").read_text())
    case = cantilever_gravity(per_height=1)  # the quick resolution
    reported = results["cases"]["cantilever_gravity"]
    assert reported["mesh"]["node_count"] == case.mesh.node_count
    fem = solve_fem_static(case.mesh, case.material_tuple, element="P2", **case.fem_arguments())
    fem_tip = tip_deflection(case, fem.displacement)
    springs_tip = tip_deflection(case, spring_static(case, spring_model(case.mesh, case.material, "lloyd")).displacement)
    # Same inputs, same solvers: agreement to the solvers' tolerances (LU; Newton to 1e-7 of the load).
    assert reported["fem"]["P2"]["tip_deflection_m"] == pytest.approx(fem_tip, rel=1e-9)
    assert reported["springs"]["lloyd"]["tip_deflection_m"] == pytest.approx(springs_tip, rel=1e-6)
    assert reported["springs"]["lloyd"]["tip_deflection_error"] == pytest.approx(
        (springs_tip - fem_tip) / fem_tip, rel=1e-6)
    assert results["headline"]["lloyd"]["cantilever_gravity_tip_deflection_error"] == pytest.approx(
        (springs_tip - fem_tip) / fem_tip, rel=1e-6)
    # The springs are stiffer than the continuum on this coarse mesh (REFERENCE.md: 0.39-0.50 of it).
    assert springs_tip < fem_tip


def test_cauchy_numbers_in_the_results(quick_run):
    _, out = quick_run
    measurements = json.loads((out / "results.json").read_text())["studies"]["cauchy"]["measurements"]
    for rule in ("van_gelder", "lloyd", "uniform"):
        nus = {m["nu_asked"]: m["nu_effective"] for m in measurements if m["rule"] == rule
               and m["pattern"] == "mirrored"}
        assert nus[0.3] == pytest.approx(nus[0.45], abs=1e-12)  # one nu whatever is asked
        assert abs(nus[0.45] - 0.45) > 0.15


def test_speed_table_has_stable_and_unstable_runs(quick_run):
    _, out = quick_run
    runs = json.loads((out / "results.json").read_text())["studies"]["speed"]["runs"]
    assert any(run["stable"] for run in runs) and any(not run["stable"] for run in runs)
    assert all(run["stable"] for run in runs if run["integrator"] == "implicit_euler")  # unconditionally stable
    assert not any(run["stable"] for run in runs if run["integrator"] == "explicit_euler")
    assert any(run.get("pareto") for run in runs)


def test_log_axes_label_major_ticks_only():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    from validation.report.figures import log_ticks

    figure, axes = plt.subplots()
    axes.loglog([0.2, 0.9], [1e-6, 1e-2])  # x within one decade (the crowded case), y over four
    log_ticks(axes)
    for axis, limits in ((axes.xaxis, axes.get_xlim()), (axes.yaxis, axes.get_ylim())):
        assert isinstance(axis.get_minor_formatter(), NullFormatter)
        shown = [v for v in axis.get_major_locator()() if limits[0] <= v <= limits[1]]
        assert len(shown) >= 2  # still labelled: an axis inside one decade gets majors at 1, 2, 5 x 10^k
    plt.close(figure)


@pytest.mark.slow
def test_full_run_writes_the_three_outputs(tmp_path):
    """The full run (no --quick), from an empty cache: about 90 s on 2 cores."""
    out = tmp_path / "full"
    status = main(["--out", str(out), "--cache", str(tmp_path / "cache"), "--no-progress"])
    assert status == 0
    results = json.loads((out / "results.json").read_text())
    assert results["quick"] is False
    assert (out / "report.html").read_text().count("data:image/png;base64,") >= 5
    assert (out / "vtu" / "cantilever_gravity.vtu").is_file()
    assert results["studies"]["refinement"]["levels"] == [1, 2, 3, 4]
    runs = results["studies"]["speed"]["runs"]
    for name in {run["integrator"] for run in runs}:
        mine = [run for run in runs if run["integrator"] == name]
        assert len(mine) >= 3
    implicit = [run["step_factor"] for run in runs if run["integrator"] == "implicit_euler"]
    assert min(implicit) == 1.0 and max(implicit) == 1000.0
    for name in ("symplectic_euler", "rk4", "verlet", "time_corrected_verlet"):  # stable to unstable
        assert {run["stable"] for run in runs if run["integrator"] == name} == {True, False}


@pytest.fixture
def beam_file(tmp_path):
    from meshing import structured_box

    path = tmp_path / "beam.vtu"
    structured_box((4, 1, 1), (1.0, 0.25, 0.25)).write(path)
    return path


@pytest.mark.parametrize("arguments, expected", [
    (["--mesh", "{mesh}", "--clamp", "xmin", "--nu", "0.5"], "--nu 0.5 is not < 0.5"),
    (["--mesh", "{mesh}"], "needs --clamp"),
    (["--mesh", "{mesh}", "--clamp", "x<-1"], "contains no mesh node"),
    (["--mesh", "{mesh}", "--clamp", "box:-1,-1,-1,0,0,0"], "singular"),   # one node: rotations free
    (["--mesh", "{mesh}", "--clamp", "left"], "is not one of"),
    (["no_such_case"], "unknown case"),
    (["--mesh", "{missing}", "--clamp", "xmin"], "no mesh file"),
])
def test_bad_input_gives_one_line_errors(arguments, expected, beam_file, tmp_path, capsys):
    argv = [a.format(mesh=beam_file, missing=tmp_path / "missing.vtu") for a in arguments]
    status = main(argv + ["--out", str(tmp_path / "out"), "--no-progress"])
    error = capsys.readouterr().err.strip()
    assert status == 2
    assert error.startswith("volspring-validate: error: ") and "\n" not in error
    assert expected in error
    assert not (tmp_path / "out" / "results.json").exists()


def test_own_mesh_run(beam_file, tmp_path):
    out = tmp_path / "own"
    status = main(["--mesh", str(beam_file), "--clamp", "xmin", "--E", "1e8", "--out", str(out),
                   "--cache", str(tmp_path / "cache"), "--no-progress"])
    assert status == 0
    results = json.loads((out / "results.json").read_text())
    own = results["cases"]["own_mesh"]
    assert set(own["springs"]) == {"van_gelder", "lloyd", "uniform"}
    assert np.isfinite(own["springs"]["van_gelder"]["tip_deflection_error"])
    assert (out / "vtu" / "own_mesh.vtu").is_file()
    # Every rung on the user's mesh, and nothing else in the ladder.
    rows = results["ladder"]["rows"]
    assert [(row["case"], row["rung"]) for row in rows] == [("own_mesh", rung) for rung in VALIDATED_MODELS]
    for row in rows:
        assert np.isfinite(row["tip_deflection_error"]) and row["block_count"] > 0
    assert rows[0]["tip_deflection_m"] == own["springs"]["van_gelder"]["tip_deflection_m"]  # the same answer


def test_results_files_are_read_back_with_their_schema_checked(tmp_path):
    from validation.report import SCHEMA, read_results

    good = tmp_path / "results.json"
    good.write_text(json.dumps({"schema": SCHEMA, "cases": {}}))
    assert read_results(good)["cases"] == {}
    newer = tmp_path / "newer.json"
    newer.write_text(json.dumps({"schema": "volspring-validate/999"}))
    with pytest.raises(ValueError, match=r"newer.json has schema 'volspring-validate/999'; this volspring reads"):
        read_results(newer)
    broken = tmp_path / "broken.json"
    broken.write_text('{"schema": ')
    with pytest.raises(ValueError, match=r"broken.json is not a readable validation results file"):
        read_results(broken)
