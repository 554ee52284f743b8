"""`femodes scaling` and femodes.app.scaling.scaling_study: a small study on a bar with a stop."""

import csv
import json
import math

import numpy as np
import pytest

from femodes.app.cases import load_case, parse_case
from femodes.app.cli import main
from femodes.app.scaling import study as sc  # scaling_study, the names it uses, its _run_child

BAR = """
[mesh]
length = 1.0
n_elements = 20
boundaries = {{ clamp = 0.0, tip = 1.0 }}

[model]
kind = "bar"
E = 1.0
rho = 1.0
area = 1.0
clamped = "clamp"

[damping]
alpha = 0.05

[[contact]]
at = "tip"
gap = 0.01

[[force]]
at = "tip"
amplitude = 0.002
harmonic = {harmonic}

[analysis]
type = "frequency_response"
omega = [1.3, 1.9]     # first resonance pi/2: the linear tip amplitude there exceeds the gap
harmonics = 3
"""

DISCRETE = """
[model]
kind = "discrete"
M = [[1.0]]
K = [[1.0]]
C = [[0.1]]

[[contact]]
at = 0
gap = 1.0

[[force]]
at = 0
amplitude = 0.2

[analysis]
type = "frequency_response"
omega = [0.5, 2.0]
harmonics = 5
"""


@pytest.fixture
def bar_case(tmp_path):
    p = tmp_path / "bar.toml"
    p.write_text(BAR.format(harmonic=1))
    return p


def test_study_on_a_bar_writes_table_csv_json_png(bar_case, tmp_path):
    out = tmp_path / "study"
    res = sc.scaling_study(bar_case, elements=[80, 20, 40], harmonics=[5, 3], repeat=2, points=3, out=out)
    assert res.success and not res.interrupted
    assert [(r.n_elements, r.H) for r in res.records] == [(20, 3), (20, 5), (40, 3), (40, 5), (80, 3), (80, 5)]
    for r in res.records:
        assert r.ok, r.error
        assert r.N == r.n_elements and r.n_reduced is None  # P1 bar clamped at one end: one DOF per element
        assert r.unknowns >= (2 * r.H + 1) * r.N and r.nnz_J > r.unknowns
        assert 0 < r.iteration_min_s <= r.iteration_median_s
        assert r.residual_median_s > 0 and r.solve_median_s > 0
        assert r.points == 3 and r.point_s > 0
        assert r.peak_mib >= r.baseline_mib > 0  # small cases: the imports set the peak
        assert r.contact_active  # linear guess near resonance + one Newton step: the stop is active
    # files
    assert {p.name for p in res.files} == {"scaling.csv", "scaling.json", "scaling.png"}
    rows = list(csv.DictReader(open(out / "scaling.csv")))
    assert len(rows) == 6 and float(rows[0]["iteration_median_s"]) > 0 and rows[0]["error"] == ""
    doc = json.loads((out / "scaling.json").read_text())
    assert len(doc["records"]) == 6 and doc["settings"]["harmonics"] == [3, 5]
    assert (out / "scaling.png").stat().st_size > 10_000
    # exponents: against N at H = 3 and 5, against H at the three N, for iteration/point/memory
    fits = {(f.quantity, f.against, f.fixed_value): f for f in res.fits}
    for H in (3, 5):
        f = fits[("iteration", "N", H)]
        assert f.sizes == (20, 40, 80)
        # the exponent is the least-squares log-log slope of the measured medians (timings vary;
        # the fit of what was measured must not)
        rec = {r.N: r.iteration_median_s for r in res.records if r.H == H}
        slope = np.polyfit(np.log([20, 40, 80]), np.log([rec[20], rec[40], rec[80]]), 1)[0]
        assert f.exponent == pytest.approx(slope, rel=1e-12, abs=1e-12)
    f = fits[("point", "H", 40)]
    rec = {r.H: r.point_s for r in res.records if r.N == 40}
    assert f.exponent == pytest.approx(np.polyfit(np.log([3, 5]), np.log([rec[3], rec[5]]), 1)[0], rel=1e-12, abs=1e-12)
    assert len(doc["exponents"]) == len(res.fits)
    # markdown table: header, rule, one row per case
    lines = res.table().splitlines()
    assert len(lines) == 8 and lines[0].startswith("| N |") and lines[2].startswith("| 20 | - | 3 |")


