"""Discretise layer: where each Fourier coefficient sits (the layout of :class:`~femodes.hbm.Harmonics`).

One signal has the coefficients ``[c0, c1, s1, c2, s2, ..., cH, sH]`` (``n_coef = 2H + 1``; ``c_k``
at row ``2k - 1``, ``s_k`` at row ``2k``); ``n`` signals are stored harmonic-major as ``Q`` of shape
``(n_coef, n)`` and the global vector is ``Q.ravel()`` (the conventions of
:mod:`femodes.hbm.harmonics`). Only this layout (and ``DofMap`` for the DOFs) computes offsets.
"""

from __future__ import annotations

import numpy as np

from ..solvers.checks import check_int

__all__ = ["HarmonicLayout", "read_only"]


def read_only(a: np.ndarray) -> np.ndarray:
    """``a`` made read-only (the cached arrays of a :class:`~femodes.hbm.Harmonics` are shared)."""
    a.setflags(write=False)
    return a


def _harmonic_numbers(k, lowest: int, H: int) -> np.ndarray:
    """``k`` as an integer array, checked to lie in ``[lowest, H]``."""
    k_arr = np.asarray(k)
    if k_arr.dtype.kind not in "iu":
        raise TypeError(f"harmonic number must be an integer, got {k!r}")
    if np.any(k_arr < lowest) or np.any(k_arr > H):
        raise ValueError(f"harmonic number must lie in [{lowest}, {H}], got {k!r}")
    return k_arr


class HarmonicLayout:
    """The rows of the coefficients of a :class:`~femodes.hbm.Harmonics` (``h.layout``): which row
    holds which harmonic, where a signal's coefficient sits in the global vector, and the checked
    reshapes between ``Q`` (``(n_coef, n)``) and ``Q.ravel()``."""

    __slots__ = ("_h",)

    def __init__(self, harmonics):  # the Harmonics whose room this is
        self._h = harmonics

    def __repr__(self) -> str:
        return f"{self._h!r}.layout"

    def size(self, n: int) -> int:
        """Length ``n_coef * n`` of the global vector of an ``n``-signal model."""
        return self._h.n_coef * check_int("n", n, 0)

    def cos_index(self, k: int) -> int:
        """Row of ``c_k`` (``k = 0`` gives the mean ``c0`` at row 0): ``max(2k - 1, 0)``; one
        harmonic ``k`` in ``[0, H]`` (several: :meth:`cos_rows`)."""
        return int(self.cos_rows(check_int("k", k, 0))[()])

    def sin_index(self, k: int) -> int:
        """Row ``2k`` of ``s_k``; one harmonic ``k`` in ``[1, H]`` (several: :meth:`sin_rows`)."""
        return int(self.sin_rows(check_int("k", k, 1))[()])

    def cos_rows(self, ks) -> np.ndarray:
        """Rows of ``c_k`` for an integer array ``ks`` in ``[0, H]`` (an array of the same shape)."""
        return np.maximum(2 * _harmonic_numbers(ks, 0, self._h.n_harmonics) - 1, 0)

    def sin_rows(self, ks) -> np.ndarray:
        """Rows of ``s_k`` for an integer array ``ks`` in ``[1, H]``."""
        return 2 * _harmonic_numbers(ks, 1, self._h.n_harmonics)

    @property
    def harmonic_of(self) -> np.ndarray:
        """Harmonic number of each coefficient row: ``[0, 1, 1, 2, 2, ..., H, H]``."""
        return self._h.memo("harmonic_of", lambda: read_only((np.arange(self._h.n_coef) + 1) // 2))

    @property
    def is_sine(self) -> np.ndarray:
        """Boolean mask of the sine rows (even rows ``>= 2``)."""
        def build():
            rows = np.arange(self._h.n_coef)
            return read_only((rows > 0) & (rows % 2 == 0))

        return self._h.memo("is_sine", build)

    def global_index(self, j, dofs, n: int):
        """Position ``j*n + dof`` of coefficient row ``j`` of signal ``dof`` in ``Q.ravel()``.

        ``j`` and ``dofs`` broadcast against each other (numpy rules), e.g.
        ``global_index(np.arange(h.n_coef)[:, None], dofs, n)`` gives the
        ``(n_coef, len(dofs))`` array of all unknowns of ``dofs``.

        Raises
        ------
        ValueError
            If a row is outside ``[0, n_coef)`` or a DOF outside ``[0, n)``.
        """
        n = check_int("n", n, 1)
        j_arr = np.asarray(j)
        d_arr = np.asarray(dofs)
        for name, arr, upper in (("j", j_arr, self._h.n_coef), ("dofs", d_arr, n)):
            if arr.size and arr.dtype.kind not in "iu":
                raise TypeError(f"{name} must be integer, got dtype {arr.dtype}")
            if arr.size and (arr.min() < 0 or arr.max() >= upper):
                raise ValueError(f"{name} must lie in [0, {upper}), got {arr!r}")
        out = j_arr.astype(np.intp) * n + d_arr.astype(np.intp)
        return int(out) if out.ndim == 0 else out

    def reshape(self, x, n: int) -> np.ndarray:
        """View a global vector of length ``n_coef * n`` as ``Q`` of shape ``(n_coef, n)``."""
        x = np.asarray(x)
        n = check_int("n", n, 1)
        nc = self._h.n_coef
        if x.ndim != 1 or x.shape[0] != nc * n:
            raise ValueError(f"expected a vector of length n_coef*n = {nc * n}, got shape {x.shape}")
        return x.reshape(nc, n)

    def flatten(self, Q) -> np.ndarray:
        """Global vector ``Q.ravel()`` of coefficients ``Q`` of shape ``(n_coef, n)``."""
        Q = np.asarray(Q)
        self.check_coef(Q, "Q")
        return np.ascontiguousarray(Q).reshape(-1)

    def convert(self, Q, to) -> np.ndarray:
        """Coefficients ``Q`` (shape ``(n_coef, ...)``) of this basis on the basis ``to`` (same
        subharmonic index): harmonics up to ``min(H, H_to)`` copied, missing ones zero, the
        ones beyond ``H_to`` dropped (the L2-best truncation)."""
        h = self._h
        if not isinstance(to, type(h)) or to.subharmonic != h.subharmonic:
            raise ValueError(f"convert: target must be a Harmonics with subharmonic={h.subharmonic}, got {to!r}")
        Q = np.asarray(Q, dtype=float)
        self.check_coef(Q, "Q")
        out = np.zeros((to.n_coef,) + Q.shape[1:])
        m = 2 * min(h.n_harmonics, to.n_harmonics) + 1  # rows [c0; c1; s1; ...; c_m; s_m] of both layouts
        out[:m] = Q[:m]
        return out

    def check_coef(self, Q, name, allow_1d=True):
        """ValueError unless ``Q`` has the shape ``(n_coef,)`` (if ``allow_1d``) or ``(n_coef, n)``."""
        nc = self._h.n_coef
        if Q.ndim not in ((1, 2) if allow_1d else (2,)) or Q.shape[0] != nc:
            raise ValueError(f"{name} must have shape (n_coef,) or (n_coef, n) with n_coef = {nc}, got {Q.shape}")
