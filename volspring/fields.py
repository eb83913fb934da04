"""Force fields under their 0.1 path, kept for one release: they live in :mod:`volspring.forces`."""


def __getattr__(name):
    from volspring import forces
    from volspring._deprecation import deprecated_alias

    names = ("Wind", "PointAttractor", "PointRepulser", "Vortex", "CallableForce", "POINT_FALLOFFS")
    return deprecated_alias(__name__, name, {n: (f"volspring.forces.{n}", getattr(forces, n)) for n in names})
