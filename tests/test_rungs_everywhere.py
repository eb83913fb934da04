"""Every rung of the model ladder wherever springs go: simulate, model files, checkpoints, output, contact, CLI.

A user simulates, collides and outputs a body on any rung (``Model.from_mesh(..., model=...)``,
``volspring-sim --model``) exactly as with springs: same integrators, supports, files and commands.
"""

import json
import re
from dataclasses import replace

import meshio
import numpy as np
import pytest

from conftest import cube_mesh
from meshing import TetMesh, add_shells
from meshing.mesh_io import read_tet_regions
from volspring import Gravity, HalfSpace, Material, Model, Pins, Scene, load_model, save_model, simulate
from volspring.checkpoint import CheckpointMismatch, load_checkpoint, save_checkpoint
from volspring.cli import main
from volspring.collision.contact import ContactForce, ObstacleContactForce, _body_edge_lengths
from volspring.elements import CorotatedTets, NodalStrain, Springs
from volspring.integrators import make_integrator
from volspring.ladder import MODELS
from volspring.output import ParaViewWriter, read_pvd
from volspring.stability import critical_steps

RUBBER = Material(E=1e6, nu=0.45, density=1100.0)
NEARLY_INCOMPRESSIBLE = Material(E=1e6, nu=0.499, density=1100.0)
SOFT = Material(E=1e5, nu=0.3, density=1000.0)


def beam():
    """0.2 m x 0.05 m x 0.05 m, 4 x 1 x 1 Kuhn cells (20 nodes, 24 tets)."""
    return cube_mesh((4, 1, 1), (0.2, 0.05, 0.05))


def beam_scene(rung, **options):
    mesh = beam()
    model = Model.from_mesh(mesh, RUBBER, model=rung, damping_ratio=0.05, **options)
    return Scene(model, forces=[Gravity()], pins=Pins(np.flatnonzero(mesh.points[:, 0] < 1e-9)))


def test_the_rungs_are_what_the_ladder_says():
    sets = {rung: [type(e) for e in beam_scene(rung).model.elements] for rung in MODELS}
    assert sets == {"springs": [Springs], "springs+volume": [Springs, NodalStrain],
                    "smoothed": [CorotatedTets, NodalStrain, NodalStrain]}
    assert [beam_scene(rung).model.rung for rung in MODELS] == list(MODELS)
    # The smoothed rung's nodal shear sits on node domains, its volume on pairs of nodes.
    _, shear, volume = beam_scene("smoothed").model.elements
    assert not shear.bulk.any() and shear.clusters is None
    assert not volume.shear.any() and volume.domains.domain_count < 0.6 * shear.domains.domain_count


# ---------------------------------------------------------------------- simulate
@pytest.mark.parametrize("name", ["implicit_euler", "symplectic_euler"])
@pytest.mark.parametrize("rung", MODELS)
def test_every_rung_simulates_with_implicit_and_explicit_integrators(rung, name):
    scene = beam_scene(rung)
    # Implicit Euler at 2 ms, far beyond the explicit limit; symplectic Euler at half its critical step.
    dt = 2e-3 if name == "implicit_euler" else 0.5 * critical_steps(scene)[name]
    result = simulate(scene, make_integrator(name), duration=0.04, dt=dt, frame_dt=0.01)
    x = result.state.x
    assert np.isfinite(x).all() and np.isfinite(result.state.v).all()
    masses = scene.model.masses
    sag = -float(masses @ (x - scene.model.rest_positions)[:, 2]) / masses.sum()
    # The centre of mass falls under gravity, held back by the clamp: by at most g t^2 / 2 = 7.8 mm in 0.04 s
    # (a single node may fall further: the bending wave from the clamp carries momentum to the free end).
    assert 1e-5 < sag < 7.85e-3
    assert result.inverted_tets.max() == 0
    # Gravity and the elastic energy are conservative and the dampers only take energy out: no frame holds
    # more than the start's (the symplectic scheme's half-step velocity may show a little more; measured
    # at most 1e-4 of the energy scale M g L).
    scale = scene.model.total_mass * 9.81 * 0.2
    assert result.total_energy.max() <= result.total_energy[0] + 1e-3 * scale


