"""Nothing silent, nothing lost (issue 37): results reattached, resumed or reused are checked
against what produced them; long runs can be interrupted and resumed; allocations that grow with
H, contacts or DOFs are estimated first; every failure is one sentence naming its cause."""

from __future__ import annotations


import numpy as np
import pytest

import femodes as fm

SPAN = (0.8, 1.6)


def contact_oscillator(gap=1.0, alpha=0.1, amplitude=0.2):
    return (fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_damping(alpha=alpha)
            .with_forcing(fm.HarmonicForce(at=0, amplitude=amplitude))
            .with_contact(fm.UnilateralContact(at=0, gap=gap)))


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """A short branch of the gap-1.0 oscillator, saved to a file."""
    model = contact_oscillator()
    br = fm.frequency_response(model, omega=(0.8, 1.0), harmonics=5)
    path = tmp_path_factory.mktemp("saved") / "frc.npz"
    br.save(path)
    return model, br, path


# -- item 1: a saved branch is tied to its model --------------------------------------------------
def test_load_branch_refuses_a_model_with_another_gap(saved):
    model, _, path = saved
    with pytest.raises(ValueError, match=r"contact 0 \(DOF 0\): gap 1 in the result, 0\.5 in this model"):
        fm.load_branch(path, model=contact_oscillator(gap=0.5))


def test_attach_refuses_other_damping_and_forcing(saved):
    model, _, path = saved
    br = fm.load_branch(path)
    with pytest.raises(ValueError, match="damping"):
        br.attach(contact_oscillator(alpha=0.2))
    with pytest.raises(ValueError, match="forcing"):
        br.attach(contact_oscillator(amplitude=0.3))
    with pytest.raises(ValueError, match="contact 0.*penalty"):
        br.attach(fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_damping(alpha=0.1)
                  .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2))
                  .with_contact(fm.PenaltyContact(at=0, gap=1.0, stiffness=100.0)))
    assert br.attach(contact_oscillator()).model is not None  # an equal model (another object) is fine


def test_in_memory_branch_attach_refuses_another_model(saved):
    _, br, _ = saved
    with pytest.raises(ValueError, match="gap"):
        br.attach(contact_oscillator(gap=0.5))


def test_old_branch_file_without_fingerprint_loads_with_a_warning(saved, tmp_path):
    from femodes.store import read_record, write_record

    _, _, path = saved
    header, arrays = read_record(path)
    header.pop("model")
    old = write_record(tmp_path / "old.npz", header, arrays)
    with pytest.warns(UserWarning, match="cannot be checked"):
        br = fm.load_branch(old, model=contact_oscillator())
    assert br.model is not None
    with pytest.raises(ValueError, match="gap"):  # the contacts stored in every file are still compared
        fm.load_branch(old, model=contact_oscillator(gap=0.5))


# -- item 2: a sweep never overwrites another sweep's study -----------------------------------------
def _sweep_args(out, gaps):
    from pathlib import Path

    frc = Path(__file__).resolve().parents[1] / "examples" / "cases" / "oscillator_frc.toml"
    return ["sweep", str(frc), "--set", f"contact.0.gap={gaps}", "--set", "analysis.harmonics=3",
            "--set", "analysis.max_points=6", "--scheduler", "threads", "--out", str(out), "--no-progress"]


@pytest.fixture
def thread_executor(monkeypatch):
    """`--scheduler threads` runs the sweep on a thread pool (no Dask cluster in a unit test)."""
    import concurrent.futures as cf

    from femodes.app.sweep import run as sweep_run

    real = sweep_run.run_sweep

    def run_sweep(case, params, *, executor=None, **kw):
        if executor == "threads":
            with cf.ThreadPoolExecutor(1) as ex:
                return real(case, params, executor=ex, **kw)
        return real(case, params, executor=executor, **kw)

    monkeypatch.setattr(sweep_run, "run_sweep", run_sweep)
    import femodes.app.sweep as sweep_pkg

    monkeypatch.setattr(sweep_pkg, "run_sweep", run_sweep)
    return run_sweep


