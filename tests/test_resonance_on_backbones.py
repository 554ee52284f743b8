"""Issue 35's check that backbones predict forced resonances, on four structures with a stop
(examples/resonance_on_backbones.py, two damping levels each): the peak of the forced response
against the backbone of the free structure at the peak's energy."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
import resonance_on_backbones as ex  # noqa: E402


@pytest.fixture(scope="module", params=list(ex.STRUCTURES))
def study(request):
    return ex.run(request.param, quick=True, echo=False)


def test_forced_peaks_lie_on_the_backbone_or_in_a_listed_tongue(study):
    """Measured (full example, damping d, d/2, d/4): bar +0.55 %, -0.12 %, +0.015 % (the
    contact-phase family past grazing; the grazing family stays at w1, 20 % below); beam +0.19,
    +0.18, +0.17 % (both ride the 6:1 internal resonance with mode 2); user's 3-D blade +0.06,
    +0.46, +0.13 %; the 2-D blade's peaks sit in the tongue of a 5:1 internal resonance with mode
    2 that its backbone steps over and lists (-6 to -11 % from the family past it). Tolerances:
    the largest measured distance of each structure, rounded up."""
    name, peaks = study["name"], study["peaks"]
    d = np.array([p.distance for p in peaks])
    if name == "blade2d":
        assert all(p.tongue is not None and 2 in p.tongue_modes for p in peaks)
        assert all("tongue" in p.predicted for p in peaks)
        return
    if name == "bar":
        assert study["family"] == "contact phase"
    bound = {"bar": 6e-3, "beam": 2e-3, "blade3d": 5e-3}[name]
    assert np.all(np.abs(d) < bound), d
    assert all(p.predicted.startswith("on the backbone") for p in peaks)
    # lower damping: a higher peak, further up the backbone
    assert peaks[1].energy > peaks[0].energy

