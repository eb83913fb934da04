"""Renamed and moved public names keep working for one release, each with a warning naming its new home."""

import importlib

import pytest

RENAMED = [
    # (module, old name, canonical module, new name)
    ("volspring", "SpringModel", "volspring", "Model"),
    ("volspring.model", "SpringModel", "volspring", "Model"),
    ("volspring.scene", "Gravity", "volspring.forces", "Gravity"),
    ("volspring.scene", "Drag", "volspring.forces", "Drag"),
    ("volspring.fields", "Wind", "volspring.forces", "Wind"),
    ("volspring.fields", "PointAttractor", "volspring.forces", "PointAttractor"),
    ("volspring.fields", "CallableForce", "volspring.forces", "CallableForce"),
    ("volspring.mesh", "TetMesh", "meshing", "TetMesh"),
    ("volspring.mesh", "signed_tet_volumes", "meshing.geometry", "signed_tet_volumes"),
    ("volspring.mesh", "ZERO_VOLUME", "meshing.tolerances", "ZERO_VOLUME"),
    ("volspring.units", "UNITS", "meshing.units", "UNITS"),
    ("volspring.topology", "SpringTopology", "meshing", "SpringTopology"),
    ("volspring.assembly", "rigid_body_modes", "meshing.geometry", "rigid_body_modes"),
    ("validation", "solve_static", "validation", "solve_fem_static"),
    ("validation", "solve_modes", "validation", "solve_fem_modes"),
    ("validation.fem", "solve_static", "validation.fem", "solve_fem_static"),
    ("validation.fem_assembly", "stiffness_matrix", "validation.fem_assembly", "fem_stiffness_matrix"),
    ("validation.fem_solvers", "SolverInfo", "validation.fem_solvers", "ReferenceInfo"),
]


@pytest.mark.parametrize("module, old, home, new", RENAMED)
def test_an_old_name_warns_names_the_new_one_and_is_the_same_object(module, old, home, new):
    with pytest.warns(DeprecationWarning, match=rf"{module}\.{old} is deprecated and will be removed in volspring "
                                                rf"0\.3\.0; use .*{new}") as caught:
        value = getattr(importlib.import_module(module), old)
    assert value is getattr(importlib.import_module(home), new)
    assert caught[0].filename == __file__  # the warning points at the caller


def test_unknown_names_are_still_attribute_errors():
    import volspring
    import volspring.mesh

    for module in (volspring, volspring.mesh):
        with pytest.raises(AttributeError, match="has no attribute 'no_such_name'"):
            module.no_such_name  # noqa: B018


def test_the_former_assembly_functions_warn_and_give_what_the_pattern_methods_give():
    import numpy as np

    import volspring.assembly as assembly
    from volspring import Material, Model

    from conftest import cube_mesh

    model = Model.from_mesh(cube_mesh((2, 1, 1)), Material(1e6, 0.3, 1000.0), damping_ratio=0.1)
    pattern = assembly.BlockPattern(model)
    x = model.rest_positions * 1.01
    new = pattern.linearize(x, stiffness_scale=2.0)
    with pytest.warns(DeprecationWarning, match=r"linearize_springs is deprecated.*BlockPattern\.linearize"):
        old = assembly.linearize_springs(pattern, x, stiffness_scale=2.0)
    assert np.array_equal(old.forces, new.forces) and np.array_equal(old.blocks, new.blocks)
    with pytest.warns(DeprecationWarning, match=r"stiffness_times is deprecated.*BlockPattern\.dfdx_times"):
        product = assembly.stiffness_times(pattern, new, x)
    assert np.array_equal(product, pattern.dfdx_times(new, x))
