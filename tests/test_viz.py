"""Outputs layer: off-screen rendering (femodes.viz).

Skipped only when pyvista is not installed (CI installs ``femodes[render]`` and the EGL/Mesa
system libraries, so these tests run there); a missing OpenGL stack is an error, not a skip.
"""

import importlib.util

import numpy as np
import pytest

import femodes as fm

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("pyvista") is None or importlib.util.find_spec("imageio") is None,
    reason="pyvista/imageio not installed (pip install 'femodes[render]')",
)

GAP = 0.01


@pytest.fixture(scope="module")
def nnm():
    mesh = fm.line_mesh(1.0, 20, boundaries={"clamp": 0.0, "tip": 1.0})
    beam = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    model = beam.with_contact(fm.UnilateralContact(at="tip", gap=GAP))
    red = fm.craig_bampton(model, 6)
    return fm.nonlinear_mode(red, 1, energy=(1e-4, 1e-3), harmonics=fm.Harmonics(5))


def test_gif(nnm, tmp_path):
    import imageio.v3 as iio

    from femodes.viz import AnimationStyle, animate

    path = animate(nnm[-1], None, tmp_path / "a" / "mode.gif", n_frames=6,
                   style=AnimationStyle(window_size=(240, 144), fps=6))
    assert path.is_file() and path.stat().st_size > 1000
    frames = iio.imread(path, index=None)
    assert frames.shape[0] == 6
    assert frames.shape[1:3] == (144, 240)
    diffs = [np.abs(frames[k].astype(int) - frames[0].astype(int)).sum() for k in range(1, 6)]
    assert min(diffs) > 0  # the structure moves
    # not blank: a white background with a coloured structure and a dark obstacle
    assert frames[0].std() > 5


def test_mp4_and_linear_mode(nnm, tmp_path):
    pytest.importorskip("imageio_ffmpeg", reason="mp4 needs imageio-ffmpeg")
    import imageio.v2 as iio2

    from femodes.viz import AnimationStyle, animate

    red = nnm.model
    modes = fm.linear_modes(red, 2)
    path = animate(modes, red, tmp_path / "lin.mp4", n_frames=4, style=AnimationStyle(window_size=(200, 120)), mode=2)
    assert path.stat().st_size > 500
    with iio2.get_reader(path) as r:
        frames = [f for f in r]
    assert len(frames) == 4
    assert frames[0].shape[:2] == (128, 208)  # rounded up to multiples of 16


def test_bar(tmp_path):
    import imageio.v3 as iio

    from femodes.viz import AnimationStyle, animate

    mesh = fm.line_mesh(1.0, 10, boundaries={"clamp": 0.0, "tip": 1.0})
    bar = fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
    model = bar.with_contact(fm.UnilateralContact(at="tip", gap=0.02))
    modes = fm.linear_modes(model, 1)
    path = animate(modes, model, tmp_path / "bar.gif", n_frames=3, style=AnimationStyle(window_size=(160, 96)), mode=1,
                   scale=0.1)
    assert iio.imread(path, index=None).shape[0] == 3


def test_bad_input(nnm, tmp_path):
    from femodes.viz import AnimationStyle, animate

    sol = nnm[-1]
    with pytest.raises(ValueError, match="n_frames"):
        animate(sol, None, tmp_path / "x.gif", n_frames=1)
    with pytest.raises(ValueError, match=r"\.gif or \.mp4"):
        animate(sol, None, tmp_path / "x.avi")
    with pytest.raises(ValueError, match="window_size"):
        AnimationStyle(window_size=(10, 5000000))
    with pytest.raises(ValueError, match="fps"):
        AnimationStyle(fps=0)
    model = fm.StructuralModel(M=np.eye(2), K=np.array([[2.0, -1.0], [-1.0, 2.0]]))
    with pytest.raises(ValueError, match="no mesh"):
        animate(fm.linear_modes(model, 1), model, tmp_path / "x.gif", mode=1)
    assert not list(tmp_path.iterdir())
