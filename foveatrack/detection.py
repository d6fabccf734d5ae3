"""Algorithm 1 of the paper (Appendix D.2): intruder detection by the per-axis median.

.. math::  p_d = [\\operatorname{med}_i x_i,\\ \\operatorname{med}_i y_i,\\ \\operatorname{med}_i z_i]^T,
           \\quad i \\in \\{ p_i \\in P : p_i \\in \\mathcal{D} \\}

Points that are not finite (NaN/inf) and exact (0, 0, 0) "no return" points (Livox) are dropped
first.  An empty result is "no detection" (``None``).  With an even number of points the median is
the mean of the two middle values (numpy), so one point gives that point and two give their midpoint.

The detection time ``t_s`` is the *median timestamp of the retained points* (not the frame's
mid-time): it is when the target was actually seen, which matters when the target occupies only
part of the 100 ms frame, and it is what the controller and reconstruction use as the observation time.

Bearings use ``atan2`` (the paper's ``arctan(y/x)`` breaks behind the sensor and at x -> 0):

.. math:: az = \\operatorname{atan2}(y, x) \\in (-180, 180],\\qquad
          el = \\operatorname{atan2}(z, \\sqrt{x^2 + y^2}) \\in [-90, 90]  \\quad [deg]

Positive azimuth = target to the LEFT (+Y), positive elevation = target UP (+Z).
"""

from __future__ import annotations

import dataclasses
import math

from dataclasses import dataclass

import numpy as np

from foveatrack.fixed_order import norm3
from foveatrack.frames import Frame


def wrap_deg(a):
    """Wrap angles to (-180, 180] degrees."""
    if isinstance(a, (float, int)):  # the per-frame scalar path, without numpy's overhead
        a = float(a)
        if -180.0 < a <= 180.0:
            return a  # in range: unchanged (the +-180 shift would round)
        w = math.fmod(a + 180.0, 360.0)
        w = (w + 360.0 if w < 0.0 else w) - 180.0
        return 180.0 if w == -180.0 else w
    a = np.asarray(a, dtype=float)
    w = np.mod(a + 180.0, 360.0) - 180.0
    w = np.where(w == -180.0, 180.0, w)
    w = np.where((a > -180.0) & (a <= 180.0), a, w)  # in range: unchanged (the +-180 shift rounds)
    return float(w) if np.ndim(w) == 0 else w


def bearing_deg(x: float, y: float, z: float, hypot_xy: float | None = None) -> tuple[float, float]:
    """Azimuth and elevation [deg] of a point (lidar or any right-handed X-fwd/Y-left/Z-up frame).
    ``hypot_xy``: ``np.hypot(x, y)`` if the caller has it (the box kernel computes it with the same
    libm ``hypot``), to spare numpy's scalar call."""
    # x + 0.0 turns -0.0 into +0.0: straight overhead (x = y = 0) has az 0, not atan2(0, -0.0) = 180.
    # math.atan2/math.degrees give numpy's bits on scalars (libm atan2, x * (180/pi)); math.hypot
    # does not (CPython's own algorithm differs from libm's hypot in the last bit), so np.hypot stays.
    az = math.degrees(math.atan2(y, x + 0.0))
    if not -180.0 < az <= 180.0:   # in range: wrap_deg returns it unchanged
        az = wrap_deg(az)
    if hypot_xy is None:
        hypot_xy = float(np.hypot(x, y))
    el = math.degrees(math.atan2(z, hypot_xy))
    return az, el


@dataclass(frozen=True)
class Detection:
    """The output of Algorithm 1 for one frame.

    t_s : float [s]        median timestamp of the retained points
    xyz : (3,) float [m]   per-axis median position in the lidar frame
    n_points : int >= 1    number of retained points
    az_deg, el_deg : float bearing of ``xyz`` (see module docstring)
    range_m : float        ``|xyz|``
    """

    t_s: float
    xyz: np.ndarray
    n_points: int
    az_deg: float
    el_deg: float
    range_m: float


