"""Parameter sweeps (femodes/app/sweep.py, ``femodes sweep``): executors, failures, study file, CLI."""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import json
import math
import multiprocessing
import os
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

from femodes.app import cases
from femodes.app.cli import main
from femodes.app.sweep import (
    WORKER_ENVIRON,
    apply_overrides,
    load_study,
    local_cluster,
    parse_set,
    run_sweep,
    save_study,
    sweep_cases,
    to_toml,
)

ROOT = Path(__file__).resolve().parents[1]
FRC = ROOT / "examples" / "cases" / "oscillator_frc.toml"
NNM = ROOT / "examples" / "cases" / "cantilever_nnm.toml"
# Tiny cases: 1-DOF oscillator against a stop, 3 harmonics, 12 continuation points (~0.1 s each).
SMALL = {"analysis.harmonics": 3, "analysis.max_points": 12}
GAPS = [0.5, 1.0, 2.0]


def _direct_amplitude(overrides: dict, tmp: Path) -> float:
    """max amplitude of the forced DOF from run_case on the same case, in this process."""
    base = cases.load_case(FRC)
    data = apply_overrides(base.data, overrides)
    data["outputs"] = {"plot": False, "branch": False, "animation": False}
    res = cases.run_case(cases.parse_case(to_toml(data), FRC), tmp)
    return float(res.branch.amplitude(res.model.dof("x")).max())


def _cases(*gaps):
    return [{"contact.0.gap": g, **SMALL} for g in gaps]


# --------------------------------------------------------------------------------- parameters
def test_parameters_product_and_explicit_list():
    combos = sweep_cases({"contact.0.gap": [0.5, 1.0], "analysis.harmonics": [3, 5, 7]})
    assert len(combos) == 6 and combos[0] == {"contact.0.gap": 0.5, "analysis.harmonics": 3}
    assert combos[-1] == {"contact.0.gap": 1.0, "analysis.harmonics": 7}  # first path varies slowest
    assert sweep_cases({"force.0.amplitude": np.array([0.1, 0.2])}) == [{"force.0.amplitude": 0.1},
                                                                          {"force.0.amplitude": 0.2}]
    assert sweep_cases([{"analysis.omega": (0.5, 1.5)}]) == [{"analysis.omega": [0.5, 1.5]}]
    with pytest.raises(TypeError, match="analysis.omega"):
        sweep_cases({"analysis.omega": "0.5"})
    with pytest.raises(ValueError, match="empty"):
        sweep_cases({"contact.0.gap": []})
    with pytest.raises(ValueError, match="at least one"):
        sweep_cases({})


def test_overrides_apply_and_name_bad_paths():
    base = cases.load_case(FRC)
    new = apply_overrides(base.data, {"contact.0.gap": 0.25, "damping.alpha": 0.1, "analysis.harmonics": None})
    assert new["contact"][0]["gap"] == 0.25 and new["damping"] == {"alpha": 0.1} and "harmonics" not in new["analysis"]
    assert base.data["contact"][0]["gap"] == 1.0  # the base case is not modified
    with pytest.raises(ValueError, match=r"'contakt'.*valid tables are .*contact\.<index>.*analysis"):
        apply_overrides(base.data, {"contakt.0.gap": 1.0})
    with pytest.raises(ValueError, match=r"unknown key 'gapp' in path 'contact.0.gapp'; valid keys .* at, gap"):
        apply_overrides(base.data, {"contact.0.gapp": 1.0})
    with pytest.raises(ValueError, match=r"'contact.1.gap' addresses \[\[contact\]\] number 2 but the case has 1"):
        apply_overrides(base.data, {"contact.1.gap": 1.0})
    with pytest.raises(ValueError, match=r"'analysis.0.harmonics' must look like 'analysis.<key>'"):
        apply_overrides(base.data, {"analysis.0.harmonics": 3})
    with pytest.raises(ValueError, match="set by the sweep"):
        apply_overrides(base.data, {"outputs.plot": True})


@pytest.mark.parametrize("path", [FRC, NNM])
def test_toml_writer_round_trip(path):
    data = cases.load_case(path).data
    assert tomllib.loads(to_toml(data)) == data
    odd = {"mesh": {"boundaries": {"a b": 0.0, "tip": 1e-5}, "file": 'x "q"\\ü.msh'},
           "analysis": {"energy": [1e16, -math.inf], "harmonics": 3, "flag": True}}
    assert tomllib.loads(to_toml(odd)) == odd


