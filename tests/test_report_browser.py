"""report.html in a real browser: Debian's headless Chromium lays the page out at 760 and 1400 px and
nothing may stick out sideways (wide tables scroll inside their wrapper) and every figure must decode.

The report holds a user's sweep too (four runs of ``examples/scenes/beam_vs_fem.toml``), so the trade-curve
section is laid out with the rest. Slow (a --quick validation run, about 30 s, then two browser runs of a few
seconds); skipped when no Chromium is installed (Debian: ``apt-get install chromium``). No browser-driver
package: Chromium's own ``--dump-dom`` prints the page after a small script, added to a copy of the report, has
measured it.
"""

import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from validation.cli import main
from validation.report import BUILT_IN, STUDIES

SCENES = Path(__file__).resolve().parents[1] / "examples" / "scenes"

BROWSERS = ("chromium", "chromium-browser", "google-chrome")
CHROMIUM = next((found for found in map(shutil.which, BROWSERS) if found), None)

pytestmark = [
    pytest.mark.slow,
    pytest.mark.browser,
    pytest.mark.skipif(CHROMIUM is None, reason="no headless browser: none of " + ", ".join(BROWSERS) + " is on "
                       "PATH (Debian: apt-get install chromium)"),
]

# Run on the load event (after the figures have decoded): every element that reaches past the right edge of
# the window, unless an ancestor scrolls sideways (a table in its wrapper), the wrappers themselves, the
# page's own scroll width and the figures' decoded sizes, written into the DOM that --dump-dom prints.
PROBE = """
window.addEventListener('load', () => {
  const width = document.documentElement.clientWidth;
  const scrolls = (el) => ['auto', 'scroll'].includes(getComputedStyle(el).overflowX);
  const sticking = [];
  for (const el of document.body.querySelectorAll('*')) {
    if (el.id === 'probe' || el.getBoundingClientRect().right <= width + 0.5) continue;
    let ancestor = el.parentElement;
    while (ancestor && ancestor !== document.body && !scrolls(ancestor)) ancestor = ancestor.parentElement;
    if (!ancestor || ancestor === document.body) sticking.push(el.tagName + ' ' + el.textContent.slice(0, 40));
  }
  const wrappers = [...document.querySelectorAll('.table-scroll')].map((el) => ({
    right: el.getBoundingClientRect().right, scrollWidth: el.scrollWidth, clientWidth: el.clientWidth}));
  const figures = [...document.images].map((img) => ({alt: img.alt, width: img.naturalWidth,
                                                       shown: img.getBoundingClientRect().width}));
  const out = document.createElement('pre');
  out.id = 'probe';
  out.textContent = JSON.stringify({clientWidth: width, scrollWidth: document.documentElement.scrollWidth,
                                    tables: document.querySelectorAll('table').length, sticking, wrappers, figures});
  document.body.appendChild(out);
});
"""


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    from volspring.sweep import run_sweep

    # A small sweep of the compared beam too, so that the page holds a trade-curve section (its table and figure).
    sweep = tmp_path_factory.mktemp("sweep")
    run_sweep(SCENES / "beam_vs_fem.toml", {"bodies[0].size": [0.1], "duration": [0.3], "compare.cache": [False],
                                            "bodies[0].model": ["springs", "smoothed"], "integrator.dt": [0.02, 0.05]},
              sweep)
    out = tmp_path_factory.mktemp("report")
    # --sweep alone runs no case: name the quick run's cases and studies.
    status = main([*BUILT_IN, *STUDIES, "--quick", "--out", str(out), "--cache", str(tmp_path_factory.mktemp("cache")),
                   "--no-progress", "--sweep", str(sweep)])
    assert status == 0
    assert "id='sweep_0'" in (out / "report.html").read_text(encoding="utf-8")
    return out / "report.html"


def layout(page, width, folder) -> dict:
    """What the probe measured of ``page`` (HTML text) in a Chromium window ``width`` px wide."""
    probed = folder / f"probed_{width}.html"
    probed.write_text(page.replace("</body>", f"<script>{PROBE}</script></body>"), encoding="utf-8")
    command = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
               f"--user-data-dir={folder / f'profile_{width}'}", f"--window-size={width},1000",
               "--virtual-time-budget=20000", "--dump-dom", probed.as_uri()]
    done = subprocess.run(command, capture_output=True, text=True, timeout=180)
    found = re.search(r'<pre id="probe">(.*?)</pre>', done.stdout, re.S)
    assert found, f"the probe wrote nothing (exit {done.returncode}): {done.stderr[-2000:]}"
    import html

    return json.loads(html.unescape(found.group(1)))


@pytest.mark.parametrize("width", [760, 1400])
def test_nothing_overflows_sideways(report, width, tmp_path):
    measured = layout(report.read_text(encoding="utf-8"), width, tmp_path)
    assert measured["clientWidth"] == width  # --hide-scrollbars: the window is the layout width
    assert measured["scrollWidth"] <= measured["clientWidth"], measured["sticking"][:10]
    assert measured["sticking"] == []
    wrappers = measured["wrappers"]
    assert len(wrappers) == measured["tables"] > 5  # every table in a wrapper
    assert all(wrapper["right"] <= width + 0.5 for wrapper in wrappers)
    if width == 760:
        # The wrappers do the work: the ladder's 14 columns are wider than a 760 px window and scroll inside it.
        assert any(wrapper["scrollWidth"] > wrapper["clientWidth"] for wrapper in wrappers)
    figures = measured["figures"]
    assert len(figures) >= 5 and all(figure["width"] > 0 for figure in figures), figures  # every SVG decodes
    assert all(figure["shown"] <= width for figure in figures)


def test_the_probe_sees_an_overflow(tmp_path):
    """Negative control: a table without its wrapper, wider than the window, is reported."""
    cells = "".join(f"<td>column {k} of a wide table</td>" for k in range(30))
    page = f"<!DOCTYPE html><html><body><table><tr>{cells}</tr></table></body></html>"
    measured = layout(page, 760, tmp_path)
    assert measured["scrollWidth"] > measured["clientWidth"]
    assert any(entry.startswith("TABLE") for entry in measured["sticking"])
