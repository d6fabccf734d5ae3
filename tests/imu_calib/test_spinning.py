"""The 16-line spinning preset (paper Fig. 10a comparison scanner)."""

import numpy as np

from sim.scan.presets import PRESETS, SPINNING_PRESETS
from sim.scan.spinning import VLP16, SpinningScanModel


def test_vlp16_geometry_and_rates():
    assert VLP16.channels == 16 and VLP16.vertical_fov_deg == 30.0
    assert np.allclose(np.diff(VLP16.elevations_deg), 2.0)
    assert VLP16.point_rate_hz == 288_000            # 1800 firings a turn, 10 turns/s, 16 beams
    assert "vlp16" in SPINNING_PRESETS and "vlp16" not in PRESETS   # Risley consumers never see it


def test_directions_are_unit_elevations_are_the_beams_and_a_turn_repeats():
    m = SpinningScanModel(VLP16)
    turn = m.scan_time(0.0, 0.1)
    assert len(turn) == 28_800
    assert np.allclose(np.linalg.norm(turn.direction, axis=1), 1.0)
    el = np.degrees(np.arcsin(turn.direction[:, 2]))
    assert np.allclose(el, np.asarray(VLP16.elevations_deg)[turn.channel])
    az = np.degrees(np.arctan2(turn.direction[:, 1], turn.direction[:, 0])) % 360
    assert np.allclose(np.unique(np.round(az, 6)), np.arange(0, 360, 0.2), atol=1e-6)
    nxt = m.scan_time(0.1, 0.2)
    assert np.allclose(nxt.direction, turn.direction)   # no new directions with accumulation
    assert np.all(np.diff(np.concatenate([turn.t_ns, nxt.t_ns])) >= 0)
    # chunking does not change the points
    a = m.scan(1000, 5000)
    b = m.scan(1000, 2000), m.scan(3000, 3000)
    assert np.array_equal(a.direction, np.vstack([b[0].direction, b[1].direction]))
    assert np.array_equal(a.t_ns, np.concatenate([b[0].t_ns, b[1].t_ns]))
