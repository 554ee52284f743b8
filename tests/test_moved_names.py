"""Names that moved to collaborators (issue 39): each old name still works for this release, warns
with a DeprecationWarning that names the new spelling and points at the caller's line, and gives
what the new spelling gives."""

import copy

import numpy as np
import pytest

import femodes as fm


@pytest.fixture(scope="module")
def models():
    mesh = fm.line_mesh(length=1.0, n_elements=6, boundaries={"clamp": 0.0, "tip": 1.0})
    beam = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    model = (beam.with_damping(modal=0.02, n_modes=3).with_contact(fm.UnilateralContact(at="tip", gap=0.01))
             .with_nonlinearity(fm.CubicSpring(at=("tip", "theta"), k3=1.0)))
    return model, fm.craig_bampton(model, 4)


def _same(a, b):
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        np.testing.assert_array_equal(a, b)
    else:
        assert a == b or (a is b)


MODEL_NAMES = {  # old spelling -> the new one, as functions of the model
    "n_contacts": (lambda m: m.n_contacts, lambda m: len(m.contacts)),
    "has_damping": (lambda m: m.has_damping, lambda m: m.damping.nonzero),
    "apply_damping": (lambda m: m.apply_damping(np.arange(m.n_dofs, dtype=float)),
                      lambda m: m.damping.apply(np.arange(m.n_dofs, dtype=float))),
    "nonlinear_dofs": (lambda m: m.nonlinear_dofs(), lambda m: fm.model.nonlinear_dofs(m)),
    "probe": (lambda m: m.probe("tip"), lambda m: m.mesh_map.probe("tip")),
    "mesh_owner": (lambda m: m.mesh_owner, lambda m: m.mesh_map.owner),
    "to_owner": (lambda m: m.to_owner(np.ones(m.n_dofs)), lambda m: m.mesh_map.to_owner(np.ones(m.n_dofs))),
    "fe_dof": (lambda m: m.fe_dof(1), lambda m: m.mesh_map.fe_dof(1)),
    "full_field": (lambda m: m.full_field(np.ones(m.n_dofs)), lambda m: m.mesh_map.full_field(np.ones(m.n_dofs))),
}


@pytest.mark.parametrize("reduced", [False, True], ids=["model", "reduced"])
@pytest.mark.parametrize("name", sorted(MODEL_NAMES))
def test_moved_model_names_warn_and_give_the_same(models, name, reduced):
    model = models[reduced]
    old, new = MODEL_NAMES[name]
    with pytest.warns(DeprecationWarning, match=rf"{type(model).__name__}\.{name} is deprecated .* use ") as rec:
        value = old(model)
    assert rec[0].filename == __file__  # the caller's line
    _same(value, new(model))


def test_model_collaborators_and_unknown_names(models):
    model, rom = models
    assert not model.is_reduced and rom.is_reduced  # a class constant, not moved
    assert model.damping_matrix().nnz == model.damping.matrix().nnz > 0  # hbm/system.py's spelling stays
    with pytest.raises(AttributeError, match="has no attribute 'nowhere'"):
        model.nowhere  # noqa: B018
    assert not hasattr(model, "nowhere")


def test_probe_with_owner_still_names_the_error(models):
    model, _ = models
    with pytest.warns(DeprecationWarning), pytest.raises(ValueError, match=r"^mine: "):
        model.probe("nowhere", "mean", "mine")
    with pytest.raises(ValueError, match=r"^probe: "):
        model.mesh_map.probe("nowhere")


# ----------------------------------------------------------------------------- the branch
@pytest.fixture(scope="module")
def branches():
    model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]]).with_forcing(fm.HarmonicForce(at=0, amplitude=0.2))
             .with_contact(fm.UnilateralContact(at=0, gap=1.0)))
    plain = fm.frequency_response(model, omega=(0.8, 1.6), harmonics=6)
    both = fm.frequency_response(model, omega=(0.8, 1.6), harmonics=6, rtol=1e-2, stability=True)
    return plain, both


