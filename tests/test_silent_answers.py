"""Answers that were wrong, or short, without a word (probes of 2026-12-02): each test is the
probe's input, with what it must give or say now."""

from __future__ import annotations

import logging

import numpy as np
import pytest

import femodes as fm


def oscillator(gap=1.0, c=0.1):
    return (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[c]])
            .with_contact(fm.UnilateralContact(at=0, gap=gap))
            .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))


def warnings_of(caplog, name):
    return [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING and name in r.getMessage()]


def assert_warns_at_the_users_line(match, call, quiet):
    """``call()`` warns (UserWarning matching ``match``) at the calling line of this file, and
    ``quiet()``, the same done as the warning advises, says nothing."""
    import warnings
    with pytest.warns(UserWarning, match=match) as rec:
        call()
    assert rec[0].filename == __file__
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        quiet()


def test_a_softening_backbone_stops_at_its_separatrix(caplog):
    """u'' + u - u^3 = 0 has periodic orbits below the energy 1/4 only (the separatrix), with w -> 0
    there. The backbone went on through w = 6e-10 to w = -0.999 and reported 97 points, three folds
    and success True; now it stops where w falls to zero, says so, and keeps the points before."""
    m = fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_nonlinearity(fm.CubicSpring(at=0, k3=-1.0))
    with caplog.at_level(logging.WARNING):
        b = fm.nonlinear_mode(m, 1, energy=(1e-3, 1.0), harmonics=7)
    assert len(b) > 10 and np.all(b.omega > 1e-6 * b.omega[0])
    assert b.energy.max() < 0.25                      # nothing past the separatrix
    assert any("separatrix" in w for w in warnings_of(caplog, "nonlinear_mode"))
    # the small-amplitude end is still the Duffing backbone: w^2 = 1 - 3/4 a^2 to O(a^4)
    a = b.amplitude(0)[0]
    assert abs(b.omega[0] ** 2 - (1 - 0.75 * a ** 2)) < 2 * a ** 4


@pytest.mark.parametrize("case, says", [
    ("direction", "direction=-1"),
    ("max_points", "max_points = 10"),
    ("turns back", "turned back at w = 0.59"),
])
def test_a_forced_response_short_of_its_span_says_so(case, says, caplog):
    """Each of these returned ``success=True`` and nothing else: a one-point branch for
    ``direction=-1``, a branch stopped at ``max_points``, and the stop at rest (gap 0) whose branch
    turns back at 0.599 rad/s and leaves the span 0.5-2 through its start."""
    opts = {"direction": fm.ContinuationOptions(direction=-1),
            "max_points": fm.ContinuationOptions(max_points=10)}.get(case)
    model = oscillator(gap=0.0 if case == "turns back" else 1.0)
    with caplog.at_level(logging.WARNING):
        b = fm.frequency_response(model, (0.5, 2.0), 5, options=opts)
    assert b.success and b.status in (1, 2)
    said = warnings_of(caplog, "does not reach the end of its span")
    assert len(said) == 1 and says in said[0]


def test_a_forced_response_that_reaches_its_end_says_nothing_of_it(caplog):
    with caplog.at_level(logging.WARNING):
        b = fm.frequency_response(oscillator(), (0.5, 2.0), 5)
    assert b.status == 0 and not warnings_of(caplog, "does not reach")


def test_linear_modes_of_an_indefinite_stiffness_are_an_error():
    """A raw model above 400 DOFs gets the diagonal test only, and linear_modes clipped the
    negative eigenvalues it found to zero: an indefinite K (lowest eigenvalue -0.9999) gave
    ``[0, 0, 0]``. A free-free chain's rigid-body mode (round-off) is still zero frequency."""
    import scipy.sparse as sp
    n = 500
    K = sp.diags([2 * np.ones(n), -1.5 * np.ones(n - 1), -1.5 * np.ones(n - 1)], [0, -1, 1]).tocsr()
    with pytest.raises(ValueError, match=r"eigenvalue\(s\) w\^2 < 0, the lowest -0\.999.*K is not positive semidefinite"):
        fm.linear_modes(fm.StructuralModel(M=sp.eye(n), K=K), 3)
    free = fm.StructuralModel(M=np.eye(3), K=[[1.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 1.0]])
    w = fm.linear_modes(free, 3).omega
    assert w[0] < 1e-6 and np.allclose(w[1:], [1.0, np.sqrt(3.0)], rtol=1e-12)


