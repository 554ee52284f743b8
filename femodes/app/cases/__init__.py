"""Application layer: TOML case files for ``femodes run case.toml``.

A case file describes a model and one analysis; :func:`load_case` reads and checks it,
:func:`build_model` turns it into a :class:`femodes.StructuralModel` with the public API and
:func:`run_case` runs the analysis and writes the outputs. Every user mistake raises
:class:`CaseError`, whose message is ``file:line: [table] message`` (the line of the offending
key when it can be found, else of its table).

One idea per module: :mod:`~femodes.app.cases.schema` (tables, keys, types, :class:`CaseError`,
:class:`Case`), :mod:`~femodes.app.cases.validation` (reading and checking a file),
:mod:`~femodes.app.cases.building` (the model), :mod:`~femodes.app.cases.running` (the
analysis), :mod:`~femodes.app.cases.reporting` (summary.txt, plot, animations) and
:mod:`~femodes.app.cases.folders` (the output folders of the commands); every name is
importable from here.

Schema (see ``examples/cases/*.toml`` for commented examples)::

    [mesh]                      # FE models only; either a file ...
    file = "../../meshes/cantilever.msh"   # relative to the case file (gmsh, vtu, ... via meshio;
                                # line meshes for beams and bars, 2-D/3-D meshes for solids)
    # ... or a straight line mesh (beam, bar):
    # length = 1.0
    # n_elements = 40
    # boundaries = { clamp = 0.0, tip = 1.0 }   # named points (x coordinates)
    # grading = 1.0
    # ... or a structured solid mesh (kind = "solid"): a rectangle [0, length] x [0, height]
    # (boundaries "left", "right", "bottom", "top") or, with nz, a box [0, length] x [0, width]
    # x [0, height] (also "front", "back"); see femodes.rectangle_mesh and femodes.box_mesh
    # length = 1.0
    # height = 0.1
    # width = 0.1               # box only
    # nx = 40                   # element divisions along x, y (and z for a box)
    # ny = 4
    # nz = 2                    # makes it a box
    # quad = true               # rectangle: quadrilaterals instead of triangles (default false)
    # hexahedra = true          # box: hexahedra instead of tetrahedra (default false)

    [model]
    kind = "beam"               # "beam" | "bar" | "solid" | "discrete"
    E = 1.0                     # beam, bar, solid
    rho = 1.0                   # beam, bar, solid
    area = 1.0                  # beam, bar
    inertia = 1.0               # beam (required)
    clamped = ["clamp"]         # beam, bar: named points; solid: named boundaries (a string or a list)
    pinned = []                 # beam only
    # order = 1                 # bar, solid: Lagrange order 1 or 2 (P1/P2, Q1/Q2)
    # nu = 0.3                  # solid: Poisson's ratio
    # plane = "stress"          # solid, 2-D meshes: "stress" or "strain"
    # thickness = 1.0           # solid, 2-D meshes
    # supports = { bottom = "u_y" }   # solid: per-component supports (a component or a list)
    # discrete: M = [[1.0]], K = [[1.0]], C = [[0.1]] (C optional), dof_names = ["x"]

    [damping]                   # optional: Rayleigh alpha, beta  or  modal = 0.02
    alpha = 0.02

    [[contact]]                 # 0..n tables
    at = "tip"                  # a name, ["tip", "w"] or a DOF index; solids: a boundary name
    gap = 0.01                  # >= 0
    # direction = [1.0, 0.0]    # solids: contact normal along +x, +y or +z (one contact per node)
    law = "complementarity"     # or "penalty" (then stiffness = ... is required)
    # c = 10.0                  # complementarity parameter (optional)

    [[force]]                   # 0..n harmonic point forces
    at = "tip"                  # solids: ["right", "u_x"] spreads the force over a boundary
    amplitude = 0.004
    # harmonic = 1
    # phase = 0.0

    [[cubic]]                   # 0..n cubic springs
    # at = "tip"
    # k3 = 1.0

    [reduction]                 # optional
    craig_bampton = 10          # number of fixed-interface modes

    [analysis]                  # required
    type = "nonlinear_mode"     # or "frequency_response"
    mode = 1                    # nonlinear_mode
    energy = [1e-4, 3e-3]       # nonlinear_mode: energy span
    # omega = [3.0, 4.2]        # frequency_response: frequency span (rad/s)
    harmonics = 10
    # max_points = 2000         # optional cap on the number of continuation points
    # stability = true          # Floquet multipliers and bifurcations of every point: true ("auto"),
                                # "hill", "shooting" or false (default); see femodes.floquet
    # rtol = 1e-3               # error control: points and folds to this relative error (rtol= of
                                # the analyses; see femodes.estimate_error)
    # energy_unit = "grazing"   # nonlinear_mode: energy in multiples of the grazing energy of the
                                # mode (femodes.grazing_energy), e.g. energy = [0.5, 20]

    [outputs]                   # optional; defaults shown
    plot = true                 # frequency_energy.png (nonlinear mode) / response.png (forced)
    branch = "branch.npz"       # saved Branch (femodes.load_branch); false to skip
    animation = true            # ParaView series of the last point (FE models only)
    gif = false                 # rendered GIF (needs pyvista; skipped with a note otherwise)
    # response_dof = "tip"      # DOF of the response plot (default: the first force)
"""

from __future__ import annotations

from .building import (CaseApi, add_contacts, add_cubic_springs, add_damping, add_forces, as_location, build_model,
                       case_mesh, discrete_model, fe_model)
from .folders import OutputFolderError, command_out_folder, usable_folder
from .reporting import stability_lines, summary_lines, write_animations, write_plot
from .running import CaseResult, analysis_span, run_analysis, run_case
from .schema import (ANALYSES, ARRAY_TABLES, LINE_MESH_KEYS, MODEL_KINDS, SCHEMA, SOLID_DIVISIONS, SOLID_MESH_KEYS,
                     Case, CaseError, key_line, schema_type_error)
from .validation import load_case, parse_case

__all__ = ["CaseError", "Case", "SCHEMA", "load_case", "parse_case", "build_model", "run_case", "key_line",
           "schema_type_error", "ARRAY_TABLES", "MODEL_KINDS", "LINE_MESH_KEYS", "SOLID_MESH_KEYS", "SOLID_DIVISIONS",
           "ANALYSES", "CaseResult", "analysis_span", "stability_lines", "OutputFolderError", "usable_folder",
           "command_out_folder", "CaseApi", "add_contacts", "add_cubic_springs", "add_damping", "add_forces",
           "as_location", "case_mesh", "discrete_model", "fe_model", "run_analysis", "summary_lines",
           "write_animations", "write_plot"]

# the former private names of the one-module cases.py, used by benchmarks and tests
_Api = CaseApi
_location = as_location
_discrete_model = discrete_model
_mesh = case_mesh
_fe_model = fe_model
_add_damping = add_damping
_add_contacts = add_contacts
_add_cubic_springs = add_cubic_springs
_add_forces = add_forces
_run_analysis = run_analysis
_summary_lines = summary_lines
_write_plot = write_plot
_write_animations = write_animations
