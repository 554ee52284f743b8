"""Discretise layer: harmonic balance (Fourier layout, AFT, dynamic stiffness, HBM problems)."""
