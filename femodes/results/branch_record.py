"""Results layer: what a branch file holds, the header and the arrays of a :class:`~femodes.results.Branch`
(written by :meth:`Branch.save`, read by :func:`~femodes.results.load_branch`)."""

from __future__ import annotations

import json

import numpy as np

from ..store import model_signature

__all__ = ["FORMAT_VERSION", "branch_header", "branch_arrays"]

FORMAT_VERSION = 1


def branch_arrays(branch, bifurcations: tuple) -> dict:
    """The arrays of a branch file: the points' values, and the error estimate and stability when
    attached, with ``bifurcations`` at the frequencies of their series (loading applies the
    correction of an error estimate again)."""
    out = {
        # "omega": the answer (converged where an error estimate gives it), "omega_truncated": the
        # frequencies of the series Q, P (older files have only "omega", which was those)
        "omega": branch.omega, "omega_truncated": branch.omega_truncated, "Q": branch.Q, "P": branch.P,
        "energy": branch.energy, "xi": branch.xi,
        "residual_norm": branch.residual_norm, "nit": branch.nit, "parameter": branch.parameter,
        "folds": np.asarray(branch.folds, dtype=int),
    }
    if branch.accuracy is not None:
        out.update({f"accuracy_{k}": v for k, v in branch.accuracy.arrays().items()})
    if branch.stable is not None and branch.multipliers is not None:  # set together (Branch.with_stability)
        bifs = bifurcations
        out.update({
            "stable": branch.stable.astype(np.int8), "multipliers_re": branch.multipliers.real,
            "multipliers_im": branch.multipliers.imag,
            "bif_index": np.asarray([b.index for b in bifs], dtype=int),
            "bif_real": np.asarray([[b.omega, b.energy, b.parameter, b.multiplier.real, b.multiplier.imag, b.xi]
                                    for b in bifs], dtype=float).reshape(len(bifs), 6),
            "bif_Q": np.asarray([b.Q for b in bifs], dtype=float).reshape((len(bifs),) + branch.Q.shape[1:]),
            "bif_P": np.asarray([b.P for b in bifs], dtype=float).reshape((len(bifs),) + branch.P.shape[1:]),
            "bif_bracket": np.asarray([b.bracket for b in bifs], dtype=float).reshape(len(bifs), 2),
        })
    return out


def _stored_meta(meta: dict) -> dict:
    """``meta`` as the file stores it (JSON), or a TypeError naming the entry it cannot store (it
    was json's "Object of type int64 is not JSON serializable", naming neither ``meta`` nor the key)."""
    for key, value in meta.items():
        try:
            json.dumps({key: value})
        except (TypeError, ValueError) as exc:
            raise TypeError(f"Branch.save: meta[{key!r}] = {value!r} cannot be stored in the file ({exc}); keep "
                            "meta to numbers, strings, lists, dicts (string keys), True/False/None: e.g. int(...), "
                            "float(...) or array.tolist()") from None
    return meta


def branch_header(branch) -> dict:
    """The JSON header of a branch file: format, kind, harmonics, contacts, status, model signature, and what
    the error estimate and stability were computed with."""
    return {
        "format": "femodes.Branch", "version": FORMAT_VERSION, "kind": branch.kind,
        "harmonics": [branch.harmonics.n_harmonics, branch.harmonics.n_time, branch.harmonics.subharmonic],
        "contacts": branch.contacts.to_json(), "success": branch.success, "status": branch.status,
        "message": branch.message, "meta": _stored_meta(branch.meta),
        "model": model_signature(branch.model) if branch.model is not None else branch.model_signature,
        "accuracy": None if branch.accuracy is None else {
            "method": [str(m) for m in branch.accuracy.method], "rtol": branch.accuracy.rtol,
            "mesh_method": branch.accuracy.mesh_method, "caveat": branch.accuracy.caveat},
        "stability": None if branch.stable is None or branch.stability_method is None else {
            "methods": [str(m) for m in branch.stability_method], "kinds": [b.kind for b in branch.bifurcations],
            "located": [bool(b.located) for b in branch.bifurcations]},
    }