def test_fit_exponents_recovers_a_power_law():
    recs = [sc.ScalingRecord(n_elements=n, H=H, N=n, iteration_median_s=1e-6 * n**1.5 * H**2,
                             iteration_min_s=1e-6, point_s=1e-5 * n * H, peak_mib=100 + n * H * 1e-3,
                             baseline_mib=100)
            for n in (100, 1000, 10000) for H in (5, 10)]
    fits = {(f.quantity, f.against, f.fixed_value): f.exponent for f in sc.fit_exponents(recs)}
    assert fits[("iteration", "N", 5)] == pytest.approx(1.5)
    assert fits[("iteration", "H", 1000)] == pytest.approx(2.0)
    assert fits[("point", "N", 10)] == pytest.approx(1.0)
    assert fits[("memory", "H", 100)] == pytest.approx(1.0)
    lines = sc.ScalingResult(case="c", records=tuple(recs), fits=tuple(sc.fit_exponents(recs)), files=()).fit_lines()
    assert lines[0] == "time per Newton iteration ~ N^a: a = 1.50 (H=5), a = 1.50 (H=10)"
    assert len(lines) == 6
    # failed cases are left out of the fits
    bad = sc.ScalingRecord(n_elements=10, H=5, N=10, error="MemoryError: ")
    assert {f.sizes for f in sc.fit_exponents(recs + [bad]) if f.against == "N"} == {(100, 1000, 10000)}


def test_positive_int_list():
    assert sc.positive_int_list("100, 1e3,10000") == [100, 1000, 10000]
    import argparse

    for bad in ("0", "abc", "1.5", "10,,20", "-3", "inf"):
        with pytest.raises(argparse.ArgumentTypeError):
            sc.positive_int_list(bad)


def test_elements_for_a_discrete_case_is_a_clear_error(tmp_path):
    p = tmp_path / "osc.toml"
    p.write_text(DISCRETE)
    with pytest.raises(ValueError, match=r"elements: .*discrete model.*fixed"):
        sc.scaling_study(p, elements=[10, 20], out=tmp_path / "o")
    assert not (tmp_path / "o").exists()


def test_elements_for_a_mesh_file_is_a_clear_error(tmp_path):
    p = tmp_path / "file.toml"
    p.write_text(BAR.format(harmonic=1).replace("length = 1.0\nn_elements = 20\nboundaries = { clamp = 0.0, tip = 1.0 }",
                                                'file = "beam.msh"'))
    with pytest.raises(ValueError, match=r"elements: .*read from a file.*beam\.msh"):
        sc.scaling_study(p, elements=[10], out=tmp_path / "o")


@pytest.mark.parametrize("kw, match", [
    ({"harmonics": [0, 3]}, "harmonics must be positive"),
    ({"harmonics": []}, "harmonics must not be empty"),
    ({"elements": [10.5]}, "elements must be positive integers"),
    ({"repeat": 0}, "repeat must be an integer >= 1"),
    ({"points": 1}, "points must be 0"),
    ({"timeout": -1}, "timeout must be a positive"),
])
def test_bad_arguments_name_the_argument(bar_case, tmp_path, kw, match):
    with pytest.raises((ValueError, TypeError), match=match):
        sc.scaling_study(bar_case, out=tmp_path / "o", **kw)


def test_failed_case_is_recorded_and_the_study_goes_on(tmp_path):
    p = tmp_path / "bar3.toml"
    p.write_text(BAR.format(harmonic=3))  # a third-harmonic force needs H >= 3
    res = sc.scaling_study(p, harmonics=[2, 3], repeat=1, points=0, out=tmp_path / "o")
    bad, good = res.records
    assert not bad.ok and "harmonic" in bad.error and good.ok and good.points == 0
    assert not res.success and "harmonic" in res.table().splitlines()[2]
    rows = list(csv.DictReader(open(tmp_path / "o" / "scaling.csv")))
    assert rows[0]["error"] and rows[1]["error"] == "" and rows[1]["point_s"] == ""


def test_timeout_is_recorded(bar_case, tmp_path):
    res = sc.scaling_study(bar_case, repeat=1, points=0, timeout=0.01, out=tmp_path / "o")
    assert "timed out" in res.records[0].error


