"""A reference trajectory (``time, x, y, z`` in the sensor frame) and the per-frame error against it.

Two forms: a CSV of ``time, x, y, z`` (seconds, metres; a header line is allowed), or a folder of
per-frame estimates ``<unix time>.npy`` each holding x, y, z (MMAUD's ``result/seqN/``).  Each tracked
frame is compared with the reference sample nearest in time if it lies within ``max_dt_s`` (half a
frame by default): a reference is a list of positions at sample times, not a curve to interpolate
through the gaps where it has none.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from foveatrack.errors import UserError


def load_reference(path) -> tuple[np.ndarray, np.ndarray]:
    """``(t_s (M,), xyz_m (M, 3))`` sorted by time."""
    p = Path(path)
    if not p.exists():
        raise UserError(f"--reference {p}: no such file or folder")
    if p.is_dir():
        from foveatrack.sources.npy_folder import timed_files
        from foveatrack.sources.stamps import seconds

        ts, xs = [], []
        for ns, f in timed_files(p, ".npy"):
            try:
                a = np.load(f, allow_pickle=False)
            except (ValueError, OSError, EOFError) as exc:
                raise UserError(f"--reference {f}: not a readable .npy array ({exc})") from None
            if a.size != 3 or a.dtype.kind not in "fiu":
                raise UserError(f"--reference {f}: expected x, y, z (3 numbers), got shape {a.shape}")
            ts.append(seconds(ns))
            xs.append(np.asarray(a, np.float64).reshape(3))
        return np.asarray(ts), np.asarray(xs).reshape(-1, 3)
    try:
        text = p.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"--reference {p}: cannot read it ({exc})") from None
    rows = []
    for i, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = [q.strip() for q in s.replace(";", ",").split(",")]
        try:
            vals = [float(q) for q in parts]
        except ValueError:
            if not rows and i == 1 or not rows and not any(c.isdigit() for c in s):
                continue   # a header line
            raise UserError(f"--reference {p}:{i}: expected time, x, y, z numbers, got {s[:60]!r}") from None
        if len(vals) < 4:
            raise UserError(f"--reference {p}:{i}: expected 4 columns (time, x, y, z), got {len(vals)}")
        rows.append(vals[:4])
    if not rows:
        raise UserError(f"--reference {p}: no rows of time, x, y, z")
    a = np.asarray(rows, np.float64)
    a = a[np.argsort(a[:, 0], kind="stable")]
    return a[:, 0], a[:, 1:4]


def match_reference(t_s: np.ndarray, ref_t_s: np.ndarray, max_dt_s: float) -> np.ndarray:
    """Index of the nearest reference sample for each time, or -1 if none within ``max_dt_s``."""
    t_s = np.asarray(t_s, np.float64)
    out = np.full(t_s.shape[0], -1, np.int64)
    if ref_t_s.size == 0:
        return out
    i = np.clip(np.searchsorted(ref_t_s, t_s), 1, max(ref_t_s.size - 1, 1))
    lo = np.where(ref_t_s.size > 1, i - 1, 0)
    hi = np.minimum(i, ref_t_s.size - 1)
    pick = np.where(np.abs(ref_t_s[lo] - t_s) <= np.abs(ref_t_s[hi] - t_s), lo, hi)
    ok = np.abs(ref_t_s[pick] - t_s) <= max_dt_s
    out[ok] = pick[ok]
    return out


def error_summary(err_m: np.ndarray) -> dict:
    """median, p95, max and count of the finite distances [m]."""
    e = np.asarray(err_m, float)
    e = e[np.isfinite(e)]
    if e.size == 0:
        return {"frames": 0, "median_m": None, "p95_m": None, "max_m": None}
    return {"frames": int(e.size), "median_m": float(np.median(e)), "p95_m": float(np.percentile(e, 95)),
            "max_m": float(e.max())}