def _strip(quadrilaterals):
    return fm.rectangle_mesh(1.0, 0.05, 20, 2, quadrilaterals=quadrilaterals)


def _remeshed(mesh, p=None, t=None):
    cls = type(mesh)
    return cls(mesh.p if p is None else p, mesh.t if t is None else t).with_boundaries(
        {"left": lambda x: x[0] < 1e-9})


@pytest.mark.parametrize("order", [1, 2])
def test_a_bow_tie_quadrilateral_is_named(order):
    """One element's vertices in crossed order: assembled with |det J|, w1 moved by 1.4 % (order 1)
    or scikit-fem's bare "Zero Jacobian determinant" (order 2)."""
    q = _strip(True)
    t = q.t.copy()
    t[[2, 3], 5] = t[[3, 2], 5]
    with pytest.raises(ValueError, match=r"mesh element 5 folds over itself.*crossed order"):
        fm.solid(_remeshed(q, t=t), fm.Material(1.0, 1.0, 0.3), clamped="left", order=order)


def test_a_node_moved_past_its_neighbour_is_named():
    """A tangled triangle mesh: every element has a constant Jacobian (one of them inverted), and
    two of them overlap; it assembled without a word."""
    m = _strip(False)
    p = m.p.copy()
    i = int(np.flatnonzero((abs(m.p[1] - 0.025) < 1e-9) & (abs(m.p[0] - 0.5) < 1e-9))[0])
    p[0, i] += 0.08                                   # past its neighbour at x = 0.55
    with pytest.raises(ValueError, match=r"mesh elements \d+ and \d+ overlap"):
        fm.solid(_remeshed(m, p=p), fm.Material(1.0, 1.0, 0.3), clamped="left")
    # either orientation of every element is still fine
    flipped = _remeshed(m, t=m.t[[0, 2, 1]])
    w = [fm.linear_modes(fm.solid(x, fm.Material(1.0, 1.0, 0.3), clamped="left"), 1).omega[0] for x in (m, flipped)]
    assert abs(w[0] / w[1] - 1) < 1e-12