def test_the_rungs_sag_alike_and_only_the_upper_ones_feel_nu():
    """The three rungs are the same body: settled by implicit Euler (0.6 s at 20 ms, well past the first
    period of 0.16 s), their sags agree with the smoothed rung's within the 40% by which springs can miss FEM
    on beams (measured 5.3 to 7.9 mm); nu changes the upper rungs' sag and not the springs'. The direction is not asserted:
    on this 4 x 1 x 1-cell beam P2 refined to 16 x 4 x 4 cells sags 3% less at nu 0.45 than at 0.3
    (the clamp holds the Poisson contraction), P2 on the mesh itself 13% less (it locks), the smoothed rung
    7% more (shear deflection at L/h = 4, unchecked by the softer volume on node pairs)."""
    sags = {}
    for rung in MODELS:
        for nu in (0.3, 0.45):
            mesh = beam()
            model = Model.from_mesh(mesh, Material(E=1e6, nu=nu, density=1100.0), model=rung, damping_ratio=0.05)
            scene = Scene(model, forces=[Gravity()], pins=Pins(np.flatnonzero(mesh.points[:, 0] < 1e-9)))
            result = simulate(scene, make_integrator("implicit_euler"), duration=0.6, dt=2e-2)
            assert result.kinetic_energy[-1] < 1e-6 * model.total_mass * 9.81 * 0.005  # settled
            sags[rung, nu] = -(result.state.x - model.rest_positions)[:, 2].min()
    reference = sags["smoothed", 0.3]
    assert all(abs(sag / reference - 1) < 0.4 for sag in sags.values()), sags
    assert sags["springs", 0.3] == sags["springs", 0.45]
    for rung in ("springs+volume", "smoothed"):
        assert abs(sags[rung, 0.45] / sags[rung, 0.3] - 1) > 0.05, sags  # measured 0.90 and 1.075


# ---------------------------------------------------------------------- model files
def _rung_models():
    mesh = beam()
    regions = (mesh.points[mesh.tets].mean(axis=1)[:, 0] > 0.1).astype(np.int64) + 3
    stiff = {4: Material(E=4e6, nu=0.3, density=900.0)}
    return {
        "springs": Model.from_mesh(mesh, RUBBER, damping_ratio=0.05),
        "springs+volume": Model.from_mesh(mesh, RUBBER, model="springs+volume", damping_ratio=0.05),
        "springs+volume, shells": Model.from_mesh(add_shells(mesh, layers=1, thickness=0.01), RUBBER,
                                                  model="springs+volume", rule="lloyd"),
        "smoothed": Model.from_mesh(mesh, RUBBER, model="smoothed", damping_ratio=0.05),
        "smoothed, alpha and regions": Model.from_mesh(mesh, RUBBER, model="smoothed", alpha=0.35, regions=regions,
                                                       materials=stiff, damping_ratio=0.1),
        # nu 0.499: the volume terms' stand-in bulk is capped (NodalStrain's stand_in_bulk differs from bulk)
        "springs+volume, nearly incompressible": Model.from_mesh(mesh, NEARLY_INCOMPRESSIBLE, model="springs+volume"),
        "smoothed, nearly incompressible": Model.from_mesh(mesh, NEARLY_INCOMPRESSIBLE, model="smoothed"),
    }


