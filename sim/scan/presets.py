"""Named scanners, each with where its numbers come from.

* ``prototype`` — the paper's Appendix B prototype: two identical prisms, n = 1.51, 18 deg wedges,
  7294 and -4664 rpm, 100 kHz ranging.  The tilted faces face each other (first prism's exit face,
  second prism's entry face), the arrangement with no central hole and the widest FoV
  (``shared/facts/risley-optics.md``: exact 38.43 deg).
* ``mid40`` — the Livox Mid-40, the product of that design: 38.4 deg circular FoV, 100 k points/s,
  beam divergence 0.28 x 0.03 deg (Livox specifications).  Same optics as ``prototype``; its prism
  speeds are the paper's pair scaled by 1.09 (``MID40_RPM``, the ratio and so the rosette's shape kept),
  so that its FoV coverage follows Livox's published Mid-40 curve (``sim.scan.livox_published``; within
  0.03 at every 0.05 s, docs/livox-files.md).  Livox does not publish the speeds.
* ``horizon`` — the paper's Section III.D.2 / Fig. 9 three-prism close-to-rectangle scanner and its
  product, the Livox Horizon: 81.7 x 25.1 deg FoV, 6 channels stacked vertically, 240 k points/s,
  line id = point index mod 6.  P1 and P2 are identical and counter-rotate with exactly opposite
  phase (a harmonic oscillator along x, horizontal); P3 has a smaller wedge and turns slower.
  The paper gives no prism parameters, so the two wedge angles are solved under exact refraction
  for the published FoV by ``scripts/solve_horizon_wedges.py`` (starting from the paraxial
  decomposition x: 2a + b, y: b) and pinned here; a test re-checks the FoV.  The channel spacing is
  our choice; the speeds are fitted to Livox's published coverage curve (within 0.03,
  docs/livox-files.md), documented below.
* ``mid70`` — Livox Mid-70: 70.4 deg circular FoV, 100 k points/s, one laser, beam divergence
  0.28 x 0.03 deg (Livox Mid-70 datasheet / user manual).  The Mid-40 design (HELIOS++
  ``livox_mid-70`` has the paper's speeds, 7294 / -4664 rpm, and a 35.2 deg half angle) with the
  wedge angle solved under exact refraction for 70.4 deg by ``scripts/solve_livox_presets.py``.
* ``avia`` — Livox Avia: 70.4 (H) x 77.2 (V) deg non-repetitive FoV, 240 k points/s, six lasers,
  beam divergence 0.28 x 0.03 deg (Livox Avia datasheet; the Gazebo plugin's avia.csv has the same
  horizontal_fov / vertical_fov).  The Mid-40 design with six lasers stacked vertically: the wedge
  angle (horizontal span) and the channel spacing (the extra vertical span) are solved together
  for the datasheet FoV.  Speeds: the paper's prototype speeds (our choice; Livox does not publish them).
* ``tele15`` — Livox Tele-15: 14.5 (H) x 16.2 (V) deg, 240 k points/s, six lasers, beam divergence
  0.02 x 0.12 deg (Livox Tele-15 datasheet; facts: livox.md).  Wedge and channel spacing solved as the
  Avia's; its own speeds (``TELE15_RPM``: one fast prism drawing circles through the centre, one slow
  prism precessing them, as on Livox's Tele-15 pattern figure), chosen so that its FoV coverage follows
  Livox's published curve (within 0.03, docs/livox-files.md).  The speeds do not change the FoV.
* ``mid100`` — Livox Mid-100: three Mid-40 heads in one housing, 98.4 x 38.4 deg, 300 k points/s
  (Livox Mid-40/Mid-100 datasheet).  Heads turned +30 / 0 / -30 deg about the vertical (HELIOS++
  ``livox-mid-100``: beam origins at -30, 0, +30 deg; 38.4 + 60 = 98.4).  Point ``k`` comes from
  head ``k mod 3``; the heads share one prism phase (:attr:`RisleyOptics.head_yaw_deg`).

``DATASHEET_FOV_DEG`` holds each preset's datasheet FoV; a test holds every preset within 0.5 deg.

Range envelope (``RANGE_ENVELOPE_M``, always on: :class:`sim.sensor.SceneSensor` returns no point
nearer than the blind zone or farther than the maximum range):

* maximum range: the datasheet range at 80 % reflectivity (``shared/facts/livox.md``, Specs: Mid-40
  and Horizon 260 m, Tele-15 500 m) carried to 100 % diffuse reflectivity by the facts' own
  scaling, maximum range ~ sqrt(reflectivity) (130 m at 20 % vs 260 m at 80 %): 290.7 m and 559.0 m.
  No diffuse target returns from farther (``return_probability`` has its 50 % point for a 100 %
  target there); the Mid-70, Avia and Mid-100 (not in the facts) take the Mid-40's.
* blind zone: the facts give none for these units; 1 m is assumed (Livox's public manuals give
  0.5 m for the later HAP; the Mid-70 is sold on its 0.05 m, taken here).  A scene can set
  both: ``[lidar] min_range_m`` / ``max_range_m``.
"""

