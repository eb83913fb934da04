"""The combinations of a sweep: a grid (the product of lists of values) and random draws from ranges.

A combination is a dict ``{key path: value}`` (key paths as ``volspring-sim --set`` takes them,
:func:`volspring.scene_file.split_key_path`), applied to the scene file as overrides. The grid is the product of
its lists, the first key varying slowest; random draws come from a local :func:`numpy.random.default_rng` of the
seed, one column of ``samples`` draws per key in the order given, so the same seed gives the same values whatever
else the process draws. With both, every grid point is run with every draw (grid x samples combinations).

Examples
--------
>>> sweep_combinations({"integrator.dt": [0.01, 0.02], "bodies[0].model": ["springs", "smoothed"]})
... # doctest: +NORMALIZE_WHITESPACE
[{'integrator.dt': 0.01, 'bodies[0].model': 'springs'}, {'integrator.dt': 0.01, 'bodies[0].model': 'smoothed'},
 {'integrator.dt': 0.02, 'bodies[0].model': 'springs'}, {'integrator.dt': 0.02, 'bodies[0].model': 'smoothed'}]
>>> sweep_combinations(random={"bodies[0].material.E": (1e5, 1e6), "integrator.newton_iterations": (0, 2)},
...                    samples=3, seed=1)  # doctest: +NORMALIZE_WHITESPACE
[{'bodies[0].material.E': 560639.462230231, 'integrator.newton_iterations': 2},
 {'bodies[0].material.E': 955417.3266933417, 'integrator.newton_iterations': 2},
 {'bodies[0].material.E': 229743.65144767036, 'integrator.newton_iterations': 0}]
>>> parse_grid("bodies[0].material.E=1e5,2e5"), parse_range("bodies[0].size=0.05:0.1")
(('bodies[0].material.E', [100000.0, 200000.0]), ('bodies[0].size', (0.05, 0.1)))
"""

from __future__ import annotations

import itertools
import math
import numbers
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

__all__ = ["parse_grid", "parse_range", "sweep_combinations"]


def sweep_combinations(grid: Mapping[str, Sequence[Any]] | None = None, *,
                       random: Mapping[str, Sequence[float]] | None = None, samples: int | None = None,
                       seed: int = 0) -> list:
    """The combinations of a sweep, in a fixed order.

    Parameters
    ----------
    grid : mapping of str to sequence, optional
        Key path -> the values to try; the combinations are their product (the first key varies slowest).
    random : mapping of str to (2,) sequence, optional
        Key path -> ``(low, high)``: ``samples`` draws, uniform in [low, high) for floats, whole numbers in
        [low, high] (both ends included) when both ends are integers.
    samples : int, optional
        Draws for ``random`` (required with it, >= 1).
    seed : int
        Seed of the local generator of the draws.

    Returns
    -------
    list of dict
        ``{key path: value}`` per combination: the grid's keys first, then the random ones.

    Raises
    ------
    ValueError
        For an empty list of values, a key both in ``grid`` and ``random``, a range with low > high or
        non-finite ends, ``samples`` missing or < 1, or nothing to sweep.
    """
    grid = dict(grid or {})
    random = dict(random or {})
    for key, values in grid.items():
        if isinstance(values, (str, bytes)) or not hasattr(values, "__iter__"):
            raise ValueError(f"grid[{key!r}] = {values!r} is not a list of values")
        if len(list(values)) == 0:
            raise ValueError(f"grid[{key!r}] is an empty list; expected at least one value")
    both = sorted(set(grid) & set(random))
    if both:
        raise ValueError(f"{both[0]} is given both as a grid and as a random range; give it once")
    if not grid and not random:
        raise ValueError("nothing to sweep: give a grid of values or random ranges for at least one key path")
    points = [dict(zip(grid, values)) for values in itertools.product(*(list(v) for v in grid.values()))]
    if not random:
        return points
    if isinstance(samples, bool) or not isinstance(samples, numbers.Integral) or samples < 1:
        raise ValueError(f"samples = {samples!r}; random ranges need a whole number of samples >= 1")
    generator = np.random.default_rng(seed)
    columns = {key: _draws(generator, key, bounds, int(samples)) for key, bounds in random.items()}
    draws = [{key: column[index] for key, column in columns.items()} for index in range(int(samples))]
    return [{**point, **draw} for point in points for draw in draws]


def _draws(generator, key, bounds, samples) -> list:
    try:
        low, high = bounds
    except (TypeError, ValueError):
        raise ValueError(f"random[{key!r}] = {bounds!r} is not a range (low, high)") from None
    for end in (low, high):
        if isinstance(end, bool) or not isinstance(end, numbers.Real) or not math.isfinite(end):
            raise ValueError(f"random[{key!r}] = ({low!r}, {high!r}): expected two finite numbers")
    if low > high:
        raise ValueError(f"random[{key!r}] = ({low!r}, {high!r}): low is above high")
    if isinstance(low, numbers.Integral) and isinstance(high, numbers.Integral):
        return [int(value) for value in generator.integers(low, high, endpoint=True, size=samples)]
    return [float(value) for value in generator.uniform(low, high, size=samples)]


def parse_grid(text: str) -> tuple:
    """``"KEY.PATH=V1,V2,..."`` -> ``(key path, [values])``, each value read as ``--set`` reads it (a TOML
    value, or a string when it is not one).

    A value that holds commas itself (a shape ``box:1,0.1,0.1``, an array) is written in brackets as a TOML
    array of the values: ``bodies[0].shape=["box:1,0.1,0.1", "box:1,0.2,0.2"]``.
    """
    from volspring.scene_file import SceneFileError, parse_assignment

    key, equals, values = text.partition("=")
    if not equals or not values.strip():
        raise SceneFileError(f"--grid {text!r} is not KEY.PATH=V1,V2,... (e.g. bodies[0].material.E=1e5,2e5)")
    key, parsed = parse_assignment(f"{key}={values}")
    if isinstance(parsed, list) and values.strip().startswith("["):
        return key, parsed
    return key, [parse_assignment(f"{key}={value}")[1] for value in values.split(",")]


def parse_range(text: str) -> tuple:
    """``"KEY.PATH=LOW:HIGH"`` -> ``(key path, (low, high))``, the ends as numbers (integers stay integers)."""
    from volspring.scene_file import SceneFileError, parse_assignment

    key, equals, values = text.partition("=")
    low, colon, high = values.partition(":")
    ends = [parse_assignment(f"{key}={end}")[1] for end in (low, high)] if equals and colon else []
    if len(ends) != 2 or not all(isinstance(end, numbers.Real) and not isinstance(end, bool) for end in ends):
        raise SceneFileError(f"--random {text!r} is not KEY.PATH=LOW:HIGH with two numbers "
                             "(e.g. bodies[0].material.E=1e5:1e6)")
    return parse_assignment(f"{key}=0")[0], tuple(ends)
