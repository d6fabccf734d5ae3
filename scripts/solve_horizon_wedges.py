"""Solve the Horizon preset's two wedge angles for the published FoV under exact refraction.

The paper (Section III.D.2, Fig. 9c) gives the FoV, 81.7 x 25.1 deg, but no prism parameters.
Paraxially P1 = P2 = a and P3 = b give x: +-(2a + b), y: +-b (``shared/facts/risley-optics.md``);
exact refraction at these angles is far from paraxial, so we start from the paraxial solution and
let a least-squares solve on the exact FoV finish.  Paste the printed wedges into
``sim/scan/presets.py``; ``tests/scan/test_analyses.py`` (``test_horizon_fov_channels_and_rate``)
re-checks the FoV.

Usage: python scripts/solve_horizon_wedges.py
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import least_squares

from sim.scan.fov import field_of_view_deg
from sim.scan.presets import HORIZON_CHANNEL_Y_DEG, N_BK7_LIKE, horizon_optics

TARGET_DEG = (81.7, 25.1)


def main() -> None:
    spread = max(HORIZON_CHANNEL_Y_DEG) - min(HORIZON_CHANNEL_Y_DEG)
    b_dev = (TARGET_DEG[1] - spread) / 2
    a_dev = (TARGET_DEG[0] / 2 - b_dev) / 2
    x0 = np.array([a_dev, b_dev]) / (N_BK7_LIKE - 1)
    print(f"paraxial start: wedge P1=P2 {x0[0]:.3f} deg, P3 {x0[1]:.3f} deg")

    def residual(x):
        fov = field_of_view_deg(horizon_optics(*x), samples=200_000)
        return np.array(fov) - TARGET_DEG

    sol = least_squares(residual, x0, x_scale=1.0, diff_step=1e-4, xtol=1e-10, ftol=1e-10)
    fov = field_of_view_deg(horizon_optics(*sol.x))
    print(f"exact solution: wedge P1=P2 {sol.x[0]:.6f} deg, P3 {sol.x[1]:.6f} deg")
    print(f"exact FoV: {fov[0]:.4f} x {fov[1]:.4f} deg (target {TARGET_DEG[0]} x {TARGET_DEG[1]})")
    par = field_of_view_deg(horizon_optics(*sol.x), model="paraxial")
    print(f"paraxial model of the same optics: {par[0]:.3f} x {par[1]:.3f} deg")
    assert math.isfinite(fov[0])


if __name__ == "__main__":
    main()
