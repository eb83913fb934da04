"""Collection of the packages' modules for their doctests (pyproject's testpaths name the packages too).

volspring._compiled imports numba at the top (its kernels are compiled functions); without the fast extra it is not
collected, as it is not imported by the package either (volspring.kernels falls back to numpy).
"""

import importlib.util

collect_ignore = [] if importlib.util.find_spec("numba") else ["volspring/_compiled.py"]