@pytest.mark.parametrize("name", list(_rung_models()))
def test_every_rung_round_trips_through_a_model_file_bit_for_bit(tmp_path, name):
    model = _rung_models()[name]
    loaded = load_model(save_model(tmp_path / "model.vsmodel.npz", model))
    assert loaded.rung == model.rung and loaded.rule == model.rule and loaded.materials == model.materials
    assert [type(e) for e in loaded.elements] == [type(e) for e in model.elements]
    assert loaded.masses.tobytes() == model.masses.tobytes()
    rng = np.random.default_rng(5)
    x = model.rest_positions + 0.005 * rng.standard_normal(model.rest_positions.shape)
    v = rng.standard_normal(x.shape)
    assert np.array_equal(loaded.forces(x, v), model.forces(x, v))
    assert loaded.energy(x) == model.energy(x)
    for mine, theirs in zip(model.elements, loaded.elements):
        assert np.array_equal(theirs.stencil, mine.stencil)
        assert np.array_equal(theirs.stiffness_blocks(x), mine.stiffness_blocks(x))
        assert np.array_equal(theirs.stiffness_blocks(x, clamp_compression=False),
                              mine.stiffness_blocks(x, clamp_compression=False))
        if not isinstance(mine, Springs):
            assert theirs.stiffness_damping == mine.stiffness_damping
            assert np.array_equal(theirs.preconditioner_blocks(x), mine.preconditioner_blocks(x))


def test_a_model_file_refuses_a_continuum_set_on_other_rest_positions(tmp_path):
    mesh = beam()
    model = Model.from_mesh(mesh, RUBBER)
    moved = model.with_elements(CorotatedTets(mesh.points * 1.01, mesh.tets, 1e5))
    with pytest.raises(ValueError, match=r"model.elements\[1\], a CorotatedTets: it was built on rest positions other"):
        save_model(tmp_path / "model.vsmodel.npz", moved)
    assert list(tmp_path.iterdir()) == []
    added = model.with_elements(NodalStrain(mesh.points, mesh.tets, 0.0, 2e6))  # a user's volume term: kept
    loaded = load_model(save_model(tmp_path / "model.vsmodel.npz", added))
    assert loaded.rung == "springs" and np.array_equal(loaded.forces(1.01 * mesh.points), added.forces(1.01 * mesh.points))


def test_a_model_file_without_a_rung_loads_as_springs(tmp_path):
    from conftest import rewritten_archive

    path = save_model(tmp_path / "new.vsmodel.npz", _rung_models()["springs"])
    old = rewritten_archive(path, tmp_path / "old.vsmodel.npz", rung=None)  # as written before the ladder
    assert load_model(old).rung == "springs"
    # A nearly incompressible model written before the stand-in's own bulk: its stand-in takes the bulk, as then.
    capped = save_model(tmp_path / "capped.vsmodel.npz", _rung_models()["smoothed, nearly incompressible"])
    volume = load_model(rewritten_archive(capped, tmp_path / "before.vsmodel.npz",
                                          **{"elements/2/stand_in_bulk": None})).elements[2]
    assert np.array_equal(volume.stand_in_bulk, volume.per_tet()["bulk"])
    assert (load_model(capped).elements[2].stand_in_bulk < volume.stand_in_bulk).all()
    smoothed = save_model(tmp_path / "smoothed.vsmodel.npz", _rung_models()["smoothed"])
    bad = rewritten_archive(smoothed, tmp_path / "bad.vsmodel.npz", **{"elements/1/bulk": np.ones(3)})
    with pytest.raises(ValueError, match=r"bad.vsmodel.npz holds an invalid model: bulk must be a number or have shape"):
        load_model(bad)


# ---------------------------------------------------------------------- checkpoints
@pytest.mark.parametrize("name", ["implicit_euler", "symplectic_euler"])
def test_a_smoothed_run_resumed_from_its_checkpoint_is_bit_identical(tmp_path, name):
    scene = beam_scene("smoothed")
    dt = 2e-3 if name == "implicit_euler" else 0.5 * critical_steps(scene)[name]
    saved = {}
    whole = simulate(scene, make_integrator(name), duration=20 * dt, dt=dt, frame_dt=10 * dt,
                     callback=lambda frame, state: saved.setdefault(frame, state))
    integrator = make_integrator(name)
    path = save_checkpoint(tmp_path / "stop.npz", saved[1], scene=scene, integrator=integrator, dt=dt)
    again = beam_scene("smoothed")  # a new process builds the model afresh
    part = simulate(again, make_integrator(name), duration=10 * dt, dt=dt,
                    state=load_checkpoint(path, scene=again, integrator=integrator, dt=dt))
    assert np.abs(whole.state.x - scene.model.rest_positions).max() > 1e-6  # it moved
    assert part.state.x.tobytes() == whole.state.x.tobytes() and part.state.v.tobytes() == whole.state.v.tobytes()
    assert part.state.step == whole.state.step


