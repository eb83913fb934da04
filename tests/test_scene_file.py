"""Scene files: ``volspring-sim scene.toml``, overrides by key path, flags over a scene, errors naming key paths.

Every example scene in examples/scenes/ runs here, shortened with the duration flag, and is checked on its
physics (the beam sags, the ball comes to rest on the block, the colliding bodies keep their momentum and
bounce apart, the ring drifts downwind and turns with the vortex; the plucked string swings to its other
side in half a period with its ends held, the hair hangs from its root without stretching, the cloth drapes
over the ball within its strain limit, the lattice bunny sags, the cloth lands on the block and folds over it).
"""

import json
from pathlib import Path

import numpy as np
import pytest

from volspring.checkpoint import load_checkpoint
from volspring.cli import build_parser, main
from volspring.cli._arguments import BODY_FLAGS, DEFAULT_NU, RUN_FLAGS
from volspring.output import read_manifest, read_pvd
from volspring.scene_file import SCENE, assemble_scene, read_scene, split_key_path

from conftest import cube_mesh

SCENES = Path(__file__).resolve().parents[1] / "examples" / "scenes"
BEAM, BALL, TWO, WIND = (SCENES / f"{name}.toml" for name in ("beam", "ball_on_block", "two_bodies", "wind_and_vortex"))
STRING, HAIR, CLOTH, LATTICE, CLOTH_ON_BLOCK = (SCENES / f"{name}.toml" for name in (
    "plucked_string", "hanging_hair", "cloth_on_a_ball", "lattice_bunny", "cloth_on_a_block"))
END_STATE = ["--checkpoint-every", "100000", "--quiet"]  # no frame checkpoint, but the end state in checkpoint.npz


@pytest.fixture(autouse=True)
def in_a_temporary_folder(tmp_path, monkeypatch):
    """The example scenes name output folders relative to the working directory: keep them out of the clone."""
    monkeypatch.chdir(tmp_path)


def run(capsys, *argv):
    status = main([str(arg) for arg in argv])
    out, err = capsys.readouterr()
    return status, out, err


def end_state(capsys, scene, folder, *argv):
    """The final state of a run of ``scene`` into ``folder``, and the scene's model (node_body, masses)."""
    status, _, err = run(capsys, scene, "--out", folder, *END_STATE, *argv)
    assert status == 0, err
    sets = [argv[index + 1] for index, token in enumerate(argv) if token == "--set"]
    model = assemble_scene(read_scene(scene, overrides=sets), base=scene.parent).model
    return load_checkpoint(folder / "checkpoint.npz"), model


def body_motion(state, model, body):
    """(centre of mass [m], its velocity [m/s], angular momentum about it [kg m^2/s]) of one body."""
    nodes = model.body_nodes(body)
    masses = model.masses[nodes]
    centre, velocity = masses @ state.x[nodes] / masses.sum(), masses @ state.v[nodes] / masses.sum()
    spin = (masses[:, None] * np.cross(state.x[nodes] - centre, state.v[nodes] - velocity)).sum(axis=0)
    return centre, velocity, spin


# ---------------------------------------------------------------------- the example scenes, on their physics
def test_the_beam_sags_downward_and_its_pinned_end_stays(tmp_path, capsys):
    state, model = end_state(capsys, BEAM, tmp_path, "--duration", "0.1")
    x0 = model.rest_positions
    tip = x0[:, 0] > 0.45
    assert (state.x[tip, 2] - x0[tip, 2]).max() < -0.01  # 0.1 s of free fall alone is 4.9 cm; the tip sags > 1 cm
    pinned = x0[:, 0] < -0.49
    assert pinned.any() and np.array_equal(state.x[pinned], x0[pinned])  # pins hold exactly, not approximately


def test_the_ball_comes_to_rest_on_the_block(tmp_path, capsys):
    state, model = end_state(capsys, BALL, tmp_path, "--duration", "0.5")
    centre, velocity, _ = body_motion(state, model, 1)
    ball = model.body_nodes(1)
    # The block's top face is z = 0 and the ball (radius 5 cm) started at z = 0.06 falling at 0.5 m/s. The
    # penalty contact lets a resting contact sink about strain / alpha edge lengths (1.5 mm here): 5 mm bounds it.
    assert state.x[ball, 2].min() > -5e-3
    assert 0.035 < centre[2] < 0.06  # dropped from 0.06 and resting on its bottom, not sunk through
    assert np.linalg.norm(velocity) < 0.1  # from 0.5 m/s; coarse contact normals leave a slow sideways drift
    block = model.body_nodes(0)
    assert state.x[block, 2].min() == pytest.approx(-0.06, abs=1e-12)  # the pinned bottom face has not moved


