"""Names that moved to a collaborator (issue 39, rooms of one idea) still work for one release: the old
spelling gives the identical object or result, with a DeprecationWarning that names the new
spelling and points at the caller's line; any other missing name is an AttributeError as before.
"""

from __future__ import annotations

import pickle
import warnings

import numpy as np
import pytest

import femodes as fm
from femodes.hbm.harmonics import _MOVED as HARMONICS_MOVED
from femodes.hbm.system import _MOVED as SYSTEM_MOVED
from femodes.hbm.system import HBMSystem


def _new(obj, path):
    """The attribute at ``path`` (``"layout.cos_index"``, ``'stiffness.term("IM")'``) of ``obj``."""
    for link in path.split("."):
        if link.endswith('")'):
            name, arg = link[:-2].split('("')
            obj = getattr(obj, name)(arg)
        else:
            obj = getattr(obj, link)
    return obj


def _old(obj, name):
    """``getattr(obj, name)``, checking its one DeprecationWarning (message and line)."""
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        value = getattr(obj, name)
    assert len(rec) == 1 and rec[0].category is DeprecationWarning, [str(r.message) for r in rec]
    cls = type(obj).__name__
    path = (HARMONICS_MOVED if cls == "Harmonics" else SYSTEM_MOVED)[name]
    assert str(rec[0].message) == (f"{cls}.{name} is deprecated and will be removed in the next release; "
                                   f"use {cls}.{path}")
    assert rec[0].filename == __file__  # the user's line, not femodes'
    return value


def _same(a, b):
    if isinstance(a, np.ndarray):
        assert a is b or (a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True))
    elif hasattr(a, "toarray"):
        assert a is b or (a != b).nnz == 0
    else:
        assert a == b


@pytest.fixture(scope="module")
def system():
    model = (fm.StructuralModel(M=np.eye(2), K=[[2.0, -1.0], [-1.0, 2.0]], C=0.02 * np.eye(2))
             .with_forcing(fm.HarmonicForce(at=1, amplitude=0.3))
             .with_contact(fm.UnilateralContact(at=0, gap=0.5)))
    return HBMSystem(model, fm.Harmonics(4))


@pytest.mark.parametrize("name", sorted(HARMONICS_MOVED))
def test_harmonics_old_name_is_the_new_one(name):
    h = fm.Harmonics(4, subharmonic=2)
    old, new = _old(h, name), _new(h, HARMONICS_MOVED[name])
    _same(old, new)  # bound methods of the same room, or the same cached array


def test_harmonics_old_names_give_identical_results():
    h = fm.Harmonics(5)
    rng = np.random.default_rng(39)
    Q, phi = rng.standard_normal((h.n_coef, 3)), rng.standard_normal(h.n_coef)
    t = np.linspace(0.0, 3.0, 7)
    with pytest.warns(DeprecationWarning, match=r"Harmonics\.\w+ is deprecated"):
        old = [h.cos_index(2), h.size(3), h.reshape(Q.ravel(), 3), h.synthesis(), h.to_time(Q), h.evaluate(Q, 1.3, t),
               h.derivative(1.3), h.time_shift(Q, 0.4), h.norm_weights(), h.positive_part(phi)[1],
               h.period(1.3), h.convert(Q, fm.Harmonics(7))]
    new = [h.layout.cos_index(2), h.layout.size(3), h.layout.reshape(Q.ravel(), 3), h.grid.synthesis(),
           h.grid.to_time(Q), h.grid.evaluate(Q, 1.3, t), h.operators.derivative(1.3), h.operators.time_shift(Q, 0.4),
           h.galerkin.norm_weights(), h.galerkin.positive_part(phi)[1], h.grid.period(1.3),
           h.layout.convert(Q, fm.Harmonics(7))]
    for a, b in zip(old, new):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("name", sorted(SYSTEM_MOVED))
def test_system_old_name_is_the_new_one(system, name):
    old, new = _old(system, name), _new(system, SYSTEM_MOVED[name])
    _same(old, new)


def test_system_old_names_give_identical_results(system):
    s, w = system, 1.4
    x = np.random.default_rng(7).standard_normal(s.nq)
    with pytest.warns(DeprecationWarning, match=r"HBMSystem\.\w+ is deprecated"):
        old = [s.force(), s.apply_linear(x, w, 0.2), s.solve_linear(s.force(), w), s.linear_operator(w).toarray(),
               s.dense_linear_operator(w, 0.1), s.abs_row_sums()]
    new = [s.linear.force(), s.linear.apply(x, w, 0.2), s.linear.solve(s.linear.force(), w),
           s.stiffness.operator(w).toarray(), s.stiffness.dense_operator(w, 0.1), s.stiffness.abs_row_sums()]
    for a, b in zip(old, new):
        np.testing.assert_array_equal(a, b)


def test_other_missing_names_are_attribute_errors(system):
    h = fm.Harmonics(3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for obj, cls in ((h, "Harmonics"), (system, "HBMSystem")):
            with pytest.raises(AttributeError, match=f"'{cls}' object has no attribute 'nonsense'"):
                obj.nonsense
            assert not hasattr(obj, "_private")
    assert pickle.loads(pickle.dumps(h)) == h and pickle.loads(pickle.dumps(h)).layout.cos_index(1) == 1


def test_threads_stays_a_setting_of_the_system(system):
    system.threads = 2
    assert system.threads == 2 and system.linear.threads == 2
    system.threads = None
    assert system.linear.factors(1.1).threads >= 1
