"""Outputs layer: VTK/ParaView time series of periodic solutions and modes (meshio).

``write_animation(solution, model, "out/mode1")`` writes ``out/mode1_0000.vtu ...`` and
``out/mode1.pvd``; ``write_linear_mode(modes, j, model, path)`` does the same for a linear mode.
"""

from .vtk import MeshFields, mesh_fields, write_animation, write_linear_mode

__all__ = ["write_animation", "write_linear_mode", "mesh_fields", "MeshFields"]
