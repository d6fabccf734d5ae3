"""A bounded summary of a long stream of times [ms]: count, last, min, max and percentiles from a
fixed-bin histogram (issue 26: the daemon kept every frame's processing and latency time in a list,
~2.3 MB an hour at 10 Hz, for the p50/p99/max of its ``stop`` event).

Percentiles are numpy's (linear interpolation between order statistics) computed on the bin centres:
each order statistic inside ``[lo_ms, hi_ms)`` is placed at its bin's centre, so a percentile is within
``bin_ms / 2`` of ``np.percentile`` of the values themselves (the result is also kept inside the
stream's exact min and max).  Values below ``lo_ms`` or at or above ``hi_ms`` are counted in an
under- or overflow bin and placed at the exact min or max: a percentile that falls there is the
stream's extreme, not an interpolation.  The defaults (0.1 ms bins up to 2 s) cost 160 KB.
"""

from __future__ import annotations

import math

import numpy as np


class StreamingSummary:
    """count / last / min / max / percentiles of a stream of values [ms] in constant memory."""

    def __init__(self, bin_ms: float = 0.1, lo_ms: float = 0.0, hi_ms: float = 2000.0):
        if not (bin_ms > 0 and hi_ms > lo_ms):
            raise ValueError(f"bins need bin_ms > 0 and hi_ms > lo_ms, got {bin_ms}, [{lo_ms}, {hi_ms})")
        self.bin_ms, self.lo_ms = float(bin_ms), float(lo_ms)
        self.n_bins = int(math.ceil((hi_ms - lo_ms) / bin_ms))
        self.hi_ms = self.lo_ms + self.n_bins * self.bin_ms
        # [underflow, bins..., overflow]
        self._counts = np.zeros(self.n_bins + 2, np.int64)
        self.count = 0
        self.last: float | None = None
        self.min = math.inf
        self.max = -math.inf

    def add(self, x_ms: float) -> None:
        x = float(x_ms)
        if not math.isfinite(x):
            return
        if x < self.lo_ms:
            i = 0
        elif x >= self.hi_ms:
            i = self.n_bins + 1
        else:
            i = 1 + min(int((x - self.lo_ms) / self.bin_ms), self.n_bins - 1)
        self._counts[i] += 1
        self.count += 1
        self.last = x
        self.min = min(self.min, x)
        self.max = max(self.max, x)

    def __len__(self) -> int:
        return self.count

    def _order_stat(self, cum: np.ndarray, k: int) -> float:
        """The k-th smallest value (0-based), as placed by the histogram (module docstring)."""
        b = int(np.searchsorted(cum, k, side="right"))
        if b == 0:
            return self.min
        if b == self.n_bins + 1:
            return self.max
        return min(max(self.lo_ms + (b - 0.5) * self.bin_ms, self.min), self.max)

    def percentile(self, p: float) -> float:
        """The ``p``-th percentile [ms] (numpy's linear method, within ``bin_ms / 2`` for values inside
        the bins); NaN when empty."""
        if self.count == 0:
            return math.nan
        cum = np.cumsum(self._counts)
        r = p / 100.0 * (self.count - 1)
        k0 = int(math.floor(r))
        k1 = min(k0 + 1, self.count - 1)
        a, b = self._order_stat(cum, k0), self._order_stat(cum, k1)
        return a + (b - a) * (r - k0)