def test_ctrl_c_keeps_what_was_measured(bar_case, tmp_path, monkeypatch, capsys):
    calls = []

    def fake_child(spec, timeout):
        calls.append(spec["data"]["analysis"]["harmonics"])
        if len(calls) == 2:
            raise KeyboardInterrupt
        return {"N": 20, "unknowns": 147, "iteration_median_s": 1e-3, "iteration_min_s": 1e-3, "peak_mib": 80.0}

    monkeypatch.setattr(sc, "_run_child", fake_child)
    res = sc.scaling_study(bar_case, harmonics=[3, 5, 7], out=tmp_path / "o", progress=True)
    assert res.interrupted and not res.success and calls == [3, 5]
    assert [r.H for r in res.records] == [3]
    assert len(list(csv.DictReader(open(tmp_path / "o" / "scaling.csv")))) == 1
    assert json.loads((tmp_path / "o" / "scaling.json").read_text())["interrupted"] is True
    assert "1/3 cases" in capsys.readouterr().err  # the progress bar


def test_cli_scaling_returns_0_and_prints_the_table(bar_case, tmp_path, capsys):
    out = tmp_path / "cli"
    rc = main(["scaling", str(bar_case), "--elements", "10,20", "--harmonics", "3", "--repeat", "1", "--points", "0",
               "--out", str(out), "--no-progress"])
    text = capsys.readouterr().out
    assert rc == 0
    assert "| 10 | - | 3 |" in text and "| 20 | - | 3 |" in text
    assert "time per Newton iteration ~ N^" in text
    assert (out / "scaling.csv").exists() and (out / "scaling.png").exists()