def test_two_bodies_keep_their_momentum_and_bounce_apart(tmp_path, capsys):
    state, model = end_state(capsys, TWO, tmp_path, "--duration", "0.15")
    (_, cube, _), (_, ball, _) = (body_motion(state, model, body) for body in (0, 1))
    masses = [model.masses[model.body_nodes(body)].sum() for body in (0, 1)]
    before = masses[0] * 1.0 - masses[1] * 1.0  # the scene's velocities: +1 and -1 m/s along x
    after = masses[0] * cube[0] + masses[1] * ball[0]
    # Contact forces sum to round-off (the reaction is spread over the other body); 1e-6 leaves room for the
    # implicit solve's tolerance, which here keeps the sum to 1e-16.
    assert after == pytest.approx(before, rel=1e-6)
    assert ball[0] - cube[0] > 0.5  # approaching at 2 m/s, separating after the contact (restitution > 0.25)


def test_the_ring_drifts_downwind_and_turns_with_the_vortex(tmp_path, capsys):
    state, model = end_state(capsys, WIND, tmp_path, "--duration", "0.3")
    centre, velocity, spin = body_motion(state, model, 0)
    assert centre[0] > 0.01 and velocity[0] > 0  # blown towards +x, from rest at the origin
    assert spin[2] > 0.01 and spin[2] > 10 * np.abs(spin[:2]).max()  # counter-clockwise about +z, only


def test_a_steady_wind_accelerates_a_free_body_as_implicit_euler_predicts(tmp_path, capsys):
    # No gusts and no vortex: every node feels c m (w - v) and the elastic forces sum to zero, so the centre of
    # mass follows implicit Euler's v_(k+1) = (v_k + h c w) / (1 + h c) exactly: v_n = w (1 - (1 + h c)^-n).
    # The direct solver: AMG-preconditioned CG stops at rtol 1e-3, which moves the mean by 1.6e-4 here.
    state, model = end_state(capsys, WIND, tmp_path, "--duration", "0.3", "--set", "fields[0].gusts=[]",
                             "--set", "fields[1].strength=0", "--set", "integrator.solver=direct")
    _, velocity, _ = body_motion(state, model, 0)
    steps, h, c, w = 30, 0.01, 0.5, 2.0  # the scene's dt, rate and speed
    # 30 steps of round-off on O(1) numbers: 1e-9 is far above it and far below a wrong formula (1e-2 apart).
    assert velocity[0] == pytest.approx(w * (1 - (1 + h * c) ** -steps), rel=1e-9)


# ---------------------------------------------------------------------- structures: strings, hair, cloth, lattices
def test_every_example_scene_is_run_here():
    # Here, or by the test file of its feature (beam_vs_fem: tests/test_scene_compare.py).
    source = "".join(path.read_text() for path in Path(__file__).parent.glob("test_scene_*.py"))
    for scene in sorted(SCENES.glob("*.toml")):
        assert scene.stem in source, f"examples/scenes/{scene.name} is not run by tests/test_scene_*.py"


def test_the_plucked_string_swings_to_its_other_side_in_half_a_period(tmp_path, capsys):
    f1 = np.sqrt(10.0 / 0.01) / 2.0  # c / (2 L): the scene's tension, density and length
    state, model = end_state(capsys, STRING, tmp_path, "--duration", str(1 / (2 * f1)))
    x0 = model.rest_positions
    assert np.array_equal(state.x[[0, 40]], x0[[0, 40]])  # the pinned ends hold exactly
    # Plucked +5 mm, the middle is at -5 mm half a period later for the wave equation. The chain's implicit
    # Euler damps mode n by (1 + (n w1 dt)^2)^(-steps / 2) (0.97 for the first, 0.75 for the third...), which
    # leaves -0.87 of the pluck (measured); 0.8 bounds that, while a string that had not swung would be > 0.
    assert -0.005 < state.x[20, 2] < -0.8 * 0.005
    assert np.abs(state.x[:, 1]).max() == 0.0  # plucked in the xz plane, it stays in it


