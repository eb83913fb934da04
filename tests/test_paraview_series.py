"""The ParaView series as ParaView sees it: exact decimal frame times in the PVD and in each VTU's
``TimeValue``, the spring kinds' names as field data, and the series read back by VTK's own reader."""

import xml.etree.ElementTree as ET
from decimal import Decimal

import meshio
import numpy as np
import pytest

from volspring import SPRING_KINDS, Material, Model, Scene
from volspring.output import ParaViewWriter
from volspring.simulate import simulate
from volspring.structures import cloth_grid, sheet_grid

from conftest import cube_mesh

RUBBER = Material(E=1e5, nu=0.3, density=1000.0)


def pvd_times(path):
    """The ``timestep`` attributes of a PVD, as the text ParaView parses."""
    return [item.get("timestep") for item in ET.parse(path).getroot().iter("DataSet")]


def decimal_steps(dt, steps):
    """repr of the floats nearest k * dt, dt taken as the decimal it is written as: "0.021" for 7 * 0.003."""
    return [repr(float(Decimal(repr(dt)) * k)) for k in steps]


def spring_pair():
    """Two 1 kg nodes on a 100 N/m spring, the far one moving: the smallest model a run can write."""
    scene = Scene(Model.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 1.0], [[0, 1]], stiffness=100.0))
    return scene, scene.initial_state(v=[[0, 0, 0], [1, 0, 0]])


@pytest.mark.parametrize("integrator", ["verlet", "implicit_euler"])  # t + dt, and t0 + h: both sum floats
@pytest.mark.parametrize("dt, frame_steps, frames", [(0.1, 1, 11), (0.003, 7, 6), (1e-5, 10, 4), (0.125, 1, 5)])
def test_pvd_times_are_the_exact_decimal_steps(tmp_path, integrator, dt, frame_steps, frames):
    """Ten steps of 0.1 s are listed as "1.0", not "0.9999999999999999", so ParaView's
    ``set_active_time_value(1.0)`` finds the frame; 0.125 (exact in binary: no drift) is left as it is."""
    scene, start = spring_pair()
    writer = ParaViewWriter(tmp_path, scene.model)
    result = simulate(scene, integrator, duration=(frames - 1) * frame_steps * dt, dt=dt,
                      frame_dt=frame_steps * dt, state=start, callback=writer)
    expected = decimal_steps(dt, range(0, frames * frame_steps, frame_steps))
    assert list(result.step) == list(range(0, frames * frame_steps, frame_steps))
    assert pvd_times(writer.pvd_path) == expected
    assert writer.times == [float(text) for text in expected]
    if dt != 0.125:  # the negative control: summing dt does drift off the decimals here
        assert [repr(float(t)) for t in result.time] != expected


@pytest.mark.parametrize("dt", [0.1, 0.003, 1e-3, 2.5e-4, 1e-5, 7e-4, 1 / 3, 0.1 / 3])
def test_frame_times_stay_on_the_decimal_steps_over_long_runs(dt):
    """300 000 steps summed as the integrators do: every sampled time comes out as k * dt exactly for a
    decimal dt; for a dt that is no decimal (1/3) it stays within the round-off bound and in order."""
    from volspring.output.paraview import _frame_time

    eps = np.finfo(float).eps
    decimal = len(repr(dt)) < 10  # 0.1, 0.003, ...; not the 16-digit floats of 1/3 and 0.1/3
    t, previous = 0.0, -1.0
    for k in range(1, 300_001):
        t += dt
        if k % 997 == 0 or k < 30:
            time = _frame_time(t, k)
            if decimal:
                assert time == float(Decimal(repr(dt)) * k), (k, t, time)
            # (k + 1) eps |t|: the slack _frame_time allows, twice the worst round-off of k additions.
            assert abs(time - t) <= (k + 1) * eps * abs(t) and time > previous
            previous = time


def test_the_issue_example_writes_one_point_zero(tmp_path):
    """The case the issue reports: dt = 0.1, the frame after ten steps used to be "1.0000000000000007"-like."""
    scene, start = spring_pair()
    writer = ParaViewWriter(tmp_path, scene.model)
    result = simulate(scene, "verlet", duration=1.0, dt=0.1, state=start, callback=writer)
    assert result.time[-1] != 1.0  # the integrator's own sum of ten 0.1 s steps
    assert pvd_times(writer.pvd_path)[-1] == "1.0"
    assert meshio.read(tmp_path / "frame_springs_0010.vtu").field_data["TimeValue"].tolist() == [1.0]


def tet_body():
    """A tet body with one shell layer: the tet and spring series, springs of four kinds (tet edges, shell
    springs, their diagonals and edges)."""
    from meshing.shells import add_shells

    mesh = cube_mesh((2, 1, 1), size=(0.2, 0.1, 0.1))
    return Model.from_mesh(add_shells(mesh, layers=1, thickness=0.01), RUBBER), None


def cloth():
    """A cloth: three spring kinds (structural, shear, bend) and the triangle surface series."""
    _, triangles = sheet_grid(1.0, 1.0, 3, 2)
    return cloth_grid(1.0, 1.0, 3, 2, areal_density=0.2, membrane_stiffness=100.0, bend_stiffness=1.0), triangles


