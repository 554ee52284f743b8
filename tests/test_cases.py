"""femodes run: TOML case files (femodes/app/cases/__init__.py) and the command line."""

from __future__ import annotations

import io
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import femodes as fm
from femodes.app import cases
from femodes.app.cli import main
from femodes.app.progress import ProgressBar

ROOT = Path(__file__).resolve().parents[1]
CASES = ROOT / "examples" / "cases"
NNM = CASES / "cantilever_nnm.toml"
FRC = CASES / "oscillator_frc.toml"
STAB = CASES / "oscillator_stability.toml"


def _run(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "femodes.app.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=120)


# --------------------------------------------------------------------------------- end to end
def test_oscillator_frc_case(tmp_path):
    r = _run("run", FRC, "--out", tmp_path, "--no-progress")
    assert r.returncode == 0, r.stderr
    assert "outputs written to" in r.stdout
    for name in ("response.npz", "response.png", "summary.txt"):
        assert (tmp_path / name).is_file()
    br = fm.load_branch(tmp_path / "response.npz")
    assert br.success and br.kind == "forced"
    folds = sorted(br.omega[list(br.folds)])
    assert folds == pytest.approx([1.08077, 1.38498], abs=2e-4)
    assert br.omega[0] == pytest.approx(0.5) and br.omega[-1] == pytest.approx(2.0)


def test_cantilever_nnm_case(tmp_path):
    r = _run("run", NNM, "--out", tmp_path, "--progress")
    assert r.returncode == 0, r.stderr
    assert "log10(energy) = " in r.stderr and " point " in r.stderr and "s = " in r.stderr  # the progress display
    for name in ("backbone.npz", "frequency_energy.png", "animation.pvd", "summary.txt"):
        assert (tmp_path / name).is_file()
    br = fm.load_branch(tmp_path / "backbone.npz")
    assert br.success and br.kind == "nonlinear mode"
    assert br.omega[0] == pytest.approx(3.5162, abs=2e-3)  # linear w1 with the contact node
    assert br.omega.max() > br.omega[0] + 0.1  # stiffening by the stop
    assert np.max(np.abs(br.xi)) < 1e-8
    assert br.energy[0] == pytest.approx(7.725e-5, rel=1e-6) and br.energy[-1] == pytest.approx(3.09e-3, rel=1e-6)


def test_oscillator_stability_case_reports_the_period_doubling(tmp_path, capsys):
    """examples/cases/oscillator_stability.toml (the seed contact oscillator, stability = true):
    the impacting orbit period-doubles at w = 0.996204 (shooting; tests/test_stability.py)."""
    assert main(["run", str(STAB), "--out", str(tmp_path), "--no-progress"]) == 0
    out = capsys.readouterr().out
    summary = (tmp_path / "summary.txt").read_text()
    assert summary.strip() in out  # what femodes run prints is summary.txt
    br = fm.load_branch(tmp_path / "response.npz")
    assert br.stable is not None and set(br.stability_method) == {"shooting"}
    pd = [b for b in br.bifurcations if b.kind == "period_doubling"]
    assert len(pd) == 1 and pd[0].omega == pytest.approx(0.996204, abs=2e-6)
    # the summary states the stable/unstable counts and lists the bifurcation with w to 6 digits
    n_stable = int(br.stable.sum())
    assert 0 < n_stable < len(br)
    assert f"stability (shooting): {n_stable} stable, {len(br) - n_stable} unstable of {len(br)} points" in summary
    assert f"bifurcations: {len(br.bifurcations)}" in summary
    m = re.search(r"^  period_doubling at w = (\S+) \(between points (\d+) and \d+, multiplier (\S+)\)$", summary,
                  flags=re.M)
    assert m, summary
    assert float(m.group(1)) == pytest.approx(0.996204, abs=2e-6) and m.group(1) == "0.996204"
    assert int(m.group(2)) == pd[0].index and float(m.group(3)) == pytest.approx(-1.0, abs=1e-5)


def test_stability_key_reaches_both_analyses(tmp_path):
    """stability = "hill" on a nonlinear mode and false (the default) on a forced response: the
    branch has stability exactly when asked, and the summary says so."""
    nnm = """
[model]
kind = "discrete"
M = [[1.0]]
K = [[1.0]]
[[cubic]]
at = 0
k3 = 0.5
[analysis]
type = "nonlinear_mode"
energy = [1e-3, 1e-1]
harmonics = 3
stability = "hill"
[outputs]
plot = false
branch = false
"""
    res = cases.run_case(cases.parse_case(nnm, tmp_path / "nnm.toml"), tmp_path / "nnm")
    assert res.branch.stable is not None and set(res.branch.stability_method) == {"hill"}
    n_stable = int(res.branch.stable.sum())
    assert any(line.startswith(f"stability (hill): {n_stable} stable") for line in res.lines)
    assert any(line.startswith("bifurcations: ") for line in res.lines)
    frc = _frc(**{"harmonics = 20": "harmonics = 3\nmax_points = 5\nstability = false", "plot = true": "plot = false"})
    res = cases.run_case(cases.parse_case(frc, tmp_path / "frc.toml"), tmp_path / "frc")
    assert res.branch.stable is None and not any(line.startswith(("stability", "bifurcations")) for line in res.lines)


def test_rtol_and_grazing_energy_unit_in_case_files(tmp_path):
    """[analysis] rtol reaches the analysis (issue 36: case files refused it) and the summary gives
    the error estimate and the contact quality; energy_unit = "grazing" gives a backbone's span in
    multiples of the grazing energy (femodes.grazing_energy), and summary.txt lists the tongues."""
    frc = _frc(**{"harmonics = 20": "harmonics = 10\nrtol = 1e-2", "plot = true": "plot = false",
                  'branch = "response.npz"': "branch = false"})
    res = cases.run_case(cases.parse_case(frc, tmp_path / "frc.toml"), tmp_path / "frc")
    assert res.branch.accuracy is not None and res.branch.accuracy.rtol == 1e-2
    assert any(line.startswith("error estimate (harmonic truncation): frequency largest") and "rtol = 0.01 met at" in line
               for line in res.lines)
    assert any(line.startswith("contact quality (truncated Fourier series, relative): max penetration")
               for line in res.lines)
    bar = """
[mesh]
length = 1.0
n_elements = 20
boundaries = { clamp = 0.0, tip = 1.0 }
[model]
kind = "bar"
E = 1.0
rho = 1.0
area = 1.0
clamped = ["clamp"]
[[contact]]
at = "tip"
gap = 0.01
[analysis]
type = "nonlinear_mode"
energy = [0.5, 25]
energy_unit = "grazing"
harmonics = 10
[outputs]
plot = false
branch = false
animation = false
"""
    res = cases.run_case(cases.parse_case(bar, tmp_path / "bar.toml"), tmp_path / "bar")
    mesh = fm.line_mesh(1.0, 20, boundaries={"clamp": 0.0, "tip": 1.0})
    eg = fm.grazing_energy(fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
                           .with_contact(fm.UnilateralContact(at="tip", gap=0.01)))
    assert res.branch.energy[0] == pytest.approx(0.5 * eg, rel=1e-2) and res.branch.energy.max() >= 25 * eg * 0.99
    assert any(line.startswith("internal-resonance tongues stepped over at w = ") for line in res.lines)
    with pytest.raises(cases.CaseError, match="rtol must be a relative error in"):
        cases.parse_case(frc.replace("rtol = 1e-2", "rtol = 2.0"), "x.toml")
    with pytest.raises(cases.CaseError, match="energy_unit is only for nonlinear_mode"):
        cases.parse_case(frc.replace("rtol = 1e-2", 'energy_unit = "grazing"'), "x.toml")
    with pytest.raises(cases.CaseError, match='energy_unit must be "grazing"'):
        cases.parse_case(bar.replace('energy_unit = "grazing"', 'energy_unit = "joule"'), "x.toml")


# --------------------------------------------------------------------------------- bad case files
def _bad(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    r = _run("run", p, "--out", tmp_path / "o", "--no-progress")
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    return r.stderr.strip()


def _frc(**subs):
    t = FRC.read_text()
    for a, b in subs.items():
        assert a in t
        t = t.replace(a, b)
    return t


def _nnm(**subs):
    t = NNM.read_text().replace('"../../meshes/cantilever.msh"', repr(str(ROOT / "meshes" / "cantilever.msh")).replace("'", '"'))
    for a, b in subs.items():
        assert a in t
        t = t.replace(a, b)
    return t


def _line(text, start):
    return next(i for i, l in enumerate(text.splitlines(), 1) if l.startswith(start))


def test_bad_syntax(tmp_path):
    t = _frc(**{"gap = 1.0": "gap = 1.0 2.0"})
    err = _bad(tmp_path, "syntax.toml", t)
    assert f"syntax.toml:{_line(t, 'gap = ')}: TOML syntax error" in err


def test_bad_unknown_key_suggests(tmp_path):
    t = _frc(**{"gap = 1.0": "gpa = 1.0"})
    err = _bad(tmp_path, "typo.toml", t)
    assert f"typo.toml:{_line(t, 'gpa')}: [contact] unknown key 'gpa' (did you mean 'gap'?)" in err


def test_bad_negative_gap(tmp_path):
    t = _nnm(**{"gap = 0.01": "gap = -0.1"})
    err = _bad(tmp_path, "neg.toml", t)
    assert err.endswith(f"neg.toml:{_line(t, 'gap =')}: [contact] gap must be >= 0, got -0.1")


def test_bad_missing_analysis(tmp_path):
    t = _frc().split("[analysis]")[0]
    err = _bad(tmp_path, "noan.toml", t)
    assert "noan.toml:1: missing table [analysis]" in err


def test_bad_type(tmp_path):
    t = _frc(**{"harmonics = 20": 'harmonics = "20"'})
    err = _bad(tmp_path, "type.toml", t)
    assert f"type.toml:{_line(t, 'harmonics')}: [analysis] harmonics must be an integer, got '20'" in err


def test_bad_stability_value(tmp_path):
    t = _frc(**{"harmonics = 20": 'harmonics = 20\nstability = "shoot"'})
    err = _bad(tmp_path, "stab.toml", t)
    assert err.endswith(f"stab.toml:{_line(t, 'stability')}: [analysis] stability must be true, false or one of "
                        "'auto', 'hill', 'shooting', got 'shoot' (did you mean 'shooting'?)")
    for bad, quoted in (("1", "1"), ('["hill"]', "['hill']"), ('"true"', "'true'")):
        t = _frc(**{"harmonics = 20": f"harmonics = 20\nstability = {bad}"})
        with pytest.raises(cases.CaseError) as ei:
            cases.parse_case(t, "x.toml")
        assert ei.value.line == _line(t, "stability") and "[analysis] stability must be true, false" in str(ei.value)
        assert str(ei.value).endswith(f"got {quoted}")


def test_bad_branch_path(tmp_path):
    """[outputs] branch names a file of the output folder: a path would be written elsewhere, while
    the run reports the outputs in that folder ("../x.npz" went to the folder's parent)."""
    for bad in ("../escape.npz", "sub/branch.npz", "/tmp/branch.npz", "..\\branch.npz"):
        t = _frc(**{'branch = "response.npz"': f"branch = {bad!r}"})
        with pytest.raises(cases.CaseError) as ei:
            cases.parse_case(t, "x.toml")
        assert ei.value.line == _line(t, "branch =") and "written in the output folder (choose it with --out)" in str(ei.value)
    # checked before the run: "response.txt" ended in a traceback after it, and the run's points were
    # removed; "checkpoint.npz" was written and then removed as the run's own checkpoint, while the run
    # reported it among its outputs
    for bad, says in (("response.txt", "branch must end in .npz, .h5, .hdf5"),
                      ("checkpoint.npz", "is the name of the run's own checkpoint")):
        t = _frc(**{'branch = "response.npz"': f"branch = {bad!r}"})
        with pytest.raises(cases.CaseError) as ei:
            cases.parse_case(t, "x.toml")
        assert ei.value.line == _line(t, "branch =") and says in str(ei.value)
    cases.parse_case(_frc(), "x.toml")


def test_bad_location(tmp_path):
    t = _nnm(**{'at = "tip"': 'at = "tipp"'})
    err = _bad(tmp_path, "tipp.toml", t)
    assert f"tipp.toml:{_line(t, 'at =')}: [contact]" in err and "'tipp'" in err and "did you mean 'tip'" in err


def test_help_mentions_commands():
    r = _run("--help")
    assert r.returncode == 0
    assert "run" in r.stdout and "demo" in r.stdout and "examples/cases" in r.stdout
    r = _run("run", "--help")
    assert r.returncode == 0 and "[[contact]]" in r.stdout and "--no-progress" in r.stdout


def test_missing_case_file(tmp_path, capsys):
    assert main(["run", str(tmp_path / "nope.toml"), "--no-progress"]) == 2
    assert "nope.toml: case file not found" in capsys.readouterr().err


# --------------------------------------------------------------------------------- unit tests
def test_key_line_tables_and_arrays():
    text = "[model]\nkind = 'beam'\n\n[[contact]]\nat = 'a'\ngap = 1\n[[contact]]\nat = 'b'\ngap = 2\n"
    assert cases.key_line(text, "model", "kind") == 2
    assert cases.key_line(text, "contact", "gap", 0) == 6
    assert cases.key_line(text, "contact", "gap", 1) == 9
    assert cases.key_line(text, "contact", None, 1) == 7
    assert cases.key_line(text, "contact", "c", 1) == 7  # missing key: its table header
    assert cases.key_line(text, "damping", "alpha") is None


def test_parse_case_errors_unit():
    good = FRC.read_text()
    case = cases.parse_case(good, "x.toml")
    assert case.data["analysis"]["harmonics"] == 20
    with pytest.raises(cases.CaseError, match=r"x.toml:\d+: \[model\] kind must be one of .*did you mean 'beam'"):
        cases.parse_case(good.replace('"discrete"', '"beem"'), "x.toml")
    with pytest.raises(cases.CaseError, match=r"\[analysis\] type must be .*did you mean 'nonlinear_mode'"):
        cases.parse_case(good.replace('"frequency_response"', '"nonlinear_mod"'), "x.toml")
    with pytest.raises(cases.CaseError, match=r"penalty contact needs stiffness"):
        cases.parse_case(good.replace("gap = 1.0", 'gap = 1.0\nlaw = "penalty"'), "x.toml")
    with pytest.raises(cases.CaseError, match=r"unknown table \[forse\] \(did you mean 'force'\?\)"):
        cases.parse_case(good.replace("[[force]]", "[[forse]]"), "x.toml")
    err = None
    try:
        cases.parse_case(good.replace("[[force]]\nat", "[[force]]\nat").replace("amplitude = 0.2", "amplitude = true"), "x.toml")
    except cases.CaseError as exc:
        err = exc
    assert err is not None and err.line == _line(good, "amplitude") and "amplitude must be a number" in str(err)


def test_build_model_line_mesh_and_library_errors(tmp_path):
    text = """
[mesh]
length = 1.0
n_elements = 20
boundaries = { clamp = 0.0, tip = 1.0 }
[model]
kind = "beam"
E = 1.0
rho = 1.0
area = 1.0
inertia = 1.0
clamped = "clamp"
[damping]
modal = 0.01
[[contact]]
at = ["tip", "w"]
gap = 0.01
law = "penalty"
stiffness = 100.0
[[cubic]]
at = "tip"
k3 = 2.0
[[force]]
at = "tip"
amplitude = 0.01
[reduction]
craig_bampton = 4
[analysis]
type = "frequency_response"
omega = [3.0, 4.0]
harmonics = 3
"""
    case = cases.parse_case(text, tmp_path / "c.toml")
    model, full = cases.build_model(case)
    assert model.is_reduced and full.n_dofs == 40 and len(full.contacts) == 1 and len(full.nonlinearities) == 1
    # a ValueError of the library is reported at the key that caused it
    bad = cases.parse_case(text.replace("clamp = 0.0, tip = 1.0", "clamp = 0.0, tip = 1.03"), tmp_path / "c.toml")
    with pytest.raises(cases.CaseError) as ei:
        cases.build_model(bad)
    assert ei.value.line == _line(text, "boundaries") and "[mesh]" in str(ei.value)
    bad = cases.parse_case(text.replace('clamped = "clamp"', 'clamped = "clomp"'), tmp_path / "c.toml")
    with pytest.raises(cases.CaseError) as ei:
        cases.build_model(bad)
    assert ei.value.line == _line(text, "clamped")


def test_progress_bar_fraction_clipped():
    s = io.StringIO()
    bar = ProgressBar((-4.0, -2.0), "log10(energy)", stream=s, width=10)
    assert bar.fraction(-5.0) == 0.0 and bar.fraction(-1.0) == 1.0 and bar.fraction(-3.0) == 0.5
    line = bar.update(-3.0)
    assert "[#####.....]" in line and "50%" in line and "points 1" in line
    bar.close()
    assert s.getvalue().endswith("\n")
    down = ProgressBar((2.0, 0.5), "w", stream=io.StringIO())
    assert down.fraction(1.25) == pytest.approx(0.5)


# --------------------------------------------------------------------------------- meshed solids
STRIP = CASES / "strip2d_contact.toml"


def _strip(**subs):
    t = STRIP.read_text()
    for a, b in subs.items():
        assert a in t, a
        t = t.replace(a, b)
    return t


def test_strip2d_contact_case_builds_the_api_model_and_runs(tmp_path):
    """examples/cases/strip2d_contact.toml: the model is the one fm.solid builds, and a few points
    of its forced response run; the first point (w = 1, tip amplitude 0.006 < gap 0.01) is the
    linear response."""
    text = _strip(**{"harmonics = 5": "harmonics = 5\nmax_points = 4", "plot = true": "plot = false",
                     "animation = true": "animation = false"})
    case = cases.parse_case(text, tmp_path / "strip.toml")
    model, full = cases.build_model(case)
    assert model is full and model.fe.kind == "solid" and model.n_dofs == 2 * 21 * 3 - 2 * 3
    ref = (fm.solid(fm.rectangle_mesh(1.0, 0.1, 20, 2, quadrilaterals=True), fm.Material(E=1.0, rho=1.0, nu=0.3),
                    clamped="left", plane="stress", thickness=1.0)
           .with_damping(beta=0.02)
           .with_contact(fm.UnilateralContact(at="right", gap=0.01, direction=(1.0, 0.0)))
           .with_forcing(fm.HarmonicForce(at=("right", "u_x"), amplitude=0.0004)))
    for a, b in ((model.K, ref.K), (model.M, ref.M), (model.C, ref.C)):
        assert abs(a - b).max() == 0.0
    assert [c.dof for c in model.contacts] == [c.dof for c in ref.contacts] and len(model.contacts) == 3
    assert np.array_equal(model.force_vectors()[1], ref.force_vectors()[1])
    res = cases.run_case(case, tmp_path / "out")
    br = res.branch
    assert len(br) == 4 and np.all(br.converged) and br.omega[0] == pytest.approx(1.0)
    sol = br[0]
    t = np.linspace(0.0, 2 * np.pi, 9)
    lin = fm.linear_response(model, 1.0).amplitude[0]
    expect = (lin[None, :] * np.exp(1j * t)[:, None]).real
    assert np.max(np.abs(sol.displacement(t) - expect)) < 1e-8 * np.max(np.abs(expect))
    assert np.max(np.abs(sol.contact_force(t))) == 0.0
    assert (tmp_path / "out" / "summary.txt").is_file() and any("solid" in line for line in res.lines)


def test_box_case_with_hexahedra_and_craig_bampton(tmp_path):
    text = """
[mesh]
length = 1.0
width = 0.2
height = 0.1
nx = 6
ny = 2
nz = 1
hexahedra = true
[model]
kind = "solid"
E = 1.0
rho = 1.0
clamped = ["left"]
order = 1
supports = { bottom = ["u_z"] }
[[contact]]
at = "right"
direction = [1.0, 0.0, 0.0]
gap = 0.01
law = "penalty"
stiffness = 10.0
[[force]]
at = ["right", "u_x"]
amplitude = 0.001
[reduction]
craig_bampton = 5
[analysis]
type = "frequency_response"
omega = [1.0, 2.0]
harmonics = 2
"""
    model, full = cases.build_model(cases.parse_case(text, tmp_path / "box.toml"))
    ref = fm.solid(fm.box_mesh(1.0, 0.2, 0.1, 6, 2, 1, hexahedra=True), fm.Material(E=1.0, rho=1.0), clamped="left",
                   supports={"bottom": ("u_z",)})
    # 42 nodes: the 6 of the clamped face fixed, u_z of the other 18 bottom nodes fixed
    assert full.n_dofs == ref.n_dofs == 3 * 42 - 3 * 6 - 18
    assert len(full.contacts) == 6 and model.is_reduced and model.n_dofs == 6 + 5


@pytest.mark.parametrize("subs, line_of, message", [
    ({"ny = 2": "ny = 2\nnz = 2"}, "quad", "[mesh] quad is for rectangles (2-D); a box (nz) takes hexahedra = true"),
    ({"ny = 2": "ny = 2\nn_elements = 20"}, "n_elements", "[mesh] n_elements is for line meshes (beam, bar)"),
    ({"ny = 2\n": ""}, "[mesh]", "[mesh] a generated solid mesh needs nx and ny (and nz for a box), or file = \"...\"; "
                                 "ny is missing"),
    ({"nx = 20": "nx = 0"}, "nx", "[mesh] nx must be >= 1, got 0"),
    ({"height = 0.1": "height = -0.1"}, "height", "[mesh] height must be > 0, got -0.1"),
    ({"ny = 2": "ny = 2\nwidth = 0.1"}, "width", "[mesh] width is for boxes (3-D): give nz too"),
    ({"quad = true": "hexahedra = true\nnz = 1"}, "plane", "[model] plane applies to 2-D solids; [mesh] with nz is a "
                                                        "3-D box"),
    ({'plane = "stress"': 'plane = "stres"'}, "plane", "[model] plane must be \"stress\" or \"strain\", got 'stres' "
                                                      "(did you mean 'stress'?)"),
    ({"thickness = 1.0": "thickness = 0.0"}, "thickness", "[model] thickness must be > 0, got 0.0"),
    ({"order = 1": "order = 3"}, "order", "[model] order must be 1 or 2, got 3"),
    ({"nu = 0.3\n": "nu = 0.3\narea = 0.1\n"}, "area", "[model] area is not used by a solid model (a 2-D solid takes "
                                                   "thickness = ...)"),
    ({"nu = 0.3\n": 'nu = 0.3\nsupports = { bottom = 1 }\n'}, "supports", "[model] supports must be a table like"),
    ({"direction = [1.0, 0.0]": "direction = [1.0, 0.0, 0.0, 0.0]"}, "direction",
     "[contact] direction must be a vector of 1 to 3 numbers like [1.0, 0.0], got [1.0, 0.0, 0.0, 0.0]"),
    ({"E = 1.0\n": ""}, "[model]", "[model] a solid model needs E = ..."),
])
def test_bad_solid_case_names_the_key(tmp_path, subs, line_of, message):
    text = _strip(**subs)
    with pytest.raises(cases.CaseError) as ei:
        cases.parse_case(text, tmp_path / "bad.toml")
    assert message in str(ei.value)
    assert ei.value.line == (_line(text, line_of) if not line_of.startswith("[") else _line(text, line_of))


@pytest.mark.parametrize("subs, key, message", [
    ({"direction = [1.0, 0.0]": "direction = [1.0, 0.0, 0.0]"}, "direction", "has 3 components, this model is 2-D"),
    ({'clamped = "left"': 'clamped = "lft"'}, "clamped", "'lft'"),
    ({"nu = 0.3\n": "nu = 0.5\n"}, "nu", "nu must satisfy -1 < nu < 0.5"),
    ({'at = "right"': 'at = "tip"'}, "at", "unknown location 'tip'"),
])
def test_library_errors_of_a_solid_case_point_at_the_key(tmp_path, subs, key, message):
    text = _strip(**subs)
    case = cases.parse_case(text, tmp_path / "bad.toml")
    with pytest.raises(cases.CaseError) as ei:
        cases.build_model(case)
    assert message in str(ei.value) and ei.value.line == _line(text, f"{key} =")


def test_solid_keys_on_a_beam_and_beam_keys_on_a_solid_are_errors():
    nnm = _nnm()
    for subs, message in (({'kind = "beam"': 'kind = "beam"\nnu = 0.3'}, "nu is used by solid models only"),
                          ({"gap = 0.01": "gap = 0.01\ndirection = [1.0, 0.0]"},
                           "direction is for contacts on the boundaries of solids")):
        with pytest.raises(cases.CaseError, match=re.escape(message)):
            cases.parse_case(_nnm(**subs), "x.toml")
    line = FRC.read_text()  # a discrete model: no mesh keys at all; a beam with nx:
    text = """[mesh]\nlength = 1.0\nn_elements = 4\nnx = 4\n[model]\nkind = "bar"\nE = 1.0\nrho = 1.0\narea = 1.0
[analysis]\ntype = "nonlinear_mode"\nenergy = [1e-3, 1e-2]\n"""
    with pytest.raises(cases.CaseError) as ei:
        cases.parse_case(text, "x.toml")
    assert ei.value.line == 4 and 'nx is for the meshes of solids (kind = "solid"); a bar takes a line mesh' in str(ei.value)
    assert "kind" in line and nnm
    # order reaches fm.bar too: a P2 bar of 4 elements clamped at one end has 8 DOFs
    bar = text.replace("nx = 4\n", "").replace('area = 1.0\n', 'area = 1.0\norder = 2\nclamped = "left"\n')
    model, _ = cases.build_model(cases.parse_case(bar, "x.toml"))
    assert model.n_dofs == 8