def test_the_hanging_hair_keeps_its_root_and_falls_without_stretching(tmp_path, capsys):
    from volspring.springs import spring_strains

    state, model = end_state(capsys, HAIR, tmp_path, "--duration", "0.1")
    x0 = model.rest_positions
    assert np.array_equal(state.x[:2], x0[:2])  # the clamped root segment, pinned by node numbers
    assert state.x[-1, 2] - x0[-1, 2] < -1e-3  # the curl sags under its own weight (measured 1.7 mm)
    # EA = 20 N against a weight of 6e-6 N: strains of order 1e-7 (measured 3e-7); 1e-5 would be a
    # strand stretched by its bending, i.e. angle springs pulling the wrong nodes.
    assert np.abs(spring_strains(model, state.x)).max() < 1e-5
    assert [type(element_set).__name__ for element_set in model.elements] == ["Springs", "AngleSprings",
                                                                              "DihedralSprings"]


def test_the_cloth_drapes_over_the_ball_within_its_strain_limit(tmp_path, capsys):
    from volspring.springs import spring_strains
    from volspring.structures import cloth_springs

    state, model = end_state(capsys, CLOTH, tmp_path, "--duration", "0.5")
    x0 = model.rest_positions
    limited = cloth_springs(model, "structural", "shear")
    # Provot's limit stops sweeping once no spring is more than tolerance = 1e-3 past tau = 0.1.
    assert spring_strains(model, state.x)[limited].max() <= 0.1 + 1e-3
    assert np.array_equal(state.x[[0, 16]], x0[[0, 16]])  # the two pinned corners
    # The free corners fall past the ball (top at z = 0) while the middle rests on it, and no node enters
    # the ball (radius 0.3 m; its 5 cm facets lie inside the sphere, by at most 1 mm).
    assert state.x[[272, 288], 2].max() < -0.2 and 0 < state.x[144, 2] < 0.02
    assert np.linalg.norm(state.x - [0, 0, -0.3], axis=1).min() > 0.3 - 1e-3
    frames = sorted(path.name for path in tmp_path.glob("frame_surface_*.vtu"))
    assert len(frames) == 26 and (tmp_path / "surface_0025.obj").is_file()  # the triangles for ParaView, Blender


def test_the_lattice_bunny_sags_from_its_ears(tmp_path, capsys):
    coarse = ["--set", "bodies[0].cell_size=20", "--set", "output.blender=false"]  # 2 cm cells: a quick bunny
    state, model = end_state(capsys, LATTICE, tmp_path, "--duration", "0.3", *coarse)
    x0 = model.rest_positions
    top = x0[:, 2] == x0[:, 2].max()
    assert top.sum() >= 4 and np.array_equal(state.x[top], x0[top])  # region "zmax": the ears' top layer
    drop = (model.masses @ (state.x - x0))[2] / model.total_mass
    rising = (model.masses @ state.v)[2] / model.total_mass
    # Hung from its ears the soft bunny (E = 50 kPa) sags by about 11 cm at 0.23 s, then springs back up
    # (measured: 8.3 cm down and rising at 0.5 m/s at 0.3 s); in free fall it would be 44 cm down and falling.
    assert -0.15 < drop < -0.02 and rising > 0.1
    assert model.rule == "lattice" and x0[:, 2].max() - x0[:, 2].min() > 0.14  # turned: the bunny's up is +z


def test_a_cloth_lands_on_a_block_and_folds_over_its_edges(tmp_path, capsys):
    from volspring.springs import spring_strains
    from volspring.structures import cloth_springs

    state, model = end_state(capsys, CLOTH_ON_BLOCK, tmp_path, "--duration", "0.3", "--set", "output.blender=false")
    cloth, x0 = model.body_nodes(1), model.rest_positions
    assert model.topology is not None and cloth.min() == model.topology.mesh.node_count  # after the block's nodes
    over = np.abs(x0[cloth, :2]).max(axis=1) < 0.19  # over the block's 0.4 m top, a cell from its edge
    # The contact layer (1 cm) holds the cloth over the block: a node's weight m g / k_c is 5e-5 m deep.
    assert state.x[cloth[over], 2].min() > 0.01 - 1e-3
    assert state.x[cloth[np.abs(x0[cloth, :2]).max(axis=1) > 0.21], 2].max() < -0.01  # the overhang hangs down
    assert spring_strains(model, state.x)[cloth_springs(model, "structural", "shear")].max() <= 0.1 + 1e-9


