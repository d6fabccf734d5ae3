"""The features the classifier (:mod:`foveatrack.sky.classify`, whose docstring defines them) reads
of a track's window of hits.

They are one numba kernel (:func:`features_rows_kernel`; its sums :func:`fsum_kernel`, CPython's
``math.fsum`` -- Shewchuk's partials and the final half-even correction of ``Modules/mathmodule.c``
-- line for line, so exactly rounded: the same bits everywhere, whatever the order): the tracker
classifies a few tracks a frame, and the same arithmetic in Python lists took ~20 us for a window of
14 hits, the largest share of the sky tracker's frame after the per-point work.  Its plain-Python
twin (:func:`features_python`, :func:`flap_period_s` and ``math.fsum``) is what
``tests/sky/test_classify.py`` compares it with, bit for bit.
A frame's reclassified tracks go in one call (from :func:`foveatrack.sky.classify.classify_many`, on
the rows the tracker keeps of each hit), every sum's partials and temporaries in one workspace; one
track's (:func:`window_features`) is the same call on one window.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


def _mean(xs) -> float:
    return math.fsum(xs) / len(xs)


def _velocity(ts, ps) -> list[float]:
    """Least-squares velocity per axis of the positions ``ps`` (lists of 3 floats) at times ``ts``;
    the times' mean and spread once for the three axes."""
    tm = _mean(ts)
    dts = [t - tm for t in ts]
    den = math.fsum([d * d for d in dts])
    if den == 0.0:
        return [0.0, 0.0, 0.0]
    out = []
    for a in range(3):
        xs = [p[a] for p in ps]
        xm = _mean(xs)
        out.append(math.fsum([d * (x - xm) for d, x in zip(dts, xs)]) / den)
    return out


def _norm(v) -> float:
    return math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


