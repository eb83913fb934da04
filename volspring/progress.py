"""A ready-made progress bar for :func:`volspring.simulate`, to pass as its ``callback`` (in a notebook, a widget).

The library never prints: :func:`~volspring.simulate` reports progress only through ``callback(frame_index,
state)`` at every frame. :func:`notebook_progress` is such a callback that a caller chooses to pass: a tqdm bar
(``tqdm.auto``: a widget in Jupyter when ipywidgets is installed, a text bar on stderr elsewhere) over the
simulated time, with the rate and the time left. It moves at frames, so a smaller ``frame_dt`` moves it more
often; use it in a ``with`` block (or call :meth:`SimulationProgress.close`) so that the bar is closed however
the run ends.

Examples
--------
>>> import io
>>> from volspring import Model, Scene, simulate
>>> from volspring.progress import notebook_progress
>>> scene = Scene(Model.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 1.0], [[0, 1]], stiffness=100.0))
>>> with notebook_progress(0.1, file=io.StringIO()) as progress:
...     result = simulate(scene, "verlet", duration=0.1, dt=0.01, frame_dt=0.05, callback=progress)
>>> round(progress.bar.n, 12), progress.bar.total
(0.1, 0.1)
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any
from collections.abc import Callable

if TYPE_CHECKING:
    from volspring.scene import State

__all__ = ["SimulationProgress", "notebook_progress"]


class SimulationProgress:
    """A :func:`~volspring.simulate` callback that moves a tqdm bar to each frame's simulated time.

    Parameters
    ----------
    duration : float
        The simulated time of the run [s] (``simulate``'s ``duration``), the bar's 100 %.
    start : float
        The simulated time the run starts from [s] (a resumed state's ``t``).
    then : callable, optional
        Another callback, called as ``then(frame_index, state)`` after the bar moved; what it returns is
        returned (``False`` stops the run).
    desc : str
        The bar's label.
    **options
        Passed on to ``tqdm.auto.tqdm`` (``file=``, ``leave=``, ``position=``...).

    Attributes
    ----------
    bar : tqdm.tqdm
        The bar; ``bar.n`` is the simulated time reached since ``start`` [s].
    """

    def __init__(self, duration: float, *, start: float = 0.0, then: Callable[[int, State], object] | None = None,
                 desc: str = "simulate", **options: Any):
        from tqdm.auto import tqdm

        duration, start = float(duration), float(start)
        if not (math.isfinite(duration) and duration >= 0):
            raise ValueError(f"duration = {duration!r} s is not a finite number >= 0")
        if not math.isfinite(start):
            raise ValueError(f"start = {start!r} s is not a finite number")
        if then is not None and not callable(then):
            raise TypeError(f"then = {then!r} is not callable; expected then(frame_index, state)")
        self.start, self.then = start, then
        options.setdefault("bar_format", "{desc}: {percentage:3.0f}%|{bar}| t = {n:.4g}/{total:.4g} s "
                                         "[{elapsed}<{remaining}]{postfix}")
        self.bar = tqdm(total=duration, desc=desc, unit="s", **options)

    def __call__(self, frame_index: int, state: State) -> object:
        """Move the bar to ``state.t`` (simulated time [s]) and name the frame; then call ``then``."""
        reached = min(max(float(state.t) - self.start, 0.0), self.bar.total)
        self.bar.set_postfix_str(f"frame {frame_index}", refresh=False)
        self.bar.update(reached - self.bar.n)
        return None if self.then is None else self.then(frame_index, state)

    def close(self) -> None:
        """Close the bar (its last state stays shown)."""
        self.bar.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc_info):
        self.close()


def notebook_progress(duration: float, *, start: float = 0.0, then: Callable[..., Any] | None = None,
                      desc: str = "simulate", **options: Any) -> SimulationProgress:
    """A progress bar to pass as :func:`~volspring.simulate`'s ``callback``: a widget in a notebook, text elsewhere.

    Parameters
    ----------
    duration : float
        The ``duration`` given to ``simulate`` [s].
    start : float
        The simulated time of the start state [s] (``state.t`` of a resumed run); default 0.
    then : callable, optional
        Your own callback ``then(frame_index, state)``, called after the bar moved (return ``False`` to stop).
    desc : str
        The bar's label.
    **options
        Passed on to ``tqdm.auto.tqdm``.

    Returns
    -------
    SimulationProgress
        The callback; use it in a ``with`` block, or close it after the run.

    Examples
    --------
    In a notebook (the bar is a widget there)::

        from volspring import simulate
        from volspring.progress import notebook_progress

        with notebook_progress(2.0) as progress:
            result = simulate(scene, "implicit_euler", duration=2.0, dt=1e-3, frame_dt=0.02, callback=progress)
    """
    return SimulationProgress(duration, start=start, then=then, desc=desc, **options)
