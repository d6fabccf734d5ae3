"""The lidar's range envelope, always on (``sim.scan.presets.RANGE_ENVELOPE_M``, applied by
``sim.sensor.SceneSensor`` / ``sim.sensor_kernels.assemble_returns_kernel``): no point nearer than the
blind zone or farther than the maximum range, whichever effects a scene lists.

Bounds asserted
---------------
* fig12 without ``return_probability`` (the effect that used to be the only range limit), 3 s
  closed loop: every point's range is within the Mid-40's envelope [1 m, 290.7 m] to the 1 mm
  output grid (sqrt(3)/2 mm); on 802524f its ground returns reached 569 km;
* hits at ranges from 1 cm to 1e7 m (beyond the int32 mm output, +-2147 km) and random envelopes:
  a hit is kept exactly when its measured range is inside the envelope, and a kept point's bearing
  is its beam's to 1e-9 rad (no saturation can bend it: the envelope's maximum is validated below
  the int32 mm limit);
* a scene's ``[lidar] min_range_m / max_range_m`` outside [0, 2147483.647] or min >= max is a
  one-line error naming the key.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from foveatrack.errors import UserError
from sim import sensor_kernels as sk
from sim.scan.kernels import RAY_OK
from sim.scan.presets import RANGE_ENVELOPE_M
from sim.scene import MAX_RANGE_LIMIT_M, scene_from_mapping
from stability_util import angle_between, examples

ROOT = Path(__file__).resolve().parents[2]
GRID_M = math.sqrt(3) * 0.5e-3   # a point on the 1 mm grid is at most this far from its true place


def _fig12_mapping() -> dict:
    return tomllib.loads((ROOT / "scenes" / "fig12-tracking.toml").read_text())


def test_fig12_without_return_probability_stays_inside_the_envelope():
    from sim.loop import ClosedLoop

    data = _fig12_mapping()
    data["scene"]["effects"] = ["range_noise", "motor_speed_noise"]
    scene = replace(scene_from_mapping(data, "fig12 without return_probability"), duration_s=3.0)
    lo, hi = scene.lidar_range_m
    assert (lo, hi) == RANGE_ENVELOPE_M["mid40"] and hi == pytest.approx(290.69, abs=0.01)
    ranges = []
    ClosedLoop(scene, frame_hook=lambda frame, out, loop: ranges.append(np.linalg.norm(frame.xyz, axis=1))).run()
    r = np.concatenate(ranges)
    assert r.size > 10_000
    assert r.min() >= lo - GRID_M and r.max() <= hi + GRID_M
    assert r.max() > 0.9 * hi   # the ground does reach out to the maximum range


@examples(60)
@given(st.integers(0, 2**32 - 1), st.floats(0.0, 50.0), st.floats(1.0, 1e7))
def test_kernel_keeps_exactly_the_hits_inside_the_envelope(seed, lo, span):
    hi = min(lo + span, MAX_RANGE_LIMIT_M)
    rng = np.random.default_rng(seed)
    n = 500
    prim = np.zeros(n, dtype=np.int64)
    status = np.full(n, RAY_OK, dtype=np.uint8)
    range_m = 10.0 ** rng.uniform(-2, 7, n)          # 1 cm .. 10 000 km
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t_ns = np.arange(n, dtype=np.int64)
    out = (np.empty((n, 3)), np.empty(n, np.int64), np.empty(n, np.uint8), np.empty(n, np.bool_))
    none = np.zeros(0)
    k = sk.assemble_returns_kernel(prim, status, range_m, d, t_ns, np.full(1, 100.0), np.full(1, 20, np.uint8), 1,
                                   none, none, 0.0, none, 0.0, none, 0.0, True, lo, hi,
                                   np.full(1, 0.2), none, 0.0, 0.0, none, 1, *out)
    inside = (range_m >= lo) & (range_m <= hi)
    assert k == int(inside.sum())
    np.testing.assert_array_equal(out[1][:k], t_ns[inside])
    xyz = out[0][:k]
    r = np.linalg.norm(xyz, axis=1)
    assert np.all(np.abs(r - range_m[inside]) <= GRID_M)
    far = r > 10.0   # the bearing of a point on the mm grid is its beam's to (grid / range) rad
    assert np.all(angle_between(xyz[far], d[inside][far]) <= GRID_M / r[far] + 1e-12)


@pytest.mark.parametrize("lidar, key", [
    ({"preset": "mid40", "max_range_m": 3e6}, "max_range_m"),
    ({"preset": "mid40", "min_range_m": -1.0}, "min_range_m"),
    ({"preset": "mid40", "min_range_m": 300.0}, "min_range_m"),
    ({"preset": "mid40", "max_range_m": "far"}, "max_range_m"),
])
def test_envelope_keys_are_checked(lidar, key):
    data = _fig12_mapping()
    data["lidar"] = lidar
    with pytest.raises(UserError, match=key) as exc:
        scene_from_mapping(data, "scene.toml")
    assert "\n" not in str(exc.value) and "[lidar]" in str(exc.value)


def test_envelope_from_the_preset_or_the_scene():
    data = _fig12_mapping()
    data["lidar"] = {"preset": "tele15"}
    assert scene_from_mapping(data, "s").lidar_range_m == RANGE_ENVELOPE_M["tele15"]
    assert RANGE_ENVELOPE_M["tele15"][1] == pytest.approx(500.0 * math.sqrt(1.25))
    data["lidar"] = {"preset": "mid40", "min_range_m": 0.5, "max_range_m": 100.0}
    assert scene_from_mapping(data, "s").lidar_range_m == (0.5, 100.0)
