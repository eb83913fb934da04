"""The report page: one self-contained HTML file (tables, figures as SVG data URIs, no script, no links out).

:func:`render_html` lays out the results of :func:`validation.report.runner.run_validation` so that the
first screen holds the conclusion: the title, on a ``--quick`` run a flag saying its meshes are coarse,
the headline (:func:`validation.report.summary.headline`: which model and integrator give which error
at what cost), the run's date, command and versions, and a contents list; then the sections of
:func:`validation.report.sections.report_sections`, the ladder of models first. Volume change is a
ratio to FEM's, and "not meaningful" in bending, where the net change is a cancellation. Every table
sits in a wrapper that scrolls sideways, so that a narrow window (760 px) cuts nothing.
"""

from __future__ import annotations

import html

from validation.report.sections import report_sections
from validation.report.summary import headline

__all__ = ["render_html"]

STYLE = """
body { font-family: sans-serif; max-width: 1360px; margin: 2em auto; padding: 0 1em; color: #222; }
p, ul { max-width: 1150px; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.85em; }
th, td { border: 1px solid #ccc; padding: 0.2em 0.5em; text-align: right; }
th:first-child, td:first-child { text-align: left; }
td { white-space: nowrap; }
td.warn, .wrap-cells td { white-space: normal; }
td.warn { min-width: 24em; }
thead { background: #f0f0f0; }
.table-scroll { max-width: 100%; overflow-x: auto; }
figure { margin: 1em 0; }
img { max-width: 100%; height: auto; }
code { overflow-wrap: anywhere; }
.headline { font-size: 1.1em; line-height: 1.45; }
.quick-flag { background: #fff4d6; border-left: 4px solid #d9a400; padding: 0.4em 0.8em; }
.contents ol { columns: 2 18em; margin: 0.3em 0; max-width: 1150px; }
.small { font-size: 0.85em; color: #555; }
.warn { color: #a00; }
a.na { color: #555; white-space: nowrap; }
"""


def _quick_flag(results) -> str:
    """On a ``--quick`` run: a flag saying that its meshes and studies are coarse."""
    if not results["quick"]:
        return ""
    counts = sorted({case["mesh"]["node_count"] for case in results["cases"].values()})
    meshes = f"meshes of {counts[0]}-{counts[-1]} nodes" if len(counts) > 1 else (
        f"meshes of {counts[0]} nodes" if counts else "coarse meshes")
    return ("<p class='quick-flag'><b>Quick run: coarse.</b> This report was made with <code>--quick</code>: "
            f"{meshes} and short studies, for a first look in about half a minute. Its errors are those of these "
            "coarse meshes and change with resolution (see the refinement study); run without <code>--quick</code> "
            "for the numbers to quote.</p>")


def _contents(sections) -> str:
    items = "".join(f"<li><a href='#{section.anchor}'>{html.escape(section.title)}</a></li>" for section in sections)
    return f"<nav class='contents small' aria-label='Contents'><b>Contents</b><ol>{items}</ol></nav>"


def render_html(results: dict, figures: dict) -> str:
    """The whole report page.

    Parameters
    ----------
    results : dict
        The results of :func:`validation.report.runner.run_validation`, with ``files`` and
        ``command`` as :func:`validation.report.outputs.write_outputs` completes them.
    figures : dict
        Figure key -> data URI (:func:`validation.report.figures.render_figures`).

    Returns
    -------
    str
        The HTML document.
    """
    sections = report_sections(results, figures)
    conclusion = headline(results)
    notes = "".join(f"<li>{html.escape(note)}</li>" for note in results.get("notes", []))
    body = []
    for index, section in enumerate(sections):
        body.append(section.html)
        if index == 0:  # the general notes after the first section, the ladder
            body.append(f"<ul class='small'>{notes}</ul>")
    if not sections:
        body.append(f"<ul class='small'>{notes}</ul>")
    versions_text = ", ".join(f"{k} {v}" for k, v in results["versions"].items())
    command = " ".join(results.get("command") or [])
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><meta name="viewport" content="width=device-width, initial-scale=1">
<title>volspring validation</title>
<style>{STYLE}</style></head><body>
<h1>volspring: the ladder of models against linear-elastic FEM</h1>
{_quick_flag(results)}
{f'<p class="headline">{html.escape(conclusion)}</p>' if conclusion else ''}
<p class="small">{html.escape(results['created'])} &middot; {'quick' if results['quick'] else 'full'} run
&middot; <code>{html.escape(command)}</code><br>{html.escape(versions_text)}</p>
{_contents(sections) if sections else ''}
{''.join(body)}
</body></html>
"""
