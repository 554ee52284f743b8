"""Models layer: finite elements (meshes, axial bars, Euler-Bernoulli beams, 2-D/3-D elastic solids) assembled with scikit-fem."""

from .bar import bar
from .beam import beam
from .material import Material, Section
from .mesh import box_mesh, line_mesh, load_mesh, named_points, rectangle_mesh
from .solid import solid

__all__ = ["bar", "beam", "solid", "Material", "Section", "line_mesh", "load_mesh", "rectangle_mesh", "box_mesh",
           "named_points"]
