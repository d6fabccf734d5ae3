"""Named scanners, each with where its numbers come from.

* ``prototype`` — the paper's Appendix B prototype: two identical prisms, n = 1.51, 18 deg wedges,
  7294 and -4664 rpm, 100 kHz ranging.  The tilted faces face each other (first prism's exit face,
  second prism's entry face), the arrangement with no central hole and the widest FoV
  (``shared/facts/risley-optics.md``: exact 38.43 deg).
* ``mid40`` — the Livox Mid-40, the product of that design: 38.4 deg circular FoV, 100 k points/s,
  beam divergence 0.28 x 0.03 deg (Livox specifications).  Same optics as ``prototype``; it differs
  in the published beam divergence and its name in reports.
* ``horizon`` — the paper's Section III.D.2 / Fig. 9 three-prism close-to-rectangle scanner and its
  product, the Livox Horizon: 81.7 x 25.1 deg FoV, 6 channels stacked vertically, 240 k points/s,
  line id = point index mod 6.  P1 and P2 are identical and counter-rotate with exactly opposite
  phase (a harmonic oscillator along x, horizontal); P3 has a smaller wedge and turns slower.
  The paper gives no prism parameters, so the two wedge angles are solved under exact refraction
  for the published FoV by ``scripts/solve_horizon_wedges.py`` (starting from the paraxial
  decomposition x: 2a + b, y: b) and pinned here; a test re-checks the FoV.  Speeds and channel
  spacing are our choices, documented below.
"""

from __future__ import annotations

from sim.scan.optics import Prism, RisleyOptics

N_BK7_LIKE = 1.51  # paper Appendix B

PROTOTYPE = RisleyOptics(
    prisms=(
        Prism(wedge_deg=18.0, index=N_BK7_LIKE, tilted_face="exit", rpm=7294.0),
        Prism(wedge_deg=18.0, index=N_BK7_LIKE, tilted_face="entry", rpm=-4664.0),
    ),
    point_rate_hz=100_000,
    name="prototype",
)

MID40 = PROTOTYPE.with_(name="mid40", beam_divergence_deg=(0.28, 0.03))

# Horizon: solved wedges (scripts/solve_horizon_wedges.py), our speeds and channel spacing.
HORIZON_WEDGE_P12_DEG = 23.940993  # solved: exact FoV 81.700 x 25.100 deg
HORIZON_WEDGE_P3_DEG = 16.640332
# P1/P2 at 6017 rpm: ~200 horizontal sweeps per second; P3 at -1307 rpm: the oscillator's line
# turns once per ~46 ms, so a 100 ms frame holds two turns.  The ratio is far from small integers.
HORIZON_RPM_P12 = 6017.0
HORIZON_RPM_P3 = -1307.0
# Six dies side by side in the focal plane, placed vertically (Fig. 8a): 0.8 deg apart.
HORIZON_CHANNEL_Y_DEG = (-2.0, -1.2, -0.4, 0.4, 1.2, 2.0)


def horizon_optics(wedge_p12_deg: float, wedge_p3_deg: float) -> RisleyOptics:
    """The Horizon layout for given wedge angles (used by the solver and the preset)."""
    return RisleyOptics(
        prisms=(
            Prism(wedge_deg=wedge_p12_deg, index=N_BK7_LIKE, tilted_face="exit", rpm=HORIZON_RPM_P12, phase_deg=0.0),
            Prism(wedge_deg=wedge_p12_deg, index=N_BK7_LIKE, tilted_face="entry", rpm=-HORIZON_RPM_P12, phase_deg=0.0),
            Prism(wedge_deg=wedge_p3_deg, index=N_BK7_LIKE, tilted_face="exit", rpm=HORIZON_RPM_P3, phase_deg=90.0),
        ),
        point_rate_hz=240_000,
        channel_offsets_deg=tuple((0.0, y) for y in HORIZON_CHANNEL_Y_DEG),
        beam_divergence_deg=(0.28, 0.03),
        name="horizon",
    )


HORIZON = horizon_optics(HORIZON_WEDGE_P12_DEG, HORIZON_WEDGE_P3_DEG)

PRESETS: dict[str, RisleyOptics] = {"prototype": PROTOTYPE, "mid40": MID40, "horizon": HORIZON}

# Multi-line spinning comparison scanners (not Risley; the lidar-IMU calibration): sim/scan/spinning.py.
from sim.scan.spinning import SPINNING_PRESETS  # noqa: E402,F401
