"""Who names an error (femodes.solvers.checks, "Who names an error"): helpers and validators raise
InputValueError / InputTypeError without a name, the public function the user called puts its
name in front, once; the innermost public function names what its nested calls raise; the
errors stay ValueError / TypeError for user code that catches those.
"""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest

import femodes as fm
from femodes.io import mesh_fields, write_linear_mode
from femodes.solvers.checks import (InputError, InputTypeError, InputValueError, check_positive, entry_name,
                                    entry_point, named_by)


def _oscillator():
    return fm.StructuralModel(M=[[1.0]], K=[[1.0]])


def _bar():
    mesh = fm.line_mesh(1.0, 4, boundaries={"clamp": 0.0, "tip": 1.0})
    return fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")


def _exactly(message: str) -> str:
    return "^" + re.escape(message) + "$"


def test_a_validator_deep_inside_simulate_is_named_simulate():
    with pytest.raises(ValueError, match=_exactly("simulate: dt must be a positive finite number, got -1.0")) as info:
        fm.simulate(_oscillator(), 1.0, -1.0)
    assert isinstance(info.value, InputValueError) and info.value.entry_point == "simulate"
    with pytest.raises(TypeError, match=_exactly("simulate: dt must be a real number, got 'x'")):
        fm.simulate(_oscillator(), 1.0, "x")


def test_options_dataclass_is_named_by_its_class():
    with pytest.raises(ValueError, match=_exactly("TimeSteppingOptions: theta must be in [0.5, 1], got 0.2")):
        fm.TimeSteppingOptions(theta=0.2)
    with pytest.raises(TypeError, match=_exactly("Material: E must be a positive real number, got 'steel'")):
        fm.Material(E="steel", rho=1.0)


def test_vtk_writer_names_itself_not_the_shared_sampler(tmp_path):
    bar = _bar()
    modes = fm.linear_modes(bar, n=2)
    with pytest.raises(ValueError, match=_exactly("write_linear_mode: mode=5 is out of range; the modes hold 2 shapes "
                                                  "(mode=1 .. 2)")):
        write_linear_mode(modes, bar, tmp_path / "m", mode=5)
    with pytest.raises(ValueError, match=_exactly("write_linear_mode: n_frames must be an integer >= 2, got 1")):
        write_linear_mode(modes, bar, tmp_path / "m", n_frames=1)
    # the sampler itself, called directly, names itself
    with pytest.raises(ValueError, match=r"^mesh_fields: mode=5 is out of range"):
        mesh_fields(modes, bar, mode=5)


def test_mesh_fields_owner_is_deprecated_and_ignored():
    bar = _bar()
    modes = fm.linear_modes(bar, n=2)
    with pytest.warns(DeprecationWarning, match="owner=.* is deprecated"):
        with pytest.raises(ValueError, match=r"^mesh_fields: mode=5 is out of range"):
            mesh_fields(modes, bar, mode=5, owner="mine")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert mesh_fields(modes, bar, mode=1, n_frames=2).displacement.shape[0] == 2


def test_plot_names_itself():
    pytest.importorskip("matplotlib")
    from femodes import plot

    bar = _bar()
    modes = fm.linear_modes(bar, n=1)
    with pytest.raises(ValueError, match=_exactly("mode_shape: n_snapshots must be an integer >= 1, got 0")):
        plot.mode_shape(modes, bar, n_snapshots=0)
    with pytest.raises(TypeError, match=r"^mode_shape: ax must be a matplotlib Axes or None, got int$"):
        plot.mode_shape(modes, bar, ax=3)


def test_contact_definitions_are_named():
    with pytest.raises(ValueError, match=_exactly("UnilateralContact: gap must be a finite non-negative number, "
                                                  "got -1.0")):
        fm.UnilateralContact(at="tip", gap=-1.0)
    with pytest.raises(TypeError, match=r"^PenaltyContact: at must be a location name like 'tip'"):
        fm.PenaltyContact(at=1.5, gap=0.0, stiffness=1.0)
    with pytest.raises(ValueError, match=r"^with_contact: UnilateralContact: at='nowhere': unknown location 'nowhere'"):
        _bar().with_contact(fm.UnilateralContact(at="nowhere", gap=0.1))
    with pytest.raises(ValueError, match=r"^with_contact: UnilateralContact\(at='tip'\): direction= needs a meshed "
                                         r"solid"):
        _bar().with_contact(fm.UnilateralContact(at="tip", gap=0.1, direction=(1.0,)))


