"""The daemon's bounded summary of its per-frame times against numpy's percentiles (issue 26)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from foveatrack.daemon.streaming_summary import StreamingSummary


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_percentiles_within_half_a_bin_of_numpy(seed):
    rng = np.random.default_rng(seed)
    # a latency-like stream: a body near 15 ms, a long tail, a few spikes, values on bin edges
    x = np.concatenate([rng.gamma(4.0, 4.0, 20_000), rng.uniform(50, 900, 200), np.arange(0, 30, 0.1)])
    rng.shuffle(x)
    s = StreamingSummary(bin_ms=0.1, hi_ms=2000.0)
    for v in x:
        s.add(v)
    assert s.count == len(s) == x.size
    assert s.last == x[-1] and s.max == x.max() and s.min == x.min()
    for p in (0, 1, 10, 50, 90, 99, 99.9, 100):
        assert abs(s.percentile(p) - np.percentile(x, p)) <= 0.05 + 1e-9, p


def test_a_coarse_bin_is_still_within_its_half_width():
    rng = np.random.default_rng(5)
    x = rng.uniform(0, 100, 999)
    s = StreamingSummary(bin_ms=5.0, hi_ms=100.0)
    for v in x:
        s.add(v)
    for p in np.linspace(0, 100, 41):
        assert abs(s.percentile(p) - np.percentile(x, p)) <= 2.5 + 1e-9, p


def test_outside_the_bins_the_extremes_are_exact():
    s = StreamingSummary(bin_ms=1.0, lo_ms=0.0, hi_ms=10.0)
    for v in [-3.0, 1.2, 2.7, 5000.0, float("nan")]:
        s.add(v)
    assert s.count == 4                      # NaN not counted
    assert s.percentile(0) == -3.0 and s.percentile(100) == 5000.0
    assert s.max == 5000.0 and s.last == 5000.0
    assert math.isnan(StreamingSummary().percentile(50))


def test_memory_does_not_grow_with_the_stream():
    s = StreamingSummary()
    before = s._counts.nbytes
    for v in np.linspace(0, 3000, 100_000):
        s.add(v)
    assert s._counts.nbytes == before