def test_second_sweep_into_the_same_out_is_refused(tmp_path, capsys, thread_executor):
    from femodes.app.cli import main
    from femodes.app.sweep import load_study

    assert main(_sweep_args(tmp_path, "0.5,1.0")) == 0
    first = load_study(tmp_path / "study.npz")
    capsys.readouterr()
    assert main(_sweep_args(tmp_path, "2.0")) == 2
    err = capsys.readouterr().err
    assert err.startswith("femodes sweep: run_sweep: out") and "already holds another sweep" in err
    assert "choose another output folder (--out)" in err and "Traceback" not in err
    again = load_study(tmp_path / "study.npz")  # the first study is untouched
    assert [r.parameters for r in again] == [r.parameters for r in first]
    assert sorted(p.name for p in (tmp_path / "cases").iterdir()) == ["c000", "c001"]


def test_same_sweep_into_the_same_out_resumes(tmp_path):
    import concurrent.futures as cf

    from femodes.app.sweep import load_study, run_sweep
    from pathlib import Path

    frc = Path(__file__).resolve().parents[1] / "examples" / "cases" / "oscillator_frc.toml"
    params = [{"contact.0.gap": g, "analysis.harmonics": 3, "analysis.max_points": 6} for g in (0.5, 1.0, 2.0)]

    def stop(rec, k, n):
        if k == 1:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt), cf.ThreadPoolExecutor(1) as ex:
        run_sweep(frc, params, out=tmp_path, executor=ex, progress=stop)
    before = load_study(tmp_path / "study.npz")
    done = [r.id for r in before if r.ok]
    assert len(done) == 1
    seen = []
    with cf.ThreadPoolExecutor(1) as ex:
        res = run_sweep(frc, params, out=tmp_path, executor=ex, progress=lambda r, k, n: seen.append(r.id))
    assert res.success and sorted(seen) == sorted(set(r.id for r in res) - set(done))  # only the others ran
    assert res[done[0]].wall_time == before[done[0]].wall_time


# -- item 3: switch_branch takes only a bifurcation of the branch it switches from ------------------
def test_switch_branch_refuses_a_bifurcation_of_another_branch():
    model = contact_oscillator(gap=1.0)
    a = fm.frequency_response(model, (0.9, 1.05), 5, stability=True)
    pd = next(z for z in a.bifurcations if z.kind == "period_doubling")
    b = fm.frequency_response(model, (0.8, 0.9), 5)
    with pytest.raises(ValueError, match=r"period_doubling at w = 0\.996204 .* is not one of branch\.bifurcations"):
        fm.switch_branch(b, pd, omega=(0.8, 1.05))


# -- item 4: time steps that cannot resolve the forcing period are refused ---------------------------
def test_steady_state_refuses_three_steps_per_period():
    model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]])
             .with_forcing(fm.HarmonicForce(at=0, amplitude=0.05)))
    with pytest.raises(ValueError, match=r"steady_state: dt=2\.0 gives 2\.62 steps per forcing period .* fewer than "
                                         r"the 20 .* use dt <= 0\.2618"):
        fm.steady_state(model, omega=1.2, dt=2.0)
    with pytest.raises(ValueError, match=r"simulate: dt=0\.5 gives"):
        fm.simulate(model, 20.0, 0.5, omega=1.2)
    ok = fm.steady_state(model, omega=1.2, dt=0.2)  # 27 steps per period: accepted
    assert ok.success
    free = fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]])
    assert fm.simulate(free, 5.0, 0.5, u0=[1.0]).success  # unforced: no forcing period to resolve


# -- item 5: one rule for an explicit error method -------------------------------------------------
def test_explicit_shooting_is_refused_alike_by_frequency_response_and_estimate_error():
    penalty = (fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_damping(alpha=0.1)
               .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2))
               .with_contact(fm.PenaltyContact(at=0, gap=1.0, stiffness=10.0)))
    with pytest.raises(ValueError, match="frequency_response: the shooting error method cannot take this model: the "
                                         "model has penalty contacts"):
        fm.frequency_response(penalty, (0.8, 1.0), 5, rtol=1e-3, error_method=fm.error_methods.Shooting())
    br = fm.frequency_response(penalty, (0.8, 1.0), 5)
    with pytest.raises(ValueError, match="estimate_error: the shooting error method cannot take this branch: the model has "
                                         "penalty contacts"):
        fm.estimate_error(br, method=fm.error_methods.Shooting())
    with pytest.raises(ValueError, match=r"error_method=Levels\(\) chooses how rtol= is met, but rtol is not given"):
        fm.frequency_response(penalty, (0.8, 1.0), 5, error_method=fm.error_methods.Levels())