def test_amplitudes_are_the_series_peak_not_a_sample():
    """Branch.amplitude took the largest of 512 samples, low by (pi k / n)^2 / 2: a linear response
    read 1.7e-5 below |X| = F / sqrt((k - m w^2)^2 + (c w)^2). Now the peak of the series: the
    linear response to its Newton tolerance (atol 1e-9 on the residual over a dynamic stiffness
    >= c w = 0.05: 2e-8 of the amplitude), a random series to round-off."""
    from femodes.results.contacts import peak_amplitude
    b = fm.frequency_response(oscillator(gap=100.0), (0.5, 2.0), 5)
    exact = 0.2 / np.sqrt((1 - b.omega ** 2) ** 2 + (0.1 * b.omega) ** 2)
    assert np.max(np.abs(b.amplitude(0) / exact - 1)) < 2e-8
    assert abs(b[len(b) // 2].amplitude(0) / exact[len(b) // 2] - 1) < 2e-8
    h = fm.Harmonics(4)
    C = np.random.default_rng(1).normal(size=(20, h.n_coef))
    theta = 2 * np.pi * np.arange(2 ** 16) / 2 ** 16
    q = C @ h.grid.synthesis(theta).T
    from scipy.optimize import minimize_scalar
    for row, c in zip(q, C):
        t0 = theta[np.argmax(np.abs(row))]
        res = minimize_scalar(lambda t: -abs(float((h.grid.synthesis(np.array([t])) @ c)[0])),
                              bounds=(t0 - 1e-3, t0 + 1e-3), method="bounded", options={"xatol": 1e-12})
        # a maximum is flat: 1e-12 in the phase is ~1e-24 in the value; eps times the series' size
        assert abs(peak_amplitude(h, c)[0] + res.fun) < 1e-13 * np.abs(c).sum()


def test_the_checkpoint_file_holds_the_branch_the_call_returned(tmp_path):
    """With ``rtol=`` the checkpoint's file was written before the error estimate: no estimate, and
    frequencies up to 0.13 rad/s from the returned ones (an upper fold 9 % low). Now the file is
    the returned branch, and resuming the finished run gives it back without estimating again."""
    path = tmp_path / "frc.npz"
    frc = fm.frequency_response(oscillator(), omega=(0.8, 1.6), harmonics=4, rtol=1e-3, checkpoint=path)
    saved = fm.load_branch(path)
    assert saved.accuracy is not None and saved.accuracy.rtol == 1e-3
    assert np.array_equal(saved.omega, frc.omega) and np.array_equal(saved.Q, frc.Q)
    again = fm.frequency_response(oscillator(), omega=(0.8, 1.6), harmonics=4, rtol=1e-3,
                                  checkpoint=fm.Checkpoint(path, resume=True))
    assert np.array_equal(again.omega, frc.omega)
    assert np.array_equal(again.accuracy.frequency_error, frc.accuracy.frequency_error)


def test_femodes_run_keeps_the_computed_branch_when_its_outputs_fail(tmp_path, monkeypatch, capsys):
    """An error after the continuation (here: the plot) removed the finished checkpoint with the
    journal, so the whole run had to be computed again; the branch is now kept, the message says
    where, and the same command reuses it."""
    from pathlib import Path

    from femodes.app import cli
    from femodes.app.cases import running

    case = Path(__file__).resolve().parents[1] / "examples" / "cases" / "oscillator_frc.toml"
    out = tmp_path / "o"

    def broken(*args, **kwargs):
        raise RuntimeError("the plot failed")

    monkeypatch.setattr(running, "write_plot", broken)
    with pytest.raises(RuntimeError, match="the plot failed"):
        cli.main(["run", str(case), "--out", str(out), "--no-progress"])
    assert (out / cli.CHECKPOINT_NAME).exists()
    assert "the computed branch is kept in" in capsys.readouterr().err
    monkeypatch.undo()
    assert cli.main(["run", str(case), "--out", str(out), "--no-progress"]) == 0
    assert (out / "response.npz").exists() and not (out / cli.CHECKPOINT_NAME).exists()


NO_START = """
[model]
kind = "discrete"
M = [[1.0, 0.0], [0.0, 1.0]]
K = [[2.0, -1.0], [-1.0, 2.0]]
[[contact]]
at = 1
gap = 0.1
[analysis]
type = "nonlinear_mode"
mode = 1
energy = [1e6, 2e6]
energy_unit = "grazing"
harmonics = 3
[outputs]
animation = false
"""


def test_summary_of_a_run_without_points_and_relative_contact_quality(tmp_path):
    """A backbone whose start fails (10^6 grazing energies) ended in an IndexError with no
    summary.txt; and the contact quality labelled "relative" printed the absolute penetration and
    tension (0.00166 for 13 % of the contact amplitude)."""
    import re

    from femodes.app import cases
    res = cases.run_case(cases.parse_case(NO_START, tmp_path / "nostart.toml"), tmp_path / "a")
    assert len(res.branch) == 0 and any("no points, success=False" in line for line in res.lines)
    assert (tmp_path / "a" / "summary.txt").exists()
    text = NO_START.replace("energy = [1e6, 2e6]", "energy = [0.5, 4.0]")
    res = cases.run_case(cases.parse_case(text, tmp_path / "nnm.toml"), tmp_path / "b")
    line = next(ln for ln in res.lines if ln.startswith("contact quality"))
    pen, ten = res.branch.contact_quality()
    shown = re.search(r"max penetration (\S+) of the largest contact displacement \((\S+) absolute\)", line)
    assert float(shown[1]) == pytest.approx(pen.max(), rel=5e-3) and float(shown[2]) == pytest.approx(
        res.branch.penetration.max(), rel=5e-3)  # 3 digits shown


def test_paraview_series_of_an_error_controlled_point_names_both_frequencies(tmp_path):
    """The files gave omega = the converged frequency and period = 2 pi / the truncated one (2.6 %
    apart on this bar) with nothing saying which is which."""
    import meshio
    mesh = fm.line_mesh(1.0, 6, boundaries={"clamp": 0.0, "tip": 1.0})
    model = (fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp").with_damping(beta=0.02)
             .with_contact(fm.UnilateralContact(at="tip", gap=0.01))
             .with_forcing(fm.HarmonicForce(at="tip", amplitude=0.004)))
    frc = fm.frequency_response(model, omega=(1.0, 2.5), harmonics=4, rtol=1e-2)
    i = int(np.argmax(np.abs(frc.omega - frc.omega_truncated)))
    sol = frc[i]
    assert sol.omega != sol.omega_truncated
    fm.io.write_animation(sol, model, tmp_path / "bar", n_frames=4)
    fd = meshio.read(tmp_path / "bar_0000.vtu").field_data
    assert float(fd["omega"][0]) == sol.omega and float(fd["omega_truncated"][0]) == sol.omega_truncated
    assert abs(float(fd["period"][0]) * sol.omega_truncated / (2 * np.pi) - 1) < 1e-14
    assert any(k.startswith("note: the frames are the truncated series") for k in fd)


def test_a_per_node_gap_function_on_a_boundary_of_dim_nodes():
    """``0.01 + 0.5 * np.dot(x, (0, 1))`` is written for one node; on a boundary of exactly 2 nodes
    in 2-D it also ran on the (2, 2) array, as a matrix product, and its gaps [0.51, 0.06] were
    kept instead of [0.01, 0.06]."""
    s = fm.solid(fm.rectangle_mesh(1.0, 0.1, 10, 1, quadrilaterals=True), fm.Material(1.0, 1.0, 0.3), clamped="left")
    for gap in (lambda x: 0.01 + 0.5 * np.dot(x, (0.0, 1.0)), lambda x: 0.01 + 0.5 * x[1]):
        m = s.with_contact(fm.UnilateralContact(at="right", gap=gap, direction=(1.0, 0.0)))
        y = m.dofmap.node_coordinates[1, [int(np.argwhere(m.dofmap.node_dof == a.dof)[0, 0]) for a in m.contacts]]
        assert np.allclose([a.item.gap for a in m.contacts], 0.01 + 0.5 * y, rtol=0, atol=1e-15)


def test_overlapping_subdomains_with_different_materials_are_an_error():
    """The mapping's order chose the material of the shared elements (w1 10451 or 10531 rad/s)."""
    m = fm.line_mesh(1.0, 20, boundaries={"clamp": 0.0}, subdomains={"a": (0.0, 0.6), "b": (0.4, 1.0)})
    steel, alu, sec = fm.Material(210e9, 7800), fm.Material(70e9, 2700), fm.Section(1e-4, 1e-9)
    with pytest.raises(ValueError, match=r"material: subdomains 'a' and 'b' overlap with different values \(4 "):
        fm.bar(m, {"a": steel, "b": alu}, sec, clamped="clamp")
    one = fm.bar(m, {"a": steel, "b": steel}, sec, clamped="clamp")     # the same value: no conflict
    assert fm.linear_modes(one, 1).omega[0] == pytest.approx(fm.linear_modes(
        fm.bar(m, steel, sec, clamped="clamp"), 1).omega[0], rel=1e-12)


@pytest.mark.filterwarnings("error::scipy.linalg.LinAlgWarning")  # scipy's "Diagonal number 4 is exactly zero" leaked
def test_a_singular_start_is_explained_in_the_users_terms():
    """"r_x singular at the start point p=0.5 (start exactly at a fold?)" for an undamped forced
    response whose second harmonic is the resonance, and "p=-2" (log10 of the energy) for a
    backbone of a mode with an exact 2:1 partner."""
    undamped = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.0]]).with_contact(fm.UnilateralContact(at=0, gap=100.0))
                .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))
    with pytest.warns(UserWarning, match="no damping"):
        b = fm.frequency_response(undamped, (0.5, 2.0), 5)
    assert not b.success and "harmonic 2 of w = 0.5 rad/s is the natural frequency w_1 = 1 rad/s" in b.message
    pair = fm.StructuralModel(M=np.eye(2), K=np.diag([1.0, 4.0])).with_contact(fm.UnilateralContact(at=1, gap=0.1))
    b = fm.nonlinear_mode(pair, 1, energy=(0.01, 1.0), harmonics=5)
    assert not b.success and "start energy 0.01" in b.message and "w_2 = 2 w_1 (2 rad/s)" in b.message


