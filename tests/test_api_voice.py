"""One API voice (issue 39, item 5): the old spellings still work, warn with a
DeprecationWarning that names the new spelling, and give the same answer."""
import warnings

import numpy as np
import pytest

import femodes as fm


def _duffing():
    return fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_nonlinearity(fm.CubicSpring(at=0, k3=0.5))


def test_nonlinear_mode_without_harmonics_is_deprecated():
    """``harmonics`` is required in both analyses; leaving it out of nonlinear_mode still means 10,
    with a warning pointing at the caller's line (past the BLAS-threads wrapper)."""
    opts = fm.ContinuationOptions(max_points=8)
    with pytest.warns(DeprecationWarning, match="harmonics=") as record:
        old = fm.nonlinear_mode(_duffing(), 1, (1e-3, 1e-2), options=opts)
    assert record[0].filename == __file__
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        new = fm.nonlinear_mode(_duffing(), 1, (1e-3, 1e-2), harmonics=10, options=opts)
    assert old.harmonics.n_harmonics == new.harmonics.n_harmonics == 10
    np.testing.assert_array_equal(old.omega, new.omega)
