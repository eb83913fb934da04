"""The report's building blocks: table cells, tables in their scrolling wrapper, figures.

Used by :mod:`validation.report.sections` and :mod:`validation.report.html`; every table of the page is
made by :func:`table` or wrapped by :func:`scroll`, so that none is cut on a narrow screen.
"""

from __future__ import annotations

import html

import numpy as np

from validation.report.summary import volume_ratio

__all__ = ["BENDING_NOTE", "fmt", "image", "refused_row", "scroll", "table", "volume_cell"]

#: Where the page says why bending cases have no volume ratio (:func:`validation.report.sections.bending_note`).
BENDING_NOTE = "bending-volume"


def fmt(value, kind="number") -> str:
    """A table cell: None as a dash, text escaped, ``kind`` "percent" / "percent_small" as signed percents."""
    if value is None:
        return "&ndash;"
    if isinstance(value, str):
        return html.escape(value)
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, (list, tuple)):
        return "(" + ", ".join(fmt(v) for v in value) + ")"
    if kind == "percent":
        return f"{100 * value:+.1f}%"
    if kind == "percent_small":  # two significant digits: integrator errors are often far below 0.1%
        return f"{100 * value:+.2g}%"
    if isinstance(value, (int, np.integer)):
        return str(value)
    return f"{value:.4g}"


def scroll(table_html: str, *, wrap_cells: bool = False) -> str:
    """A table in a wrapper that scrolls sideways when the table is wider than the page; its cells keep
    to one line (numbers) unless ``wrap_cells`` (lists of names)."""
    return f"<div class='table-scroll{' wrap-cells' if wrap_cells else ''}'>{table_html}</div>"


def table(header, rows, *, extra="", wrap_cells: bool = False) -> str:
    """A table of ready cells in its scrolling wrapper (:func:`scroll`); ``extra``: more rows as HTML (a
    refusal spanning the row)."""
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{cell}</td>" for cell in row) + "</tr>" for row in rows)
    return scroll(f"<table><thead><tr>{head}</tr></thead><tbody>{body}{extra}</tbody></table>", wrap_cells=wrap_cells)


def volume_cell(value, reference, *, not_meaningful=False) -> str:
    """A volume change [m^3] as a multiple of the reference's (``1.74&times;``), a dash without a reference,
    or, where the reference's change is bending's cancellation, a link to the note that says why there is none."""
    if not_meaningful:
        return f"<a class='na' href='#{BENDING_NOTE}'>not meaningful: bending</a>"
    ratio = volume_ratio(value, reference)
    return "&ndash;" if ratio is None else f"{ratio:#.3g}&times;"


def refused_row(labels, message, width) -> str:
    """A table row: the cells ``labels`` (ready HTML), then the refusal ``message`` across ``width`` columns."""
    return ("<tr>" + "".join(f"<td>{label}</td>" for label in labels)
            + f"<td colspan='{width}' class='warn' style='text-align: left'>refused: {html.escape(message)}</td></tr>")


def image(figures, key, alt) -> str:
    """The figure ``key`` (a data URI, :func:`validation.report.figures.render_figures`), or nothing without it."""
    if key not in figures:
        return ""
    return f'<figure><img alt="{html.escape(alt)}" src="{figures[key]}"></figure>'
