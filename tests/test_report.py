"""volspring-validate end to end: the three outputs, their numbers against a direct computation, bad input."""

import base64
import html
import json
import re

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
    assert page.count("data:image/svg+xml;base64,") >= 5  # profiles, refinement, volume, speed, Cauchy
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
    # The costs say which code ran the timed steps' hot loops (volspring.kernels).
    assert f"with the {results['ladder']['kernels']} kernels" in page


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


# ---------------------------------------------------------------------- the page tells its story
def page_and_results(quick_run):
    _, out = quick_run
    return (out / "report.html").read_text(encoding="utf-8"), json.loads((out / "results.json").read_text())


def test_headline_says_which_model_and_integrator_give_which_error_at_what_cost(quick_run):
    page, results = page_and_results(quick_run)
    found = re.search(r'<p class="headline">(.*?)</p>', page, re.S)
    assert found, "no headline paragraph"
    sentence = html.unescape(found.group(1))
    assert page.index('class="headline"') < page.index("<h2")  # on the first screen, above the ladder
    # The rung with the smallest worst error (tip deflection of the static cases, first frequency of the modal
    # one), its worst error and median cost as in results.json, and the rung of the lowest median cost: springs or
    # lattice, which cost the same to within the timing's noise (0.89-1.18 x springs on the quick meshes).
    worst, costs = {}, {}
    for row in results["ladder"]["rows"]:
        if "refused" in row:
            continue
        error = row["frequency_errors"][0] if row["kind"] == "modes" else row["tip_deflection_error"]
        worst[row["rung"]] = max(worst.get(row["rung"], 0.0), abs(error))
        costs.setdefault(row["rung"], []).append(row["step_cost_vs_springs"])
    best = min(worst, key=worst.get)
    assert worst[best] >= 0.1  # the quick meshes are coarse: whole percents
    assert f"the {best} rung is the most accurate model, within {100 * worst[best]:.0f}%" in sentence
    assert f"at {np.median(costs[best]):.2g}× the springs rung's cost per implicit Euler step" in sentence
    cheap = min(costs, key=lambda rung: np.median(costs[rung]))
    assert cheap in ("springs", "lattice"), costs
    assert f"the {cheap} rung is the cheapest" in sentence and f"off by up to {100 * worst[cheap]:.0f}%" in sentence
    # The integrators: the cheapest stable run with its wall time per simulated second, and the cheapest run
    # that keeps the first frequency within 1%.
    stable = [run for run in results["studies"]["speed"]["runs"] if run["stable"]]
    cheapest = min(stable, key=lambda run: run["wall_seconds_per_simulated_second"])
    assert (f"{cheapest['integrator']} at {cheapest['step_factor']:g} × " in sentence
            and f"is the cheapest stable integrator: {cheapest['wall_seconds_per_simulated_second']:.2g} s" in sentence)
    keeping = [run for run in stable if run.get("first_frequency_error") is not None
               and abs(run["first_frequency_error"]) <= 0.01]
    faithful = min(keeping, key=lambda run: run["wall_seconds_per_simulated_second"])
    assert (f"within 1% is {faithful['integrator']} at {faithful['step_factor']:g} × the critical step: "
            f"{faithful['wall_seconds_per_simulated_second']:.2g} s per simulated second") in sentence


def test_headline_branches():
    """The sentence without a speed study, with one rung both best and cheapest, with no run keeping f1."""
    from validation.report.summary import headline

    rows = [{"case": "c", "title": "Case", "kind": "static", "rung": "smoothed", "tip_deflection_error": -0.05,
             "step_cost_vs_springs": 0.9, "step_seconds": 2e-3},
            {"case": "c", "title": "Case", "kind": "static", "rung": "springs", "tip_deflection_error": 0.5,
             "step_cost_vs_springs": 1.0, "step_seconds": 2.2e-3},
            {"case": "c", "title": "Case", "kind": "static", "rung": "springs+volume", "refused": "nu too low"}]
    text = headline({"ladder": {"rows": rows}, "studies": {}})
    assert text == ("Against FEM on the same meshes, the smoothed rung is the most accurate model, within 5% in tip "
                    "deflection and first frequency (worst: case), and also the cheapest (2 ms per implicit Euler "
                    "step).")
    runs = [{"integrator": "rk4", "step_factor": 0.5, "step_unit": "critical step", "stable": True,
             "wall_seconds_per_simulated_second": 3.0, "settled_deflection_error": 1e-6, "first_frequency_error": 0.02},
            {"integrator": "explicit_euler", "step_factor": 0.2, "step_unit": "2 / omega_max", "stable": False,
             "wall_seconds_per_simulated_second": 0.1}]
    text = headline({"ladder": {"rows": []}, "studies": {"speed": {"node_count": 44, "runs": runs}}})
    assert "rk4 at 0.5 × the critical step is the cheapest stable integrator: 3 s" in text
    assert text.endswith("no run keeps the first frequency within 1%.")
    assert headline({"ladder": {"rows": rows[:1]}, "studies": {}}) == (
        "Against FEM on the same meshes, the smoothed rung is within 5% in tip deflection and first frequency "
        "(worst: case), at 2 ms per implicit Euler step.")  # one rung: no "most accurate"
    assert headline({"ladder": {"rows": []}, "studies": {}}) == ""