def test_a_checkpoint_refuses_another_rung_or_alpha(tmp_path):
    scene, integrator = beam_scene("smoothed"), make_integrator("implicit_euler")
    state = integrator.step(scene, scene.initial_state(), 0.01)
    path = save_checkpoint(tmp_path / "run.npz", state, scene=scene, integrator=integrator, dt=0.01)
    load_checkpoint(path, scene=beam_scene("smoothed"), integrator=integrator, dt=0.01)  # the same run resumes
    for other in ("springs", "springs+volume"):
        with pytest.raises(CheckpointMismatch, match=rf"written for a model on the 'smoothed' rung; this run's model "
                                                     rf"is on the '{re.escape(other)}' rung"):
            load_checkpoint(path, scene=beam_scene(other))
    with pytest.raises(CheckpointMismatch, match=r"its elements\[0\] CorotatedTets, elements\[1\] NodalStrain, "
                                                 r"elements\[2\] NodalStrain differ \(another alpha, E, nu, regions or "
                                                 r"damping\?\)"):
        load_checkpoint(path, scene=beam_scene("smoothed", alpha=0.5))
    nu = beam_scene("smoothed")
    nu = Scene(Model.from_mesh(beam(), Material(E=1e6, nu=0.3, density=1100.0), model="smoothed",
                               damping_ratio=0.05), forces=nu.forces, pins=nu.pins)
    with pytest.raises(CheckpointMismatch, match=r"elements\[1\] NodalStrain, elements\[2\] NodalStrain differ"):
        load_checkpoint(path, scene=nu)
    # A springs+volume checkpoint refuses another nu through its volume term's bulk coefficient.
    volume = beam_scene("springs+volume")
    path = save_checkpoint(tmp_path / "volume.npz", volume.initial_state(), scene=volume, integrator=integrator,
                           dt=0.01)
    softer = Scene(Model.from_mesh(beam(), Material(E=1e6, nu=0.4, density=1100.0), model="springs+volume",
                                   damping_ratio=0.05), forces=volume.forces, pins=volume.pins)
    with pytest.raises(CheckpointMismatch, match=r"elements\[1\] NodalStrain differ"):
        load_checkpoint(path, scene=softer)


# ---------------------------------------------------------------------- output
def test_a_model_without_springs_writes_the_tet_series_with_its_strain_and_no_spring_series(tmp_path):
    model = beam_scene("smoothed").model
    writer = ParaViewWriter(tmp_path, model)
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    stretch = np.diag([1.02, 1.0, 1.0])
    from volspring import State

    writer(0, State(model.rest_positions @ turn.T, np.zeros_like(model.rest_positions), t=0.0))  # rotated only
    writer(1, State(model.rest_positions @ stretch.T @ turn.T, np.zeros_like(model.rest_positions), t=0.1))
    assert writer.springs_pvd_path is None and sorted(p.name for p in tmp_path.iterdir()) == [
        "frame.pvd", "frame_0000.vtu", "frame_0001.vtu"]
    rotated, stretched = (meshio.read(file) for _, file in read_pvd(tmp_path / "frame.pvd"))
    assert np.abs(rotated.cell_data["strain"][0]).max() < 1e-12  # a rotation is no strain
    np.testing.assert_allclose(stretched.cell_data["strain"][0], 0.02, rtol=1e-9)  # 2% stretch in every tet
    with pytest.raises(ValueError, match=r"springs=True, but the model has no springs \(its rung is 'smoothed'\)"):
        ParaViewWriter(tmp_path / "other", model, springs=True)
    # A model with springs keeps both series, and its tets get the same strain.
    springs = ParaViewWriter(tmp_path / "springs", beam_scene("springs+volume").model)
    assert springs.springs_pvd_path is not None