def test_parse_set():
    assert parse_set("contact.0.gap=0.005,0.01") == ("contact.0.gap", [0.005, 0.01])
    assert parse_set("analysis.omega=[0.5,2.0],[1, 2]") == ("analysis.omega", [[0.5, 2.0], [1, 2]])
    assert parse_set('force.0.at=x,"tip",["tip","w"]') == ("force.0.at", ["x", "tip", ["tip", "w"]])
    for bad in ("contact.0.gap", "=1", "analysis.harmonics=", "analysis.harmonics=1,,2", "analysis.harmonics=1 2"):
        with pytest.raises(ValueError, match="--set"):
            parse_set(bad)


def test_bad_arguments_name_the_argument(tmp_path):
    with pytest.raises(TypeError, match=r"executor must be a concurrent.futures.Executor, a distributed.Client or a "
                                        r"scheduler address like 'tcp://host:8786', got 8786"):
        run_sweep(FRC, _cases(1.0), out=tmp_path, executor=8786)
    with pytest.raises(TypeError, match="executor must be .* got <class .*ThreadPoolExecutor'>"):
        run_sweep(FRC, _cases(1.0), out=tmp_path, executor=cf.ThreadPoolExecutor)  # the class, not an instance
    for bad in ("threads", "", "tcp://", "host 8786", "tcp://host:8786 "):
        with pytest.raises(ValueError, match=re.escape(f"executor={bad!r} is not a Dask scheduler address; an address "
                                                       "looks like 'tcp://host:8786'")):
            run_sweep(FRC, _cases(1.0), out=tmp_path, executor=bad)
    for bad in ("yes", 1, None, [print]):
        with pytest.raises(TypeError, match=r"progress must be True, False or a callable\(record, n_done, n_total\), "
                                            f"got {re.escape(repr(bad))}"):
            with cf.ThreadPoolExecutor(1) as ex:
                run_sweep(FRC, _cases(1.0), out=tmp_path, executor=ex, progress=bad)
    with pytest.raises(TypeError, match="unexpected keyword argument 'scheduler'"):  # merged into executor
        run_sweep(FRC, _cases(1.0), out=tmp_path, scheduler="tcp://127.0.0.1:1")
    with pytest.raises(TypeError, match="unexpected keyword argument 'callback'"):  # merged into progress
        run_sweep(FRC, _cases(1.0), out=tmp_path, callback=print)
    with pytest.raises(ValueError, match="n_workers must be an integer >= 1, got 0"):
        run_sweep(FRC, _cases(1.0), out=tmp_path, n_workers=0)
    with pytest.raises(ValueError, match="study must be a file name"):
        run_sweep(FRC, _cases(1.0), out=tmp_path, study="study.csv")
    with pytest.raises(TypeError, match="case must be a case file path"):
        run_sweep(3, _cases(1.0), out=tmp_path)
    with pytest.raises(ValueError, match="'contact.0.gop'"):
        run_sweep(FRC, {"contact.0.gop": [1.0]}, out=tmp_path)
    assert not (tmp_path / "cases").exists()  # nothing started


# --------------------------------------------------------------------------------- executors
@pytest.fixture(scope="module")
def thread_sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("threads")
    seen = []
    params = _cases(*GAPS, -1.0) + [{"force.0.at": "nope", **SMALL}]
    with cf.ThreadPoolExecutor(2) as ex:
        res = run_sweep(FRC, params, out=out, executor=ex, progress=lambda r, k, n: seen.append((r, k, n)))
    return res, seen


