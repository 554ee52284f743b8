"""Application layer: ``femodes demo`` tells a clear story and its pictures match its words.

The demo runs once per module (~30 s on 2 cores, rendering included) under a hard time limit;
every test reads what it wrote: the branches (.npz), the ParaView series, the GIF and the summary.
"""

import contextlib
import dataclasses
import importlib.util
import os
import re
import signal
import time
import xml.etree.ElementTree as ET

os.environ.setdefault("MPLBACKEND", "Agg")
os.environ.setdefault("PYVISTA_OFF_SCREEN", "true")  # rendering is always off screen here

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import femodes as fm  # noqa: E402
from femodes.app import demo  # noqa: E402

#: A hang guard, not a speed test (the demo's speed is measured by `femodes demo` itself): 16 s of
#: CPU, 40 s wall on a 2-core machine at load 7; 90 s was exceeded at load 8 by three test suites.
TIME_LIMIT = 300
W1 = 3.516184  # linear w1 of the Craig-Bampton model (the demo's table: 3.51618400 rad/s)
W2 = 22.047341  # linear w2 of the same model
GAP = 0.01
HAS_RENDER = importlib.util.find_spec("pyvista") is not None and importlib.util.find_spec("imageio") is not None


@contextlib.contextmanager
def time_limit(seconds):
    """Fail (instead of hanging) if the block runs longer than ``seconds`` (POSIX; no-op elsewhere)."""
    if not hasattr(signal, "SIGALRM"):
        yield
        return

    def expired(signum, frame):
        raise TimeoutError(f"femodes demo exceeded {seconds} s")

    old = signal.signal(signal.SIGALRM, expired)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    t0 = time.perf_counter()
    with time_limit(TIME_LIMIT):
        res = demo.run_demo(out)
    res["elapsed"] = time.perf_counter() - t0
    return res


@pytest.fixture(scope="module")
def backbone(run):
    return fm.load_branch(run["out"] / "backbone.npz")


@pytest.fixture(scope="module")
def forced(run):
    return fm.load_branch(run["out"] / "forced.npz")


def tip_harmonics(sol):
    """Amplitudes of harmonics 0..H of the contact (tip) DOF, computed here from the coefficients."""
    h, q = sol.harmonics, sol.Q[:, sol.contacts.dofs[0]]
    return np.array([abs(q[0])] + [np.hypot(q[h.layout.cos_index(k)], q[h.layout.sin_index(k)]) for k in range(1, h.n_harmonics + 1)])


def animated_frames(run):
    """Frame times and omega of the ParaView series (what the demo animated)."""
    import meshio

    pvd = run["out"] / "mode1.pvd"
    entries = ET.parse(pvd).getroot().findall(".//DataSet")
    first = meshio.read(pvd.parent / entries[0].get("file"))
    return [float(e.get("timestep")) for e in entries], float(np.ravel(first.field_data["omega"])[0])


def test_return_contract_and_files(run):
    assert set(run) >= {"lines", "plot", "out", "files"}
    assert run["plot"] == run["out"] / "cantilever_modes.png"
    names = [p.name for p in run["files"]]
    assert names[:3] == ["cantilever_modes.png", "frequency_energy.png", "mode1.pvd"]
    assert {"summary.txt", "backbone.npz", "forced.npz"} <= set(names)
    for p in run["files"]:
        assert p.is_file() and p.stat().st_size > 0, p
    for p in ("cantilever_modes.png", "frequency_energy.png"):
        assert (run["out"] / p).stat().st_size > 20_000  # a real figure, not an empty canvas
    # the GIF is listed exactly when it was written (the CLI prints the names in `files`)
    gif = run["out"] / "mode1.gif"
    assert ("mode1.gif" in names) == gif.is_file()
    if "mode1.gif" not in names:
        assert any(line.startswith("rendered animation skipped") for line in run["lines"])
    assert (run["out"] / "summary.txt").read_text().splitlines() == run["lines"]
    assert run["elapsed"] < TIME_LIMIT


