"""Models layer: 1-D finite elements (meshes, axial bars, Euler-Bernoulli beams) assembled with scikit-fem."""

from .bar import bar
from .beam import beam
from .material import Material, Section
from .mesh import line_mesh, load_mesh

__all__ = ["bar", "beam", "Material", "Section", "line_mesh", "load_mesh"]