def test_thread_pool_sweep_with_failures(thread_sweep, tmp_path):
    res, seen = thread_sweep
    assert [r.id for r in res] == ["c000", "c001", "c002", "c003", "c004"]
    # progress(record, n_done, n_total) once per finished case, with the records of the result
    assert sorted(k for _, k, _ in seen) == [1, 2, 3, 4, 5] and {n for *_, n in seen} == {5}
    assert sorted(r.id for r, _, _ in seen) == [r.id for r in res] and all(r is res[r.id] for r, _, _ in seen)
    assert seen[0][0].id == "c003" and seen[0][1] == 1  # rejected by the case-file checks: recorded first
    assert [r.status for r in res] == ["ok", "ok", "ok", "failed", "failed"] and not res.success
    assert res["c003"].message == "[contact] gap must be >= 0, got -1.0"  # rejected by the case-file checks
    assert "unknown location 'nope'" in res["c004"].message  # raised inside the task
    assert res["c004"].branch == "" and math.isnan(res["c004"].max_amplitude)
    for r, g in zip(res, GAPS):
        assert r.parameters == {"contact.0.gap": g, **SMALL}
        assert r.n_points == 12 and r.amplitude_dof == "x" and 0 <= r.max_penetration < 0.5  # H = 3: coarse
        assert (res.study.parent / r.branch).is_file() and r.branch == f"cases/{r.id}/branch.npz"
        assert (res.study.parent / "cases" / r.id / "case.toml").is_file()
    # same numbers as running the case directly
    assert res[1].max_amplitude == pytest.approx(_direct_amplitude(_cases(1.0)[0], tmp_path), abs=1e-12)
    br = res.load_branch("c001")
    assert len(br) == 12 and br.amplitude(0).max() == pytest.approx(res[1].max_amplitude, abs=1e-12)
    assert res[1].max_penetration == pytest.approx(br.penetration.max(), abs=1e-12)
    assert "c003" in res.table() and "gap must be >= 0" in res.table()


def _same(a, b):
    assert a.parameters == b.parameters and len(a) == len(b)
    for ra, rb in zip(a, b):
        for f in dataclasses.fields(ra):
            va, vb = getattr(ra, f.name), getattr(rb, f.name)
            assert va == vb or (isinstance(va, float) and math.isnan(va) and math.isnan(vb)), f.name


def test_study_file_round_trip(thread_sweep, tmp_path):
    res, _ = thread_sweep
    back = load_study(res.study)
    _same(back, res)
    assert back.load_branch(0).omega[0] == pytest.approx(0.5)
    with np.load(res.study) as f:  # readable without femodes
        assert list(f["status"]) == ["ok", "ok", "ok", "failed", "failed"]
        assert f["max_amplitude"][1] == res[1].max_amplitude and f["param:contact.0.gap"][3] == "-1.0"
    h5 = save_study(dataclasses.replace(res, study=tmp_path / "study.h5"))
    _same(load_study(h5), res)
    (tmp_path / "junk.npz").write_bytes(b"not a study")
    with pytest.raises(ValueError, match="not a readable femodes study"):
        load_study(tmp_path / "junk.npz")
    assert not list(res.study.parent.glob("*.tmp"))  # atomic write left nothing behind


def test_sweep_reports_stable_points_per_case(tmp_path, thread_sweep):
    """analysis.stability as a sweep parameter: n_stable (stable points of the branch, -1 without
    stability), the methods and the bifurcations by kind, in the records, the study file and the table."""
    assert parse_set("analysis.stability=true,false,hill") == ("analysis.stability", [True, False, "hill"])
    # 16 points: the step control bounds the change of the response's size per step
    # (target_norm_change), so 12 points end before the grazing point
    params = {"contact.0.gap": [1.0], "analysis.stability": [True, False], **{k: [v] for k, v in SMALL.items()},
              "analysis.max_points": [16]}
    with cf.ThreadPoolExecutor(2) as ex:
        res = run_sweep(FRC, params, out=tmp_path, executor=ex)
    assert res.success and [r.parameters["analysis.stability"] for r in res] == [True, False]
    on, off = res
    br = res.load_branch(on.id)
    assert br.stable is not None and on.n_stable == int(br.stable.sum())
    assert 0 < on.n_stable < on.n_points == len(br) == 16  # H = 3: unstable past the grazing point
    # "auto": shooting, with Hill where a shooting fails
    assert on.stability_method == "+".join(sorted(set(br.stability_method)))
    assert on.stability_method in ("shooting", "hill+shooting")
    kinds = [b.kind for b in br.bifurcations]
    assert (on.n_branch_point, on.n_period_doubling, on.n_neimark_sacker, on.n_nonsmooth) == tuple(
        kinds.count(k) for k in ("branch_point", "period_doubling", "neimark_sacker", "nonsmooth"))
    # the multipliers leave the unit circle where contact starts (a jump, or a crossing at -1 at H = 3)
    assert on.n_nonsmooth + on.n_period_doubling >= 1
    assert res.load_branch(off.id).stable is None
    assert (off.n_stable, off.stability_method, off.n_period_doubling, off.n_nonsmooth) == (-1, "", -1, -1)
    assert all(r.n_stable == -1 for r in thread_sweep[0])  # no stability asked: -1
    back = load_study(res.study)
    _same(back, res)
    with np.load(res.study) as f:  # readable without femodes: integer columns, -1 = not computed
        assert f["n_stable"].dtype.kind == "i" and list(f["n_stable"]) == [on.n_stable, -1]
        assert list(f["n_nonsmooth"]) == [on.n_nonsmooth, -1] and list(f["stability_method"]) == [on.stability_method, ""]
        assert json.loads(str(f["header"]))["version"] == 2
    lines = res.table().splitlines()
    assert "stable" in lines[0] and "bifurcations" in lines[0]
    assert f"{on.n_stable}/{on.n_points}" in lines[2]
    for kind, count in (("nonsmooth", on.n_nonsmooth), ("period_doubling", on.n_period_doubling)):
        assert (f"{kind} {count}" in lines[2]) == (count > 0)
    assert " - " in lines[3]
    assert "stable" not in thread_sweep[0].table().splitlines()[0]  # no stability column without stability