def frozen_maker(cls):
    """A fast positional constructor for a frozen dataclass without ``__post_init__``: every field
    in declaration order, all required.  The object equals ``cls(*args)`` (tested); it skips the
    generated ``__init__``'s one ``object.__setattr__`` per field (~4 us -> ~1.5 us for 15 fields),
    which matters once per frame."""
    if not dataclasses.is_dataclass(cls) or hasattr(cls, "__post_init__"):
        raise TypeError(f"{cls.__name__}: frozen_maker needs a dataclass without __post_init__")
    names = tuple(f.name for f in dataclasses.fields(cls))
    # generated as dataclasses generates __init__: the fields by position (a wrong count is Python's
    # TypeError) into one dict display, ~0.4 us where update(zip(names, args)) took ~0.55 us for ten
    params = ", ".join(f"_{i}" for i in range(len(names)))
    items = ", ".join(f"{name!r}: _{i}" for i, name in enumerate(names))
    ns = {"new": object.__new__, "cls": cls}
    exec(f"def make({params}):\n    obj = new(cls)\n    obj.__dict__.update({{{items}}})\n    return obj\n", ns)
    make = ns["make"]
    make.__qualname__ = make.__name__ = f"make_{cls.__name__}"
    return make


_make_detection = frozen_maker(Detection)


def valid_points(xyz: np.ndarray) -> np.ndarray:
    """Mask of points that are finite and not the exact (0,0,0) no-return marker."""
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    x, y, z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    # Column by column: ~10x faster than np.all/np.any(..., axis=1) on (N, 3) arrays.
    return np.isfinite(x) & np.isfinite(y) & np.isfinite(z) & ((x != 0.0) | (y != 0.0) | (z != 0.0))


def detect_points(xyz: np.ndarray, t_ns: np.ndarray, space=None, *, test_xyz: np.ndarray | None = None
                  ) -> Detection | None:
    """Algorithm 1 on raw arrays.

    ``space`` (anything with ``contains(xyz) -> bool mask``; ``None`` = everything) is tested on
    ``test_xyz`` if given (the same points expressed in D's frame, e.g. the world), otherwise on ``xyz``.
    """
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    t_ns = np.asarray(t_ns, dtype=np.int64).reshape(-1)
    keep = valid_points(xyz)
    if space is not None and keep.any():
        # Test every point and mask after: cheaper than gathering the valid ones first.  Invalid
        # points may give NaN comparisons (False) inside ``contains``; they are masked out anyway.
        pts = xyz if test_xyz is None else np.asarray(test_xyz, dtype=np.float64).reshape(-1, 3)
        with np.errstate(invalid="ignore", over="ignore"):
            keep &= np.asarray(space.contains(pts), dtype=bool)
    if not keep.any():
        return None
    return _median_detection(xyz[keep], t_ns[keep])


LEVEL = (1.0, 0.0, 1.0, 0.0)   # (cos pan, sin pan, cos tilt, sin tilt) of pan = tilt = 0: no turn


def detect_in_box(xyz: np.ndarray, t_ns: np.ndarray, box, trig=LEVEL, offset=(0.0, 0.0, 0.0)) -> Detection | None:
    """Algorithm 1 with a box D in one kernel call (:func:`foveatrack.kernels.box_median_kernel`):
    the same detection as :func:`detect_points` with ``test_xyz = (xyz + offset) @ R.T``, where
    ``R = rotation_matrix(pan, tilt)`` and ``trig = head_trig(pan, tilt)`` (the cosines and sines it
    is made of, :mod:`foveatrack.reconstruction`)."""
    xyz = np.ascontiguousarray(xyz, dtype=np.float64).reshape(-1, 3)
    t_ns = np.ascontiguousarray(t_ns, dtype=np.int64).reshape(-1)
    lo, hi = box_bounds(box)
    trig = tuple(float(v) for v in trig)
    offset = np.asarray(offset, dtype=np.float64)
    if t_ns.shape[0] < xyz.shape[0]:   # malformed input: the general route reports it
        return _detect_in_box_general(xyz, t_ns, trig, offset, lo, hi)
    return box_detection(xyz, t_ns, trig, offset, lo, hi)


