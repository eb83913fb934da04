"""Element sets: the internal physics of a model, one family of elements per set.

See :mod:`volspring.elements.base` for what a set gives (forces, energy, Jacobian blocks on
its stencil) and how assembly uses it. Built in: :class:`Springs` (edge springs and dampers).
"""

from volspring.elements.base import BlockMap, ElementSet, Linearization
from volspring.elements.springs import SpringLinearization, Springs

__all__ = ["BlockMap", "ElementSet", "Linearization", "SpringLinearization", "Springs"]