def test_study_version_1_is_read(thread_sweep, tmp_path):
    """A study file written before the stability columns (version 1) still reads: no stability (-1)."""
    res, _ = thread_sweep
    with np.load(res.study) as f:
        arrays = {k: f[k] for k in f.files}
    header = json.loads(str(arrays.pop("header")))
    new = ("n_stable", "stability_method", "n_branch_point", "n_period_doubling", "n_neimark_sacker", "n_nonsmooth")
    header["version"] = 1
    header["records"] = [{k: v for k, v in r.items() if k not in new} for r in header["records"]]
    old = tmp_path / "old.npz"
    np.savez_compressed(old, header=np.array(json.dumps(header)), **{k: v for k, v in arrays.items() if k not in new})
    back = load_study(old)
    assert [r.id for r in back] == [r.id for r in res] and all(r.n_stable == -1 for r in back)
    assert back[1].max_amplitude == res[1].max_amplitude
    header["version"] = 99
    np.savez_compressed(old, header=np.array(json.dumps(header)))
    with pytest.raises(ValueError, match="study version 99, this femodes reads versions 1, 2"):
        load_study(old)


class _LostWorkers(cf.Executor):
    """An executor whose tasks die without a result (like a killed worker)."""

    def submit(self, fn, /, *args, **kwargs):
        fut = cf.Future()
        fut.set_exception(RuntimeError("worker lost"))
        return fut


def test_task_that_cannot_run_is_reported(tmp_path):
    res = run_sweep(FRC, _cases(1.0), out=tmp_path, executor=_LostWorkers())
    assert res[0].status == "failed" and res[0].message == "RuntimeError: worker lost"
    assert load_study(res.study)[0].message == "RuntimeError: worker lost"


def test_process_pool_sweep(tmp_path, thread_sweep):
    with cf.ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as ex:
        res = run_sweep(FRC, {"contact.0.gap": GAPS[:2], **{k: [v] for k, v in SMALL.items()}}, out=tmp_path,
                        executor=ex)
    assert res.success and len(res) == 2
    assert len({r.worker for r in res} - {""}) >= 1 and all(r.worker.split(":")[1] != str(os.getpid()) for r in res)
    for r, ref in zip(res, thread_sweep[0]):
        assert r.max_amplitude == pytest.approx(ref.max_amplitude, abs=1e-12) and r.n_points == ref.n_points