def _shared_point_msh() -> str:
    """tests/test_mesh.py's gmsh 4.1 line, its end point (entity 2) also in a group "stop"."""
    from .test_mesh import GMSH41
    text = GMSH41
    for old, new in (('$PhysicalNames\n3\n', '$PhysicalNames\n4\n'), ('0 2 "tip"\n', '0 2 "tip"\n0 4 "stop"\n'),
                     ('2 1 0 0 1 2\n', '2 1 0 0 2 2 4\n')):
        assert old in text
        text = text.replace(old, new)
    return text


def test_a_gmsh_4_entity_in_two_physical_groups_is_said(tmp_path):
    """meshio gives an entity's cells the first of its physical groups: "stop" came back empty (a
    3-D corner in "tip" and "tipcorners" left "tipcorners" 3 of its 4 nodes, and clamped= clamped
    3) without a word."""
    path = tmp_path / "shared.msh"
    path.write_text(_shared_point_msh())
    with pytest.warns(UserWarning, match=r"the point 2 in 'tip', 'stop'\); meshio keeps only the first group of each, "
                      r"so the group 'stop' miss"):
        mesh = fm.load_mesh(path)
    assert "tip" in mesh.boundaries and "stop" not in mesh.boundaries


def test_a_modal_damping_ratio_above_1_is_said():
    """``with_damping(modal=5.0)`` (5 % meant) made every mode overdamped without a word."""
    m = fm.StructuralModel(M=np.eye(2), K=[[2.0, -1.0], [-1.0, 2.0]])
    assert_warns_at_the_users_line(r"damping ratios above 1 \(largest 5\).*5 % is 0\.05", lambda: m.with_damping(modal=5.0),
                                   lambda: m.with_damping(modal=[0.05, 1.0]))   # critical damping is fine


