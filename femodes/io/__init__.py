"""Outputs layer: VTK/ParaView time series of periodic solutions and modes (meshio).

``write_animation(solution, model, "out/mode1")`` writes ``out/mode1_0000.vtu ...`` and
``out/mode1.pvd``; ``write_linear_mode(modes, model, path, mode=1)`` does the same for a linear mode (mode numbers
are 1-based, as everywhere in femodes).
"""

from ..fields import MeshFields, mesh_fields
from .vtk import write_animation, write_linear_mode

__all__ = ["write_animation", "write_linear_mode", "mesh_fields", "MeshFields"]
