"""Run the validation and write what a user reads: report.html, results.json and VTU files.

The data path reads one way, one module per step::

    results, artefacts = run_validation(cases=..., quick=...)   # runner: cases and studies -> numbers
    images = render_figures(results)                              # figures: matplotlib -> SVG data URIs
    page = render_html(results, images)                           # html: headline, contents, sections
    write_outputs(out, results, artefacts)                        # outputs: VTU, JSON, HTML, each atomic

:func:`validate` does all of it (``volspring-validate`` calls it). :func:`run_validation` returns
the results (plain JSON numbers, every key naming its unit; the layout is in
:mod:`validation.report.runner`) with the arrays for figures and VTU files; :func:`write_outputs`
writes ``DIR/report.html`` (self-contained: the headline, tables, matplotlib figures as SVG),
``DIR/results.json`` and ``DIR/vtu/*.vtu``.
"""

# The names validation/report.py had, importable from here as before (volspring-validate uses
# BUILT_IN and STUDIES); each is defined in the module named.
from validation.report.outputs import read_results, validate, write_outputs
from validation.report.runner import (
    BUILT_IN,
    HELDOUT,
    NOTES,
    SCHEMA,
    STATIC_CASES,
    STUDIES,
    SWEEP_NUS,
    SWEEP_STRAINS,
    UNITS,
    run_validation,
    versions,
)

__all__ = ["SCHEMA", "read_results", "run_validation", "validate", "versions", "write_outputs"]