def test_a_contact_at_a_named_point_of_a_solid_without_direction_is_said():
    """On a boundary the contact without ``direction=`` warns that it acts along +x; at a named
    point it did so silently. ``at=(name, "u_x")`` keeps +x and says nothing."""
    s = fm.solid(fm.rectangle_mesh(1.0, 0.1, 8, 2, quadrilaterals=True), fm.Material(1.0, 1.0, 0.3), clamped="left",
                 points={"top_mid": (0.5, 0.1)})
    assert_warns_at_the_users_line(
        r"no direction= for point 'top_mid' of a 2-D solid; the contact acts along \+x \('u_x'\)\. Give the stop's "
        r"direction, e\.g\. direction=\(0\.0, 1\.0\)", lambda: s.with_contact(fm.UnilateralContact(at="top_mid", gap=0.01)),
        lambda: s.with_contact(fm.UnilateralContact(at=("top_mid", "u_x"), gap=0.01)))


def test_a_force_on_a_solid_without_a_component_is_said():
    """``HarmonicForce(at="right")`` on a 2-D solid acted along +x without a word."""
    s = fm.solid(fm.rectangle_mesh(1.0, 0.1, 8, 2, quadrilaterals=True), fm.Material(1.0, 1.0, 0.3), clamped="left")
    assert_warns_at_the_users_line(
        r"HarmonicForce\(at='right'\) names no component on a 2-D solid; the force acts along \+x \('u_x'\)\. Give "
        r"one, e\.g\. at=\('right', 'u_y'\)", lambda: s.with_forcing(fm.HarmonicForce(at="right", amplitude=1.0)),
        lambda: s.with_forcing(fm.HarmonicForce(at=("right", "u_y"), amplitude=1.0)))


