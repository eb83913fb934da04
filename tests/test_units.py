"""Length units on input: the unit table, units x scale into metres, and the warning for bodies read too large."""

import argparse
import logging
import math
import warnings

import numpy as np
import pytest

from meshing.units import (LARGE_BODY_DIAGONAL, UNITS, add_unit_arguments, length_factor, scaled_points,
                             warn_if_large)


def test_the_table():
    assert UNITS == {"m": 1.0, "cm": 0.01, "mm": 0.001}


@pytest.mark.parametrize("units, scale, factor", [
    ("m", None, 1.0),
    ("mm", None, 1e-3),
    ("cm", None, 1e-2),
    ("m", 2, 2.0),
    ("cm", 2.5, 0.025),  # both given: units x scale
    ("mm", np.float32(4.0), 4e-3),
])
def test_factor_is_units_times_scale(units, scale, factor):
    # One product of two doubles: exact to the last bit or one rounding, hence 1e-15.
    assert length_factor(units, scale) == pytest.approx(factor, rel=1e-15)


def test_defaults_are_metres():
    assert length_factor() == 1.0


@pytest.mark.parametrize("units", ["inch", "MM", "", None, 1])
def test_unknown_unit_names_the_value_and_the_choices(units):
    with pytest.raises(ValueError, match=rf"units = {units!r} is not a known length unit; "
                                         r"expected one of 'm', 'cm', 'mm'"):
        length_factor(units)


@pytest.mark.parametrize("scale", [0, -1.0, math.nan, math.inf, -math.inf, "2", True, [1.0]])
def test_scale_must_be_a_finite_number_above_zero(scale):
    with pytest.raises(ValueError, match=rf"scale = {scale!r} is not a finite number > 0".replace("[", r"\[")
                       .replace("]", r"\]")):
        length_factor("m", scale)


def test_scaling_that_overflows_is_refused():
    with pytest.raises(ValueError, match=r"body.stl: scaling by 1000 makes coordinates overflow float64: "
                                         r"the largest absolute coordinate is 1e\+306"):
        scaled_points(np.array([[1e306, 0.0, 0.0]]), 1000.0, name="body.stl")


def test_scaling_multiplies():
    points = np.array([[1.0, 2.0, 3.0]])
    np.testing.assert_array_equal(scaled_points(points, 1e-3, name="x"), points * 1e-3)


def _box(diagonal):
    return np.array([[0.0, 0.0, 0.0], [diagonal / math.sqrt(3)] * 3])


def test_a_body_over_ten_metres_read_in_metres_warns_and_logs(caplog):
    with pytest.warns(UserWarning, match=r"body.obj is 12 m across \(bounding-box diagonal\), more than 10 m: "
                                         r"if its coordinates are in millimetres or centimetres, read it with "
                                         r"units=\"mm\" or units=\"cm\" \(on the command line: --units mm\)"):
        warn_if_large(_box(12.0), units="m", scale=None, name="body.obj")
    assert "body.obj is 12 m across" in caplog.text and caplog.records[0].levelno == logging.WARNING


@pytest.mark.parametrize("diagonal, units, scale", [
    (0.99 * LARGE_BODY_DIAGONAL, "m", None),  # below the threshold
    (12.0, "m", 1.0),  # an explicit scale says the size is meant
    (12.0, "mm", None),  # units given: already converted, whatever the size
])
def test_no_warning_when_the_size_is_plausible_or_meant(diagonal, units, scale):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warn_if_large(_box(diagonal), units=units, scale=scale, name="body.obj")


def test_cli_arguments():
    parser = argparse.ArgumentParser()
    add_unit_arguments(parser, applies_to="the input file")
    args = parser.parse_args(["--units", "mm", "--scale", "2"])
    assert length_factor(args.units, args.scale) == pytest.approx(2e-3, rel=1e-15)  # one product
    defaults = parser.parse_args([])
    assert (defaults.units, defaults.scale) == ("m", None)
    assert "the input file" in parser.format_help()
