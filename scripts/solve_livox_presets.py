"""Solve the Mid-70, Avia and Tele-15 presets' optics for their datasheet FoV under exact refraction.

Livox publishes the FoV, point rate, laser count and beam divergence of each unit, not its prisms.
Each is modelled as the Mid-40's two-prism design (identical wedges, n = 1.51, tilted faces facing
each other, Mid-40 speeds 7294 / -4664 rpm as HELIOS++ also gives its Mid-70) scaled to its own FoV:

- mid70: one laser, 70.4 deg circular -> one unknown, the wedge angle;
- avia: six lasers stacked vertically, 70.4 (H) x 77.2 (V) deg -> the wedge angle (H) and the
  channel spacing (V), two unknowns, two targets;
- tele15: six lasers stacked vertically, 14.5 (H) x 16.2 (V) deg -> as the Avia.

The paraxial start is wedge = (FoV_H / 4) / (n - 1), spacing = (FoV_V - FoV_H) / 5; a least-squares
solve on the exact FoV (``sim.scan.fov.field_of_view_deg``) finishes.  Paste the printed values into
``sim/scan/presets.py``; ``tests/scan/test_livox_presets.py`` re-checks every preset's FoV.

Usage: python scripts/solve_livox_presets.py
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from sim.scan.fov import field_of_view_deg
from sim.scan.presets import N_BK7_LIKE, stacked_optics

TARGETS = {"mid70": (70.4, 70.4, 1), "avia": (70.4, 77.2, 6), "tele15": (14.5, 16.2, 6)}


def main() -> None:
    for name, (h_deg, v_deg, channels) in TARGETS.items():
        wedge0 = (h_deg / 4) / (N_BK7_LIKE - 1)
        if channels == 1:
            def residual(x):
                return [field_of_view_deg(stacked_optics(name, x[0], 1, 0.0), samples=200_000)[0] - h_deg]
            x0 = [wedge0]
        else:
            def residual(x):
                fov = field_of_view_deg(stacked_optics(name, x[0], channels, x[1]), samples=200_000)
                return np.array(fov) - (h_deg, v_deg)
            x0 = [wedge0, (v_deg - h_deg) / (channels - 1)]
        sol = least_squares(residual, x0, diff_step=1e-4, xtol=1e-10, ftol=1e-10)
        spacing = sol.x[1] if channels > 1 else 0.0
        fov = field_of_view_deg(stacked_optics(name, sol.x[0], channels, spacing))
        print(f"{name}: wedge {sol.x[0]:.6f} deg, channel spacing {spacing:.6f} deg -> exact FoV "
              f"{fov[0]:.4f} x {fov[1]:.4f} deg (datasheet {h_deg} x {v_deg})")


if __name__ == "__main__":
    main()
