"""External forces and fields: what acts on a model from outside its element sets.

The protocol (:mod:`volspring.forces.protocol`): ``accumulate(model, x, v, t, out)``, optional
``jacobian(model, x, v, t)`` and ``potential_energy(model, x, t)``. A scene pays only for the
forces it names: ``Scene(model, forces=[Gravity(), Wind(direction=(1, 0, 0), speed=5.0, rate=0.2)])``.

:class:`Gravity`, :class:`Drag`, :class:`Wind`
    uniform, mass-proportional (:mod:`volspring.forces.uniform`).
:class:`PointAttractor`, :class:`PointRepulser`, :class:`Vortex`
    point fields (:mod:`volspring.forces.point`).
:class:`CallableForce`
    a user function ``f(x, v, t) -> (n, 3)`` forces [N], checked for shape and finiteness.
:class:`PointLoads`
    constant node forces (lumped tractions, point loads), conservative.

Contact with obstacles and between bodies is a force too (:mod:`volspring.collision`).
"""

from volspring.forces.point import POINT_FALLOFFS, PointAttractor, PointRepulser, Vortex
from volspring.forces.protocol import Force, HasJacobian, HasPotential, as_force
from volspring.forces.uniform import Drag, Gravity, Wind
from volspring.forces.user import CallableForce, PointLoads

__all__ = ["POINT_FALLOFFS", "CallableForce", "Drag", "Force", "Gravity", "HasJacobian", "HasPotential",
           "PointAttractor", "PointLoads", "PointRepulser", "Vortex", "Wind", "as_force"]