def test_fe_constructor_names_itself_through_its_helpers():
    mesh = fm.line_mesh(1.0, 4, boundaries={"clamp": 0.0, "tip": 1.0})
    with pytest.raises(ValueError, match=r"^bar: clamped names location 'nowhere', but the mesh has the named "
                                         r"locations \['clamp'"):
        fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="nowhere")
    with pytest.raises(TypeError, match=r"^beam: mesh must be a skfem.MeshLine"):
        fm.beam(object(), fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0))


def test_the_innermost_entry_point_names_a_nested_call():
    inner = entry_point("inner")(lambda: check_positive("x", -1))

    @entry_point("outer")
    def outer():
        check_positive("y", 1.0)
        return inner()

    with pytest.raises(ValueError, match=_exactly("inner: x must be a positive finite number, got -1")) as info:
        outer()
    assert info.value.entry_point == "inner"
    # a real one: grazing_energy computes the linear modes with linear_modes, as before
    model = _bar().with_contact(fm.UnilateralContact(at="tip", gap=0.1))
    with pytest.raises(ValueError, match=_exactly("grazing_energy: mode must be an integer >= 1, got 0")):
        fm.grazing_energy(model, mode=0)


def test_same_exception_object_and_traceback_kept():
    def deep():
        raise InputTypeError("thing must be a str, got 1")

    @entry_point("api")
    def api():
        deep()

    with pytest.raises(TypeError) as info:
        api()
    assert str(info.value) == "api: thing must be a str, got 1"
    assert info.value.args == ("api: thing must be a str, got 1",)
    assert info.traceback[-1].name == "deep"  # raised where it happened, not re-created by the wrapper


def test_errors_stay_value_and_type_errors_and_others_pass_through():
    assert issubclass(InputValueError, ValueError) and issubclass(InputValueError, InputError)
    assert issubclass(InputTypeError, TypeError) and issubclass(InputTypeError, InputError)

    @entry_point("api")
    def api(callback):
        return callback()

    def user_callback():
        raise ValueError("the user's own message")

    with pytest.raises(ValueError, match=_exactly("the user's own message")):
        api(user_callback)
    with pytest.raises(ValueError, match=_exactly("plain: not named")):
        api(lambda: (_ for _ in ()).throw(ValueError("plain: not named")))


def test_named_by_and_entry_name():
    assert entry_name() is None

    @entry_point("api")
    def api():
        assert entry_name() == "api"
        with named_by("block"):
            assert entry_name() == "block"
            check_positive("z", np.float64(-2.0))

    with pytest.raises(ValueError, match=_exactly("block: z must be a positive finite number, got -2.0")):
        api()
    assert entry_name() is None
    with named_by(None), pytest.raises(ValueError, match=_exactly("z must be a positive finite number, got 0")):
        check_positive("z", 0)


def test_the_owner_arguments_left_are_deprecated_and_still_name_the_error():
    """``StructuralModel.dof``/``probe`` and ``DofMap.index``/``node_dofs`` took an ``owner`` that
    named their errors: still honoured for a release, with a DeprecationWarning that points at the
    caller's line; without it the methods name themselves as before."""
    mesh = fm.line_mesh(length=1.0, n_elements=4, boundaries={"clamp": 0.0, "tip": 1.0})
    model = fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
    with pytest.raises(ValueError, match=r"^dof: "):
        model.dof("nowhere")
    with pytest.raises(ValueError, match=r"^DofMap: "):
        model.dofmap.index("nowhere")
    with pytest.warns(DeprecationWarning, match="StructuralModel.dof: owner= is deprecated") as rec:
        with pytest.raises(ValueError, match=r"^mine: "):
            model.dof("nowhere", "mine")
    assert rec[0].filename == __file__
    with pytest.warns(DeprecationWarning, match="DofMap.node_dofs: owner= is deprecated"):
        assert model.dofmap.node_dofs("tip", "mine") == [model.dof("tip")]
