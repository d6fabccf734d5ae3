"""Confidence intervals of the study's per-seed values, and when two settings differ beyond noise.

Every closed-loop number of the study is a mean over seeds; this module turns the per-seed values
(kept in the JSON) into a two-sided Student-t interval of the mean (95 % by default).  A difference
between two settings counts only when it lies outside the noise: for paired runs (same seed, two
settings) the interval of the paired differences must exclude zero; for costs, the two intervals
must not overlap.  With one seed there is no interval (``half`` is None) and nothing is claimed.
"""

from __future__ import annotations

import math

LEVEL = 0.95


def interval(values, level: float = LEVEL) -> dict | None:
    """``{"mean", "half", "lo", "hi", "n", "values"}`` of the finite ``values`` (None if there are none).

    ``half`` is the t-interval's half-width, ``t_{n-1} * s / sqrt(n)``; None (and lo = hi = mean)
    with a single value.  ``values`` are kept in their order (per seed), for the JSON.
    """
    from scipy.stats import t as student_t

    v = [float(x) for x in values if x is not None and isinstance(x, (int, float)) and math.isfinite(x)]
    if not v:
        return None
    n = len(v)
    mean = math.fsum(v) / n
    if n < 2:
        return {"mean": mean, "half": None, "lo": mean, "hi": mean, "n": 1, "values": v}
    sd = math.sqrt(math.fsum((x - mean) ** 2 for x in v) / (n - 1))
    half = float(student_t.ppf(0.5 + level / 2, n - 1)) * sd / math.sqrt(n)
    return {"mean": mean, "half": half, "lo": mean - half, "hi": mean + half, "n": n, "values": v}


def paired_delta(a: dict, b: dict, level: float = LEVEL) -> dict | None:
    """Interval of ``a[seed] - b[seed]`` over the seeds both have (``a``, ``b``: seed -> value)."""
    seeds = sorted(s for s in a if s in b and a[s] is not None and b[s] is not None)
    return interval([a[s] - b[s] for s in seeds], level)


def paired_ratio(a: dict, b: dict, level: float = LEVEL) -> dict | None:
    """Interval of ``a[seed] / b[seed]`` (costs relative to a reference measured in the same study)."""
    seeds = sorted(s for s in a if s in b and a[s] is not None and b[s])
    return interval([a[s] / b[s] for s in seeds], level)


def abs_bounds(iv: dict | None) -> tuple[float, float] | None:
    """Bounds of ``|x|`` for ``x`` in the interval: ``(0, ...)`` when it contains zero."""
    if iv is None:
        return None
    lo, hi = iv["lo"], iv["hi"]
    if lo <= 0.0 <= hi:
        return 0.0, max(-lo, hi) + 0.0      # + 0.0: never -0.0
    return min(abs(lo), abs(hi)), max(abs(lo), abs(hi))


def excludes_zero(iv: dict | None) -> bool:
    """True when the interval is real (two or more values) and does not contain zero."""
    return iv is not None and iv["half"] is not None and not (iv["lo"] <= 0.0 <= iv["hi"])


def fmt(iv: dict | None, digits: str = "{:.3g}") -> str:
    """``mean ± half`` for the report (``-`` when missing, the bare mean with one value)."""
    if iv is None:
        return "-"
    if iv["half"] is None:
        return digits.format(iv["mean"])
    return f"{digits.format(iv['mean'])} ± {digits.format(iv['half'])}"