from __future__ import annotations

import math

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

# Mid-40 speeds: the paper's pair (ratio, hence pattern shape, kept) scaled by 1.09 so that the swath
# coverage follows Livox's published Mid-40 curve (within 0.014 at every 0.05 s to 1.4 s; the paper's
# own speeds are 0.044 low at 0.7 s): scripts/fit_livox_presets.py, docs/livox-files.md.  Livox does not
# publish the Mid-40's speeds; both stay under the 12000 rpm the paper's motors reach (Section III.A).
MID40_RPM = (7950.5, -5083.8)
MID40 = PROTOTYPE.with_(name="mid40", beam_divergence_deg=(0.28, 0.03)).with_prism(0, rpm=MID40_RPM[0]) \
    .with_prism(1, rpm=MID40_RPM[1])

# Horizon: solved wedges (scripts/solve_horizon_wedges.py), our speeds and channel spacing.
HORIZON_WEDGE_P12_DEG = 23.940993  # solved: exact FoV 81.700 x 25.100 deg
HORIZON_WEDGE_P3_DEG = 16.640332
# Speeds fitted to Livox's published Horizon coverage curve (scripts/fit_livox_presets.py, within 0.03 at
# every 0.05 s to 0.6 s; docs/livox-files.md): P3 / P1 = -0.7172 and the scale searched.  P1/P2 at
# 6107.3 rpm: ~204 horizontal sweeps per second (20 per 0.1 s frame, which sets the line spacing);
# P3 at -4380.1 rpm carries the sweeps round its circle 7.3 times per 0.1 s.  (Before issue 27:
# 6017 / -1307 rpm, 0.048 below Livox's curve at 0.35 s.)
HORIZON_RPM_P12 = 6107.3
HORIZON_RPM_P3 = -4380.1
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

# ---- the other Livox SDK v1 Risley units (scripts/solve_livox_presets.py) -----------------------------
# The paper's prototype speeds (HELIOS++ gives its Mid-70 the same 7294 / -4664); our choice for the
# Mid-70 and Avia (the Tele-15 has its own, TELE15_RPM, below).
LIVOX_RPM = (7294.0, -4664.0)   # the paper's prototype speeds (the Mid-40 preset has its own, MID40_RPM)


def stacked_optics(name: str, wedge_deg: float, channels: int, spacing_deg: float, point_rate_hz: int = 240_000,
                   beam_divergence_deg: tuple[float, float] = (0.28, 0.03),
                   rpm: tuple[float, float] = LIVOX_RPM) -> RisleyOptics:
    """The Mid-40 design with its own wedge angle and ``channels`` lasers stacked vertically
    (``y_opt``) ``spacing_deg`` apart, centred on the axis (used by the solver and the presets).
    ``rpm``: the two prisms' speeds (the FoV does not depend on them)."""
    offsets = tuple((0.0, (c - (channels - 1) / 2) * spacing_deg) for c in range(channels))
    return RisleyOptics(
        prisms=(
            Prism(wedge_deg=wedge_deg, index=N_BK7_LIKE, tilted_face="exit", rpm=rpm[0]),
            Prism(wedge_deg=wedge_deg, index=N_BK7_LIKE, tilted_face="entry", rpm=rpm[1]),
        ),
        point_rate_hz=point_rate_hz,
        channel_offsets_deg=offsets,
        beam_divergence_deg=beam_divergence_deg,
        name=name,
    )