def test_a_cloth_from_a_triangle_file_pinned_by_node_numbers(tmp_path, capsys):
    import trimesh

    from volspring.structures import cloth_springs

    trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]],
                    process=False).export(tmp_path / "sheet.obj")
    (tmp_path / "scene.toml").write_text('[[bodies]]\nkind = "cloth"\nmesh = "sheet.obj"\nareal_density = 0.2\n'
                                         'membrane_stiffness = 100.0\nbend_stiffness = 1.0\n'
                                         '[[supports]]\ntype = "pin"\nnodes = [0, 1]\n[[fields]]\ntype = "gravity"\n')
    state, model = end_state(capsys, tmp_path / "scene.toml", tmp_path / "out", "--duration", "0.05")
    counts = [int(cloth_springs(model, kind).sum()) for kind in ("structural", "bend")]
    assert model.node_count == 4 and counts == [5, 1]  # the square's 5 edges, 1 spring across its diagonal
    assert np.array_equal(state.x[:2], model.rest_positions[:2]) and state.x[2:, 2].max() < -1e-3


def test_a_structure_scene_resumes_bit_identically(tmp_path, capsys):
    whole, parts = tmp_path / "whole", tmp_path / "parts"
    assert run(capsys, STRING, "--duration", "0.008", "--out", whole, *END_STATE)[0] == 0
    assert run(capsys, STRING, "--duration", "0.004", "--out", parts, *END_STATE)[0] == 0
    status, _, err = run(capsys, STRING, "--duration", "0.008", "--out", parts, *END_STATE,
                         "--resume", parts / "checkpoint.npz")
    assert status == 0, err
    resumed, uninterrupted = (load_checkpoint(folder / "checkpoint.npz") for folder in (parts, whole))
    assert resumed.step == 40 and resumed.x.tobytes() == uninterrupted.x.tobytes()
    # The spring series (a string has no tets) continues: frames 0 to 4 at 2 ms, none written twice.
    assert [time for time, _ in read_pvd(parts / "frame_springs.pvd")] == [0.0, 0.002, 0.004, 0.006, 0.008]


@pytest.mark.parametrize("override, message", [
    ("bodies[0].kind=strng", 'bodies[0].kind = "strng" is not a known kind; did you mean string?'),
    ("bodies[0].cont=3", "bodies[0].cont is not a known key; did you mean count?"),
    ("bodies[0].count=1", "bodies[0].count = 1 nodes; expected an integer >= 2"),
    ("bodies[0].tension=-1e6", "bodies[0].tension = -1000000.0 N would need a rest length"),
    ("bodies[0].pluck_at=1.5", "bodies[0].pluck_at = 1.5 is not in (0, 1)"),
    ("supports[0].nodes=[0, 41]", "supports[0].nodes = [0, 41]: node 41 is not in bodies[0] (41 nodes, 0 to 40)"),
    ('supports[0].region="xmin"', "supports[0] gives region and nodes; expected one of region"),
    ("output.blender=true", "output.blender: strings and hair have no surface for Blender's OBJ files"),
])
def test_bad_structure_values_are_one_line_naming_the_key_path(capsys, override, message):
    status, out, err = run(capsys, STRING, "--set", override, "--duration", "0")
    assert status == 2 and out == "" and err.count("\n") == 1
    assert message in err, err


@pytest.mark.parametrize("text, message", [
    ('[[bodies]]\nkind = "cloth"\nwidth = 1\nheight = 1\nnx = 4\nareal_density = 0.2\n', "bodies[0] gives no ny"),
    ('[[bodies]]\nkind = "cloth"\nwidth = 1\nheight = 1\nnx = 4\nny = 4\nareal_density = 0.2\n',
     "bodies[0]: give membrane_stiffness= (E t [N/m]) or stretch_stiffness= (k [N/m]), one of the two"),
    ('[[bodies]]\nkind = "lattice"\nshape = "sphere:0.1"\n', "bodies[0].cell_size is missing; expected a number"),
    ('[[bodies]]\nkind = "lattice"\nshape = "sphere:0.1"\ncell_size = 0.05\nmaterial = {nu = 0.7}\n',
     "bodies[0].material.nu = 0.7 is not in (-1, 0.5)"),
    ('[[bodies]]\nkind = "string"\nstart = [0, 0, 0]\nend = [1, 0, 0]\ncount = 3\nmass = 1\nstiffness = 1\n'
     '[[bodies]]\nshape = "box:1,0.1,0.1"\n', "bodies[1] is a tet body after bodies[0] (kind = \"string\")"),
])
def test_bad_structure_scene_files_are_one_line_naming_the_key_path(tmp_path, capsys, text, message):
    (tmp_path / "scene.toml").write_text(text)
    status, _, err = run(capsys, tmp_path / "scene.toml", "--duration", "0")
    assert status == 2 and err.count("\n") == 1
    assert message in err, err