# ---------------------------------------------------------------------- contact
def two_bodies(rung, meshes, translations, **options):
    """One model of several placed bodies on a rung: ``Model.from_bodies`` builds springs only, so the
    bodies' meshes are joined into one mesh (no tet joins two bodies, so no element set couples them)
    and the body of every node set after."""
    points = np.concatenate([mesh.points + offset for mesh, offset in zip(meshes, translations)])
    starts = np.cumsum([0] + [mesh.node_count for mesh in meshes])
    tets = np.concatenate([mesh.tets + start for mesh, start in zip(meshes, starts)])
    model = Model.from_mesh(TetMesh(points, tets), SOFT, model=rung, **options)
    node_body = np.repeat(np.arange(len(meshes)), [mesh.node_count for mesh in meshes])
    return replace(model, node_body=node_body, materials=(SOFT,) * len(meshes), body_names=("",) * len(meshes))


def test_smoothed_bodies_collide_like_spring_bodies():
    """tests/test_contact.py's cube pushed into a pinned block, on the springs and the smoothed rung:
    the smoothed cube sinks no deeper than a tenth of an edge (the contact rule's bound) nor much deeper
    than the spring cube, and the energy does not rise."""
    block = cube_mesh((4, 4, 2), (0.1, 0.1, 0.05))
    cube = cube_mesh((2, 2, 2), (0.04, 0.04, 0.04))
    depths = {}
    for rung in ("springs", "smoothed"):
        model = two_bodies(rung, [block, cube], [(0, 0, 0), (0.0312, 0.0291, 0.0505)], damping_ratio=0.3)
        contact = ContactForce(model, friction=0.5)
        edge = float(contact.bodies.mean_edge_lengths.min())
        push = 0.1 * edge * contact.pair_stiffness.min()
        pushed = np.where(model.node_body == 1, model.masses, 0.0)
        block_nodes = model.body_nodes(0)
        bottom = block_nodes[model.rest_positions[block_nodes, 2] < 1e-9]
        scene = Scene(model, forces=[Gravity(masses=pushed, g=(0, 0, -push / model.body_masses[1])), contact],
                      pins=Pins(bottom))
        result = simulate(scene, make_integrator("implicit_euler", solver="direct"), duration=0.2, dt=4e-3,
                          frame_dt=0.02, guard="off")
        final = result.state
        assert np.isfinite(final.x).all()
        depths[rung] = contact.contacts(final.x).max_depth
        assert 0 < depths[rung] <= 0.1 * edge
        energy = result.total_energy
        assert np.diff(energy).max() <= 1e-6 * np.abs(energy).max()
    # Measured: 0.0131 (springs) and 0.0129 (smoothed, alpha 0.65) edge lengths.
    assert depths["smoothed"] <= 1.25 * depths["springs"], depths


def test_a_smoothed_cube_dropped_on_the_floor_comes_to_rest_on_it():
    cube = cube_mesh((2, 2, 2), (0.05, 0.05, 0.05))
    results = {}
    for rung in ("springs", "smoothed"):
        model = Model.from_mesh(TetMesh(cube.points + (0, 0, 0.005), cube.tets), SOFT, model=rung, damping_ratio=0.2)
        floor = ObstacleContactForce(model, [HalfSpace((0, 0, 0), (0, 0, 1))], friction=0.5)
        scene = Scene(model, forces=[Gravity(), floor])
        result = simulate(scene, make_integrator("implicit_euler"), duration=0.2, dt=4e-3, frame_dt=0.05)
        x = result.state.x
        assert np.isfinite(x).all()
        # Dropped 5 mm: the impact's energy is M g 5 mm; it never gains energy beyond that.
        assert result.total_energy.max() <= result.total_energy[0] + 1e-9
        results[rung] = (-x[:, 2].min(), scene.kinetic_energy(result.state.v))
    for rung, (depth, kinetic) in results.items():
        assert 0 < depth < 0.1 * 0.025, (rung, depth)  # below the floor by less than a tenth of an edge
        assert kinetic < 1e-3 * SOFT.density * 0.05**3 * 9.81 * 0.005  # at rest
    assert results["smoothed"][0] <= 1.25 * results["springs"][0]


