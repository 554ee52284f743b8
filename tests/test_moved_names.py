"""Names that moved to collaborators (issue 39): each old name still works for this release, warns
with a DeprecationWarning that names the new spelling and points at the caller's line, and gives
what the new spelling gives."""

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
