r"""Analyses layer: the error of a branch from the spatial discretisation (the mesh), by Richardson.

Harmonic balance on a finite-element model has two discretisations: the harmonics (``H -> inf``,
:func:`femodes.estimate_error`) and the mesh (``h -> 0``). This module estimates the second from
the same branch traced on two or three meshes, and attaches it to the fine branch's
:class:`~femodes.results.ErrorEstimate` as its ``"mesh"`` source.

**Matching.** A backbone (nonlinear mode) is compared at equal energy: the coarse branches'
frequencies are interpolated at the fine branch's energies, monotone cubic (PCHIP) in
``log E`` on each run of the branch where the energy is monotone; where two runs cover an energy
(the linear branch below grazing and the contact-phase family just above it), the one nearest in
frequency is taken. Fine points outside a coarse branch's energies get NaN.

**Richardson.** If the frequency error behaves like ``C h^p`` (``h`` the element size), two meshes
with ``r = h_coarse / h_fine > 1`` give the fine branch's error

.. math::  w_h - w_0 \approx \frac{w_h - w_{rh}}{r^p - 1}

with a *stated* order ``p`` (``order=``: 2 for the linear frequencies of P1 bars, 4 for P2 bars
and Hermite beams; references.md). A third, coarser mesh *measures* it: with
``d_1 = w_f - w_c`` and ``d_2 = w_c - w_cc`` (size ratios ``r_1 = h_c / h_f``,
``r_2 = h_cc / h_c``), ``d_2 / d_1 = r_1^p (r_2^p - 1) / (r_1^p - 1)`` (``= r^p`` for equal
ratios), solved for ``p`` at every point. A point is in the asymptotic range when the two changes
have the same sign, contract, and give an order within :data:`ORDER_RANGE`; the branch's order is
the median over those points, and their error is ``|d_1| / (r_1^p - 1)`` with it. The other
points (changes of opposite sign, growing, or an order outside the range) are *not* extrapolated:
their estimate is the larger change ``max(|d_1|, |d_2|)``, and the estimate's ``mesh_method`` says
how many there are. With three meshes and ``order=`` the order is stated and only checked.

Errors are relative to the fine branch's frequency. How well the estimate does on the bar with a
stop (measured): :doc:`/guide/accuracy` (The mesh's share).
"""

from __future__ import annotations

import logging
import math

import numpy as np

from .nonsmooth_modes import family_caveat
from .results import Branch, ErrorEstimate
from .results.branch import fill_in_place

__all__ = ["estimate_mesh_error", "ORDER_RANGE"]

log = logging.getLogger(__name__)

#: Measured orders in ``h`` taken for asymptotic behaviour: a ratio of changes that gives an order
#: outside it is noise or a pre-asymptotic mesh, and the point is not extrapolated.
ORDER_RANGE = (0.5, 8.0)


