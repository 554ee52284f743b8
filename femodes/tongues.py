"""Analyses layer: the branch inside a tongue of internal resonance (:func:`tongue_branch`).

Past grazing, :func:`femodes.nonlinear_mode` follows the contact-phase family by its frequency
and steps over the tongues of internal resonance it meets (``branch.internal_resonances``). A
lightly damped forced response can be caught by such a tongue instead: as the damping falls its
peak climbs the tongue at nearly constant frequency while another mode takes the energy (the 2-D
blade of ``examples/resonance_on_backbones.py``: mode 2 near 5:1). The tongue's own branch is what
a continuation in the energy follows (it is what catches an energy continuation at grazing): it
is traced here from the family's last orbit below the tongue, and
:func:`femodes.compare_resonance` measures forced peaks against it.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from .analyses import branch_from_continuation, nonlinear_mode_options
from .hbm.problems import NonlinearModeProblem
from .resonance import point_shares
from .results import Branch
from .solvers import ContinuationOptions, continuation
from .solvers.checks import entry_point

__all__ = ["tongue_branch"]

log = logging.getLogger(__name__)


def _start(backbone: Branch, k: int) -> int:
    """Index of the backbone's orbit that starts the tongue ``k``'s branch: the highest frequency
    below the tongue's first (on a contact-phase family the frequency rises with the energy)."""
    tongues = backbone.internal_resonances
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not -len(tongues) <= k < len(tongues):
        raise ValueError(f"tongue_branch: tongue must be an index into backbone.internal_resonances (it lists "
                         f"{len(tongues)}), got {k!r}")
    w0 = float(np.nanmin(np.asarray(tongues[k]["omega"], dtype=float)))
    below = np.flatnonzero(backbone.omega < w0)
    if not below.size:
        raise ValueError(f"tongue_branch: the backbone has no orbit below tongue {k}'s first frequency {w0:g}")
    return int(below[np.argmax(backbone.omega[below])])


@entry_point("tongue_branch")
def tongue_branch(backbone: Branch, tongue: int = 0, energy_max: float | None = None, *,
                  options: ContinuationOptions | None = None) -> Branch:
    """The branch of the free system inside a tongue of internal resonance of ``backbone``.

    Parameters
    ----------
    backbone : Branch
        A nonlinear mode past grazing (:func:`femodes.nonlinear_mode`) that lists the tongue in
        ``backbone.internal_resonances``; computed with the default projection.
    tongue : int
        Index of the tongue in ``backbone.internal_resonances``.
    energy_max : float, optional
        Energy at which the branch ends (it starts at the backbone's last orbit below the tongue);
        default: the end of the backbone's energy span.
    options : ContinuationOptions, optional
        As for :func:`femodes.nonlinear_mode`.

    Returns
    -------
    Branch
        A continuation in the energy from that orbit (``kind == "nonlinear mode"``), which climbs
        the tongue; ``meta["family"] == "internal resonance"``, ``meta["tongue"]`` the index,
        ``meta["modes"]`` and ``meta["shares"]`` the other modes holding more than 5 % of the
        energy at its last orbit, largest first.
    """
    if not isinstance(backbone, Branch) or backbone.kind != "nonlinear mode" or backbone.model is None:
        raise TypeError("tongue_branch: backbone must be a Branch from femodes.nonlinear_mode (with its model), got "
                        f"{getattr(backbone, 'kind', type(backbone).__name__)!r}")
    if not backbone.internal_resonances:
        raise ValueError("tongue_branch: the backbone lists no tongue of internal resonance (backbone."
                         "internal_resonances is empty); only a period-driven nonlinear mode past grazing has them")
    i = _start(backbone, tongue)
    e0 = float(backbone.energy[i])
    span = backbone.meta.get("energy_span", [e0, float(np.max(backbone.energy))])
    e1 = float(span[1]) if energy_max is None else float(energy_max)
    if not (math.isfinite(e1) and e1 > e0):
        raise ValueError(f"tongue_branch: energy_max must be above the start orbit's energy {e0:g} (the backbone's "
                         f"last orbit below the tongue), got {e1!r}")
    mode = int(backbone.meta.get("mode", 1))
    model = backbone.model
    h = backbone.harmonics
    problem = NonlinearModeProblem(model, h, mode, reference_energy=e0)
    x0 = problem.pack(backbone.Q[i], backbone.P[i], float(backbone.omega[i]), float(backbone.xi[i]))
    res = continuation(problem, (math.log10(e0), math.log10(e1)), x0=x0,
                       options=nonlinear_mode_options(problem, x0, options))
    meta = {"mode": mode, "energy_span": [e0, e1], "family": "internal resonance", "tongue": int(tongue),
            "start": {"omega": float(backbone.omega[i]), "energy": e0}}
    branch = branch_from_continuation(problem, res, kind="nonlinear mode", model=model, meta=meta)
    if not branch.success:
        log.warning("tongue_branch: the branch of tongue %d ends short of the energy %.6g: %s", tongue, e1, branch.message)
    if len(branch):
        f, _ = point_shares(branch, len(branch) - 1)
        others = [j for j in np.argsort(f)[::-1] if j != mode - 1 and f[j] > 0.05]
        branch.meta["modes"] = [int(j) + 1 for j in others]
        branch.meta["shares"] = [float(f[j]) for j in others]
    return branch
