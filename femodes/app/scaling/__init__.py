"""Application layer: scaling studies of a case file (``femodes scaling case.toml``).

How do the cost of one Newton iteration and of one continuation point, and the peak memory,
grow with the number of DOFs ``N`` and of harmonics ``H``? :func:`scaling_study` answers this
for a user's own case file: it varies the mesh (``[mesh] n_elements`` of a line mesh, or a
refinement factor of the case's generated mesh: ``n_elements``, or ``nx, ny, nz`` of a solid's
rectangle or box) and ``[analysis] harmonics``, measures every ``(N, H)`` pair in a fresh Python process and fits the
exponents ``t ~ N^a`` (at fixed ``H``) and ``t ~ H^b`` (at fixed ``N``).

Outputs in ``out``: ``scaling.csv`` (one row per case), ``scaling.json`` (settings, records,
fitted exponents), ``scaling.png`` (log-log plots with the fitted slopes in the legends).

Modules: :mod:`.records` (the result types and their table), :mod:`.child` (the child process
that measures one case, and what it measures), :mod:`.report` (fits, CSV/JSON files, the plot),
:mod:`.study` (:func:`scaling_study` and its arguments), :mod:`.command` (``femodes scaling``).
"""

from .command import SCALING_HELP, add_scaling_parser, scaling_cli
from .records import CSV_COLUMNS, ScalingFit, ScalingRecord, ScalingResult
from .report import fit_exponents, plot_scaling
from .study import positive_float_list, positive_int_list, refined_divisions, scaling_study

__all__ = ["ScalingRecord", "ScalingFit", "ScalingResult", "scaling_study", "positive_int_list",
           "positive_float_list", "refined_divisions", "fit_exponents",
           "plot_scaling", "CSV_COLUMNS", "SCALING_HELP", "add_scaling_parser", "scaling_cli"]
