"""The int32 millimetre grid of a Livox's Cartesian points (SDK data types 0, 2, 4 and 7), in one place.

A Livox sends x, y, z as int32 mm; the live client (:mod:`foveatrack.livox.protocol`), the simulator's
sensor and the recordings (:mod:`foveatrack.recording`: points packed on this grid) all convert with
these functions, so a point takes the same bits whichever path it came by.  Kept apart from the
protocol so that the recordings do not depend on the Livox package (which reads recordings to export
LVX files).
"""

from __future__ import annotations

import numpy as np

MM_PER_M = 1000.0
INT32_MM_MIN, INT32_MM_MAX = -(2**31), 2**31 - 1


def m_to_mm(xyz_m) -> np.ndarray:
    """Metres -> the int32 millimetres a Livox sends (round half to even, saturated at the int32 range:
    ±2147 km, far past any range a sensor reports).  Any shape; NaN is not allowed."""
    return np.rint(np.asarray(xyz_m, dtype=np.float64) * MM_PER_M).clip(INT32_MM_MIN, INT32_MM_MAX).astype(np.int32)


def mm_to_m(mm) -> np.ndarray:
    """int32 millimetres -> float64 metres: ``mm * 1e-3``, THE operation of every Cartesian point the
    live client decodes and every point the simulator outputs (a product with 1e-3, not a quotient by
    1000: the two differ in the last bit for some values, so nothing else may be used)."""
    return np.multiply(np.asarray(mm, dtype=np.int32), 1e-3)


def quantise_to_mm_grid(xyz_m) -> np.ndarray:
    """Points [m] as a Livox reports them: on the int32 mm grid, in the client's float64 metres."""
    return mm_to_m(m_to_mm(xyz_m))