def test_branch_meta_that_a_file_cannot_hold_is_named(tmp_path):
    b = fm.frequency_response(oscillator(), (0.8, 1.0), 3)
    b.meta["user"] = np.int64(3)
    with pytest.raises(TypeError, match=r"Branch\.save: meta\['user'\] = np\.int64\(3\) cannot be stored|"
                       r"Branch\.save: meta\['user'\] = 3 cannot be stored"):
        b.save(tmp_path / "b.npz")
    b.meta["user"] = 3
    assert fm.load_branch(b.save(tmp_path / "b.npz")).meta["user"] == 3


def test_an_animation_path_that_names_a_folder_is_refused(tmp_path):
    """``write_animation(sol, model, "d/")`` wrote d.pvd and d_0000.vtu next to the folder, and
    ``"x.vtk"`` gave x.vtk.pvd."""
    mesh = fm.line_mesh(1.0, 4, boundaries={"clamp": 0.0, "tip": 1.0})
    model = (fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp").with_damping(beta=0.02)
             .with_contact(fm.UnilateralContact(at="tip", gap=0.01)).with_forcing(fm.HarmonicForce(at="tip", amplitude=0.004)))
    sol = fm.frequency_response(model, omega=(1.0, 1.2), harmonics=3)[0]
    with pytest.raises(ValueError, match=r"got the folder '.*d/'; give a stem inside it, e\.g\. '.*d/mode1'"):
        fm.io.write_animation(sol, model, str(tmp_path / "d") + "/", n_frames=2)
    pvd = fm.io.write_animation(sol, model, tmp_path / "x.vtk", n_frames=2)
    assert pvd.name == "x.pvd" and (tmp_path / "x_0001.vtu").exists()


def test_a_spring_or_point_mass_on_a_support_is_an_error():
    """Accepted and without effect (the DOF is eliminated), where a contact or force is refused."""
    m = fm.line_mesh(1.0, 4, boundaries={"clamp": 0.0, "tip": 1.0})
    for arg in ("springs", "point_masses"):
        with pytest.raises(ValueError, match=rf"bar: {arg}\['clamp'\] acts on a supported DOF"):
            fm.bar(m, fm.Material(1.0, 1.0), fm.Section(1.0), clamped="clamp", **{arg: {"clamp": 5.0}})
    tip = fm.bar(m, fm.Material(1.0, 1.0), fm.Section(1.0), clamped="clamp", point_masses={"tip": 5.0})
    assert tip.M.diagonal().max() > 5.0


def test_fewer_linear_modes_than_asked_are_said(caplog):
    m = fm.StructuralModel(M=[[1.0, 0.0], [0.0, 0.0]], K=[[2.0, -1.0], [-1.0, 2.0]])
    with caplog.at_level(logging.WARNING):
        w = fm.linear_modes(m, 2).omega
    assert w.size == 1 and abs(w[0] - np.sqrt(1.5)) < 1e-12     # the massless DOF condensed: k = 2 - 1/2
    assert any("2 modes asked, the model has 1: 1 of its 2 DOFs are massless" in r.getMessage() for r in caplog.records)


def test_femodes_run_into_the_folder_of_another_case_is_refused(tmp_path, capsys):
    """The second case's outputs were written beside the first's (its animation, backbone and plot
    stayed) under the second's summary, without a word."""
    from pathlib import Path

    from femodes.app import cli
    cases_dir = Path(__file__).resolve().parents[1] / "examples" / "cases"
    out = tmp_path / "o"
    assert cli.main(["run", str(cases_dir / "oscillator_frc.toml"), "--out", str(out), "--no-progress"]) == 0
    capsys.readouterr()
    assert cli.main(["run", str(cases_dir / "oscillator_stability.toml"), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"femodes run: --out {str(out)!r} holds the outputs of case") and "oscillator_frc.toml" in err
    # the same case again (by another path) is fine
    assert cli.main(["run", str(cases_dir / ".." / "cases" / "oscillator_frc.toml"), "--out", str(out),
                     "--no-progress"]) == 0