def test_backbone_stiffens_with_contact(backbone):
    w = backbone.omega
    assert len(backbone) >= 120  # BACKBONE_MAX_STEP = 0.005 gives ~140 points
    assert w[0] == pytest.approx(W1, abs=1e-5)  # starts linear, below the grazing energy
    # contact raises the frequency by 5.4 % (3.5162 -> 3.7075 rad/s); at least 5 %, at most 7 %
    assert 1.05 * W1 < w.max() < 1.07 * W1
    # no straight chord invents a feature: the first point in contact is close to grazing,
    # and neighbouring points are close in frequency all along
    first = int(np.flatnonzero(w > W1 * (1 + 1e-5))[0])
    assert w[first] - W1 < 0.01
    assert backbone.energy[first] / backbone.energy[first - 1] < 1.05
    assert np.abs(np.diff(w)).max() < 0.012
    # the stiffening part dominates: the frequency rises over > 10x the width of the bend-back
    i_top = int(np.argmax(w))
    assert w[i_top] - W1 > 10 * (w[i_top] - w[i_top:].min())


def test_internal_resonance_labelled(run, backbone):
    irs = demo.internal_resonances(backbone, backbone.contacts.dofs[0], [W1, W2, 61.796, 121.29])
    assert [(r.k, r.mode) for r in irs] == [(6, 2)]
    r = irs[0]
    assert r.omega_line == pytest.approx(W2 / 6, rel=1e-6)
    for i in r.indices:  # each flagged point: harmonic 6 above 10 % of the fundamental, 6 w near w2
        a = tip_harmonics(backbone[i])
        assert a[6] > demo.IR_SHARE * a[1]
        assert abs(6 * backbone.omega[i] / W2 - 1) < demo.IR_TOLERANCE
    # the resonance sets in after the frequency maximum, on the bend-back
    assert min(r.indices) > int(np.argmax(backbone.omega))
    summary = (run["out"] / "summary.txt").read_text()
    assert "6:1 internal resonance with mode 2 (w2/6 = 3.6746 rad/s)" in summary
    assert "stiffens" in summary and "grazing energy" in summary


def test_forced_folds_located(run, forced):
    assert len(forced.folds) == 2
    np.testing.assert_allclose(forced.omega[list(forced.folds)], [3.7446, 3.6871], atol=2e-3)
    assert "folds at w = 3.7446 and 3.6871 rad/s" in (run["out"] / "summary.txt").read_text()
    # FORCED_MAX_STEP = 0.2 bounds the steps: over 100 points on the span (117 with the contact forces
    # scaled by the contact stiffness in the arclength, 150 before)
    assert len(forced) >= 100


def test_animation_frames_follow_the_spectrum(run, backbone):
    times, omega = animated_frames(run)
    i = int(np.argmin(np.abs(backbone.omega - omega)))
    assert backbone.omega[i] == pytest.approx(omega, rel=1e-12)
    sol = backbone[i]
    n = len(times)
    np.testing.assert_allclose(np.diff(times), sol.period / n, rtol=1e-9)  # one period, evenly spaced
    a = tip_harmonics(sol)
    k = max(j for j in range(1, a.size) if a[j] > 0.01 * sol.amplitude(sol.contacts.dofs[0]))
    assert k == 6  # the 6th harmonic (mode 2) is the highest that matters for this orbit ...
    assert n >= 8 * k and n >= 24  # ... so it gets at least 8 frames per period
    # the animated orbit is mode 1: the fundamental dominates every higher harmonic
    assert a[1] > 5 * a[2:].max()
    if (run["out"] / "mode1.gif").is_file():
        import imageio.v3 as iio

        assert iio.imread(run["out"] / "mode1.gif", index=None).shape[0] == n


def test_summary_reports_penetration(run, backbone, forced):
    summary = (run["out"] / "summary.txt").read_text()
    assert "penetration" in summary
    pen = backbone.penetration.max()
    assert 0 < pen < 0.1 * GAP  # below 10 % of the gap on the backbone (H = 10)
    assert f"{pen:.1e} = {100 * pen / GAP:.1f} % of the gap on the backbone" in summary
    assert f"{forced.penetration.max():.1e}" in summary
    _, omega = animated_frames(run)
    sol = backbone[int(np.argmin(np.abs(backbone.omega - omega)))]
    assert f"max penetration {sol.penetration:.1e}" in summary