# ---------------------------------------------------------------------- a scene file and the flags
def test_the_readme_beam_from_a_scene_file_equals_the_flags_bit_for_bit(tmp_path, capsys):
    flags = ["box:1,0.1,0.1", "--size", "0.05", "--pin", "-0.51,-1,-1,-0.49,1,1", "--dt", "0.01", "--blender"]
    for name, argv in (("flags", flags), ("file", [BEAM])):
        status, _, err = run(capsys, *argv, "--duration", "0.1", "--out", tmp_path / name, *END_STATE)
        assert status == 0, err
    by_flags, by_file = (load_checkpoint(tmp_path / name / "checkpoint.npz") for name in ("flags", "file"))
    assert by_file.step == by_flags.step == 10
    assert by_file.x.tobytes() == by_flags.x.tobytes() and by_file.v.tobytes() == by_flags.v.tobytes()
    for frame in ("frame_0002.vtu", "surface.pc2"):
        assert (tmp_path / "file" / frame).read_bytes() == (tmp_path / "flags" / frame).read_bytes()


def test_the_command_a_manifest_records_remakes_the_run_bit_for_bit(tmp_path, capsys, monkeypatch):
    # The README's beam scene, as a user runs it: a relative scene path and a relative output folder.
    (tmp_path / "beam.toml").write_bytes(BEAM.read_bytes())
    assert run(capsys, "beam.toml", "--duration", "0.1", "--out", "beam_run", "--no-progress")[0] == 0
    manifest = read_manifest(tmp_path / "beam_run")
    files = {name: (tmp_path / "beam_run" / name).read_bytes() for name in manifest["files"]}
    assert "frame_0002.vtu" in files and "surface.pc2" in files
    monkeypatch.chdir(tmp_path.parent)  # made again from elsewhere: the manifest says where the command ran
    monkeypatch.chdir(manifest["working_directory"])
    status, _, err = run(capsys, *manifest["command"][1:], "--overwrite")
    assert status == 0, err
    again = read_manifest(tmp_path / "beam_run")
    assert again["scene"] == manifest["scene"] and again["files"] == manifest["files"]
    for name, data in files.items():  # every frame file, byte for byte
        assert (tmp_path / "beam_run" / name).read_bytes() == data, name


def test_flags_override_the_single_body_and_the_run_and_the_manifest_records_the_resolved_scene(tmp_path, capsys):
    status, out, err = run(capsys, BEAM, "--E", "2e6", "--dt", "0.02", "--duration", "0.04", "--gravity", "0,0,-1",
                           "--set", "bodies[0].material.density=900", "--out", tmp_path, "--no-progress")
    assert status == 0, err
    assert "E 2e+06 Pa" in out and "density 900 kg/m^3" in out and "dt = 0.02 s, 2 steps" in out
    scene = read_manifest(tmp_path)["scene"]
    assert scene["bodies"][0]["material"] == {"E": 2e6, "nu": DEFAULT_NU, "density": 900.0}  # defaults filled in
    assert scene["integrator"]["dt"] == 0.02 and scene["duration"] == 0.04
    assert scene["fields"] == [{"type": "gravity", "g": [0.0, 0.0, -1.0]}]
    assert scene["output"]["folder"] == str(tmp_path) and scene["output"]["blender"] is True
    assert json.loads(json.dumps(scene)) == read_scene(BEAM, overrides=[
        "bodies[0].material.E=2e6", "bodies[0].material.density=900", "integrator.dt=0.02", "duration=0.04",
        f"output.folder='{tmp_path}'", "fields=[{type='gravity', g=[0, 0, -1]}]"])


def test_a_body_flag_is_refused_for_a_scene_of_several_bodies(capsys):
    status, _, err = run(capsys, BALL, "--E", "2e6", "--duration", "0")
    assert status == 2
    assert "--E is ambiguous" in err and "2 bodies" in err and "--set bodies[N].material.E=VALUE" in err