@pytest.mark.parametrize("make", [tet_body, cloth])
def test_each_vtu_carries_its_time_and_the_kind_names(tmp_path, make):
    model, triangles = make()
    scene = Scene(model)
    writer = ParaViewWriter(tmp_path, model, triangles=triangles)
    simulate(scene, "implicit_euler", duration=0.03, dt=0.01, callback=writer)
    pvds = sorted(tmp_path.glob("*.pvd"))
    assert len(pvds) == 2  # tets + springs, or springs + surface
    for pvd in pvds:
        root = ET.parse(pvd).getroot()
        assert pvd_times(pvd) == ["0.0", "0.01", "0.02", "0.03"]
        for item in root.iter("DataSet"):
            data = meshio.read(tmp_path / item.get("file"))
            # One Float64 value, written with repr: read back exactly, equal to the PVD's time.
            assert data.field_data["TimeValue"].tolist() == [float(item.get("timestep"))]
            if "kind" in data.cell_data:
                codes = data.cell_data["kind"][0]
                names = {name.removeprefix("kind="): int(value[0]) for name, value in data.field_data.items()
                         if name.startswith("kind=")}
                # Every kind present is named, and only those: name -> code as in SPRING_KINDS.
                assert names == {SPRING_KINDS[code]: int(code) for code in np.unique(codes)}
                assert len(names) == (4 if make is tet_body else 3)


def test_the_cli_writes_decimal_times(tmp_path, capsys):
    """``volspring-sim --dt 0.001 --frame-dt 0.01``: the PVD lists 0.01, 0.02, ... as written, not the sums of 0.001."""
    from volspring.cli import main

    beam = tmp_path / "beam.vtu"
    cube_mesh((4, 1, 1), size=(0.2, 0.05, 0.05)).write(beam)
    status = main([str(beam), "--pin", "-1,-1,-1,0,1,1", "--dt", "0.001", "--frame-dt", "0.01", "--duration", "0.05",
                   "--out", str(tmp_path / "out"), "--quiet"])
    assert status == 0, capsys.readouterr().err
    assert pvd_times(tmp_path / "out" / "frame.pvd") == ["0.0", "0.01", "0.02", "0.03", "0.04", "0.05"]
    assert pvd_times(tmp_path / "out" / "frame_springs.pvd") == ["0.0", "0.01", "0.02", "0.03", "0.04", "0.05"]


@pytest.mark.viz
def test_vtk_reads_the_series(tmp_path):
    """VTK's own XML reader (ParaView's) opens every frame of both series without an error, with the
    PVD's time as ``TimeValue``, the written arrays and the kind names. The PVD itself is read by
    ParaView's vtkPVDReader, not in VTK: its XML is parsed here."""
    pytest.importorskip("vtk", reason="VTK's reader is in the viz extra: pip install volspring[viz]")
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkCommonCore import vtkCommand
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader

    model, _ = tet_body()
    scene = Scene(model)
    writer = ParaViewWriter(tmp_path, model)
    frames = []
    simulate(scene, "implicit_euler", duration=0.3, dt=0.1,
             callback=lambda k, state: (frames.append(state), writer(k, state)))
    errors = []
    for pvd, series in ((writer.pvd_path, "body"), (writer.springs_pvd_path, "springs")):
        items = list(ET.parse(pvd).getroot().iter("DataSet"))
        assert [item.get("timestep") for item in items] == ["0.0", "0.1", "0.2", "0.3"]
        for item, state in zip(items, frames):
            reader = vtkXMLUnstructuredGridReader()
            reader.AddObserver(vtkCommand.ErrorEvent, lambda caller, event: errors.append((pvd.name, event)))
            reader.SetFileName(str(pvd.parent / item.get("file")))
            reader.Update()
            grid = reader.GetOutput()
            fields = grid.GetFieldData()
            assert fields.GetArray("TimeValue").GetNumberOfTuples() == 1
            assert fields.GetArray("TimeValue").GetValue(0) == float(item.get("timestep"))
            n = grid.GetNumberOfPoints()
            # Float64 in, Float64 out: the state comes back bit for bit.
            assert np.array_equal(vtk_to_numpy(grid.GetPoints().GetData()), state.x[:n])
            assert np.array_equal(vtk_to_numpy(grid.GetPointData().GetArray("velocity")), state.v[:n])
            if series == "body":
                assert grid.GetNumberOfCells() == len(model.topology.mesh.tets)
                assert grid.GetCellData().GetArray("volume_ratio") is not None
            else:
                assert np.array_equal(vtk_to_numpy(grid.GetCellData().GetArray("kind")), model.kinds)
                names = {fields.GetArrayName(i): fields.GetArray(i).GetValue(0)
                         for i in range(fields.GetNumberOfArrays()) if fields.GetArrayName(i).startswith("kind=")}
                assert names == {"kind=tet_edge": 0, "kind=shell": 1, "kind=shell_diagonal": 2, "kind=shell_edge": 3}
    assert errors == []
