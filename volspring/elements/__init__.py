"""Element sets: the internal physics of a model, one family of elements per set.

See :mod:`volspring.elements.base` for what a set gives (forces, energy, Jacobian blocks on
its stencil) and how assembly uses it. Built in: :class:`Springs` (edge springs and dampers),
:class:`CorotatedTets` and :class:`NodalStrain` (continuum terms: the smoothed-strain element and
nodal volume preservation, :mod:`volspring.elements.continuum`) and :class:`AngleSprings` (bending at
the joints of node chains: strings, hair) with :class:`DihedralSprings` (their twist), both in
:mod:`volspring.elements.angles`.
"""

from volspring.elements.angles import AngleSprings, DihedralSprings
from volspring.elements.base import BlockMap, ElementSet, Linearization, OperatorLinearization
from volspring.elements.continuum import CorotatedTets, NodalStrain
from volspring.elements.springs import SpringLinearization, Springs

__all__ = ["AngleSprings", "BlockMap", "CorotatedTets", "DihedralSprings", "ElementSet", "Linearization", "NodalStrain",
           "OperatorLinearization", "SpringLinearization", "Springs"]
