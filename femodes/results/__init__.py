"""Results layer: ``Branch`` (a continued family of periodic solutions) and ``PeriodicSolution``.

A solution is stored by its Fourier coefficients; everything else (time histories, contact forces,
penetration, tension, energy) is evaluated from them. Branches save to ``.npz`` (always
available, never pickled) or ``.h5`` (with h5py) and load back with :func:`load_branch`.

Files are written by :mod:`femodes.store` (atomic writes; the checkpoint journal of long runs).
The package: :mod:`.solution` (``PeriodicSolution``), :mod:`.branch` (``Branch`` and saving it),
:mod:`.branch_file` (``load_branch``), :mod:`.bifurcation`, :mod:`.error_estimate`
(``ErrorEstimate``) and :mod:`.contacts` (``ContactInfo``, contact quality).
"""

from __future__ import annotations

from .bifurcation import BIFURCATION_KINDS, Bifurcation
from .branch import FORMAT_VERSION, Branch
from .branch_file import load_branch
from .contacts import ContactInfo, contact_differences
from .error_estimate import ERROR_METHODS, ERROR_SOURCES, ErrorEstimate
from .solution import PeriodicSolution

__all__ = ["PeriodicSolution", "Branch", "Bifurcation", "ErrorEstimate", "ERROR_SOURCES", "ERROR_METHODS", "load_branch",
           "contact_differences", "ContactInfo", "FORMAT_VERSION", "BIFURCATION_KINDS"]
