"""examples/user_blade_3d.py, the small version: a user's 3-D structure from a gmsh mesh through
Craig-Bampton, a backbone with stability, a forced response with rtol and a ParaView series."""

import sys
from pathlib import Path

import meshio
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
import user_blade_3d as ex  # noqa: E402


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    return ex.run(tmp_path_factory.mktemp("user_blade"), quick=True, echo=False)


def test_every_stage_returns_with_its_answer(study):
    r = study
    # 6 x 2 x 1 Q2 hexahedra: 13 x 5 x 3 nodes, the root's 15 clamped: 180 nodes, 540 DOFs; the pad
    # (last element of 6, top face) has 3 x 5 nodes
    assert r["model"].n_dofs == 540 and len(r["model"].contacts) == 15
    assert r["rom"].n_dofs == 15 + 10
    # first flap bending of the tapered plate: between the Euler-Bernoulli values of the root's
    # and the tip's sections (1.875^2 sqrt(E t^2 / 12 rho) / L^2 does not depend on the chord),
    # within the coarse mesh's stiffening (measured 1110 rad/s on 15 x 4, 1.6 % higher here)
    w_beam = 1.8751040687 ** 2 * np.sqrt(ex.STEEL.E * ex.THICK ** 2 / 12 / ex.STEEL.rho) / ex.LENGTH ** 2
    assert 0.9 * w_beam < r["w1"] < 1.25 * w_beam
    bb = r["backbone"]
    assert bb.stable is not None and len(bb.stable) == len(bb)
    assert bb.omega.max() > 1.05 * r["w1"]          # the stop stiffens the mode
    fr = r["forced"]
    assert fr.accuracy is not None                   # rtol returned (met or said why)
    assert all(t >= 0 for t in r["times"].values())
    assert Path(r["series"]).exists()


def test_forced_peak_lies_on_the_backbone(study):
    """The peak of the 1 %-damped forced response within 3 % of the backbone at its energy."""
    (peak,) = study["compare"]
    assert abs(peak.distance) < 0.03


def test_committed_meshes_are_what_the_gmsh_script_writes(tmp_path):
    pytest.importorskip("gmsh", reason="gmsh (the meshes extra) regenerates the committed meshes")
    for quick, path in ex.MESHES.items():
        new = meshio.read(ex.write_mesh(tmp_path / path.name, *ex.SIZES[quick]))
        old = meshio.read(path)
        assert np.allclose(new.points, old.points, atol=1e-12)
        assert set(new.field_data) == set(old.field_data) >= {"root", "tip", "pad", "blade"}


def test_help_explains_the_command_line_and_writes_nothing(tmp_path, monkeypatch, capsys):
    # '--help' was taken for the output folder: the script ran the whole study into './--help'
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as stop:
        ex.main(["--help"])
    assert stop.value.code == 0
    assert "out_dir" in capsys.readouterr().out and not any(tmp_path.iterdir())
