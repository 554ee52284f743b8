"""Shared fixtures: small meshes and models used across the test modules."""

import os

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")

import femodes as fm  # noqa: E402


@pytest.fixture
def unit():
    """Unit material and section: EA = EI = rho A = 1."""
    return fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0)


def cantilever(n_elements=10, length=1.0):
    mesh = fm.line_mesh(length=length, n_elements=n_elements, boundaries={"clamp": 0.0, "tip": length})
    return fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")


def fixed_free_bar(n_elements=10, order=1, **kw):
    mesh = fm.line_mesh(length=1.0, n_elements=n_elements, boundaries={"clamp": 0.0, "tip": 1.0})
    return fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), order=order, clamped="clamp", **kw)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