def estimate_mesh_error(fine: Branch, coarse: Branch, *, coarser: Branch | None = None, order: float | None = None,
                        sizes=None) -> Branch:
    """Attach the mesh's share of the error to ``fine`` (``fine.accuracy.sources["mesh"]``).

    ``fine``, ``coarse`` (and ``coarser``) are the same nonlinear mode traced with the same
    harmonics on successively finer meshes; they are compared at equal energy and the fine
    branch's frequency error ``|w_h - w_0| / w_h`` is extrapolated by Richardson (module
    docstring): with ``order`` stated, or, with ``coarser``, measured per point and as the
    branch's median. The estimate joins the harmonic one if ``fine`` has it
    (:func:`femodes.estimate_error`; an estimate computed later keeps the mesh source), else it
    is an estimate of the mesh alone (:attr:`~femodes.results.ErrorEstimate.covers` says so).

    Parameters
    ----------
    fine, coarse : Branch
        Nonlinear modes (:func:`femodes.nonlinear_mode`) with the same mode and harmonics, on a
        fine and a coarser mesh, with their models attached unless ``sizes`` is given.
    coarser : Branch, optional
        The same on a third, still coarser mesh: the order is measured.
    order : float, optional
        Convergence order ``p`` of the frequency in the element size (``> 0``). Required without
        ``coarser``.
    sizes : sequence of float, optional
        Element sizes of the meshes of ``fine``, ``coarse`` (and ``coarser``), in any common
        unit; by default ``n_elements ** (-1 / dim)`` of each model's mesh (uniform refinement).

    Returns
    -------
    Branch
        A new branch: ``fine`` with :attr:`~femodes.Branch.accuracy` carrying the ``"mesh"``
        source; its ``meta["mesh_error"]`` holds the sizes, the order and whether it was measured,
        and the number of points extrapolated. For this release ``fine`` itself is filled too, as
        before (:func:`~femodes.results.branch.fill_in_place`); use the branch returned.
    """
    branches = [fine, coarse] + ([coarser] if coarser is not None else [])
    _check_branches(branches)
    if order is not None:
        if isinstance(order, bool) or not isinstance(order, (int, float, np.integer, np.floating)) \
                or not math.isfinite(order) or order <= 0:
            raise ValueError(f"estimate_mesh_error: order must be a positive number (the convergence order of the "
                             f"frequency in the element size, e.g. 2 for P1 elements), got {order!r}")
        order = float(order)
    elif coarser is None:
        raise ValueError("estimate_mesh_error: give order= (the convergence order of the frequency in the element "
                         "size, e.g. 2 for P1 bars, 4 for Hermite beams) or coarser= (a branch on a third, coarser "
                         "mesh, from which the order is measured)")
    h = _sizes(branches, sizes)
    if not all(a < b for a, b in zip(h, h[1:])):
        raise ValueError(f"estimate_mesh_error: the meshes must go from fine to coarse (fine, coarse, coarser); "
                         f"their element sizes are {', '.join(f'{v:.4g}' for v in h)}")
    w = fine.omega
    wc = _frequency_at_energy(coarse, fine.energy, w)
    d1 = w - wc
    r1 = h[1] / h[0]
    if coarser is None:
        assert order is not None  # required without coarser (checked above)
        err = np.abs(d1) / (r1 ** order - 1.0)
        p_used, measured, n_ok = order, False, int(np.sum(np.isfinite(err)))
        how = f"Richardson from {_names(branches, h)}, order {order:g} stated"
    else:
        d2 = wc - _frequency_at_energy(coarser, fine.energy, w)
        r2 = h[2] / h[1]
        p_pt = np.array([_order(a, b, r1, r2) for a, b in zip(d1, d2)])
        ok = np.isfinite(p_pt) & (p_pt >= ORDER_RANGE[0]) & (p_pt <= ORDER_RANGE[1])
        measured = order is None
        p_used = order if order is not None else (float(np.median(p_pt[ok])) if ok.any() else math.nan)
        both = np.isfinite(d1) & np.isfinite(d2)
        fallback = np.fmax(np.abs(d1), np.abs(d2))
        err = np.where(ok, np.abs(d1) / (r1 ** p_used - 1.0), np.where(both, fallback, np.nan)) \
            if math.isfinite(p_used) else np.where(both, fallback, np.nan)
        n_ok = int(ok.sum()) if math.isfinite(p_used) else 0
        stated = "measured" if measured else "stated"
        order_text = f"order {p_used:.3g} {stated}" if math.isfinite(p_used) else "order not measured"
        how = (f"Richardson from {_names(branches, h)}, {order_text}; {int(both.sum()) - n_ok} of "
               f"{int(both.sum())} points not in the asymptotic range (changes of opposite sign, growing, or an order "
               f"outside {ORDER_RANGE[0]:g}-{ORDER_RANGE[1]:g}): the larger change there")
        if both.any() and n_ok < 0.5 * both.sum():
            log.warning("estimate_mesh_error: %d of %d points are not in the asymptotic range of the meshes; their "
                        "estimate is the larger change between meshes, not an extrapolation", int(both.sum()) - n_ok,
                        int(both.sum()))
    rel = err / np.abs(w)
    new = _with_mesh(fine, rel, how)
    new.meta["mesh_error"] = {"sizes": [float(v) for v in h], "order": float(p_used), "order_measured": bool(measured),
                              "extrapolated": n_ok, "compared": int(np.sum(np.isfinite(rel)))}
    fill_in_place(fine, new)  # the legacy of this release: the branch given is filled too
    return new


def _check_branches(branches: list) -> None:
    for b in branches:
        if not isinstance(b, Branch):
            raise TypeError(f"estimate_mesh_error: the branches must be femodes.Branch objects, got {type(b).__name__}")
        if b.kind != "nonlinear mode":
            raise ValueError("estimate_mesh_error: only nonlinear modes (backbones, compared at equal energy) are "
                             f"supported so far; got a {b.kind!r} branch")
        if len(b) < 2:
            raise ValueError(f"estimate_mesh_error: a branch has {len(b)} point(s); at least 2 are needed")
    f = branches[0]
    for b in branches[1:]:
        if (b.harmonics.n_harmonics, b.harmonics.subharmonic) != (f.harmonics.n_harmonics, f.harmonics.subharmonic):
            raise ValueError(f"estimate_mesh_error: the branches must have the same harmonics (H = "
                             f"{f.harmonics.n_harmonics} and {b.harmonics.n_harmonics}): their difference would mix "
                             "the harmonic truncation into the mesh's error")
        if b.meta.get("mode") != f.meta.get("mode"):
            raise ValueError(f"estimate_mesh_error: the branches follow different modes ({f.meta.get('mode')} and "
                             f"{b.meta.get('mode')})")
        if (family_caveat(b) is None) != (family_caveat(f) is None):
            raise ValueError("estimate_mesh_error: the branches follow different families past grazing (one the "
                             "contact-phase family, one the grazing family: branch.meta['family'] and "
                             "['energy_continuation']); trace them the same way")