def test_frequency_energy_fold_markers_and_points(forced, backbone):
    import matplotlib.pyplot as plt

    try:
        ax = fm.plot.frequency_energy([backbone, forced])
        lines = ax.get_lines()
        assert len(lines) == 3  # two branches, then the fold markers (on by default)
        assert lines[2].get_marker() == "x"
        np.testing.assert_array_equal(lines[2].get_xdata(), forced.omega[list(forced.folds)])
        np.testing.assert_array_equal(lines[2].get_ydata(), forced.energy[list(forced.folds)])
        assert lines[0].get_marker() in ("None", None, "")  # no point markers by default
        ax = fm.plot.frequency_energy([backbone, forced], mark_folds=False, show_points=True)
        lines = ax.get_lines()
        assert len(lines) == 2
        assert all(ln.get_marker() == "." for ln in lines)
    finally:
        plt.close("all")


@pytest.mark.skipif(not HAS_RENDER, reason="pyvista/imageio not installed (pip install 'femodes[render]')")
def test_gif_shows_penetration(run, backbone):
    """The contact node is drawn red (and the frame text red) exactly in the frames where it is inside the stop."""
    import imageio.v3 as iio

    assert (run["out"] / "mode1.gif").is_file(), "rendering is installed, so the demo must write the GIF"
    frames = iio.imread(run["out"] / "mode1.gif", index=None).astype(int)
    times, omega = animated_frames(run)
    sol = backbone[int(np.argmin(np.abs(backbone.omega - omega)))]
    g = sol.gap(np.asarray(times))[:, 0]
    red = [int(((f[..., 0] > 180) & (f[..., 1] < 70) & (f[..., 2] < 70)).sum()) for f in frames]
    inside = np.flatnonzero(g < -1e-3 * GAP)
    clear = np.flatnonzero(g > 0.1 * GAP)
    assert inside.size and clear.size
    assert min(red[j] for j in inside) > 50
    assert max(red[j] for j in clear) == 0


@pytest.mark.skipif(not HAS_RENDER, reason="pyvista/imageio not installed (pip install 'femodes[render]')")
def test_animate_contact_overlay_is_optional(run, tmp_path):
    """``show_contact=False`` draws no contact ball and no penetration text; linear modes get none."""
    import imageio.v3 as iio

    mesh = fm.load_mesh(demo._find_mesh("cantilever.msh"))
    beam = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    rom = fm.craig_bampton(beam.with_contact(fm.UnilateralContact(at="tip", gap=GAP)), n_modes=10)
    backbone = fm.load_branch(run["out"] / "backbone.npz").attach(rom)
    sol = backbone[int(np.argmax(backbone.omega))]
    t = sol.period * np.arange(16) / 16
    j = int(np.argmin(sol.gap(t)[:, 0]))  # the deepest frame on the 16-frame grid
    small = fm.viz.AnimationStyle(window_size=(320, 180))
    with_overlay = iio.imread(fm.viz.animate(sol, rom, tmp_path / "on.gif", 16, style=small), index=j).astype(int)
    off = dataclasses.replace(small, show_contact=False)
    without = iio.imread(fm.viz.animate(sol, rom, tmp_path / "off.gif", 16, style=off), index=j).astype(int)

    def n_red(f):
        return int(((f[..., 0] > 180) & (f[..., 1] < 70) & (f[..., 2] < 70)).sum())

    assert n_red(with_overlay) > 20 and n_red(without) == 0
    with pytest.raises(TypeError, match="unit"):
        fm.viz.AnimationStyle(unit=3)


def test_summary_mentions_units_and_story(run):
    text = "\n".join(run["lines"])
    for phrase in ("EI = rho A = L = 1", "grazing energy", "below E_g: linear", "contact stiffens mode 1",
                   "folds at", "internal resonance", "penetration", "frames per period"):
        assert phrase in text, phrase
    assert re.search(r"w rises to 3\.70\d\d rad/s \(\+5\.\d %\)", text)


def test_demo_shows_stability_and_the_period_doubling(run):
    """The impact oscillator's period doubling (shooting) is reported, drawn and switched onto."""
    summary = (run["out"] / "summary.txt").read_text()
    assert "period doubling at w = 0.996204" in summary
    assert "period-2 branch (switch_branch" in summary
    osc = fm.load_branch(run["out"] / "oscillator.npz")
    assert [b.kind for b in osc.bifurcations].count("period_doubling") == 1
    assert (run["out"] / "stability.png") in run["files"] and (run["out"] / "stability.png").stat().st_size > 10_000
