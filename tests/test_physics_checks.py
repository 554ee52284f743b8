"""Physics mistakes that used to pass silently get a warning that names the fix (issue 36, item 4)."""

import warnings

import pytest

import femodes as fm


def test_contact_on_a_solid_boundary_without_direction_warns():
    """A boundary of a 3-D solid without direction= acts along +x: said, with the fix."""
    model = fm.solid(fm.box_mesh(1.0, 0.2, 0.1, 4, 1, 1), fm.Material(E=1.0, rho=1.0, nu=0.3), clamped="left")
    with pytest.warns(UserWarning, match=r"no direction= for boundary 'top' of a 3-D solid.*direction=\(0.0, 0.0, 1.0\)"):
        model.with_contact(fm.UnilateralContact(at="top", gap=0.01))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model.with_contact(fm.UnilateralContact(at="top", gap=0.01, direction=(0.0, 0.0, 1.0)))
        model.with_contact(fm.UnilateralContact(at=("top", "u_x"), gap=0.01))


def test_undamped_forced_response_warns():
    model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]])
             .with_forcing(fm.HarmonicForce(at=0, amplitude=0.1)))
    with pytest.warns(UserWarning, match="no damping.*with_damping"):
        fm.frequency_response(model, omega=(0.5, 0.8), harmonics=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fm.frequency_response(model.with_damping(alpha=0.1), omega=(0.5, 0.8), harmonics=1)


def test_unmerged_mesh_warns(tmp_path):
    """Two tetrahedra meeting on a face whose three nodes are duplicated (an unmerged gmsh mesh):
    half the mesh floats free; load_mesh says so and how to merge. The shipped meshes do not warn."""
    import numpy as np
    import meshio

    a = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    b = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], float)  # the face again, not shared
    meshio.write(tmp_path / "two.vtu", meshio.Mesh(np.vstack([a, b]), [("tetra", np.array([[0, 1, 2, 3], [4, 5, 6, 7]]))]))
    with pytest.warns(UserWarning, match=r"3 node\(s\) at the position of another node.*not merged.*RemoveDuplicateNodes"):
        fm.load_mesh(tmp_path / "two.vtu")
    from pathlib import Path

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for name in ("blade2d.msh", "blade3d.msh"):
            fm.load_mesh(Path(__file__).resolve().parents[1] / "meshes" / name)


def test_contact_direction_into_the_body_warns():
    """A stop above the top face is along +z; -z puts it inside the plate: said, with the fix.
    Negative normals on faces that face that way (left face, -x) are not warned of."""
    model = fm.solid(fm.box_mesh(1.0, 0.2, 0.1, 4, 1, 1), fm.Material(E=1.0, rho=1.0, nu=0.3), clamped="left")
    with pytest.warns(UserWarning, match=r"points into the body at boundary 'top' \(its outward normal is \(0, 0, 1\)\).*"
                                         r"direction=\(0, 0, 1\)"):
        model.with_contact(fm.UnilateralContact(at="top", gap=0.01, direction=(0.0, 0.0, -1.0)))
    strip = fm.solid(fm.rectangle_mesh(1.0, 0.1, 8, 2), fm.Material(E=1.0, rho=1.0, nu=0.3), clamped="right")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        strip.with_contact(fm.UnilateralContact(at="left", gap=0.01, direction=(-1.0, 0.0)))


def _free_bar(clamped=None):
    mesh = fm.line_mesh(1.0, 20, boundaries={"a": 0.0, "tip": 1.0})
    return (fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped=clamped)
            .with_contact(fm.UnilateralContact(at="tip", gap=0.01))
            .with_forcing(fm.HarmonicForce(at="tip", amplitude=0.01)).with_damping(beta=0.01))


def test_rigid_body_modes_are_caught_before_an_analysis_that_needs_supports():
    """A bar without supports: its first mode is rigid (w^2 at the round-off floor of K, here
    w = 3e-7 against w2 = 3.14): nonlinear_mode of it is refused, naming the fix; a forced response
    warns (the mean position is then not the structure's); a supported bar is silent."""
    free = _free_bar()
    assert fm.linear.rigid_body_modes(free, fm.linear_modes(free, 2).omega).tolist() == [True, False]
    with pytest.raises(ValueError, match="rigid-body mode.*clamped="):
        fm.nonlinear_mode(free, 1, energy=(1e-5, 1e-3), harmonics=3)
    with pytest.warns(UserWarning, match="rigid-body mode.*clamped="):
        fm.frequency_response(free, (1.0, 1.2), 3, options=fm.ContinuationOptions(max_points=5))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fm.frequency_response(_free_bar("a"), (1.0, 1.2), 3, options=fm.ContinuationOptions(max_points=5))