def _sizes(branches: list, sizes) -> list[float]:
    if sizes is not None:
        h = [float(v) for v in np.ravel(np.asarray(sizes, dtype=float))]
        if len(h) != len(branches) or not all(math.isfinite(v) and v > 0 for v in h):
            raise ValueError(f"estimate_mesh_error: sizes must be {len(branches)} positive element sizes (fine, coarse"
                             f"{', coarser' if len(branches) == 3 else ''}), got {sizes!r}")
        return h
    out = []
    for b in branches:
        mesh = getattr(getattr(b.model, "fe", None), "mesh", None)
        if mesh is None:
            raise ValueError("estimate_mesh_error: a branch has no model with a mesh (loaded from a file, or a "
                             "discrete model); attach its model (branch.attach(model)) or give sizes=")
        out.append(float(mesh.t.shape[1]) ** (-1.0 / mesh.dim()))
    return out


def _names(branches: list, h: list[float]) -> str:
    counts = []
    for b, v in zip(branches, h):
        mesh = getattr(getattr(b.model, "fe", None), "mesh", None)
        counts.append(f"{mesh.t.shape[1]}" if mesh is not None else f"h = {v:.3g}")
    return ", ".join(counts) + (" elements" if all(c.isdigit() for c in counts) else "")


def _order(d1: float, d2: float, r1: float, r2: float) -> float:
    """The order ``p`` with ``d2 / d1 = r1^p (r2^p - 1) / (r1^p - 1)`` (module docstring); NaN when the
    changes have opposite signs or no order in ``(0, 50]`` fits."""
    from scipy.optimize import brentq

    if not (math.isfinite(d1) and math.isfinite(d2)) or d1 == 0.0 or d2 == 0.0 or (d1 > 0) != (d2 > 0):
        return math.nan
    q = math.log(d2 / d1)

    def f(p):
        return p * math.log(r1) + math.log(math.expm1(p * math.log(r2))) - math.log(math.expm1(p * math.log(r1))) - q

    lo, hi = 1e-6, 50.0
    if f(lo) * f(hi) > 0:
        return math.nan
    return float(brentq(f, lo, hi, xtol=1e-10))


def _frequency_at_energy(branch: Branch, energy: np.ndarray, near: np.ndarray) -> np.ndarray:
    """The branch's frequency at each of ``energy`` (PCHIP in ``log E`` on each run where the energy
    is monotone; of several runs, the one nearest in frequency to ``near``); NaN outside."""
    from scipy.interpolate import PchipInterpolator

    x, y = np.log(branch.energy), branch.omega
    out = np.full(len(energy), np.nan)
    step = np.sign(np.diff(x))
    cuts = [0] + [i + 1 for i in range(1, len(step)) if step[i] != step[i - 1] and step[i] != 0] + [len(x)]
    runs = [(a, b) for a, b in zip(cuts, cuts[1:])]
    # consecutive runs share their turning point
    runs = [(max(a - 1, 0), b) for a, b in runs]
    best = np.full(len(energy), np.inf)
    for a, b in runs:
        xs, ys = x[a:b], y[a:b]
        if len(xs) < 2:
            continue
        order = np.argsort(xs, kind="stable")
        xs, ys = xs[order], ys[order]
        keep = np.concatenate([[True], np.diff(xs) > 0])
        xs, ys = xs[keep], ys[keep]
        if len(xs) < 2:
            continue
        f = PchipInterpolator(xs, ys, extrapolate=False)
        v = f(np.log(energy))
        closer = np.isfinite(v) & (np.abs(v - near) < best)
        out[closer], best[closer] = v[closer], np.abs(v - near)[closer]
    return out


def _with_mesh(branch: Branch, rel: np.ndarray, how: str) -> Branch:
    """The branch with the mesh source joining its estimate, or making one of its own."""
    if branch.accuracy is not None:
        return branch.with_accuracy(branch.accuracy.with_mesh(rel, how))
    n = len(branch)
    pen, ten = branch.contact_quality()
    nan = np.full(n, np.nan)
    return branch.with_accuracy(ErrorEstimate(omega=nan, amplitude=nan, penetration=pen, tension=ten,
                                      harmonics=np.full(n, branch.harmonics.n_harmonics), rate=nan,
                                      method=np.full(n, "none"), mesh=rel, mesh_method=how,
                                      caveat=family_caveat(branch)))