# -- item 6: the dense Schur complement is estimated before the first solve -------------------------
def strip_with_contacts(n_contacts=9):
    mesh = fm.rectangle_mesh(length=1.0, height=0.1, nx=n_contacts - 1, ny=1)
    model = fm.solid(mesh, fm.Material(E=1.0, rho=1.0, nu=0.3), clamped="left", plane="stress")
    return (model.with_damping(alpha=0.01)
            .with_forcing(fm.HarmonicForce(at=("right", "u_y"), amplitude=1e-3))
            .with_contact(fm.UnilateralContact(at="top", gap=0.01, direction=(0.0, 1.0))))


def test_schur_complement_too_large_for_memory_is_refused_before_solving(monkeypatch):
    from femodes.solvers import checks

    model = strip_with_contacts()
    monkeypatch.setattr(checks, "available_memory", lambda: 0.5 * 2**30)  # a machine with 0.5 GiB free
    with pytest.raises(ValueError, match=r"harmonics: H = 200 with \d+ nonlinear DOFs \(\d+ complementarity contacts\) "
                                         r"gives a dense Schur complement of size \d+ whose factorisation needs about "
                                         r"[\d.]+ GiB, more than the 0\.5 GiB available; use fewer harmonics"):
        fm.frequency_response(model, (0.1, 0.2), 200)