def test_the_contact_edge_length_of_a_model_without_springs_or_mesh_comes_from_its_tets():
    mesh = cube_mesh((2, 1, 1), (0.2, 0.1, 0.1))
    springs = Model.from_mesh(mesh, SOFT)
    smoothed = Model.from_mesh(mesh, SOFT, model="smoothed")
    bare = replace(smoothed, topology=None)  # element sets only, as a user may build one
    expected = _body_edge_lengths(springs)
    np.testing.assert_allclose(_body_edge_lengths(bare), expected, rtol=1e-12)
    floor = ObstacleContactForce(bare, [HalfSpace((0, 0, 0), (0, 0, 1))])
    assert np.isfinite(floor.node_stiffness).all()


# ---------------------------------------------------------------------- region tags in mesh files
def _tagged_files(tmp_path):
    """The beam with tags 1 (x < 0.1) and 2, written as Medit (all tets numbered inverted) and as gmsh 2.2 in two
    tetra blocks plus a triangle block with a node of its own, so that reading flips, merges and drops nodes."""
    mesh = beam()
    tags = (mesh.points[mesh.tets].mean(axis=1)[:, 0] > 0.1).astype(np.int64) + 1
    inverted = mesh.tets[:, [0, 1, 3, 2]]
    medit = tmp_path / "beam.mesh"
    meshio.write(medit, meshio.Mesh(mesh.points, [("tetra", inverted)], cell_data={"medit:ref": [tags]}))
    order = np.argsort(-tags, kind="stable")  # the tets of tag 2 first, then tag 1: the file's own order
    extra = np.concatenate([mesh.points, [[5.0, 5.0, 5.0]]])
    gmsh = tmp_path / "beam.msh"
    cells = [("triangle", np.array([[0, 1, len(mesh.points)]])), ("tetra", mesh.tets[order][:10]),
             ("tetra", mesh.tets[order][10:])]
    physical = [np.array([7]), tags[order][:10], tags[order][10:]]
    meshio.write(gmsh, meshio.Mesh(extra, cells, cell_data={"gmsh:physical": physical, "gmsh:geometrical": physical}),
                 file_format="gmsh22", binary=False)
    return {"medit": medit, "gmsh": gmsh}


def test_region_tags_follow_the_tets_of_the_mesh_as_read(tmp_path):
    for path in _tagged_files(tmp_path).values():
        mesh = TetMesh.read(path)
        tags = read_tet_regions(path)
        assert tags.shape == (mesh.tet_count,) and tags.dtype == np.int64
        # Each tet's tag is the one of its place: the right half is region 2.
        np.testing.assert_array_equal(tags, (mesh.points[mesh.tets].mean(axis=1)[:, 0] > 0.1) + 1)
    untagged = tmp_path / "plain.vtu"
    beam().write(untagged)
    assert read_tet_regions(untagged) is None


# ---------------------------------------------------------------------- the command line
FAST = ["--pin", "xmin", "--dt", "0.005", "--frame-dt", "0.01", "--duration", "0.02", "--no-progress"]


def run(capsys, *argv):
    status = main([str(arg) for arg in argv])
    out, err = capsys.readouterr()
    return status, out, err


@pytest.fixture(scope="module")
def beam_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("mesh") / "beam.vtu"
    beam().write(path)
    return path


@pytest.mark.parametrize("rung", MODELS)
def test_the_cli_runs_every_rung_and_records_it(tmp_path, capsys, beam_file, rung):
    status, out, err = run(capsys, beam_file, *FAST, "--model", rung, "--out", tmp_path, "--blender",
                           "--checkpoint-every", "1")
    assert status == 0 and err == "", err
    assert f"model: {rung} (" in out
    manifest = json.loads((tmp_path / "volspring-run.json").read_text())
    assert manifest["model"]["rung"] == rung and manifest["status"] == "finished"
    assert ("alpha" in manifest["model"]) == (rung == "smoothed")
    written = {p.name for p in tmp_path.iterdir()} - {"volspring-run.json"}
    assert written == set(manifest["files"])
    assert ("frame_springs.pvd" in written) == (rung != "smoothed")
    assert ("frame_springs.pvd" in out) == (rung != "smoothed")
    last = meshio.read(read_pvd(tmp_path / "frame.pvd")[-1][1])
    assert last.point_data["displacement"][:, 2].min() < -1e-5 and last.cell_data["strain"][0].max() > 0
    assert load_checkpoint(tmp_path / "checkpoint.npz").step == 4


