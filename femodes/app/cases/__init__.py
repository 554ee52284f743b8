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

The full schema, every table and key: :doc:`/howto/case-files`; commented examples:
``examples/cases/*.toml``.
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