def test_cli_run_reports_memory_in_one_line(monkeypatch, tmp_path, capsys):
    from femodes.app.cli import main
    from femodes.solvers import checks

    monkeypatch.setattr(checks, "available_memory", lambda: 1e6)
    case = tmp_path / "osc.toml"
    case.write_text('[model]\nkind = "discrete"\nM = [[1.0]]\nK = [[1.0]]\n[damping]\nalpha = 0.1\n'
                    '[[contact]]\nat = 0\ngap = 1.0\n[[force]]\nat = 0\namplitude = 0.2\n'
                    '[analysis]\ntype = "frequency_response"\nomega = [0.8, 1.0]\nharmonics = 400\n')
    assert main(["run", str(case), "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert "needs about" in err and "GiB" in err and "use fewer harmonics" in err


# -- item 7: Ctrl-C keeps the work and exits 130 ---------------------------------------------------
CASE = ('[model]\nkind = "discrete"\nM = [[1.0]]\nK = [[1.0]]\n[damping]\nalpha = 0.1\n'
        '[[contact]]\nat = 0\ngap = 1.0\n[[force]]\nat = 0\namplitude = 0.2\n'
        '[analysis]\ntype = "frequency_response"\nomega = [0.8, 1.6]\nharmonics = 5\n'
        '[outputs]\nplot = false\nanimation = false\n')


def test_ctrl_c_in_femodes_run_keeps_the_points_and_the_same_command_resumes(tmp_path, capsys, monkeypatch):
    from femodes.app import progress
    from femodes.app.cli import main

    case = tmp_path / "osc.toml"
    case.write_text(CASE)
    out = tmp_path / "out"
    real = progress.BranchProgress.update
    calls = {"n": 0}

    def ctrl_c_at_point_6(self, point):
        calls["n"] += 1
        if calls["n"] == 6:
            raise KeyboardInterrupt
        return real(self, point)

    monkeypatch.setattr(progress.BranchProgress, "update", ctrl_c_at_point_6)
    assert main(["run", str(case), "--out", str(out), "--progress"]) == 130
    err = capsys.readouterr().err
    assert "Traceback" not in err
    line = err.strip().splitlines()[-1]
    assert line.startswith("femodes run: interrupted; 6 points kept in") and "run the same command again to resume" in line
    assert len(list((out / "checkpoint.npz.points").glob("*.npz"))) == 6
    monkeypatch.setattr(progress.BranchProgress, "update", real)
    assert main(["run", str(case), "--out", str(out), "--no-progress"]) == 0
    resumed = fm.load_branch(out / "branch.npz")
    ref = fm.frequency_response(contact_oscillator(), SPAN, 5)
    assert len(resumed) == len(ref) and np.allclose(resumed.omega, ref.omega, atol=1e-9)
    assert not (out / "checkpoint.npz").exists() and not (out / "checkpoint.npz.points").exists()


def test_ctrl_c_in_femodes_sweep_exits_130_in_one_line(tmp_path, capsys, monkeypatch, thread_executor):
    from femodes.app.cli import main

    real = thread_executor

    def interrupted(case, params, *, progress=False, **kw):
        def stop(rec, k, n):
            raise KeyboardInterrupt
        return real(case, params, progress=stop, **kw)

    import femodes.app.sweep as sweep_pkg

    monkeypatch.setattr(sweep_pkg, "run_sweep", interrupted)
    assert main(_sweep_args(tmp_path, "0.5,1.0")) == 130
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.strip().splitlines() == [
        f"femodes sweep: interrupted; 1 finished case kept in {str(tmp_path / 'study.npz')!r}; run the same command "
        "again to resume"]


# -- item 8: one run per checkpoint ------------------------------------------------------------------
def test_second_run_on_a_locked_checkpoint_is_refused(tmp_path):
    from femodes.store import CheckpointInUse, CheckpointStore

    path = tmp_path / "frc.npz"
    with CheckpointStore(path).lock("other run"):  # as another process running this checkpoint holds it
        with pytest.raises(CheckpointInUse, match=r"frequency_response: checkpoint .*frc\.npz' is in use by another "
                                                  r"run \(process \d+\); wait for that run to finish, or use another "
                                                  r"checkpoint file"):
            fm.frequency_response(contact_oscillator(), (0.8, 1.0), 5, checkpoint=fm.Checkpoint(path, resume=True))
        assert not (tmp_path / "frc.npz.points").exists()  # nothing of the other run touched
    br = fm.frequency_response(contact_oscillator(), (0.8, 1.0), 5, checkpoint=fm.Checkpoint(path, resume=True))
    assert br.success and path.is_file() and not (tmp_path / "frc.npz.lock").exists()


@pytest.mark.slow  # two Python processes: ~5 s on a loaded machine
def test_two_processes_on_one_checkpoint(tmp_path):
    """A second process started on a running checkpoint fails at once with the one-sentence error."""
    import subprocess
    import sys
    import textwrap
    import time

    path = tmp_path / "frc.npz"
    holder = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import time
        from femodes.store import CheckpointStore
        with CheckpointStore({str(path)!r}).lock():
            print("locked", flush=True)
            time.sleep(30)
        """)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        t0 = time.perf_counter()
        second = subprocess.run([sys.executable, "-c", textwrap.dedent(f"""
            import femodes as fm
            m = (fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_damping(alpha=0.1)
                 .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)).with_contact(fm.UnilateralContact(at=0, gap=1.0)))
            fm.frequency_response(m, (0.8, 1.0), 5, checkpoint=fm.Checkpoint({str(path)!r}, resume=True))
            """)], capture_output=True, text=True, timeout=60)
        assert second.returncode != 0 and time.perf_counter() - t0 < 20
        assert f"CheckpointInUse: frequency_response: checkpoint {str(path)!r} is in use by another run (process " \
               f"{holder.pid})" in second.stderr
    finally:
        holder.kill()
        holder.wait()


# -- item 9: load_branch validates the whole schema ---------------------------------------------------
@pytest.mark.parametrize("drop, message", [
    (("header", "harmonics"), "its header has no 'harmonics'"),
    (("header", "kind"), "its header has no 'kind'"),
    (("array", "Q"), "it has no array 'Q'"),
    (("array", "folds"), "it has no array 'folds'"),
    (("contacts", "gaps"), "header field 'contacts' has no list 'gaps'"),
    (("accuracy", "accuracy_rate"), "it has an error estimate but no array 'accuracy_rate'"),
    (("shape", "P"), r"arrays 'Q' \(\d+, 11, 1\) and 'P' \(\d+, 3, 1\) do not fit 5 harmonics \(11 coefficients\) "
                     "and 1 complementarity contacts"),
])
def test_load_branch_names_the_missing_field(saved, tmp_path, drop, message):
    from femodes.store import read_record, write_record

    _, _, path = saved
    header, arrays = read_record(path)
    where, key = drop
    if where == "header":
        header.pop(key)
    elif where == "array":
        arrays.pop(key)
    elif where == "contacts":
        header["contacts"].pop(key)
    elif where == "accuracy":
        header["accuracy"] = {"method": ["doubling"] * len(arrays["omega"]), "rtol": None}
        arrays.update({f"accuracy_{k}": np.zeros(len(arrays["omega"]))
                       for k in ("omega", "amplitude", "penetration", "tension", "harmonics")})
    elif where == "shape":
        arrays["P"] = arrays["P"][:, :3]
    bad = write_record(tmp_path / "bad.npz", header, arrays)
    with pytest.raises(ValueError, match=f"load_branch: .*bad.npz' is incomplete or damaged: {message}; it cannot be "
                                         "read as a branch"):
        fm.load_branch(bad)


def test_load_study_names_what_an_incomplete_study_lacks(tmp_path):
    import json

    from femodes.app.sweep import load_study

    path = tmp_path / "study.npz"
    np.savez(path, header=np.array(json.dumps({"format": "femodes.Study", "version": 2, "parameters": []})))
    with pytest.raises(ValueError, match="load_study: .* is incomplete or damaged: its header has no list 'records'"):
        load_study(path)


# -- item 10: structured meshes check the product of their sizes -------------------------------------
def test_huge_structured_meshes_are_refused_naming_the_divisions():
    with pytest.raises(ValueError, match=r"rectangle_mesh: nx \* ny = 100000 \* 100000 = 1e\+10 grid cells, more than "
                                         r"1e\+07 .*; use fewer divisions"):
        fm.rectangle_mesh(1, 1, 100000, 100000)
    with pytest.raises(ValueError, match=r"box_mesh: nx \* ny \* nz = 1000 \* 1000 \* 100 = 1e\+08 grid cells"):
        fm.box_mesh(1, 1, 1, 1000, 1000, 100)
    assert fm.rectangle_mesh(1, 1, 4, 4).p.shape == (2, 25)


# -- item 11: a zero-area element is named as such ---------------------------------------------------
def test_zero_area_triangle_is_named_not_called_an_overflow():
    import skfem

    p = np.array([[0.0, 1.0, 1.0, 0.0, 0.5], [0.0, 0.0, 1.0, 1.0, 0.0]])
    t = np.array([[0, 1, 2], [0, 2, 3], [0, 4, 1]]).T  # the third triangle is flat (y = 0)
    mesh = skfem.MeshTri(p, t).with_boundaries({"left": lambda x: x[0] < 1e-9})
    with pytest.raises(ValueError, match=r"solid: mesh element 2 has zero area \(vertices \[0, 1, 4\] at \(0, 0\), "
                                         r"\(1, 0\), \(0\.5, 0\) are collinear; 1 such element\); remove or repair"):
        fm.solid(mesh, fm.Material(E=1.0, rho=1.0, nu=0.3), clamped="left")
    tiny = skfem.MeshTri(1e-6 * p[:, :4], np.array([[0, 1, 2], [0, 2, 3]]).T).with_boundaries(
        {"left": lambda x: x[0] < 1e-15})
    assert fm.solid(tiny, fm.Material(E=1.0, rho=1.0, nu=0.3), clamped="left").n_dofs > 0  # small is not flat


# -- item 12: an x0 of the wrong size is named as such -----------------------------------------------
def test_x0_of_the_wrong_size_is_named():
    model = contact_oscillator()
    with pytest.raises(ValueError, match=r"frequency_response: x0 has shape \(3,\), this problem has 22 unknowns "
                                         r"\(1 DOFs x 11 coefficients \+ 11 contact-force coefficients\)"):
        fm.frequency_response(model, (0.8, 1.0), 5, x0=np.zeros(3))
    problem = fm.ForcedResponseProblem(model, fm.Harmonics(5))
    with pytest.raises(ValueError, match=r"continuation: x0 has 3 values, the problem has 22 unknowns"):
        fm.continuation(problem, (0.8, 1.0), x0=np.zeros(3))
    with pytest.raises(ValueError, match=r"static_contact: x0 has shape \(5,\), this problem has 2 unknowns"):
        fm.static_contact(model, x0=np.zeros(5))


# -- item 13: a case file with a UTF-8 byte-order mark reads ------------------------------------------
def test_case_file_with_byte_order_mark_reads(tmp_path):
    from femodes.app.cases import load_case, parse_case

    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + CASE.encode("utf-8"))
    case = load_case(path)
    assert case.data["analysis"]["harmonics"] == 5 and not case.text.startswith("\ufeff")
    assert parse_case("\ufeff" + CASE, path).data["model"]["kind"] == "discrete"


# -- item 14: a --set value of the wrong type exits 2 before anything runs -----------------------------
def test_set_value_of_the_wrong_type_exits_2(tmp_path, capsys):
    from femodes.app.cli import main

    args = _sweep_args(tmp_path, "abc")
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.strip() == "femodes sweep: --set 'contact.0.gap=abc': gap must be a number, got 'abc'"
    assert not (tmp_path / "study.npz").exists()


# -- items 15, 16: absurd scales name their cause ------------------------------------------------------
def test_forcing_amplitude_1e200_is_named():
    with pytest.raises(ValueError, match=r"frequency_response: the response at omega = 0\.8 is 2\.65e\+200, too large "
                                         r"for floating point .* the forcing amplitude \(HarmonicForce amplitude\) is "
                                         r"too large for these units; rescale them"):
        fm.frequency_response(contact_oscillator(amplitude=1e200), (0.8, 1.0), 5)


def test_contact_parameter_and_x0_of_1e300_are_named():
    model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_damping(alpha=0.1)
             .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2))
             .with_contact(fm.UnilateralContact(at=0, gap=1.0, c=1e300)))
    with pytest.raises(ValueError, match=r"frequency_response: the contact parameter c = 1e\+300 \(UnilateralContact "
                                         r"c, DOF 0\) .* leave c=None"):
        fm.frequency_response(model, (0.8, 1.0), 5)
    free = fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_contact(fm.UnilateralContact(at=0, gap=1.0, c=1e300))
    with pytest.raises(ValueError, match=r"nonlinear_mode: the contact parameter c = 1e\+300"):
        fm.nonlinear_mode(free, 1, energy=(0.1, 2.0), harmonics=5)
    with pytest.raises(ValueError, match=r"frequency_response: x0 has entries up to 1e\+300, whose squares overflow"):
        fm.frequency_response(contact_oscillator(), (0.8, 1.0), 5, x0=np.full(22, 1e300))
    penalty = (fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_damping(alpha=0.1)
               .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2))
               .with_contact(fm.PenaltyContact(at=0, gap=1.0, stiffness=1e300)))
    with pytest.raises(ValueError, match=r"frequency_response: the penalty stiffness 1e\+300"):
        fm.frequency_response(penalty, (0.8, 1.0), 5)


# -- item 17: an undamped exact branch names the missing damping at once --------------------------------
def test_undamped_exact_frequency_response_names_the_missing_damping():
    import time

    model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_forcing(fm.HarmonicForce(at=0, amplitude=0.2))
             .with_contact(fm.UnilateralContact(at=0, gap=1.0)))
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match=r"exact_frequency_response: the model has no damping \(C = 0\) and "
                                         r"restitution = 1: nothing dissipates.*add damping"):
        fm.exact_frequency_response(model, (0.5, 2.0))
    assert time.perf_counter() - t0 < 1.0
    damped = model.with_damping(alpha=0.1)
    assert fm.exact_frequency_response(damped, (0.5, 0.6)).success


# -- same class: outputs take the model a solution was solved on -----------------------------------
def test_animation_refuses_a_model_other_than_the_solutions(saved, tmp_path):
    _, br, path = saved
    with pytest.raises(ValueError, match=r"write_animation: model differs from the one the solution was solved on "
                                         r"\(contact 0 \(DOF 0\): gap 1 in the result, 0\.5 in this model\)"):
        fm.io.write_animation(br[0], contact_oscillator(gap=0.5), tmp_path / "anim", n_frames=4)
    loaded = fm.load_branch(path)  # no model: the stored contacts are still compared
    with pytest.raises(ValueError, match="gap 1 in the result"):
        fm.io.write_animation(loaded[0], contact_oscillator(gap=0.5), tmp_path / "anim", n_frames=4)


def test_craig_bampton_basis_too_large_for_memory_is_refused(monkeypatch):
    from femodes.solvers import checks

    model = strip_with_contacts()
    monkeypatch.setattr(checks, "available_memory", lambda: 1e3)
    with pytest.raises(ValueError, match=r"craig_bampton: the dense reduction basis of \d+ DOFs x \d+ kept DOFs \+ 4 "
                                         r"modes needs about .* GiB, more than the .* GiB available; keep fewer DOFs"):
        fm.craig_bampton(model, n_modes=4)


# -- same class: a scaling study does not replace another one -----------------------------------------
def test_scaling_study_into_the_folder_of_another_is_refused(tmp_path, capsys):
    from femodes.app.cli import main

    case = tmp_path / "osc.toml"
    case.write_text(CASE)
    out = tmp_path / "scaling"
    args = ["scaling", str(case), "--harmonics", "3", "--repeat", "1", "--points", "0", "--out", str(out),
            "--no-progress"]
    assert main(args) == 0
    first = (out / "scaling.json").read_text()
    capsys.readouterr()
    assert main(args[:3] + ["5"] + args[4:]) == 2
    err = capsys.readouterr().err
    assert "already holds the scaling study of other settings (harmonics differ)" in err and "Traceback" not in err
    assert (out / "scaling.json").read_text() == first


def test_interrupted_sweep_case_resumes_from_its_journal(tmp_path, monkeypatch, caplog):
    from femodes import runs
    from femodes.app.sweep import run_sweep_case

    real = runs._progress_callback

    def ctrl_c_at_point_5(user_cb, span, label, progress):
        def cb(point):
            if point.index == 5:
                raise KeyboardInterrupt
        return cb

    monkeypatch.setattr(runs, "_progress_callback", ctrl_c_at_point_5)
    with pytest.raises(KeyboardInterrupt):
        run_sweep_case("c000", CASE, str(tmp_path / "c000"))
    assert len(list((tmp_path / "c000" / "checkpoint.npz.points").glob("*.npz"))) == 6
    monkeypatch.setattr(runs, "_progress_callback", real)
    with caplog.at_level("INFO", logger="femodes.runs"):
        rec = run_sweep_case("c000", CASE, str(tmp_path / "c000"))
    assert rec["status"] == "ok" and any("resuming" in r.getMessage() for r in caplog.records)
    assert not (tmp_path / "c000" / "checkpoint.npz.points").exists()


# -- same class: FE assembly is estimated before the basis is built ------------------------------------
def test_fe_assembly_too_large_for_memory_is_refused(monkeypatch):
    from femodes.solvers import checks

    monkeypatch.setattr(checks, "available_memory", lambda: 1e5)
    mesh = fm.rectangle_mesh(1.0, 0.1, 40, 4)
    with pytest.raises(ValueError, match=r"solid: assembling M and K on 320 elements of 6 DOFs each needs about "
                                         r".* GiB, more than the .* GiB available; use a coarser mesh or order=1"):
        fm.solid(mesh, fm.Material(E=1.0, rho=1.0, nu=0.3), clamped="left")
    with pytest.raises(ValueError, match=r"beam: assembling M and K on 2000 elements of 4 DOFs each"):
        fm.beam(fm.line_mesh(length=1.0, n_elements=2000, boundaries={"clamp": 0.0}), fm.Material(E=1.0, rho=1.0),
                fm.Section(area=1.0, inertia=1.0), clamped="clamp")


def test_femodes_run_of_an_edited_case_after_ctrl_c_says_how_to_start_over(tmp_path, capsys, monkeypatch):
    from femodes.app import progress
    from femodes.app.cli import main

    case = tmp_path / "osc.toml"
    case.write_text(CASE)
    out = tmp_path / "out"

    def ctrl_c(self, point):
        raise KeyboardInterrupt

    monkeypatch.setattr(progress.BranchProgress, "update", ctrl_c)
    assert main(["run", str(case), "--out", str(out), "--progress"]) == 130
    monkeypatch.undo()
    case.write_text(CASE.replace("gap = 1.0", "gap = 0.5"))
    capsys.readouterr()
    assert main(["run", str(case), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "was written by a different run" in err and "to start this case over" in err
    assert (out / "checkpoint.npz.points").is_dir()  # the other case's points are not thrown away


def test_second_sweep_while_one_runs_in_the_same_out_is_refused(tmp_path, capsys, thread_executor):
    from femodes.app.cli import main
    from femodes.store import FileInUse, file_lock

    with file_lock(tmp_path / "study.npz.lock", lambda holder: FileInUse(holder)):  # as a running sweep holds it
        assert main(_sweep_args(tmp_path, "0.5")) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"femodes sweep: run_sweep: out {str(tmp_path)!r} is in use by another sweep (process ")
    assert err.endswith("wait for it to finish, or choose another output folder (--out)")
    assert not (tmp_path / "study.npz").exists()
    assert main(_sweep_args(tmp_path, "0.5")) == 0 and not (tmp_path / "study.npz.lock").exists()


def test_huge_spans_are_named_not_an_overflow_error():
    free = fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_contact(fm.UnilateralContact(at=0, gap=1.0))
    with pytest.raises(ValueError, match=r"nonlinear_mode: energy = \(1e\+250, 1e\+280\) is out of the representable "
                                         r"range"):
        fm.nonlinear_mode(free, 1, energy=(1e250, 1e280), harmonics=5)
    problem = fm.ForcedResponseProblem(contact_oscillator(), fm.Harmonics(3))
    with pytest.raises(ValueError, match=r"p_span \(-1e\+200, 1e\+200\): its width squared under- or overflows"):
        fm.continuation(problem, (-1e200, 1e200))


# -- same class: the points a continuation keeps are bounded by the memory available ------------------
def test_continuation_stops_with_its_points_before_memory_runs_out(monkeypatch):
    from femodes import runs

    monkeypatch.setattr(runs, "available_memory", lambda: 2 * 10 * runs.POINT_COPIES * 8 * 22)  # room for 10 points
    br = fm.frequency_response(contact_oscillator(), SPAN, 5)
    assert len(br) == 10 and br.omega[-1] < SPAN[1]
    assert br.message.startswith("stopped at p = ") and "would outgrow the memory available (10 points)" in br.message


# -- same class: an error estimate uses the projection the branch was computed with -------------------
def test_estimate_error_refuses_another_projection_than_the_branchs():
    from femodes.hbm import SampledProjection

    br = fm.frequency_response(contact_oscillator(), (0.8, 1.0), 5, projection=SampledProjection())
    assert br.meta["projection"] == "SampledProjection"
    with pytest.raises(ValueError, match=r"estimate_error: the branch was computed with SampledProjection but "
                                         r"projection=None means ExactProjection"):
        fm.estimate_error(br)


@pytest.mark.parametrize("quad", [False, True])
def test_assembly_memory_estimate_is_near_the_measured_peak(quad):
    import tracemalloc

    import skfem

    from femodes.fe.checks import assembly_memory

    mesh = fm.rectangle_mesh(1.0, 0.1, 60, 6, quadrilaterals=quad)
    scalar = skfem.ElementQuad1() if quad else skfem.ElementTriP1()
    estimate = assembly_memory(mesh, skfem.ElementVector(scalar))
    tracemalloc.start()
    try:
        fm.solid(mesh, fm.Material(E=1.0, rho=1.0, nu=0.3), clamped="left")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    # measured 1.6 (triangles) and ~1 (quadrilaterals) with scikit-fem's default rule; a lower
    # quadrature (fewer points than the estimate assumes) only lowers the peak: on the safe side
    assert 0.5 < estimate / peak < 6.0


def test_animation_over_a_longer_one_leaves_no_stale_frames(tmp_path):
    mesh = fm.line_mesh(length=1.0, n_elements=4, boundaries={"clamp": 0.0, "tip": 1.0})
    model = (fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp").with_damping(alpha=0.1)
             .with_forcing(fm.HarmonicForce(at="tip", amplitude=0.01)))
    sol = fm.frequency_response(model, (0.5, 0.6), 3)[0]
    fm.io.write_animation(sol, model, tmp_path / "anim", n_frames=8)
    (tmp_path / "anim_other_0000.vtu").write_text("not ours")
    fm.io.write_animation(sol, model, tmp_path / "anim", n_frames=4)
    assert sorted(p.name for p in tmp_path.glob("anim_*.vtu")) == [f"anim_{j:04d}.vtu" for j in range(4)] + [
        "anim_other_0000.vtu"]