# solved by scripts/solve_livox_presets.py (exact FoV printed beside each)
MID70_WEDGE_DEG = 29.681516              # 70.400 x 70.400 deg
AVIA_WEDGE_DEG = 29.614309               # 70.400 x 77.200 deg
AVIA_CHANNEL_SPACING_DEG = 0.923672
TELE15_WEDGE_DEG = 7.060391              # 14.500 x 16.200 deg
TELE15_CHANNEL_SPACING_DEG = 0.335468

#: Datasheet FoV (horizontal, vertical) [deg] of every preset, the target each is solved for.
DATASHEET_FOV_DEG = {"prototype": (38.4, 38.4), "mid40": (38.4, 38.4), "horizon": (81.7, 25.1),
                     "mid70": (70.4, 70.4), "avia": (70.4, 77.2), "tele15": (14.5, 16.2), "mid100": (98.4, 38.4)}
#: Mid-100: three Mid-40 heads, left / centre / right, 30 deg apart (HELIOS++ livox-mid-100: beam
#: origins rotated -30, 0, +30 deg about the vertical; 38.4 + 2 x 30 = 98.4 deg, the datasheet FoV).
MID100_HEAD_YAW_DEG = (30.0, 0.0, -30.0)

MID70 = stacked_optics("mid70", MID70_WEDGE_DEG, 1, 0.0, point_rate_hz=100_000)
AVIA = stacked_optics("avia", AVIA_WEDGE_DEG, 6, AVIA_CHANNEL_SPACING_DEG)
# Tele-15 speeds, chosen for Livox's published coverage curve (scripts/fit_livox_presets.py,
# docs/livox-files.md).  One fast prism draws circles through the FoV centre, the other turns slowly
# against it and precesses them: the pattern of Livox's own Tele-15 picture (tele_15_pattern.png).
# rpm2 / rpm1 = -0.0377 and the scale were searched; within 0.03 at every 0.01 s to the plateau.
TELE15_RPM = (24600.0, -927.4)
TELE15 = stacked_optics("tele15", TELE15_WEDGE_DEG, 6, TELE15_CHANNEL_SPACING_DEG,
                        beam_divergence_deg=(0.02, 0.12), rpm=TELE15_RPM)
MID100 = MID40.with_(name="mid100", point_rate_hz=300_000, channel_offsets_deg=((0.0, 0.0),) * 3,
                     head_yaw_deg=MID100_HEAD_YAW_DEG)

PRESETS: dict[str, RisleyOptics] = {"prototype": PROTOTYPE, "mid40": MID40, "horizon": HORIZON, "mid70": MID70,
                                    "avia": AVIA, "tele15": TELE15, "mid100": MID100}

#: Datasheet range at 80 % reflectivity [m] (facts: livox.md, Specs), and the maximum range it gives
#: at 100 % diffuse reflectivity (range ~ sqrt(reflectivity), the facts' 130 m @ 20 % vs 260 m @ 80 %).
RANGE_80PCT_M = {"mid40": 260.0, "horizon": 260.0, "tele15": 500.0}
BLIND_ZONE_M = 1.0   # assumed: not in the facts (module docstring)


def _max_range_m(range_80pct_m: float) -> float:
    return range_80pct_m * math.sqrt(1.0 / 0.8)


#: (blind zone, maximum range) [m] per preset (module docstring); custom optics take the Mid-40's.
RANGE_ENVELOPE_M: dict[str, tuple[float, float]] = {
    name: (0.05 if name == "mid70" else BLIND_ZONE_M, _max_range_m(RANGE_80PCT_M.get(name, RANGE_80PCT_M["mid40"])))
    for name in PRESETS}
DEFAULT_RANGE_ENVELOPE_M = RANGE_ENVELOPE_M["mid40"]

# Multi-line spinning comparison scanners (not Risley; the lidar-IMU calibration): sim/scan/spinning.py.
from sim.scan.spinning import SPINNING_PRESETS  # noqa: E402,F401