def test_scene_defaults_are_the_flags_defaults():
    parser = build_parser()
    for flags, prefix in ((BODY_FLAGS, "bodies[0]."), (RUN_FLAGS, "")):
        for dest, key_path in flags.items():
            *tables, name = [part for part in split_key_path(prefix + key_path) if not isinstance(part, int)]
            spec = SCENE
            for table in tables:
                spec = spec.keys[table].table
            default = parser.get_default(dest) if dest != "nu" else DEFAULT_NU
            if spec.keys[name].default is not None and default is not None:
                assert spec.keys[name].default == default, (dest, key_path)


# ---------------------------------------------------------------------- supports and obstacles
def test_prescribed_motion_and_sliding_are_exact(tmp_path, capsys):
    supports = ('supports=[{type="prescribed", region="xmin", components="xyz", velocity=[0, 0, 0.5]}, '
                '{type="sliding", region="xmax", normal="y"}]')
    state, model = end_state(capsys, BEAM, tmp_path, "--duration", "0.05", "--set", supports)
    x0 = model.rest_positions
    moved, sliding = np.isclose(x0[:, 0], -0.5), np.isclose(x0[:, 0], 0.5)
    np.testing.assert_allclose(state.x[moved], x0[moved] + [0, 0, 0.5 * state.t], rtol=0, atol=1e-15)
    assert np.array_equal(state.x[sliding, 1], x0[sliding, 1]) and not np.allclose(state.x[sliding], x0[sliding])


@pytest.mark.parametrize("response", ["penalty", "projection"])
def test_a_beam_dropped_on_a_ground_plane_stops_on_it(tmp_path, capsys, response):
    ground = f'obstacles=[{{type="plane", point=[0, 0, -0.1], response="{response}"}}]'
    state, model = end_state(capsys, BEAM, tmp_path, "--duration", "0.3", "--set", "supports=[]", "--set", ground)
    # Falling 5 cm from rest takes 0.1 s; a body passing through the plane would be 30 cm below it by 0.3 s.
    assert state.x[:, 2].min() > -0.1 - 5e-3  # the penalty layer lets nodes sink a few mm; projection none
    assert state.x[:, 2].mean() < -0.03  # it did fall (rest: mean z = 0)


def test_a_mesh_file_body_relative_to_the_scene_file_in_millimetres(tmp_path, capsys):
    cube_mesh((4, 1, 1), size=(200.0, 50.0, 50.0)).write(tmp_path / "beam.vtu")  # in mm
    (tmp_path / "scene.toml").write_text('[[bodies]]\nmesh = "beam.vtu"\nunits = "mm"\n'
                                         '[[supports]]\ntype = "pin"\nregion = "x<1"\nunits = "mm"\n'
                                         '[[fields]]\ntype = "gravity"\n')
    state, model = end_state(capsys, tmp_path / "scene.toml", tmp_path / "out", "--duration", "0.02")
    assert np.abs(model.rest_positions).max() == pytest.approx(0.2)  # read as mm: 0.2 m long
    assert state.x[:, 2].min() < -1e-6 and state.step == 20  # the default step of 1 ms


# ---------------------------------------------------------------------- errors name the key path
@pytest.mark.parametrize("override, message", [
    ("bodies[0].material.nu=0.7", "bodies[0].material.nu = 0.7 is not in (-1, 0.5)"),
    ("bodies[0].materal.E=2e6", "bodies[0].materal is not a known key; did you mean material?"),
    ('integrator.dt="fast"', 'integrator.dt = "fast" is a string; expected a number'),
    ("integrator.dt=-0.01", "integrator.dt = -0.01 is not a finite number > 0"),
    ("fields[0].type=wnd", 'fields[0].type = "wnd" is not a known type; did you mean wind?'),
    ("fields[0].g=[0,0]", "fields[0].g = [0, 0] is an array; expected 3 numbers [x, y, z]"),
    ("supports[0].region=x<-5", "supports[0].region = 'x<-5' selects no node; the scene spans [-0.5, 0.5]"),
    ("supports[0].region=wmin", "supports[0].region 'wmin': unknown face 'wmin'"),
    ("bodies[0].alpha=0.5", "bodies[0]: alpha= is the smoothed rung's weight; model='springs' takes none"),
    ("bodies[2].material.E=1", "bodies[2] does not exist (len(bodies) = 1: bodies[0] to bodies[0])"),
    ("output.checkpoint_every=0", "output.checkpoint_every = 0 is not a finite number >= 1"),
    ("bodies[0].shape=ball:1", "bodies[0].shape: unknown shape 'ball'"),
])
def test_bad_values_are_one_line_naming_the_key_path(capsys, override, message):
    status, out, err = run(capsys, BEAM, "--set", override, "--duration", "0")
    assert status == 2 and out == ""
    assert err.startswith("volspring-sim: error: ") and err.count("\n") == 1
    assert message in err, err


