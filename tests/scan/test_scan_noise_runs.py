"""The fused scan's speed noise (sim.scan.kernels._scan_block_setup) against a numpy twin that asks
every point for its segment, bit for bit: the kernel finds where a block's run of one noise segment
ends from the block's last point and a bisection (a point's segment floor(t / T) does not decrease
along the block), not point by point; the phases, times and channels must not change."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim.scan import kernels as K
from sim.scan.model import ScanModel
from sim.scan.optics import SpeedNoise
from sim.scan.presets import PRESETS


def _twin_phases(model, k, m, segment_s):
    """``revs[:, :m]`` of the block ``k .. k + m - 1`` (within one 256-point cell), each point's
    segment its own ``floor(t / T)``, the kernel's expression element for element."""
    rate_f = float(model.optics.point_rate_hz)
    ramp = np.arange(K._BLOCK, dtype=np.float64)
    off = k % K._BLOCK
    anchor = k - off
    t = (float(k) + ramp[:m]) / rate_f
    seg = np.floor(t / segment_s)
    row_of = seg.astype(np.int64) - model._noise_seg0
    out = np.empty((model.prism_count, m))
    for p in range(model.prism_count):
        base = K._phase_rev_at(anchor, model._r_h1[p], model._r_h2[p], model._r_lo[p], model._phase0_rev[p])
        r_p = model._r_h1[p] + model._r_h2[p] + model._r_lo[p]
        cum = model._noise_cum[row_of, p]
        eps = model._noise_eps[row_of, p]
        v = (base + ramp[off:off + m] * r_p) + model._rev_per_s[p] * (cum + eps * (t - seg * segment_s))
        out[p] = v - np.floor(v)
    return out


@pytest.mark.parametrize("segment_s", [0.01, 0.00093, 1.37e-3, 2.5e-5, 1e-5, 0.00256])
def test_noise_runs_found_by_bisection_give_each_points_segment(segment_s):
    optics = PRESETS["mid40"]
    rate = optics.point_rate_hz
    model = ScanModel(optics, speed_noise=SpeedNoise(segment_s=segment_s), rng=np.random.default_rng(3))
    rng = np.random.default_rng(int(segment_s * 1e7))
    starts = [0, 1, 255, 256, 1000, 12_345, 99_999] + rng.integers(0, 30 * rate, 40).tolist()
    model._grow_noise(int(math.floor((max(starts) + 2 * K._BLOCK) / rate / segment_s)) + 2)
    pattern = np.array([j % optics.channels for j in range(K._BLOCK + optics.channels)], dtype=np.uint8)
    for k0 in starts:
        k = int(k0)
        for m in sorted({m for m in (1, 2, 7, K._BLOCK - k % K._BLOCK) if m <= K._BLOCK - k % K._BLOCK}):
            revs = np.full((model.prism_count, K._BLOCK), np.nan)
            t_ns = np.empty(m, dtype=np.int64)
            channel = np.empty(m, dtype=np.uint8)
            tb = np.empty(K._BLOCK)
            K._scan_block_setup(k, m, rate, model._r_h1, model._r_h2, model._r_lo, model._phase0_rev, True,
                                segment_s, model._noise_cum, model._noise_eps, model._noise_seg0, model._rev_per_s,
                                optics.channels, pattern, revs, t_ns, channel, np.int64(0), tb)
            want = _twin_phases(model, k, m, segment_s)
            assert revs[:, :m].tobytes() == want.tobytes(), (k, m)
            assert np.array_equal(t_ns, [(kk * 1_000_000_000) // rate for kk in range(k, k + m)])
            assert np.array_equal(channel, [kk % optics.channels for kk in range(k, k + m)])