def _stability(b):
    return dict(stable=b.stable, multipliers=b.multipliers, bifurcations=b.bifurcations, methods=b.stability_method,
                tol=b.meta["stability_tol"])


def _same_branch(a, b):
    for name in ("omega", "omega_truncated", "omega_error", "amplitude_error", "error_estimate", "stable", "multipliers",
                 "stability_method", "converged"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            np.testing.assert_array_equal(x, y)
    assert [(z.kind, z.index, z.omega, z.omega_truncated) for z in a.bifurcations] == \
           [(z.kind, z.index, z.omega, z.omega_truncated) for z in b.bifurcations]
    assert a.accuracy is b.accuracy and a.meta == b.meta


def test_with_accuracy_and_with_stability_leave_the_branch_as_it_is(branches):
    plain, both = branches
    new = plain.with_accuracy(both.accuracy).with_stability(**_stability(both))
    assert new is not plain and plain.accuracy is None and plain.stable is None and plain.error_estimate is None
    assert "stability_tol" not in plain.meta and not plain.bifurcations
    _same_branch(new, both)
    with pytest.raises(TypeError, match="^with_accuracy: expected an ErrorEstimate"):
        plain.with_accuracy("estimate")
    with pytest.raises(ValueError, match=r"^with_stability: one value per point"):
        plain.with_stability(**{**_stability(both), "stable": both.stable[:-1]})


def test_set_accuracy_and_set_stability_still_fill_the_branch_with_a_warning(branches):
    plain, both = branches
    old = copy.copy(plain)
    with pytest.warns(DeprecationWarning, match=r"Branch\.set_accuracy is deprecated .*with_accuracy") as rec:
        assert old.set_accuracy(both.accuracy) is old
    assert rec[0].filename == __file__
    with pytest.warns(DeprecationWarning, match=r"Branch\.set_stability is deprecated .*with_stability"):
        assert old.set_stability(**_stability(both)) is old
    _same_branch(old, both)
    assert plain.accuracy is None  # the copy was filled, not the branch it was copied from
    with pytest.warns(DeprecationWarning), pytest.raises(TypeError, match="^set_accuracy: expected an ErrorEstimate"):
        old.set_accuracy("estimate")


def test_assigning_bifurcations_still_replaces_them_with_a_warning(branches, tmp_path):
    """As before branches became values: the assignment replaces the bifurcations the branch reports
    and saves; it warns, at the caller's line, with the replacement."""
    _, both = branches
    b = copy.copy(both)
    with pytest.warns(DeprecationWarning, match=r"assigning the bifurcations is deprecated.*with_stability") as rec:
        b.bifurcations = b.bifurcations[:1]
    assert rec[0].filename == __file__
    assert len(both.bifurcations) == 4 and len(b.bifurcations) == 1  # the branch copied from is unchanged
    assert b.bifurcations[0].kind == both.bifurcations[0].kind and b.bifurcations[0].omega == both.bifurcations[0].omega
    b.save(tmp_path / "b.npz")
    assert [(z.kind, z.index) for z in fm.load_branch(tmp_path / "b.npz").bifurcations] == \
           [(z.kind, z.index) for z in b.bifurcations]


def test_point_harmonics_is_the_solutions(branches):
    _, both = branches
    with pytest.warns(DeprecationWarning, match=r"Branch\.point_harmonics is deprecated .* branch\[i\]\.harmonics"):
        h = both.point_harmonics(3)
    assert h is both[3].harmonics or h.n_harmonics == both[3].harmonics.n_harmonics
    with pytest.raises(AttributeError, match="has no attribute 'nowhere'"):
        both.nowhere  # noqa: B018


def test_estimate_error_returns_a_new_branch_and_fills_the_given_one_this_release(branches):
    plain, _ = branches
    given = copy.copy(plain)
    new = fm.estimate_error(given)
    assert new is not given and new.accuracy is not None and plain.accuracy is None
    _same_branch(given, new)  # the legacy of this release
