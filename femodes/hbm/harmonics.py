r"""Truncated real Fourier series: layout, time grids, operators (and the exact positive part).

A :class:`Harmonics` is the basis (``H``, ``N``, ``nu``); its rooms do the work:
``h.layout`` (:class:`~femodes.hbm.harmonic_layout.HarmonicLayout`: rows and indices),
``h.grid`` (:class:`~femodes.hbm.time_grid.TimeGrid`: time grid, synthesis, analysis),
``h.operators`` (:class:`~femodes.hbm.time_operators.TimeOperators`: ``d/dt``, time shift) and
``h.galerkin`` (:class:`~femodes.hbm.galerkin.GalerkinProjection`: norms, weights, positive part).

Conventions (owned by this module; nobody else computes offsets)
-----------------------------------------------------------------
Phase and time.  Every periodic signal is written in the phase
:math:`\theta = (\omega/\nu)\,t`, where :math:`\omega` is the excitation
frequency and :math:`\nu \ge 1` the subharmonic index, so the base
frequency is :math:`W = \omega/\nu` and the period is
:math:`T = 2\pi\nu/\omega`.

Series.  With :math:`H` harmonics

.. math::

    u(\theta) = c_0 + \sum_{k=1}^{H} \bigl(c_k \cos k\theta + s_k \sin k\theta\bigr).

Coefficient order of one signal: ``[c0, c1, s1, c2, s2, ..., cH, sH]``,
``n_coef = 2H + 1``; ``c_k`` sits at row ``2k - 1`` and ``s_k`` at row ``2k``.

Several signals (``n`` DOFs, or ``m`` contact gaps) are stored *harmonic-major* as ``Q`` of shape
``(n_coef, n)``; the unknowns are ``Q.ravel()`` (C order): row ``j`` of signal ``i`` is entry
``j*n + i``. An operator on the harmonic index (``A``) and one on the DOF index (``B``) combine as
``np.kron(A, B) @ Q.ravel() == (A @ Q @ B.T).ravel()``.

Time grid: ``N = n_time`` phases :math:`\theta_j = 2\pi j/N`, times :math:`t_j = 2\pi\nu j/(\omega N)`.

Projection.  Coefficient ``a`` of a periodic ``f`` is ``norm_a * int_0^{2 pi} f b_a dθ`` with the
basis ``b = [1, cos θ, sin θ, ...]`` and ``norm = [1/2π, 1/π, 1/π, ...]``
(``h.galerkin.projection_norms()``); period averages of products use the weights
``[1, 1/2, 1/2, ...]`` (``h.galerkin.norm_weights()``). ``h.galerkin.positive_part(phi)`` is the
exact projection of ``max(0, phi)`` and its Jacobian, from the sign changes of ``phi``
(:mod:`femodes.hbm.positive_part`; the sampled alternative is ``positive_part_sampled``). The
equations: :doc:`/guide/harmonic-balance`.
"""

from __future__ import annotations

from scipy.fft import next_fast_len

from ..solvers.checks import check_int
from .deprecated import moved_attribute
from .galerkin import GalerkinProjection
from .harmonic_layout import HarmonicLayout
from .time_grid import TimeGrid
from .time_operators import TimeOperators

__all__ = ["Harmonics"]

#: The methods that moved to the rooms of a Harmonics, by their old names (deprecated; found by
#: ``Harmonics.__getattr__`` with a DeprecationWarning until the next release).
_MOVED = {name: f"{room}.{name}" for room, names in (
    ("layout", ("size", "cos_index", "sin_index", "cos_rows", "sin_rows", "harmonic_of", "is_sine", "global_index",
                "reshape", "flatten", "convert", "check_coef")),
    ("grid", ("phases", "period", "times", "frequencies", "synthesis", "grid_operators", "analysis", "to_time",
              "from_time", "evaluate", "most_open_phase")),
    ("operators", ("derivative", "derivative_domega", "time_shift", "shift_generator")),
    ("galerkin", ("projection_norms", "norm_weights", "positive_part", "positive_intervals", "positive_part_sampled")),
) for name in names}

# Largest dense operator (entries) a Harmonics may need: the (N, 2H+1) synthesis and analysis
# matrices are built on first use, so a huge H or N must fail here, naming the argument, and
# not later in numpy ("array is too big") or as a MemoryError. 2**28 float64 = 2 GiB.
_MAX_DENSE = 2**28


def _time_samples(H: int, n_time: int | None) -> int:
    """The number ``N`` of phase samples of a basis with ``H`` harmonics: ``n_time``, checked
    (``N >= 2H + 1``), or by default ``next_fast_len(4H + 1)``; ValueError if the dense
    ``(N, 2H + 1)`` Fourier operators would exceed :data:`_MAX_DENSE` entries."""
    if n_time is None:
        if (2 * H + 1) * (4 * H + 1) > _MAX_DENSE:  # before next_fast_len, which fails for huge H
            raise ValueError(
                f"n_harmonics={H} needs dense ({4 * H + 1} x {2 * H + 1}) Fourier operators of more than "
                f"{8 * _MAX_DENSE / 2**30:.0f} GiB; reduce n_harmonics"
            )
        N = int(next_fast_len(4 * H + 1, real=True))
    else:
        N = check_int("n_time", n_time, 1)
        if N < 2 * H + 1:
            raise ValueError(
                f"n_time must be >= 2*n_harmonics + 1 = {2 * H + 1}, got {n_time!r}"
            )
    if (2 * H + 1) * N > _MAX_DENSE:
        raise ValueError(
            f"n_harmonics={H} with n_time={N} needs dense ({N} x {2 * H + 1}) Fourier operators of "
            f"{8 * (2 * H + 1) * N / 2**30:.3g} GiB (more than {8 * _MAX_DENSE / 2**30:.0f} GiB); "
            "reduce n_harmonics or n_time"
        )
    return N


