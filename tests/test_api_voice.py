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


@pytest.fixture(scope="module")
def forced():
    model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_damping(alpha=0.05)
             .with_forcing(fm.HarmonicForce(at=0, amplitude=0.1)).with_contact(fm.UnilateralContact(at=0, gap=0.5)))
    return fm.frequency_response(model, (0.5, 1.5), 5)


def _lines(ax):
    return [np.asarray(ln.get_xydata()) for ln in ax.get_lines()]


def test_plot_frequency_response_is_a_deprecated_alias_of_frequency_amplitude(forced):
    pytest.importorskip("matplotlib")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with pytest.warns(DeprecationWarning, match="frequency_amplitude") as record:
        old = fm.plot.frequency_response(forced, 0, label="curve")
    assert record[0].filename == __file__ and len(record) == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        new = fm.plot.frequency_amplitude(forced, 0, label="curve")
    for a, b in zip(_lines(old), _lines(new), strict=True):
        np.testing.assert_array_equal(a, b)
    _, ax = plt.subplots()
    with pytest.warns(DeprecationWarning) as record:  # the old name with ax by position: both said
        assert fm.plot.frequency_response(forced, 0, ax) is ax
    assert {str(w.message).split(";")[0] for w in record} == {
        "femodes.plot.frequency_response is deprecated", "femodes.plot.frequency_amplitude: passing ax by position "
        "is deprecated"}
    assert all(w.filename == __file__ for w in record)
    plt.close("all")


@pytest.mark.parametrize("name, args, keywords", [
    ("frequency_energy", (), ("ax",)),
    ("frequency_amplitude", (0,), ("ax",)),
    ("time_history", (0,), ("ax", "n_periods")),
    ("phase_portrait", (0,), ("ax",)),
    ("mode_shape", (None,), ("ax", "n_snapshots")),
])
def test_plot_ax_by_position_is_deprecated(forced, name, args, keywords):
    """``ax`` (and ``n_periods``, ``n_snapshots`` after it) are keyword-only in every plot, as in
    contact_pressure; by position they still work, with a warning naming the keywords."""
    pytest.importorskip("matplotlib")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    source = forced if name in ("frequency_energy", "frequency_amplitude") else forced[len(forced) // 2]
    values = {"ax": None, "n_periods": 2, "n_snapshots": 3}
    _, ax = plt.subplots()
    values["ax"] = ax
    with pytest.warns(DeprecationWarning, match="pass " + ", ".join(f"{k}=" + r"\.\.\." for k in keywords)) as record:
        out = getattr(fm.plot, name)(source, *args, *(values[k] for k in keywords))
    assert out is ax and record[0].filename == __file__
    _, ax2 = plt.subplots()
    values["ax"] = ax2
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        new = getattr(fm.plot, name)(source, *args, **{k: values[k] for k in keywords})
    for a, b in zip(_lines(out), _lines(new), strict=True):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(TypeError, match="multiple values for argument 'ax'"):
        getattr(fm.plot, name)(source, *args, ax, ax=ax)
    plt.close("all")


def test_rectangle_mesh_quad_is_deprecated_for_quadrilaterals():
    """The cells named in full in both structured meshes: rectangle_mesh(quadrilaterals=), as
    box_mesh(hexahedra=)."""
    with pytest.warns(DeprecationWarning, match=r"quadrilaterals=") as record:
        old = fm.rectangle_mesh(1.0, 0.1, 4, 2, quad=True)
    assert record[0].filename == __file__
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        new = fm.rectangle_mesh(1.0, 0.1, 4, 2, quadrilaterals=True)
        tri = fm.rectangle_mesh(1.0, 0.1, 4, 2)
    assert type(old) is type(new) and type(new).__name__.startswith("MeshQuad") and type(tri).__name__.startswith("MeshTri")
    np.testing.assert_array_equal(old.p, new.p)
    np.testing.assert_array_equal(old.t, new.t)
    with pytest.warns(DeprecationWarning):
        assert type(fm.rectangle_mesh(1.0, 0.1, 4, 2, quad=False)).__name__.startswith("MeshTri")
    with pytest.raises(TypeError, match="not both"):
        fm.rectangle_mesh(1.0, 0.1, 4, 2, quadrilaterals=True, quad=True)
    with pytest.raises(TypeError, match="'quadrilaterals' must be True or False"):
        fm.rectangle_mesh(1.0, 0.1, 4, 2, quadrilaterals="yes")


@pytest.mark.parametrize("name", ["shoot", "monodromy", "trajectory"])
def test_time_state0_keyword_is_deprecated_for_x0(name):
    """The start state ``[q; v]`` (or first guess) of the event-driven flow is ``x0``, as in
    exact_frequency_response(x0=) and semismooth_newton; ``state0=`` still works and warns."""
    model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]])
             .with_forcing(fm.HarmonicForce(at=0, amplitude=1.0)))
    f = getattr(fm.time, name)
    extra = {"t": np.linspace(0.0, 1.0, 5)} if name == "trajectory" else {}
    with pytest.warns(DeprecationWarning, match=r"x0=") as record:
        old = f(model, 1.2, state0=[0.0, 0.0], **extra)
    assert record[0].filename == __file__
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        new = f(model, 1.2, x0=[0.0, 0.0], **extra)
        assert type(f(model, 1.2, [0.0, 0.0], **extra)) is type(new)
    value = (lambda r: r) if name == "trajectory" else (lambda r: r.x if name == "shoot" else r.matrix)
    np.testing.assert_array_equal(value(old), value(new))
    with pytest.raises(TypeError, match="not both"):
        f(model, 1.2, [0.0, 0.0], state0=[0.0, 0.0], **extra)