@pytest.mark.parametrize("args, message", [
    (["--elements", "0"], "argument --elements: values must be positive integers"),
    (["--harmonics", "abc"], "argument --harmonics: expected positive integers"),
    (["--points", "1"], "argument --points"),
])
def test_cli_bad_values_exit_2_without_traceback(bar_case, capsys, args, message):
    with pytest.raises(SystemExit) as exc:
        main(["scaling", str(bar_case), *args])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_cli_elements_for_a_discrete_case_exit_2(tmp_path, capsys):
    p = tmp_path / "osc.toml"
    p.write_text(DISCRETE)
    assert main(["scaling", str(p), "--elements", "10,20", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "femodes scaling: elements: cannot vary the number of elements: the case is a discrete model" in err
    assert main(["scaling", str(tmp_path / "missing.toml")]) == 2
    assert "case file not found" in capsys.readouterr().err


def test_stability_of_a_case_is_timed_apart(tmp_path):
    """A case with ``stability`` gets its branch's stability timed per point, with the methods
    used; a case without it reports none (``-``)."""
    p = tmp_path / "stab.toml"
    p.write_text(BAR.format(harmonic=1).replace("harmonics = 3", 'harmonics = 3\nstability = "hill"'))
    res = sc.scaling_study(p, elements=[20], harmonics=[3], repeat=1, points=4, out=tmp_path / "s")
    (r,) = res.records
    assert r.ok, r.error
    assert r.stability_s > 0 and r.stability_method == "hill"
    assert f"({r.stability_method})" in res.table().splitlines()[2]
    doc = json.loads((tmp_path / "s" / "scaling.json").read_text())
    assert doc["records"][0]["stability_method"] == "hill"
    plain = sc.scaling_study(_plain(tmp_path), elements=[20], harmonics=[3],
                             repeat=1, points=2, out=tmp_path / "p")
    assert math.isnan(plain.records[0].stability_s) and plain.records[0].stability_method == ""
    assert "| 2 | - |" in plain.table().splitlines()[2]


def _plain(tmp_path):
    q = tmp_path / "plain.toml"
    q.write_text(BAR.format(harmonic=1))
    return q


# --------------------------------------------------------------------------------- meshed solids
STRIP = """
[mesh]
length = 1.0
height = 0.1
nx = 4
ny = 1
quad = true

[model]
kind = "solid"
E = 1.0
rho = 1.0
clamped = "left"

[damping]
beta = 0.02

[[contact]]
at = "right"
direction = [1.0, 0.0]
gap = 0.01

[[force]]
at = ["right", "u_x"]
amplitude = 0.0004

[analysis]
type = "frequency_response"
omega = [1.3, 1.9]
harmonics = 2
"""


@pytest.fixture
def strip_case(tmp_path):
    p = tmp_path / "strip.toml"
    p.write_text(STRIP)
    return p


def test_refine_a_solid_keeps_the_aspect_and_fits_against_N(strip_case, tmp_path):
    """--refine 3,1 on a 4 x 1 Q1 strip: nx, ny scaled together, N = 2 nx (ny + 1) (left edge
    clamped), one contact per node of the tip edge; exponents fitted against N."""
    out = tmp_path / "s"
    res = sc.scaling_study(strip_case, refine=[3, 1], harmonics=[2], repeat=1, points=0, out=out)
    assert res.success, [r.error for r in res.records]
    assert [(r.refine, r.mesh) for r in res.records] == [(1.0, "nx=4 ny=1"), (3.0, "nx=12 ny=3")]
    assert [r.N for r in res.records] == [2 * 4 * 2, 2 * 12 * 4]
    for r in res.records:
        assert r.n_elements is None and r.ok and r.points == 0
        ny = int(r.mesh.split("ny=")[1])
        # unknowns: (2H+1) coefficients of every DOF and of every contact force (ny + 1 contacts)
        assert r.unknowns == 5 * (r.N + ny + 1)
    f = next(f for f in res.fits if f.quantity == "iteration" and f.against == "N")
    assert f.sizes == (16, 96) and f.fixed_value == 2
    rows = list(csv.DictReader(open(out / "scaling.csv")))
    assert [row["mesh"] for row in rows] == ["nx=4 ny=1", "nx=12 ny=3"] and rows[0]["refine"] == "1.0"
    doc = json.loads((out / "scaling.json").read_text())
    assert doc["settings"]["refine"] == [1.0, 3.0] and doc["settings"]["elements"] is None
    assert doc["settings"]["meshes"] == [{"nx": 4, "ny": 1}, {"nx": 12, "ny": 3}]
    assert res.table().splitlines()[2].endswith("| nx=4 ny=1 |")


def test_refined_divisions_round_and_stay_positive(strip_case, bar_case):
    case = load_case(strip_case)
    assert sc.refined_divisions(case, 1.5) == {"nx": 6, "ny": 2}  # 1.5 rounds to 2 (half to even)
    assert sc.refined_divisions(case, 0.1) == {"nx": 1, "ny": 1}
    box = parse_case(STRIP.replace("quad = true", "nz = 2\nhexahedra = true"), "box.toml")
    assert sc.refined_divisions(box, 2.5) == {"nx": 10, "ny": 2, "nz": 5}
    assert sc.refined_divisions(load_case(bar_case), 2.5) == {"n_elements": 50}


def test_refine_of_a_line_mesh_scales_n_elements(bar_case, tmp_path):
    res = sc.scaling_study(bar_case, refine=[0.5], harmonics=[3], repeat=1, points=0, out=tmp_path / "o")
    assert [(r.n_elements, r.refine, r.N, r.mesh) for r in res.records] == [(10, 0.5, 10, "")]


@pytest.mark.parametrize("text, kw, match", [
    (STRIP, {"elements": [10, 20]}, r"elements: a solid's mesh is refined with refine"),
    (STRIP, {"elements": [10], "refine": [2]}, r"give either elements .* or refine .*, not both"),
    (STRIP, {"refine": [0.0, 1.0]}, r"refine must be positive numbers, got 0\.0"),
    (STRIP, {"refine": []}, r"refine must not be empty"),
    (STRIP, {"refine": ["2"]}, r"refine must be positive numbers, got '2'"),
    (STRIP.replace("length = 1.0\nheight = 0.1\nnx = 4\nny = 1\nquad = true", 'file = "blade.msh"'), {"refine": [2]},
     r"refine: cannot refine the mesh: the mesh is read from a file .*blade\.msh"),
    (DISCRETE, {"refine": [2]}, r"refine: cannot refine the mesh: the case is a discrete model"),
])
def test_bad_refine_is_a_clear_error(tmp_path, text, kw, match):
    p = tmp_path / "c.toml"
    p.write_text(text)
    with pytest.raises((ValueError, TypeError), match=match):
        sc.scaling_study(p, out=tmp_path / "o", **kw)
    assert not (tmp_path / "o").exists()


def test_cli_refine(strip_case, tmp_path, capsys):
    rc = main(["scaling", str(strip_case), "--refine", "2", "--harmonics", "2", "--repeat", "1", "--points", "0",
               "--out", str(tmp_path / "cli"), "--no-progress"])
    text = capsys.readouterr().out
    assert rc == 0 and "| 48 | - | 2 |" in text and "| nx=8 ny=2 |" in text
    for args, message in ((["--refine", "0"], "argument --refine: values must be positive numbers"),
                          (["--refine", "2", "--elements", "10"], "not allowed with argument")):
        with pytest.raises(SystemExit) as exc:
            main(["scaling", str(strip_case), *args])
        assert exc.value.code == 2 and message in capsys.readouterr().err
    assert main(["scaling", str(strip_case), "--elements", "10", "--out", str(tmp_path / "o")]) == 2
    assert "femodes scaling: elements: a solid's mesh is refined with refine" in capsys.readouterr().err
