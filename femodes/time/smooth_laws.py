"""The smooth laws of a Moreau-Jean step on its local DOFs (cubic springs, penalty contacts), stacked per kind.

Each kind of smooth law is evaluated at once by its stacked law (:mod:`femodes.laws`):
:attr:`SmoothLaws.laws` holds (stacked law, local positions, whether a position repeats) per kind;
the positions are a slice when contiguous (a view: :meth:`SmoothLaws.force` runs in every local
Newton iteration of :class:`~femodes.time.moreau_step.Stepper`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..laws import CubicSpring, PenaltyContact

__all__ = ["SmoothLaws"]


class SmoothLaws:
    """The smooth laws ``smooth`` (pairs ``(law, dof)``) on the local DOFs, ``pos`` mapping a DOF to
    its local position among ``n_local`` local DOFs."""

    def __init__(self, smooth: list, pos: dict, n_local: int):
        cubic = sorted(((law, pos[d]) for law, d in smooth if isinstance(law, CubicSpring)), key=lambda ld: ld[1])
        penalty = [(law, pos[d]) for law, d in smooth if isinstance(law, PenaltyContact)]
        # (stacked law, local positions: a slice when contiguous else an index array, whether one repeats)
        self.laws: list[tuple[Any, Any, bool]] = []
        for kind, group in ((CubicSpring, cubic), (PenaltyContact, penalty)):
            if group:
                idx = np.asarray([i for _, i in group], dtype=int)
                loc: Any = idx
                if np.array_equal(idx, np.arange(idx[0], idx[0] + idx.size)):
                    loc = slice(int(idx[0]), int(idx[0]) + idx.size)
                repeats = not isinstance(loc, slice) and np.unique(idx).size < idx.size
                self.laws.append((kind.stack(law for law, _ in group), loc, repeats))
        #: one kind of law, one law on every local DOF
        self.everywhere = (len(self.laws) == 1 and isinstance(self.laws[0][1], slice)
                           and self.laws[0][1] == slice(0, n_local))
        #: what :meth:`force` calls: the stacked law itself when it covers every local DOF
        self.force_fn = self.laws[0][0].force if self.everywhere else self.force

    def force(self, qS: np.ndarray):
        """Local smooth forces (cubic + penalty) and derivatives on the local DOFs."""
        if self.everywhere:  # one kind of law, one on every local DOF
            return self.laws[0][0].force(qS)
        f = np.zeros(qS.shape)
        df = np.zeros(qS.shape)
        for law, loc, repeats in self.laws:
            fl, dfl = law.force(qS[loc])
            if repeats:  # several laws on one DOF (cubic springs): accumulate
                np.add.at(f, loc, fl)
                np.add.at(df, loc, dfl)
            else:
                f[loc] += fl
                df[loc] += dfl
        return f, df

    def potential(self, qS: np.ndarray) -> np.ndarray:
        """Potential energy of the smooth laws, ``qS`` of shape ``(..., |S|)`` -> shape ``(...)``."""
        E = np.zeros(qS.shape[:-1])
        for law, loc, _ in self.laws:
            E += np.sum(law.potential(qS[..., loc]), axis=-1)
        return E
