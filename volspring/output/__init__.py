"""Files that users open elsewhere: VTU/PVD series for ParaView, OBJ sequences and PC2 caches for Blender.

Each writer is a ``simulate`` callback (``writer(frame_index, state)``) that writes one frame per
call, atomically, and refuses states holding NaN or Inf. A :class:`RunFolder` keeps the list of
the files a run wrote in its output folder (pass its ``record`` to the writers), so that the next
run into that folder replaces them all and nothing else.
"""

from volspring.output.blender import BlenderWriter, BoundarySurface, read_pc2
from volspring.output.paraview import ParaViewWriter, read_pvd, write_pvd
from volspring.output.run_folder import RunFolder, RunFolderRefused, check_output_folder, read_manifest

__all__ = ["BlenderWriter", "BoundarySurface", "ParaViewWriter", "RunFolder", "RunFolderRefused",
           "check_output_folder", "read_manifest", "read_pc2", "read_pvd", "write_pvd"]