def box_detection(xyz: np.ndarray, t_ns: np.ndarray, trig: tuple[float, float, float, float],
                  offset: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> Detection | None:
    """:func:`detect_in_box` for a caller that holds its arguments as the kernel takes them, as the
    tracker does every frame: a :class:`~foveatrack.frames.Frame`'s ``xyz`` (N, 3) float64 and
    ``t_ns`` (N,) int64 (contiguous, of one length), the pose's ``trig`` as floats, ``offset`` (3,)
    and D's bounds ``lo``, ``hi`` (3,) float64 (:func:`box_bounds`)."""
    global _box_median_kernel
    if _box_median_kernel is None:   # numba loads on first use, not on import
        from foveatrack.kernels import box_median_kernel as _box_median_kernel
    p = np.empty(3)
    cp, sp, ct, st = trig
    n, t_med_ns, hypot_xy = _box_median_kernel(xyz, t_ns, cp, sp, ct, st, offset, lo, hi, p)
    if n == 0:
        return None
    if n < 0:   # a zero median: its sign is numpy's sort's business (see the kernel)
        return _detect_in_box_general(xyz, t_ns, trig, offset, lo, hi)
    return _detection(p, t_med_ns, n, hypot_xy)


_box_median_kernel = None
_BOX_BOUNDS: dict = {}


def box_bounds(box) -> tuple[np.ndarray, np.ndarray]:
    """``box.min_xyz``, ``box.max_xyz`` as float64 arrays, made once per distinct box."""
    key = (tuple(box.min_xyz), tuple(box.max_xyz))
    b = _BOX_BOUNDS.get(key)
    if b is None:
        if len(_BOX_BOUNDS) > 64:
            _BOX_BOUNDS.clear()
        b = _BOX_BOUNDS[key] = (np.asarray(box.min_xyz, dtype=np.float64), np.asarray(box.max_xyz, dtype=np.float64))
        for a in b:
            a.flags.writeable = False
    return b


def _detect_in_box_general(xyz, t_ns, trig, offset, lo, hi) -> Detection | None:
    """:func:`detect_in_box` with numpy's medians (:func:`_median_detection`)."""
    from foveatrack.kernels import box_members_kernel

    idx = np.empty(xyz.shape[0], dtype=np.int64)
    cp, sp, ct, st = trig
    n = box_members_kernel(xyz, cp, sp, ct, st, offset, lo, hi, idx)
    if n == 0:
        return None
    return _median_detection(xyz[idx[:n]], t_ns[idx[:n]])


def _median_detection(pts: np.ndarray, t_ns: np.ndarray) -> Detection:
    p = _median_rows(pts)
    return _detection(p, _median_rows(t_ns.astype(np.float64)), int(pts.shape[0]))


def _detection(p: np.ndarray, t_med_ns: float, n: int, hypot_xy: float | None = None) -> Detection:
    """A Detection from the median position ``p`` (3,), median time [ns] and the point count
    (``hypot_xy``: see :func:`bearing_deg`).
    ``|p|`` summed in a fixed order (:func:`foveatrack.fixed_order.norm3`: not BLAS's, which differs per CPU)."""
    x, y, z = p.tolist()
    az, el = bearing_deg(x, y, z, hypot_xy)
    return _make_detection(float(t_med_ns) * 1e-9, p, n, az, el, norm3(p))


def _median_rows(a: np.ndarray):
    """``np.median(a, axis=0)`` (the same values: the middle one, or the mean of the middle two)
    without its generic machinery, which cost more than the sort for a frame's few points."""
    s = np.sort(a, axis=0)
    m = s.shape[0] // 2
    return s[m] if s.shape[0] % 2 else (s[m - 1] + s[m]) / 2


def detect(frame: Frame, space=None, *, test_xyz: np.ndarray | None = None) -> Detection | None:
    """Algorithm 1 on a :class:`~foveatrack.frames.Frame`."""
    return detect_points(frame.xyz, frame.t_ns, space, test_xyz=test_xyz)


def compile_all() -> None:
    """Compile (or load from numba's cache) the kernels of :mod:`foveatrack.kernels` before a
    real-time driver's data flows.

    A first call compiles, which takes seconds on a fresh install and would stall the first frames.
    numba compiles one version per argument signature, so the kernels are run through the tracker's
    own entry point, :func:`detect_in_box`, with both of its routes (the median
    kernel, and a zero median's numpy route through :func:`box_members_kernel`): the types are then
    the tracker's by construction.  (Hand-made arguments once missed its read-only D bounds, and the
    daemon's first frame compiled anew, 1.8 s late, in a fresh clone.)
    """
    from foveatrack.space_of_interest import Box

    box = Box((0.0, 0.0, 0.0), (2.0, 2.0, 2.0))
    t_ns = np.zeros(1, dtype=np.int64)
    detect_in_box(np.ones((1, 3)), t_ns, box, LEVEL, np.zeros(3))
    detect_in_box(np.array([[1.0, 0.0, 1.0]]), t_ns, box, LEVEL, np.zeros(3))   # a zero median
