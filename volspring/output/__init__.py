"""Files that users open elsewhere: VTU/PVD series for ParaView, OBJ sequences and PC2 caches for Blender.

Each writer is a ``simulate`` callback (``writer(frame_index, state)``) that writes one frame per
call, atomically, and refuses states holding NaN or Inf.
"""

from volspring.output.blender import BlenderWriter, BoundarySurface, read_pc2
from volspring.output.paraview import ParaViewWriter, read_pvd, write_pvd

__all__ = ["BlenderWriter", "BoundarySurface", "ParaViewWriter", "read_pc2", "read_pvd", "write_pvd"]