def test_the_cli_refuses_a_resume_with_another_rung_or_alpha(tmp_path, capsys, beam_file):
    common = [beam_file, *FAST[:-3], "--quiet", "--out", tmp_path, "--model", "smoothed"]
    assert run(capsys, *common, "--duration", "0.01", "--checkpoint-every", "1")[0] == 0
    checkpoint = tmp_path / "checkpoint.npz"
    status, _, err = run(capsys, *common, "--duration", "0.02", "--resume", checkpoint)
    assert status == 0, err
    for extra, message in [(["--alpha", "0.5"], r"NodalStrain differ \(another alpha, E, nu, regions or damping\?\)"),
                           (["--nu", "0.3"], r"NodalStrain differ"),
                           (["--damping-ratio", "0.2"], r"NodalStrain differ")]:
        status, _, err = run(capsys, *common, "--duration", "0.03", "--resume", checkpoint, *extra)
        assert status == 2 and len(err.splitlines()) == 1 and re.search(message, err), err  # bad input
    other = [arg if arg != "smoothed" else "springs" for arg in common]
    status, _, err = run(capsys, *other, "--duration", "0.03", "--resume", checkpoint)
    assert status == 2 and "written for a model on the 'smoothed' rung; this run's model is on the 'springs'" in err


def test_the_cli_damping_ratio_damps_every_rung(capsys, beam_file):
    energies = {}
    for rung in MODELS:
        for ratio in ("0", "0.3"):
            status, out, err = run(capsys, beam_file, *FAST, "--model", rung, "--damping-ratio", ratio,
                                   "--duration", "0.02", "--integrator", "symplectic_euler", "--dt", "2e-4",
                                   "--frame-dt", "0.02")
            assert status == 0, err
            energies[rung, ratio] = float(re.search(r"total energy ([-\d.e+]+) J", out).group(1))
    for rung in MODELS:  # the damped run ends with less energy than the undamped one
        assert energies[rung, "0.3"] < energies[rung, "0"], energies


def test_region_materials_from_the_command_line(tmp_path, capsys):
    path = _tagged_files(tmp_path)["medit"]
    mass = re.compile(r"mass ([\d.e+-]+) kg")
    status, out, err = run(capsys, path, *FAST, "--model", "smoothed")
    assert status == 0, err
    plain = float(mass.search(out).group(1))
    status, out, err = run(capsys, path, *FAST, "--model", "smoothed", "--region-material", "2:4e6:0.3:550",
                           "--region-material", "1:1e6")
    assert status == 0, err
    assert float(mass.search(out).group(1)) == pytest.approx(0.75 * plain)  # half the beam at half the density
    assert "2 region material(s) (tags 2, 1)" in out
    for argv, message in [
        (["--region-material", "9:1e6"], r"names tag\(s\) 9, but no tet of .* has them \(tags present: 1, 2\)"),
        (["--region-material", "2:1e6:0.5"], r"--region-material 2: nu = 0.5 is not in"),
        (["--region-material", "two:1e6"], r"--region-material 'two:1e6' is not TAG:E\[:NU\[:DENSITY\]\]"),
        (["--region-material", "1:1e6", "--region-material", "1:2e6"], "gives tag 1 twice"),
    ]:
        status, _, err = run(capsys, path, *FAST, *argv)
        assert status == 2 and len(err.splitlines()) == 1 and re.search(message, err), err  # bad input
    status, _, err = run(capsys, "box:0.2,0.05,0.05", "--size", "0.05", *FAST, "--region-material", "1:1e6")
    assert status == 2 and "needs a mesh file whose tets carry region tags; INPUT is a built-in shape" in err
    untagged = beam().write(tmp_path / "untagged.vtu")
    status, _, err = run(capsys, untagged, *FAST, "--region-material", "1:1e6")
    assert status == 2 and "has no region tags on its tets" in err