@pytest.mark.parametrize("text, message", [
    ('[[bodies]]\nshape = "box:1,0.1,0.1"\n[integrater]\ndt = 0.1\n', "integrater is not a known key; did you "
                                                                      "mean integrator?"),
    ('duration = 1\n', "bodies is missing; expected an array of tables"),
    ('[[bodies]]\nshape = "box:1,0.1,0.1"\nmesh = "b.vtu"\n', "bodies[0] gives mesh and shape; expected one"),
    ('[[bodies]\n', "is not valid TOML"),
    ('[[bodies]]\nshape = "box:1,0.1,0.1"\nzzz = 1\n', "bodies[0].zzz is not a known key; expected one of: name, "),
    ('bodies = []\n', "bodies = [] holds no body; expected at least one [[bodies]] table"),
    ('[[bodies]]\nshape = "box:1,0.1,0.1"\n[[fields]]\ntype = "wind"\ndirection = [1, 0, 0]\nrate = -1\n',
     "fields[0].rate = -1.0 is not finite and >= 0"),
])
def test_bad_scene_files_are_one_line_naming_the_key_path(tmp_path, capsys, text, message):
    (tmp_path / "scene.toml").write_text(text)
    status, _, err = run(capsys, tmp_path / "scene.toml", "--duration", "0")
    assert status == 2 and err.count("\n") == 1
    assert message in err, err


def test_set_needs_a_scene_file(capsys):
    status, _, err = run(capsys, "box:0.2,0.05,0.05", "--set", "duration=0")
    assert status == 2 and "--set sets a value of a scene file" in err


def test_the_readme_scene_runs_and_its_bodies_land_on_the_plane(tmp_path, capsys):
    import re

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    section = readme[readme.index("## Scene files"):]
    blocks = re.findall(r"```toml\n(.*?)```", section[:section.index("\n## ", 1)], flags=re.S)
    assert len(blocks) == 1, "the README's scene file section has one TOML block"
    (tmp_path / "scene.toml").write_text(blocks[0])
    state, model = end_state(capsys, tmp_path / "scene.toml", tmp_path / "out", "--duration", "0.1")
    assert model.body_count == 2 and read_manifest(tmp_path / "out")["scene"]["obstacles"][0]["type"] == "plane"
    # Gravity brings the bodies (bottoms at z = -0.05) onto the plane z = -0.06 after 0.045 s; 5 mm bounds the
    # penalty layer, while a body falling through would be 2 cm below it by 0.1 s.
    assert -0.06 - 5e-3 < state.x[:, 2].min() < -0.05


def test_a_scene_file_run_resumes_bit_identically(tmp_path, capsys):
    whole, parts = tmp_path / "whole", tmp_path / "parts"
    shorter = ["--set", "bodies[0].size=0.1", "--set", "output.blender=false"]  # 0.1 m tets: a quicker beam
    assert run(capsys, BEAM, *shorter, "--duration", "0.08", "--out", whole, *END_STATE)[0] == 0
    assert run(capsys, BEAM, *shorter, "--duration", "0.04", "--out", parts, *END_STATE)[0] == 0
    status, _, err = run(capsys, BEAM, *shorter, "--duration", "0.08", "--out", parts, *END_STATE,
                         "--resume", parts / "checkpoint.npz")
    assert status == 0, err
    resumed, uninterrupted = (load_checkpoint(folder / "checkpoint.npz") for folder in (parts, whole))
    assert resumed.step == 8 and resumed.x.tobytes() == uninterrupted.x.tobytes()


def test_a_nu_given_to_a_pure_spring_body_is_said_to_be_ignored(capsys):
    no_output = ["--set", "output={}", "--duration", "0", "--quiet"]  # no output folder: nothing to refuse
    status, _, err = run(capsys, BEAM, "--nu", "0.3", *no_output)
    assert status == 0
    assert err.count("\n") == 1 and 'bodies[0].material.nu = 0.3 is ignored by model "springs"' in err
    assert run(capsys, BEAM, "--nu", "0.3", "--model", "smoothed", *no_output) == (0, "", "")