def flap_period_s(ts, zs, min_period_s: float, threshold: float) -> float | None:
    """Apparent period of the series ``zs`` sampled at ``ts`` (about evenly): the lag of the first
    normalised autocorrelation peak above ``threshold`` with at least two periods in the window."""
    n = len(zs)
    if n < 6:
        return None
    dt = (ts[-1] - ts[0]) / (n - 1)
    m = _mean(zs)
    d = [z - m for z in zs]
    var = math.fsum([x * x for x in d])
    if var <= 0.0 or dt <= 0.0:
        return None
    ac = {}

    def at(k: int) -> float:
        # each lag's autocorrelation when the search first reads it (most windows hold no peak
        # above the threshold, and the lags below the shortest period are read by none)
        if k not in ac:
            ac[k] = math.fsum([d[i] * d[i + k] for i in range(n - k)]) / var
        return ac[k]

    for k in range(1, n // 2):
        if k * dt >= min_period_s and at(k) >= threshold and at(k) >= at(k - 1) and at(k) >= at(k + 1):
            return k * dt
    return None


def _base_features(track) -> dict:
    return {"hits": len(track.history), "speed_m_s": track.kf.speed_m_s,
            "excursion_m": float(getattr(track, "excursion_m", 0.0)),
            "age_s": float(track.last_hit_t_s - track.first_t_s)}


def features_python(track, period: tuple[float, float] | None = None) -> dict:
    """:func:`window_features` in Python lists and ``math.fsum``: the twin of :func:`features_rows_kernel`.
    ``period``: ``(min_period_s, threshold)`` to look for ``flap_period_s`` (:func:`flap_period_s`;
    None: it stays None)."""
    h = track.history
    f = _base_features(track)
    if len(h) < 2:
        return f
    f["median_points"] = float(sorted(int(x[3]) for x in h)[len(h) // 2])
    ts = [x[0] for x in h]
    span = ts[-1] - ts[0]
    sides = [x[2].tolist() for x in h]
    zs = [float(s[2]) for s in sides]
    f["size_m"] = sorted(float(max(s)) for s in sides)[len(h) // 2]
    p0, p1 = h[0][1].tolist(), h[-1][1].tolist()
    f["net_speed_m_s"] = _norm([p1[a] - p0[a] for a in range(3)]) / span if span > 0 else 0.0
    zm = _mean(zs)
    f["flap_cv"] = math.sqrt(_mean([(z - zm) * (z - zm) for z in zs])) / zm if zm > 0 else 0.0
    half = len(h) // 2
    if half >= 3:
        ps = [x[1].tolist() for x in h]
        va, vb = _velocity(ts[:half], ps[:half]), _velocity(ts[half:], ps[half:])
        dt = _mean(ts[half:]) - _mean(ts[:half])
        f["manoeuvre_m_s2"] = _norm([vb[i] - va[i] for i in range(3)]) / dt if dt > 0 else 0.0
    f["flap_period_s"] = None if period is None else flap_period_s(ts, zs, *period)
    return f


@njit(cache=True)
def fsum_kernel(xs):
    """``math.fsum`` of the array ``xs``: CPython's ``math_fsum`` (Modules/mathmodule.c) line for
    line -- the partials of Shewchuk's exact sum, the special values set aside, the partials summed
    from the top until inexact, and the correction that makes the rounding half-even across them.
    Exactly rounded, so the bits of ``math.fsum`` whatever the order (its errors too: an intermediate
    overflow of finite values, -inf + inf)."""
    return _fsum_into(xs, xs.shape[0], np.empty(xs.shape[0] + 1))


@njit(cache=True)
def _fsum_into(xs, m, p):
    """:func:`fsum_kernel` of ``xs[:m]``, its partials in ``p`` (at least ``m + 1`` long; the
    features' one workspace, not an array a sum)."""
    n = 0
    special_sum = 0.0
    inf_sum = 0.0
    for k in range(m):
        x = xs[k]
        xsave = x
        i = 0
        for j in range(n):          # for y in partials
            y = p[j]
            if abs(x) < abs(y):
                x, y = y, x
            hi = x + y
            yr = hi - x
            lo = y - yr
            if lo != 0.0:
                p[i] = lo
                i += 1
            x = hi
        n = i                       # partials[i:] = [x]
        if x != 0.0:
            if not math.isfinite(x):
                # an intermediate overflow, or a nan or inf among the summands
                if math.isfinite(xsave):
                    raise OverflowError("intermediate overflow in fsum")
                if math.isinf(xsave):
                    inf_sum += xsave
                special_sum += xsave
                n = 0
            else:
                p[n] = x
                n += 1
    if special_sum != 0.0:
        if math.isnan(inf_sum):
            raise ValueError("-inf + inf in fsum")
        return special_sum
    hi = 0.0
    lo = 0.0
    if n > 0:
        n -= 1
        hi = p[n]
        # the partials from the top, until the sum becomes inexact
        while n > 0:
            x = hi
            n -= 1
            y = p[n]
            hi = x + y
            yr = hi - x
            lo = y - yr
            if lo != 0.0:
                break
        # half-even rounding across the partials (sum([1e-16, 1, 1e16]) rounds up to 2 in the last digit)
        if n > 0 and ((lo < 0.0 and p[n - 1] < 0.0) or (lo > 0.0 and p[n - 1] > 0.0)):
            y = lo * 2.0
            x = hi + y
            yr = x - hi
            if y == yr:
                hi = x
    return hi


@njit(cache=True)
def _mean_kernel(xs, m, p):
    return _fsum_into(xs, m, p) / m


@njit(cache=True)
def _sorted_middle(xs):
    """``sorted(xs)[len(xs) // 2]`` (a stable insertion sort: the element Python's sort puts there),
    for values with no NaN among them (a NaN compares false both ways and the two sorts part): the
    tracker's box sides and point counts come from finite points.  Sorts ``xs`` in place."""
    a = xs
    for i in range(1, a.shape[0]):
        v = a[i]
        j = i - 1
        while j >= 0 and v < a[j]:
            a[j + 1] = a[j]
            j -= 1
        a[j + 1] = v
    return a[a.shape[0] // 2]


@njit(cache=True)
def _velocity_kernel(ts, P, out, W):
    """:func:`_velocity` of the times ``ts`` (n,) and positions ``P`` (n, 3), into ``out`` (3,);
    ``W`` (4, >= n + 1) a workspace.  Returns the times' mean (the manoeuvre's dt reads it)."""
    n = ts.shape[0]
    p = W[0]
    dts = W[1]
    tmp = W[2]
    xs = W[3]
    tm = _mean_kernel(ts, n, p)
    for i in range(n):
        dts[i] = ts[i] - tm
    for i in range(n):
        tmp[i] = dts[i] * dts[i]
    den = _fsum_into(tmp, n, p)
    if den == 0.0:
        out[:] = 0.0
        return tm
    for a in range(3):
        for i in range(n):
            xs[i] = P[i, a]
        xm = _mean_kernel(xs, n, p)
        for i in range(n):
            tmp[i] = dts[i] * (xs[i] - xm)
        out[a] = _fsum_into(tmp, n, p) / den
    return tm


@njit(cache=True)
def _flap_period_kernel(ts, zs, m, var, min_period_s, threshold, W):
    """:func:`flap_period_s`; NaN for None.  Each lag's autocorrelation is summed when the search
    first reads it, as there (a lag read by none is never summed).  ``m``: the mean of ``zs``,
    ``var`` the sum of their squared deviations from it if known (NaN: summed here; the flap cv's
    sums, the same bits).  ``W`` (4, >= n + 1) a workspace (``zs`` not in it)."""
    n = zs.shape[0]
    if n < 6:
        return np.nan
    p = W[0]
    d = W[1]
    tmp = W[2]
    ac = W[3]               # each lag's autocorrelation, NaN until summed
    dt = (ts[n - 1] - ts[0]) / (n - 1)
    for i in range(n):
        d[i] = zs[i] - m
    if math.isnan(var):
        for i in range(n):
            tmp[i] = d[i] * d[i]
        var = _fsum_into(tmp, n, p)
    if var <= 0.0 or dt <= 0.0:
        return np.nan
    done = np.zeros(n // 2 + 1, np.bool_)
    for k in range(1, n // 2):
        if not k * dt >= min_period_s:
            continue
        peak = True
        for q in (k, k - 1, k + 1):         # at(k), at(k - 1), at(k + 1) as the test reads them
            if not done[q]:
                for i in range(n - q):
                    tmp[i] = d[i] * d[i + q]
                ac[q] = _fsum_into(tmp, n - q, p) / var
                done[q] = True
            if not (ac[k] >= threshold if q == k else ac[k] >= ac[q]):
                peak = False
                break
        if peak:
            return k * dt
    return np.nan


@njit(cache=True)
def _features(ts, counts, P, S, want_period, min_period_s, threshold, out, W):
    """The window's features of :func:`features_python` (n >= 2 hits) from its times ``ts`` (n,),
    returns ``counts`` (n,), positions ``P`` (n, 3) and box sides ``S`` (n, 3), into ``out`` (8,):
    median points, size, net speed, flap cv, whether the manoeuvre is defined (1.0) and its value,
    whether a flap period was found (1.0, looked for only if ``want_period``) and its value.  ``W``
    (7, >= n + 1) its workspace: its sums' partials and temporaries (one array a window where they
    were a couple of dozen)."""
    n = ts.shape[0]
    p = W[0]
    zs = W[1]
    tmp = W[2]
    for i in range(n):
        tmp[i] = counts[i]
    out[0] = _sorted_middle(tmp[:n])
    span = ts[n - 1] - ts[0]
    for i in range(n):
        zs[i] = S[i, 2]
        m = S[i, 0]                  # max(s): the first of the largest, as Python's max
        if S[i, 1] > m:
            m = S[i, 1]
        if S[i, 2] > m:
            m = S[i, 2]
        tmp[i] = m
    out[1] = _sorted_middle(tmp[:n])
    if span > 0:
        dx = P[n - 1, 0] - P[0, 0]
        dy = P[n - 1, 1] - P[0, 1]
        dz = P[n - 1, 2] - P[0, 2]
        out[2] = math.sqrt(dx * dx + dy * dy + dz * dz) / span
    else:
        out[2] = 0.0
    zm = _mean_kernel(zs, n, p)
    sq = np.nan                 # the squared deviations' sum, once (the flap period's too)
    if zm > 0:
        for i in range(n):
            tmp[i] = (zs[i] - zm) * (zs[i] - zm)
        sq = _fsum_into(tmp, n, p)
        out[3] = math.sqrt(sq / n) / zm
    else:
        out[3] = 0.0
    half = n // 2
    out[4] = 0.0
    out[5] = 0.0
    V = W[3:7]
    if half >= 3:
        va = np.empty(3)
        vb = np.empty(3)
        ta = _velocity_kernel(ts[:half], P[:half], va, V)
        dt = _velocity_kernel(ts[half:], P[half:], vb, V) - ta      # the halves' mean times
        out[4] = 1.0
        if dt > 0:
            ex = vb[0] - va[0]
            ey = vb[1] - va[1]
            ez = vb[2] - va[2]
            out[5] = math.sqrt(ex * ex + ey * ey + ez * ez) / dt
    out[6] = 0.0
    out[7] = 0.0
    if want_period:
        period = _flap_period_kernel(ts, zs[:n], zm, sq, min_period_s, threshold, V)
        if not math.isnan(period):
            out[6] = 1.0
            out[7] = period


def window_features(track, period: tuple[float, float] | None) -> dict:
    """The features of a track (:mod:`foveatrack.sky.classify`) from its ``history`` and filter;
    ``period`` as in :func:`features_python`: :func:`window_features_many` of the one track."""
    return window_features_many([track], [period is not None], period or (0.0, 0.0))[0]


def _put_features(f: dict, row) -> None:
    """A window's eight outputs (:func:`_features`' ``out``, as floats) into the dict ``f``."""
    median_points, size_m, net_speed, flap_cv, has_manoeuvre, manoeuvre, has_period, flap = row
    f["median_points"] = median_points
    f["size_m"] = size_m
    f["net_speed_m_s"] = net_speed
    f["flap_cv"] = flap_cv
    if has_manoeuvre:
        f["manoeuvre_m_s2"] = manoeuvre
    f["flap_period_s"] = flap if has_period else None


@njit(cache=True)
def features_rows_kernel(H, starts, want_period, min_period_s, threshold, out):
    """:func:`_features` of many windows given as rows: ``H`` (m, 8) the hits, each ``(t_s,
    n_points, xyz_m, sides_m)``, window ``j`` its rows ``starts[j]`` to ``starts[j + 1]``; its features
    into ``out[j]``, its flap period looked for if ``want_period[j]``."""
    longest = 0
    for j in range(starts.shape[0] - 1):
        longest = max(longest, starts[j + 1] - starts[j])
    W = np.empty((7, longest + 1))          # one workspace for every window
    for j in range(starts.shape[0] - 1):
        a = starts[j]
        b = starts[j + 1]
        _features(H[a:b, 0], H[a:b, 1], H[a:b, 2:5], H[a:b, 5:8], want_period[j], min_period_s, threshold, out[j], W)


def history_rows(history) -> np.ndarray:
    """A history's hits ``(t_s, xyz_m, sides_m, n_points)`` as rows (n, 8) ``(t_s, n_points, xyz_m,
    sides_m)`` (:func:`features_rows_kernel`'s; a count of returns is a whole number: the same as a
    float)."""
    R = np.empty((len(history), 8))
    if history:
        ts, ps, sides, counts = zip(*history)
        R[:, 0] = ts
        R[:, 1] = counts
        R[:, 2:5] = ps
        R[:, 5:8] = sides
    return R


def kept_rows(track):
    """The track's history as rows (n, 8) where it keeps them in step with its history
    (:class:`foveatrack.sky.tracks.SkyTrack`'s ``rows``, each hit's row written as it came), else
    None."""
    h = track.history
    if getattr(track, "rows_of", None) is h and track.rows_end - track.rows_lo == len(h):
        return track.rows[track.rows_lo:track.rows_end]
    return None


def window_features_many(tracks, want_period, period: tuple[float, float]) -> list[dict]:
    """:func:`window_features` of each of ``tracks``, ``period`` looked for where ``want_period[i]``
    (a sequence of bools), the windows in one :func:`features_rows_kernel` call: a frame's few
    reclassified tracks paid the arrays' making and the kernel's dispatch each, ~4 us a track.  A
    track's rows are its own where it keeps them (:func:`kept_rows`), else made of its history."""
    fs = [_base_features(tr) for tr in tracks]
    blocks, starts, want, due = [], [0], [], []
    for f, tr, w in zip(fs, tracks, want_period):
        n = len(tr.history)
        if n < 2:
            continue
        R = kept_rows(tr)
        blocks.append(history_rows(tr.history) if R is None else R)
        starts.append(starts[-1] + n)
        want.append(w)
        due.append(f)
    if not due:
        return fs
    out = np.empty((len(due), 8))
    features_rows_kernel(np.concatenate(blocks), np.array(starts, np.int64), np.array(want, np.bool_), *period, out)
    for f, row in zip(due, out.tolist()):
        _put_features(f, row)
    return fs
