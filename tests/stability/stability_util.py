"""Shared helpers of the stability suite (hypothesis sizing, angle helpers)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import settings

# The loaded profile's max_examples relative to hypothesis's default (100): 1 under "ci", 20 under "long".
SCALE = settings.default.max_examples / 100.0
LONG = settings.default.max_examples > 100


def examples(ci_count: int, **kw) -> settings:
    """``@settings`` with ``ci_count`` examples under the "ci" profile, scaled up under "long"."""
    return settings(max_examples=max(1, int(round(ci_count * SCALE))), **kw)


def angle_between(a, b) -> np.ndarray:
    """Angle [rad] between rows of unit-ish vectors, accurate near 0 and pi (atan2 of |axb|, a.b)."""
    a = np.atleast_2d(np.asarray(a, float))
    b = np.atleast_2d(np.asarray(b, float))
    cross = np.linalg.norm(np.cross(a, b), axis=1)
    dot = np.einsum("ij,ij->i", a, b)
    return np.arctan2(cross, dot)


def wrap_rev_diff(a, b) -> np.ndarray:
    """Signed difference of two phases [rev], wrapped to [-0.5, 0.5)."""
    d = np.asarray(a, float) - np.asarray(b, float)
    return d - np.floor(d + 0.5)


def deg_diff(a, b) -> float:
    """Difference of two angles [deg] wrapped to (-180, 180]."""
    d = (a - b + 180.0) % 360.0 - 180.0
    return 180.0 if d == -180.0 else d


def isclose_all(a, b, tol) -> bool:
    return bool(np.all(np.abs(np.asarray(a) - np.asarray(b)) <= tol))


__all__ = ["SCALE", "LONG", "examples", "angle_between", "wrap_rev_diff", "deg_diff", "isclose_all", "math"]
