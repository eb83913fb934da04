"""Kept for one release (until 0.3.0): length units of input files live in :mod:`meshing.units`."""

from volspring._deprecation import moved_names

__getattr__ = moved_names(__name__, "meshing.units", ("LARGE_BODY_DIAGONAL", "UNITS", "add_unit_arguments",
                                                      "length_factor", "scaled_points", "warn_if_large"))
