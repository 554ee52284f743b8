"""Linear modes of the 2-DOF chain ground-k1-m1-k2-m2 with k = m = 1.

Exact: w = (sqrt(5) -/+ 1) / 2 and shape ratios x2/x1 = +1.618, -0.618.
"""

import numpy as np

import femodes as fm

model = fm.StructuralModel(M=np.eye(2), K=[[2.0, -1.0], [-1.0, 1.0]], dof_names=["x1", "x2"])
modes = fm.linear_modes(model, n=2)
ratios = modes.shapes[1] / modes.shapes[0]

if __name__ == "__main__":
    for w, r in zip(modes.omega, ratios):
        print(f"w = {w:.10f} rad/s, x2/x1 = {r:+.10f}")