def test_dask_cluster_of_two_workers(tmp_path, thread_sweep):
    from distributed import Client

    env = dict(os.environ)
    with local_cluster(2) as cluster, Client(cluster) as client:
        assert os.environ == env  # the nanny's pre-spawn variables do not leak into this process
        worker_env = client.run(lambda: {k: os.environ.get(k) for k in WORKER_ENVIRON})
        assert len(worker_env) == 2
        for e in worker_env.values():
            assert e == WORKER_ENVIRON  # no MALLOC_TRIM_THRESHOLD_, one BLAS thread
        params = _cases(*GAPS, -1.0) + [{"force.0.at": "nope", **SMALL}]
        res = run_sweep(FRC, params, out=tmp_path / "client", executor=client)
        res2 = run_sweep(FRC, _cases(GAPS[1]), out=tmp_path / "address", executor=cluster.scheduler_address)
    ref = thread_sweep[0]
    assert [r.status for r in res] == [r.status for r in ref]
    assert res["c004"].message == ref["c004"].message
    for r, rr in zip(res, ref):
        assert r.n_points == rr.n_points and (r.max_amplitude == pytest.approx(rr.max_amplitude, abs=1e-12)
                                                or not r.ok)
    workers = {r.worker for r in res if r.worker}
    assert workers and all(w.split(":")[1] != str(os.getpid()) for w in workers)  # ran in the worker processes
    assert res2.success and res2[0].max_amplitude == pytest.approx(ref[1].max_amplitude, abs=1e-12)


# --------------------------------------------------------------------------------- command line
def test_cli_sweep_on_embedded_cluster(tmp_path, capsys, thread_sweep):
    rc = main(["sweep", str(FRC), "--set", "contact.0.gap=0.5,1.0,-1", "--set", "analysis.harmonics=3",
               "--set", "analysis.max_points=12", "--workers", "2", "--out", str(tmp_path), "--progress"])
    cap = capsys.readouterr()
    assert rc == 1  # one case failed, the others completed
    assert "2 of 3 cases ok" in cap.out and "gap must be >= 0, got -1" in cap.out
    assert "[3/3]" in cap.err and "Traceback" not in cap.err
    study = load_study(tmp_path / "study.npz")
    assert [r.status for r in study] == ["ok", "ok", "failed"]
    assert study[1].max_amplitude == pytest.approx(thread_sweep[0][1].max_amplitude, abs=1e-12)


@pytest.mark.parametrize("args, message", [
    (["--set", "contact.0.gap"], "expected PATH=VALUE"),
    (["--set", "contact.0.gap=1,,2"], "empty value"),
    (["--set", "contact.0.gapp=1"], "unknown key 'gapp'"),
    (["--set", "contact.0.gap=1", "--set", "contact.0.gap=2"], "given twice"),
    ([], "at least one --set"),
    (["--set", "contact.0.gap=1", "--workers", "0"], "n_workers must be an integer >= 1"),
    (["--set", "contact.0.gap=1", "--scheduler", "nowhere"], "executor='nowhere' is not a Dask scheduler address"),
])
def test_cli_bad_set_exits_2(tmp_path, capsys, args, message):
    assert main(["sweep", str(FRC), "--out", str(tmp_path), *args]) == 2
    err = capsys.readouterr().err
    assert err.startswith("femodes sweep: ") and message in err and "Traceback" not in err
    assert not (tmp_path / "study.npz").exists()


def test_progress_true_logs_one_line_per_case(tmp_path, caplog):
    with caplog.at_level("INFO", logger="femodes.app.sweep.run"), cf.ThreadPoolExecutor(1) as ex:
        res = run_sweep(FRC, _cases(1.0, -1.0), out=tmp_path, executor=ex, progress=True)
    lines = [m for r in caplog.records
             if r.name == "femodes.app.sweep.run" and (m := r.getMessage()).startswith("case ")]
    assert res[0].ok and len(lines) == 2
    assert any(line.startswith("case c000 (") and " ok in " in line for line in lines)
    assert any(line.startswith("case c001 (1/2) failed") and "gap must be >= 0" in line for line in lines)


def test_interrupted_sweep_keeps_a_study_file(tmp_path):
    """The study file follows every finished case: Ctrl-C after the first case loses nothing."""

    def stop(rec, k, n):
        if k == 1 and rec.status == "ok":
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        with cf.ThreadPoolExecutor(1) as ex:
            run_sweep(FRC, _cases(*GAPS), out=tmp_path, executor=ex, progress=stop)
    st = load_study(tmp_path / "study.npz")
    statuses = [r.status for r in st]
    assert statuses.count("ok") == 1 and statuses.count("pending") == 2
    done = next(r for r in st if r.status == "ok")
    assert st.load_branch(done.id).omega.size == done.n_points > 0