def test_volume_change_is_a_ratio_to_fem(quick_run):
    """-74% (compression) and +103% (tension) were the same failure: twice the change; now 1.74x and 2.03x."""
    page, results = page_and_results(quick_run)
    assert "volume change error" not in page and "volume vs FEM" not in page  # the old percent columns
    ratios = 0
    for row in results["ladder"]["rows"]:
        if row.get("volume_change_error_vs_fem") is not None:
            ratio = row["volume_change_m3"] / row["reference_volume_change_m3"]
            assert f"<td>{ratio:#.3g}&times;</td>" in page
            ratios += 1
    assert ratios >= 8  # the hanging bar and the compressed cube, every rung
    springs = {row["case"]: row for row in results["ladder"]["rows"] if row["rung"] == "springs"}
    # The quick run's springs: about twice P2's change in both, whatever the sign of the error.
    for case in ("hanging_bar", "uniaxial_compression"):
        assert 1.5 < springs[case]["volume_change_m3"] / springs[case]["reference_volume_change_m3"] < 2.5
    # The case tables and the rules table too, against P2 and against the closed form.
    case = results["cases"]["hanging_bar"]
    volume = case["springs"]["lloyd"]["volume_change_m3"]
    assert f"<td>{volume / case['fem']['P2']['volume_change_m3']:#.3g}&times;</td>" in page
    assert f"<td>{volume / case['analytic']['volume_change_m3']:#.3g}&times;</td>" in page
    assert "hanging bar volume change / FEM" in page


def test_bending_volume_change_is_not_meaningful_and_says_why(quick_run):
    page, results = page_and_results(quick_run)
    bending = [name for name, case in results["cases"].items() if case["kind"] != "modes"
               and abs(case["fem"]["P2"]["volume_change_m3"]) < 0.02 * case["fem"]["P2"]["gross_volume_change_m3"]]
    assert bending == ["cantilever_gravity", "cantilever_end_load"]
    # One "not meaningful" per ladder row of a bending case and per answer in its case table, none elsewhere.
    ladder_rows = [row for row in results["ladder"]["rows"] if row["case"] in bending and "refused" not in row]
    answers = sum(len(results["cases"][name]["springs"])
                  + sum("refused" not in values for values in results["cases"][name]["models"].values())
                  for name in bending)
    link = "<a class='na' href='#bending-volume'>not meaningful: bending</a>"
    assert page.count(link) == len(ladder_rows) + answers
    note = re.search(r"<p id='bending-volume'>(.*?)</p>", page, re.S)
    assert note and "cancellation" in note.group(1) and "below 2% of the gross" in note.group(1)


def test_quick_run_is_flagged_as_coarse(quick_run):
    from validation.report.html import render_html

    page, results = page_and_results(quick_run)
    flag = re.search(r"<p class='quick-flag'>(.*?)</p>", page, re.S)
    assert flag and "coarse" in flag.group(1) and "--quick" in flag.group(1)
    assert page.index("quick-flag") < page.index("<h2")
    full = render_html(dict(results, quick=False), {})
    assert "<p class='quick-flag'>" not in full and "Quick run" not in full


def test_contents_list_every_section_in_page_order(quick_run):
    page, _ = page_and_results(quick_run)
    contents = re.search(r"<nav class='contents[^>]*>(.*?)</nav>", page, re.S)
    assert contents and page.index("<nav") < page.index("<h2")
    listed = re.findall(r"<a href='#([^']+)'>", contents.group(1))
    headings = re.findall(r"<h2 id='([^']+)'>", page)
    assert listed == headings and len(headings) >= 10  # ladder, rules, Cauchy, five cases, two studies, files
    assert listed[0] == "ladder"


def test_figures_are_svg(quick_run):
    page, _ = page_and_results(quick_run)
    sources = re.findall(r'<img alt="[^"]*" src="([^"]+)"', page)
    assert len(sources) >= 5 and "image/png" not in page
    for source in sources:
        prefix = "data:image/svg+xml;base64,"
        assert source.startswith(prefix)
        assert b"<svg" in base64.b64decode(source[len(prefix):])[:2000]


def test_speed_points_are_labelled_with_their_step():
    from validation.report.figures import render_figures

    def run(integrator, factor, unit, wall, error):
        return {"integrator": integrator, "step_factor": factor, "step_unit": unit, "stable": True,
                "wall_seconds_per_simulated_second": wall, "settled_deflection_error": error,
                "first_frequency_error": error}

    speed = {"model_frequency_error": 0.3, "model_deflection_error": -0.6,
             "runs": [run("rk4", 0.37, "critical step", 2.0, 1e-4), run("implicit_euler", 123.0, "2 / omega_max", 0.2, 0.3)]}
    figures = render_figures({"cases": {}, "studies": {"speed": speed}, "rules": []})
    svg = base64.b64decode(figures["speed"].split(",", 1)[1]).decode()
    # Text drawn as paths keeps its string in a comment: each label once per panel.
    assert svg.count("<!-- 0.37 -->") == 2 and svg.count("<!-- 123 -->") == 2
    assert "rk4 (step in dt_crit)" in svg and "implicit_euler (step in 2/omega_max)" in svg


def test_every_table_is_in_a_scrolling_wrapper(quick_run):
    page, _ = page_and_results(quick_run)
    tables = page.count("<table")
    assert tables >= 10 and page.count("<div class='table-scroll") == tables
    assert len(re.findall(r"<div class='table-scroll[^']*'><table", page)) == tables  # each wraps its table
    assert re.search(r"\.table-scroll \{[^}]*overflow-x: auto", page)


@pytest.mark.slow
def test_full_run_writes_the_three_outputs(tmp_path):
    """The full run (no --quick), from an empty cache: about 90 s on 2 cores."""
    out = tmp_path / "full"
    status = main(["--out", str(out), "--cache", str(tmp_path / "cache"), "--no-progress"])
    assert status == 0
    results = json.loads((out / "results.json").read_text())
    assert results["quick"] is False
    assert (out / "report.html").read_text().count("data:image/svg+xml;base64,") >= 5
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
