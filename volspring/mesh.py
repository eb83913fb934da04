"""Kept for one release (until 0.3.0): the tet mesh container lives in the geometry layer, :mod:`meshing`.

Each name warns once used and names its canonical home: ``from meshing import TetMesh``
(:mod:`meshing.mesh`: ``TetMesh``, ``TET_EDGES``, ``TET_FACES``), :mod:`meshing.mesh_io`
(``mesh_file_format``, ``PREFERRED_FORMATS``), :mod:`meshing.geometry` (``signed_tet_volumes``) and
:mod:`meshing.tolerances` (``ZERO_VOLUME``, ``LARGEST_COORDINATE``, ``SMALLEST_EXTENT``).
"""

_HOMES = {"TetMesh": "meshing.mesh", "TET_EDGES": "meshing.mesh", "TET_FACES": "meshing.mesh",
          "mesh_file_format": "meshing.mesh_io", "PREFERRED_FORMATS": "meshing.mesh_io",
          "signed_tet_volumes": "meshing.geometry", "ZERO_VOLUME": "meshing.tolerances",
          "LARGEST_COORDINATE": "meshing.tolerances", "SMALLEST_EXTENT": "meshing.tolerances"}


def __getattr__(name):
    import importlib

    from volspring._deprecation import deprecated_alias

    if name not in _HOMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_HOMES[name]), name)
    return deprecated_alias(__name__, name, {name: (f"{_HOMES[name]}.{name}", value)})