class Harmonics:
    r"""Truncated real Fourier basis with ``H`` harmonics of the base frequency ``omega/nu``.

    .. math::

        u(\theta) = c_0 + \sum_{k=1}^{H} c_k\cos k\theta + s_k\sin k\theta,
        \qquad \theta = \frac{\omega}{\nu} t.

    Immutable and hashable; dense operators are built lazily and cached
    (cached arrays are returned read-only).

    Parameters
    ----------
    n_harmonics : int
        Number of harmonics ``H >= 0`` (``H = 0``: constants only).
    n_time : int, optional
        Number ``N`` of equidistant phase samples per period.  Must satisfy
        ``N >= 2H + 1`` (the discrete projection reproduces every degree-``H``
        polynomial).  Default: ``scipy.fft.next_fast_len(4H + 1)``.  The rule
        ``N >= 4H + 1`` makes the Galerkin projection of a *cubic* nonlinearity
        alias-free: ``u^3 cos(k theta)`` has degree ``<= 4H`` and the discrete
        orthogonality ``sum_j cos(m theta_j) = 0`` is exact for
        ``0 < |m| < N``.  NLvib (companion code of Krack & Gross, *Harmonic
        Balance for Nonlinear Vibration Problems*, Springer 2019) examples use
        the same ``N = 4H + 1`` for cubic polynomials, citing App. A of
        Woiwode et al., Mech. Syst. Signal Process. 136 (2020) 106503,
        doi:10.1016/j.ymssp.2019.106503.  It is rounded up to a 5-smooth
        (fast FFT) size with :func:`scipy.fft.next_fast_len`.
        Non-polynomial laws are not alias-free for any finite ``N``; pass a
        larger ``n_time`` for them.
    subharmonic : int, optional
        Subharmonic index ``nu >= 1``; the period is ``2 pi nu / omega``.

    Raises
    ------
    TypeError
        If an argument is not an integer (``bool`` and ``float`` are rejected).
    ValueError
        If an argument is out of range.
    """

    __slots__ = ("_H", "_N", "_nu", "_cache", "layout", "grid", "operators", "galerkin")

    #: Where each coefficient sits: rows of a harmonic, global indices, checked reshapes.
    layout: HarmonicLayout
    #: The series in time: phase grid, synthesis and analysis, evaluation, period.
    grid: TimeGrid
    #: ``d/dt`` and the time shift on the coefficients.
    operators: TimeOperators
    #: Projection norms, period-average weights, the projection of ``max(0, phi)``.
    galerkin: GalerkinProjection

    def __init__(self, n_harmonics: int, n_time: int | None = None, subharmonic: int = 1):
        H = check_int("n_harmonics", n_harmonics, 0)
        if H == 0:  # only the mean: no periodic motion can be represented
            raise ValueError("n_harmonics must be >= 1 (a periodic solution needs at least the fundamental), got 0; "
                             "for static equilibria with contact use femodes.static_contact")
        nu = check_int("subharmonic", subharmonic, 1)
        N = _time_samples(H, n_time)
        object.__setattr__(self, "_H", H)
        object.__setattr__(self, "_N", N)
        object.__setattr__(self, "_nu", nu)
        object.__setattr__(self, "_cache", {})
        # the rooms of the basis (each holds this Harmonics: caches live in one place, memo)
        object.__setattr__(self, "layout", HarmonicLayout(self))
        object.__setattr__(self, "grid", TimeGrid(self))
        object.__setattr__(self, "operators", TimeOperators(self))
        object.__setattr__(self, "galerkin", GalerkinProjection(self))

    def __setattr__(self, name, value):
        raise AttributeError(f"{type(self).__name__} is immutable")

    def __delattr__(self, name):
        raise AttributeError(f"{type(self).__name__} is immutable")

    def __repr__(self):
        return f"Harmonics(n_harmonics={self._H}, n_time={self._N}, subharmonic={self._nu})"

    def __eq__(self, other):
        if not isinstance(other, Harmonics):
            return NotImplemented
        return (self._H, self._N, self._nu) == (other._H, other._N, other._nu)

    def __hash__(self):
        return hash((Harmonics, self._H, self._N, self._nu))

    def __reduce__(self):
        return (Harmonics, (self._H, self._N, self._nu))

    def memo(self, key, build):
        """The value cached under ``key``, computed by ``build()`` on first use (the rooms'
        operators, :mod:`femodes.hbm.positive_part`'s tables)."""
        try:
            return self._cache[key]
        except KeyError:
            value = build()
            self._cache[key] = value
            return value

    # ------------------------------------------------------------------ sizes
    @property
    def n_harmonics(self) -> int:
        """Number of harmonics ``H``."""
        return self._H

    @property
    def n_time(self) -> int:
        """Number ``N`` of phase samples per period."""
        return self._N

    @property
    def subharmonic(self) -> int:
        """Subharmonic index ``nu`` (base frequency ``omega/nu``)."""
        return self._nu

    @property
    def n_coef(self) -> int:
        """Number of real coefficients per signal, ``2H + 1``."""
        return 2 * self._H + 1

    def __getattr__(self, name):
        # only for names a Harmonics does not have: the methods that moved to its rooms
        return moved_attribute(self, name, _MOVED)

