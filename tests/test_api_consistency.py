"""One API voice: what the public names promise, whichever entry point a user takes.

Mode numbers are 1-based everywhere; writers take (result, model, path); problems name their
unknowns (no slicing by callers) and are scaled at construction; results are exported from the
package; reduced models answer the same questions about their mesh as full ones.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import femodes as fm
from femodes.fields import mesh_fields


@pytest.fixture(scope="module")
def cantilever():
    mesh = fm.line_mesh(1.0, 12, boundaries={"clamp": 0.0, "tip": 1.0})
    return fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")


def test_mode_numbers_are_one_based_everywhere(cantilever, tmp_path):
    modes = fm.linear_modes(cantilever, 3)
    # mode=2 is the second mode (column 1) in the fields every output uses...
    f = mesh_fields(modes, cantilever, n_frames=4, mode=2)
    phi = cantilever.mesh_map.full_field(modes.shapes[:, 1])[cantilever.fe.nodal[0]]
    np.testing.assert_allclose(f.displacement[0], phi, rtol=0, atol=1e-14 * np.abs(phi).max())
    assert f.omega == modes.omega[1]
    # ... in the ParaView writer (same argument order as write_animation) and in the plots
    pvd = fm.io.write_linear_mode(modes, cantilever, tmp_path / "m2", n_frames=4, mode=2)
    assert pvd.is_file()
    ax = fm.plot.mode_shape(modes, cantilever, mode=2, n_snapshots=1)
    np.testing.assert_allclose(ax.get_lines()[0].get_ydata(), phi)
    # ... as in nonlinear_mode(mode=1): the first mode is 1, 0 is refused with the range
    with pytest.raises(ValueError, match=r"mode must be an integer >= 1"):
        mesh_fields(modes, cantilever, mode=0)
    with pytest.raises(ValueError, match=r"mode=4 is out of range.*mode=1 \.\. 3"):
        mesh_fields(modes, cantilever, mode=4)


def test_problems_name_their_unknowns():
    osc = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]])
           .with_contact(fm.UnilateralContact(at=0, gap=1.0))
           .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))
    h = fm.Harmonics(3)
    pr = fm.ForcedResponseProblem(osc, h)
    x = pr.linear_guess(0.5)
    u = pr.unpack(x, 0.5)
    assert isinstance(u, fm.hbm.HBMUnknowns) and u.omega == 0.5 and u.xi == 0.0
    assert u.Q.shape == (h.n_coef, 1) and u.P.shape == (h.n_coef, 1)
    np.testing.assert_array_equal(u.y, x)
    # the forcing part of the residual: at rest, away from the stop, r(0, w) = -forcing()
    np.testing.assert_array_equal(pr.residual(np.zeros(pr.size), 0.5)[0], -pr.forcing())
    assert np.count_nonzero(pr.forcing()) == 1  # cos(w t) on the only DOF
    nnm = fm.NonlinearModeProblem(osc.without_forcing().with_damping(), h, 1, reference_energy=4.0)
    xn = nnm.linear_guess(0.5)
    un = nnm.unpack(xn, math.log10(0.5))
    assert un.omega == pytest.approx(1.0) and un.xi == 0.0 and un.y.size == nnm.system.size
    scale = nnm.arclength_scale(xn)
    assert scale.shape == (nnm.size,) and scale[-2] == pytest.approx(1.0) and scale[-1] == pytest.approx(0.1)
    # scaled at construction: the force scale follows the reference energy (amplitude ~ sqrt(E))
    ref1 = fm.NonlinearModeProblem(osc.without_forcing().with_damping(), h, 1, reference_energy=1.0)
    assert nnm.force_scale == pytest.approx(2.0 * ref1.force_scale)
    assert not hasattr(nnm, "set_reference_energy")


def test_results_are_exported():
    for name in ("NewtonResult", "ContinuationResult", "ContinuationState", "StaticContactResult", "Branch",
                 "PeriodicSolution", "TimeHistory", "SteadyState"):
        assert name in fm.__all__ and hasattr(fm, name), name


def test_static_contact_gap_is_a_field():
    model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_contact(fm.UnilateralContact(at=0, gap=0.5))
             .with_forcing(fm.HarmonicForce(at=0, amplitude=2.0)))
    res = fm.static_contact(model)
    assert res.success and res.gap.shape == (1,)
    assert res.contact_force[0] == pytest.approx(1.5, rel=1e-9)  # K q = f - p with q = gap
    assert res.gap[0] == pytest.approx(0.0, abs=1e-9) and res.penetration <= 1e-9


def test_reduced_models_answer_mesh_questions(cantilever):
    model = cantilever.with_contact(fm.UnilateralContact(at="tip", gap=0.01))
    rom = fm.craig_bampton(model, 4)
    rr = fm.craig_bampton(rom, 2)
    assert rom.mesh_map.owner is model and rr.mesh_map.owner is model
    tip = model.dof("tip")
    assert rr.mesh_map.fe_dof(rr.dof("tip")) == model.mesh_map.fe_dof(tip) == int(model.fe.free[tip])
    assert rr.mesh_map.fe_dof(rr.n_dofs - 1) is None  # a modal coordinate
    q = np.random.default_rng(0).standard_normal((3, rr.n_dofs))
    np.testing.assert_allclose(rr.mesh_map.to_owner(q), rom.expand(rr.expand(q)))
    assert fm.StructuralModel(M=[[1.0]], K=[[1.0]]).mesh_map.owner is None


def test_contact_mass_is_a_strategy(cantilever):
    law = fm.UnilateralContact(at="tip", gap=0.01)
    tip = cantilever.dof("tip")
    assert cantilever.with_contact(law).M[tip, tip] == 0.0  # default on FE models: redistributed
    kept = cantilever.with_contact(law, contact_mass=fm.ConsistentMass())
    assert kept.M[tip, tip] == cantilever.M[tip, tip] > 0
    moved = cantilever.with_contact(law, contact_mass=fm.RedistributeMass())
    assert moved.M[tip, tip] == 0.0 and moved.mass_redistribution[0]["dof"] == tip
    with pytest.raises(TypeError, match="contact_mass must be"):
        cantilever.with_contact(law, contact_mass=True)
    discrete = fm.StructuralModel(M=[[1.0]], K=[[1.0]])
    with pytest.raises(ValueError, match="needs an FE model"):
        discrete.with_contact(fm.UnilateralContact(at=0, gap=1.0), contact_mass=fm.RedistributeMass())