@pytest.mark.parametrize("argv, message", [
    (["--alpha", "0.5"], r"--alpha applies to --model smoothed .*not --model springs"),
    (["--model", "smoothed", "--alpha", "1.5"], r"--alpha = 1.5 is not in \[0, 1\]"),
    (["--model", "smoothed", "--rule", "lloyd"], r"--model smoothed has no springs: --rule does not apply"),
    (["--model", "springs+volume", "--rule", "uniform", "--stiffness", "10"], r"derives its springs from the material"),
    (["--model", "springs+volume", "--nu", "0.1"], r"model 'springs\+volume' cannot reach nu = 0.1 .*Use model='smoothed'"),
    (["--model", "ladder"], r"argument --model: invalid choice: 'ladder'"),
])
def test_the_cli_refuses_what_a_rung_cannot_take(capsys, beam_file, argv, message):
    status, out, err = run(capsys, beam_file, *FAST, *argv)
    assert status == 2 and out == "" and len(err.splitlines()) == 1, err  # bad input or a bad command line
    assert re.search(message, err), err


def test_a_topology_file_with_shells_runs_with_volume_and_is_refused_by_the_smoothed_rung(tmp_path, capsys):
    from meshing.topology_io import write_topology

    path = write_topology(tmp_path / "beam.vstopo.npz", add_shells(beam(), layers=1, thickness=0.01))
    status, out, err = run(capsys, path, *FAST, "--model", "springs+volume")
    assert status == 0 and err == "", err
    assert "shell springs" in out and "nodal volume term on 20 smoothing domains" in out
    status, out, err = run(capsys, path, *FAST, "--model", "smoothed")
    assert status == 2 and out == "" and len(err.splitlines()) == 1
    assert "--model smoothed takes a tet mesh without shells (shells are springs)" in err


def test_a_smoothed_contact_step_reuses_the_stand_in_of_the_hierarchy(monkeypatch):
    """With the continuum sets applied as products, their stand-in blocks (a linearisation of their own) are
    computed when the AMG hierarchy is built, not again at each contact step's update of it; the steps still solve
    to the asked residual."""
    from volspring.elements import CorotatedTets
    from volspring.integrators.implicit import ImplicitEuler

    block = cube_mesh((4, 4, 2), (0.1, 0.1, 0.05))
    cube = cube_mesh((2, 2, 2), (0.04, 0.04, 0.04))
    model = two_bodies("smoothed", [block, cube], [(0, 0, 0), (0.0312, 0.0291, 0.0405)], damping_ratio=0.3)
    contact = ContactForce(model, friction=0.5)
    block_nodes = model.body_nodes(0)
    scene = Scene(model, forces=[Gravity(), contact], pins=Pins(block_nodes[model.rest_positions[block_nodes, 2] < 1e-9]))
    calls = []
    original = CorotatedTets.preconditioner_blocks
    monkeypatch.setattr(CorotatedTets, "preconditioner_blocks", lambda self, x: calls.append(1) or original(self, x))
    integrator = ImplicitEuler(rtol=1e-6)
    state = scene.initial_state(v=np.where(model.node_body[:, None] == 1, [0.0, 0.0, -0.5], 0.0))
    builds = contact_steps = 0
    for _ in range(12):
        contact_steps += contact.contacts(state.x).count > 0
        state = integrator.step(scene, state, 4e-3)
        builds += integrator.last_solve.rebuilt
        assert integrator.last_solve.residual <= 1e-6
    assert contact_steps >= 3  # the cube hits the block within the first steps
    # One CorotatedTets set (the two bodies' meshes are one mesh here): one stand-in evaluation per build, none
    # per contact step's update (there were contact_steps of them).
    assert len(calls) == builds < contact_steps
